//! Records: a sampled free response with its rig constants, and the CSV formats.
//!
//! - SI CSV: header `t_s,x_m,v_m_s` plus any of `ft_n`, `temp_c`, `ecr_ohm` (any order after the
//!   three required columns), rig constants in leading comment lines `# mass_kg=…`,
//!   `# stiffness_n_per_m=…`, `# load_n=…`.
//! - Dimensionless CSV: header `tau,y,ydot` (the rig is [`Rig::UNIT`]).
//! - Runs recorded by `tribo` (not defined yet): [`Record::load`] dispatches on the path — a
//!   directory is where a stored run will be read; today it reports a clear error.

use crate::model::Rig;
use std::fmt::Write as _;
use std::path::Path;

/// Three sample columns `(τ, y, y')`.
pub type Columns = (Vec<f64>, Vec<f64>, Vec<f64>);

/// Units of a record's columns.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Units {
    /// SI (s, m, m/s, N).
    Si,
    /// Dimensionless (τ, y, y').
    Dimensionless,
}

/// A sampled free response.
#[derive(Debug, Clone, PartialEq)]
pub struct Record {
    /// Time (s, or τ if dimensionless), strictly increasing.
    pub t: Vec<f64>,
    /// Displacement (m, or y).
    pub x: Vec<f64>,
    /// Velocity (m/s, or y').
    pub v: Vec<f64>,
    /// Tangential friction force (N), if measured.
    pub ft: Option<Vec<f64>>,
    /// Plane temperature (°C), if measured.
    pub temp: Option<Vec<f64>>,
    /// Electrical contact resistance (Ω), if measured.
    pub ecr: Option<Vec<f64>>,
    /// Rig constants (`None` if the file did not give them; CLI flags may supply them).
    pub rig: Option<Rig>,
    /// Units of the columns.
    pub units: Units,
}

/// Error reading or validating a record.
#[derive(Debug, Clone, PartialEq)]
pub struct RecordError(pub String);

impl std::fmt::Display for RecordError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}
impl std::error::Error for RecordError {}

fn err<T>(msg: impl Into<String>) -> Result<T, RecordError> {
    Err(RecordError(msg.into()))
}

impl Record {
    /// A record with only `t, x, v`.
    pub fn new(t: Vec<f64>, x: Vec<f64>, v: Vec<f64>, rig: Option<Rig>, units: Units) -> Record {
        Record {
            t,
            x,
            v,
            ft: None,
            temp: None,
            ecr: None,
            rig,
            units,
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }
    /// True if there are no samples.
    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The rig constants, or an error telling how to give them.
    pub fn rig(&self) -> Result<Rig, RecordError> {
        match self.units {
            Units::Dimensionless => Ok(Rig::UNIT),
            Units::Si => self.rig.ok_or_else(|| {
                RecordError(
                    "record has no rig constants: add `# mass_kg=…`, `# stiffness_n_per_m=…`, \
                     `# load_n=…` comment lines or pass them on the command line"
                        .into(),
                )
            }),
        }
    }

    /// Mean sampling interval.
    pub fn dt(&self) -> f64 {
        if self.t.len() < 2 {
            0.0
        } else {
            (self.t[self.t.len() - 1] - self.t[0]) / (self.t.len() - 1) as f64
        }
    }

    /// Checks lengths, finiteness, increasing time, at least 8 samples, and the rig.
    pub fn validate(&self) -> Result<(), RecordError> {
        let n = self.t.len();
        if n < 8 {
            return err(format!("record too short: {n} samples (need at least 8)"));
        }
        let cols: [(&str, Option<&Vec<f64>>); 6] = [
            ("t", Some(&self.t)),
            ("x", Some(&self.x)),
            ("v", Some(&self.v)),
            ("ft", self.ft.as_ref()),
            ("temp", self.temp.as_ref()),
            ("ecr", self.ecr.as_ref()),
        ];
        for (name, c) in cols {
            if let Some(c) = c {
                if c.len() != n {
                    return err(format!("column {name} has {} samples, t has {n}", c.len()));
                }
                if let Some(i) = c.iter().position(|v| !v.is_finite()) {
                    return err(format!("column {name}: non-finite value at sample {i}"));
                }
            }
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return err(format!(
                "time is not strictly increasing at sample {}",
                i + 1
            ));
        }
        if let Some(r) = &self.rig {
            r.validate().map_err(RecordError)?;
        }
        Ok(())
    }

    /// Loads a record, dispatching on the path: a directory is a run recorded by `tribo`
    /// (extension point, not yet supported), anything else is parsed as CSV (SI or
    /// dimensionless, told apart by the header).
    pub fn load(path: &Path) -> Result<Record, RecordError> {
        if path.is_dir() {
            return err(format!(
                "{}: reading runs recorded by `tribo` is not supported yet; export it as CSV",
                path.display()
            ));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| RecordError(format!("{}: {e}", path.display())))?;
        Record::from_csv_str(&text).map_err(|e| RecordError(format!("{}: {}", path.display(), e.0)))
    }

    /// Parses CSV text (SI or dimensionless).
    pub fn from_csv_str(text: &str) -> Result<Record, RecordError> {
        let mut rig_vals: [Option<f64>; 3] = [None; 3];
        let mut header: Option<Vec<String>> = None;
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for (ln, line) in text.lines().enumerate() {
            let line = line.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                if let Some((k, v)) = c.split_once('=') {
                    let k = k.trim();
                    let idx = match k {
                        "mass_kg" => Some(0),
                        "stiffness_n_per_m" => Some(1),
                        "load_n" => Some(2),
                        _ => None,
                    };
                    if let Some(i) = idx {
                        let val: f64 = v.trim().parse().map_err(|_| {
                            RecordError(format!(
                                "line {}: bad value for {k}: {:?}",
                                ln + 1,
                                v.trim()
                            ))
                        })?;
                        rig_vals[i] = Some(val);
                    }
                }
                continue;
            }
            match &header {
                None => {
                    let h: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
                    cols = vec![Vec::new(); h.len()];
                    header = Some(h);
                }
                Some(h) => {
                    let fields: Vec<&str> = line.split(',').collect();
                    if fields.len() != h.len() {
                        return err(format!(
                            "line {}: {} fields, header has {} (truncated file?)",
                            ln + 1,
                            fields.len(),
                            h.len()
                        ));
                    }
                    for (i, f) in fields.iter().enumerate() {
                        let v: f64 = f.trim().parse().map_err(|_| {
                            RecordError(format!(
                                "line {}: column {}: not a number: {:?}",
                                ln + 1,
                                h[i],
                                f.trim()
                            ))
                        })?;
                        if !v.is_finite() {
                            return err(format!(
                                "line {}: column {}: non-finite value",
                                ln + 1,
                                h[i]
                            ));
                        }
                        cols[i].push(v);
                    }
                }
            }
        }
        let Some(h) = header else {
            return err("no header line (expected `t_s,x_m,v_m_s` or `tau,y,ydot`)");
        };
        let find = |name: &str| h.iter().position(|c| c == name);
        let take =
            |i: Option<usize>, cols: &mut Vec<Vec<f64>>| i.map(|i| std::mem::take(&mut cols[i]));
        let rec = if let (Some(it), Some(ix), Some(iv)) = (find("t_s"), find("x_m"), find("v_m_s"))
        {
            let rig =
                match rig_vals {
                    [Some(m), Some(k), Some(n)] => Some(Rig::new(m, k, n).map_err(RecordError)?),
                    [None, None, None] => None,
                    _ => return err(
                        "incomplete rig constants: need all of mass_kg, stiffness_n_per_m, load_n",
                    ),
                };
            let (ift, itemp, iecr) = (find("ft_n"), find("temp_c"), find("ecr_ohm"));
            Record {
                t: take(Some(it), &mut cols).unwrap_or_default(),
                x: take(Some(ix), &mut cols).unwrap_or_default(),
                v: take(Some(iv), &mut cols).unwrap_or_default(),
                ft: take(ift, &mut cols),
                temp: take(itemp, &mut cols),
                ecr: take(iecr, &mut cols),
                rig,
                units: Units::Si,
            }
        } else if let (Some(it), Some(iy), Some(iv)) = (find("tau"), find("y"), find("ydot")) {
            Record::new(
                take(Some(it), &mut cols).unwrap_or_default(),
                take(Some(iy), &mut cols).unwrap_or_default(),
                take(Some(iv), &mut cols).unwrap_or_default(),
                Some(Rig::UNIT),
                Units::Dimensionless,
            )
        } else {
            return err(format!(
                "unknown header {:?}: expected `t_s,x_m,v_m_s[,ft_n][,temp_c][,ecr_ohm]` or `tau,y,ydot`",
                h.join(",")
            ));
        };
        rec.validate()?;
        Ok(rec)
    }

    /// Writes CSV text (with rig comment lines for SI records).
    pub fn to_csv_string(&self) -> String {
        let mut s = String::with_capacity(self.len() * 60);
        match self.units {
            Units::Dimensionless => {
                s.push_str("tau,y,ydot\n");
                for i in 0..self.len() {
                    let _ = writeln!(s, "{:e},{:e},{:e}", self.t[i], self.x[i], self.v[i]);
                }
            }
            Units::Si => {
                if let Some(r) = &self.rig {
                    let _ = writeln!(s, "# mass_kg={}", r.mass_kg);
                    let _ = writeln!(s, "# stiffness_n_per_m={}", r.stiffness_n_per_m);
                    let _ = writeln!(s, "# load_n={}", r.load_n);
                }
                s.push_str("t_s,x_m,v_m_s");
                let extra: Vec<(&str, &Vec<f64>)> = [
                    ("ft_n", self.ft.as_ref()),
                    ("temp_c", self.temp.as_ref()),
                    ("ecr_ohm", self.ecr.as_ref()),
                ]
                .into_iter()
                .filter_map(|(n, c)| c.map(|c| (n, c)))
                .collect();
                for (n, _) in &extra {
                    s.push(',');
                    s.push_str(n);
                }
                s.push('\n');
                for i in 0..self.len() {
                    let _ = write!(s, "{:e},{:e},{:e}", self.t[i], self.x[i], self.v[i]);
                    for (_, c) in &extra {
                        let _ = write!(s, ",{:e}", c[i]);
                    }
                    s.push('\n');
                }
            }
        }
        s
    }

    /// Writes the record as CSV to `path`.
    pub fn save(&self, path: &Path) -> Result<(), RecordError> {
        std::fs::write(path, self.to_csv_string())
            .map_err(|e| RecordError(format!("{}: {e}", path.display())))
    }

    /// Dimensionless view `(τ, y, y')` using the record's rig.
    pub fn dimensionless(&self) -> Result<Columns, RecordError> {
        let rig = self.rig()?;
        Ok((
            self.t.iter().map(|&t| rig.tau_of_t(t)).collect(),
            self.x.iter().map(|&x| rig.y_of_x(x)).collect(),
            self.v.iter().map(|&v| rig.ydot_of_v(v)).collect(),
        ))
    }
}

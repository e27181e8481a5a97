//! Records: a sampled free response with its rig constants, and the CSV formats.
//!
//! - SI CSV: header `t_s,x_m,v_m_s` plus any of `ft_n`, `temp_c`, `ecr_ohm` (any order after the
//!   three required columns), rig constants in leading comment lines `# mass_kg=…`,
//!   `# stiffness_n_per_m=…`, `# load_n=…`.
//! - Dimensionless CSV: header `tau,y,ydot` (the rig is [`Rig::UNIT`]).
//! - Header keys (`# key=value`, each at most once): `mass_kg`, `stiffness_n_per_m`, `load_n` (all
//!   three or none), `force_cutoff_hz` (the force channel's low-pass, when it has one) and
//!   `force_zero_n` (what the force channel reads at zero tangential force, when the rig zeroed it).
//! - Runs recorded by `tribo` are folders, read by the `tribo` crate; [`Record::load`] refuses them
//!   with a clear error.

use crate::invalid::InvalidParameter;
use crate::model::Rig;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

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
    /// Low-pass cut-off of the force channel (the charge amplifier's, Hz), when the record says
    /// (`# force_cutoff_hz=300`); `None` = not stated.
    pub force_cutoff_hz: Option<f64>,
    /// What the force channel reads at zero tangential force (N), when the record says
    /// (`# force_zero_n=0`, the channel zeroed with the contact unloaded); `None` = not stated.
    /// Without it a constant force offset cannot be told from a direction asymmetry of μ0.
    pub force_zero_n: Option<f64>,
    /// The apparatus alone (`# load_n=0`: no contact, a calibration run). Its friction
    /// coefficients are undefined; only the blades' own damping μ_a means something. `rig.load_n`
    /// then holds a token load ([`Record::apparatus_token_load`]) so that the dimensionless form
    /// exists: a viscous law's μ1 does not depend on it.
    pub apparatus: bool,
    /// Rig constants a file gave when it did not give all three (`mass_kg`, `stiffness_n_per_m`,
    /// `load_n`, in that order): `rig` is then `None`, and the command line completes them.
    pub rig_partial: [Option<f64>; 3],
}

/// What kind of problem a [`RecordError`] is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum RecordErrorKind {
    /// The file could not be read.
    Io,
    /// The text is not a record (encoding, header, a field that is not a number, a repeated key…).
    Syntax,
    /// A sample is NaN or infinite: the record is readable but cannot be analysed.
    NonFinite,
    /// The values are inconsistent (lengths, time not increasing, rig constants out of range).
    Invalid,
}

/// Why a record cannot be read, written or analysed. The message says what and where (line and
/// column for parse errors); [`RecordError::In`] adds the file, with the error as its source.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be read or written.
    #[error("cannot {verb} {}", path.display())]
    Io {
        /// `read` or `write`.
        verb: &'static str,
        /// The file.
        path: PathBuf,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
    /// The text is not a record (encoding, header, a field that is not a number, a repeated key…).
    #[error("line {line}, column {col}: {what}")]
    Syntax {
        /// Line, from 1.
        line: usize,
        /// Column, from 1.
        col: usize,
        /// What is wrong there.
        what: String,
    },
    /// A sample is NaN or infinite: the record is readable but cannot be analysed.
    #[error("{what}")]
    NonFinite {
        /// Which sample of which channel.
        what: String,
    },
    /// The values are inconsistent (lengths, time not increasing, a setting out of range).
    #[error("{0}")]
    Invalid(String),
    /// The rig constants the record gives are out of range.
    #[error(transparent)]
    Rig(InvalidParameter),
    /// An error in the record `path`.
    #[error("cannot use the record {}", path.display())]
    In {
        /// The record's file.
        path: PathBuf,
        /// What is wrong in it.
        #[source]
        source: Box<RecordError>,
    },
}

impl RecordError {
    /// An [`RecordError::Invalid`] error.
    pub fn invalid(msg: impl Into<String>) -> RecordError {
        RecordError::Invalid(msg.into())
    }
    /// The error, said to be in the record `path`.
    pub fn in_file(self, path: &Path) -> RecordError {
        RecordError::In {
            path: path.to_path_buf(),
            source: Box::new(self),
        }
    }
    /// The kind (of the innermost error, for one in a file).
    pub fn kind(&self) -> RecordErrorKind {
        match self {
            RecordError::Io { .. } => RecordErrorKind::Io,
            RecordError::Syntax { .. } => RecordErrorKind::Syntax,
            RecordError::NonFinite { .. } => RecordErrorKind::NonFinite,
            RecordError::Invalid(_) | RecordError::Rig(_) => RecordErrorKind::Invalid,
            RecordError::In { source, .. } => source.kind(),
        }
    }
}

fn err<T>(msg: impl Into<String>) -> Result<T, RecordError> {
    Err(RecordError::invalid(msg))
}

/// A parse error at a line and column (both from 1; the column counts characters).
fn at<T>(line: usize, col: usize, msg: impl std::fmt::Display) -> Result<T, RecordError> {
    Err(RecordError::Syntax {
        line,
        col,
        what: msg.to_string(),
    })
}

/// Byte offset in `text` just past the line `raw` (a line of `text.lines()`) and its line ending.
fn line_end(text: &str, raw: &str) -> usize {
    let end = (raw.as_ptr() as usize - text.as_ptr() as usize) + raw.len();
    text.as_bytes()[end..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(text.len(), |i| end + i + 1)
}

/// Rows of at least this many bytes are parsed on two threads.
const PLAIN_ROWS_SPLIT: usize = 1 << 20;

/// The columns of CSV rows that are all *plain*: `n` non-empty fields of the characters of a
/// decimal number (`0-9 . e E + -`) parsing to finite values, between commas, lines ended by
/// `\n` or `\r\n`, empty lines skipped. Each field is parsed as [`Record::from_csv_str`] parses
/// it (`str::parse::<f64>`, the field having nothing to trim), so the numbers are the same bits.
/// `None` for anything else (a comment, a space, an empty ECR field, a bad or non-finite number, a
/// short row): then the general parser reads them and says what is wrong where. A long text is
/// split at a line ending and its halves parsed on two threads (one when the caller fits on one).
fn plain_rows(text: &str, n: usize) -> Option<Vec<Vec<f64>>> {
    let threads = crate::identify::fit_threads();
    if threads < 2 || text.len() < PLAIN_ROWS_SPLIT {
        return plain_rows_serial(text, n, text.len()).map(trimmed);
    }
    let mid = text.len() / 2;
    let cut = text.as_bytes()[mid..]
        .iter()
        .position(|&b| b == b'\n')
        .map_or(text.len(), |i| mid + i + 1);
    let (a, b) = text.split_at(cut);
    let (first, second) = std::thread::scope(|s| {
        let h = s.spawn(|| plain_rows_serial(b, n, b.len()));
        let first = plain_rows_serial(a, n, text.len());
        (first, h.join().ok().flatten())
    });
    let mut cols = first?;
    for (c, d) in cols.iter_mut().zip(second?) {
        c.extend_from_slice(&d);
    }
    Some(trimmed(cols))
}

/// Columns without their spare capacity.
fn trimmed(mut cols: Vec<Vec<f64>>) -> Vec<Vec<f64>> {
    for c in &mut cols {
        c.shrink_to_fit();
    }
    cols
}

/// [`plain_rows`] on one thread; `room`: bytes of rows the columns are sized for.
fn plain_rows_serial(text: &str, n: usize, room: usize) -> Option<Vec<Vec<f64>>> {
    // Sized from the first lines' length (a little over: the columns are trimmed at the end).
    let sample = &text.as_bytes()[..text.len().min(4096)];
    let lines = sample.iter().filter(|&&b| b == b'\n').count().max(1);
    let cap = room / (sample.len() / lines).max(1) * 9 / 8 + 16;
    let mut cols: Vec<Vec<f64>> = (0..n).map(|_| Vec::with_capacity(cap)).collect();
    let bytes = text.as_bytes();
    // One pass: `field` is where the current field starts, `k` how many of the line's fields are
    // read; a line ends at `\n` or `\r\n` (or the end of the text).
    let (mut field, mut k) = (0, 0);
    let mut i = 0;
    while i <= bytes.len() {
        let b = bytes.get(i).copied().unwrap_or(b'\n');
        match b {
            b'0'..=b'9' | b'.' | b'e' | b'E' | b'+' | b'-' => {
                i += 1;
                continue;
            }
            b',' | b'\n' => {}
            b'\r' if bytes.get(i + 1).is_none_or(|&c| c == b'\n') => {}
            _ => return None,
        }
        let end_of_line = b != b',';
        if !(end_of_line && k == 0 && i == field) {
            // Not an empty line: a field ends here.
            if i == field || k == n {
                return None;
            }
            let v: f64 = text[field..i].parse().ok()?;
            if !v.is_finite() {
                return None;
            }
            cols[k].push(v);
            k += 1;
            if end_of_line {
                if k != n {
                    return None;
                }
                k = 0;
            }
        }
        i += if b == b'\r' { 2 } else { 1 };
        field = i;
    }
    Some(cols)
}

/// The header keys a record may give (`# key=value` comment lines).
pub const HEADER_KEYS: [&str; 5] = [
    "mass_kg",
    "stiffness_n_per_m",
    "load_n",
    "force_cutoff_hz",
    "force_zero_n",
];

/// Line and column (from 1, columns in characters) of byte `offset` of `text`.
fn line_col(text: &[u8], offset: usize) -> (usize, usize) {
    let before = &text[..offset.min(text.len())];
    let line = before.iter().filter(|&&b| b == b'\n').count() + 1;
    let start = before
        .iter()
        .rposition(|&b| b == b'\n')
        .map_or(0, |i| i + 1);
    let col = String::from_utf8_lossy(&before[start..]).chars().count() + 1;
    (line, col)
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
            force_cutoff_hz: None,
            force_zero_n: None,
            apparatus: false,
            rig_partial: [None; 3],
        }
    }

    /// The token load of an apparatus record (`k · A`, A the largest |x|: y then spans about ±1).
    pub fn apparatus_token_load(stiffness_n_per_m: f64, x: &[f64]) -> f64 {
        let a = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        (stiffness_n_per_m * a).max(1e-12)
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
                let missing: Vec<&str> = ["mass_kg", "stiffness_n_per_m", "load_n"]
                    .iter()
                    .zip(self.rig_partial)
                    .filter(|(_, v)| v.is_none())
                    .map(|(k, _)| *k)
                    .collect();
                if missing.len() < 3 {
                    RecordError::invalid(format!(
                        "incomplete rig constants: {} missing (add `# {}=…` to the record, or pass \
                         it on the command line)",
                        missing.join(", "),
                        missing[0]
                    ))
                } else {
                    RecordError::invalid(
                        "record has no rig constants: add `# mass_kg=…`, `# stiffness_n_per_m=…`, \
                         `# load_n=…` comment lines or pass them on the command line",
                    )
                }
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

    /// The channels present, by name, with their samples.
    pub fn channels(&self) -> Vec<(&'static str, &[f64])> {
        let mut v: Vec<(&'static str, &[f64])> =
            vec![("t", &self.t), ("x", &self.x), ("v", &self.v)];
        for (name, c) in [("ft", &self.ft), ("temp", &self.temp), ("ecr", &self.ecr)] {
            if let Some(c) = c {
                v.push((name, c));
            }
        }
        v
    }

    /// Checks lengths, finiteness, increasing time, at least 8 samples, and the rig. A non-finite
    /// sample is a [`RecordErrorKind::NonFinite`] error.
    pub fn validate(&self) -> Result<(), RecordError> {
        let n = self.t.len();
        if n < 8 {
            return err(format!("record too short: {n} samples (need at least 8)"));
        }
        for (name, c) in self.channels() {
            if c.len() != n {
                return err(format!("column {name} has {} samples, t has {n}", c.len()));
            }
        }
        for (name, c) in self.channels() {
            if let Some(i) = c.iter().position(|v| !v.is_finite()) {
                return Err(RecordError::NonFinite {
                    what: format!("column {name}: non-finite value {} at sample {i}", c[i]),
                });
            }
        }
        if let Some(i) = self.t.windows(2).position(|w| w[1] <= w[0]) {
            return err(format!(
                "time is not strictly increasing at sample {}",
                i + 1
            ));
        }
        if let Some(r) = &self.rig {
            r.validate().map_err(RecordError::Rig)?;
        }
        if let Some(fc) = self.force_cutoff_hz {
            if !(fc.is_finite() && fc > 0.0) {
                return err(format!("force_cutoff_hz must be > 0, got {fc}"));
            }
        }
        if let Some(z) = self.force_zero_n {
            if !z.is_finite() {
                return err(format!("force_zero_n must be finite, got {z}"));
            }
        }
        Ok(())
    }

    /// Loads a record, dispatching on the path: a directory is a run recorded by `tribo`
    /// (read by the `tribo` crate, not here), anything else is parsed as CSV (SI or
    /// dimensionless, told apart by the header). Errors name the file (and the line and column
    /// of a parse error).
    pub fn load(path: &Path) -> Result<Record, RecordError> {
        if path.is_dir() {
            return err(format!(
                "{}: reading runs recorded by `tribo` is not supported here; export it as CSV",
                path.display()
            ));
        }
        let bytes = std::fs::read(path).map_err(|source| RecordError::Io {
            verb: "read",
            path: path.to_path_buf(),
            source,
        })?;
        Record::from_csv_bytes(&bytes).map_err(|e| e.in_file(path))
    }

    /// Parses CSV bytes: UTF-8 (a leading byte-order mark is skipped); a byte that is not UTF-8
    /// is an error at its line and column.
    pub fn from_csv_bytes(bytes: &[u8]) -> Result<Record, RecordError> {
        match std::str::from_utf8(bytes) {
            Ok(text) => Record::from_csv_str(text),
            Err(e) => {
                let (line, col) = line_col(bytes, e.valid_up_to());
                at(
                    line,
                    col,
                    format!(
                        "not UTF-8 text (byte 0x{:02x}); save the file as UTF-8",
                        bytes[e.valid_up_to()]
                    ),
                )
            }
        }
    }

    /// Parses CSV text (SI or dimensionless). A leading byte-order mark is skipped. An empty
    /// `ecr_ohm` field is a sample without an ECR reading: for analysis it takes the nearest
    /// reading ([`fill_missing`], as a stored run's record does), a column without any is dropped. Strict: every
    /// field must be a number, every row as long as the header, a header key (`# key=value`)
    /// and a column name may appear once; errors give the line and column. Values that parse but
    /// are not finite (`inf`, `NaN`, `1e999`) are [`RecordErrorKind::NonFinite`] errors.
    pub fn from_csv_str(text: &str) -> Result<Record, RecordError> {
        let text = text.strip_prefix('\u{feff}').unwrap_or(text);
        let mut rig_vals: [Option<f64>; 3] = [None; 3];
        let mut force_cutoff_hz: Option<f64> = None;
        let mut force_zero_n: Option<f64> = None;
        // Every `# key=value` seen: key → line.
        let mut keys: Vec<(String, usize)> = Vec::new();
        let mut header: Option<(Vec<String>, usize)> = None;
        let mut cols: Vec<Vec<f64>> = Vec::new();
        for (ln, raw) in text.lines().enumerate() {
            let line_no = ln + 1;
            let indent = raw.chars().take_while(|c| c.is_whitespace()).count();
            let line = raw.trim();
            if line.is_empty() {
                continue;
            }
            if let Some(c) = line.strip_prefix('#') {
                let Some((k, v)) = c.split_once('=') else {
                    continue;
                };
                let key = k.trim();
                let is_key = !key.is_empty()
                    && key
                        .chars()
                        .all(|ch| ch.is_ascii_alphanumeric() || ch == '_')
                    && !key.starts_with(|ch: char| ch.is_ascii_digit());
                if !is_key {
                    continue; // free text that happens to contain '='
                }
                let key_col = indent + 1 + c.find(key).unwrap_or(0) + 1;
                if let Some((_, first)) = keys.iter().find(|(k, _)| k == key) {
                    return at(
                        line_no,
                        key_col,
                        format!("header key {key} given again (first on line {first}); keep one"),
                    );
                }
                keys.push((key.to_string(), line_no));
                let slot = match key {
                    "mass_kg" => Some(0),
                    "stiffness_n_per_m" => Some(1),
                    "load_n" => Some(2),
                    "force_cutoff_hz" => Some(3),
                    "force_zero_n" => Some(4),
                    _ => None,
                };
                if let Some(i) = slot {
                    let val_col = indent + 1 + c.find('=').unwrap_or(0) + 2;
                    let val: f64 = v.trim().parse().or_else(|_| {
                        at(
                            line_no,
                            val_col,
                            format!("bad value for {key}: {:?} (a number)", v.trim()),
                        )
                    })?;
                    match i {
                        0..=2 => rig_vals[i] = Some(val),
                        3 => force_cutoff_hz = Some(val),
                        _ => force_zero_n = Some(val),
                    }
                }
                continue;
            }
            match &header {
                None => {
                    let h: Vec<String> = line.split(',').map(|s| s.trim().to_string()).collect();
                    let mut col = indent + 1;
                    for (i, name) in h.iter().enumerate() {
                        if let Some(j) = h[..i].iter().position(|n| n == name) {
                            return at(
                                line_no,
                                col,
                                format!(
                                    "column {name:?} appears twice (columns {} and {})",
                                    j + 1,
                                    i + 1
                                ),
                            );
                        }
                        col += line.split(',').nth(i).map_or(0, |f| f.chars().count()) + 1;
                    }
                    cols = vec![Vec::new(); h.len()];
                    // The rows after the header, when every one of them is plain (see
                    // [`plain_rows`]): the same numbers as the loop below gives, line by line.
                    let after = line_end(text, raw);
                    let plain = plain_rows(&text[after..], h.len());
                    header = Some((h, line_no));
                    if let Some(c) = plain {
                        cols = c;
                        break;
                    }
                }
                Some((h, _)) => {
                    let fields: Vec<&str> = line.split(',').collect();
                    if fields.len() != h.len() {
                        return at(
                            line_no,
                            line.chars().count() + indent + 1,
                            format!(
                                "{} fields, the header has {} (truncated file?)",
                                fields.len(),
                                h.len()
                            ),
                        );
                    }
                    let mut col = indent + 1;
                    for (i, f) in fields.iter().enumerate() {
                        let fcol = col + f.chars().take_while(|c| c.is_whitespace()).count();
                        // An empty ECR field: the rig had no reading for that sample.
                        if f.trim().is_empty() && h[i] == "ecr_ohm" {
                            cols[i].push(f64::NAN);
                            col += f.chars().count() + 1;
                            continue;
                        }
                        let v: f64 = f.trim().parse().or_else(|_| {
                            at(
                                line_no,
                                fcol,
                                format!("column {}: not a number: {:?}", h[i], f.trim()),
                            )
                        })?;
                        if !v.is_finite() {
                            return Err(RecordError::NonFinite {
                                what: format!(
                                    "line {line_no}, column {fcol}: column {}: non-finite value {:?}",
                                    h[i],
                                    f.trim()
                                ),
                            });
                        }
                        cols[i].push(v);
                        col += f.chars().count() + 1;
                    }
                }
            }
        }
        let Some((h, header_line)) = header else {
            return at(
                text.lines().count().max(1),
                1,
                "no header line (expected `t_s,x_m,v_m_s` or `tau,y,ydot`)",
            );
        };
        let find = |name: &str| h.iter().position(|c| c == name);
        let take =
            |i: Option<usize>, cols: &mut Vec<Vec<f64>>| i.map(|i| std::mem::take(&mut cols[i]));
        let rec = if let (Some(it), Some(ix), Some(iv)) = (find("t_s"), find("x_m"), find("v_m_s"))
        {
            let apparatus = matches!(rig_vals, [Some(_), Some(_), Some(n)] if n == 0.0);
            let rig = match rig_vals {
                [Some(m), Some(k), Some(_)] if apparatus => {
                    let xs = find("x_m").map(|i| cols[i].as_slice()).unwrap_or(&[]);
                    let token = Record::apparatus_token_load(k, xs);
                    Some(Rig::new(m, k, token).map_err(RecordError::Rig)?)
                }
                [Some(m), Some(k), Some(n)] => Some(Rig::new(m, k, n).map_err(RecordError::Rig)?),
                // Some given, some not: kept for the command line to complete
                // (`rig_partial`); without it, `Record::rig` says which are missing.
                _ => None,
            };
            let (ift, itemp, iecr) = (find("ft_n"), find("temp_c"), find("ecr_ohm"));
            Record {
                t: take(Some(it), &mut cols).unwrap_or_default(),
                x: take(Some(ix), &mut cols).unwrap_or_default(),
                v: take(Some(iv), &mut cols).unwrap_or_default(),
                ft: take(ift, &mut cols),
                temp: take(itemp, &mut cols),
                ecr: take(iecr, &mut cols).and_then(|mut e| fill_missing(&mut e).then_some(e)),
                rig,
                units: Units::Si,
                force_cutoff_hz,
                force_zero_n,
                apparatus,
                rig_partial: if rig.is_none() { rig_vals } else { [None; 3] },
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
            return at(
                header_line,
                1,
                format!(
                    "unknown header {:?}: expected `t_s,x_m,v_m_s[,ft_n][,temp_c][,ecr_ohm]` or `tau,y,ydot`",
                    h.join(",")
                ),
            );
        };
        rec.validate()?;
        Ok(rec)
    }

    /// Writes CSV text (with rig comment lines for SI records). An ECR value that is not finite
    /// (the rig had no reading for that sample) is written as an empty field; [`Record::from_csv_str`]
    /// reads it back as missing.
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
                    let load = if self.apparatus { 0.0 } else { r.load_n };
                    let _ = writeln!(s, "# load_n={load}");
                }
                if let (Some(fc), Some(_)) = (self.force_cutoff_hz, &self.ft) {
                    let _ = writeln!(s, "# force_cutoff_hz={fc}");
                }
                if let (Some(z), Some(_)) = (self.force_zero_n, &self.ft) {
                    let _ = writeln!(s, "# force_zero_n={z}");
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
                    for (name, c) in &extra {
                        if *name == "ecr_ohm" && !c[i].is_finite() {
                            // Not measured: left empty, never a number the rig did not give.
                            s.push(',');
                        } else {
                            let _ = write!(s, ",{:e}", c[i]);
                        }
                    }
                    s.push('\n');
                }
            }
        }
        s
    }

    /// Writes the record as CSV to `path`.
    pub fn save(&self, path: &Path) -> Result<(), RecordError> {
        std::fs::write(path, self.to_csv_string()).map_err(|source| RecordError::Io {
            verb: "write",
            path: path.to_path_buf(),
            source,
        })
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

/// Replaces non-finite values (samples without a reading) by the previous finite one, the first
/// finite one for those before it: how a record's ECR column is completed for analysis (a stored
/// run's and a CSV's alike; the exports keep them empty). `false` when there is no finite value.
pub fn fill_missing(v: &mut [f64]) -> bool {
    let Some(first) = v.iter().copied().find(|x| x.is_finite()) else {
        return false;
    };
    let mut last = first;
    for x in v.iter_mut() {
        if x.is_finite() {
            last = *x;
        } else {
            *x = last;
        }
    }
    true
}

#[cfg(test)]
mod force_zero_tests {
    use super::*;

    #[test]
    fn the_force_zero_is_read_written_and_checked() {
        let mut text = String::from(
            "# mass_kg=0.04\n# stiffness_n_per_m=1150\n# load_n=0.3\n# force_zero_n=-0.0012\n\
             t_s,x_m,v_m_s,ft_n\n",
        );
        for i in 0..16 {
            let t = i as f64 * 1e-3;
            let (x, v) = (1e-4 * (170.0 * t).cos(), -0.017 * (170.0 * t).sin());
            text.push_str(&format!("{t},{x},{v},0.006\n"));
        }
        let text = text.as_str();
        let r = Record::from_csv_str(text).unwrap();
        assert_eq!(r.force_zero_n, Some(-0.0012));
        let back = Record::from_csv_str(&r.to_csv_string()).unwrap();
        assert_eq!(back.force_zero_n, Some(-0.0012));
        // Not stated: None; a bad value: an error at its line.
        let r = Record::from_csv_str(&text.replace("# force_zero_n=-0.0012\n", "")).unwrap();
        assert_eq!(r.force_zero_n, None);
        let e = Record::from_csv_str(&text.replace("-0.0012", "zero")).unwrap_err();
        assert!(e.to_string().contains("force_zero_n"), "{e}");
        let e = Record::from_csv_str(&text.replace("-0.0012", "inf")).unwrap_err();
        assert!(e.to_string().contains("force_zero_n"), "{e}");
    }
}

#[cfg(test)]
mod plain_rows_tests {
    use super::*;

    /// A CSV of `rows` rows whose numbers take every form a plain field may have (exponents of
    /// either case and sign, leading `+`, `.5`, `5.`, 17 digits, negative zero), lines ended by
    /// `eol`, with empty lines among them.
    fn csv(rows: usize, eol: &str) -> String {
        let mut s = format!("# mass_kg=0.04{eol}# stiffness_n_per_m=1150{eol}# load_n=0.3{eol}");
        s.push_str(&format!("t_s,x_m,v_m_s,ft_n{eol}"));
        let mut z: u64 = 0x9e37_79b9_7f4a_7c15;
        for i in 0..rows {
            z = z
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            let u = (z >> 11) as f64 / (1u64 << 53) as f64;
            let t = i as f64 * 1e-4;
            let x = 6.67e-4 * (170.0 * t).cos() + 1e-7 * (u - 0.5);
            let v = -0.11 * (170.0 * t).sin() * (1.0 + 1e-3 * u);
            let f = match i % 7 {
                0 => format!("{:E}", -4e-5 * u),
                1 => format!("+{}", 0.5 * u),
                2 => ".5".to_string(),
                3 => "5.".to_string(),
                4 => "-0".to_string(),
                5 => format!("{:.16e}", u * 1e-300),
                _ => format!("{}e+2", u),
            };
            s.push_str(&format!("{t:e},{x:e},{v},{f}{eol}"));
            if i % 5000 == 17 {
                s.push_str(eol);
            }
        }
        s
    }

    fn bits(r: &Record) -> Vec<Vec<u64>> {
        [Some(&r.t), Some(&r.x), Some(&r.v), r.ft.as_ref()]
            .into_iter()
            .flatten()
            .map(|c| c.iter().map(|v| v.to_bits()).collect())
            .collect()
    }

    #[test]
    fn plain_rows_are_the_general_parsers_numbers() {
        // 60,000 rows (about 3.5 MB): parsed as two halves on two threads.
        for eol in ["\n", "\r\n"] {
            let text = csv(60_000, eol);
            assert!(text.len() > 2 * PLAIN_ROWS_SPLIT);
            let fast = Record::from_csv_str(&text).unwrap();
            // A comment after the rows is not plain: the general parser reads every row.
            let general = Record::from_csv_str(&format!("{text}# end{eol}")).unwrap();
            assert_eq!(fast.len(), 60_000);
            assert_eq!(bits(&fast), bits(&general));
            // Plain rows on one thread: the same numbers.
            let one = std::thread::spawn(move || {
                crate::identify::set_fit_threads(1);
                Record::from_csv_str(&text).unwrap()
            })
            .join()
            .unwrap();
            assert_eq!(bits(&one), bits(&general));
        }
    }

    #[test]
    fn a_bad_row_in_either_half_is_the_general_parsers_error() {
        let text = csv(60_000, "\n");
        let lines: Vec<&str> = text.lines().collect();
        let spaced = lines[30_000].replacen(',', ", ", 1);
        for (at, bad, what) in [
            (10usize, "1e-4,2e-4,inf,0", "non-finite"),
            (50_000, "1e-4,2e-4,3e-4", "3 fields, the header has 4"),
            (50_000, "1e-4,2e-4,1.2.3,0", "not a number"),
            (30_000, spaced.as_str(), "trimmed"),
        ] {
            let mut l = lines.clone();
            l[at] = bad;
            let e = Record::from_csv_str(&l.join("\n")).map(|r| bits(&r));
            if what == "trimmed" {
                // A space is not plain, but the general parser trims it: read, not refused.
                assert_eq!(e.unwrap(), bits(&Record::from_csv_str(&text).unwrap()));
                continue;
            }
            let e = e.unwrap_err().to_string();
            assert!(e.contains(what), "{e}");
            assert!(e.contains(&format!("line {}", at + 1)), "{e}");
        }
    }
}

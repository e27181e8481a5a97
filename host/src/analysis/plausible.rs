//! The checks between opening a record and analysing it: a sample that is not finite, a run
//! folder that is not whole, rig constants (from the record's header or from flags) outside what
//! the rig can have, a motion beyond what its channels measure, an apparatus damping blades
//! cannot have. Each refusal is an [`AnalysisError`] naming the likely mistake; `cmd::exit` maps
//! it to a status.

use super::AnalysisError;
use crate::load::{open, Holes, LoadError, Opened};
use serde::Serialize;
use std::path::Path;
use tribo_physics::record::Units;
use tribo_physics::{Record, Rig};

/// A record with a non-finite sample is read but cannot be analysed:
/// [`AnalysisError::NonFinite`], not the loader's error.
fn analysable<T>(r: Result<T, LoadError>) -> Result<T, AnalysisError> {
    r.map_err(|e| {
        if e.is_non_finite() {
            AnalysisError::NonFinite(e)
        } else {
            AnalysisError::Load(e)
        }
    })
}

/// [`crate::load::load_record`] for the analysis commands: a non-finite sample is
/// [`AnalysisError::NonFinite`]; a run folder that is not whole is refused
/// ([`LoadError::Incomplete`]); so is a record not plausible as written ([`plausible_record`]),
/// under its path.
pub fn load_for_analysis(path: &Path) -> Result<Record, AnalysisError> {
    let o = open_analysable(path, Holes::Whole)?;
    plausible_record(&o.record).map_err(|e| e.of(path.display().to_string()))?;
    Ok(o.record)
}

/// [`crate::load::load_for_fit`] for the analysis commands (a non-finite sample is
/// [`AnalysisError::NonFinite`]).
pub fn load_analysable_for_fit(path: &Path, holes: Holes) -> Result<Record, AnalysisError> {
    open_analysable(path, holes).map(|o| o.record)
}

/// [`open`] for the analysis commands: a record with a non-finite sample is read but cannot be
/// analysed ([`AnalysisError::NonFinite`]).
pub fn open_analysable(path: &Path, holes: Holes) -> Result<Opened, AnalysisError> {
    analysable(open(path, holes))
}

/// Where a rig constant of a result came from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Source {
    /// The record's header (or the run's metadata).
    Record,
    /// A command-line flag.
    Flag,
    /// Neither: the real rig's value stood in ([`Rig::REAL`]).
    Default,
    /// A dimensionless record needs none.
    Dimensionless,
}

/// The rig constants a result used, and where each came from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct RigUsed {
    /// Moving mass m (kg).
    pub mass_kg: f64,
    /// Blade stiffness k (N/m).
    pub stiffness_n_per_m: f64,
    /// Normal load N (N).
    pub load_n: f64,
    /// Where the mass came from.
    pub mass_kg_from: Source,
    /// Where the stiffness came from.
    pub stiffness_n_per_m_from: Source,
    /// Where the load came from.
    pub load_n_from: Source,
}

impl RigUsed {
    /// Names of the constants a default stood in for.
    pub fn defaults(&self) -> Vec<&'static str> {
        [
            ("mass_kg", self.mass_kg_from),
            ("stiffness_n_per_m", self.stiffness_n_per_m_from),
            ("load_n", self.load_n_from),
        ]
        .into_iter()
        .filter(|(_, s)| *s == Source::Default)
        .map(|(n, _)| n)
        .collect()
    }

    /// One line for the terminal: `m = 0.04 kg, k = 1150 N/m, N = 0.3 N (from the record)`, with
    /// the defaults named.
    pub fn describe(&self) -> String {
        if self.mass_kg_from == Source::Dimensionless {
            return "dimensionless record (τ, y, y′): no rig constants needed".into();
        }
        let tag = |s: Source| match s {
            Source::Record => "",
            Source::Flag => " [flag]",
            Source::Default => " [DEFAULT]",
            Source::Dimensionless => "",
        };
        let mut s = format!(
            "m = {} kg{}, k = {} N/m{}, N = {} N{}",
            self.mass_kg,
            tag(self.mass_kg_from),
            self.stiffness_n_per_m,
            tag(self.stiffness_n_per_m_from),
            self.load_n,
            tag(self.load_n_from)
        );
        let d = self.defaults();
        if !d.is_empty() {
            s.push_str(&format!(
                " — the real rig's default stood in for {} (neither the record's source nor a flag gave it)",
                d.join(", ")
            ));
        }
        s
    }
}

/// Rig constants given on the command line (`--mass-kg`, `--stiffness`, `--load-n`).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct RigFlags {
    /// `--mass-kg`: the moving mass (kg).
    pub mass_kg: Option<f64>,
    /// `--stiffness`: the blades' stiffness (N/m).
    pub stiffness_n_per_m: Option<f64>,
    /// `--load-n`: the normal load (N).
    pub load_n: Option<f64>,
}

impl RigFlags {
    fn any(&self) -> bool {
        self.mass_kg.is_some() || self.stiffness_n_per_m.is_some() || self.load_n.is_some()
    }
}

/// Applies the flags to the record's rig constants: a flag overrides the record; a constant that
/// neither gives takes the real rig's value ([`Rig::REAL`]) when at least one flag was given, and
/// the result records that it did (as it does for the constants in `recorded_defaults`, those a run
/// was taken with by default, the run's `defaults`). A record with no constants and no flag is an
/// error that says which flags to pass.
pub fn apply_rig_flags(
    rec: &mut Record,
    flags: RigFlags,
    recorded_defaults: &[String],
) -> Result<RigUsed, AnalysisError> {
    if rec.units == Units::Dimensionless {
        if flags.any() {
            return Err(AnalysisError::Request(
                "the record is dimensionless (tau,y,ydot): --mass-kg, --stiffness and --load-n do not apply"
                    .into(),
            ));
        }
        return Ok(RigUsed {
            mass_kg: 1.0,
            stiffness_n_per_m: 1.0,
            load_n: 1.0,
            mass_kg_from: Source::Dimensionless,
            stiffness_n_per_m_from: Source::Dimensionless,
            load_n_from: Source::Dimensionless,
        });
    }
    let was_default = |name: &str| {
        recorded_defaults
            .iter()
            .any(|d| d == name || d.starts_with(&format!("{name}=")))
    };
    let pick = |flag: Option<f64>, rec: Option<f64>, default: f64, name: &str| match (flag, rec) {
        (Some(v), _) => (v, Source::Flag),
        (None, Some(v)) if was_default(name) => (v, Source::Default),
        (None, Some(v)) => (v, Source::Record),
        (None, None) => (default, Source::Default),
    };
    // What the file gave: all three, or some (the flags complete them).
    let given: [Option<f64>; 3] = match rec.rig {
        Some(r) => [Some(r.mass_kg), Some(r.stiffness_n_per_m), Some(r.load_n)],
        None => rec.rig_partial,
    };
    if rec.rig.is_none() && !flags.any() {
        let missing: Vec<&str> = ["--mass-kg", "--stiffness", "--load-n"]
            .iter()
            .zip(given)
            .filter(|(_, v)| v.is_none())
            .map(|(f, _)| *f)
            .collect();
        return Err(AnalysisError::Request(format!(
            "the record's rig constants are incomplete or absent: add `# mass_kg=…`, \
             `# stiffness_n_per_m=…`, `# load_n=…` lines to it, or pass {}",
            missing.join(", ")
        )));
    }
    let (m, mf) = pick(flags.mass_kg, given[0], Rig::REAL.mass_kg, "mass_kg");
    let (k, kf) = pick(
        flags.stiffness_n_per_m,
        given[1],
        Rig::REAL.stiffness_n_per_m,
        "stiffness_n_per_m",
    );
    let (n, nf) = pick(flags.load_n, given[2], Rig::REAL.load_n, "load_n");
    plausible_constants(rec, [(m, mf), (k, kf), (n, nf)])?;
    plausible_motion(rec)?;
    rec.rig = Some(Rig::new(m, k, n)?);
    Ok(RigUsed {
        mass_kg: m,
        stiffness_n_per_m: k,
        load_n: n,
        mass_kg_from: mf,
        stiffness_n_per_m_from: kf,
        load_n_from: nf,
    })
}

/// A limit of `tribo_wire::limits` (an `f32`) as the number a person wrote: 0.7, not
/// 0.699999988079071.
fn shown(x: f32) -> f64 {
    x.to_string().parse().unwrap_or(x as f64)
}

/// `v` to four significant digits, as a person reads it (`0.667`, `1.2e-5`).
fn sig4(v: f64) -> String {
    if v == 0.0 || !v.is_finite() {
        return format!("{v}");
    }
    let mag = v.abs().log10().floor() as i32;
    if (-3..5).contains(&mag) {
        let digits = (3 - mag).max(0) as usize;
        let t = format!("{v:.digits$}");
        if t.contains('.') {
            t.trim_end_matches('0').trim_end_matches('.').to_string()
        } else {
            t
        }
    } else {
        format!("{v:.3e}")
    }
}

/// A value out of the rig's range, and the unit mistake that would explain it: the value read
/// in a unit 1000 or 10⁶ times too small (millimetres as metres, mN as N, grams as kg), when that
/// brings it into the range.
fn unit_hint(v: f64, lo: f64, hi: f64, si: &str, units: [(&str, f64); 2]) -> String {
    for (unit, f) in units {
        let w = v / f;
        if !(lo..=hi).contains(&v) && (lo..=hi).contains(&w) && w > 0.0 {
            return format!(
                " — a value in {unit}? ({} {unit} is {} {si})",
                sig4(v),
                sig4(w)
            );
        }
    }
    String::new()
}

/// The rig's constants against the rig's ranges (`tribo_wire::limits`: the mass, blade stiffness
/// and micrometric knob the rig can have). A flag out of range is a usage error (status 2); a
/// record's header out of range is a record that cannot be analysed as written (status 3). Each
/// names the unit mistake that would explain it (`# load_n=300`: mN written as N).
fn plausible_constants(rec: &Record, got: [(f64, Source); 3]) -> Result<(), AnalysisError> {
    use tribo_wire::limits as l;
    let range = |r: &std::ops::RangeInclusive<f32>| (shown(*r.start()), shown(*r.end()));
    let checks = [
        (
            "--mass-kg",
            "mass_kg",
            "kg",
            range(&l::MASS_KG),
            [("g", 1e3), ("mg", 1e6)],
        ),
        (
            "--stiffness",
            "stiffness_n_per_m",
            "N/m",
            range(&l::STIFFNESS_N_PER_M),
            [("N/mm", 1e-3), ("N/µm", 1e-6)],
        ),
        (
            "--load-n",
            "load_n",
            "N",
            range(&l::LOAD_N),
            [("mN", 1e3), ("µN", 1e6)],
        ),
    ];
    for ((flag, key, unit, (lo, hi), units), (v, from)) in checks.into_iter().zip(got) {
        // The apparatus alone (`# load_n=0`) is a record of the blades without a contact.
        if key == "load_n" && rec.apparatus && from != Source::Flag {
            continue;
        }
        // A load must press the pin (0 is the apparatus run, recorded as such, not a fit's flag).
        let lo_ok = if key == "load_n" { v > lo } else { v >= lo };
        if v.is_finite() && lo_ok && v <= hi {
            continue;
        }
        let hint = unit_hint(v, lo, hi, unit, units);
        let span = format!(
            "the rig's range is {}{lo} to {hi} {unit}",
            if key == "load_n" { "above " } else { "" }
        );
        match from {
            Source::Flag => {
                return Err(AnalysisError::Usage(format!(
                    "{flag} {}: {span}{hint}",
                    sig4(v)
                )))
            }
            _ => {
                return Err(AnalysisError::NotAnalysable(format!(
                    "not analysable as written: `# {key}={}` {unit}: {span}{hint}; correct the \
                     record's header (`tribo fit` also takes {flag})",
                    sig4(v)
                )))
            }
        }
    }
    Ok(())
}

/// A record as loaded, before any flag: its motion (`plausible_motion`) and the rig constants
/// its header gives (`plausible_constants`), for the commands that take no rig flag (`explain`,
/// `onboard`, `report`). Status 3 naming the likely unit mistake.
pub fn plausible_record(rec: &Record) -> Result<(), AnalysisError> {
    plausible_motion(rec)?;
    if rec.units != Units::Si {
        return Ok(());
    }
    let given: [Option<f64>; 3] = match rec.rig {
        Some(r) => [Some(r.mass_kg), Some(r.stiffness_n_per_m), Some(r.load_n)],
        None => rec.rig_partial,
    };
    // Only what the header gives is checked here (a constant it lacks is another error).
    let real = [
        Rig::REAL.mass_kg,
        Rig::REAL.stiffness_n_per_m,
        Rig::REAL.load_n,
    ];
    let got = [0, 1, 2].map(|i| (given[i].unwrap_or(real[i]), Source::Record));
    plausible_constants(rec, got)
}

/// The displacement and velocity of an SI record against what the rig can measure: the pin is
/// held at most 1 mm out of its rest (`tribo_wire::limits::INITIAL_AMPLITUDE_M`), inside the
/// displacement channel's ±2 mm, and the velocity channel spans ±0.25 m/s (the real rig's front
/// ends, `Configure::real_rig`). A record beyond them was written in another unit than its
/// header says (millimetres under `x_m`): status 3, naming it.
fn plausible_motion(rec: &Record) -> Result<(), AnalysisError> {
    if rec.units != Units::Si {
        return Ok(());
    }
    let cal = tribo_wire::Configure::real_rig(0.3).calibration;
    let full = |c: tribo_wire::Channel| {
        let g = cal[c.index()];
        shown((g.gain * 32768.0).abs())
    };
    let peak = |c: &[f64]| c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let checks = [
        (
            "x_m",
            "m",
            peak(&rec.x),
            full(tribo_wire::Channel::Displacement),
            [("millimetres", 1e3), ("micrometres", 1e6)],
        ),
        (
            "v_m_s",
            "m/s",
            peak(&rec.v),
            full(tribo_wire::Channel::Velocity),
            [("mm/s", 1e3), ("µm/s", 1e6)],
        ),
    ];
    for (col, unit, p, fs, units) in checks {
        if p <= fs {
            continue;
        }
        let hint = units
            .iter()
            .find(|(_, f)| p / f <= fs)
            .map(|(u, f)| {
                format!(
                    ": a record in {u} under a header in {unit}? ({} {u} is {} {unit})",
                    sig4(p),
                    sig4(p / f)
                )
            })
            .unwrap_or_default();
        return Err(AnalysisError::NotAnalysable(format!(
            "not analysable as written: column {col} reaches {} {unit}, beyond the rig's \
             ±{fs} {unit} channel{hint}; write the column in {unit}",
            sig4(p)
        )));
    }
    Ok(())
}

/// The largest apparatus damping μ_a blades can have and still ring: a damping ratio μ_a/2 of
/// 5 %. The rig's blades have about 1.1e-3 (the virtual rig's 0.0011).
pub const MAX_APPARATUS_MU1: f64 = 0.1;

/// `--apparatus-mu1` against what blades can have (0 to [`MAX_APPARATUS_MU1`]): a usage error
/// (status 2) otherwise, naming the likely slip (1.1 for 1.1e-3).
pub fn plausible_apparatus_mu1(mu_a: f64) -> Result<(), AnalysisError> {
    if mu_a.is_finite() && (0.0..=MAX_APPARATUS_MU1).contains(&mu_a) {
        return Ok(());
    }
    let hint = if mu_a.is_finite() && mu_a > MAX_APPARATUS_MU1 && mu_a * 1e-3 <= MAX_APPARATUS_MU1 {
        format!(" (did you mean {mu_a}e-3? the rig's blades have about 1.1e-3)")
    } else {
        String::new()
    };
    Err(AnalysisError::Usage(format!(
        "--apparatus-mu1 {mu_a}: blades have a dimensionless damping μ_a from 0 to \
         {MAX_APPARATUS_MU1} (a damping ratio μ_a/2 of at most 5 %; measure it with a `tribo run \
         --load 0` and `tribo fit`){hint}"
    )))
}

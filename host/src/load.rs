//! Loading a record from a path, whatever it is: a run folder of the store, or a CSV file; and
//! saying where its rig constants came from.

use serde::Serialize;
use std::path::Path;
use tribo_physics::record::{RecordError, RecordErrorKind, Units};
use tribo_physics::{Record, Rig};

/// Loads a record: a directory is a run recorded by `tribo` (its samples in SI with its rig
/// constants), anything else is a CSV file in the physics formats.
pub fn load_record(path: &Path) -> Result<Record, RecordError> {
    if path.is_dir() {
        let run =
            tribo_store::Run::open(path).map_err(|e| RecordError(e.msg, RecordErrorKind::Io))?;
        if let Some(r) = &run.recovery {
            eprintln!("warning: {}: {r}", path.display());
        }
        let missing = run.missing_blocks();
        if !missing.is_empty() {
            eprintln!(
                "warning: {}: {} sample blocks are missing (first: {}); `tribo pull {}` fetches them if the rig \
                 still holds the run",
                path.display(),
                missing.len(),
                missing[0],
                path.display()
            );
        }
        let rec = run
            .record()
            .map_err(|e| RecordError(e.msg, RecordErrorKind::Invalid))?;
        rec.validate()
            .map_err(|e| RecordError(format!("{}: {}", path.display(), e.0), e.1))?;
        return Ok(rec);
    }
    Record::load(path)
}

/// [`load_record`] for the analysis commands: a record with a non-finite sample is read but cannot
/// be analysed, which is [`crate::exit::Incomplete`] (status 3), not an error (status 1).
pub fn load_for_analysis(path: &Path) -> anyhow::Result<Record> {
    load_record(path).map_err(|e| match e.kind() {
        RecordErrorKind::NonFinite => {
            anyhow::Error::new(crate::exit::Incomplete(format!("not analysable: {}", e.0)))
        }
        _ => anyhow::Error::new(e),
    })
}

/// The rig constants a run folder's metadata says a default stood in for (empty for a CSV file).
pub fn recorded_defaults(path: &Path) -> Vec<String> {
    if !path.is_dir() {
        return Vec::new();
    }
    tribo_store::Run::open(path)
        .map(|r| r.meta().defaults.clone())
        .unwrap_or_default()
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
    pub mass_kg: f64,
    pub stiffness_n_per_m: f64,
    pub load_n: f64,
    pub mass_kg_from: Source,
    pub stiffness_n_per_m_from: Source,
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
    pub mass_kg: Option<f64>,
    pub stiffness_n_per_m: Option<f64>,
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
/// was taken with by default: [`recorded_defaults`]). A record with no constants and no flag is an
/// error that says which flags to pass.
pub fn apply_rig_flags(
    rec: &mut Record,
    flags: RigFlags,
    recorded_defaults: &[String],
) -> anyhow::Result<RigUsed> {
    if rec.units == Units::Dimensionless {
        if flags.any() {
            anyhow::bail!(
                "the record is dimensionless (tau,y,ydot): --mass-kg, --stiffness and --load-n do not apply"
            );
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
    if rec.rig.is_none() && !flags.any() {
        anyhow::bail!(
            "the record has no rig constants: add `# mass_kg=…`, `# stiffness_n_per_m=…`, `# load_n=…` \
             lines to it, or pass --mass-kg, --stiffness and --load-n"
        );
    }
    let r = rec.rig;
    let (m, mf) = pick(
        flags.mass_kg,
        r.map(|r| r.mass_kg),
        Rig::REAL.mass_kg,
        "mass_kg",
    );
    let (k, kf) = pick(
        flags.stiffness_n_per_m,
        r.map(|r| r.stiffness_n_per_m),
        Rig::REAL.stiffness_n_per_m,
        "stiffness_n_per_m",
    );
    let (n, nf) = pick(
        flags.load_n,
        r.map(|r| r.load_n),
        Rig::REAL.load_n,
        "load_n",
    );
    rec.rig = Some(Rig::new(m, k, n).map_err(anyhow::Error::msg)?);
    Ok(RigUsed {
        mass_kg: m,
        stiffness_n_per_m: k,
        load_n: n,
        mass_kg_from: mf,
        stiffness_n_per_m_from: kf,
        load_n_from: nf,
    })
}

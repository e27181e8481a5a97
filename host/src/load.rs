//! Loading a record from a path, whatever it is: a run folder of the store, or a CSV file; and
//! saying where its rig constants came from.
//!
//! A fit assumes the samples it is given follow each other at the sample rate. A record with holes
//! (samples the rig lost, reported by its gap frames; blocks never received; a CSV whose time axis
//! jumps) breaks that assumption: [`load_for_fit`] refuses it, saying where the holes are, unless
//! the caller asks for the longest clean stretch ([`Holes::LongestCleanStretch`], the
//! `--longest-clean-stretch` flag of `tribo fit` and `tribo explain`).

use serde::Serialize;
use std::ops::Range;
use std::path::{Path, PathBuf};
use tribo_physics::record::{RecordError, RecordErrorKind, Units};
use tribo_physics::{Record, Rig};
use tribo_store::StoreError;

/// Why a record could not be loaded from a path.
#[derive(Debug, thiserror::Error)]
pub enum LoadError {
    /// A CSV file, or a run's samples, that is not a usable record.
    #[error(transparent)]
    Record(#[from] RecordError),
    /// A run folder the store cannot read.
    #[error("cannot read the run {}", path.display())]
    Run {
        path: PathBuf,
        #[source]
        source: StoreError,
    },
    /// A record with holes, refused for a fit ([`Holes::Refuse`]); the message says where the
    /// holes are and what to do.
    #[error("{}: {message}", path.display())]
    Holes {
        path: PathBuf,
        message: String,
        /// A run folder's holes (blocks not received, samples the rig lost): its data is
        /// incomplete (status 3); a CSV whose time axis jumps is a file to fix (status 1).
        run: bool,
    },
    /// A run folder that is not whole (a torn or cut frame log, blocks or the end not received),
    /// refused for analysis: status 3, as for any incomplete run. The message says what is
    /// missing and how to get it, or how to analyse what is held.
    #[error("{}: {message}", path.display())]
    Incomplete { path: PathBuf, message: String },
}

impl LoadError {
    /// A run whose data is not whole (exit status 3, `IncompleteRun` in Python).
    pub fn is_incomplete(&self) -> bool {
        matches!(
            self,
            LoadError::Holes { run: true, .. } | LoadError::Incomplete { .. }
        )
    }

    /// A readable record with a NaN or infinite sample: it cannot be analysed.
    pub fn is_non_finite(&self) -> bool {
        matches!(self, LoadError::Record(e) if e.kind() == RecordErrorKind::NonFinite)
    }
}

fn run_error(path: &Path) -> impl FnOnce(StoreError) -> LoadError + '_ {
    move |source| LoadError::Run {
        path: path.to_path_buf(),
        source,
    }
}

/// The flag that makes `tribo fit` / `tribo explain` fit the longest stretch without holes.
pub const LONGEST_CLEAN_STRETCH_FLAG: &str = "--longest-clean-stretch";

/// A path opened by [`open`], the loader of the commands that turn a path into a record (`fit`,
/// `explain`, `onboard`, `report` of a record, `export` of a CSV) and of the Python package's
/// `fit`, `explain` and `read_record`: its record, the rig constants a default stood in for, and
/// the run.
#[derive(Debug)]
pub struct Opened {
    /// The samples, as the [`Holes`] policy asked.
    pub record: Record,
    /// The rig constants a run folder's metadata says a default stood in for (empty for a CSV
    /// file): what a result made with them must say.
    pub defaults: Vec<String>,
    /// The run, for a run folder (its on-board result, metadata, completeness); `None` for a CSV
    /// file or standard input.
    pub run: Option<tribo_store::Run>,
}

/// Opens a record once: a directory is a run recorded by `tribo` (its samples in SI with its rig
/// constants; the store's warnings about it on standard error), `-` a CSV on standard input,
/// anything else a CSV file in the physics formats. `holes` says what to do with a record that is
/// not whole or has holes.
pub fn open(path: &Path, holes: Holes) -> Result<Opened, LoadError> {
    if path.is_dir() && path != Path::new("-") {
        let run = open_run(path)?;
        let defaults = run.meta().defaults.clone();
        let record = match holes {
            Holes::Keep | Holes::Whole => {
                if holes == Holes::Whole && !run.is_complete() {
                    return Err(LoadError::Incomplete {
                        path: path.to_path_buf(),
                        message: incomplete_run(&run, path),
                    });
                }
                let rec = run.record().map_err(run_error(path))?;
                rec.validate().map_err(|e| e.in_file(path))?;
                rec
            }
            Holes::Refuse | Holes::LongestCleanStretch => run_for_fit(&run, path, holes)?,
        };
        return Ok(Opened {
            record,
            defaults,
            run: Some(run),
        });
    }
    let rec = if path == Path::new("-") {
        stdin_record()?
    } else {
        Record::load(path)?
    };
    let record = match holes {
        Holes::Keep | Holes::Whole => rec,
        Holes::Refuse | Holes::LongestCleanStretch => {
            let stretches = time_axis_stretches(&rec.t);
            let described = describe_time_holes(&rec.t, &stretches);
            stretch_for_fit(rec, stretches, described, path, holes)?
        }
    };
    Ok(Opened {
        record,
        defaults: Vec::new(),
        run: None,
    })
}

/// Loads a record ([`open`] with [`Holes::Keep`]): samples keep their times, so a run with holes
/// gives a time axis with jumps (see [`load_for_fit`]).
pub fn load_record(path: &Path) -> Result<Record, LoadError> {
    open(path, Holes::Keep).map(|o| o.record)
}

/// A CSV record read from standard input (the path `-`, as `tribo sim -o -` writes one).
fn stdin_record() -> Result<Record, LoadError> {
    use std::io::Read;
    let mut text = String::new();
    std::io::stdin()
        .read_to_string(&mut text)
        .map_err(|source| RecordError::Io {
            verb: "read",
            path: PathBuf::from("-"),
            source,
        })?;
    Ok(Record::from_csv_str(&text).map_err(|e| e.in_file(Path::new("standard input")))?)
}

/// What to do with a record that has holes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Holes {
    /// Refuse it, with an error that says where the holes are and names
    /// [`LONGEST_CLEAN_STRETCH_FLAG`].
    #[default]
    Refuse,
    /// Keep the longest stretch of consecutive samples (told on stderr).
    LongestCleanStretch,
    /// Keep every sample at its time (a time axis with jumps), and a run that is not whole as far
    /// as it goes: to export or draw what is stored.
    Keep,
    /// As [`Holes::Keep`], but refuse a run folder that is not whole
    /// ([`LoadError::Incomplete`]): for the analyses that take a record as it is.
    Whole,
}

/// A record ready to fit ([`open`] with [`Holes::Refuse`] or [`Holes::LongestCleanStretch`]): no
/// holes, or the longest stretch without one.
pub fn load_for_fit(path: &Path, holes: Holes) -> Result<Record, LoadError> {
    open(path, holes).map(|o| o.record)
}

/// A run folder's record ready to fit.
fn run_for_fit(run: &tribo_store::Run, path: &Path, holes: Holes) -> Result<Record, LoadError> {
    if !run.is_complete() && run.missing_blocks().is_empty() {
        // Not whole, yet no hole inside: the log's end is cut (or the end never came). What
        // it holds is analysed only when asked for.
        match holes {
            Holes::Refuse => {
                return Err(LoadError::Incomplete {
                    path: path.to_path_buf(),
                    message: format!(
                        "{}. Pass {LONGEST_CLEAN_STRETCH_FLAG} to analyse what it holds",
                        incomplete_run(run, path)
                    ),
                })
            }
            _ => crate::errln!(
                "note: {}: {}; analysing what it holds",
                path.display(),
                run.completeness().summary()
            ),
        }
    }
    let rec = run.record().map_err(run_error(path))?;
    let stretches = positions_of(run)?;
    let described = describe_run_holes(run);
    stretch_for_fit(rec, stretches, described, path, holes)
}

/// `rec` ready to fit: whole if it has one stretch, else refused or its longest stretch.
fn stretch_for_fit(
    rec: Record,
    stretches: Vec<Range<usize>>,
    described: String,
    path: &Path,
    holes: Holes,
) -> Result<Record, LoadError> {
    if stretches.len() <= 1 {
        rec.validate().map_err(|e| e.in_file(path))?;
        return Ok(rec);
    }
    let longest = stretches
        .iter()
        .max_by_key(|r| (r.len(), std::cmp::Reverse(r.start)))
        .cloned()
        .unwrap_or(0..0);
    let span = |r: &Range<usize>| -> String {
        match (rec.t.get(r.start), rec.t.get(r.end.saturating_sub(1))) {
            (Some(a), Some(b)) => format!("t = {a:.4} .. {b:.4} s, {} samples", r.len()),
            _ => format!("{} samples", r.len()),
        }
    };
    match holes {
        Holes::Refuse | Holes::Keep | Holes::Whole => Err(LoadError::Holes {
            run: path.is_dir(),
            path: path.to_path_buf(),
            message: format!(
                "{described}. A fit across a hole would treat the samples after it as if they \
             followed on at once. Pass {LONGEST_CLEAN_STRETCH_FLAG} to fit the longest stretch \
             without one ({}){}",
                span(&longest),
                if path.is_dir() {
                    format!(
                        ", or, if blocks are missing, fetch them with `tribo pull {}`",
                        path.display()
                    )
                } else {
                    String::new()
                }
            ),
        }),
        Holes::LongestCleanStretch => {
            crate::errln!(
                "note: {}: {described}; fitting the longest clean stretch ({}) of the {} stretches",
                path.display(),
                span(&longest),
                stretches.len()
            );
            let part = slice(&rec, longest);
            part.validate().map_err(|e| e.in_file(path))?;
            Ok(part)
        }
    }
}

fn open_run(path: &Path) -> Result<tribo_store::Run, LoadError> {
    let run = tribo_store::Run::open(path).map_err(run_error(path))?;
    if let Some(r) = &run.recovery {
        crate::errln!("warning: {}: {r}", path.display());
    }
    let missing = run.missing_blocks();
    if !missing.is_empty() {
        crate::errln!(
            "warning: {}: {} sample blocks are missing (first: {}); `tribo pull {}` fetches them if the rig \
             still holds the run",
            path.display(),
            missing.len(),
            missing[0],
            path.display()
        );
    }
    Ok(run)
}

/// A record with a non-finite sample is read but cannot be analysed: that is
/// [`crate::exit::Incomplete`] (status 3), not an error (status 1).
fn analysable<T>(r: Result<T, LoadError>) -> anyhow::Result<T> {
    r.map_err(|e| {
        if e.is_non_finite() {
            let said = crate::exit::chain_text(&e);
            anyhow::Error::new(crate::exit::Incomplete(format!("not analysable: {said}")))
        } else {
            anyhow::Error::new(e)
        }
    })
}

/// [`load_record`] for the analysis commands (a non-finite sample is status 3; so is a run folder
/// that is not whole, refused: [`LoadError::Incomplete`]).
pub fn load_for_analysis(path: &Path) -> anyhow::Result<Record> {
    let o = open_analysable(path, Holes::Whole)?;
    plausible_record(&o.record).map_err(|e| e.context(path.display().to_string()))?;
    Ok(o.record)
}

/// What a run that is not whole lacks and how to get it: `the run is incomplete: 79 of ? blocks
/// (no end); its frame log was cut: … ; `tribo pull DIR` fetches the rest while the rig holds it`.
pub fn incomplete_run(run: &tribo_store::Run, path: &Path) -> String {
    let mut s = format!("the run is {}", run.completeness().summary());
    if let Some(r) = &run.recovery {
        s.push_str(&format!(" (its frame log: {r})"));
    }
    s.push_str(&format!(
        "; `tribo pull {}` fetches the rest while the rig holds it",
        path.display()
    ));
    s
}

/// [`load_for_fit`] for the analysis commands (a non-finite sample is status 3).
pub fn load_analysable_for_fit(path: &Path, holes: Holes) -> anyhow::Result<Record> {
    open_analysable(path, holes).map(|o| o.record)
}

/// [`open`] for the analysis commands: a record with a non-finite sample is read but cannot be
/// analysed ([`crate::exit::Incomplete`], status 3).
pub fn open_analysable(path: &Path, holes: Holes) -> anyhow::Result<Opened> {
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
        anyhow::bail!(
            "the record's rig constants are incomplete or absent: add `# mass_kg=…`, \
             `# stiffness_n_per_m=…`, `# load_n=…` lines to it, or pass {}",
            missing.join(", ")
        );
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
fn plausible_constants(rec: &Record, got: [(f64, Source); 3]) -> anyhow::Result<()> {
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
                return Err(crate::exit::Usage(format!("{flag} {}: {span}{hint}", sig4(v))).into())
            }
            _ => {
                return Err(crate::exit::Incomplete(format!(
                    "not analysable as written: `# {key}={}` {unit}: {span}{hint}; correct the \
                     record's header (`tribo fit` also takes {flag})",
                    sig4(v)
                ))
                .into())
            }
        }
    }
    Ok(())
}

/// A record as loaded, before any flag: its motion ([`plausible_motion`]) and the rig constants
/// its header gives ([`plausible_constants`]), for the commands that take no rig flag (`explain`,
/// `onboard`, `report`). Status 3 naming the likely unit mistake.
pub fn plausible_record(rec: &Record) -> anyhow::Result<()> {
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
fn plausible_motion(rec: &Record) -> anyhow::Result<()> {
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
        return Err(crate::exit::Incomplete(format!(
            "not analysable as written: column {col} reaches {} {unit}, beyond the rig's \
             ±{fs} {unit} channel{hint}; write the column in {unit}",
            sig4(p)
        ))
        .into());
    }
    Ok(())
}

/// The largest apparatus damping μ_a blades can have and still ring: a damping ratio μ_a/2 of
/// 5 %. The rig's blades have about 1.1e-3 (the virtual rig's 0.0011).
pub const MAX_APPARATUS_MU1: f64 = 0.1;

/// `--apparatus-mu1` against what blades can have (0 to [`MAX_APPARATUS_MU1`]): a usage error
/// (status 2) otherwise, naming the likely slip (1.1 for 1.1e-3).
pub fn plausible_apparatus_mu1(mu_a: f64) -> anyhow::Result<()> {
    if mu_a.is_finite() && (0.0..=MAX_APPARATUS_MU1).contains(&mu_a) {
        return Ok(());
    }
    let hint = if mu_a.is_finite() && mu_a > MAX_APPARATUS_MU1 && mu_a * 1e-3 <= MAX_APPARATUS_MU1 {
        format!(" (did you mean {mu_a}e-3? the rig's blades have about 1.1e-3)")
    } else {
        String::new()
    };
    Err(crate::exit::Usage(format!(
        "--apparatus-mu1 {mu_a}: blades have a dimensionless damping μ_a from 0 to \
         {MAX_APPARATUS_MU1} (a damping ratio μ_a/2 of at most 5 %; measure it with a `tribo run \
         --load 0` and `tribo fit`){hint}"
    ))
    .into())
}

/// The run's clean stretches as positions in its record (whose samples are the run's, in index
/// order).
fn positions_of(run: &tribo_store::Run) -> Result<Vec<Range<usize>>, LoadError> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    for r in run.clean_stretches() {
        let n = (r.end - r.start) as usize;
        out.push(pos..pos + n);
        pos += n;
    }
    Ok(out)
}

/// The samples each acquisition gap of a run lost, as `first..end` (end exclusive).
pub fn gap_spans(run: &tribo_store::Run) -> Vec<String> {
    run.gaps()
        .map(|g| {
            format!(
                "{}..{}",
                g.first_sample,
                g.first_sample as u64 + g.count as u64
            )
        })
        .collect()
}

/// "2 acquisition gaps (samples 1200..1500, 9000..9010: 310 lost) and 3 blocks not received".
fn describe_run_holes(run: &tribo_store::Run) -> String {
    let gaps = gap_spans(run);
    let missing = run.missing_blocks().len();
    let mut parts = Vec::new();
    if !gaps.is_empty() {
        parts.push(format!(
            "{} acquisition gap{} (samples {}: {} lost by the rig)",
            gaps.len(),
            if gaps.len() == 1 { "" } else { "s" },
            gaps.join(", "),
            run.lost_samples()
        ));
    }
    if missing > 0 {
        parts.push(format!(
            "{missing} sample block{} not received",
            if missing == 1 { "" } else { "s" }
        ));
    }
    if parts.is_empty() {
        "the samples have holes".into()
    } else {
        format!("the run has {}", parts.join(" and "))
    }
}

/// Stretches of a time axis without jumps: a step over 1.5 times the median step is a hole.
pub fn time_axis_stretches(t: &[f64]) -> Vec<Range<usize>> {
    if t.len() < 3 {
        return std::iter::once(0..t.len()).collect();
    }
    let mut steps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    steps.sort_by(f64::total_cmp);
    let median = steps[steps.len() / 2];
    let mut out = Vec::new();
    let mut start = 0;
    for i in 1..t.len() {
        if t[i] - t[i - 1] > 1.5 * median {
            out.push(start..i);
            start = i;
        }
    }
    out.push(start..t.len());
    out
}

fn describe_time_holes(t: &[f64], stretches: &[Range<usize>]) -> String {
    let holes: Vec<String> = stretches
        .windows(2)
        .filter_map(|w| {
            let a = t.get(w[0].end.checked_sub(1)?)?;
            let b = t.get(w[1].start)?;
            Some(format!("{a:.4} s .. {b:.4} s"))
        })
        .collect();
    format!(
        "the time axis jumps {} time{} ({})",
        holes.len(),
        if holes.len() == 1 { "" } else { "s" },
        holes.join(", ")
    )
}

/// Samples `r` of a record (every column).
fn slice(rec: &Record, r: Range<usize>) -> Record {
    let cut = |v: &Vec<f64>| v.get(r.clone()).unwrap_or(&[]).to_vec();
    let mut out = Record::new(cut(&rec.t), cut(&rec.x), cut(&rec.v), rec.rig, rec.units);
    out.ft = rec.ft.as_ref().map(cut);
    out.temp = rec.temp.as_ref().map(cut);
    out.ecr = rec.ecr.as_ref().map(cut);
    out.force_cutoff_hz = rec.force_cutoff_hz;
    out.force_zero_n = rec.force_zero_n;
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_time_axis_is_split_at_each_jump_and_nowhere_else() {
        let mut t: Vec<f64> = (0..100).map(|i| i as f64 * 1e-4).collect();
        assert_eq!(
            time_axis_stretches(&t),
            Vec::from_iter(std::iter::once(0..100))
        );
        // Samples 40..70 and 90..91 missing.
        t.retain(|x| {
            let i = (x / 1e-4).round() as i64;
            !(40..70).contains(&i) && i != 90
        });
        assert_eq!(time_axis_stretches(&t), [0..40, 40..60, 60..69]);
        let d = describe_time_holes(&t, &time_axis_stretches(&t));
        assert!(
            d.contains("jumps 2 times") && d.contains("0.0039 s .. 0.0070 s"),
            "{d}"
        );
    }
}

//! Loading a record from a path, whatever it is: a run folder of the store, or a CSV file; and
//! saying where its rig constants came from.
//!
//! A fit assumes the samples it is given follow each other at the sample rate. A record with holes
//! (samples the rig lost, reported by its gap frames; blocks never received; a CSV whose time axis
//! jumps) breaks that assumption: [`load_for_fit`] refuses it, saying where the holes are, unless
//! the caller asks for the longest clean stretch ([`Holes::LongestCleanStretch`], the
//! `--longest-clean-stretch` flag of `tribo fit` and `tribo explain`).

use std::ops::Range;
use std::path::{Path, PathBuf};
use tribo_physics::record::{RecordError, RecordErrorKind};
use tribo_physics::Record;
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
        /// The run folder.
        path: PathBuf,
        /// What the store could not read.
        #[source]
        source: StoreError,
    },
    /// A record with holes, refused for a fit ([`Holes::Refuse`]); the message says where the
    /// holes are and what to do.
    #[error("{}: {message}", path.display())]
    Holes {
        /// The record.
        path: PathBuf,
        /// Where the holes are and what to do.
        message: String,
        /// A run folder's holes (blocks not received, samples the rig lost): its data is
        /// incomplete (status 3); a CSV whose time axis jumps is a file to fix (status 1).
        run: bool,
    },
    /// A run folder that is not whole (a torn or cut frame log, blocks or the end not received),
    /// refused for analysis: status 3, as for any incomplete run. The message says what is
    /// missing and how to get it, or how to analyse what is held.
    #[error("{}: {message}", path.display())]
    Incomplete {
        /// The run folder.
        path: PathBuf,
        /// What is missing and how to get it.
        message: String,
    },
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

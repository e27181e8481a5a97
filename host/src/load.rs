//! Loading a record from a path, whatever it is: a run folder of the store, or a CSV file.
//!
//! A fit assumes the samples it is given follow each other at the sample rate. A record with holes
//! (samples the rig lost, reported by its gap frames; blocks never received; a CSV whose time axis
//! jumps) breaks that assumption: [`load_for_fit`] refuses it, saying where the holes are, unless
//! the caller asks for the longest clean stretch ([`Holes::LongestCleanStretch`], the
//! `--longest-clean-stretch` flag of `tribo fit` and `tribo explain`).

use std::ops::Range;
use std::path::Path;
use tribo_physics::record::RecordError;
use tribo_physics::Record;

/// The flag that makes `tribo fit` / `tribo explain` fit the longest stretch without holes.
pub const LONGEST_CLEAN_STRETCH_FLAG: &str = "--longest-clean-stretch";

/// Loads a record: a directory is a run recorded by `tribo` (its samples in SI with its rig
/// constants), anything else is a CSV file in the physics formats. Samples keep their times, so a
/// run with holes gives a time axis with jumps (see [`load_for_fit`]).
pub fn load_record(path: &Path) -> Result<Record, RecordError> {
    if path.is_dir() {
        let run = open_run(path)?;
        let rec = run.record().map_err(|e| RecordError(e.msg))?;
        rec.validate()
            .map_err(|e| RecordError(format!("{}: {}", path.display(), e.0)))?;
        return Ok(rec);
    }
    Record::load(path)
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
}

/// A record ready to fit: no holes, or the longest stretch without one.
pub fn load_for_fit(path: &Path, holes: Holes) -> Result<Record, RecordError> {
    let (rec, stretches, described) = if path.is_dir() {
        let run = open_run(path)?;
        let rec = run.record().map_err(|e| RecordError(e.msg))?;
        let stretches = positions_of(&run)?;
        let described = describe_run_holes(&run);
        (rec, stretches, described)
    } else {
        let rec = Record::load(path)?;
        let stretches = time_axis_stretches(&rec.t);
        let described = describe_time_holes(&rec.t, &stretches);
        (rec, stretches, described)
    };
    if stretches.len() <= 1 {
        rec.validate()
            .map_err(|e| RecordError(format!("{}: {}", path.display(), e.0)))?;
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
        Holes::Refuse => Err(RecordError(format!(
            "{}: {described}. A fit across a hole would treat the samples after it as if they \
             followed on at once. Pass {LONGEST_CLEAN_STRETCH_FLAG} to fit the longest stretch \
             without one ({}){}",
            path.display(),
            span(&longest),
            if path.is_dir() {
                format!(
                    ", or, if blocks are missing, fetch them with `tribo pull {}`",
                    path.display()
                )
            } else {
                String::new()
            }
        ))),
        Holes::LongestCleanStretch => {
            eprintln!(
                "note: {}: {described}; fitting the longest clean stretch ({}) of the {} stretches",
                path.display(),
                span(&longest),
                stretches.len()
            );
            let part = slice(&rec, longest);
            part.validate()
                .map_err(|e| RecordError(format!("{}: {}", path.display(), e.0)))?;
            Ok(part)
        }
    }
}

fn open_run(path: &Path) -> Result<tribo_store::Run, RecordError> {
    let run = tribo_store::Run::open(path).map_err(|e| RecordError(e.msg))?;
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
    Ok(run)
}

/// The run's clean stretches as positions in its record (whose samples are the run's, in index
/// order).
fn positions_of(run: &tribo_store::Run) -> Result<Vec<Range<usize>>, RecordError> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    for r in run.clean_stretches() {
        let n = (r.end - r.start) as usize;
        out.push(pos..pos + n);
        pos += n;
    }
    Ok(out)
}

/// "2 acquisition gaps (samples 1200..1500, 9000..9010: 310 lost) and 3 blocks not received".
fn describe_run_holes(run: &tribo_store::Run) -> String {
    let gaps: Vec<String> = run
        .gaps()
        .map(|g| {
            format!(
                "{}..{}",
                g.first_sample,
                g.first_sample as u64 + g.count as u64
            )
        })
        .collect();
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

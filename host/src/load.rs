//! Loading a record from a path, whatever it is: a run folder of the store, or a CSV file.

use std::path::Path;
use tribo_physics::record::{RecordError, RecordErrorKind};
use tribo_physics::Record;

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

//! The lab catalog's tests (`host/catalog/tests/lab.rs`, `host/tests/it/lab_catalog.rs`) start a
//! real PostgreSQL server of their own; CI must have its binaries and must not skip them.

use crate::apt;
use std::path::PathBuf;

/// Debian's package of the PostgreSQL server (`initdb`, `pg_ctl`, `postgres`, `psql`).
const PACKAGE: &str = "postgresql";

fn server_bin() -> Option<PathBuf> {
    if let Some(b) = std::env::var_os("TRIBO_PG_BIN") {
        return Some(PathBuf::from(b));
    }
    std::fs::read_dir("/usr/lib/postgresql")
        .ok()?
        .filter_map(|e| e.ok().map(|e| e.path().join("bin")))
        .find(|b| b.join("initdb").is_file() && b.join("pg_ctl").is_file())
}

/// Makes sure the lab catalog's tests will run: PostgreSQL's server binaries installed (with
/// apt-get when run as root), and `TRIBO_SKIP_POSTGRES` not set in CI.
pub fn ensure() -> Result<(), String> {
    if std::env::var("TRIBO_SKIP_POSTGRES").is_ok_and(|v| v == "1") {
        if std::env::var_os("CI").is_some() {
            return Err(
                "TRIBO_SKIP_POSTGRES=1 in CI: the lab catalog's tests must run there; unset it"
                    .into(),
            );
        }
        eprintln!("xtask: TRIBO_SKIP_POSTGRES=1: the lab catalog's tests will be skipped");
        return Ok(());
    }
    if let Some(b) = server_bin() {
        eprintln!(
            "xtask: the lab catalog's tests use PostgreSQL from {}",
            b.display()
        );
        return Ok(());
    }
    apt::ensure(&apt::Need {
        what: "the lab catalog's tests (they start a PostgreSQL server of their own)",
        packages: &[PACKAGE],
        present: &|| server_bin().is_some(),
        otherwise: "or set TRIBO_PG_BIN to the folder of initdb and pg_ctl; or, on a developer's \
                    machine, TRIBO_SKIP_POSTGRES=1 skips those tests",
    })
}

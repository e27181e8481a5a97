//! The lab catalog's tests (`host/catalog/tests/lab.rs`, `host/tests/lab_catalog.rs`) start a
//! real PostgreSQL server of their own; CI must have its binaries and must not skip them.

use std::path::{Path, PathBuf};
use std::process::Command;

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
    if !(Path::new("/usr/bin/apt-get").exists() && super::is_root()) {
        return Err(format!(
            "PostgreSQL's server binaries (initdb, pg_ctl) are missing; the lab catalog's tests start a server of their own.\n  \
             → `sudo apt-get install -y {PACKAGE}` (Debian/Ubuntu), or set TRIBO_PG_BIN to their folder\n  \
             → or, on a developer's machine, TRIBO_SKIP_POSTGRES=1 skips those tests"
        ));
    }
    eprintln!("xtask: installing {PACKAGE} for the lab catalog's tests");
    super::run(Command::new("apt-get").arg("update").arg("-q"))?;
    super::run(
        Command::new("apt-get")
            .env("DEBIAN_FRONTEND", "noninteractive")
            .args(["install", "-y", "-q", "--no-install-recommends", PACKAGE]),
    )?;
    server_bin()
        .map(|_| ())
        .ok_or_else(|| format!("{PACKAGE} installed, but no /usr/lib/postgresql/*/bin/initdb"))
}

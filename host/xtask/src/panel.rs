//! The front panel's browser tests (`host/tests/panel_browser.rs`): `tribo panel` driven in
//! Debian's headless `chromium` through `chromedriver`, against a virtual rig. They are
//! `#[ignore]`d in a plain `cargo test` (they need the browser); here chromium and its driver are
//! installed when missing (root, apt-get), and the tests run: a missing browser is an error, never
//! a skipped test.

use crate::{cargo, is_root, run};
use std::path::Path;
use std::process::{Command, Stdio};

/// What the browser tests need from Debian.
const PACKAGES: [&str; 2] = ["chromium", "chromium-driver"];

fn have(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .status()
        .is_ok_and(|s| s.success())
}

/// Installs chromium and chromedriver when they are missing and we may (root, apt-get).
fn ensure_browser() -> Result<(), String> {
    if have("chromium") && have("chromedriver") {
        return Ok(());
    }
    if !(Path::new("/usr/bin/apt-get").exists() && is_root()) {
        return Err(format!(
            "the panel's browser tests need chromium and chromedriver.\n  → on Debian: `sudo apt-get \
             install -y --no-install-recommends {}` and run this again",
            PACKAGES.join(" ")
        ));
    }
    eprintln!("xtask: installing {}", PACKAGES.join(" "));
    run(Command::new("apt-get").args(["update", "-q"]))?;
    run(Command::new("apt-get")
        .args(["install", "-y", "-q", "--no-install-recommends"])
        .args(PACKAGES)
        .env("DEBIAN_FRONTEND", "noninteractive"))?;
    if have("chromium") && have("chromedriver") {
        Ok(())
    } else {
        Err(format!(
            "{} installed, but chromium or chromedriver is still missing",
            PACKAGES.join(" ")
        ))
    }
}

/// Installs the browser when needed, then runs the panel's browser tests.
pub fn browser_tests() -> Result<(), String> {
    ensure_browser()?;
    run(cargo().args([
        "test",
        "-p",
        "tribo",
        "--test",
        "panel_browser",
        "--",
        "--ignored",
    ]))
}

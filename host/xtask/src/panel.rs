//! The front panel's browser tests (`host/tests/it/panel_browser.rs`): `tribo panel` driven in
//! Debian's headless `chromium` through `chromedriver`, against a virtual rig. They are
//! `#[ignore]`d in a plain `cargo test` (they need the browser); here chromium and its driver are
//! installed when missing (root, apt-get), and the tests run: a missing browser is an error, never
//! a skipped test.

use crate::{apt, cargo, run};

/// What the browser tests need from Debian.
const PACKAGES: [&str; 2] = ["chromium", "chromium-driver"];

/// Installs chromium and chromedriver when they are missing and we may (root, apt-get).
fn ensure_browser() -> Result<(), String> {
    apt::ensure(&apt::Need {
        what: "the panel's browser tests",
        packages: &PACKAGES,
        present: &|| apt::answers("chromium", true) && apt::answers("chromedriver", true),
        otherwise: "",
    })
}

/// Installs the browser when needed, then runs the panel's browser tests.
pub fn browser_tests() -> Result<(), String> {
    ensure_browser()?;
    run(cargo().args([
        "test",
        "-p",
        "tribo",
        "--test",
        "it",
        "--",
        "--ignored",
        "panel_browser::",
    ]))
}

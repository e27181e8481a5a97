//! What a step needs from the machine, and Debian's packages that bring it.
//!
//! Every step of `cargo xtask` that needs a program the Rust toolchain does not bring (Debian's
//! rustc for a target rustup lacks, QEMU, mingw and Wine, chromium, PostgreSQL, Python's venv)
//! asks for it here, in its own terms: what it needs, how to tell it is there, which packages
//! bring it. On Debian, as root, a missing need is installed with apt-get (and the log says what
//! and why); elsewhere the step stops and names the command to run. No step relies on another
//! step having installed something before it: each one checks and installs what it uses.

use crate::run;
use std::path::Path;
use std::process::Command;

/// What one step needs.
pub struct Need<'a> {
    /// What the packages are for, as the log should say it ("the Windows build", …).
    pub what: &'a str,
    /// Debian's packages that bring it.
    pub packages: &'a [&'a str],
    /// Whether the machine has it now.
    pub present: &'a dyn Fn() -> bool,
    /// What else a person may do instead of installing the packages (or "").
    pub otherwise: &'a str,
}

/// What to do about a need, from what the machine has.
#[derive(Debug, PartialEq, Eq)]
pub enum Action {
    /// Already there.
    Nothing,
    /// Install these packages with apt-get.
    Install,
    /// Stop: cannot install here; the message says what to run.
    Refuse(String),
}

/// Whether this process may install Debian packages: apt-get is there and we are root.
pub fn may_install() -> bool {
    Path::new("/usr/bin/apt-get").exists() && crate::is_root()
}

/// The decision, as a function of the need and the machine (kept pure for the tests).
pub fn decide(need: &Need, present: bool, may_install: bool) -> Action {
    if present {
        Action::Nothing
    } else if may_install {
        Action::Install
    } else {
        let mut msg = format!(
            "{} needs Debian's {}.\n  → on Debian/Ubuntu: `sudo apt-get install -y --no-install-recommends {}` and run this again",
            need.what,
            need.packages.join(", "),
            need.packages.join(" ")
        );
        if !need.otherwise.is_empty() {
            msg.push_str("\n  → ");
            msg.push_str(need.otherwise);
        }
        Action::Refuse(msg)
    }
}

/// Makes sure `need` is met: nothing when it is, an apt-get install when we may, an error that
/// says what to install otherwise.
pub fn ensure(need: &Need) -> Result<(), String> {
    match decide(need, (need.present)(), may_install()) {
        Action::Nothing => Ok(()),
        Action::Refuse(msg) => Err(msg),
        Action::Install => {
            install(need.what, need.packages)?;
            if (need.present)() {
                Ok(())
            } else {
                Err(format!(
                    "{} installed for {}, but it is still not usable",
                    need.packages.join(" "),
                    need.what
                ))
            }
        }
    }
}

/// `apt-get update` (once per process) and `apt-get install` of `packages`, saying why.
pub fn install(what: &str, packages: &[&str]) -> Result<(), String> {
    use std::sync::atomic::{AtomicBool, Ordering};
    static UPDATED: AtomicBool = AtomicBool::new(false);
    eprintln!(
        "xtask: installing {} for {what} (Debian packages)",
        packages.join(" ")
    );
    if !UPDATED.swap(true, Ordering::SeqCst) {
        run(Command::new("apt-get").args(["update", "-q"]))?;
    }
    run(Command::new("apt-get")
        .env("DEBIAN_FRONTEND", "noninteractive")
        .args(["install", "-y", "-q", "--no-install-recommends"])
        .args(packages))?;
    INSTALLED
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .extend(packages.iter().map(|p| p.to_string()));
    Ok(())
}

/// The packages this process installed, in order.
static INSTALLED: std::sync::Mutex<Vec<String>> = std::sync::Mutex::new(Vec::new());

/// What [`install`] has installed so far.
pub fn installed() -> Vec<String> {
    INSTALLED.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Whether `program --version` starts (and, when `success`, exits 0).
pub fn answers(program: &str, success: bool) -> bool {
    Command::new(program)
        .arg("--version")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .status()
        .is_ok_and(|s| s.success() || !success)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn need() -> Need<'static> {
        Need {
            what: "the on-target tests",
            packages: &["qemu-system-arm"],
            present: &|| false,
            otherwise: "",
        }
    }

    #[test]
    fn present_needs_nothing_whoever_runs() {
        assert_eq!(decide(&need(), true, false), Action::Nothing);
        assert_eq!(decide(&need(), true, true), Action::Nothing);
    }

    #[test]
    fn missing_is_installed_as_root_and_named_otherwise() {
        assert_eq!(decide(&need(), false, true), Action::Install);
        match decide(&need(), false, false) {
            Action::Refuse(m) => {
                assert!(m.contains("the on-target tests"), "{m}");
                assert!(m.contains("apt-get install -y --no-install-recommends qemu-system-arm"));
            }
            other => panic!("{other:?}"),
        }
    }
}

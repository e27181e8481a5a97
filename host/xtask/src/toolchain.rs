//! Which Rust toolchain builds for a foreign target here: rustup's, when its active toolchain
//! holds the target's standard library; otherwise Debian's `rustc-web` with
//! `RUSTC_BOOTSTRAP=1 -Z build-std`, installed first when missing and we may (root, apt-get).
//!
//! Each cross-build (the firmware for `thumbv7em-none-eabihf`, `tribo.exe` for
//! `x86_64-pc-windows-gnu`) chooses for its own target and installs what *it* needs: a machine
//! whose rustup has the firmware's target and not Windows' must still get Debian's rustc for the
//! Windows build (issue 31: that build once relied on the firmware's choice to install it).
//! The choice is [`choose`], a function of what the machine has ([`Machine`]), tested below for
//! every combination that matters.

use crate::apt;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A part of Debian's Rust toolchain a cross-build may need.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Part {
    /// `/usr/bin/cargo` and `/usr/bin/rustc`.
    Compiler,
    /// The standard library's sources (`core` for the firmware, `std` for Windows).
    CoreSource,
    StdSource,
    /// LLVM's `lld` (package `lld-22`), the firmware's linker under the name `rust-lld`.
    Lld,
    /// `cargo-clippy`, for linting the firmware for its target.
    Clippy,
}

/// What one cross-build needs.
#[derive(Debug)]
pub struct CrossBuild {
    pub what: &'static str,
    pub target: &'static str,
    /// What it needs from Debian when rustup lacks the target.
    pub parts: &'static [Part],
    /// The packages that bring those parts.
    pub packages: &'static [&'static str],
}

/// The firmware (`cargo xtask firmware`, `target-test`, `firmware --clippy`).
pub const FIRMWARE: CrossBuild = CrossBuild {
    what: "the firmware build",
    target: "thumbv7em-none-eabihf",
    parts: &[Part::Compiler, Part::CoreSource, Part::Lld, Part::Clippy],
    packages: &[
        "rustc-web",
        "cargo-web",
        "rust-web-src",
        "lld-22",
        "rust-web-clippy",
    ],
};

/// `tribo.exe` (`cargo xtask windows`); its linker is mingw's gcc, installed by that step.
pub const WINDOWS: CrossBuild = CrossBuild {
    what: "the Windows build",
    target: "x86_64-pc-windows-gnu",
    parts: &[Part::Compiler, Part::StdSource],
    packages: &["rustc-web", "cargo-web", "rust-web-src"],
};

/// What the machine has, as far as the choice goes.
#[derive(Debug, Clone, Default)]
pub struct Machine {
    /// Targets whose standard library the active rustup toolchain holds.
    pub rustup_targets: Vec<String>,
    /// The parts of Debian's toolchain that are installed.
    pub debian: Vec<Part>,
    /// apt-get is there and we are root.
    pub may_install: bool,
}

/// The choice for one cross-build.
#[derive(Debug, PartialEq, Eq)]
pub enum Choice {
    /// Build with rustup's toolchain: the target is installed.
    Rustup,
    /// Build with Debian's rustc and build-std: every part is there.
    Debian,
    /// Install these packages, then build with Debian's rustc.
    InstallDebian(&'static [&'static str]),
    /// Nothing can build it here; the message says what to do.
    Refuse(String),
}

/// The choice for `build` on `machine`.
pub fn choose(build: &CrossBuild, machine: &Machine) -> Choice {
    if machine.rustup_targets.iter().any(|t| t == build.target) {
        return Choice::Rustup;
    }
    if build.parts.iter().all(|p| machine.debian.contains(p)) {
        return Choice::Debian;
    }
    if machine.may_install {
        return Choice::InstallDebian(build.packages);
    }
    Choice::Refuse(format!(
        "no toolchain for {} ({}): rustup lacks the target and Debian's rustc-web is incomplete.\n  \
         → either `rustup target add {}`\n  \
         → or, on Debian, `sudo apt-get install -y {}` and run this again",
        build.target,
        build.what,
        build.target,
        build.packages.join(" ")
    ))
}

/// How a cross-build runs on this machine.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Toolchain {
    /// rustup's toolchain, which has the target.
    Rustup,
    /// Debian's `/usr/bin/cargo` and `/usr/bin/rustc`, building the standard library (build-std).
    Debian,
}

pub const DEBIAN_CARGO: &str = "/usr/bin/cargo";
pub const DEBIAN_RUSTC: &str = "/usr/bin/rustc";
const DEBIAN_LIBRARY: &str = "/usr/lib/rustlib/src/rust/library";
/// LLVM's multi-flavour linker from `lld-22`.
pub const DEBIAN_LLD: &str = "/usr/lib/llvm-22/bin/lld";

/// A folder (under `target_dir`) holding `rust-lld`, a link to Debian's lld.
///
/// The ARM targets name their linker `rust-lld`, which rustup ships inside its sysroot and Debian
/// does not ship at all; lld under that name takes the `-flavor gnu` rustc passes to it.
pub fn debian_linker_dir(target_dir: &Path) -> Result<PathBuf, String> {
    let dir = target_dir.join("linker");
    let link = dir.join("rust-lld");
    if std::fs::read_link(&link).is_ok_and(|t| t == Path::new(DEBIAN_LLD)) {
        return Ok(dir);
    }
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let _ = std::fs::remove_file(&link);
    #[cfg(unix)]
    std::os::unix::fs::symlink(DEBIAN_LLD, &link)
        .map_err(|e| format!("cannot link {} to {DEBIAN_LLD}: {e}", link.display()))?;
    #[cfg(not(unix))]
    return Err("Debian's toolchain is for Debian".into());
    Ok(dir)
}

/// Reads the machine.
pub fn machine() -> Machine {
    let mut debian = vec![];
    let has = |p: &str| Path::new(p).exists();
    if has(DEBIAN_CARGO) && has(DEBIAN_RUSTC) {
        debian.push(Part::Compiler);
    }
    if Path::new(DEBIAN_LIBRARY).join("core").is_dir() {
        debian.push(Part::CoreSource);
    }
    if Path::new(DEBIAN_LIBRARY).join("std").is_dir() {
        debian.push(Part::StdSource);
    }
    if has(DEBIAN_LLD) {
        debian.push(Part::Lld);
    }
    if has("/usr/bin/cargo-clippy") {
        debian.push(Part::Clippy);
    }
    Machine {
        rustup_targets: rustup_targets(),
        debian,
        may_install: apt::may_install(),
    }
}

/// The targets whose standard library is in the sysroot of `$RUSTC` (rustup's active toolchain).
fn rustup_targets() -> Vec<String> {
    let rustc = std::env::var_os("RUSTC").unwrap_or_else(|| "rustc".into());
    let Ok(out) = Command::new(rustc).args(["--print", "sysroot"]).output() else {
        return vec![];
    };
    if !out.status.success() {
        return vec![];
    }
    let rustlib = PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()).join("lib/rustlib");
    std::fs::read_dir(rustlib)
        .map(|rd| {
            rd.flatten()
                .filter(|e| e.path().join("lib").is_dir())
                .map(|e| e.file_name().to_string_lossy().into_owned())
                .collect()
        })
        .unwrap_or_default()
}

/// The toolchain for `build` here, installing Debian's packages first when that is the choice.
pub fn resolve(build: &CrossBuild) -> Result<Toolchain, String> {
    match choose(build, &machine()) {
        Choice::Rustup => Ok(Toolchain::Rustup),
        Choice::Debian => Ok(Toolchain::Debian),
        Choice::Refuse(msg) => Err(msg),
        Choice::InstallDebian(packages) => {
            eprintln!(
                "xtask: rustup has no {} target; {} uses Debian's rustc-web",
                build.target, build.what
            );
            apt::install(build.what, packages)?;
            match choose(build, &machine()) {
                Choice::Rustup | Choice::Debian => {}
                _ => {
                    return Err(format!(
                        "{} installed, but Debian's toolchain for {} is still incomplete \
                         (need /usr/bin/cargo, /usr/bin/rustc, {DEBIAN_LIBRARY}, and for the \
                         firmware rust-lld and cargo-clippy)",
                        packages.join(" "),
                        build.what
                    ))
                }
            }
            Ok(Toolchain::Debian)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_debian() -> Vec<Part> {
        vec![
            Part::Compiler,
            Part::CoreSource,
            Part::StdSource,
            Part::Lld,
            Part::Clippy,
        ]
    }

    fn machine(targets: &[&str], debian: Vec<Part>, root: bool) -> Machine {
        Machine {
            rustup_targets: targets.iter().map(|t| t.to_string()).collect(),
            debian,
            may_install: root,
        }
    }

    /// Issue 31's machine: rustup stable with the firmware's target, no Windows target, no
    /// Debian rustc. The firmware builds with rustup, and the Windows build must install
    /// Debian's toolchain itself (it used to start a `/usr/bin/cargo` that was not there).
    #[test]
    fn fresh_machine_with_the_firmware_target_installs_debian_for_windows() {
        let m = machine(&["x86_64-unknown-linux-gnu", FIRMWARE.target], vec![], true);
        assert_eq!(choose(&FIRMWARE, &m), Choice::Rustup);
        assert_eq!(
            choose(&WINDOWS, &m),
            Choice::InstallDebian(&["rustc-web", "cargo-web", "rust-web-src"])
        );
    }

    #[test]
    fn neither_target_in_rustup_each_build_installs_what_it_needs() {
        let m = machine(&["x86_64-unknown-linux-gnu"], vec![], true);
        assert_eq!(
            choose(&FIRMWARE, &m),
            Choice::InstallDebian(FIRMWARE.packages)
        );
        assert_eq!(
            choose(&WINDOWS, &m),
            Choice::InstallDebian(WINDOWS.packages)
        );
        // After the firmware's install, the Windows build finds everything it needs.
        let m = machine(&["x86_64-unknown-linux-gnu"], all_debian(), true);
        assert_eq!(choose(&FIRMWARE, &m), Choice::Debian);
        assert_eq!(choose(&WINDOWS, &m), Choice::Debian);
    }

    /// What the Windows build needs is not what the firmware needs: no linker or clippy of
    /// Debian's, but the whole `std` source; the firmware needs rust-lld and clippy.
    #[test]
    fn each_build_checks_its_own_parts() {
        let compiler_and_std = vec![Part::Compiler, Part::CoreSource, Part::StdSource];
        let m = machine(&[], compiler_and_std, true);
        assert_eq!(choose(&WINDOWS, &m), Choice::Debian);
        assert_eq!(
            choose(&FIRMWARE, &m),
            Choice::InstallDebian(FIRMWARE.packages)
        );
        let no_std = vec![Part::Compiler, Part::CoreSource, Part::Lld, Part::Clippy];
        let m = machine(&[], no_std, true);
        assert_eq!(choose(&FIRMWARE, &m), Choice::Debian);
        assert_eq!(
            choose(&WINDOWS, &m),
            Choice::InstallDebian(WINDOWS.packages)
        );
    }

    #[test]
    fn rustup_targets_win_over_debian() {
        let m = machine(&[WINDOWS.target, FIRMWARE.target], all_debian(), false);
        assert_eq!(choose(&FIRMWARE, &m), Choice::Rustup);
        assert_eq!(choose(&WINDOWS, &m), Choice::Rustup);
    }

    #[test]
    fn not_root_without_a_toolchain_is_told_what_to_run() {
        let m = machine(&[FIRMWARE.target], vec![Part::Compiler], false);
        match choose(&WINDOWS, &m) {
            Choice::Refuse(msg) => {
                assert!(
                    msg.contains("rustup target add x86_64-pc-windows-gnu"),
                    "{msg}"
                );
                assert!(
                    msg.contains("apt-get install -y rustc-web cargo-web rust-web-src"),
                    "{msg}"
                );
            }
            other => panic!("{other:?}"),
        }
    }

    /// The reading of rustup's targets finds the host's own (whatever else it holds).
    #[test]
    fn this_machine_lists_its_host_target() {
        let host = if cfg!(all(target_arch = "x86_64", target_os = "linux")) {
            "x86_64-unknown-linux-gnu"
        } else {
            return;
        };
        assert!(
            rustup_targets().iter().any(|t| t == host),
            "{:?}",
            rustup_targets()
        );
    }
}

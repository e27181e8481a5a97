//! `cargo xtask wheel [--release] [--test]`: the `tribo` Python package (`python/`).
//!
//! Builds the abi3 wheel (CPython ≥ 3.9) with maturin into `target/wheels/`, reusing the
//! workspace's target directory and, unless `--release`, its dev profile (whose dependencies are
//! optimised: see the workspace's `[profile.dev.package."*"]`), so CI does not build the whole
//! stack a second time. maturin itself comes from PyPI into a build venv (`target/py-build`).
//! `--test` then installs the wheel into a fresh virtual environment (`target/py-test`) with
//! what the tests need (pytest numpy pandas pyarrow duckdb polars) and runs `python/tests`
//! against the `tribo` binary of the same build. Needs `python3` with its `venv` module (Debian:
//! `python3-venv`).

use crate::{cargo, root, run};
use std::path::{Path, PathBuf};
use std::process::Command;

/// What the pytest suite needs besides the wheel.
const TEST_PACKAGES: [&str; 6] = ["pytest", "numpy", "pandas", "pyarrow", "duckdb", "polars"];

fn target_dir() -> PathBuf {
    std::env::var_os("CARGO_TARGET_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| root().join("target"))
}

fn python3() -> String {
    std::env::var("PYTHON").unwrap_or_else(|_| "python3".into())
}

fn venv_bin(venv: &Path, exe: &str) -> PathBuf {
    if cfg!(windows) {
        venv.join("Scripts").join(format!("{exe}.exe"))
    } else {
        venv.join("bin").join(exe)
    }
}

/// A virtual environment at `dir` (made fresh when `fresh`) with `packages` installed.
fn venv(dir: &Path, fresh: bool, packages: &[&str]) -> Result<PathBuf, String> {
    if fresh && dir.exists() {
        std::fs::remove_dir_all(dir)
            .map_err(|e| format!("cannot remove {}: {e}", dir.display()))?;
    }
    let py = venv_bin(dir, "python");
    if !py.exists() {
        run(Command::new(python3()).args(["-m", "venv"]).arg(dir)).map_err(|e| {
            format!(
                "{e}\n  → install Python 3.9+ with its venv module (Debian/Ubuntu: `sudo apt-get \
                 install python3-venv python3-pip`), or point $PYTHON at one"
            )
        })?;
    }
    if !packages.is_empty() {
        run(Command::new(&py)
            .args(["-m", "pip", "install", "-q", "--disable-pip-version-check"])
            .args(packages))
        .map_err(|e| format!("{e}\n  → PyPI must be reachable (or a pip mirror set up)"))?;
    }
    Ok(py)
}

/// Python with its `venv` and `ensurepip` modules (Debian splits them into `python3-venv`).
fn ensure_python() -> Result<(), String> {
    let usable = || {
        Command::new(python3())
            .args(["-c", "import venv, ensurepip"])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .status()
            .is_ok_and(|s| s.success())
    };
    crate::apt::ensure(&crate::apt::Need {
        what: "the Python wheel and its tests (python3 with venv and pip)",
        packages: &["python3", "python3-venv", "python3-pip"],
        present: &usable,
        otherwise: "or point $PYTHON at a Python 3.9+ that has its venv module",
    })
}

/// Builds the wheel; returns its path.
pub fn wheel(release: bool) -> Result<PathBuf, String> {
    ensure_python()?;
    let target = target_dir();
    let build = venv(&target.join("py-build"), false, &[])?;
    let maturin = venv_bin(&target.join("py-build"), "maturin");
    if !maturin.exists() {
        venv(&target.join("py-build"), false, &["maturin>=1.5,<2"])?;
    }
    let out = target.join("wheels");
    // Old wheels out of the way: the one built is the only one there.
    if let Ok(rd) = std::fs::read_dir(&out) {
        for e in rd.flatten() {
            if e.path().extension().is_some_and(|x| x == "whl") {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
    let t0 = std::time::Instant::now();
    // maturin says nothing while cargo compiles the extension (a minute or two): say what runs.
    eprintln!(
        "xtask: building the wheel with maturin ({} profile) into {}; compiling the extension takes \
         a minute or two, maturin reports when it is done",
        if release { "release" } else { "dev" },
        out.display()
    );
    let mut cmd = Command::new(&maturin);
    cmd.current_dir(root())
        .env("CARGO_TARGET_DIR", &target)
        .env("PYO3_PYTHON", &build)
        .args(["build", "--strip", "-m", "python/Cargo.toml", "-o"])
        .arg(&out);
    if release {
        cmd.arg("--release");
    } else {
        cmd.args(["--profile", "dev"]);
    }
    run(&mut cmd)?;
    let whl = std::fs::read_dir(&out)
        .map_err(|e| format!("cannot read {}: {e}", out.display()))?
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|x| x == "whl"))
        .ok_or_else(|| format!("maturin wrote no wheel into {}", out.display()))?;
    eprintln!(
        "wheel: {} ({:.1} s)",
        whl.display(),
        t0.elapsed().as_secs_f64()
    );
    Ok(whl)
}

/// Installs `whl` into a fresh venv and runs the package's pytest suite.
pub fn test(whl: &Path) -> Result<(), String> {
    let t0 = std::time::Instant::now();
    // The CLI the package must agree with, from the same build.
    run(cargo().args(["build", "-p", "tribo"]))?;
    let bin = target_dir()
        .join("debug")
        .join(if cfg!(windows) { "tribo.exe" } else { "tribo" });
    let whl_s = whl.display().to_string();
    let mut pkgs: Vec<&str> = vec![&whl_s];
    pkgs.extend(TEST_PACKAGES);
    let py = venv(&target_dir().join("py-test"), true, &pkgs)?;
    let t1 = std::time::Instant::now();
    run(Command::new(&py)
        .current_dir(root())
        .env("TRIBO_BIN", &bin)
        .args([
            "-m",
            "pytest",
            "-q",
            "-p",
            "no:cacheprovider",
            "python/tests",
        ]))?;
    eprintln!(
        "python: venv and packages {:.1} s, pytest {:.1} s",
        (t1 - t0).as_secs_f64(),
        t1.elapsed().as_secs_f64()
    );
    Ok(())
}

/// `cargo xtask wheel [--release] [--test]`.
pub fn wheel_cmd(args: &[String]) -> Result<(), String> {
    for a in args {
        if a != "--release" && a != "--test" {
            return Err(format!(
                "unknown argument {a:?}: `cargo xtask wheel [--release] [--test]`"
            ));
        }
    }
    let whl = wheel(args.iter().any(|a| a == "--release"))?;
    if args.iter().any(|a| a == "--test") {
        test(&whl)?;
    }
    Ok(())
}

/// CI's step: the dev-profile wheel, a fresh venv, the pytest suite.
pub fn ci() -> Result<(), String> {
    test(&wheel(false)?)
}

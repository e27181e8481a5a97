//! `cargo xtask windows`: cross-builds `tribo.exe` for `x86_64-pc-windows-gnu` with mingw-w64 and
//! runs a smoke test of it under Wine: `--help`, `sim`, `fit`, `devices`, the demo (a virtual rig in
//! the process), a virtual rig served over TCP by one `tribo.exe` and a run taken from it by
//! another, and the exit statuses of a usage error and of a rig that is not there.
//!
//! The toolchain: the rustup target when it is installed; otherwise Debian's rustc with
//! `RUSTC_BOOTSTRAP=1 -Z build-std=std,panic_abort` (as for the firmware), in a target directory of
//! its own. Either way the linker and C compiler (SQLite is compiled in) are Debian's
//! `x86_64-w64-mingw32-gcc`.

use crate::toolchain::{self, Toolchain};
use crate::{apt, cargo, run};
use std::io::{BufRead, BufReader, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const TARGET: &str = toolchain::WINDOWS.target;
const GCC: &str = "x86_64-w64-mingw32-gcc";
/// What the build and the smoke test need from Debian.
const PACKAGES: [&str; 3] = ["gcc-mingw-w64-x86-64", "wine", "wine64"];
/// Longest a single `tribo.exe` command may take under Wine.
const STEP_TIMEOUT: Duration = Duration::from_secs(240);

/// The mingw compiler (the linker, and the C compiler for the bundled SQLite) and Wine.
fn ensure_packages() -> Result<(), String> {
    apt::ensure(&apt::Need {
        what: "the Windows build and its smoke test",
        packages: &PACKAGES,
        present: &|| apt::answers(GCC, false) && apt::answers("wine", false),
        otherwise: "",
    })
}

/// The build command and its target directory.
fn build_command(root: &Path) -> Result<(Command, PathBuf, &'static str), String> {
    // Chosen for this target alone: the firmware's rustup target says nothing about Windows'.
    match toolchain::resolve(&toolchain::WINDOWS)? {
        Toolchain::Rustup => Ok((cargo(), root.join("target"), "rustup target")),
        Toolchain::Debian => {
            let mut c = Command::new(toolchain::DEBIAN_CARGO);
            c.current_dir(root)
                .env("RUSTC", toolchain::DEBIAN_RUSTC)
                .env("RUSTC_BOOTSTRAP", "1")
                .env_remove("RUSTDOC")
                .env_remove("RUSTC_WRAPPER")
                .env_remove("CARGO")
                .args(["-Z", "build-std=std,panic_abort"]);
            Ok((
                c,
                root.join("target/windows"),
                "Debian rustc + build-std=std,panic_abort",
            ))
        }
    }
}

/// Builds `tribo.exe`; returns its path.
fn build() -> Result<PathBuf, String> {
    ensure_packages()?;
    let root = crate::root();
    let (mut cmd, target_dir, how) = build_command(&root)?;
    let t0 = Instant::now();
    cmd.env("CARGO_TARGET_DIR", &target_dir)
        .env("CARGO_TARGET_X86_64_PC_WINDOWS_GNU_LINKER", GCC)
        .env("CC_x86_64_pc_windows_gnu", GCC)
        .env("AR_x86_64_pc_windows_gnu", "x86_64-w64-mingw32-ar")
        // No debug info: half the build time, and nobody debugs this copy.
        .env("CARGO_PROFILE_RELEASE_DEBUG", "0")
        .args([
            "build",
            "--release",
            "-p",
            "tribo",
            "--bin",
            "tribo",
            "--target",
            TARGET,
        ]);
    run(&mut cmd)?;
    let exe = target_dir.join(TARGET).join("release/tribo.exe");
    let size = std::fs::metadata(&exe)
        .map_err(|e| format!("{}: {e}", exe.display()))?
        .len();
    println!(
        "windows exe:  {} ({:.1} MiB)",
        exe.display(),
        size as f64 / 1048576.0
    );
    println!(
        "toolchain:    {how}, linker {GCC}; built in {:.0} s",
        t0.elapsed().as_secs_f64()
    );
    Ok(exe)
}

/// `cargo xtask windows [--no-smoke]`.
pub fn windows(args: &[String]) -> Result<(), String> {
    let exe = build()?;
    if args.iter().any(|a| a == "--no-smoke") {
        return Ok(());
    }
    smoke(&exe)
}

/// A copy of `tribo.exe` in a folder of its own, with the DLL stand-in Wine needs, run under Wine
/// in a throwaway prefix.
struct Wine {
    dir: PathBuf,
    prefix: PathBuf,
}

impl Wine {
    fn command(&self, args: &[&str]) -> Command {
        let mut c = Command::new("wine");
        c.arg("tribo.exe")
            .args(args)
            .current_dir(&self.dir)
            .env("WINEPREFIX", &self.prefix)
            .env("WINEDEBUG", "-all")
            // No Mono or Gecko installer when the prefix is made: a console program needs neither.
            .env("WINEDLLOVERRIDES", "mscoree,mshtml=")
            .env_remove("DISPLAY")
            .stdin(Stdio::null());
        c
    }

    /// Runs `tribo.exe args`, expecting exit status `code`; returns its stdout and stderr.
    fn expect(&self, args: &[&str], code: i32) -> Result<(String, String), String> {
        let mut cmd = self.command(args);
        let shown = format!("wine tribo.exe {}", args.join(" "));
        let t0 = Instant::now();
        let child = cmd
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|e| format!("cannot start wine: {e}"))?;
        let (status, out, err) =
            wait_with_timeout(child, STEP_TIMEOUT).map_err(|e| format!("`{shown}`: {e}"))?;
        eprintln!(
            "$ {shown}  → exit {} in {:.1} s",
            status.map_or("none".into(), |c| c.to_string()),
            t0.elapsed().as_secs_f64()
        );
        if status != Some(code) {
            return Err(format!(
                "`{shown}` exited with {status:?}, expected {code}\n--- stdout\n{out}\n--- stderr\n{err}"
            ));
        }
        Ok((out, err))
    }
}

/// Waits for `child` at most `limit`, collecting its output; kills it past the limit.
fn wait_with_timeout(
    mut child: Child,
    limit: Duration,
) -> Result<(Option<i32>, String, String), String> {
    fn drain(r: Option<impl Read + Send + 'static>) -> mpsc::Receiver<String> {
        let (tx, rx) = mpsc::channel();
        std::thread::spawn(move || {
            let mut s = String::new();
            if let Some(mut r) = r {
                let mut b = Vec::new();
                let _ = r.read_to_end(&mut b);
                s = String::from_utf8_lossy(&b).into_owned();
            }
            let _ = tx.send(s);
        });
        rx
    }
    let out = drain(child.stdout.take());
    let err = drain(child.stderr.take());
    let t0 = Instant::now();
    let status = loop {
        if let Some(s) = child.try_wait().map_err(|e| e.to_string())? {
            break s;
        }
        if t0.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            return Err(format!("still running after {} s: killed", limit.as_secs()));
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let get =
        |rx: mpsc::Receiver<String>| rx.recv_timeout(Duration::from_secs(10)).unwrap_or_default();
    Ok((status.code(), get(out), get(err)))
}

/// The smoke test of `exe` under Wine.
fn smoke(exe: &Path) -> Result<(), String> {
    let t0 = Instant::now();
    let root = crate::root();
    let base = exe
        .parent()
        .and_then(Path::parent)
        .and_then(Path::parent)
        .unwrap_or(&root);
    let wine = Wine {
        dir: base.join("wine-smoke"),
        prefix: base.join("wine-prefix"),
    };
    let _ = std::fs::remove_dir_all(&wine.dir);
    std::fs::create_dir_all(&wine.dir).map_err(|e| format!("{}: {e}", wine.dir.display()))?;
    std::fs::copy(exe, wine.dir.join("tribo.exe"))
        .map_err(|e| format!("copying tribo.exe: {e}"))?;
    let src = root.join("host/xtask/wine/bcryptprimitives.c");
    run(Command::new(GCC)
        .args(["-shared", "-O2", "-s", "-o"])
        .arg(wine.dir.join("bcryptprimitives.dll"))
        .arg(&src)
        .arg("-ladvapi32"))?;

    // One Wine server for all the steps (each would otherwise start its own, ~3 s apiece); the
    // first step fills the prefix.
    std::fs::create_dir_all(&wine.prefix).map_err(|e| format!("{}: {e}", wine.prefix.display()))?;
    let _ = Command::new("wineserver")
        .arg("-p")
        .env("WINEPREFIX", &wine.prefix)
        .status();
    let result = smoke_steps(&wine);
    // Whatever happened: no Wine process of this prefix is left behind.
    let _ = Command::new("wineserver")
        .arg("-k")
        .env("WINEPREFIX", &wine.prefix)
        .status();
    result?;
    println!(
        "windows smoke test under Wine: passed in {:.0} s ({})",
        t0.elapsed().as_secs_f64(),
        wine.dir.display()
    );
    Ok(())
}

fn smoke_steps(wine: &Wine) -> Result<(), String> {
    let check = |ok: bool, what: &str, out: &str| -> Result<(), String> {
        if ok {
            Ok(())
        } else {
            Err(format!("{what}\n--- output\n{out}"))
        }
    };
    // --help (the first start also makes the Wine prefix).
    let (out, _) = wine.expect(&["--help"], 0)?;
    check(
        out.contains("tribometer") && out.contains("demo"),
        "--help does not describe tribo",
        &out,
    )?;

    // sim → fit: the fitted law is the simulated one, to the thesis's precision.
    let (mu0, mu1) = (0.015, 0.003);
    let mu = format!("{mu0},{mu1}");
    wine.expect(&["sim", "--mu", &mu, "--noise", "-o", "rec.csv"], 0)?;
    let (out, _) = wine.expect(&["fit", "rec.csv", "--json"], 0)?;
    let v: serde_json::Value = serde_json::from_str(out.trim())
        .map_err(|e| format!("`fit --json` printed no JSON ({e}):\n{out}"))?;
    let fitted: Vec<f64> = v["mu"]
        .as_array()
        .map(|a| a.iter().filter_map(|x| x.as_f64()).collect())
        .unwrap_or_default();
    check(
        v["converged"] == true
            && fitted.len() == 2
            && (fitted[0] - mu0).abs() < 1e-3
            && (fitted[1] - mu1).abs() < 2e-4,
        &format!("the Windows fit of a simulated μ0 = {mu0}, μ1 = {mu1} record is off"),
        &out,
    )?;

    // The serial ports, as Windows lists them.
    wine.expect(&["devices", "--all"], 0)?;

    // The demo: a virtual rig in the process, a run through the link, stored, fitted, drawn.
    let (out, _) = wine.expect(
        &["demo", "--out", "demo-out", "--speed", "20", "--quiet"],
        0,
    )?;
    check(
        out.contains("complete"),
        "the demo's run is not complete",
        &out,
    )?;
    check(
        wine.dir.join("demo-out/report/report.html").is_file(),
        "the demo wrote no report",
        &out,
    )?;

    // A virtual rig on TCP in one tribo.exe, a run from another.
    rig_and_run(wine)?;

    // Exit statuses: a usage error is 2, a rig that is not there 1 with a sentence saying why.
    wine.expect(&["sim"], 2)?;
    let (_, err) = wine.expect(&["run", "--port", "tcp://127.0.0.1:1", "--load", "0.3"], 1)?;
    check(
        err.contains("nothing listens"),
        "no clear error for a missing rig",
        &err,
    )?;
    Ok(())
}

/// `tribo.exe rig --virtual` on a free port, and `tribo.exe run --port tcp://…` against it.
fn rig_and_run(wine: &Wine) -> Result<(), String> {
    let mut rig = wine
        .command(&[
            "rig",
            "--virtual",
            "--listen",
            "127.0.0.1:0",
            "--speed",
            "20",
        ])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .map_err(|e| format!("cannot start wine: {e}"))?;
    eprintln!("$ wine tribo.exe rig --virtual --listen 127.0.0.1:0 --speed 20 &");
    let (tx, rx) = mpsc::channel();
    let stdout = rig.stdout.take().expect("piped");
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if let Some(i) = line.find("tcp://") {
                let _ = tx.send(line[i..].trim().to_string());
            }
        }
    });
    let result = (|| {
        let addr = rx
            .recv_timeout(Duration::from_secs(120))
            .map_err(|_| "`tribo.exe rig --virtual` never printed its address".to_string())?;
        let (out, err) = wine.expect(
            &[
                "run", "--port", &addr, "--load", "0.3", "--store", "runs", "--quiet",
            ],
            0,
        )?;
        if out.contains("(complete") {
            Ok(())
        } else {
            Err(format!("the run over TCP is not complete\n{out}\n{err}"))
        }
    })();
    let _ = rig.kill();
    let _ = rig.wait();
    result
}

//! Project automation, run as `cargo xtask <task>`.
//!
//! * `cargo xtask firmware [--run | --clippy]`: builds the release firmware ELF for
//!   `thumbv7em-none-eabihf` and prints its flash and RAM use (`--clippy`: lints the board binary and
//!   the crates under it for the target instead, `-D warnings`; on the host the board is an empty
//!   stub, so the workspace clippy does not see its code). Uses the rustup target when it is
//!   installed; otherwise Debian's `rustc-web`/`cargo-web`/`rust-web-src`/`lld-22` with
//!   `RUSTC_BOOTSTRAP=1 -Z build-std=core` (see [`toolchain`]).
//! * `cargo xtask target-test [FILTER]`: the on-target tests (`firmware/target-tests`): generates
//!   the record bundle on the host, builds the test binary for the Cortex-M7 with the firmware's
//!   flags and profile, runs it under QEMU (`qemu-system-arm -machine mps2-an500 -icount shift=0`)
//!   and fails unless every test passed within its budgets.
//! * `cargo xtask windows [--no-smoke]`: cross-builds `tribo.exe` for `x86_64-pc-windows-gnu` and
//!   runs its smoke test under Wine (see [`windows`]).
//! * `cargo xtask soak [RUNS] [SEED]`: the soak (`tests/soak.rs`): RUNS runs (default 1000) against
//!   one virtual rig through a faulty line (or two hosts racing for it over TCP), a fault drawn at
//!   random for each, every stored run checked against the rig's own copy; prints the figures
//!   (runs, faults by kind, runs stored, intact, honestly incomplete, mixed, races and how they
//!   ended). CI runs a short one with the other tests.
//! * `cargo xtask fuzz [RUNS]`: each libFuzzer target of the wire crate (`firmware/wire/fuzz`:
//!   the frame decoder, the codec) for RUNS executions (default 10 000 000), with cargo-fuzz
//!   (installed from crates.io when missing) on the machine's toolchain (`RUSTC_BOOTSTRAP=1`);
//!   prints each target's count and time. Not in CI (minutes per target).
//! * `cargo xtask wheel [--release] [--test]`: the Python package's wheel (see [`python`]).
//! * `cargo xtask ci`: everything CI checks: rustfmt, clippy `-D warnings`, every test, the lab
//!   catalog against a real PostgreSQL, the panel in headless chromium, the Python wheel and its
//!   pytest suite, the firmware, the on-target tests, the Windows build and its smoke test.
//!
//! Every step installs what it needs and lacks (Debian's packages, as root; see [`apt`]), whatever
//! the steps before it did or found, and says what it installs; `ci` lists it all at the end.
//! Elsewhere a step that lacks something stops and names the command that brings it.

mod apt;
mod elf;
mod frames;
mod memory;
mod panel;
mod postgres;
mod python;
mod qemu;
mod toolchain;
mod windows;

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode};
use toolchain::Toolchain;

const TARGET: &str = toolchain::FIRMWARE.target;
const BOARD: &str = "tribo-board";
const TARGET_TESTS: &str = "tribo-target-tests";
const PROFILE: &str = "firmware";
/// Least the AXI SRAM must leave after the static data: the task stack (PSP, growing down from its
/// end) and its guard below it.
const MIN_STACK: u64 =
    (tribo_firmware::stack::MIN_TASK_STACK_BYTES + tribo_firmware::stack::TASK_GUARD_BYTES) as u64;
/// Frames printed by `cargo xtask firmware`.
const FRAMES_SHOWN: usize = 8;

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let result = match args.first().map(String::as_str) {
        Some("firmware") => firmware(&args[1..]).map(|_| ()),
        Some("target-test") => target_test(&args[1..]),
        Some("windows") => windows::windows(&args[1..]),
        Some("soak") => soak(&args[1..]),
        Some("fuzz") => fuzz(&args[1..]),
        Some("wheel") => python::wheel_cmd(&args[1..]),
        Some("ci") => ci(),
        _ => {
            eprintln!(
                "usage: cargo xtask <task>\n\n\
                 tasks:\n  \
                 firmware [--run | --clippy]\n                     \
                 build the STM32H743 firmware ELF and print its size\n                     \
                 (--run: flash it with probe-rs and show the defmt log;\n                     \
                 --clippy: lint the board and the crates under it for the target)\n  \
                 target-test [FILTER]\n                     \
                 run the on-target tests on an emulated Cortex-M7 (QEMU; Debian package\n                     \
                 qemu-system-arm); FILTER runs only the tests whose name contains it\n  \
                 fuzz [RUNS]        each wire fuzz target for RUNS executions (default 10 M)\n  \
                 soak [RUNS] [SEED]\n                     \
                 the soak: RUNS runs (default 1000) through a faulty line, random faults,\n                     \
                 every stored run checked against the rig's own copy\n  \
                 windows [--no-smoke]\n                     \
                 cross-build tribo.exe (mingw-w64) and smoke-test it under Wine\n  \
                 wheel [--release] [--test]\n                     \
                 build the Python package's wheel (maturin); --test: its pytest suite\n  \
                 ci                 rustfmt, clippy -D warnings, all tests, firmware build,\n                     \
                 on-target tests, Windows build and smoke test"
            );
            return ExitCode::from(2);
        }
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("xtask: {e}");
            ExitCode::FAILURE
        }
    }
}

/// `cargo xtask fuzz [RUNS]`.
fn fuzz(args: &[String]) -> Result<(), String> {
    let runs = args.first().map_or("10000000", String::as_str);
    if runs.parse::<u64>().is_err() {
        return Err(format!("RUNS must be a whole number, got {runs:?}"));
    }
    let has_fuzz = cargo()
        .args(["fuzz", "--version"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !has_fuzz {
        run(cargo().args(["install", "cargo-fuzz", "--locked"]))?;
    }
    let dir = root().join("firmware/wire");
    for target in ["decoder", "codec"] {
        let t0 = std::time::Instant::now();
        let out = cargo()
            .current_dir(&dir)
            .env("RUSTC_BOOTSTRAP", "1")
            .args(["fuzz", "run", "-O", target, "--"])
            .arg(format!("-runs={runs}"))
            .output()
            .map_err(|e| format!("cargo fuzz: {e}"))?;
        let log = String::from_utf8_lossy(&out.stderr);
        if !out.status.success() {
            return Err(format!(
                "fuzz target {target} failed (its crash input is under firmware/wire/fuzz/artifacts):\n{}",
                log.lines().rev().take(30).collect::<Vec<_>>().join("\n")
            ));
        }
        let done = log
            .lines()
            .find(|l| l.starts_with("Done "))
            .unwrap_or("(no summary line)");
        eprintln!(
            "fuzz {target}: {done} ({:.0} s in all)",
            t0.elapsed().as_secs_f64()
        );
    }
    Ok(())
}

/// `cargo xtask soak [RUNS] [SEED]`.
fn soak(args: &[String]) -> Result<(), String> {
    let runs = args.first().map_or("1000", String::as_str);
    let seed = args.get(1).map_or("1", String::as_str);
    for (what, v) in [("RUNS", runs), ("SEED", seed)] {
        if v.parse::<u64>().is_err() {
            return Err(format!("{what} must be a whole number, got {v:?}"));
        }
    }
    run(cargo()
        .args([
            "test",
            "--release",
            "-p",
            "tribo-tests",
            "--test",
            "soak",
            "--",
            "--nocapture",
        ])
        .env("SOAK_RUNS", runs)
        .env("SOAK_SEED", seed))
}

fn kib(bytes: u64) -> f64 {
    bytes as f64 / 1024.0
}

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("workspace root")
}

fn run(cmd: &mut Command) -> Result<(), String> {
    eprintln!("$ {}", show(cmd));
    let status = cmd
        .status()
        .map_err(|e| format!("cannot start {}: {e}", show(cmd)))?;
    if status.success() {
        Ok(())
    } else {
        Err(format!("`{}` failed ({status})", show(cmd)))
    }
}

pub(crate) fn show(cmd: &Command) -> String {
    let mut s: Vec<String> = cmd
        .get_envs()
        .filter_map(|(k, v)| Some(format!("{}={}", k.to_str()?, v?.to_str()?)))
        .collect();
    s.push(cmd.get_program().to_string_lossy().into_owned());
    s.extend(cmd.get_args().map(|a| a.to_string_lossy().into_owned()));
    s.join(" ")
}

fn cargo() -> Command {
    let mut c = Command::new(std::env::var_os("CARGO").unwrap_or_else(|| "cargo".into()));
    c.current_dir(root());
    c
}

fn ci() -> Result<(), String> {
    run(cargo().args(["fmt", "--all", "--", "--check"]))
        .map_err(|e| format!("{e}\n  → run `cargo fmt --all` and commit the result"))?;
    run(cargo().args([
        "clippy",
        "--workspace",
        "--all-targets",
        "--",
        "-D",
        "warnings",
    ]))?;
    postgres::ensure()?;
    run(cargo().args(["test", "--workspace", "--no-fail-fast"]))?;
    panel::browser_tests()?;
    python::ci()?;
    firmware(&[])?;
    firmware(&["--clippy".to_string()])?;
    target_test(&[])?;
    windows::windows(&[])?;
    let installed = apt::installed();
    if installed.is_empty() {
        eprintln!("xtask ci: passed; nothing was installed");
    } else {
        eprintln!(
            "xtask ci: passed; installed on the way (Debian packages): {}",
            installed.join(" ")
        );
    }
    Ok(())
}

pub(crate) fn is_root() -> bool {
    Command::new("id")
        .arg("-u")
        .output()
        .map(|o| String::from_utf8_lossy(&o.stdout).trim() == "0")
        .unwrap_or(false)
}

/// A cargo command for the ARM target with `toolchain`, and the target directory it uses.
fn cross_cargo(toolchain: &Toolchain) -> Result<(Command, PathBuf), String> {
    let root = root();
    let (mut cmd, target_dir) = match toolchain {
        Toolchain::Rustup => {
            let dir = root.join("target");
            (cargo(), dir)
        }
        Toolchain::Debian => {
            // A target directory of its own: another compiler, another standard library.
            let dir = root.join("target/debian-build-std");
            let linker = toolchain::debian_linker_dir(&dir)?;
            let mut c = Command::new(toolchain::DEBIAN_CARGO);
            c.current_dir(&root)
                .env("RUSTC", toolchain::DEBIAN_RUSTC)
                .env("RUSTC_BOOTSTRAP", "1")
                .env_remove("RUSTDOC")
                .env_remove("RUSTC_WRAPPER")
                .env_remove("CARGO")
                // `cargo clippy` finds `cargo-clippy` on the PATH: Debian's, beside this cargo,
                // not rustup's proxy (which would lint with a toolchain that has no ARM `core`);
                // the target's linker, `rust-lld`, is LLVM's lld under that name.
                .env("PATH", debian_first_path(&linker));
            // `-Z build-std=core` as configuration, so that it reaches the cargo that
            // `cargo clippy` runs too (a `-Z` before the subcommand would stay with the outer one).
            c.env("CARGO_UNSTABLE_BUILD_STD", "core");
            (c, dir)
        }
    };
    cmd.env("CARGO_TARGET_DIR", &target_dir);
    Ok((cmd, target_dir))
}

/// `PATH` with `linker` (the folder of `rust-lld`) and `/usr/bin` first.
fn debian_first_path(linker: &Path) -> std::ffi::OsString {
    let rest = std::env::var_os("PATH").unwrap_or_default();
    let mut dirs = vec![linker.to_path_buf(), PathBuf::from("/usr/bin")];
    dirs.extend(std::env::split_paths(&rest));
    std::env::join_paths(dirs).unwrap_or(rest)
}

fn firmware(args: &[String]) -> Result<PathBuf, String> {
    let flash = args.iter().any(|a| a == "--run");
    let lint = args.iter().any(|a| a == "--clippy");
    let toolchain = toolchain::resolve(&toolchain::FIRMWARE)?;
    let (mut cmd, target_dir) = cross_cargo(&toolchain)?;
    let task = match (lint, flash) {
        (true, _) => "clippy",
        (false, true) => "run",
        (false, false) => "build",
    };
    cmd.args([task, "-p", BOARD, "--target", TARGET, "--profile", PROFILE]);
    if lint {
        cmd.args(["--", "-D", "warnings"]);
        run(&mut cmd).map_err(|e| {
            format!("{e}\n  → the firmware has clippy findings for {TARGET} (listed above)")
        })?;
        println!("clippy: {BOARD} and the crates under it are clean for {TARGET}");
        return Ok(target_dir);
    }
    run(&mut cmd)?;
    let elf_path = target_dir.join(TARGET).join(PROFILE).join(BOARD);
    let bytes = std::fs::read(&elf_path).map_err(|e| format!("{}: {e}", elf_path.display()))?;
    let size = elf::size(&bytes).map_err(|e| format!("{}: {e}", elf_path.display()))?;
    println!("firmware ELF: {}", elf_path.display());
    println!(
        "toolchain:    {}",
        match toolchain {
            Toolchain::Rustup => "rustup target",
            Toolchain::Debian => "Debian rustc-web + build-std=core",
        }
    );
    println!(
        "flash: {:>8} bytes ({:.1} KiB; text {} + rodata {} + data {} + vectors {})",
        size.flash(),
        kib(size.flash()),
        size.text,
        size.rodata,
        size.data,
        size.vectors,
    );
    let memory_x = root().join("memory.x");
    let text =
        std::fs::read_to_string(&memory_x).map_err(|e| format!("{}: {e}", memory_x.display()))?;
    let regions = memory::regions(&text)?;
    let sections = elf::sections(&bytes).map_err(|e| format!("{}: {e}", elf_path.display()))?;
    let mut used = memory::usage(&regions, &sections);
    let mut over = vec![];
    println!("memory regions (memory.x):");
    for (r, u) in regions.iter().zip(used.iter_mut()) {
        let note = match r.name.as_str() {
            "FLASH" => {
                // .data's initial values are stored in flash too.
                *u = size.flash();
                "code, constants, .data's initial values (bank 1)".to_string()
            }
            "RAM" => {
                let stack = r.length.saturating_sub(*u);
                if stack < MIN_STACK {
                    over.push(format!(
                        "RAM leaves {:.1} KiB for the stack, less than {} KiB",
                        kib(stack),
                        MIN_STACK / 1024
                    ));
                }
                format!(
                    ".data, .bss, .uninit; the task stack (PSP) has the other {:.1} KiB, \
                     its lowest {} KiB (aligned) the MPU guard",
                    kib(stack),
                    tribo_firmware::stack::TASK_GUARD_BYTES / 1024
                )
            }
            "MSP_STACK" => {
                *u = r.length;
                "the handlers' stack (MSP: interrupts, HardFault, NMI)".to_string()
            }
            _ => String::new(),
        };
        if *u > r.length {
            over.push(format!("{} is over its size", r.name));
        }
        println!(
            "  {:<6} {:>8.1} KiB of {:>6.0} KiB ({:>5.1} %)  {note}",
            r.name,
            kib(*u),
            kib(r.length),
            100.0 * *u as f64 / r.length.max(1) as f64,
        );
    }
    println!("  bank 2 of the flash (0x0810_0000, 1024 KiB): the run store, written at run time");
    // No frame may step over the task stack's guard (no stack probes on thumbv7em).
    let guard = tribo_firmware::stack::TASK_GUARD_BYTES;
    let frames = frames::frames(&bytes).map_err(|e| format!("{}: {e}", elf_path.display()))?;
    println!(
        "largest stack frames (every SP decrement of the function summed; guard {guard} bytes):"
    );
    for f in frames.iter().take(FRAMES_SHOWN) {
        println!("  {:>6} B  {:#010x}  {}", f.bytes, f.addr, f.name);
    }
    for f in &frames {
        if f.bytes > guard {
            over.push(format!(
                "the frame of {} ({} B) is larger than the task stack's guard ({guard} B): an \
                 overflow there could step over it (make the frame smaller or the guard larger, \
                 tribo_firmware::stack::TASK_GUARD_BYTES)",
                f.name, f.bytes
            ));
        }
        if f.unknown {
            over.push(format!(
                "{} moves SP down by a register the frame reader cannot size: check its frame \
                 against the guard by hand (host/xtask/src/frames.rs)",
                f.name
            ));
        }
    }
    if !over.is_empty() {
        return Err(over.join("; "));
    }
    Ok(elf_path)
}

/// The on-target tests (see the module docs): bundle, cross-build, QEMU.
fn target_test(args: &[String]) -> Result<(), String> {
    let filter = match args {
        [] => "",
        [f] if !f.starts_with('-') => f.as_str(),
        _ => return Err("usage: cargo xtask target-test [FILTER]".into()),
    };
    apt::ensure(&apt::Need {
        what: "the on-target tests",
        packages: &["qemu-system-arm"],
        present: &|| qemu::find().is_ok(),
        otherwise: "",
    })?;
    let qemu = qemu::find()?;
    let started = std::time::Instant::now();
    let bytes = tribo_target_tests::generate::bundle()
        .map_err(|e| format!("generating the record bundle: {e}"))?;
    let dir = root().join("target/target-tests");
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let bundle = dir.join("bundle.bin");
    // Rewritten only when it changed, so that an unchanged bundle does not relink the binary.
    if std::fs::read(&bundle).ok().as_deref() != Some(&bytes[..]) {
        std::fs::write(&bundle, &bytes).map_err(|e| format!("{}: {e}", bundle.display()))?;
    }
    eprintln!(
        "xtask: record bundle {} ({:.0} KiB) generated in {:.1} s",
        bundle.display(),
        bytes.len() as f64 / 1024.0,
        started.elapsed().as_secs_f64()
    );
    let toolchain = toolchain::resolve(&toolchain::FIRMWARE)?;
    let (mut cmd, target_dir) = cross_cargo(&toolchain)?;
    cmd.env("TRIBO_TARGET_BUNDLE", &bundle).args([
        "build",
        "-p",
        TARGET_TESTS,
        "--target",
        TARGET,
        "--profile",
        PROFILE,
    ]);
    run(&mut cmd)?;
    let elf = target_dir.join(TARGET).join(PROFILE).join(TARGET_TESTS);
    // The fatal tests (a panic, a HardFault) end their run in the handler: one QEMU each, after
    // the others.
    let fatal: Vec<&str> = tribo_target_tests::fatal::FATAL
        .iter()
        .map(|(name, _)| *name)
        .filter(|name| name.contains(filter))
        .collect();
    let ordinary = tribo_target_tests::tests::TESTS
        .iter()
        .any(|t| t.name.contains(filter));
    if ordinary || fatal.is_empty() {
        qemu::run(&qemu, &elf, filter)?;
    }
    for name in fatal {
        qemu::run(&qemu, &elf, name)?;
    }
    Ok(())
}

//! Benchmark of the host's fits (issue #37): times, in this process, `tribo fit --law quadratic` on
//! the 40 s record (400 001 samples: `tribo sim --law coulomb-viscous --mu 0.0008,0.0011
//! --load-n 0.05 --duration-s 40`, the light-friction record of `physics-bench`), the same fit on a
//! 2 s bench record (`tribo sim --law quadratic --mu 0.02,0.01,0.002 --duration-s 2 --noise
//! --held-s 0.2 --dropouts-per-s 5`) and `tribo explain` on a 2 s record with two effects (a μ2
//! term and a 3 ms force-channel lag: `tribo sim --law quadratic --mu 0.02,0.01,0.004
//! --duration-s 2 --noise --force-lag-s 0.003`), then prints the process's peak memory. Each is
//! run `--repeat N` times (default 3) and its fastest and slowest times printed.
//!
//! `--scipy` also times the SciPy peer (`host/physics/bench/scipy_fit.py`, solve_ivp +
//! least_squares) on the 40 s record: it takes minutes.
//!
//! `cargo run --release -p tribo --example fit_bench -- [--repeat N] [--scipy]`

use std::time::Instant;
use tribo::simulate::{simulate, SimOptions};
use tribo_physics::identify::{fit, FitOptions, LawSpec};
use tribo_physics::Record;

fn record(o: SimOptions) -> Record {
    simulate(&o).expect("the benchmark's record simulates").0
}

/// Fastest and slowest of `n` runs of `f`, in seconds, and the last result.
fn time<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, f64, T) {
    let (mut lo, mut hi) = (f64::INFINITY, 0.0f64);
    let mut last = None;
    for _ in 0..n.max(1) {
        let t0 = Instant::now();
        last = Some(f());
        let dt = t0.elapsed().as_secs_f64();
        lo = lo.min(dt);
        hi = hi.max(dt);
    }
    (lo, hi, last.expect("run at least once"))
}

/// Peak resident memory of this process (kB), from /proc/self/status (Linux).
fn peak_kb() -> Option<u64> {
    let s = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = s.lines().find(|l| l.starts_with("VmHWM:"))?;
    line.split_whitespace().nth(1)?.parse().ok()
}

fn main() {
    let mut repeat = 3usize;
    let mut scipy = false;
    let mut args = std::env::args().skip(1);
    while let Some(a) = args.next() {
        match a.as_str() {
            "--repeat" => {
                repeat = args
                    .next()
                    .and_then(|s| s.parse().ok())
                    .expect("--repeat N: a whole number")
            }
            "--scipy" => scipy = true,
            other => panic!("unknown argument {other} (--repeat N, --scipy)"),
        }
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    println!("{threads} cores; each figure: fastest and slowest of {repeat} runs, in this process");

    let long = record(SimOptions {
        law: LawSpec::CoulombViscous,
        mu: vec![0.0008, 0.0011],
        load_n: 0.05,
        duration_s: 40.0,
        ..SimOptions::default()
    });
    let opts = FitOptions::default();
    let (lo, hi, r) = time(repeat, || {
        fit(&long, LawSpec::Quadratic, &opts).expect("the 40 s record fits")
    });
    println!(
        "fit quadratic, 40 s record ({} samples): {lo:.3}–{hi:.3} s  mu = {:?}  {} iterations, {}",
        long.len(),
        r.mu,
        r.iterations,
        r.verdict.name()
    );

    let bench = record(SimOptions {
        law: LawSpec::Quadratic,
        mu: vec![0.02, 0.01, 0.002],
        duration_s: 2.0,
        noise: true,
        held_s: 0.2,
        dropouts_per_s: 5.0,
        ..SimOptions::default()
    });
    let (lo, hi, r) = time(repeat, || {
        fit(&bench, LawSpec::Quadratic, &opts).expect("the bench record fits")
    });
    println!(
        "fit quadratic, 2 s bench record ({} samples): {lo:.3}–{hi:.3} s  mu = {:?}  {}",
        bench.len(),
        r.mu,
        r.verdict.name()
    );

    let two = record(SimOptions {
        law: LawSpec::Quadratic,
        mu: vec![0.02, 0.01, 0.004],
        duration_s: 2.0,
        noise: true,
        force_lag_s: 0.003,
        ..SimOptions::default()
    });
    let eo = tribo_explain::ExplainOptions::default();
    let (lo, hi, e) = time(repeat, || {
        tribo_explain::explain(&two, &eo).expect("the two-effect record is explained")
    });
    println!(
        "explain, 2 s record with a μ2 term and a 3 ms force lag: {lo:.3}–{hi:.3} s  {}, named: [{}]",
        e.conclusion.name(),
        e.missing_effects.join(", ")
    );
    match peak_kb() {
        Some(kb) => println!("peak memory (VmHWM): {:.1} MB", kb as f64 / 1024.0),
        None => println!("peak memory: unknown (no /proc/self/status)"),
    }

    if !scipy {
        println!("(SciPy peer not run: pass --scipy, it takes minutes)");
        return;
    }
    let dir = std::env::temp_dir().join(format!("tribo-fit-bench-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary directory");
    let csv = dir.join("rec40.csv");
    long.save(&csv).expect("the 40 s record is written");
    let script = concat!(env!("CARGO_MANIFEST_DIR"), "/physics/bench/scipy_fit.py");
    let t0 = Instant::now();
    match std::process::Command::new("python3")
        .arg(script)
        .arg(&csv)
        .output()
    {
        Ok(out) if out.status.success() => {
            print!("{}", String::from_utf8_lossy(&out.stdout));
            println!(
                "scipy peer, whole process on the 40 s record: {:.1} s",
                t0.elapsed().as_secs_f64()
            );
        }
        Ok(out) => println!(
            "scipy peer failed: {}",
            String::from_utf8_lossy(&out.stderr)
                .lines()
                .last()
                .unwrap_or("")
        ),
        Err(e) => println!("scipy peer: python3 not available ({e})"),
    }
    let _ = std::fs::remove_dir_all(&dir);
}

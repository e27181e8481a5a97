//! The release instant measured from the motion ([`tribo_explain::release`]) against the
//! generator's, over every held record of a grid (`support/lhs.rs`, the independent generator):
//! its error in samples, its ± and how often the truth is within 2σ and 3σ, by window length.
//! It is the measurement's own benchmark; explain then fits the instant in every model under it.
//!
//! `cargo run --release -p tribo-explain --example release_instant -- [--records N] [--seed S]
//! [--max-s T] [--windows 0.6,1,1.5] [--verbose]`

#[path = "../tests/support/mod.rs"]
mod support;

use tribo_explain::release::{release_from_motion_over, RELEASE_WINDOW_RAD};

fn main() {
    let mut records = 520usize;
    let mut seed = 1u64;
    let mut max_s = 25.0f64;
    let mut windows = vec![RELEASE_WINDOW_RAD];
    let mut verbose = false;
    let args: Vec<String> = std::env::args().skip(1).collect();
    let mut it = args.iter();
    while let Some(a) = it.next() {
        let mut value = |name: &str| -> String {
            it.next()
                .cloned()
                .unwrap_or_else(|| fail(&format!("{name} needs a value")))
        };
        match a.as_str() {
            "--records" => records = value(a).parse().unwrap_or_else(|_| fail("--records N")),
            "--seed" => seed = value(a).parse().unwrap_or_else(|_| fail("--seed S")),
            "--max-s" => max_s = value(a).parse().unwrap_or_else(|_| fail("--max-s T")),
            "--windows" => {
                windows = value(a)
                    .split(',')
                    .map(|w| {
                        w.parse()
                            .unwrap_or_else(|_| fail("--windows 0.6,1,1.5 (rad)"))
                    })
                    .collect()
            }
            "--verbose" => verbose = true,
            "-h" | "--help" => {
                println!(
                    "release_instant [--records N] [--seed S] [--max-s T] [--windows W,..] \
                     [--verbose]: the release instant measured from the motion on every held \
                     record of the grid, against the generator's"
                );
                return;
            }
            other => fail(&format!("unknown argument {other:?} (see --help)")),
        }
    }
    let cases = support::lhs::grid_with(records, seed, max_s);
    let held: Vec<_> = cases.iter().filter(|c| c.bench.hold_s > 0.0).collect();
    println!(
        "{} held records of {records} (seed {seed}); errors in samples, the truth the generator's \
         release (the hold's end)",
        held.len()
    );
    // Per window: (|error| in samples, |z|) of each record, and the records with no fit.
    let mut out: Vec<(Vec<(f64, f64)>, usize)> = vec![(Vec::new(), 0); windows.len()];
    for c in &held {
        let rec = c.record();
        let (tau, y, yd) = rec.dimensionless().expect("a grid record is valid");
        let start = tribo_physics::identify::motion_span(&tau, &y, &yd).start;
        let rig = rec.rig().expect("a grid record states its rig");
        let truth = tau[0] + rig.tau_of_t(c.bench.hold_s);
        let dtau = tau[1] - tau[0];
        for (k, &w) in windows.iter().enumerate() {
            match release_from_motion_over(&tau, &y, &yd, start, w) {
                Some(f) => {
                    let (err, se) = ((f.tau - truth) / dtau, f.se / dtau);
                    out[k].0.push((err.abs(), (err / se).abs()));
                    if verbose {
                        println!(
                            "#{} {} window {w} rad: {err:+.3} ± {se:.3} samples (χ²/dof {:.2}, \
                             ω {:.4})",
                            c.index,
                            c.label(),
                            f.chi2_dof,
                            f.omega
                        );
                    }
                }
                None => {
                    out[k].1 += 1;
                    if verbose {
                        println!("#{} {} window {w} rad: no fit", c.index, c.label());
                    }
                }
            }
        }
    }
    println!("window (rad)  fitted  no fit  |z|≤2    |z|≤3    median |err|  90 % |err|  max |err|");
    for (w, (v, none)) in windows.iter().zip(&out) {
        if v.is_empty() {
            println!("{w:<12}  0       {none}");
            continue;
        }
        let n = v.len() as f64;
        let within = |k: f64| v.iter().filter(|(_, z)| *z <= k).count() as f64 / n;
        let mut e: Vec<f64> = v.iter().map(|(e, _)| *e).collect();
        e.sort_by(f64::total_cmp);
        let q = |p: f64| e[((p * (e.len() - 1) as f64).round() as usize).min(e.len() - 1)];
        println!(
            "{w:<12}  {:<6}  {none:<6}  {:<7.1}  {:<7.1}  {:<12.3}  {:<10.3}  {:.3}",
            v.len(),
            100.0 * within(2.0),
            100.0 * within(3.0),
            q(0.5),
            q(0.9),
            e[e.len() - 1]
        );
    }
}

fn fail(msg: &str) -> ! {
    eprintln!("release_instant: {msg}");
    std::process::exit(2)
}

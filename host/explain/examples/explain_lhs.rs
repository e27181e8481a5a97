//! `tribo explain` over the randomized grid of issue #32: a Latin hypercube over every range of
//! `shared/docs/real-bench.md` (rig, load, μ0, μ1, rate, hold, record length, force filter and
//! whether the header states it, vibrometer noise ×1–×50), with clean records, each effect alone
//! in every form of real-bench's table (from below its detection limit to its strongest), every
//! pair of effects, and two effects outside the vocabulary. Records come from the independent
//! generator of the explain tests (`tests/support/bench.rs`: its own equations and integrator).
//!
//! Prints the confusion table (present → named), the detection limit per effect (overall, per
//! noise band and per rig band: the weakest strength above which ≥ 90 % of the effect's records
//! alone are named rightly), the right names above those limits, effect-constant coverage (truth
//! within 2σ, where the form matches explain's model), false names on clean records, outside
//! effects named as a vocabulary effect, errors, and time per record. The vocabulary is read from
//! `Effect::ALL`: an effect the generator makes that explain has no name for is scored as outside.
//!
//! `cargo run --release -p tribo-explain --example explain_lhs -- --records 520 --seed 1
//! [--jobs 2] [--out records.tsv] [--only EFFECT] [--groups clean,alone,pair,outside] [--every K]
//! [--case INDEX] [--max-s S] [--verbose]` (`--only`, `--groups`, `--every`: a part of the same
//! grid — `--every K` keeps every K-th record of each group; `--case`: one record in detail;
//! `--max-s`: records of at most S s, default 25 — `--records 240 --seed 3 --max-s 6` is the grid
//! `tests/lhs_grid.rs` runs in CI)

#[path = "../tests/support/mod.rs"]
mod support;

use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use support::lhs::{
    compared_motion_s, drift_within, grid_with, run, score, strength_unit, vocabulary, Case, Group,
    Outcome, Score, EFFECTS, OUTSIDE,
};

const NOISE_BANDS: [(f64, f64, &str); 4] = [
    (1.0, 3.0, "×1–3"),
    (3.0, 9.0, "×3–9"),
    (9.0, 25.0, "×9–25"),
    (25.0, 50.01, "×25–50"),
];
const RIG_BANDS: [(f64, f64, &str); 2] = [(0.0, 25.0, "18–25 Hz"), (25.0, 99.0, "25–36 Hz")];

/// The weakest strength `s` such that the records at or above it are named rightly in ≥ 90 %
/// (at least 3 of them): `(s, right, of)`.
fn detection_limit(mut v: Vec<(f64, bool)>) -> Option<(f64, usize, usize)> {
    v.sort_by(|a, b| a.0.total_cmp(&b.0));
    for i in 0..v.len() {
        let above = &v[i..];
        let ok = above.iter().filter(|r| r.1).count();
        if above.len() >= 3 && ok as f64 >= 0.9 * above.len() as f64 {
            return Some((v[i].0, ok, above.len()));
        }
    }
    None
}

fn fmt_limit(v: Vec<(f64, bool)>) -> String {
    let n = v.len();
    let ok = v.iter().filter(|r| r.1).count();
    match detection_limit(v) {
        Some((s, k, m)) => format!("{s:.3} ({k}/{m})"),
        None => format!("none ({ok}/{n} right)"),
    }
}

/// A selection of the grid's cases.
type Select<'a> = &'a dyn Fn(&Case) -> bool;

/// One row of the detection-limit table: the limit over every record `pts` selects (strength,
/// named rightly), then per noise band and per rig band.
fn limit_row(label: &str, unit: &str, pts: &dyn Fn(Select) -> Vec<(f64, bool)>) {
    print!("{label:<20} {unit:<26} {:<22}", fmt_limit(pts(&|_| true)));
    for (lo, hi, _) in NOISE_BANDS {
        print!(
            " {:<22}",
            fmt_limit(pts(&|c| c.noise >= lo && c.noise < hi))
        );
    }
    for (lo, hi, _) in RIG_BANDS {
        print!(
            " {:<22}",
            fmt_limit(pts(&|c| c.freq_hz() >= lo && c.freq_hz() < hi))
        );
    }
    println!();
}

fn main() {
    let mut records = 520usize;
    let mut seed = 1u64;
    let mut jobs = 1usize;
    let mut out_path: Option<String> = None;
    let mut only: Option<String> = None;
    let mut verbose = false;
    let mut case: Option<usize> = None;
    let mut groups: Option<String> = None;
    let mut every = 1usize;
    let mut max_s = 25.0f64;
    let mut args = std::env::args().skip(1);
    let usage = "usage: explain_lhs [--records N] [--seed S] [--jobs J] [--out FILE] [--only EFFECT] [--case INDEX] [--groups clean,alone,pair,outside] [--every K] [--max-s S] [--verbose]";
    while let Some(a) = args.next() {
        let mut val = |name: &str| {
            args.next().unwrap_or_else(|| {
                eprintln!("{name} needs a value\n{usage}");
                std::process::exit(2)
            })
        };
        match a.as_str() {
            "--records" => records = val("--records").parse().unwrap_or(records),
            "--seed" => seed = val("--seed").parse().unwrap_or(seed),
            "--jobs" => jobs = val("--jobs").parse::<usize>().unwrap_or(1).max(1),
            "--out" => out_path = Some(val("--out")),
            "--only" => only = Some(val("--only")),
            "--verbose" => verbose = true,
            "--case" => case = val("--case").parse().ok(),
            "--groups" => groups = Some(val("--groups")),
            "--every" => every = val("--every").parse::<usize>().unwrap_or(1).max(1),
            "--max-s" => max_s = val("--max-s").parse::<f64>().unwrap_or(max_s).max(1.0),
            other => {
                eprintln!("unknown argument {other}\n{usage}");
                std::process::exit(2)
            }
        }
    }
    let vocab = vocabulary();
    let mut cases = grid_with(records, seed, max_s);
    if let Some(o) = &only {
        cases.retain(|c| {
            c.label().split('+').any(|e| e == o) || (o == "none" && c.present.is_empty())
        });
    }
    if let Some(g) = &groups {
        // A part of the grid (the same records as in the whole grid).
        cases.retain(|c| {
            let name = match c.group {
                Group::Clean => "clean",
                Group::Alone => "alone",
                Group::Pair => "pair",
                Group::Outside => "outside",
            };
            g.split(',').any(|x| x == name)
        });
    }
    if every > 1 {
        // Every K-th record of each group (the same records as in the whole grid), so that a
        // subset of a few dozen to a few hundred records still holds every group.
        let mut seen: BTreeMap<u8, usize> = BTreeMap::new();
        cases.retain(|c| {
            let g = match c.group {
                Group::Clean => 0u8,
                Group::Alone => 1,
                Group::Pair => 2,
                Group::Outside => 3,
            };
            let n = seen.entry(g).or_insert(0);
            *n += 1;
            (*n - 1).is_multiple_of(every)
        });
    }
    if let Some(i) = case {
        // One record in detail: explain's report and every round's candidates.
        let Some(c) = cases.iter().find(|c| c.index == i) else {
            eprintln!("no case {i} in a grid of {records}");
            std::process::exit(2)
        };
        println!("{}", c.describe());
        match tribo_explain::explain(&c.record(), &tribo_explain::ExplainOptions::default()) {
            Ok(e) => {
                println!("{}", e.to_text());
                if let Some(t) = &e.mu0_trend {
                    println!("the force channel's μ0 trend (final model): {}", t.text());
                }
                if let Some(p) = &e.position_dependence {
                    println!("position check: {}", p.text());
                }
                for (k, r) in e.rounds.iter().enumerate() {
                    for c in r {
                        println!(
                            "  round {} {:<20} evidence {:>10.1} excess removed {:>6.2} {}",
                            k + 1,
                            c.effect,
                            c.evidence.unwrap_or(f64::NAN),
                            c.excess_removed.unwrap_or(f64::NAN),
                            if c.significant { "significant" } else { "" }
                        );
                    }
                }
                for s in &e.steps {
                    for ch in &s.evidence.channels {
                        println!(
                            "  step {:<20} {:<8} rss {:.4e} -> {:.4e}, n {}, n_eff {:.0}, noise var {:.3e}, evidence {:.1}",
                            s.effect, ch.channel, ch.rss_before, ch.rss_after, ch.n, ch.n_eff, ch.noise_var, ch.evidence
                        );
                    }
                }
            }
            Err(e) => println!("error: {e}"),
        }
        return;
    }
    let total = cases.len();
    eprintln!(
        "{total} records (seed {seed}, {jobs} jobs); vocabulary: {}",
        vocab.join(", ")
    );
    let t0 = std::time::Instant::now();
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<(Outcome, Score)>>> = Mutex::new(vec![None; total]);
    std::thread::scope(|sc| {
        for _ in 0..jobs {
            sc.spawn(|| loop {
                let i = next.fetch_add(1, Ordering::SeqCst);
                if i >= total {
                    break;
                }
                let c = &cases[i];
                let out = run(c);
                let s = score(c, &out, &vocab);
                let d = done.fetch_add(1, Ordering::SeqCst) + 1;
                if verbose || !s.right {
                    let est: Vec<String> = out
                        .estimates
                        .iter()
                        .filter_map(|(tc, got)| {
                            got.map(|(v, se)| {
                                format!("{} {v:.4e} ± {se:.1e} (truth {:.4e})", tc.key, tc.value)
                            })
                        })
                        .collect();
                    eprintln!(
                        "{} → {} [{}]{} ({:.1} s){}{}",
                        c.describe(),
                        if out.named.is_empty() {
                            out.conclusion.clone()
                        } else {
                            out.named.join("+")
                        },
                        out.conclusion,
                        if s.right { "" } else { " WRONG" },
                        out.seconds,
                        if est.is_empty() { "" } else { "; " },
                        est.join("; ")
                    );
                }
                if d.is_multiple_of(10) || d == total {
                    eprintln!(
                        "{d} / {total} records ({:.0} s)",
                        t0.elapsed().as_secs_f64()
                    );
                }
                results.lock().unwrap()[i] = Some((out, s));
            });
        }
    });
    let results: Vec<(Outcome, Score)> = results
        .into_inner()
        .unwrap()
        .into_iter()
        .map(|r| r.expect("every record ran"))
        .collect();
    let wall = t0.elapsed().as_secs_f64();
    report(&cases, &results, &vocab, wall, jobs);
    if let Some(p) = out_path {
        let mut s = String::from("index\tgroup\tpresent\tstrengths\tnamed\tconclusion\tright\tnoise\tfreq_hz\tseconds\tcase\n");
        for (c, (o, sc)) in cases.iter().zip(&results) {
            let strengths: Vec<String> = c
                .present
                .iter()
                .map(|p| format!("{:.4}", p.strength))
                .collect();
            s += &format!(
                "{}\t{:?}\t{}\t{}\t{}\t{}\t{}\t{:.2}\t{:.1}\t{:.2}\t{}\n",
                c.index,
                c.group,
                c.label(),
                strengths.join("+"),
                o.named.join("+"),
                o.conclusion,
                sc.right,
                c.noise,
                c.freq_hz(),
                o.seconds,
                c.describe()
            );
        }
        if let Err(e) = std::fs::write(&p, s) {
            eprintln!("could not write {p}: {e}");
        }
    }
}

fn report(cases: &[Case], results: &[(Outcome, Score)], vocab: &[&str], wall: f64, jobs: usize) {
    let pct = |k: usize, n: usize| {
        if n == 0 {
            "—".to_string()
        } else {
            format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64)
        }
    };
    let in_vocab = |e: &str| vocab.contains(&e);
    println!(
        "explain over the Latin-hypercube grid: {} records; vocabulary {}",
        cases.len(),
        vocab.join(", ")
    );
    let outside_now: Vec<&str> = EFFECTS
        .iter()
        .chain(OUTSIDE.iter())
        .copied()
        .filter(|e| !in_vocab(e))
        .collect();
    println!("outside the vocabulary: {}", outside_now.join(", "));

    // Confusion.
    println!("\nconfusion: present → named (counts; `—` = nothing named: the conclusion follows)");
    let mut conf: BTreeMap<(u8, String), BTreeMap<String, usize>> = BTreeMap::new();
    for (c, (o, _)) in cases.iter().zip(results) {
        let g = match c.group {
            Group::Clean => 0,
            Group::Alone => 1,
            Group::Pair => 2,
            Group::Outside => 3,
        };
        let named = if o.named.is_empty() {
            format!("— {}", o.conclusion)
        } else {
            o.named.join("+")
        };
        *conf
            .entry((g, c.label()))
            .or_default()
            .entry(named)
            .or_default() += 1;
    }
    for ((_, label), row) in &conf {
        let n: usize = row.values().sum();
        let mut cells: Vec<(&String, &usize)> = row.iter().collect();
        cells.sort_by(|a, b| b.1.cmp(a.1));
        let cells: Vec<String> = cells.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        println!("{label:<40} ({n:>3}) {}", cells.join(", "));
    }

    // Detection limits (effects alone).
    println!(
        "\ndetection limit (effects alone): the weakest strength above which ≥ 90 % of the records \
         are named rightly (right/of at or above it)"
    );
    print!("{:<20} {:<26} {:<22}", "effect", "unit", "all");
    for (_, _, n) in NOISE_BANDS {
        print!(" {:<22}", format!("noise {n}"));
    }
    for (_, _, n) in RIG_BANDS {
        print!(" {n:<22}");
    }
    println!();
    let mut limit_of: BTreeMap<&str, f64> = BTreeMap::new();
    for e in EFFECTS {
        let rows: Vec<(&Case, bool)> = cases
            .iter()
            .zip(results)
            .filter(|(c, _)| c.group == Group::Alone && c.present[0].effect == e)
            .map(|(c, (_, s))| (c, s.right))
            .collect();
        let pts = |f: &dyn Fn(&Case) -> bool| -> Vec<(f64, bool)> {
            rows.iter()
                .filter(|(c, _)| f(c))
                .map(|(c, r)| (c.present[0].strength, *r))
                .collect()
        };
        let all = pts(&|_| true);
        if let Some((s, _, _)) = detection_limit(all) {
            limit_of.insert(e, s);
        }
        let tag = if in_vocab(e) { "" } else { " (outside)" };
        limit_row(&format!("{e}{tag}"), strength_unit(e), &pts);
    }

    // The drifts of μ0 on a second yardstick beside the grid's: what the compared motion holds.
    // The grid states thermal drift over the generator's whole ramp and running-in over its
    // Coulomb estimate of the motion's length; a ramp of 0.3–5 s from the release, or a motion
    // that a viscous term shortens, leaves part of that drift outside the compared motion.
    // (Scoring unchanged: the limits above, and the right names above them, use the grid's.)
    for e in ["thermal-drift", "running-in"] {
        let pts: Vec<(f64, bool, &Case)> = cases
            .iter()
            .zip(results)
            .filter(|(c, _)| c.group == Group::Alone && c.present[0].effect == e)
            .filter_map(|(c, (_, s))| {
                let d = drift_within(c, e, compared_motion_s(c)?)?;
                Some((d, s.right, c))
            })
            .collect();
        if pts.is_empty() {
            continue;
        }
        let band = |f: &dyn Fn(&Case) -> bool| -> Vec<(f64, bool)> {
            pts.iter()
                .filter(|(_, _, c)| f(c))
                .map(|(d, r, _)| (*d, *r))
                .collect()
        };
        limit_row(e, "|Δμ0|/μ0 in compared motion", &band);
        let each: Vec<String> = pts
            .iter()
            .map(|(d, r, c)| {
                format!(
                    "#{} {:.3}→{:.3}{}",
                    c.index,
                    c.present[0].strength,
                    d,
                    if *r { "" } else { " missed" }
                )
            })
            .collect();
        println!(
            "  {e} (grid's strength → in the compared motion): {}",
            each.join(", ")
        );
    }

    // Right names above the limits.
    let above = |c: &Case| {
        !c.present.is_empty()
            && c.present.iter().all(|p| {
                in_vocab(p.effect) && limit_of.get(p.effect).is_some_and(|&l| p.strength >= l)
            })
    };
    for (g, name) in [(Group::Alone, "alone"), (Group::Pair, "pairs")] {
        let sel: Vec<&Score> = cases
            .iter()
            .zip(results)
            .filter(|(c, _)| c.group == g && above(c))
            .map(|(_, (_, s))| s)
            .collect();
        println!(
            "right names above the detection limits ({name}, vocabulary effects with a limit): {}",
            pct(sel.iter().filter(|s| s.right).count(), sel.len())
        );
    }
    let pairs_all: Vec<&Score> = cases
        .iter()
        .zip(results)
        .filter(|(c, _)| c.group == Group::Pair && c.present.iter().all(|p| in_vocab(p.effect)))
        .map(|(_, (_, s))| s)
        .collect();
    println!(
        "pairs of vocabulary effects (upper half of their strength ranges) named both, nothing else: {}",
        pct(pairs_all.iter().filter(|s| s.right).count(), pairs_all.len())
    );

    // Coverage.
    println!(
        "\neffect-constant coverage (named effects whose form matches explain's model; every force \
         filter of the grid, none, 1-pole or 2-pole, is one it models): truth within 2σ"
    );
    // (effect, key) → (within 2σ, of, named without a ±, |z|s)
    type Cov = (usize, usize, usize, Vec<f64>);
    let mut cov: BTreeMap<(&str, &str), Cov> = BTreeMap::new();
    for (c, (o, _)) in cases.iter().zip(results) {
        for (tc, got) in &o.estimates {
            let Some(p) = c.present.iter().find(|p| p.effect == tc.effect) else {
                continue;
            };
            if !p.form_matches || !in_vocab(tc.effect) {
                continue;
            }
            let e = cov.entry((tc.effect, tc.key)).or_default();
            match got {
                Some((v, se)) if se.is_finite() && *se > 0.0 => {
                    let z = (v - tc.value) / se;
                    e.0 += usize::from(z.abs() <= 2.0);
                    e.1 += 1;
                    e.3.push(z.abs());
                }
                Some(_) => e.2 += 1,
                None => {}
            }
        }
    }
    let (mut all_ok, mut all_n) = (0, 0);
    for ((e, k), (ok, n, nose, mut zs)) in cov {
        zs.sort_by(f64::total_cmp);
        let med = zs.get(zs.len() / 2).copied().unwrap_or(f64::NAN);
        all_ok += ok;
        all_n += n;
        println!(
            "{e:<20} {k:<16} within 2σ {:<16} median |z| {med:.2}{}",
            pct(ok, n),
            if nose > 0 {
                format!(", {nose} without a ±")
            } else {
                String::new()
            }
        );
    }
    println!("all constants: {}", pct(all_ok, all_n));

    // Clean, outside, errors.
    let clean: Vec<&(Outcome, Score)> = cases
        .iter()
        .zip(results)
        .filter(|(c, _)| c.group == Group::Clean)
        .map(|(_, r)| r)
        .collect();
    let clean_false = clean
        .iter()
        .filter(|(_, s)| !s.false_names.is_empty())
        .count();
    let clean_inadequate = clean
        .iter()
        .filter(|(o, _)| o.named.is_empty() && o.conclusion != "base-adequate")
        .count();
    println!(
        "\nclean records with a false name: {}; called something else than base-adequate without a name: {}",
        pct(clean_false, clean.len()),
        pct(clean_inadequate, clean.len())
    );
    let outside: Vec<&(Outcome, Score)> = cases
        .iter()
        .zip(results)
        .filter(|(c, _)| c.present.iter().any(|p| !in_vocab(p.effect)))
        .map(|(_, r)| r)
        .collect();
    println!(
        "records with an effect outside the vocabulary named as a vocabulary effect: {}",
        pct(
            outside.iter().filter(|(_, s)| s.outside_named).count(),
            outside.len()
        )
    );
    for e in &outside_now {
        let rs: Vec<&(Outcome, Score)> = cases
            .iter()
            .zip(results)
            .filter(|(c, _)| c.present.len() == 1 && c.present[0].effect == *e)
            .map(|(_, r)| r)
            .collect();
        let mut by: BTreeMap<String, usize> = BTreeMap::new();
        for (o, _) in &rs {
            *by.entry(if o.named.is_empty() {
                o.conclusion.clone()
            } else {
                o.named.join("+")
            })
            .or_default() += 1;
        }
        let cells: Vec<String> = by.iter().map(|(k, v)| format!("{k}: {v}")).collect();
        println!("  {e} alone ({}): {}", rs.len(), cells.join(", "));
    }
    // Effects the record cannot identify (a direction asymmetry without a hold).
    let unident: Vec<&(Outcome, Score)> = results
        .iter()
        .filter(|(_, s)| !s.unidentifiable.is_empty())
        .collect();
    let flagged = unident
        .iter()
        .filter(|(o, s)| {
            o.force_offset_flagged && !o.named.iter().any(|n| s.unidentifiable.contains(n))
        })
        .count();
    println!(
        "records with an effect the record cannot identify (direction asymmetry without a hold: \
         its symmetric twin with two zero offsets, tests/asymmetry_zero.rs): {}; of them, the \
         offset flagged and the effect not named: {}",
        unident.len(),
        pct(flagged, unident.len())
    );
    let errors: Vec<&str> = results
        .iter()
        .filter(|(_, s)| s.error)
        .map(|(o, _)| o.conclusion.as_str())
        .collect();
    println!("errors (refusals): {}", pct(errors.len(), results.len()));
    let mut kinds: BTreeMap<&str, usize> = BTreeMap::new();
    for e in &errors {
        *kinds.entry(e).or_default() += 1;
    }
    for (k, v) in kinds {
        println!("  {v} × {k}");
    }

    // Time.
    let mut ts: Vec<f64> = results.iter().map(|(o, _)| o.seconds).collect();
    ts.sort_by(f64::total_cmp);
    println!(
        "\ntime per record (explain only, {jobs} jobs on a shared machine): median {:.1} s, max {:.1} s; \
         whole grid {:.0} s wall",
        ts.get(ts.len() / 2).copied().unwrap_or(f64::NAN),
        ts.last().copied().unwrap_or(f64::NAN),
        wall
    );
}

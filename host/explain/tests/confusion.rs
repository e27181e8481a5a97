//! The explain workflow's confusion table: records with each effect of its vocabulary at a weak,
//! realistic strength, clean records (noiseless and through the acquisition chain, three laws), and
//! an effect outside the vocabulary. Every record comes from the independent generator in
//! `support` (not from explain's own models) through the rig's acquisition chain.
//!
//! `cargo test -p tribo-explain --test confusion -- --nocapture` prints the table.

mod support;

use std::time::Instant;
use support::{chain, record, Contact};
use tribo_explain::{explain, Conclusion, ExplainOptions, Explanation};
use tribo_physics::identify::LawSpec;
use tribo_physics::sensor::SensorModel;
use tribo_physics::Record;

const MU0: f64 = 0.02;
const MU1: f64 = 0.002;

/// What a case should give: the effects named, or an empty list (and then either the base law
/// suffices, or the record is "unexplained").
pub struct Case {
    pub name: &'static str,
    pub rec: Record,
    pub base: LawSpec,
    pub want: Vec<&'static str>,
    pub want_unexplained: bool,
    /// True values of the named effect's parameters.
    pub truth: Vec<(&'static str, f64)>,
}

pub fn cv() -> Contact {
    Contact::coulomb_viscous(MU0, MU1)
}

pub fn cases(seed: u64) -> Vec<Case> {
    let noisy = |c: &Contact, s: u64| record(c, 0.3, 1.3, Some(&chain(seed * 100 + s)));
    let ideal = |c: &Contact| record(c, 0.3, 1.3, None);
    let quad = Contact { mu2: 0.004, ..cv() };
    let coul = Contact::coulomb_viscous(0.03, 0.0);
    vec![
        Case {
            name: "clean coulomb-viscous, noiseless",
            rec: ideal(&cv()),
            base: LawSpec::CoulombViscous,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "clean coulomb-viscous, noisy",
            rec: noisy(&cv(), 1),
            base: LawSpec::CoulombViscous,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "clean quadratic, noiseless",
            rec: ideal(&quad),
            base: LawSpec::Quadratic,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "clean quadratic, noisy",
            rec: noisy(&quad, 2),
            base: LawSpec::Quadratic,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "clean coulomb, noiseless",
            rec: ideal(&coul),
            base: LawSpec::Coulomb,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "clean coulomb, noisy",
            rec: noisy(&coul, 3),
            base: LawSpec::Coulomb,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "quadratic-velocity μ2 = 5e-4",
            rec: noisy(&Contact { mu2: 5e-4, ..cv() }, 4),
            base: LawSpec::CoulombViscous,
            want: vec!["quadratic-velocity"],
            want_unexplained: false,
            truth: vec![("mu2", 5e-4)],
        },
        Case {
            name: "stribeck μs = 1.25 μ0, vs = 0.3",
            rec: noisy(
                &Contact {
                    stribeck: Some((1.25 * MU0, 0.3)),
                    ..cv()
                },
                5,
            ),
            base: LawSpec::CoulombViscous,
            want: vec!["stribeck"],
            want_unexplained: false,
            truth: vec![("mu_s", 1.25 * MU0), ("v_s", 0.3)],
        },
        Case {
            name: "frictional-lag, memory 2 ms",
            rec: noisy(
                &Contact {
                    memory_s: 2e-3,
                    ..cv()
                },
                6,
            ),
            base: LawSpec::CoulombViscous,
            want: vec!["frictional-lag"],
            want_unexplained: false,
            truth: vec![("memory_s", 2e-3)],
        },
        Case {
            name: "cubic-stiffness k3 = 1e7 N/m³",
            rec: noisy(&Contact { k3: 1e7, ..cv() }, 7),
            base: LawSpec::CoulombViscous,
            want: vec!["cubic-stiffness"],
            want_unexplained: false,
            truth: vec![("k3_n_per_m3", 1e7)],
        },
        Case {
            name: "thermal-drift −3 % μ0 over +3 K",
            rec: noisy(
                &Contact {
                    thermal: Some((-2e-4, 3.0, 0.8)),
                    ..cv()
                },
                8,
            ),
            base: LawSpec::CoulombViscous,
            want: vec!["thermal-drift"],
            want_unexplained: false,
            truth: vec![("dmu0_dT_per_c", -2e-4)],
        },
        Case {
            // Both make friction fall as the run goes on; the quadratic term alone brings the
            // envelope to its noise floor, and the temperature column is what names the drift.
            name: "quadratic μ2 = 6e-4 with thermal drift −6 % μ0",
            rec: noisy(
                &Contact {
                    mu2: 6e-4,
                    thermal: Some((-4e-4, 3.0, 0.8)),
                    ..cv()
                },
                13,
            ),
            base: LawSpec::CoulombViscous,
            want: vec!["quadratic-velocity", "thermal-drift"],
            want_unexplained: false,
            // The first step's μ2 carries part of the drift (checked: 6.9e-4 ± 8e-6); the
            // constants of two effects at once are not a claim of this table.
            truth: vec![],
        },
        Case {
            name: "sensor-lag 1 ms",
            rec: {
                let ch = tribo_physics::sensor::SensorModel {
                    force_lag_s: 1e-3,
                    ..chain(seed * 100 + 9)
                };
                record(&cv(), 0.3, 1.3, Some(&ch))
            },
            base: LawSpec::CoulombViscous,
            want: vec!["sensor-lag"],
            want_unexplained: false,
            truth: vec![("delay_s", 1e-3)],
        },
        Case {
            name: "temperature rises, friction does not follow",
            rec: noisy(
                &Contact {
                    thermal: Some((0.0, 3.0, 0.8)),
                    ..cv()
                },
                10,
            ),
            base: LawSpec::CoulombViscous,
            want: vec![],
            want_unexplained: false,
            truth: vec![],
        },
        Case {
            name: "direction asymmetry μ0 backward 0.8 μ0, force zero stated",
            rec: zero_stated(noisy(
                &Contact {
                    mu0_backward: Some(0.8 * MU0),
                    ..cv()
                },
                11,
            )),
            base: LawSpec::CoulombViscous,
            want: vec!["direction-asymmetry"],
            want_unexplained: false,
            truth: vec![("dmu0_forward_minus_backward", 0.2 * MU0)],
        },
    ]
}

/// The record with its force channel's zero stated as the rig's records state it (`# force_zero_n=0`):
/// without it a direction asymmetry cannot be told from a zero offset of the force channel.
pub fn zero_stated(mut rec: Record) -> Record {
    rec.force_zero_n = Some(0.0);
    rec
}

pub fn run(c: &Case) -> Explanation {
    let opts = ExplainOptions {
        base: c.base,
        ..ExplainOptions::default()
    };
    explain(&c.rec, &opts).unwrap_or_else(|e| panic!("{}: {e}", c.name))
}

#[test]
fn confusion_table_named_against_present() {
    let mut failures = Vec::new();
    eprintln!(
        "{:<52} {:<28} {:<20} {:>6}",
        "record", "named", "conclusion", "s"
    );
    for c in cases(1) {
        let t = Instant::now();
        let e = run(&c);
        let named: Vec<&str> = e.missing_effects.iter().map(String::as_str).collect();
        eprintln!(
            "{:<52} {:<28} {:<20} {:>6.1}",
            c.name,
            if named.is_empty() {
                "—".into()
            } else {
                named.join("+")
            },
            e.conclusion.name(),
            t.elapsed().as_secs_f64()
        );
        // Each named effect's parameters against the truth and their own standard errors.
        let mut bad_params = Vec::new();
        if let Some(st) = e.steps.first() {
            for (k, truth) in &c.truth {
                let (v, se) = (st.params[*k], st.params_se[*k]);
                if !(se.is_finite() && (v - truth).abs() <= 3.0 * se + 1e-3 * truth.abs()) {
                    bad_params.push(format!("{k} = {v:e} ± {se:e}, truth {truth:e}"));
                }
            }
        }
        let ok = bad_params.is_empty()
            && named == c.want
            && (!c.want_unexplained || e.conclusion == Conclusion::Unexplained)
            && (c.want_unexplained
                || matches!(
                    e.conclusion,
                    Conclusion::BaseAdequate | Conclusion::Explained
                ));
        for st in &e.steps {
            for (k, v) in &st.params {
                eprintln!("    {k} = {v:.4e} ± {:.1e}", st.params_se[k]);
            }
        }
        for (i, r) in e.rounds.iter().enumerate() {
            let cells: Vec<String> = r
                .iter()
                .map(|c| {
                    format!(
                        "{}={:.0}/{:.0}%",
                        &c.effect[..4],
                        c.evidence.unwrap_or(f64::NAN),
                        100.0 * c.excess_removed.unwrap_or(f64::NAN)
                    )
                })
                .collect();
            eprintln!("    round {}: {}", i + 1, cells.join(" "));
        }
        if !ok {
            failures.push(format!("{}: {bad_params:?}\n{}", c.name, e.to_text()));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// A larger sweep: the same cases over several noise seeds, as a confusion table (rows: present,
/// columns: named). `cargo test --release -p tribo-explain --test confusion -- --ignored --nocapture`
#[test]
#[ignore]
fn confusion_table_over_seeds() {
    use std::collections::BTreeMap;
    let seeds = 2..7u64;
    let mut table: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for seed in seeds {
        for c in cases(seed) {
            let e = run(&c);
            let present = if c.want.is_empty() {
                if c.want_unexplained {
                    "other (outside)".to_string()
                } else {
                    "none (clean)".to_string()
                }
            } else {
                c.want.join("+")
            };
            let named = if e.missing_effects.is_empty() {
                e.conclusion.name().to_string()
            } else {
                e.missing_effects.join("+")
            };
            eprintln!("seed {seed}: {:<52} {named}", c.name);
            *table.entry(present).or_default().entry(named).or_default() += 1;
        }
    }
    eprintln!("\npresent → named (counts over seeds)");
    for (p, row) in &table {
        let cells: Vec<String> = row.iter().map(|(n, k)| format!("{n}: {k}")).collect();
        eprintln!("{p:<24} {}", cells.join(", "));
    }
}

/// A dimensionless record `tau,y,ydot` (thesis Table 3 style, Y0 = 10): no force channel, no
/// temperature, the envelope alone.
#[test]
fn envelope_alone_names_quadratic_velocity() {
    use tribo_physics::integrate::Method;
    use tribo_physics::record::Units;
    use tribo_physics::{FrictionLaw, Model, Rig};
    let mu = [0.1, 0.04, 0.005];
    let tau: Vec<f64> = (0..12_000).map(|i| i as f64 * 0.01).collect();
    let tr = tribo_physics::simulate(
        &Model::new(FrictionLaw::quadratic(mu[0], mu[1], mu[2])),
        10.0,
        0.0,
        &tau,
        Method::dopri(1e-10),
    )
    .unwrap();
    let rec = Record::new(tau, tr.y, tr.ydot, Some(Rig::UNIT), Units::Dimensionless);
    let e = explain(&rec, &ExplainOptions::default()).unwrap();
    assert!(e.base_model.gap_force.is_none());
    assert_eq!(e.missing_effects, ["quadratic-velocity"], "{}", e.to_text());
    assert_eq!(e.conclusion, Conclusion::Explained, "{}", e.to_text());
    let st = &e.steps[0];
    assert!(
        (st.params["mu2"] - mu[2]).abs() < 0.02 * mu[2],
        "{}",
        e.to_text()
    );
    assert!((e.final_model.params["mu0"] - mu[0]).abs() < 0.02 * mu[0]);
    assert!((e.final_model.params["mu1"] - mu[1]).abs() < 0.02 * mu[1]);
}

/// Below the test set's strengths: each effect at about a third of it (and a 5 % direction
/// asymmetry). The workflow may miss them or call them ambiguous, but it must never name a wrong
/// effect. `cargo test --release -p tribo-explain --test confusion -- --ignored --nocapture`
#[test]
#[ignore]
fn weaker_effects_are_missed_rather_than_misnamed() {
    let c = cv();
    let cases: Vec<(&str, Contact, f64, &str)> = vec![
        (
            "μ2 = 1.5e-4",
            Contact {
                mu2: 1.5e-4,
                ..c.clone()
            },
            0.0,
            "quadratic-velocity",
        ),
        (
            "μs = 1.08 μ0",
            Contact {
                stribeck: Some((1.08 * MU0, 0.3)),
                ..c.clone()
            },
            0.0,
            "stribeck",
        ),
        (
            "memory 0.5 ms",
            Contact {
                memory_s: 5e-4,
                ..c.clone()
            },
            0.0,
            "frictional-lag",
        ),
        (
            "k3 = 3e6 N/m³",
            Contact {
                k3: 3e6,
                ..c.clone()
            },
            0.0,
            "cubic-stiffness",
        ),
        (
            "μ0 −1 % over +3 K",
            Contact {
                thermal: Some((-0.667e-4, 3.0, 0.8)),
                ..c.clone()
            },
            0.0,
            "thermal-drift",
        ),
        ("force delay 0.2 ms", c.clone(), 2e-4, "sensor-lag"),
        (
            "μ0 5 % lower backwards",
            Contact {
                mu0_backward: Some(0.95 * MU0),
                ..c.clone()
            },
            0.0,
            "",
        ),
    ];
    let mut wrong = Vec::new();
    for (name, contact, lag, truth) in cases {
        for seed in 1..4 {
            let ch = tribo_physics::sensor::SensorModel {
                force_lag_s: lag,
                ..chain(900 + seed)
            };
            let e = explain(
                &record(&contact, 0.3, 1.3, Some(&ch)),
                &ExplainOptions::default(),
            )
            .unwrap();
            eprintln!(
                "{name:<24} seed {seed}: {:<22} {}",
                e.missing_effects.join("+"),
                e.conclusion.name()
            );
            if e.missing_effects.iter().any(|m| m != truth) {
                wrong.push(format!("{name}, seed {seed}: {:?}", e.missing_effects));
            }
        }
    }
    assert!(wrong.is_empty(), "wrong names: {wrong:?}");
}

/// At every bench noise level (×1 to ×50 the simulator's default vibrometer noise): a clean record
/// gets no name; a 30 % direction asymmetry of μ0 with the force channel's zero stated is named;
/// the same record with the asymmetry taken out of the vocabulary (an effect outside it) is
/// "unexplained" and located (the force misfit differs between the sliding directions); and a
/// 2 ms frictional lag and a 1 ms sensor lag (seen by the force channel, whatever the vibrometer's
/// noise) are named alone.
#[test]
fn no_false_name_and_the_force_channel_effects_at_every_noise_level() {
    use tribo_physics::bench::NOISE_LEVELS;
    let mut failures = Vec::new();
    for (li, level) in NOISE_LEVELS.iter().enumerate() {
        let chain = |lag: f64, s: u64| SensorModel {
            disp_noise_m: level.disp_m,
            vel_noise_m_s: level.vel_m_s,
            force_lag_s: lag,
            seed: 500 + 10 * li as u64 + s,
            ..SensorModel::default()
        };
        let cases = [
            (
                "clean",
                record(&cv(), 0.3, 1.3, Some(&chain(0.0, 1))),
                "base-adequate",
            ),
            (
                "direction asymmetry 30 %",
                zero_stated(record(
                    &Contact {
                        mu0_backward: Some(0.7 * MU0),
                        ..cv()
                    },
                    0.3,
                    1.3,
                    Some(&chain(0.0, 2)),
                )),
                "direction-asymmetry",
            ),
            (
                "direction asymmetry 30 %, not in the vocabulary (outside)",
                zero_stated(record(
                    &Contact {
                        mu0_backward: Some(0.7 * MU0),
                        ..cv()
                    },
                    0.3,
                    1.3,
                    Some(&chain(0.0, 2)),
                )),
                "unexplained",
            ),
            (
                "frictional lag 2 ms",
                record(
                    &Contact {
                        memory_s: 2e-3,
                        ..cv()
                    },
                    0.3,
                    1.3,
                    Some(&chain(0.0, 3)),
                ),
                "frictional-lag",
            ),
            (
                "sensor lag 1 ms",
                record(&cv(), 0.3, 1.3, Some(&chain(1e-3, 4))),
                "sensor-lag",
            ),
        ];
        for (name, rec, want) in cases {
            // The effect outside the vocabulary: the asymmetry with its name taken out.
            let opts = ExplainOptions {
                candidates: tribo_explain::Effect::ALL
                    .into_iter()
                    .filter(|&e| {
                        want != "unexplained" || e != tribo_explain::Effect::DirectionAsymmetry
                    })
                    .collect(),
                ..ExplainOptions::default()
            };
            let e = explain(&rec, &opts).unwrap();
            let got = if e.missing_effects.is_empty() {
                e.conclusion.name().to_string()
            } else {
                e.missing_effects.join("+")
            };
            eprintln!("{}: {name}: {got}", level.name);
            // What stays unexplained is located: friction that differs between the sliding
            // directions is said to.
            if want == "unexplained"
                && !e
                    .disagreement
                    .iter()
                    .any(|d| d.contains("depends on the sliding direction"))
            {
                failures.push(format!(
                    "{}: {name}: the direction is not named where it disagrees: {:?}",
                    level.name, e.disagreement
                ));
            }
            if got != want {
                failures.push(format!(
                    "{}: {name}: {got}, not {want}\n{}",
                    level.name,
                    e.to_text()
                ));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

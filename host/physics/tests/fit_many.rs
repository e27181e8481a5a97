//! `fit_many`: several records fitted on every core give, in input order, what each fit alone
//! gives (to the last bit: each worker fits on its own thread, as `fit` does with one thread).

use tribo_physics::identify::{fit, fit_many, FitOptions, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};

#[test]
fn fit_many_gives_each_record_its_own_fit_in_order() {
    let recs: Vec<_> = [0.01, 0.02, 0.03, 0.015, 0.025]
        .iter()
        .enumerate()
        .map(|(i, &mu0)| {
            let spec = RecordSpec {
                rig: Rig::REAL,
                x0_m: 667e-6,
                v0_m_s: 0.0,
                duration_s: 0.5,
                rate_hz: 10_000.0,
            };
            let sensor = SensorModel {
                seed: i as u64,
                ..SensorModel::default()
            };
            let model = Model::new(FrictionLaw::coulomb_viscous(mu0, 0.005));
            generate(&spec, &model, Method::default(), Some(&sensor)).unwrap()
        })
        .collect();
    // One record unreadable as a fit: a constant signal (its error in its place).
    let mut bad = recs[0].clone();
    bad.x.iter_mut().for_each(|x| *x = 0.0);
    bad.v.iter_mut().for_each(|v| *v = 0.0);
    let mut all = recs.clone();
    all.insert(2, bad.clone());
    let opts = FitOptions::default();
    let many = fit_many(&all, LawSpec::CoulombViscous, &opts);
    assert_eq!(many.len(), all.len());
    for (rec, got) in all.iter().zip(&many) {
        let alone = fit(rec, LawSpec::CoulombViscous, &opts);
        match (alone, got) {
            (Ok(a), Ok(b)) => {
                assert_eq!(a.mu, b.mu);
                assert_eq!(a.mu_se, b.mu_se);
            }
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
            (a, b) => panic!("alone {a:?}, among others {b:?}"),
        }
    }
    assert!(many[2].is_err(), "a record at rest has no fit");
    // In input order: the fitted μ0 follow the records'.
    let mu0: Vec<f64> = many
        .iter()
        .filter_map(|r| r.as_ref().ok())
        .map(|r| r.mu[0])
        .collect();
    for (m, truth) in mu0.iter().zip([0.01, 0.02, 0.03, 0.015, 0.025]) {
        assert!((m - truth).abs() < 0.1 * truth, "{mu0:?}");
    }
}

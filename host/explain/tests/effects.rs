//! The discrepancy workflow on records with one hidden effect, and on clean records.
//!
//! Every record is simulated by tribo-physics with the real rig's constants (k = 1150 N/m,
//! m = 0.04 kg, N = 0.3 N, x0 = 667 µm, 10 kHz) and passed through its sensor model (noise, 16-bit
//! quantisation, 300 Hz charge-amplifier low-pass on the force channel). The truth is a
//! Coulomb–viscous law (μ0 = 0.02, μ1 = 0.002) plus at most one effect; the workflow is run with
//! the Coulomb–viscous base, which lacks it.
//!
//! The temperature-dependent friction of the thermal-drift case is not in tribo-physics' model: the
//! record is built here from its pieces (a `Simulator` restarted every 0.5 ms with the Coulomb level
//! of the true temperature, then the sensor chain with its thermocouple channel).

use tribo_explain::{explain, ExplainOptions, Explanation};
use tribo_physics::integrate::{Method, Simulator};
use tribo_physics::law::{FrictionLaw, LuGre};
use tribo_physics::model::{Model, Rig};
use tribo_physics::record::{Record, Units};
use tribo_physics::sensor::{generate, RecordSpec, SensorModel, Thermal};

const MU0: f64 = 0.02;
const MU1: f64 = 0.002;
const DURATION_S: f64 = 1.3;

fn rig() -> Rig {
    Rig::REAL
}

fn spec() -> RecordSpec {
    RecordSpec {
        rig: rig(),
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: DURATION_S,
        rate_hz: 10_000.0,
    }
}

fn sensor(seed: u64) -> SensorModel {
    SensorModel {
        seed,
        ..SensorModel::default()
    }
}

fn record(model: Model, sensor: &SensorModel) -> Record {
    generate(&spec(), &model, Method::dopri(1e-10), Some(sensor)).unwrap()
}

fn base_law() -> FrictionLaw {
    FrictionLaw::coulomb_viscous(MU0, MU1)
}

fn run(rec: &Record) -> Explanation {
    let t = std::time::Instant::now();
    let e = explain(rec, &ExplainOptions::default()).unwrap();
    eprintln!("{} ({:.2} s)", e.to_json(), t.elapsed().as_secs_f64());
    e
}

fn param(e: &Explanation, k: &str) -> f64 {
    *e.steps[0]
        .params
        .get(k)
        .unwrap_or_else(|| panic!("no parameter {k} in {:?}", e.steps[0].params))
}

fn assert_found(e: &Explanation, effect: &str) {
    assert_eq!(
        e.missing_effects,
        vec![effect.to_string()],
        "{}",
        e.to_text()
    );
    let s = &e.steps[0];
    assert!(
        s.gap_after <= 0.5 * s.gap_before,
        "gap {} -> {} did not halve",
        s.gap_before,
        s.gap_after
    );
    assert!(e.gap_final <= 0.5 * e.gap_initial);
}

fn close(got: f64, want: f64, rel: f64, what: &str) {
    assert!(
        ((got - want) / want).abs() <= rel,
        "{what}: recovered {got}, truth {want} (tolerance {rel})"
    );
}

#[test]
fn clean_records_have_no_missing_effect() {
    for (seed, load) in [(11, 0.3), (12, 0.15)] {
        let mut sp = spec();
        sp.rig.load_n = load;
        let rec = generate(
            &sp,
            &Model::new(base_law()),
            Method::dopri(1e-10),
            Some(&sensor(seed)),
        )
        .unwrap();
        let e = run(&rec);
        assert!(e.missing_effects.is_empty(), "{}", e.to_text());
        assert!(e.steps.is_empty() && e.ambiguous.is_empty());
        assert_eq!(e.gap_final, e.gap_initial);
        // The base fit itself recovers the truth.
        close(e.base_model.params["mu0"], MU0, 0.02, "mu0");
        close(e.base_model.params["mu1"], MU1, 0.1, "mu1");
    }
}

#[test]
fn quadratic_velocity() {
    let mu2 = 0.004;
    let rec = record(
        Model::new(FrictionLaw::quadratic(MU0, MU1, mu2)),
        &sensor(21),
    );
    let e = run(&rec);
    assert_found(&e, "quadratic-velocity");
    close(param(&e, "mu2"), mu2, 0.1, "mu2");
    // Thesis Tables 6–7: the Coulomb–viscous constants drift from window to window.
    assert!(
        e.diagnostics.window_drift.unwrap() > 0.3,
        "{:?}",
        e.diagnostics.windows
    );
}

#[test]
fn quadratic_velocity_without_force_channel() {
    // Dimensionless record `tau,y,ydot` (thesis Table 3 style, Y0 = 10): the envelope alone.
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
    let e = run(&rec);
    assert!(e.base_model.gap_force.is_none());
    assert_found(&e, "quadratic-velocity");
    close(param(&e, "mu2"), mu[2], 0.05, "mu2");
    close(e.final_model.params["mu0"], mu[0], 0.05, "mu0");
    close(e.final_model.params["mu1"], mu[1], 0.05, "mu1");
}

#[test]
fn stribeck() {
    let (mu_s, v_s) = (0.035, 0.3);
    let law = FrictionLaw::Stribeck {
        mu_c: MU0,
        mu_s,
        v_s,
        delta: 2.0,
        mu_v: MU1,
    };
    let e = run(&record(Model::new(law), &sensor(31)));
    assert_found(&e, "stribeck");
    close(param(&e, "mu_s"), mu_s, 0.1, "mu_s");
    close(param(&e, "v_s"), v_s, 0.2, "v_s");
}

#[test]
fn frictional_lag() {
    let sigma0 = 0.3;
    let law = FrictionLaw::LuGre(LuGre {
        sigma0,
        sigma1: 0.0,
        sigma2: MU1,
        mu_c: MU0,
        mu_s: MU0,
        v_s: 1.0,
        a: 2.0,
    });
    let e = run(&record(Model::new(law), &sensor(41)));
    assert_found(&e, "frictional-lag");
    close(param(&e, "sigma0"), sigma0, 0.15, "sigma0");
    close(
        param(&e, "sigma0_n_per_m"),
        sigma0 * rig().stiffness_n_per_m,
        0.15,
        "sigma0 (N/m)",
    );
}

#[test]
fn cubic_stiffness() {
    let k3 = 3.0e7; // N/m³: 1.2 % stiffening at x0
    let kappa = rig().kappa_of_k3(k3);
    let rec = record(Model::new(base_law()).with_cubic(kappa), &sensor(51));
    let e = run(&rec);
    assert_found(&e, "cubic-stiffness");
    close(param(&e, "k3_n_per_m3"), k3, 0.05, "k3");
    // The Duffing backbone read off the measured half periods gives κ before any fit.
    close(
        e.diagnostics.kappa_estimate.unwrap(),
        kappa,
        0.15,
        "kappa from frequency",
    );
}

#[test]
fn sensor_lag() {
    let lag = 3e-3;
    let s = SensorModel {
        force_lag_s: lag,
        ..sensor(61)
    };
    let e = run(&record(Model::new(base_law()), &s));
    assert_found(&e, "sensor-lag");
    close(param(&e, "delay_s"), lag, 0.05, "delay");
    // The diagnostic scan already sees the lag, and a pure delay removes almost all the misfit.
    close(
        e.diagnostics.force_lag_s.unwrap(),
        lag,
        0.1,
        "diagnostic lag",
    );
    assert!(e.diagnostics.force_lag_gain.unwrap() > 0.8);
}

/// Record whose Coulomb level follows the plane temperature: `μ0(T) = μ0 + γ (T − T0)`.
fn thermal_record(gamma: f64, th: Thermal, seed: u64) -> Record {
    let sp = spec();
    let r = sp.rig;
    let n = (sp.duration_s * sp.rate_hz).round() as usize + 1;
    let t: Vec<f64> = (0..n).map(|i| i as f64 / sp.rate_hz).collect();
    let law_at = |ts: f64| {
        let temp = th.start_c + th.drift_c_per_s * ts;
        Model::new(FrictionLaw::coulomb_viscous(
            MU0 + gamma * (temp - th.start_c),
            MU1,
        ))
    };
    let method = Method::dopri(1e-10);
    let mut sim = Simulator::new(law_at(0.0), r.y_of_x(sp.x0_m), 0.0, method);
    let (mut x, mut v, mut f, mut stuck) = (vec![], vec![], vec![], vec![]);
    for (i, &ti) in t.iter().enumerate() {
        if i > 0 && i % 5 == 0 {
            // Restart every 0.5 ms with the friction of the current temperature.
            let s = sim.step_to(r.tau_of_t(ti)).unwrap();
            sim = Simulator::with_state(law_at(ti), r.tau_of_t(ti), [s.y, s.ydot, s.z], method);
        }
        let s = sim.step_to(r.tau_of_t(ti)).unwrap();
        x.push(r.x_of_y(s.y));
        v.push(r.v_of_ydot(s.ydot));
        f.push(s.f * r.load_n);
        stuck.push(s.stuck);
    }
    let mut rec = Record::new(t, x, v, Some(r), Units::Si);
    let chain = SensorModel {
        thermal: Some(th),
        ..sensor(seed)
    };
    chain.apply(&mut rec, &f, &stuck);
    rec
}

#[test]
fn thermal_drift() {
    // The plane heats by 8 °C/s and the contact's friction falls with it (−50 % over the run).
    let gamma = -1e-3; // per °C
    let th = Thermal {
        start_c: 40.0,
        drift_c_per_s: 8.0,
        noise_c: 0.1,
    };
    let e = run(&thermal_record(gamma, th, 71));
    assert_found(&e, "thermal-drift");
    close(param(&e, "dmu0_dT_per_c"), gamma, 0.1, "dmu0/dT");
}

#[test]
fn temperature_channel_without_drift_is_not_blamed() {
    // A temperature channel that drifts while the friction does not depend on it.
    let th = Thermal {
        start_c: 40.0,
        drift_c_per_s: 5.0,
        noise_c: 0.1,
    };
    let e = run(&thermal_record(0.0, th, 72));
    assert!(e.missing_effects.is_empty(), "{}", e.to_text());
}

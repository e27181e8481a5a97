//! The drift check's fast search (coarse to fine over the delay × memory grid, on a few blocks of
//! a long span) gives the trend the exhaustive one does (every grid point on every selected
//! sample): on records with and without a drift of μ0, with the force filter stated and not, with
//! a sensor lag, short (one block: the whole span) and long (blocks). The estimate and its ± agree
//! within a tenth of the ±, and the verdict is the same. (A light contact's record is still
//! moving after 6 s: 60 000 samples, more than the fast search's blocks take.)

use tribo_physics::identify::{fit, mu0_trend_exhaustive, FitOptions, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::record::Record;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Rig};

/// A quadratic contact's record, `secs` long at 10 kHz, through `sensor`, its force channel's μ0
/// changed by `drift` (relative) over the record.
/// `light`: the 40 s record's contact (0.05 N, μ0 0.0008), still moving after 10 s; else 0.3 N,
/// μ0 0.01 (stopped after about 1.2 s).
fn record(secs: f64, sensor: &SensorModel, drift: f64, light: bool) -> Record {
    let rig = Rig {
        load_n: if light { 0.05 } else { 0.3 },
        ..Rig::REAL
    };
    let spec = RecordSpec {
        rig,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: secs,
        rate_hz: 10_000.0,
    };
    let (mu0, mu1, mu2) = if light {
        (0.0008, 0.0011, 0.0005)
    } else {
        (0.01, 0.01, 0.002)
    };
    let model = Model::new(FrictionLaw::quadratic(mu0, mu1, mu2));
    let mut rec = generate(&spec, &model, Method::default(), Some(sensor)).unwrap();
    if drift != 0.0 {
        let t_mid = 0.5 * secs;
        let v = rec.v.clone();
        let t = rec.t.clone();
        if let Some(ft) = rec.ft.as_mut() {
            for ((f, v), t) in ft.iter_mut().zip(&v).zip(&t) {
                *f += v.signum() * rig.load_n * mu0 * drift * (t - t_mid) / secs;
            }
        }
    }
    rec
}

fn compare(name: &str, rec: &Record, failures: &mut Vec<String>) {
    let r = fit(rec, LawSpec::Quadratic, &FitOptions::default()).unwrap();
    let fast = r
        .mu0_trend
        .clone()
        .expect("a force channel and a Coulomb level");
    let exh = mu0_trend_exhaustive(rec, &r).expect("the exhaustive search finds a trend");
    let d = (fast.relative_change - exh.relative_change).abs() / exh.relative_change_se;
    let dse = (fast.relative_change_se - exh.relative_change_se).abs() / exh.relative_change_se;
    eprintln!(
        "{name}: fast {:+.4} ± {:.4} %, exhaustive {:+.4} ± {:.4} % ({:.3}σ apart, ± {:.3} apart)",
        100.0 * fast.relative_change,
        100.0 * fast.relative_change_se,
        100.0 * exh.relative_change,
        100.0 * exh.relative_change_se,
        d,
        dse
    );
    if d > 0.1 || dse > 0.1 || fast.significant != exh.significant {
        failures.push(format!(
            "{name}: fast {} / exhaustive {}",
            fast.text(),
            exh.text()
        ));
    }
}

#[test]
fn the_fast_search_finds_the_exhaustive_trend() {
    let mut failures = Vec::new();
    for (secs, light, drift, stated, lag_s, seed) in [
        (2.0, false, 0.0, true, 0.0, 1),
        (2.0, false, 0.12, true, 0.0, 2),
        (2.0, false, 0.0, false, 0.0, 3),
        (2.0, false, -0.12, false, 0.0, 4),
        (2.0, false, 0.0, false, 0.003, 5),
        (2.0, false, 0.12, false, 0.001, 6),
        (6.0, true, 0.0, false, 0.0, 7),
        (6.0, true, 0.12, false, 0.0, 8),
        (6.0, true, 0.0, true, 0.003, 9),
        (6.0, true, -0.12, false, 0.001, 10),
    ] {
        let sensor = SensorModel {
            force_lag_s: lag_s,
            // The light contact's friction force is 40 µN: a channel 20 times quieter than the
            // default's.
            force_noise_n: if light { 1e-5 } else { 2e-4 },
            seed,
            ..SensorModel::default()
        };
        let mut rec = record(secs, &sensor, drift, light);
        if !stated {
            rec.force_cutoff_hz = None;
        }
        compare(
            &format!(
                "{secs} s{}, drift {drift:+}, filter {}, lag {} ms",
                if light { " light" } else { "" },
                if stated { "stated" } else { "unstated" },
                1e3 * lag_s
            ),
            &rec,
            &mut failures,
        );
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

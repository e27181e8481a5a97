//! The screening that decides whether a record can be fitted at all: it must refuse what cannot be
//! analysed (no oscillation, too few half cycles, a clipped channel, a non-finite sample) and pass
//! every ordinary noisy record — a false "saturated" or "too few half cycles" would withhold a
//! result that exists.

use tribo_physics::identify::{screen, NotAnalysable, MIN_HALF_CYCLES};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::{generate, RecordSpec, SensorModel};
use tribo_physics::{FrictionLaw, Model, Record, Rig};

fn record(load_n: f64, law: FrictionLaw, seed: u64, vel_noise: f64) -> Record {
    let spec = RecordSpec {
        rig: Rig::new(0.04, 1150.0, load_n).unwrap(),
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 1.0,
        rate_hz: 10_000.0,
    };
    let s = SensorModel {
        seed,
        vel_noise_m_s: vel_noise,
        ..SensorModel::default()
    };
    generate(&spec, &Model::new(law), Method::dopri(1e-9), Some(&s)).unwrap()
}

fn screened(rec: &Record) -> Result<usize, NotAnalysable> {
    let (t, y, v) = rec.dimensionless().unwrap();
    screen(&t, &y, &v).map(|s| s.half_cycles)
}

#[test]
fn ordinary_noisy_records_all_pass() {
    let mut seed = 0;
    for (load, law) in [
        (0.3, FrictionLaw::coulomb_viscous(0.02, 0.01)),
        (0.1, FrictionLaw::coulomb_viscous(0.005, 0.002)),
        (0.7, FrictionLaw::quadratic(0.02, 0.004, 0.003)),
    ] {
        for vel_noise in [2e-5, 6e-5] {
            for _ in 0..40 {
                seed += 1;
                let r = screened(&record(load, law.clone(), seed, vel_noise));
                assert!(
                    r.is_ok(),
                    "N = {load}, {law:?}, noise {vel_noise}, seed {seed}: {r:?}"
                );
            }
        }
    }
}

#[test]
fn what_cannot_be_analysed_is_refused_with_its_reason() {
    let good = record(0.3, FrictionLaw::coulomb_viscous(0.02, 0.01), 1, 2e-5);
    // 44 half cycles above the noise in this second of motion.
    assert!(screened(&good).unwrap() > 40);
    // A displacement converter clipping at 85 % of x0: the first few peaks only.
    let mut clip = good.clone();
    let lim = 0.85 * good.x.iter().fold(0.0f64, |m, x| m.max(x.abs()));
    clip.x.iter_mut().for_each(|x| *x = x.clamp(-lim, lim));
    assert!(
        matches!(
            screened(&clip),
            Err(NotAnalysable::Saturated {
                channel: "displacement",
                ..
            })
        ),
        "{:?}",
        screened(&clip)
    );
    // A velocity converter clipping at 90 % of the peak speed.
    let mut vclip = good.clone();
    let vlim = 0.9 * good.v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    vclip.v.iter_mut().for_each(|v| *v = v.clamp(-vlim, vlim));
    assert!(matches!(
        screened(&vclip),
        Err(NotAnalysable::Saturated {
            channel: "velocity",
            ..
        })
    ));
    // The pin held at x0, never released.
    let mut held = good.clone();
    held.x.iter_mut().for_each(|x| *x = 667e-6);
    held.v.iter_mut().for_each(|v| *v = 0.0);
    assert!(matches!(
        screened(&held),
        Err(NotAnalysable::NoOscillation { .. })
    ));
    // A Coulomb contact that stops after a half cycle or two.
    let short = record(0.3, FrictionLaw::coulomb(0.8), 2, 2e-5);
    match screened(&short) {
        Err(NotAnalysable::TooFewHalfCycles { found, need }) => {
            assert!(found < MIN_HALF_CYCLES && need == MIN_HALF_CYCLES)
        }
        other => panic!("{other:?}"),
    }
    // Rig constants off by a factor 9 in mass, either way: the extrema are a third of, or three,
    // natural half periods apart.
    for (mass, apart) in [(0.36, "0.33"), (0.04 / 9.0, "3.00")] {
        let mut wrong = good.clone();
        wrong.rig = Some(Rig::new(mass, 1150.0, 0.3).unwrap());
        match screened(&wrong) {
            Err(NotAnalysable::NoOscillation { reason }) => assert!(
                reason.contains("check the rig constants") && reason.contains(apart),
                "{reason}"
            ),
            other => panic!("{other:?}"),
        }
    }
}

/// The fit's screening leaves a few clipped peaks out (`screen_with(…, true)`), but a channel stuck
/// at its rail in one long stretch is still refused: only the runs it leaves out are excused.
#[test]
fn leaving_clipped_peaks_out_does_not_excuse_a_channel_stuck_at_its_rail() {
    use tribo_physics::identify::screen_with;
    let good = record(0.3, FrictionLaw::coulomb_viscous(0.02, 0.01), 3, 2e-5);
    let mut stuck = good.clone();
    let vmax = good.v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    // 5 ms (a seventh of a cycle) stuck at the velocity channel's top while the pin moves.
    for v in &mut stuck.v[3000..3050] {
        *v = 1.01 * vmax;
    }
    let (t, y, v) = stuck.dimensionless().unwrap();
    for allow in [false, true] {
        assert!(
            matches!(
                screen_with(&t, &y, &v, allow),
                Err(NotAnalysable::Saturated {
                    channel: "velocity",
                    ..
                })
            ),
            "allow_clipped {allow}: {:?}",
            screen_with(&t, &y, &v, allow)
        );
    }
}

/// A pin that never moves (held by friction above the blades' pull) reads noise about where it was
/// released, quantised by the converters: that is "the pin never moves", not a saturated channel
/// (its noise sits on the extreme codes for long runs). A velocity input stuck at one code while
/// the displacement swings is a stuck channel, not "the pin never moves" — and so is a
/// displacement stuck while the velocity swings.
#[test]
fn a_still_pin_and_a_stuck_channel_are_told_apart_from_a_saturated_one() {
    let good = record(0.3, FrictionLaw::coulomb_viscous(0.02, 0.01), 7, 2e-5);
    let mut rng = tribo_physics::sensor::Rng::new(11);
    // The rig's converters: 16 bits over ±2 mm and ±0.25 m/s.
    let q = |v: f64, fs: f64| {
        let lsb = 2.0 * fs / 65536.0;
        (v / lsb).round() * lsb
    };
    let mut still = good.clone();
    still
        .x
        .iter_mut()
        .for_each(|x| *x = q(667e-6 + 2e-8 * rng.normal(), 2e-3));
    still
        .v
        .iter_mut()
        .for_each(|v| *v = q(2e-5 * rng.normal(), 0.25));
    match screened(&still) {
        Err(NotAnalysable::NoOscillation { reason }) => {
            assert!(reason.contains("the pin never moves"), "{reason}")
        }
        other => panic!("{other:?}"),
    }
    let mut stuck_v = good.clone();
    stuck_v.v.iter_mut().for_each(|v| *v = q(0.0, 0.25));
    assert!(
        matches!(
            screened(&stuck_v),
            Err(NotAnalysable::Stuck {
                channel: "velocity",
                ..
            })
        ),
        "{:?}",
        screened(&stuck_v)
    );
    let mut stuck_x = good.clone();
    stuck_x.x.iter_mut().for_each(|x| *x = q(1e-4, 2e-3));
    assert!(
        matches!(
            screened(&stuck_x),
            Err(NotAnalysable::Stuck {
                channel: "displacement",
                ..
            })
        ),
        "{:?}",
        screened(&stuck_x)
    );
}

//! The firmware's on-board analysis run over a record (`tribo onboard`): runs the firmware's on-board analysis over a record, as if the
//! record were being sampled live by the rig.
//!
//! The record's SI samples are turned into 16-bit counts through a calibration that spans the record
//! like the rig's bipolar converters would (each channel's full scale is ±1.05 × its largest
//! magnitude, zero at mid-scale), then fed one by one to the very same
//! [`tribo_firmware::analysis::Pipeline`] the MCU runs. The release is read from the data as `tribo
//! fit` reads it (the velocity leaving its own noise for good, traced back along the sine); the
//! samples before it are the hold, captured as the rig captures it while the magnet holds (zeros
//! and noise: the reversal detector arms at 8 × that noise); a record that starts at the release
//! has no hold, and the pipeline reads the noise from the motion. The record must be uniformly
//! sampled (1 % jitter at most).
use crate::firmware::analysis::Pipeline;
use crate::firmware::calib;
use crate::physics::Record;
use crate::wire::{
    Channel, ChannelCal, ChannelSet, Configure, Estimate, OnboardResult, RigConstants, Verdict,
};
use anyhow::{bail, Context};
use std::fmt::Write as _;
/// Relative spread of the sampling interval tolerated (the pipeline assumes a uniform rate).
const MAX_JITTER: f64 = 0.01;
/// Full scale of each converter relative to the channel's largest magnitude in the record.
const HEADROOM: f64 = 1.05;

/// Runs the on-board pipeline over a record (sampled live, 16-bit counts) and returns its result.
/// The release is read from the data as `tribo fit` reads it.
pub fn analyse(record: &Record) -> anyhow::Result<OnboardResult> {
    analyse_released_at(record, None)
}

/// [`analyse`] with the release at sample `release` when it is known (as on the rig, where the
/// magnet's release is an event), else read from the data. The samples before it are the hold:
/// the pipeline captures them as the rig does while the magnet holds.
pub fn analyse_released_at(
    record: &Record,
    release: Option<usize>,
) -> anyhow::Result<OnboardResult> {
    record.validate()?;
    let rig = record.rig()?;
    let dt = record.dt();
    if !(dt.is_finite() && dt > 0.0) {
        bail!("cannot tell the sampling interval of the record");
    }
    if let Some(w) = record
        .t
        .windows(2)
        .find(|w| ((w[1] - w[0]) / dt - 1.0).abs() > MAX_JITTER)
    {
        bail!(
            "the record is not uniformly sampled (interval {} s at t = {} s, mean {dt} s); the on-board \
             analysis needs a constant sample rate",
            w[1] - w[0],
            w[0]
        );
    }
    let rate = (1.0 / dt).round();
    if !(1.0..=u32::MAX as f64).contains(&rate) {
        bail!("sample rate {rate} Hz is out of range");
    }
    let bipolar = |c: &[f64]| -> anyhow::Result<ChannelCal> {
        let peak = c.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let fs = if peak > 0.0 { HEADROOM * peak } else { 1.0 };
        calib::spanning(-fs, fs).context("cannot build a converter range for the record")
    };
    let mut calibration = [ChannelCal {
        gain: 1.0,
        zero: 0.0,
    }; 5];
    calibration[Channel::Displacement as usize] = bipolar(&record.x)?;
    calibration[Channel::Velocity as usize] = bipolar(&record.v)?;
    let mut channels = ChannelSet(0)
        .with(Channel::Displacement)
        .with(Channel::Velocity);
    if let Some(ft) = &record.ft {
        calibration[Channel::Force as usize] = bipolar(ft)?;
        channels = channels.with(Channel::Force);
    }
    // The release is read from the data as `tribo fit` reads it; what comes before it is the hold.
    let start = match release {
        Some(i) if i < record.len() => i,
        Some(i) => bail!(
            "the release at sample {i} is past the record's end ({} samples)",
            record.len()
        ),
        None => release_index(record),
    };
    // The release amplitude: the largest |x| over the first period after the release (the
    // release displacement itself for a record that starts held).
    let period = (2.0 * std::f64::consts::PI / rig.omega() / dt).ceil() as usize;
    let x0 = record
        .x
        .iter()
        .skip(start)
        .take(period.max(1))
        .fold(0.0f64, |m, v| m.max(v.abs()));
    let x0 = if x0 > 0.0 {
        x0
    } else {
        record.x.iter().fold(0.0f64, |m, v| m.max(v.abs()))
    };
    let duration =
        record.t.last().copied().unwrap_or(0.0) - record.t.first().copied().unwrap_or(0.0);
    let cfg = Configure {
        rig: RigConstants {
            mass_kg: rig.mass_kg as f32,
            stiffness_n_per_m: rig.stiffness_n_per_m as f32,
            load_n: rig.load_n as f32,
        },
        sample_rate_hz: rate as u32,
        channels,
        initial_amplitude_m: x0 as f32,
        max_duration_s: (duration + 2.0 * dt) as f32,
        calibration,
    };
    let mut pipeline = Pipeline::new(&cfg)?;
    let count = |ch: Channel, v: f64| calib::to_count(calibration[ch as usize], v).unwrap_or(0);
    let sample = |i: usize| -> ([u16; 3], usize) {
        let mut s = [0u16; 3];
        s[0] = count(Channel::Displacement, record.x[i]);
        s[1] = count(Channel::Velocity, record.v[i]);
        match &record.ft {
            Some(ft) => {
                s[2] = count(Channel::Force, ft[i]);
                (s, 3)
            }
            None => (s, 2),
        }
    };
    // The hold, as the rig captures it while the magnet holds: the zeros and the noise.
    for i in 0..start {
        let (s, n) = sample(i);
        pipeline.capture(&s[..n]);
    }
    pipeline.release();
    for i in start..record.len() {
        let (s, n) = sample(i);
        if pipeline.push(&s[..n]) != crate::firmware::analysis::Phase::Running {
            break;
        }
    }
    Ok(pipeline.finish(0))
}

/// Index at which to start feeding: a record may begin with the pin still held (v ≈ 0), and the
/// pipeline takes the first sample fed as the release (it waits for motion only so long, and a
/// noisy hold fed to it reads as no oscillation). The release is found as `tribo fit` finds it
/// ([`tribo_physics::identify::motion_span`]: the velocity leaving its own noise for good, traced
/// back along the sine), within a sample or two; feeding starts two samples before it.
fn release_index(record: &Record) -> usize {
    record
        .dimensionless()
        .map(|(tau, y, ydot)| tribo_physics::identify::motion_span(&tau, &y, &ydot).start)
        .unwrap_or(0)
        .saturating_sub(2)
}

fn num(v: f32) -> String {
    if v.is_finite() {
        format!("{v}")
    } else {
        "null".into()
    }
}

/// `f32` as a JSON number (`null` when not finite), printed as the shortest decimal that reads back
/// as the same `f32`.
fn jnum(v: f32) -> serde_json::Value {
    if v.is_finite() {
        format!("{v}")
            .parse::<f64>()
            .ok()
            .and_then(serde_json::Number::from_f64)
            .map_or(serde_json::Value::Null, serde_json::Value::Number)
    } else {
        serde_json::Value::Null
    }
}

fn estimate_json(e: &Estimate) -> serde_json::Value {
    serde_json::json!({
        "mu0": jnum(e.mu0),
        "mu1": jnum(e.mu1),
        "mu0_se": jnum(e.mu0_se),
        "mu1_se": jnum(e.mu1_se),
    })
}

/// The result as one JSON object: `mu0`, `mu1`, `mu0_se`, `mu1_se` (the value shown to the
/// technician and its standard error), `cycles`, `envelope_shape`, `verdict`, `frequency_hz`,
/// `curvature`, `initial_amplitude_m`, `duration_s`, and the two estimators under `averaging` and
/// `decrement`. Unavailable numbers are `null`.
pub fn to_json(r: &OnboardResult) -> String {
    serde_json::json!({
        "mu0": jnum(r.best.mu0),
        "mu1": jnum(r.best.mu1),
        "mu0_se": jnum(r.best.mu0_se),
        "mu1_se": jnum(r.best.mu1_se),
        "cycles": r.cycles,
        "envelope_shape": r.shape.name(),
        "verdict": r.verdict.name(),
        "frequency_hz": jnum(r.frequency_hz),
        "curvature": jnum(r.curvature),
        "initial_amplitude_m": jnum(r.initial_amplitude_m),
        "duration_s": jnum(r.duration_s),
        "averaging": estimate_json(&r.averaging),
        "decrement": estimate_json(&r.decrement),
    })
    .to_string()
}

/// The result as a short table for the terminal.
/// The on-board result as text; a dimensionless record's (`dimensionless`) frequency, amplitude
/// and duration are in its own units (per unit τ, y, τ), not Hz, m and s.
pub fn to_text(r: &OnboardResult, dimensionless: bool) -> String {
    let mut s = String::new();
    let row = |s: &mut String, name: &str, e: &Estimate| {
        let _ = writeln!(
            s,
            "{name:<10} mu0 = {:<12} ± {:<10} mu1 = {:<12} ± {}",
            num(e.mu0),
            num(e.mu0_se),
            num(e.mu1),
            num(e.mu1_se)
        );
    };
    let _ = writeln!(
        s,
        "verdict    {}{}",
        r.verdict.name(),
        if r.verdict == Verdict::EstimatorsDisagree {
            " — the decrement and averaging estimators disagree beyond their ±: the \
             Coulomb–viscous law may not describe this record (`tribo fit`, `tribo explain`)"
        } else {
            ""
        }
    );
    let (hz, m, sec) = if dimensionless {
        (" per unit τ", " (y)", " (τ)")
    } else {
        (" Hz", " m", " s")
    };
    let _ = writeln!(
        s,
        "cycles     {}   frequency {}{hz}   x0 {}{m}   duration {}{sec}",
        r.cycles,
        num(r.frequency_hz),
        num(r.initial_amplitude_m),
        num(r.duration_s)
    );
    row(&mut s, "best", &r.best);
    row(&mut s, "averaging", &r.averaging);
    row(&mut s, "decrement", &r.decrement);
    let _ = writeln!(s, "±          one standard error");
    let _ = writeln!(
        s,
        "envelope   {} (a2 = {})",
        r.shape.name(),
        num(r.curvature)
    );
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Exact Coulomb + viscous free response written as an SI record (f64, piecewise closed form).
    fn exact_record(load: f64, mu0: f64, mu1: f64, rate: f64, seconds: f64) -> Record {
        let (k, m, x0) = (1150.0f64, 0.04f64, 667e-6f64);
        let omega = f64::sqrt(k / m);
        let sigma = 0.5 * mu1 * omega;
        let wd = (omega * omega - sigma * sigma).sqrt();
        let (r, half) = (mu0 * load / k, std::f64::consts::PI / wd);
        let (mut t0, mut xs, mut stuck) = (0.0, x0, false);
        let (mut t, mut x, mut v) = (vec![], vec![], vec![]);
        for i in 0..(rate * seconds) as usize {
            let ti = i as f64 / rate;
            let mut e = r * xs.signum();
            while !stuck && ti >= t0 + half {
                xs = e - (xs - e) * (-sigma * half).exp();
                t0 += half;
                stuck = xs.abs() <= r;
                e = r * xs.signum();
            }
            let (xi, vi) = if stuck {
                (xs, 0.0)
            } else {
                let tau = ti - t0;
                let (s, c) = (wd * tau).sin_cos();
                let d = (-sigma * tau).exp();
                (
                    e + (xs - e) * d * (c + sigma / wd * s),
                    -(xs - e) * d * omega * omega / wd * s,
                )
            };
            t.push(ti);
            x.push(xi);
            v.push(vi);
        }
        let rig = crate::physics::Rig {
            mass_kg: m,
            stiffness_n_per_m: k,
            load_n: load,
        };
        Record::new(t, x, v, Some(rig), crate::physics::record::Units::Si)
    }

    #[test]
    fn a_csv_record_goes_through_the_firmware_pipeline() {
        let rec = exact_record(0.2, 0.02, 0.005, 10_000.0, 4.0);
        // through the CSV format, as the command reads it
        let rec = Record::from_csv_str(&rec.to_csv_string()).unwrap();
        let r = analyse(&rec).unwrap();
        assert_eq!(r.verdict, crate::wire::Verdict::Ok, "{r:?}");
        assert!(
            (r.best.mu0 - 0.02).abs() < 1e-3 && (r.best.mu1 - 0.005).abs() < 2e-4,
            "{r:?}"
        );
        let j = to_json(&r);
        let v: serde_json::Value = serde_json::from_str(&j).unwrap();
        for key in ["mu0", "mu1", "cycles", "envelope_shape", "mu0_se", "mu1_se"] {
            assert!(!v[key].is_null(), "{key} missing in {j}");
        }
        assert_eq!(v["verdict"], "ok");
        assert_eq!(v["mu0"].as_f64().unwrap() as f32, r.best.mu0);
        assert!(!j.contains("NaN") && !j.contains("inf"));
    }

    #[test]
    fn too_short_a_record_is_refused_with_nulls() {
        let rec = exact_record(0.7, 0.2, 0.01, 10_000.0, 1.0);
        let r = analyse(&rec).unwrap();
        assert_eq!(r.verdict, crate::wire::Verdict::TooFewCycles);
        let v: serde_json::Value = serde_json::from_str(&to_json(&r)).unwrap();
        assert!(
            v["mu0"].is_null() && v["verdict"] == "too-few-cycles",
            "{v}"
        );
    }

    #[test]
    fn a_held_start_is_skipped() {
        let rec = exact_record(0.2, 0.02, 0.005, 10_000.0, 4.0);
        let plain = analyse(&rec).unwrap();
        // prepend half a second of hold at x0
        let hold = 5000;
        let mut held = rec.clone();
        held.t = (0..hold + rec.len()).map(|i| i as f64 / 10_000.0).collect();
        held.x = std::iter::repeat_n(rec.x[0], hold)
            .chain(rec.x.iter().copied())
            .collect();
        held.v = std::iter::repeat_n(0.0, hold)
            .chain(rec.v.iter().copied())
            .collect();
        let r = analyse(&held).unwrap();
        assert_eq!(r.verdict, crate::wire::Verdict::Ok, "{r:?}");
        assert!(
            (r.best.mu0 - plain.best.mu0).abs() < 1e-4,
            "{r:?} vs {plain:?}"
        );
        assert!(
            (r.best.mu1 - plain.best.mu1).abs() < 2e-5,
            "{r:?} vs {plain:?}"
        );
    }

    /// Speckle dropouts of the vibrometer (single-sample spikes in the velocity, up to full scale,
    /// ten a second) do not stop the pipeline: it read "no oscillation" on every such record.
    #[test]
    fn speckle_dropouts_are_stood_in_for() {
        let rec = exact_record(0.3, 0.02, 0.01, 10_000.0, 2.0);
        let plain = analyse(&rec).unwrap();
        let mut spiky = rec.clone();
        let vmax = rec.v.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        for (k, i) in (500..spiky.len()).step_by(1_000).enumerate() {
            spiky.v[i] = if k % 2 == 0 {
                1.04 * vmax
            } else {
                -1.04 * vmax
            };
        }
        let r = analyse(&spiky).unwrap();
        assert_eq!(r.verdict, crate::wire::Verdict::Ok, "{r:?}");
        assert!(
            (r.best.mu0 - plain.best.mu0).abs() < 2e-4,
            "{r:?} vs {plain:?}"
        );
        assert!(
            (r.best.mu1 - plain.best.mu1).abs() < 2e-4,
            "{r:?} vs {plain:?}"
        );
    }

    #[test]
    fn irregular_sampling_is_an_error_not_a_panic() {
        let mut rec = exact_record(0.2, 0.02, 0.005, 10_000.0, 0.5);
        rec.t[100] += 0.5e-4;
        assert!(analyse(&rec).is_err());
    }
}

//! Disagreement measures of a fitted base model: envelope residual against
//! amplitude and time, windowed fits (thesis Tables 6–7), instantaneous frequency against
//! amplitude, force-channel lag and dissipated energy, temperature drift.

use crate::model::{linreg, residuals, rms, simulate_spec, Effect, Prepared};
use crate::FittedModel;
use serde::Serialize;
use tribo_physics::envelope::peaks;
use tribo_physics::identify::{windowed_fits, FitOptions, LawSpec};
use tribo_physics::integrate::Method;
use tribo_physics::sensor::delay;
use tribo_physics::uncertainty::effective_count;

/// Envelope residual statistics over a band.
#[derive(Debug, Clone, Serialize)]
pub struct Band {
    /// Band start (amplitude relative to the initial one, or fraction of the record).
    pub from: f64,
    /// Band end.
    pub to: f64,
    /// Mean of (simulated − measured envelope) / initial amplitude.
    pub mean: f64,
    /// RMS of it.
    pub rms: f64,
}

/// A windowed fit summary.
#[derive(Debug, Clone, Serialize)]
pub struct Window {
    /// Amplitude at the window start (dimensionless).
    pub a_start: f64,
    /// Amplitude at the window end.
    pub a_end: f64,
    /// Fitted `μ_j`.
    pub mu: Vec<f64>,
    /// Gap on the window.
    pub gap: f64,
}

/// Diagnostics of the base model.
#[derive(Debug, Clone, Serialize)]
pub struct Diagnostics {
    /// Envelope residual in amplitude bands (fractions of the initial amplitude).
    pub residual_by_amplitude: Vec<Band>,
    /// Envelope residual in time thirds (fractions of the record).
    pub residual_by_time: Vec<Band>,
    /// Base law fitted on windows of equal amplitude drop.
    pub windows: Vec<Window>,
    /// Largest relative drift of a constant between first and last window.
    pub window_drift: Option<f64>,
    /// Slope of the half-cycle angular frequency (in units of Ω) against amplitude².
    pub freq_slope_per_a2: Option<f64>,
    /// Cubic-spring estimate `κ = 8/3 · slope` (backbone of the Duffing oscillator).
    pub kappa_estimate: Option<f64>,
    /// Delay of the measured force behind the base model's force that best aligns them (s).
    pub force_lag_s: Option<f64>,
    /// Relative force RMS improvement that delay brings.
    pub force_lag_gain: Option<f64>,
    /// Friction energy dissipated according to the force channel divided by the base model's.
    pub dissipation_ratio: Option<f64>,
    /// Temperature slope (°C per second of record time).
    pub temp_slope_c_per_s: Option<f64>,
    /// Temperature change over the record (°C).
    pub temp_change_c: Option<f64>,
    /// Scatter of the temperature channel about the plate's temperature: RMS of the segment means
    /// (each [`crate::model::THERMAL_SEGMENT`] of τ) about the smoothed temperature thermal drift
    /// follows ([`crate::model::Prepared::temp_smooth`], a local straight line), i.e. the
    /// channel's noise, not a ramp's curvature (°C).
    pub temp_scatter_c: Option<f64>,
}

impl Diagnostics {
    /// Whether the temperature column moves over the motion: a change more than five times its
    /// scatter about the plate's (smoothed) temperature. Only then can the record show thermal
    /// drift beyond what the envelope alone says. (The scatter was about the straight line of the
    /// whole motion: a ramp that settles early in the motion, 0.6 K at 3 K/s over a 1.8 s motion,
    /// left the line 0.085 K RMS against a change of 0.36 K, and the column was read as still.)
    pub fn temperature_moves(&self) -> bool {
        match (self.temp_change_c, self.temp_scatter_c) {
            (Some(d), Some(s)) => d.is_finite() && s.is_finite() && d.abs() > 5.0 * s,
            _ => false,
        }
    }
}

/// Computes the diagnostics of `base` on `data`.
pub fn diagnose(data: &Prepared, base: &FittedModel, law: LawSpec) -> Diagnostics {
    let sim = simulate_spec(data, &base.spec, &base.p).ok();
    let (env, _) = sim.as_ref().map(|s| residuals(data, s)).unwrap_or_default();
    let a_rel: Vec<f64> = data.a_meas.iter().map(|a| a / data.a0).collect();
    let band = |sel: &dyn Fn(usize) -> bool, from: f64, to: f64| {
        let v: Vec<f64> = (0..env.len()).filter(|&i| sel(i)).map(|i| env[i]).collect();
        Band {
            from,
            to,
            mean: if v.is_empty() {
                0.0
            } else {
                v.iter().sum::<f64>() / v.len() as f64
            },
            rms: rms(&v),
        }
    };
    let edges = [1.01, 0.8, 0.6, 0.4, 0.2, 0.0];
    let residual_by_amplitude = edges
        .windows(2)
        .map(|w| {
            band(
                &|i| a_rel[i] <= w[0] && a_rel[i] > w[1],
                w[1],
                w[0].min(1.0),
            )
        })
        .collect();
    let n = env.len().max(1) as f64;
    let residual_by_time = (0..3)
        .map(|k| {
            let (a, b) = (k as f64 / 3.0, (k + 1) as f64 / 3.0);
            band(&|i| (i as f64 / n) >= a && (i as f64 / n) < b, a, b)
        })
        .collect();

    let wopts = FitOptions {
        method: Method::dopri(1e-8),
        max_points: 300,
        max_iter: 12,
        tol: 1e-9,
        ..FitOptions::default()
    };
    let windows: Vec<Window> = windowed_fits(&data.tau, &data.y, &data.ydot, law, 3, &wopts)
        .map(|ws| {
            ws.into_iter()
                .map(|w| Window {
                    a_start: w.a_start,
                    a_end: w.a_end,
                    mu: w.fit.mu,
                    gap: w.fit.gap,
                })
                .collect()
        })
        .unwrap_or_default();
    let window_drift = match (windows.first(), windows.last()) {
        (Some(a), Some(b)) if windows.len() >= 2 => {
            let scale: f64 = a.mu.iter().map(|v| v.abs()).fold(0.0, f64::max).max(1e-12);
            Some(
                a.mu.iter()
                    .zip(&b.mu)
                    .map(|(x, y)| (y - x).abs() / x.abs().max(0.05 * scale))
                    .fold(0.0, f64::max),
            )
        }
        _ => None,
    };

    let (freq_slope_per_a2, kappa_estimate) = match frequency_slope(data) {
        Some(s) => (Some(s), Some(8.0 / 3.0 * s)),
        None => (None, None),
    };

    let (mut force_lag_s, mut force_lag_gain, mut dissipation_ratio) = (None, None, None);
    if let (Some(fm), Some(s)) = (&data.f_meas, &sim) {
        let rss = |f: &[f64]| -> f64 {
            data.f_idx
                .iter()
                .map(|&i| (f[i] - fm[i]).powi(2))
                .sum::<f64>()
        };
        let r0 = rss(&s.f_meas);
        // Scan 0..10 ms (or 2 rad) in steps of about 0.1 ms.
        let max_d = (data.rig.tau_of_t(0.01).min(2.0) / data.dtau)
            .ceil()
            .max(1.0);
        let step = (max_d / 100.0).max(0.25);
        let mut best = (0.0, r0);
        let mut d = step;
        while d <= max_d {
            let r = rss(&delay(&s.f_meas, d));
            if r < best.1 {
                best = (d, r);
            }
            d += step;
        }
        force_lag_s = Some(data.rig.t_of_tau(best.0 * data.dtau));
        force_lag_gain = Some(1.0 - (best.1 / r0.max(1e-300)).sqrt());
        let work = |f: &[f64]| -> f64 { f.iter().zip(&data.ydot).map(|(a, v)| a * v).sum::<f64>() };
        let wm = work(&s.f_meas);
        if wm.abs() > 0.0 {
            dissipation_ratio = Some(work(fm) / wm);
        }
    }

    let (temp_slope_c_per_s, temp_change_c) = match data.temp {
        Some((_, slope)) => {
            let per_s = slope * data.rig.omega();
            let span = data.tau.last().copied().unwrap_or(0.0) - data.tau[0];
            (Some(per_s), Some(slope * span))
        }
        None => (None, None),
    };
    let temp_scatter_c = match (data.temp_seg.as_ref(), data.temp_smooth.as_ref()) {
        (Some(seg), Some(smooth)) if !seg.is_empty() && seg.len() == smooth.len() => {
            let ss: f64 = seg.iter().zip(smooth).map(|(v, s)| (v - s) * (v - s)).sum();
            Some((ss / seg.len() as f64).sqrt())
        }
        _ => None,
    };

    Diagnostics {
        residual_by_amplitude,
        residual_by_time,
        windows,
        window_drift,
        freq_slope_per_a2,
        kappa_estimate,
        force_lag_s,
        force_lag_gain,
        dissipation_ratio,
        temp_slope_c_per_s,
        temp_change_c,
        temp_scatter_c,
    }
}

/// Half-cycle frequency `π / Δτ` regressed on the squared mean amplitude of the half cycle
/// (half cycles above 20 % of the initial amplitude): the slope.
pub fn frequency_slope(data: &Prepared) -> Option<f64> {
    let pk = peaks(&data.tau, &data.y, &data.ydot, 1.0);
    let (mut a2, mut w) = (Vec::new(), Vec::new());
    for p in pk.windows(2) {
        let dt = p[1].0 - p[0].0;
        let a = 0.5 * (p[0].1 + p[1].1);
        if dt > 0.0 && a > 0.2 * data.a0 {
            a2.push(a * a);
            w.push(std::f64::consts::PI / dt);
        }
    }
    if a2.len() < 4 {
        return None;
    }
    linreg(&a2, &w).map(|(s, _)| s)
}

/// Where a model still disagrees with the record, in words a person can act on: each channel whose
/// misfit stands above [`tribo_physics::identify::ADEQUATE_RATIO`] × its noise floor, the part of
/// the motion (time third, amplitude band) where it is largest, and — on the force channel — a
/// misfit that differs between the two sliding directions. Empty when every channel is at its
/// floor.
pub fn locate(data: &Prepared, m: &FittedModel) -> Vec<String> {
    use tribo_physics::identify::ADEQUATE_RATIO;
    let mut out = Vec::new();
    let t_end = data.tau.last().copied().unwrap_or(0.0).max(1e-12);
    let secs = |tau: f64| data.rig.t_of_tau(tau);
    // (name, residuals, their sample indices, floor)
    let channels: [(&str, &[f64], &[usize], f64); 2] = [
        ("envelope", &m.env_resid, &data.env_idx, data.env_floor()),
        ("force", &m.force_resid, &data.f_idx, data.force_floor()),
    ];
    for (name, r, idx, floor) in channels {
        if r.is_empty() || floor <= 0.0 {
            continue;
        }
        let ratio = rms(r) / floor;
        if ratio <= ADEQUATE_RATIO {
            continue;
        }
        // By time thirds.
        let third = |k: usize| -> f64 {
            let v: Vec<f64> = r
                .iter()
                .zip(idx)
                .filter(|(_, &i)| ((3.0 * data.tau[i] / t_end) as usize).min(2) == k)
                .map(|(x, _)| *x)
                .collect();
            rms(&v) / floor
        };
        let by_time = [third(0), third(1), third(2)];
        let (kmax, rmax) = by_time
            .iter()
            .copied()
            .enumerate()
            .max_by(|a, b| a.1.total_cmp(&b.1))
            .unwrap_or((0, ratio));
        let what = if name == "envelope" {
            "the envelope (displacement and velocity)"
        } else {
            "the friction force channel"
        };
        out.push(format!(
            "{what} misses by {ratio:.2} × its noise floor, most in the {} third of the motion \
             (t = {:.2}–{:.2} s: {rmax:.2} × the floor; {:.2}, {:.2}, {:.2} by thirds)",
            ["first", "middle", "last"][kmax],
            secs(kmax as f64 * t_end / 3.0),
            secs((kmax + 1) as f64 * t_end / 3.0),
            by_time[0],
            by_time[1],
            by_time[2]
        ));
        if name == "envelope" {
            let edges = [1.01, 0.6, 0.3, 0.0];
            let bands: Vec<(f64, f64, f64)> = edges
                .windows(2)
                .map(|w| {
                    let v: Vec<f64> = r
                        .iter()
                        .zip(&data.a_meas)
                        .filter(|(_, &a)| a / data.a0 <= w[0] && a / data.a0 > w[1])
                        .map(|(x, _)| *x)
                        .collect();
                    (w[1], w[0].min(1.0), rms(&v) / floor)
                })
                .collect();
            if let Some((lo, hi, b)) = bands.iter().copied().max_by(|a, b| a.2.total_cmp(&b.2)) {
                out.push(format!(
                    "the envelope's misfit is largest at amplitudes of {:.0}–{:.0} % of the \
                     release ({b:.2} × the floor there)",
                    100.0 * lo,
                    100.0 * hi
                ));
            }
        } else {
            // The force misfit by sliding direction, away from the reversals.
            let vmax = idx.iter().map(|&i| data.ydot[i].abs()).fold(0.0, f64::max);
            let side = |sign: f64| -> Vec<f64> {
                r.iter()
                    .zip(idx)
                    .filter(|(_, &i)| sign * data.ydot[i] > 0.3 * vmax)
                    .map(|(x, _)| -*x)
                    .collect()
            };
            let (fw, bw) = (side(1.0), side(-1.0));
            if fw.len() >= 10 && bw.len() >= 10 {
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
                let se = |v: &[f64]| {
                    let mu = mean(v);
                    let c: Vec<f64> = v.iter().map(|x| x - mu).collect();
                    rms(&c) / effective_count(&c).max(1.0).sqrt()
                };
                let (mf, mb) = (mean(&fw), mean(&bw));
                let s = se(&fw).hypot(se(&bw));
                let newton = data.a0 * data.rig.load_n;
                // Measured − model, in N: the same sign both ways is a constant force, i.e. a
                // friction level that differs between the directions (forward μ0 + δ, backward
                // μ0 − δ) or an offset of the channel's zero; opposite signs, a level that is
                // too high or too low both ways.
                let common = 0.5 * (mf + mb);
                let level = 0.5 * (mf - mb);
                if common.abs() > 4.0 * 0.5 * s {
                    out.push(format!(
                        "the measured friction force stands {:+.2e} N from the model in both \
                         sliding directions (forward {:+.2e} N, backward {:+.2e} N; {:.0}σ): a \
                         friction level that depends on the sliding direction (the {} one \
                         higher by {:.2e} N, about {:.0} % of the mean level), or an offset of \
                         the force channel's zero",
                        common * newton,
                        mf * newton,
                        mb * newton,
                        common.abs() / (0.5 * s),
                        if common > 0.0 { "forward" } else { "backward" },
                        2.0 * common.abs() * newton,
                        100.0 * 2.0 * common.abs() * data.a0
                            / m.spec.mu(&m.p).first().copied().unwrap_or(f64::NAN).abs()
                    ));
                }
                if level.abs() > 4.0 * 0.5 * s {
                    out.push(format!(
                        "the measured friction level is {} than the model's by {:.2e} N in both \
                         sliding directions ({:.0}σ)",
                        if level > 0.0 { "higher" } else { "lower" },
                        level.abs() * newton,
                        level.abs() / (0.5 * s)
                    ));
                }
            }
        }
    }
    out
}

/// A friction level that depends on where on the track the pin slides: the force channel's
/// misfit while sliding (|y'| above 30 % of its largest), as a friction level (measured − model,
/// times the sliding direction), in bins of the displacement (a tenth of the release amplitude
/// wide), each bin against its mirror image about the centre. No effect of the vocabulary makes
/// the level at `y` differ from the level at `−y` (a speed-, time- or temperature-dependent level
/// is the same on both sides of a cycle; a direction asymmetry changes sign with the direction, not
/// the side); a worn or contaminated stripe, or a load that varies along the track, does.
#[derive(Debug, Clone, Serialize)]
pub struct PositionDependence {
    /// Mirror-bin pairs compared.
    pub pairs: usize,
    /// Σ z² over the pairs (each difference over its ±, the residuals' correlation accounted
    /// for).
    pub chi2: f64,
    /// The largest |z| of a pair.
    pub max_z: f64,
    /// Where (m; y for a dimensionless record): the bin centre of the side whose level stands
    /// higher than its mirror's in the pair of the largest |z|.
    pub at_m: f64,
    /// That pair's difference of level (higher side − lower side) relative to μ0.
    pub change_relative: f64,
    /// The level's profile across the track (`None`: too few sliding samples): what the mirror
    /// pairs cannot see, a level that depends on the distance from the centre alike on both
    /// sides (a stripe across the centre), told from a level that depends on the speed or the
    /// time by the amplitude's decay ([`AcrossTrack`]).
    pub across: Option<AcrossTrack>,
    /// Whether it is significant: the largest |z| of a mirror pair above 5, Σ z² above χ²'s
    /// 10⁻³ upper quantile for that many pairs, or the profile across the track significant.
    pub significant: bool,
}

/// The force channel's friction level (measured − model, as in [`PositionDependence`]) in bins
/// of the distance from the centre, |y|, a tenth of the release amplitude wide, with a level
/// changing with the speed (|y'|, y'²) and in time (t, t²) fitted beside them. No effect of the
/// vocabulary makes the level depend on where the pin is but through the speed or the time: at a
/// given |y| the speed changes from cycle to cycle as the amplitude decays, so a level that
/// follows the speed is the speed terms', and one that follows the time the time terms'. A
/// stripe of the track (worn, contaminated) holds its level at its |y| at every amplitude. The
/// mirror pairs cannot see a stripe across the centre; this can. A level that differs between
/// the outward and the inward half of a swing (`y sgn y'`, and its product with |y'|: a lag the
/// model has wrong) is fitted beside them too; a stripe is the same both ways. The bins' levels
/// are each poorly known beside those terms, so the profile as a whole is tested, not where it
/// peaks.
#[derive(Debug, Clone, Serialize)]
pub struct AcrossTrack {
    /// Bins compared (each with at least 20 sliding samples).
    pub bins: usize,
    /// The drop of the misfit when the level may differ bin by bin, over the residuals' variance
    /// (the correlation accounted for): χ² with `bins − 1` degrees of freedom when the level
    /// does not depend on |y|.
    pub chi2: f64,
    /// χ²'s 10⁻⁴ upper quantile for `bins − 1` degrees of freedom.
    pub threshold: f64,
    /// `chi2` above `threshold`, judged on a model that names a drift of μ0 (running-in, thermal
    /// drift: what a stripe across the centre looks like, its share of the sliding growing as the
    /// amplitude decays) or is otherwise at the record's noise floor. A model that still misses
    /// the record leaves a misfit with a profile across the track of its own, which says nothing
    /// of the track (grid #361: quadratic velocity and a sensor lag behind a 1-pole 106 Hz
    /// filter, neither named, χ² 76 over 9 bins).
    pub significant: bool,
}

impl PositionDependence {
    /// One sentence a person can act on.
    pub fn text(&self) -> String {
        let mirror_significant = mirror_significant(self.max_z, self.pairs, self.chi2);
        match self.across.as_ref().filter(|a| a.significant) {
            Some(a) if !mirror_significant => format!(
                "the friction level depends on the distance from the centre of the track, alike \
                 on both sides, beyond what a level following the speed or the time can make \
                 (χ² {:.1} over {} bins, {:.1} at 10⁻⁴) — not an effect of the vocabulary (a \
                 worn or contaminated stripe across the centre?)",
                a.chi2, a.bins, a.threshold
            ),
            _ => format!(
                "the friction level depends on where the pin slides: {:+.0} % of μ0 about {:.0} \
                 µm from the centre against the mirror side ({:.1}σ; {} bin pairs, χ² {:.1}) — \
                 not an effect of the vocabulary (a worn or contaminated stripe, a load that \
                 varies along the track?)",
                100.0 * self.change_relative,
                1e6 * self.at_m,
                self.max_z,
                self.pairs,
                self.chi2
            ),
        }
    }
}

/// Whether the mirror pairs of [`PositionDependence`] show a level that depends on the side: the
/// largest |z| above 5, or Σ z² above χ²'s 10⁻³ upper quantile for that many pairs.
fn mirror_significant(max_z: f64, pairs: usize, chi2: f64) -> bool {
    max_z > 5.0
        || (pairs > 0 && chi2 > tribo_physics::uncertainty::chi2_upper_quantile(pairs, 1e-3))
}

/// [`PositionDependence`] of the fitted model `m`'s force residuals; `None` without a force
/// channel or with too few sliding samples.
pub fn position_dependence(data: &Prepared, m: &FittedModel) -> Option<PositionDependence> {
    let r = &m.force_resid;
    let idx = &data.f_idx;
    if r.is_empty() || r.len() != idx.len() {
        return None;
    }
    let vmax = idx.iter().map(|&i| data.ydot[i].abs()).fold(0.0, f64::max);
    const BINS: usize = 20;
    let mut bins: Vec<Vec<f64>> = vec![Vec::new(); BINS];
    let mut all = Vec::new();
    // (|y| / a0, |y'| / vmax, τ, level, y sgn y' / a0) of every sliding sample, for the profile
    // across the track.
    let mut sliding = Vec::new();
    for (x, &i) in r.iter().zip(idx) {
        let v = data.ydot[i];
        if v.abs() <= 0.3 * vmax {
            continue;
        }
        // Measured − model, as a friction level (the sign of the sliding direction taken off).
        let u = -x * v.signum();
        let pos = data.y[i] / data.a0;
        let b = (((pos + 1.0) * 0.5 * BINS as f64).floor() as isize).clamp(0, BINS as isize - 1);
        bins[b as usize].push(u);
        all.push(u);
        sliding.push((pos.abs(), v.abs() / vmax, data.tau[i], u, pos * v.signum()));
    }
    if all.len() < 100 {
        return None;
    }
    // The residuals' correlation: each bin's variance inflated by n / n_eff of the whole series.
    let inflate = all.len() as f64 / effective_count(&all).max(1.0);
    let drift_named = m
        .spec
        .effects
        .iter()
        .any(|e| matches!(e, Effect::RunningIn | Effect::ThermalDrift));
    let judged = drift_named || m.adequate(data);
    let across = across_track(&sliding, inflate, BINS / 2).map(|(bins, chi2)| {
        let threshold = tribo_physics::uncertainty::chi2_upper_quantile(bins - 1, 1e-4);
        AcrossTrack {
            bins,
            chi2,
            threshold,
            significant: judged && chi2 > threshold,
        }
    });
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
    let var = |v: &[f64]| {
        let mu = mean(v);
        v.iter().map(|x| (x - mu) * (x - mu)).sum::<f64>() / (v.len() as f64 - 1.0).max(1.0)
    };
    let mu0 = m.spec.mu(&m.p).first().copied().unwrap_or(f64::NAN).abs();
    let (mut pairs, mut chi2) = (0usize, 0.0);
    let mut best: Option<(f64, f64, f64)> = None; // (|z|, position of the higher side, Δ)
    for b in 0..BINS / 2 {
        let (lo, hi) = (&bins[b], &bins[BINS - 1 - b]);
        if lo.len() < 20 || hi.len() < 20 {
            continue;
        }
        let d = mean(hi) - mean(lo);
        let se = (inflate * (var(hi) / hi.len() as f64 + var(lo) / lo.len() as f64)).sqrt();
        if !(se.is_finite() && se > 0.0) {
            continue;
        }
        let z = d / se;
        pairs += 1;
        chi2 += z * z;
        let centre = ((BINS - 1 - b) as f64 + 0.5) / BINS as f64 * 2.0 - 1.0;
        let at = if d > 0.0 { centre } else { -centre };
        if best.is_none_or(|(bz, _, _)| z.abs() > bz) {
            best = Some((z.abs(), at, d.abs()));
        }
    }
    let (max_z, at, d) = best?;
    let across_significant = across.as_ref().is_some_and(|a| a.significant);
    Some(PositionDependence {
        pairs,
        chi2,
        max_z,
        at_m: data.rig.x_of_y(at * data.a0),
        change_relative: d * data.a0 / mu0,
        significant: mirror_significant(max_z, pairs, chi2) || across_significant,
        across,
    })
}

/// A drift of μ0 in time (running-in) against a stripe of the track, on the force channel
/// ([`drift_or_stripe`]).
#[derive(Debug, Clone, Serialize)]
pub struct DriftOrStripe {
    /// The drift's evidence: the drop of the force channel's misfit, as a friction level, when
    /// the drift's own shape (the model with it less the model without) is fitted to the model
    /// without it, over the residuals' variance (their correlation accounted for).
    pub drift: f64,
    /// The same for the best stripe: a level that differs over one stretch of the track.
    pub stripe: f64,
    /// The best stripe's evidence beside the drift: the drop of the misfit when a stripe is
    /// fitted as well as the drift, over the variance left by both.
    pub stripe_beside_drift: f64,
    /// The drift's evidence beside the best stripe alone, the same way.
    pub drift_beside_stripe: f64,
    /// Where that stripe lies along the track (m from the centre, or the record's unit of
    /// displacement; from, to).
    pub stripe_from_to_m: (f64, f64),
    /// What the stripe must beat the drift by to take the name from it: the penalty of its own
    /// freedom (where it lies, 3 constants against the drift's) as the evidence thresholds
    /// count it, set by the caller.
    pub freedom: f64,
    /// Whether the stripe, less its freedom, is within the margin a candidate needs over its
    /// runner-up of the drift ([`crate::ExplainOptions::min_margin`]), set by the caller: a
    /// drift named so carries the stripe as a caveat.
    pub close: bool,
}

/// A drift of μ0 in time, fitted as `with` beside the model `without` it, against a stripe of
/// the track (worn, contaminated: a friction level that differs over one stretch of it), on the
/// force channel's friction level (measured − model, the sliding direction's sign taken off) of
/// `without`: each fitted beside a constant and a level that differs between the outward and the
/// inward half of a swing, the drift as its own shape (`with`'s level less `without`'s), the
/// stripe over every stretch of whole bins a tenth of the release amplitude wide. A stripe near
/// the centre makes the mean friction level rise as the amplitude decays, its share of each
/// swing growing: a drift in time takes it, but within a swing the level stays where the stripe
/// is; a drift changes the level everywhere from cycle to cycle. On the randomized grid (520
/// records, seed 1, as the example `explain_lhs` runs it): #499, a +30 % stripe across the
/// centre at ×24 noise, named running-in at evidence 134, has the stripe at 179 and the drift at
/// 146; records with
/// running-in strong in the compared motion (8–30 %) have the drift ahead by 36–500, weak ones
/// (2–7 %) within a few units of the stripe, as #483 (a −11 % stripe, 102 against 103). Each
/// is also fitted beside the other: a stripe the drift takes most of still leaves a share
/// beside it (#483, 17.3), where a drift leaves a stripe little (running-in on the grid, at
/// most 10.1). The same comparison serves a cubic stiffness, its shape in the drift's place. The
/// samples are those sliding at more than 0.3 of the swing's speed amplitude (reversals left
/// out), at every amplitude. `None` without a force channel, with too few sliding samples or a
/// singular fit.
pub fn drift_or_stripe(
    data: &Prepared,
    without: &FittedModel,
    with: &FittedModel,
) -> Option<DriftOrStripe> {
    let (r0, r1, idx) = (&without.force_resid, &with.force_resid, &data.f_idx);
    if r0.is_empty() || r0.len() != idx.len() || r1.len() != idx.len() {
        return None;
    }
    const BINS: usize = 20;
    // Per bin: Σ1, Σw, Σw², Σy, Σwy, Σd (y the level, w = y/a0 sgn y', d the drift's level).
    let mut per = [[0.0f64; 6]; BINS];
    // Over all: the same, Σy², and Σd, Σwd, Σd², Σdy (d the drift's level).
    let mut all = [0.0f64; 10];
    let mut levels = Vec::new();
    for ((&a, &b), &i) in r0.iter().zip(r1).zip(idx) {
        let (v, y) = (data.ydot[i], data.y[i]);
        if v.abs() <= 0.3 * y.hypot(v) {
            continue;
        }
        let pos = y / data.a0;
        let bin = (((pos + 1.0) * 0.5 * BINS as f64).floor() as isize).clamp(0, BINS as isize - 1);
        let w = pos * v.signum();
        // Residuals are measured − model: the drift's level is `with`'s model less `without`'s.
        let (u, d) = (-a * v.signum(), (b - a) * v.signum());
        let row = [1.0, w, w * w, u, w * u, d];
        for (s, x) in per[bin as usize].iter_mut().zip(row) {
            *s += x;
        }
        for (s, x) in all
            .iter_mut()
            .zip([1.0, w, w * w, u, w * u, u * u, d, w * d, d * d, d * u])
        {
            *s += x;
        }
        levels.push(u);
    }
    let n = levels.len();
    if n < 100 {
        return None;
    }
    let [s1, sw, sww, sy, swy, syy, sd, swd, sdd, sdy] = all;
    // The misfit left by [1, w, x] given Σx, Σwx, Σx², Σxy.
    let rss3 = |sx: f64, swx: f64, sxx: f64, sxy: f64| -> Option<f64> {
        let a = vec![vec![s1, sw, sx], vec![sw, sww, swx], vec![sx, swx, sxx]];
        let rhs = [sy, swy, sxy];
        let beta = tribo_physics::identify::solve(a, rhs.to_vec())?;
        Some(syy - beta.iter().zip(rhs).map(|(b, r)| b * r).sum::<f64>())
    };
    // [1, w] alone (the stretch empty).
    let rss0 = rss3(0.0, 0.0, 1.0, 0.0)?;
    let rss_drift = rss3(sd, swd, sdd, sdy)?;
    // The misfit left by [1, w, d, x] (the drift and a stripe together) given the stripe's Σx,
    // Σwx, Σdx, Σxy (x an indicator: Σx² = Σx).
    let rss_both = |sx: f64, swx: f64, sdx: f64, sxy: f64| -> Option<f64> {
        let a = vec![
            vec![s1, sw, sd, sx],
            vec![sw, sww, swd, swx],
            vec![sd, swd, sdd, sdx],
            vec![sx, swx, sdx, sx],
        ];
        let rhs = [sy, swy, sdy, sxy];
        let beta = tribo_physics::identify::solve(a, rhs.to_vec())?;
        Some(syy - beta.iter().zip(rhs).map(|(b, r)| b * r).sum::<f64>())
    };
    // The best stripe alone (its misfit, from, to, and the misfit beside the drift), and the
    // least misfit of a stripe beside the drift.
    let mut stripe: Option<(f64, usize, usize, f64)> = None;
    let mut both_min = f64::INFINITY;
    for from in 0..BINS {
        let mut acc = [0.0f64; 6];
        for (to, bin) in per.iter().enumerate().skip(from) {
            for (s, x) in acc.iter_mut().zip(bin) {
                *s += x;
            }
            // A stretch of fewer than 20 samples, or of all of them, is no stripe.
            if acc[0] < 20.0 || s1 - acc[0] < 20.0 {
                continue;
            }
            // The indicator's sums: Σ1 = Σx = Σx², Σwx, Σxy over the stretch.
            let both = rss_both(acc[0], acc[1], acc[5], acc[3]).unwrap_or(f64::NAN);
            if both < both_min {
                both_min = both;
            }
            if let Some(r) = rss3(acc[0], acc[1], acc[0], acc[3]) {
                if stripe.is_none_or(|(b, ..)| r < b) {
                    stripe = Some((r, from, to, both));
                }
            }
        }
    }
    let (rss_stripe, from, to, rss_beside) = stripe?;
    let inflate = n as f64 / effective_count(&levels).max(1.0);
    let s2 = inflate * rss_drift.min(rss_stripe) / (n - 4) as f64;
    let s2_both = inflate * both_min / (n - 5) as f64;
    let beyond = |r: f64, r_both: f64| {
        let e = (r - r_both).max(0.0) / s2_both;
        if e.is_finite() {
            e
        } else {
            0.0
        }
    };
    let edge = |b: usize| {
        data.rig
            .x_of_y((b as f64 / BINS as f64 * 2.0 - 1.0) * data.a0)
    };
    (s2.is_finite() && s2 > 0.0).then(|| DriftOrStripe {
        drift: (rss0 - rss_drift).max(0.0) / s2,
        stripe: (rss0 - rss_stripe).max(0.0) / s2,
        stripe_beside_drift: beyond(rss_drift, both_min),
        drift_beside_stripe: beyond(rss_stripe, rss_beside),
        stripe_from_to_m: (edge(from), edge(to + 1)),
        freedom: 0.0,
        close: false,
    })
}

/// The level's profile across the track ([`AcrossTrack`]) from the sliding samples `(|y| / a0,
/// |y'| / vmax, τ, level, y sgn y' / a0)`, in `bins` bins of |y| / a0 over [0, 1], their variance
/// inflated by `inflate` (n / n_eff): `(bins compared, χ²)`. `None` with fewer than two bins of 20
/// samples or a singular fit.
fn across_track(
    s: &[(f64, f64, f64, f64, f64)],
    inflate: f64,
    bins: usize,
) -> Option<(usize, f64)> {
    let bin = |a: f64| ((a * bins as f64).floor() as usize).min(bins - 1);
    let mut count = vec![0usize; bins];
    for &(a, ..) in s {
        count[bin(a)] += 1;
    }
    let used: Vec<usize> = (0..bins).filter(|&b| count[b] >= 20).collect();
    if used.len() < 2 {
        return None;
    }
    let col = |b: usize| used.iter().position(|&u| u == b);
    let (t_lo, t_hi) = s
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x.2), hi.max(x.2))
        });
    let t_span = (t_hi - t_lo).max(1e-12);
    // The speed and time terms, |y'|, y'², t, t² (t over [−1, 1]), and a level that differs
    // between the outward and the inward half of a swing, y sgn y' and its product with |y'| (a
    // lag of the friction or of the channel, a low-pass the model has wrong: the force lags the
    // speed's rise and fall alike at every amplitude; a stripe is the same both ways).
    let smooth = |&(_, v, t, _, w): &(f64, f64, f64, f64, f64)| {
        let t = 2.0 * (t - t_lo) / t_span - 1.0;
        [v, v * v, t, t * t, w, w * v]
    };
    let kept: Vec<&(f64, f64, f64, f64, f64)> =
        s.iter().filter(|x| col(bin(x.0)).is_some()).collect();
    let rss = |rows: &[Vec<f64>], y: &[f64]| -> Option<f64> {
        let beta = tribo_physics::identify::least_squares(rows, y)?;
        Some(
            rows.iter()
                .zip(y)
                .map(|(row, &y)| {
                    let f: f64 = row.iter().zip(&beta).map(|(a, b)| a * b).sum();
                    (y - f) * (y - f)
                })
                .sum(),
        )
    };
    let y: Vec<f64> = kept.iter().map(|x| x.3).collect();
    let full: Vec<Vec<f64>> = kept
        .iter()
        .map(|x| {
            let mut row = vec![0.0; used.len()];
            row[col(bin(x.0))?] = 1.0;
            row.extend(smooth(x));
            Some(row)
        })
        .collect::<Option<_>>()?;
    let reduced: Vec<Vec<f64>> = kept
        .iter()
        .map(|x| {
            let mut row = vec![1.0];
            row.extend(smooth(x));
            row
        })
        .collect();
    let n = y.len();
    if n <= full[0].len() + 10 {
        return None;
    }
    let rss_full = rss(&full, &y)?;
    let rss_reduced = rss(&reduced, &y)?;
    let s2 = inflate * rss_full / (n - full[0].len()) as f64;
    if !(s2.is_finite() && s2 > 0.0) {
        return None;
    }
    Some((used.len(), (rss_reduced - rss_full).max(0.0) / s2))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::law::FrictionLaw;
    use tribo_physics::model::{Model, Rig};
    use tribo_physics::sensor::{generate, RecordSpec};

    #[test]
    fn frequency_slope_follows_the_duffing_backbone() {
        // Weakly damped Duffing oscillator: ω(A) = 1 + 3κA²/8 (first-order backbone).
        let kappa = 2e-3;
        let m = Model::new(FrictionLaw::coulomb_viscous(0.01, 0.002)).with_cubic(kappa);
        let sp = RecordSpec {
            rig: Rig::REAL,
            x0_m: 667e-6,
            v0_m_s: 0.0,
            duration_s: 1.0,
            rate_hz: 10_000.0,
        };
        let rec = generate(&sp, &m, Method::dopri(1e-10), None).unwrap();
        let data = Prepared::new(&rec, 400, 3000, None).unwrap();
        let s = frequency_slope(&data).unwrap();
        let k = 8.0 / 3.0 * s;
        assert!((k - kappa).abs() < 0.1 * kappa, "kappa estimate {k}");
        // A linear spring has no slope.
        let rec = generate(
            &sp,
            &Model::new(FrictionLaw::coulomb_viscous(0.01, 0.002)),
            Method::dopri(1e-10),
            None,
        )
        .unwrap();
        let data = Prepared::new(&rec, 400, 3000, None).unwrap();
        assert!(frequency_slope(&data).unwrap().abs() < 0.05 * s);
    }
}

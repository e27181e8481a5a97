//! On-board analysis: raw counts in, μ0 and μ1 out, sample by sample, in constant memory.
//!
//! ```text
//! counts ─▶ calib (gain, zero; zeros captured while held) ─▶ peaks (velocity reversals, fitted peak)
//!                                                       └──▶ envelope (half-cycle moments)
//!        at each reversal: one HalfCycle record (20 bytes) ─▶ finish(): frequency, two fits, verdict
//! ```
//!
//! Use: [`Pipeline::new`] from the `Configure` message; [`Pipeline::capture`] every sample while the
//! magnet holds the pin; [`Pipeline::release`] when it lets go; [`Pipeline::push`] every sample until
//! [`Pipeline::is_finished`]; then [`Pipeline::finish`].
//!
//! # Zeros
//! While held the pin is at rest at `x0`: the velocity and force zeros are the mean counts of the hold,
//! and the displacement zero is set so that the hold reads `+x0` (the configured initial amplitude).
//! The analysis itself does not depend on the displacement zero: each estimator finds the centre of the
//! oscillation from the motion (the decrement fit as a parameter, the averaging fit as the mean
//! displacement over an even number of half-cycles), so an inexact `x0` or a vibrometer whose
//! displacement is not referenced to the rest position costs nothing. Without any hold sample the
//! configured zeros are kept.
//!
//! # Estimators (dimensionless: y = k x / N, τ = Ω t)
//! * **Decrement**: successive fitted peak magnitudes obey `X_{n+1} = D X_n − r (1 + D)` exactly for
//!   Coulomb + viscous friction; regressed on signed peaks with an alternating term that absorbs the
//!   displacement offset. `μ1 = 2ζ` with `D = exp(−π ζ / sqrt(1 − ζ²))`, `μ0 = r k / N`.
//! * **Averaging**: `dA/dτ = a0 + a1 A`, `μ0 = −π a0 / 2`, `μ1 = −2 a1`, regressed on the half-cycle
//!   RMS Mark & Crandall envelope with central differences over two half-cycles. The envelope is taken
//!   about each half-cycle's own centre of oscillation (offset ± the Coulomb shift r = μ0 N / k, with
//!   μ0 from this same fit, iterated), which removes the `r²/2A` bias of the plain envelope near the
//!   end of Coulomb-dominated runs. A quadratic `a2 A²` fitted alongside gives the envelope's shape.
//!
//! The technician is shown the inverse-variance mean of the two ([`OnboardResult::best`]); its
//! standard error includes half their difference in quadrature. When they differ by more than the
//! method's stated precision (μ0 ± 0.001, μ1 ± 0.0002) plus three combined standard errors, the
//! verdict is `EstimatorsDisagree` (typically: the friction law is not Coulomb–viscous).
use crate::calib::{self, OffsetCapture, ADC_MAX, CHANNELS};
use crate::envelope::{HalfCycleMoments, Moments};
use crate::fit::{self, Ols};
use crate::peaks::{PeakFitter, ReversalDetector};
use crate::wire::{Channel, ChannelCal, Configure, EnvelopeShape, Estimate, OnboardResult, Verdict};
use core::f64::consts::PI;

/// Capacity of the half-cycle store: 1024 cycles, 39 s at 26 Hz. A run that fills it stops there.
pub const MAX_HALF_CYCLES: usize = 2048;
/// Fewer complete cycles than this and no estimate is reported (the thesis's minimum).
pub const MIN_CYCLES: u16 = 5;
/// Stated precision of the method on μ0 (used by the cross-check).
pub const MU0_PRECISION: f64 = 0.001;
/// Stated precision of the method on μ1 (used by the cross-check).
pub const MU1_PRECISION: f64 = 0.0002;
/// Number of noise standard deviations the velocity must exceed to arm the reversal detector.
const ARM_SIGMAS: f64 = 8.0;
/// Noise floor (counts) assumed when no hold sample was captured, and minimum noise used.
const MIN_NOISE_COUNTS: f64 = 1.0;

/// A `Configure` the pipeline cannot work with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ConfigError {
    /// Mass not finite and positive.
    Mass,
    /// Stiffness not finite and positive.
    Stiffness,
    /// Normal load not finite and positive.
    Load,
    /// Sample rate zero.
    SampleRate,
    /// Maximum duration not finite and positive.
    MaxDuration,
    /// Initial amplitude not finite and positive.
    InitialAmplitude,
    /// The channel set lacks a channel the analysis needs.
    MissingChannel(Channel),
    /// A needed channel's calibration has a zero or non-finite gain, or a non-finite zero.
    Calibration(Channel),
    /// The sample rate is not above 8 × the natural frequency (too few samples per half-cycle).
    Undersampled,
}

impl core::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            Self::Mass => f.write_str("mass must be a positive number of kg"),
            Self::Stiffness => f.write_str("stiffness must be a positive number of N/m"),
            Self::Load => f.write_str("normal load must be a positive number of N"),
            Self::SampleRate => f.write_str("sample rate must be positive"),
            Self::MaxDuration => f.write_str("maximum duration must be a positive number of seconds"),
            Self::InitialAmplitude => f.write_str("initial amplitude must be a positive number of metres"),
            Self::MissingChannel(c) => write!(f, "the on-board analysis needs the {c:?} channel"),
            Self::Calibration(c) => write!(f, "the {c:?} calibration needs a finite non-zero gain and a finite zero"),
            Self::Undersampled => f.write_str("sample rate must exceed 8 times the natural frequency sqrt(k/m)/2π"),
        }
    }
}

/// Why the pipeline stopped taking samples.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum StopReason {
    /// No reversal for 1.5 half-periods after the last one: the pin sticks.
    AtRest,
    /// The half-amplitude between the last two peaks fell to the displacement noise.
    InNoise,
    /// No reversal at all within three expected half-periods of release.
    NoMotion,
    /// `max_duration_s` reached.
    MaxDuration,
    /// [`MAX_HALF_CYCLES`] half-cycles stored.
    BufferFull,
}

/// Where the pipeline is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Phase {
    /// Before release: samples go to the offset capture.
    Holding,
    /// Oscillating: samples are analysed.
    Running,
    /// Stopped; [`Pipeline::finish`] gives the result.
    Finished(StopReason),
}

/// What is kept of one half-cycle, recorded at the velocity reversal that ends it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HalfCycle {
    /// Time of the reversal after release (s), interpolated between samples.
    pub t: f32,
    /// Displacement at the reversal (m, calibrated zero), fitted over ±1 rad.
    pub peak: f32,
    /// Moments of the two vibrometer channels over the half-cycle that ends here.
    pub moments: HalfCycleMoments,
}

#[derive(Clone, Copy, Debug)]
struct Pending {
    due: u32,
    t: f64,
    moments: HalfCycleMoments,
}

/// The on-board analysis of one run (≈ 43 KiB; keep it in a `static`, or reuse it with
/// [`Pipeline::reset`]).
#[derive(Clone, Debug)]
pub struct Pipeline {
    mass: f64,
    stiffness: f64,
    load: f64,
    rate: f64,
    x0: f64,
    max_samples: u32,
    slot_x: usize,
    slot_v: usize,
    /// Channel of each slot of a sample vector.
    slots: [u8; CHANNELS],
    width: usize,
    cal: [ChannelCal; CHANNELS],
    capture: OffsetCapture,
    phase: Phase,
    n: u32,
    x_ref: i32,
    v_ref: i32,
    x_release: f32,
    noise_x: f64,
    detector: ReversalDetector,
    fitter: PeakFitter,
    moments: Moments,
    pending: Option<Pending>,
    records: heapless::Vec<HalfCycle, MAX_HALF_CYCLES>,
    first_sign: i8,
    last_rev: f64,
    half_period: f64,
    saturated: u32,
    rejected: u32,
}

fn positive(v: f32) -> Option<f64> {
    (v.is_finite() && v > 0.0).then_some(v as f64)
}

fn cal_ok(c: ChannelCal) -> bool {
    c.gain.is_finite() && c.gain != 0.0 && c.zero.is_finite()
}

impl Pipeline {
    /// A pipeline for the run described by `cfg`, in the holding phase.
    pub fn new(cfg: &Configure) -> Result<Self, ConfigError> {
        let mass = positive(cfg.rig.mass_kg).ok_or(ConfigError::Mass)?;
        let stiffness = positive(cfg.rig.stiffness_n_per_m).ok_or(ConfigError::Stiffness)?;
        let load = positive(cfg.rig.load_n).ok_or(ConfigError::Load)?;
        if cfg.sample_rate_hz == 0 {
            return Err(ConfigError::SampleRate);
        }
        let rate = cfg.sample_rate_hz as f64;
        let max_duration = positive(cfg.max_duration_s).ok_or(ConfigError::MaxDuration)?;
        let x0 = positive(cfg.initial_amplitude_m).ok_or(ConfigError::InitialAmplitude)?;
        let slot_x = calib::slot(cfg.channels, Channel::Displacement).ok_or(ConfigError::MissingChannel(Channel::Displacement))?;
        let slot_v = calib::slot(cfg.channels, Channel::Velocity).ok_or(ConfigError::MissingChannel(Channel::Velocity))?;
        let cal = cfg.calibration;
        if !cal_ok(cal[Channel::Displacement as usize]) {
            return Err(ConfigError::Calibration(Channel::Displacement));
        }
        if !cal_ok(cal[Channel::Velocity as usize]) {
            return Err(ConfigError::Calibration(Channel::Velocity));
        }
        let omega = fit::sqrt(stiffness / mass);
        // half-period in samples
        let half_period = PI / omega * rate;
        if !(half_period > 4.0) {
            return Err(ConfigError::Undersampled);
        }
        let mut slots = [0u8; CHANNELS];
        let mut width = 0;
        for ch in 0..CHANNELS as u8 {
            if cfg.channels.0 & (1 << ch) != 0 {
                if let Some(s) = slots.get_mut(width) {
                    *s = ch;
                }
                width += 1;
            }
        }
        let max_samples = (max_duration * rate).min(u32::MAX as f64) as u32;
        let mut fitter = PeakFitter::new();
        fitter.set_step(PI / half_period);
        Ok(Self {
            mass,
            stiffness,
            load,
            rate,
            x0,
            max_samples,
            slot_x,
            slot_v,
            slots,
            width,
            cal,
            capture: OffsetCapture::default(),
            phase: Phase::Holding,
            n: 0,
            x_ref: 0,
            v_ref: 0,
            x_release: f32::NAN,
            noise_x: 0.0,
            detector: ReversalDetector::new(f32::MAX),
            fitter,
            moments: Moments::default(),
            pending: None,
            records: heapless::Vec::new(),
            first_sign: 1,
            last_rev: 0.0,
            half_period,
            saturated: 0,
            rejected: 0,
        })
    }

    /// Re-initialises in place for a new run (no 43 KiB temporary on the stack of the caller beyond
    /// the one `new` builds). On error the pipeline is left unchanged.
    pub fn reset(&mut self, cfg: &Configure) -> Result<(), ConfigError> {
        *self = Self::new(cfg)?;
        Ok(())
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        self.phase
    }

    /// True once the run has stopped (pin at rest, amplitude in the noise, maximum duration, store
    /// full, or no motion).
    pub fn is_finished(&self) -> bool {
        matches!(self.phase, Phase::Finished(_))
    }

    /// Samples analysed since release.
    pub fn samples(&self) -> u32 {
        self.n
    }

    /// Sample vectors refused because they were shorter than the channel set.
    pub fn rejected(&self) -> u32 {
        self.rejected
    }

    /// Calibration in use (zeros updated by the capture at release).
    pub fn calibration(&self) -> &[ChannelCal; CHANNELS] {
        &self.cal
    }

    /// Half-cycles recorded so far.
    pub fn half_cycles(&self) -> &[HalfCycle] {
        &self.records
    }

    /// SI value of one channel's count with the current calibration.
    pub fn to_si(&self, channel: Channel, count: u16) -> f32 {
        self.cal.get(channel as usize).map_or(f32::NAN, |c| calib::to_si(*c, count))
    }

    /// Feeds one sample taken while the magnet holds the pin (counts in the channel-set order).
    /// Ignored once released.
    pub fn capture(&mut self, counts: &[u16]) {
        if self.phase != Phase::Holding {
            return;
        }
        if counts.len() < self.width {
            self.rejected = self.rejected.saturating_add(1);
            return;
        }
        let slots = self.slots;
        self.capture.add(counts.iter().zip(slots.iter()).map(|(&c, &ch)| (ch as usize, c)));
    }

    /// The magnet has let go: fixes the zeros and the noise thresholds and starts the analysis.
    pub fn release(&mut self) {
        if self.phase != Phase::Holding {
            return;
        }
        let xi = Channel::Displacement as usize;
        let vi = Channel::Velocity as usize;
        let fi = Channel::Force as usize;
        if let Some(m) = self.capture.mean(vi) {
            if let Some(c) = self.cal.get_mut(vi) {
                c.zero = m as f32;
            }
        }
        if let Some(m) = self.capture.mean(fi) {
            if let Some(c) = self.cal.get_mut(fi) {
                c.zero = m as f32;
            }
        }
        if let Some(m) = self.capture.mean(xi) {
            if let Some(c) = self.cal.get_mut(xi) {
                let z = m - self.x0 / c.gain as f64;
                if z.is_finite() {
                    c.zero = z as f32;
                }
            }
        }
        let xc = self.cal[xi];
        let vc = self.cal[vi];
        let sx = self.capture.std(xi).unwrap_or(MIN_NOISE_COUNTS).max(MIN_NOISE_COUNTS);
        let sv = self.capture.std(vi).unwrap_or(MIN_NOISE_COUNTS).max(MIN_NOISE_COUNTS);
        self.noise_x = sx * (xc.gain as f64).abs();
        self.detector = ReversalDetector::new((ARM_SIGMAS * sv * (vc.gain as f64).abs()) as f32);
        self.x_ref = (xc.zero as f64).clamp(0.0, ADC_MAX as f64) as i32;
        self.v_ref = (vc.zero as f64).clamp(0.0, ADC_MAX as f64) as i32;
        self.phase = Phase::Running;
    }

    /// Feeds one sample after release (counts in the channel-set order) and returns the phase.
    /// A sample pushed while holding releases the pin first.
    pub fn push(&mut self, counts: &[u16]) -> Phase {
        if self.phase == Phase::Holding {
            self.release();
        }
        if self.phase != Phase::Running {
            return self.phase;
        }
        let (Some(&cx), Some(&cv)) = (counts.get(self.slot_x), counts.get(self.slot_v)) else {
            self.rejected = self.rejected.saturating_add(1);
            return self.phase;
        };
        if counts.len() < self.width {
            self.rejected = self.rejected.saturating_add(1);
            return self.phase;
        }
        if cx == 0 || cx == ADC_MAX || cv == 0 || cv == ADC_MAX {
            self.saturated = self.saturated.saturating_add(1);
        }
        let idx = self.n;
        self.n = self.n.saturating_add(1);
        if idx == 0 {
            self.x_release = calib::to_si(self.cal[Channel::Displacement as usize], cx);
        }
        self.fitter.push(cx);
        let v = calib::to_si(self.cal[Channel::Velocity as usize], cv);
        if let Some(rev) = self.detector.update(v) {
            self.on_reversal(idx, rev.frac as f64, rev.before);
        }
        self.moments.add(cx as i32 - self.x_ref, cv as i32 - self.v_ref);
        if let Some(p) = self.pending {
            if idx >= p.due {
                self.complete_pending(p);
            }
        }
        self.check_stop(idx);
        self.phase
    }

    fn on_reversal(&mut self, idx: u32, frac: f64, before: i8) {
        let pos = (idx as f64 - 1.0 + frac).max(0.0);
        let xc = self.cal[Channel::Displacement as usize];
        let vc = self.cal[Channel::Velocity as usize];
        let hm = self.moments.summarise(xc, self.x_ref, vc, self.v_ref).unwrap_or_default();
        self.moments = Moments::default();
        if let Some(p) = self.pending.take() {
            // Two reversals within one window: only garbage does that; keep the raw peak.
            self.complete_pending(p);
        }
        let first = self.records.is_empty() && self.pending.is_none();
        let hp = pos - self.last_rev;
        if first {
            self.first_sign = before;
        }
        if hp > 4.0 {
            self.half_period = hp;
            self.fitter.set_step(PI / hp);
        }
        self.last_rev = pos;
        let centre = (pos + 0.5) as u32;
        let due = centre.saturating_add(self.fitter.half_window() as u32);
        self.pending = Some(Pending { due, t: pos / self.rate, moments: hm });
    }

    fn complete_pending(&mut self, p: Pending) {
        self.pending = None;
        let xc = self.cal[Channel::Displacement as usize];
        let peak_count = self.fitter.fit_centre().unwrap_or(xc.zero as f64);
        let peak = (xc.gain as f64 * (peak_count - xc.zero as f64)) as f32;
        let rec = HalfCycle { t: p.t as f32, peak, moments: p.moments };
        let prev = self.records.last().map(|r| r.peak);
        if self.records.push(rec).is_err() || self.records.is_full() {
            self.phase = Phase::Finished(StopReason::BufferFull);
            return;
        }
        if let Some(prev) = prev {
            let half_amplitude = (peak as f64 - prev as f64).abs() * 0.5;
            if half_amplitude < 4.0 * self.noise_x {
                self.phase = Phase::Finished(StopReason::InNoise);
            }
        }
    }

    fn check_stop(&mut self, idx: u32) {
        if self.phase != Phase::Running {
            return;
        }
        if self.n >= self.max_samples {
            self.phase = Phase::Finished(StopReason::MaxDuration);
            return;
        }
        let since = idx as f64 - self.last_rev;
        let reversed = !self.records.is_empty() || self.pending.is_some();
        if reversed {
            if since > 1.5 * self.half_period + self.fitter.half_window() as f64 + 2.0 && self.pending.is_none() {
                self.phase = Phase::Finished(StopReason::AtRest);
            }
        } else if since > 3.0 * self.half_period {
            self.phase = Phase::Finished(StopReason::NoMotion);
        }
    }

    /// Analyses what was recorded and returns the result (can be called at any time; normally once
    /// [`Pipeline::is_finished`]).
    pub fn finish(&self, run_id: u32) -> OnboardResult {
        let recs: &[HalfCycle] = &self.records;
        let nan = Estimate { mu0: f32::NAN, mu1: f32::NAN, mu0_se: f32::NAN, mu1_se: f32::NAN };
        let n_rev = recs.len();
        let cycles = (n_rev / 2).min(u16::MAX as usize) as u16;
        let mut out = OnboardResult {
            run_id,
            verdict: Verdict::NoOscillation,
            cycles,
            frequency_hz: f32::NAN,
            initial_amplitude_m: f32::NAN,
            duration_s: recs.last().map_or(self.n as f64 / self.rate, |r| r.t as f64) as f32,
            best: nan,
            averaging: nan,
            decrement: nan,
            shape: EnvelopeShape::Straight,
            curvature: f32::NAN,
        };
        // Frequency: reversals are half a damped period apart, Coulomb or not.
        let Some(freq) = Ols::<1>::fit(recs.iter().enumerate().map(|(i, r)| ([i as f64], r.t as f64))) else {
            return out;
        };
        let half_period_s = freq.coef[0];
        let omega_cfg = fit::sqrt(self.stiffness / self.mass);
        let omega_d = PI / half_period_s;
        let plausible = omega_d > 0.5 * omega_cfg && omega_d < 2.0 * omega_cfg && fit::sqrt(freq.sigma2) < 0.05 * half_period_s;
        if !plausible {
            return out;
        }
        out.frequency_hz = (omega_d / (2.0 * PI)) as f32;
        if cycles < MIN_CYCLES {
            out.verdict = Verdict::TooFewCycles;
            return out;
        }
        let scale = self.stiffness / self.load; // metres → y
        let dec = self.decrement(scale);
        let avg = self.averaging(scale, omega_d);
        if let Some(d) = &dec {
            out.decrement = d.estimate;
        }
        if let Some(a) = &avg {
            out.averaging = a.estimate;
            out.shape = a.shape;
            out.curvature = a.curvature as f32;
            let mu1 = a.estimate.mu1 as f64;
            let omega = omega_d / fit::sqrt((1.0 - 0.25 * mu1 * mu1).max(0.25));
            out.frequency_hz = (omega / (2.0 * PI)) as f32;
        }
        let centre = dec.as_ref().map(|d| d.offset).or(avg.as_ref().map(|a| a.offset));
        if let Some(c) = centre {
            out.initial_amplitude_m = (self.x_release as f64 - c).abs() as f32;
        }
        let (verdict, best) = match (&dec, &avg) {
            (None, None) => (Verdict::NoOscillation, nan),
            (Some(d), None) => (Verdict::EstimatorsDisagree, d.estimate),
            (None, Some(a)) => (Verdict::EstimatorsDisagree, a.estimate),
            (Some(d), Some(a)) => combine(&d.estimate, &a.estimate),
        };
        out.best = best;
        out.verdict = if verdict == Verdict::NoOscillation {
            verdict
        } else if self.saturated > 0 {
            Verdict::Saturated
        } else {
            verdict
        };
        let all_finite = [out.best.mu0, out.best.mu1, out.best.mu0_se, out.best.mu1_se].iter().all(|v| v.is_finite());
        if !all_finite && out.verdict == Verdict::Ok {
            out.verdict = Verdict::NoOscillation;
        }
        out
    }

    /// Peak sign (+1 maximum) of reversal `i`.
    fn sign(&self, i: usize) -> f64 {
        let s = self.first_sign as f64;
        if i % 2 == 0 {
            s
        } else {
            -s
        }
    }

    fn decrement(&self, scale: f64) -> Option<Fitted> {
        let recs: &[HalfCycle] = &self.records;
        let rows = recs.windows(2).enumerate().filter_map(|(i, w)| {
            let (a, b) = (w.first()?, w.get(1)?);
            let (sa, sb) = (self.sign(i), self.sign(i + 1));
            Some(([sa * a.peak as f64, sb], sb * b.peak as f64))
        });
        let f = Ols::<2>::fit(rows)?;
        let (beta, d, gamma) = (f.intercept, f.coef[0], f.coef[1]);
        if !(d > 0.0 && d < 2.0) {
            return None;
        }
        let r = -beta / (1.0 + d);
        let offset = gamma / (1.0 + d);
        let l = -fit::ln(d) / PI;
        let q = 1.0 + l * l;
        let zeta = l / fit::sqrt(q);
        let mu1 = 2.0 * zeta;
        let mu0 = r * scale;
        let dmu1_dd = 2.0 / (q * fit::sqrt(q)) * (-1.0 / (PI * d));
        let g0 = [-scale / (1.0 + d), scale * beta / ((1.0 + d) * (1.0 + d)), 0.0];
        let g1 = [0.0, dmu1_dd, 0.0];
        let estimate = estimate(mu0, mu1, f.var_of(&g0), f.var_of(&g1))?;
        Some(Fitted { estimate, offset, shape: EnvelopeShape::Straight, curvature: 0.0 })
    }

    fn averaging(&self, scale: f64, omega_d: f64) -> Option<Fitted> {
        let recs: &[HalfCycle] = &self.records;
        let n = recs.len();
        // Half-cycle j (1 ≤ j < n) runs from reversal j−1 to reversal j; 0 starts at release: skipped.
        let even = if (n - 1) % 2 == 0 { n - 1 } else { n - 2 };
        if even < 2 {
            return None;
        }
        let offset = recs.iter().skip(1).take(even).map(|r| r.moments.mean_x as f64).sum::<f64>() / even as f64;
        let t_mid = |j: usize| -> Option<f64> { Some(0.5 * (recs.get(j - 1)?.t as f64 + recs.get(j)?.t as f64)) };
        let (mut r, mut mu1) = (0.0f64, 0.0f64);
        let mut result = None;
        for _ in 0..4 {
            let omega = omega_d / fit::sqrt((1.0 - 0.25 * mu1 * mu1).max(0.25));
            // envelope of half-cycle j, in y units, about its centre offset − s_j r
            let amp = |j: usize| -> Option<f64> {
                let centre = offset - self.sign(j) * r;
                Some(recs.get(j)?.moments.envelope(centre, omega) * scale)
            };
            let row = |j: usize| -> Option<(f64, f64)> {
                let dt = (t_mid(j + 1)? - t_mid(j - 1)?) * omega;
                if !(dt > 0.0) {
                    return None;
                }
                Some((amp(j)?, (amp(j + 1)? - amp(j - 1)?) / dt))
            };
            let lin = Ols::<1>::fit((2..n.saturating_sub(1)).filter_map(row).map(|(a, d)| ([a], d)))?;
            let (a0, a1) = (lin.intercept, lin.coef[0]);
            let mu0 = -PI * a0 / 2.0;
            mu1 = -2.0 * a1;
            r = mu0 / scale;
            if !(r.is_finite() && mu1.is_finite()) {
                return None;
            }
            let quad = Ols::<2>::fit((2..n.saturating_sub(1)).filter_map(row).map(|(a, d)| ([a, a * a], d)));
            let (lo, hi) = (2..n.saturating_sub(1))
                .filter_map(amp)
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), a| (lo.min(a), hi.max(a)));
            let (shape, curvature) = match quad {
                Some(q) => (shape_of(&q, lo, hi), q.coef[1]),
                None => (EnvelopeShape::Straight, f64::NAN),
            };
            let est = estimate(mu0, mu1, lin.cov(0, 0) * PI * PI / 4.0, lin.cov(1, 1) * 4.0)?;
            result = Some(Fitted { estimate: est, offset, shape, curvature });
        }
        result
    }
}

struct Fitted {
    estimate: Estimate,
    /// Displacement of the centre of oscillation in the calibrated frame (m).
    offset: f64,
    shape: EnvelopeShape,
    curvature: f64,
}

fn estimate(mu0: f64, mu1: f64, var0: f64, var1: f64) -> Option<Estimate> {
    let e = Estimate { mu0: mu0 as f32, mu1: mu1 as f32, mu0_se: fit::sqrt(var0.max(0.0)) as f32, mu1_se: fit::sqrt(var1.max(0.0)) as f32 };
    [e.mu0, e.mu1, e.mu0_se, e.mu1_se].iter().all(|v| v.is_finite()).then_some(e)
}

/// Shape of `F(A) = a0 + a1 A + a2 A²` over `[lo, hi]` from the sign of `F'` at both ends (3σ).
fn shape_of(q: &Ols<2>, lo: f64, hi: f64) -> EnvelopeShape {
    let class = |a: f64| -> i8 {
        let d = q.coef[0] + 2.0 * q.coef[1] * a;
        let sd = fit::sqrt(q.var_of(&[0.0, 1.0, 2.0 * a]).max(0.0));
        if d < -3.0 * sd {
            -1
        } else if d > 3.0 * sd {
            1
        } else {
            0
        }
    };
    let (cl, ch) = (class(lo), class(hi));
    match (cl, ch) {
        (-1, 1) | (1, -1) => EnvelopeShape::Mixed,
        (-1, _) | (_, -1) => EnvelopeShape::Convex,
        (1, _) | (_, 1) => EnvelopeShape::Concave,
        _ => EnvelopeShape::Straight,
    }
}

/// Inverse-variance mean of the two estimators and the cross-check verdict.
fn combine(d: &Estimate, a: &Estimate) -> (Verdict, Estimate) {
    let one = |x: f32, sx: f32, y: f32, sy: f32, tol: f64| -> (f64, f64, bool) {
        let (x, sx, y, sy) = (x as f64, sx as f64, y as f64, sy as f64);
        let diff = x - y;
        let agree = diff.abs() <= tol + 3.0 * fit::sqrt(sx * sx + sy * sy);
        let (wx, wy) = (1.0 / (sx * sx).max(1e-30), 1.0 / (sy * sy).max(1e-30));
        let mean = (wx * x + wy * y) / (wx + wy);
        let se = fit::sqrt(1.0 / (wx + wy) + 0.25 * diff * diff);
        (mean, se, agree)
    };
    let (m0, s0, ok0) = one(d.mu0, d.mu0_se, a.mu0, a.mu0_se, MU0_PRECISION);
    let (m1, s1, ok1) = one(d.mu1, d.mu1_se, a.mu1, a.mu1_se, MU1_PRECISION);
    let best = Estimate { mu0: m0 as f32, mu1: m1 as f32, mu0_se: s0 as f32, mu1_se: s1 as f32 };
    (if ok0 && ok1 { Verdict::Ok } else { Verdict::EstimatorsDisagree }, best)
}

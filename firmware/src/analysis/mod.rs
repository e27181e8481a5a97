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
//! The natural frequency comes from the reversal times (half a damped period apart, Coulomb or not),
//! regressed on their index with weights ∝ amplitude² (a crossing's timing error goes as
//! 1/amplitude), then Ω = ω_d / sqrt(1 − ζ²). The noise variances measured during the hold are taken
//! out of the envelope's mean square, and the central differences use the nominal half-cycle spacing.
//!
//! The velocity noise is also measured from the motion (the second difference of the velocity
//! counts, its `(ωΔt)⁴ v²` signal part taken out), updated at every reversal: the reversal detector
//! arms at 8 × the larger of the hold's and the motion's noise, and the envelope's
//! noise correction uses the larger too. Without it a run released with no (or a quiet) hold armed
//! within ~1.5 σ of a 16-bit vibrometer's noise, counted the noise around zero after the pin stuck as
//! reversals, never stopped `AtRest`, and both estimators were biased (μ0 low, μ1 high).
//!
//! `cycles` is half the number of velocity reversals seen. Below [`MIN_CYCLES`] the averaging fit
//! has too few central differences: a run of [`MIN_HALF_CYCLES`] or more half-cycles is then
//! analysed from its peaks alone (the decrement fit, `best` = `decrement`, `averaging` NaN, verdict
//! `Ok`: nothing to disagree with), its ± propagated from each peak's variance through the fit.
//! Those peaks are fitted again at the end of the run, from the windows the pipeline keeps for the
//! first [`SHORT_PEAKS`] of them, with the motion's own model ([`crate::peaks::arc`]: the vertex
//! and the decay fitted, each peak's variance from its window's residuals); under
//! [`MIN_HALF_CYCLES`] the verdict is `TooFewCycles` and every
//! estimate is `NaN`. Saturated displacement or velocity samples after release
//! give the verdict `Saturated` (the numbers are still filled in, to be read with care).
//!
//! Cost: per sample, integer sums and one `f32` calibration (175 host instructions, 158 before the
//! dropout stand-ins: callgrind over `examples/pipeline_bench.rs`); per half-cycle, one peak fit
//! over ±1 rad; the regressions run once, in `f64`, in [`Pipeline::finish`].
//!
//! The technician is shown the averaging estimator's result ([`OnboardResult::best`]: one
//! estimator per quantity). Its ± accounts for the correlation of its regression's residuals (each
//! amplitude is in two central differences: ρ = −½ two rows apart, or what the residuals show when
//! that differs beyond its scatter), and its central differences are inverted exactly (`sinh`):
//! over the bench grid (`host/examples/onboard_grid.rs`) z = (estimate − truth)/σ has an sd of
//! 0.97–1.18 at every noise level. The decrement estimator's ± is its textbook one, wide; it
//! serves the check between the two: when they differ by more than the method's stated precision
//! (μ0 ± 0.001, μ1 ± 0.0002) plus three combined standard errors, the verdict is
//! `EstimatorsDisagree` (typically: the friction law is not Coulomb–viscous), and the host's
//! cross-check calls the on-board result not usable.
//!
//! # The release and the first reversal
//! The first sample pushed is the release (the rig's magnet lets go at a known sample; a record's
//! release is read from its data by the host, as `tribo fit` reads it, and the samples before it
//! captured as the hold). Until the first reversal the reversal detector arms at 8 × the hold's
//! noise or a quarter of the release speed ω·x0, whichever is larger: the pin leaves at rest, and
//! with no (or a short) hold the noise is not known yet.
use crate::calib::{OffsetCapture, ADC_MAX, CHANNELS};
use crate::envelope::{HalfCycleMoments, Moments};
use crate::fit::{self, Ols, OlsPasses, Pass};
use crate::peaks::arc::ArcFitter;
use crate::peaks::{PeakFitter, ReversalDetector};
use crate::wire::{
    Channel, ChannelCal, Configure, EnvelopeShape, Estimate, OnboardResult, Verdict,
};
use core::f64::consts::PI;

/// Capacity of the half-cycle store: 1024 cycles, 39 s at 26 Hz. A run that fills it stops there.
pub const MAX_HALF_CYCLES: usize = 2048;
/// Fewer complete cycles than this and the result is the peaks' decrement fit alone, its ±
/// propagated from the peaks' (the thesis's minimum for its two estimators).
pub const MIN_CYCLES: u16 = 5;
/// Fewer half-cycles than this and no estimate is reported: the decrement fit has three
/// constants (D, the Coulomb shift, the centre) and needs three pairs of peaks after the release
/// (whose first milliseconds are not free motion on a real bench).
pub const MIN_HALF_CYCLES: usize = 4;
/// Peaks whose windows the pipeline keeps for the end of the run: a short run has fewer than
/// `2·MIN_CYCLES`.
pub const SHORT_PEAKS: usize = 2 * MIN_CYCLES as usize;
/// Counts of a kept window, at most.
const WINDOW_LEN: usize = 2 * crate::peaks::MAX_HALF_WINDOW + 1;
/// Stated precision of the method on μ0 (used by the cross-check).
pub const MU0_PRECISION: f64 = 0.001;
/// Stated precision of the method on μ1 (used by the cross-check).
pub const MU1_PRECISION: f64 = 0.0002;
/// Number of noise standard deviations the velocity must exceed to arm the reversal detector.
const ARM_SIGMAS: f64 = 8.0;
/// Velocity noise σ a sample may leave the line through the two before it by, before it is taken
/// for a speckle dropout.
const SPIKE_SIGMAS: f64 = 20.0;
/// Fraction of the release speed ω·x0 the velocity must reach before the first reversal is armed.
const START_FRACTION: f64 = 0.25;
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
            Self::MaxDuration => {
                f.write_str("maximum duration must be a positive number of seconds")
            }
            Self::InitialAmplitude => {
                f.write_str("initial amplitude must be a positive number of metres")
            }
            Self::MissingChannel(c) => write!(f, "the on-board analysis needs the {c:?} channel"),
            Self::Calibration(c) => write!(
                f,
                "the {c:?} calibration needs a finite non-zero gain and a finite zero"
            ),
            Self::Undersampled => {
                f.write_str("sample rate must exceed 8 times the natural frequency sqrt(k/m)/2π")
            }
        }
    }
}

impl core::error::Error for ConfigError {}

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
    /// Where the reversal lies after the window's centre sample (samples, |delta| ≤ ½).
    delta: f64,
    moments: HalfCycleMoments,
}

/// The on-board analysis of one run (≈ 43 KiB; keep it in a `static`, or reuse it with
/// [`Pipeline::reset`]).
#[derive(Clone, Debug)]
pub struct Pipeline {
    st: State,
    /// The peak fitter (1.5 KiB of ring and table: reset in place, never rebuilt by value).
    fitter: PeakFitter,
    records: heapless::Vec<HalfCycle, MAX_HALF_CYCLES>,
    /// The first peaks' windows, for the end of a short run (5 KiB).
    windows: Windows,
    /// The fitter of a short run's peaks at its end (see `finish::Refit`).
    arc: core::cell::RefCell<ArcFitter>,
}

/// The windows of the first [`SHORT_PEAKS`] peaks, in order (uninitialised storage until a
/// window is kept: built in place, never on a stack).
pub(crate) type Windows = heapless::Vec<Window, SHORT_PEAKS>;

/// A kept window: its counts (oldest first; `len` of them) and where the reversal lies after the
/// centre sample (it is fitted with the run's phase step, known at the run's end).
#[derive(Clone, Debug)]
pub(crate) struct Window {
    pub(crate) counts: [u16; WINDOW_LEN],
    pub(crate) len: u16,
    pub(crate) delta: f32,
}

/// Everything but the half-cycle store (small: rebuilt in place by [`Pipeline::reset`]).
#[derive(Clone, Debug)]
struct State {
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
    /// Variances of the displacement (m²) and velocity (m²/s²) noise measured during the hold.
    noise_var: (f64, f64),
    detector: ReversalDetector,
    /// Velocity noise measured during the hold (counts, at least [`MIN_NOISE_COUNTS`]).
    sv_hold: f64,
    /// The two previous velocity counts (for the second difference).
    v_prev: (i32, i32),
    /// A velocity sample that jumps from the previous one by more than this many counts is a
    /// speckle dropout of the vibrometer (the motion changes by at most ω·Δt·ω·x0 a sample, under
    /// 9 % of the release speed at 2 kS/s): the previous count stands in for it.
    spike_counts: i32,
    /// The last velocity count captured while held, and how many spikes in a row stood in for.
    hold_v: Option<u16>,
    hold_spikes: u8,
    /// Velocity samples in a row the line through the previous two stood in for, and how far
    /// (counts) a sample may leave that line (set at the release and at every reversal).
    stand_ins: u8,
    line_limit: i32,
    /// Σ (second difference of the velocity counts)² and its number of terms.
    d2_sum: i64,
    d2_n: u32,
    /// Σ (velocity counts − reference)² over the completed half-cycles and its number of terms.
    vsq_sum: i64,
    vsq_n: u32,
    /// Velocity noise measured from the motion (counts), updated at each reversal.
    sv_motion: f64,
    moments: Moments,
    pending: Option<Pending>,
    first_sign: i8,
    last_rev: f64,
    half_period: f64,
    /// Sample index after which, with no new reversal, the run is over (integer compare per sample).
    deadline: u32,
    saturated: u32,
    rejected: u32,
    /// Acquisition gaps (see [`Pipeline::gap`]): the half-cycles recorded before the first one are
    /// what the result uses; the second difference of the velocity restarts at `d2_from`, and a
    /// peak is compared with the previous one only if both come after `pair_from` records.
    kept: Option<usize>,
    d2_from: u32,
    pair_from: usize,
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
        let st = Self::state(cfg)?;
        let mut fitter = PeakFitter::new();
        fitter.set_step(PI / st.half_period);
        Ok(Self {
            st,
            fitter,
            records: heapless::Vec::new(),
            windows: heapless::Vec::new(),
            arc: core::cell::RefCell::new(ArcFitter::new()),
        })
    }

    fn state(cfg: &Configure) -> Result<State, ConfigError> {
        let mass = positive(cfg.rig.mass_kg).ok_or(ConfigError::Mass)?;
        let stiffness = positive(cfg.rig.stiffness_n_per_m).ok_or(ConfigError::Stiffness)?;
        let load = positive(cfg.rig.load_n).ok_or(ConfigError::Load)?;
        if cfg.sample_rate_hz == 0 {
            return Err(ConfigError::SampleRate);
        }
        let rate = cfg.sample_rate_hz as f64;
        let max_duration = positive(cfg.max_duration_s).ok_or(ConfigError::MaxDuration)?;
        let x0 = positive(cfg.initial_amplitude_m).ok_or(ConfigError::InitialAmplitude)?;
        let slot_x = cfg
            .channels
            .position(Channel::Displacement)
            .ok_or(ConfigError::MissingChannel(Channel::Displacement))?;
        let slot_v = cfg
            .channels
            .position(Channel::Velocity)
            .ok_or(ConfigError::MissingChannel(Channel::Velocity))?;
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
        if half_period.is_nan() || half_period <= 4.0 {
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
        Ok(State {
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
            noise_var: (0.0, 0.0),
            detector: ReversalDetector::new(f32::MAX),
            sv_hold: MIN_NOISE_COUNTS,
            v_prev: (0, 0),
            spike_counts: {
                // A quarter of the release speed ω·x0, in counts (at least one count).
                let g = cal[Channel::Velocity as usize].gain.abs() as f64;
                let c = if g > 0.0 {
                    0.25 * omega * x0 / g
                } else {
                    f64::MAX
                };
                c.clamp(1.0, i32::MAX as f64) as i32
            },
            hold_v: None,
            hold_spikes: 0,
            stand_ins: 0,
            line_limit: i32::MAX,
            d2_sum: 0,
            d2_n: 0,
            vsq_sum: 0,
            vsq_n: 0,
            sv_motion: 0.0,
            moments: Moments::default(),
            pending: None,
            first_sign: 1,
            last_rev: 0.0,
            half_period,
            deadline: (3.0 * half_period) as u32,
            saturated: 0,
            rejected: 0,
            kept: None,
            d2_from: 2,
            pair_from: 0,
        })
    }

    /// Re-initialises in place for a new run: only the small state (≈ 0.4 KiB) is rebuilt, the
    /// peak fitter and the half-cycle store are cleared, never copied. On error the pipeline is left unchanged.
    pub fn reset(&mut self, cfg: &Configure) -> Result<(), ConfigError> {
        self.st = Self::state(cfg)?;
        self.fitter.reset();
        self.fitter.set_step(PI / self.st.half_period);
        self.records.clear();
        self.windows.clear();
        Ok(())
    }

    /// Current phase.
    pub fn phase(&self) -> Phase {
        self.st.phase
    }

    /// True once the run has stopped (pin at rest, amplitude in the noise, maximum duration, store
    /// full, or no motion).
    pub fn is_finished(&self) -> bool {
        matches!(self.st.phase, Phase::Finished(_))
    }

    /// Samples analysed since release.
    pub fn samples(&self) -> u32 {
        self.st.n
    }

    /// Sample vectors refused because they were shorter than the channel set.
    pub fn rejected(&self) -> u32 {
        self.st.rejected
    }

    /// Calibration in use (zeros updated by the capture at release).
    pub fn calibration(&self) -> &[ChannelCal; CHANNELS] {
        &self.st.cal
    }

    /// Half-cycles recorded so far.
    pub fn half_cycles(&self) -> &[HalfCycle] {
        &self.records
    }

    /// SI value of one channel's count with the current calibration.
    pub fn to_si(&self, channel: Channel, count: u16) -> f32 {
        self.st
            .cal
            .get(channel as usize)
            .map_or(f32::NAN, |c| c.to_si(count))
    }

    /// Feeds one sample taken while the magnet holds the pin (counts in the channel-set order).
    /// Ignored once released.
    pub fn capture(&mut self, counts: &[u16]) {
        if self.st.phase != Phase::Holding {
            return;
        }
        if counts.len() < self.st.width {
            self.st.rejected = self.st.rejected.saturating_add(1);
            return;
        }
        // A speckle dropout while held (a spike of up to the velocity's full scale) would make
        // the hold's velocity zero and noise: 10 a second over a 5 s hold raised the arming level
        // and the envelope's noise correction enough to end the run 7 cycles early and bias μ0 by
        // 5 σ. The previous count stands in for it; three in a row are a level, not a spike, and
        // are kept.
        let slot_v = self.st.slot_v;
        let mut cv = counts.get(slot_v).copied().unwrap_or(0);
        if let Some(prev) = self.st.hold_v {
            // The pin is at rest: a sixth of the stand-in threshold of the motion (4 % of ω·x0,
            // above 6 σ of a sample-to-sample difference at the noisiest bench's noise).
            let limit = self.st.spike_counts / 6;
            if (cv as i32 - prev as i32).abs() > limit && self.st.hold_spikes < 3 {
                self.st.hold_spikes += 1;
                cv = prev;
            } else {
                self.st.hold_spikes = 0;
            }
        }
        self.st.hold_v = Some(cv);
        let slots = self.st.slots;
        self.st.capture.add(
            counts
                .iter()
                .zip(slots.iter())
                .enumerate()
                .map(|(k, (&c, &ch))| (ch as usize, if k == slot_v { cv } else { c })),
        );
    }

    /// The magnet has let go: fixes the zeros and the noise thresholds and starts the analysis.
    pub fn release(&mut self) {
        if self.st.phase != Phase::Holding {
            return;
        }
        let xi = Channel::Displacement as usize;
        let vi = Channel::Velocity as usize;
        let fi = Channel::Force as usize;
        if let Some(m) = self.st.capture.mean(vi) {
            if let Some(c) = self.st.cal.get_mut(vi) {
                c.zero = m as f32;
            }
        }
        if let Some(m) = self.st.capture.mean(fi) {
            if let Some(c) = self.st.cal.get_mut(fi) {
                c.zero = m as f32;
            }
        }
        if let Some(m) = self.st.capture.mean(xi) {
            if let Some(c) = self.st.cal.get_mut(xi) {
                let z = m - self.st.x0 / c.gain as f64;
                if z.is_finite() {
                    c.zero = z as f32;
                }
            }
        }
        let xc = self.st.cal[xi];
        let vc = self.st.cal[vi];
        let sx = self
            .st
            .capture
            .std(xi)
            .unwrap_or(MIN_NOISE_COUNTS)
            .max(MIN_NOISE_COUNTS);
        let sv = self
            .st
            .capture
            .std(vi)
            .unwrap_or(MIN_NOISE_COUNTS)
            .max(MIN_NOISE_COUNTS);
        self.st.noise_x = sx * (xc.gain as f64).abs();
        let var = |ch: usize, gain: f32| {
            let s = self.st.capture.std(ch).unwrap_or(0.0) * gain as f64;
            s * s
        };
        self.st.noise_var = (var(xi, xc.gain), var(vi, vc.gain));
        self.st.sv_hold = sv;
        // Until the first reversal the noise of the motion is not known, and the hold may be short,
        // quiet or missing (a record fed from its release): the pin leaves at rest, so the first
        // arming waits for a quarter of the release speed ω·x0 as well. Armed within a few noise
        // σ, the detector took the noise around the release for a reversal, of either sign: one
        // of the wrong sign hid the real first reversal and the run ended `AtRest` before the
        // second ("no oscillation").
        let omega = fit::sqrt(self.st.stiffness / self.st.mass);
        let start = START_FRACTION * omega * self.st.x0;
        self.st.detector =
            ReversalDetector::new((ARM_SIGMAS * sv * (vc.gain as f64).abs()).max(start) as f32);
        self.st.x_ref = (xc.zero as f64).clamp(0.0, ADC_MAX as f64) as i32;
        self.st.v_ref = (vc.zero as f64).clamp(0.0, ADC_MAX as f64) as i32;
        self.st.phase = Phase::Running;
    }

    /// Feeds one sample after release (counts in the channel-set order) and returns the phase.
    /// A sample pushed while holding releases the pin first.
    pub fn push(&mut self, counts: &[u16]) -> Phase {
        if self.st.phase == Phase::Holding {
            self.release();
        }
        if self.st.phase != Phase::Running {
            return self.st.phase;
        }
        let (Some(&cx), Some(&cv)) = (counts.get(self.st.slot_x), counts.get(self.st.slot_v))
        else {
            self.st.rejected = self.st.rejected.saturating_add(1);
            return self.st.phase;
        };
        if counts.len() < self.st.width {
            self.st.rejected = self.st.rejected.saturating_add(1);
            return self.st.phase;
        }
        if cx == 0 || cx == ADC_MAX || cv == 0 || cv == ADC_MAX {
            self.st.saturated = self.st.saturated.saturating_add(1);
        }
        // A speckle dropout. Once the motion is under way (from the first reversal: the release
        // is a kink of the velocity, ω²x0·Δt off any line, 14 % of ω·x0 at 2 kS/s), with two
        // samples before it, the line through them stands in for a sample that leaves it by more
        // than 20 noise σ (8 σ of a second difference) or a sixth of the stand-in threshold
        // below, whichever is larger (the motion's own departure is (ωΔt)² v, under 2 % of ω·x0
        // at 2 kS/s): a dropout of a few % of the speed, let through by the threshold below, put
        // its square in a half cycle's mean square velocity and biased μ0 by 10 σ at 10 dropouts
        // a second. A third such sample in a row is kept (the line is then restarted). Before,
        // the previous count stands in for a jump of a quarter of ω·x0; the first sample has none.
        let (v1, v2) = self.st.v_prev;
        let moving = !self.records.is_empty() || self.st.pending.is_some();
        let cv = if moving && self.st.n >= self.st.d2_from {
            let pred = 2 * v1 - v2;
            if (cv as i32 - pred).abs() <= self.st.line_limit {
                self.st.stand_ins = 0;
                cv
            } else if self.st.stand_ins < 2 {
                self.st.stand_ins += 1;
                pred.clamp(0, u16::MAX as i32) as u16
            } else {
                self.st.stand_ins = 0;
                self.st.d2_from = self.st.n.saturating_add(2);
                cv
            }
        } else if self.st.n > 0 && (cv as i32 - v1).abs() > self.st.spike_counts {
            v1.clamp(0, u16::MAX as i32) as u16
        } else {
            cv
        };
        let idx = self.st.n;
        self.st.n = self.st.n.saturating_add(1);
        if idx == 0 {
            self.st.x_release = self.st.cal[Channel::Displacement as usize].to_si(cx);
        }
        self.fitter.push(cx);
        // Second difference of the velocity: white noise of variance σ² gives 6σ², the motion only
        // (ωΔt)⁴ v², taken out at the reversals (see `update_noise`).
        let cvi = cv as i32;
        let d2 = (cvi - 2 * self.st.v_prev.0 + self.st.v_prev.1) as i64;
        self.st.v_prev = (cvi, self.st.v_prev.0);
        // A dropout smaller than the stand-in's threshold still passes: its second differences
        // (±s, ∓2s) are left out of the noise, which they would raise tenfold (a run cut short by
        // an arming level at 80 σ). The motion's own is (ωΔt)² v, under 2 % of ω·x0 at 2 kS/s.
        if idx >= self.st.d2_from && d2.abs() <= (self.st.spike_counts / 2) as i64 {
            self.st.d2_sum = self.st.d2_sum.wrapping_add(d2 * d2);
            self.st.d2_n = self.st.d2_n.wrapping_add(1);
        }
        let v = self.st.cal[Channel::Velocity as usize].to_si(cv);
        if let Some(rev) = self.st.detector.update(v) {
            self.on_reversal(idx, rev.frac as f64, rev.before);
        }
        self.st
            .moments
            .add(cx as i32 - self.st.x_ref, cv as i32 - self.st.v_ref);
        if let Some(p) = self.st.pending {
            if idx >= p.due {
                self.complete_pending(p);
            }
        }
        self.check_stop(idx);
        self.st.phase
    }

    fn on_reversal(&mut self, idx: u32, frac: f64, before: i8) {
        let pos = (idx as f64 - 1.0 + frac).max(0.0);
        let xc = self.st.cal[Channel::Displacement as usize];
        let vc = self.st.cal[Channel::Velocity as usize];
        let hm = self
            .st
            .moments
            .summarise(xc, self.st.x_ref, vc, self.st.v_ref)
            .unwrap_or_default();
        self.update_noise();
        self.st.moments = Moments::default();
        if let Some(p) = self.st.pending.take() {
            // Two reversals within one window: only garbage does that; keep the raw peak.
            self.complete_pending(p);
        }
        let first = self.records.is_empty() && self.st.pending.is_none();
        let hp = pos - self.st.last_rev;
        if first {
            self.st.first_sign = before;
        }
        if hp > 4.0 {
            self.st.half_period = hp;
            self.fitter.set_step(PI / hp);
        }
        self.st.last_rev = pos;
        let wait = 1.5 * self.st.half_period + self.fitter.half_window() as f64 + 2.0;
        self.st.deadline = (pos + wait) as u32;
        let centre = (pos + 0.5) as u32;
        let due = centre.saturating_add(self.fitter.half_window() as u32);
        self.st.pending = Some(Pending {
            due,
            t: pos / self.st.rate,
            delta: pos - centre as f64,
            moments: hm,
        });
    }

    /// Velocity noise from the motion itself (once per half-cycle): a run analysed without a hold
    /// (or with a hold quieter than the motion, e.g. a vibrometer whose noise grows with speed) would
    /// otherwise arm the reversal detector within a couple of noise σ, and once the pin stops the
    /// noise around zero would be counted as reversals: spurious half-cycles that bias both
    /// estimators and keep the run from ever ending `AtRest`. The arming threshold follows
    /// `ARM_SIGMAS` × the larger of the hold's and the motion's noise.
    fn update_noise(&mut self) {
        self.st.vsq_sum = self.st.vsq_sum.wrapping_add(self.st.moments.sum_sq_v());
        self.st.vsq_n = self.st.vsq_n.wrapping_add(self.st.moments.len());
        if self.st.d2_n > 0 && self.st.vsq_n > 0 {
            let step = PI / self.st.half_period;
            let s2 = step * step;
            let d2 = self.st.d2_sum as f64 / self.st.d2_n as f64;
            let vsq = self.st.vsq_sum as f64 / self.st.vsq_n as f64;
            let var = (d2 - s2 * s2 * vsq) / 6.0;
            if var.is_finite() && var > 0.0 {
                self.st.sv_motion = fit::sqrt(var);
            }
        }
        // From the first reversal on, the noise alone sets the arming level (the release's is
        // dropped even when the motion's noise cannot be read, as on a noiseless record).
        let sv = self.st.sv_hold.max(self.st.sv_motion);
        self.st.line_limit = (SPIKE_SIGMAS * sv)
            .max((self.st.spike_counts / 6) as f64)
            .min(i32::MAX as f64) as i32;
        let gain = self.st.cal[Channel::Velocity as usize].gain as f64;
        self.st
            .detector
            .set_threshold((ARM_SIGMAS * sv * gain.abs()) as f32);
    }

    fn complete_pending(&mut self, p: Pending) {
        self.st.pending = None;
        let xc = self.st.cal[Channel::Displacement as usize];
        let peak_count = self.fitter.fit_centre().unwrap_or(xc.zero as f64);
        let peak = (xc.gain as f64 * (peak_count - xc.zero as f64)) as f32;
        if self.windows.len() == self.records.len() && !self.windows.is_full() {
            // kept for the end of a short run (len 0 when the window is not full)
            let mut w = Window {
                counts: [0; WINDOW_LEN],
                len: 0,
                delta: p.delta as f32,
            };
            w.len = self.fitter.window(&mut w.counts) as u16;
            let _ = self.windows.push(w);
        }
        let rec = HalfCycle {
            t: p.t as f32,
            peak,
            moments: p.moments,
        };
        let prev = self
            .records
            .last()
            .filter(|_| self.records.len() > self.st.pair_from)
            .map(|r| r.peak);
        if self.records.push(rec).is_err() || self.records.is_full() {
            self.st.phase = Phase::Finished(StopReason::BufferFull);
            return;
        }
        if let Some(prev) = prev {
            let half_amplitude = (peak as f64 - prev as f64).abs() * 0.5;
            if half_amplitude < 4.0 * self.st.noise_x {
                self.st.phase = Phase::Finished(StopReason::InNoise);
            }
        }
    }

    fn check_stop(&mut self, idx: u32) {
        if self.st.phase != Phase::Running {
            return;
        }
        if self.st.n >= self.st.max_samples {
            self.st.phase = Phase::Finished(StopReason::MaxDuration);
            return;
        }
        if idx > self.st.deadline && self.st.pending.is_none() {
            self.st.phase = Phase::Finished(if self.records.is_empty() {
                StopReason::NoMotion
            } else {
                StopReason::AtRest
            });
        }
    }

    /// `count` samples following the last one pushed were lost (an acquisition gap): the sample
    /// index, hence the time axis, steps over them. A half-cycle straddling a gap cannot be
    /// measured and records on either side cannot be paired, so the result keeps the half-cycles
    /// completed before the first gap ([`Pipeline::finish`]); after it, reversals are still followed
    /// so that the run ends when the pin stops, as it would have without the gap.
    pub fn gap(&mut self, count: u32) {
        if self.st.phase != Phase::Running || count == 0 {
            return;
        }
        self.st.n = self.st.n.saturating_add(count);
        self.st.deadline = self.st.deadline.saturating_add(count);
        // What straddles the gap: the half-cycle in progress, the peak window, the velocity history.
        self.st.pending = None;
        self.st.moments = Moments::default();
        self.st.detector = ReversalDetector::new(self.st.detector.threshold());
        self.fitter.reset();
        self.fitter.set_step(PI / self.st.half_period);
        self.st.d2_from = self.st.n.saturating_add(2);
        // No half-period measured across the gap.
        self.st.last_rev = f64::NAN;
        self.st.pair_from = self.records.len();
        if self.st.kept.is_none() {
            self.st.kept = Some(self.records.len());
        }
    }
}

mod finish;
pub use finish::*;

#[cfg(test)]
mod tests;

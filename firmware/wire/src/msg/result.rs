//! The end of a run: the on-board analysis's result (estimates with their ±, the envelope's shape,
//! a verdict) and the end frame.

use super::*;

wire_type! {
    /// Shape of the envelope's decay, from the sign of F'(A) over the amplitudes seen (thesis 3.3).
    #[derive(Copy, Eq)]
    pub enum EnvelopeShape {
        Straight,
        Convex,
        Concave,
        Mixed,
    }
}

impl EnvelopeShape {
    pub const fn name(self) -> &'static str {
        match self {
            EnvelopeShape::Straight => "straight",
            EnvelopeShape::Convex => "convex",
            EnvelopeShape::Concave => "concave",
            EnvelopeShape::Mixed => "mixed",
        }
    }
}

wire_type! {
    /// Whether the on-board numbers can be trusted, and if not why.
    #[derive(Copy, Eq)]
    pub enum Verdict {
        Ok,
        /// Fewer than 5 cycles: the thesis advises against any fit.
        TooFewCycles,
        NoOscillation,
        /// The displacement or velocity ADC saturated.
        Saturated,
        /// The two estimators disagree beyond their standard errors.
        EstimatorsDisagree,
        Aborted,
        /// The on-board analysis did not run: an unloaded run (load 0, the apparatus alone), whose
        /// dimensionless μ are undefined. Fit the stored record on the host instead.
        NotAnalysed,
    }
}

impl Verdict {
    pub const fn name(self) -> &'static str {
        match self {
            Verdict::Ok => "ok",
            Verdict::TooFewCycles => "too-few-cycles",
            Verdict::NoOscillation => "no-oscillation",
            Verdict::Saturated => "saturated",
            Verdict::EstimatorsDisagree => "estimators-disagree",
            Verdict::Aborted => "aborted",
            Verdict::NotAnalysed => "not-analysed",
        }
    }
}

wire_type! {
    /// Coulomb–viscous constants (dimensionless μ0, μ1 of the thesis, eq. 10–11) and standard errors.
    #[derive(Copy, Default)]
    pub struct Estimate {
        pub mu0: f32,
        pub mu1: f32,
        pub mu0_se: f32,
        pub mu1_se: f32,
    }
}

wire_type! {
    /// The on-board analysis of a run.
    #[derive(Copy)]
    pub struct OnboardResult {
        pub run_id: u32,
        pub verdict: Verdict,
        pub cycles: u16,
        pub frequency_hz: f32,
        pub initial_amplitude_m: f32,
        pub duration_s: f32,
        /// What the technician is shown.
        pub best: Estimate,
        /// Averaging-law regression dA/dτ = a0 + a1 A.
        pub averaging: Estimate,
        /// Half-cycle peak regression X_{n+1} = D X_n − r(1 + D).
        pub decrement: Estimate,
        pub shape: EnvelopeShape,
        /// a2 of dA/dτ = a0 + a1 A + a2 A² (dimensionless).
        pub curvature: f32,
    }
}

wire_type! {
    /// Why a run ended.
    #[derive(Copy, Eq)]
    pub enum EndReason {
        /// The pin came to rest (or its amplitude sank into the noise).
        Stopped,
        MaxDuration,
        Aborted,
        Fault(HeaterFault),
        /// The acquisition overran and the run cannot be trusted.
        Overrun,
    }
}

wire_type! {
    /// Closes a run.
    #[derive(Copy)]
    pub struct RunEnd {
        pub run_id: u32,
        pub blocks: u32,
        pub samples: u32,
        pub overruns: u32,
        pub reason: EndReason,
    }
}

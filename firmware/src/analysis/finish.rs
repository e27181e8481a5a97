//! The end-of-run fit, spread over polls ([`Pipeline::start_finish`], [`Pipeline::finish_step`]):
//! the decrement regression over the usable half-cycles, then the averaging iterations, then the
//! estimates with their standard errors, the envelope's shape and the verdict.

use super::*;

impl Pipeline {
    /// The half-cycles the result is computed from: all of them, or those before the first gap.
    pub(super) fn usable(&self) -> &[HalfCycle] {
        let n = self.st.kept.unwrap_or(self.records.len());
        self.records.get(..n).unwrap_or(&self.records)
    }

    /// Analyses what was recorded and returns the result (can be called at any time; normally once
    /// [`Pipeline::is_finished`]). All at once: see [`Pipeline::finish_step`] to spread the work.
    pub fn finish(&self, run_id: u32) -> OnboardResult {
        let mut job = self.start_finish(run_id);
        loop {
            if let Some(r) = self.finish_step(&mut job, u32::MAX) {
                return r;
            }
        }
    }

    /// Starts the end-of-run analysis as a job of bounded steps ([`Pipeline::finish_step`]). The
    /// pipeline must not take samples or be reset until the job is done.
    pub fn start_finish(&self, run_id: u32) -> Finish {
        let recs: &[HalfCycle] = self.usable();
        let n_rev = recs.len();
        let cycles = (n_rev / 2).min(u16::MAX as usize) as u16;
        Finish {
            out: OnboardResult {
                run_id,
                verdict: Verdict::NoOscillation,
                cycles,
                frequency_hz: f32::NAN,
                initial_amplitude_m: f32::NAN,
                duration_s: recs
                    .last()
                    .map_or(self.st.n as f64 / self.st.rate, |r| r.t as f64)
                    as f32,
                best: NAN_ESTIMATE,
                averaging: NAN_ESTIMATE,
                decrement: NAN_ESTIMATE,
                shape: EnvelopeShape::Straight,
                curvature: f32::NAN,
            },
            stage: Stage::Frequency(OlsPasses::new()),
            i: 0,
            omega_d: 0.0,
            scale: 0.0,
            dec: None,
            avg: Averaging::default(),
            short: false,
            refit: Refit::new(),
        }
    }

    /// Advances the end-of-run analysis by at most `rows` rows of its regressions (a row is one
    /// half-cycle of one pass: a few hundred instructions at most) and returns the result once it
    /// is complete. Run to the end, the steps compute exactly what [`Pipeline::finish`] does.
    ///
    /// What is computed, in order: the frequency from the reversal times (weighted least squares, 3
    /// passes) and the spread of the half periods about it (1 pass); the decrement fit on the peaks (3 passes); the averaging fit: the mean displacement
    /// (1 pass), then 4 iterations of the linear fit (3 passes), the quadratic fit (3 passes) and the
    /// range of amplitudes (1 pass). Then the verdict.
    pub fn finish_step(&self, job: &mut Finish, rows: u32) -> Option<OnboardResult> {
        let recs: &[HalfCycle] = self.usable();
        let n = recs.len();
        let mut budget = rows;
        loop {
            match &mut job.stage {
                Stage::Frequency(f) => {
                    // Reversals are half a damped period apart, Coulomb or not. Weighted by the
                    // squared amplitude about the reversal (the crossing time's error goes as
                    // 1/amplitude), so that reversals of tiny final half-cycles do not bias it.
                    let omega_c = fit::sqrt(self.st.stiffness / self.st.mass);
                    while job.i < n {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        let i = job.i;
                        let m = recs[i].moments;
                        let w = m.var_x as f64 + m.mean_v2 as f64 / (omega_c * omega_c);
                        f.row([i as f64], recs[i].t as f64, w);
                        job.i += 1;
                    }
                    job.i = 0;
                    let freq = match f.end_pass() {
                        Pass::Again => continue,
                        Pass::Done(None) => return Some(job.done()),
                        Pass::Done(Some(freq)) => freq,
                    };
                    let half_period_s = freq.coef[0];
                    let omega_d = PI / half_period_s;
                    let plausible = omega_d > 0.5 * omega_c && omega_d < 2.0 * omega_c;
                    if !plausible {
                        return Some(job.done());
                    }
                    job.stage = Stage::Spread {
                        half_period_s,
                        sw: 0.0,
                        swd: 0.0,
                    };
                    job.i = 1;
                }
                Stage::Spread {
                    half_period_s,
                    sw,
                    swd,
                } => {
                    // The half periods one by one about their mean, weighted as above: a spring
                    // whose stiffness depends on the amplitude (a cubic term of a few % of k)
                    // shortens or lengthens them slowly over the run, which a straight line
                    // through the reversal times cannot follow (its residuals grew to several %
                    // of a half period over 50 cycles and the record was called "no
                    // oscillation"); reversals counted from noise scatter them by their own size.
                    let omega_c = fit::sqrt(self.st.stiffness / self.st.mass);
                    let weight = |m: &HalfCycleMoments| {
                        m.var_x as f64 + m.mean_v2 as f64 / (omega_c * omega_c)
                    };
                    while job.i < n {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        let (a, b) = (&recs[job.i - 1], &recs[job.i]);
                        let w = weight(&a.moments).min(weight(&b.moments));
                        let d = (b.t as f64 - a.t as f64) / *half_period_s - 1.0;
                        if w.is_finite() && w > 0.0 {
                            *sw += w;
                            *swd += w * d * d;
                        }
                        job.i += 1;
                    }
                    job.i = 0;
                    let spread = if *sw > 0.0 {
                        fit::sqrt(*swd / *sw)
                    } else {
                        f64::INFINITY
                    };
                    let regular = spread < MAX_HALF_PERIOD_SPREAD;
                    if !regular {
                        return Some(job.done());
                    }
                    let omega_d = PI / *half_period_s;
                    job.out.frequency_hz = (omega_d / (2.0 * PI)) as f32;
                    if n < MIN_HALF_CYCLES {
                        job.out.verdict = Verdict::TooFewCycles;
                        return Some(job.done());
                    }
                    job.omega_d = omega_d;
                    job.scale = self.st.stiffness / self.st.load; // metres → y
                    job.refit.step = omega_d / self.st.rate;
                    job.stage = if job.out.cycles < MIN_CYCLES {
                        Stage::Refit
                    } else {
                        Stage::Decrement(OlsPasses::new())
                    };
                }
                Stage::Refit => {
                    // A short run's result rests on its few peaks and their ±: each is fitted
                    // again from its kept window with the motion's own model, one piece of one
                    // window a step (a few thousand instructions on the M7).
                    let at_once = rows == u32::MAX;
                    let done = self.refit_step(&mut job.refit, at_once);
                    if done {
                        job.stage = Stage::Decrement(OlsPasses::new());
                    }
                    if !at_once {
                        // the regressions start in a step of their own
                        return None;
                    }
                }
                Stage::Decrement(f) => {
                    while job.i + 1 < n {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        let i = job.i;
                        let (a, b) = (job.refit.peak(recs, i), job.refit.peak(recs, i + 1));
                        let (sa, sb) = (self.sign(i), self.sign(i + 1));
                        f.row([sa * a, sb], sb * b, 1.0);
                        job.i += 1;
                    }
                    job.i = 0;
                    let fitted = match f.end_pass() {
                        Pass::Again => continue,
                        Pass::Done(fitted) => fitted,
                    };
                    job.dec = fitted.and_then(|f| decrement(&f, job.scale));
                    if job.out.cycles < MIN_CYCLES {
                        // Too few half-cycles for the averaging fit's central differences: the
                        // peaks alone, their ± propagated from each peak's own (see `Short`).
                        job.i = 0;
                        job.stage = Stage::Short {
                            base: None,
                            var: [0.0; 2],
                        };
                        continue;
                    }
                    if n < 6 {
                        return Some(self.conclude(job));
                    }
                    // Half-cycle j (1 ≤ j < n) runs from reversal j−1 to reversal j; 0 starts at
                    // release: skipped.
                    job.avg = Averaging {
                        even: if (n - 1) & 1 == 0 { n - 1 } else { n - 2 },
                        ..Averaging::default()
                    };
                    if job.avg.even < 2 {
                        return Some(self.conclude(job));
                    }
                    job.i = 1;
                    job.stage = Stage::Offset { sum: -0.0 };
                }
                Stage::Offset { sum } => {
                    while job.i <= job.avg.even {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        *sum += recs[job.i].moments.mean_x as f64;
                        job.i += 1;
                    }
                    job.avg.offset = *sum / job.avg.even as f64;
                    self.next_iteration(job);
                }
                Stage::Linear(f) => {
                    while job.i < n.saturating_sub(1) {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        if let Some((a, d)) = self.averaging_row(&job.avg, job.scale, job.i) {
                            f.row([a], d, 1.0);
                        }
                        job.i += 1;
                    }
                    job.i = 2;
                    let lin = match f.end_pass() {
                        Pass::Again => continue,
                        Pass::Done(None) => {
                            job.avg.result = None;
                            return Some(self.conclude(job));
                        }
                        Pass::Done(Some(lin)) => lin,
                    };
                    let (a0, a1, _) = central(&lin, job.avg.dtau);
                    let a = &mut job.avg;
                    a.mu0 = -PI * a0 / 2.0;
                    a.mu1 = -2.0 * a1;
                    a.r = a.mu0 / job.scale;
                    if !(a.r.is_finite() && a.mu1.is_finite()) {
                        a.result = None;
                        return Some(self.conclude(job));
                    }
                    job.stage = Stage::Quadratic {
                        lin,
                        quad: OlsPasses::new(),
                    };
                }
                Stage::Quadratic { lin, quad } => {
                    while job.i < n.saturating_sub(1) {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        if let Some((a, d)) = self.averaging_row(&job.avg, job.scale, job.i) {
                            quad.row([a, a * a], d, 1.0);
                        }
                        job.i += 1;
                    }
                    job.i = 2;
                    let quad = match quad.end_pass() {
                        Pass::Again => continue,
                        Pass::Done(q) => q,
                    };
                    job.stage = Stage::Range {
                        lin: *lin,
                        quad,
                        lo: f64::INFINITY,
                        hi: f64::NEG_INFINITY,
                    };
                }
                Stage::Range { lin, quad, lo, hi } => {
                    while job.i < n.saturating_sub(1) {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        if let Some(a) = self.amplitude(&job.avg, job.scale, job.i) {
                            (*lo, *hi) = (lo.min(a), hi.max(a));
                        }
                        job.i += 1;
                    }
                    let (shape, curvature) = match quad {
                        Some(q) => (shape_of(q, *lo, *hi), q.coef[1]),
                        None => (EnvelopeShape::Straight, f64::NAN),
                    };
                    let a = &mut job.avg;
                    // Each amplitude enters the central differences of the rows either side of
                    // it: residuals two rows apart are correlated (ρ2 = −½ but for the a1 term).
                    let h2 = 1.0 / (a.dtau * a.dtau);
                    let (_, a1, [g0, g1]) = central(lin, a.dtau);
                    let rho = [0.0, -h2 / (2.0 * h2 + a1 * a1)];
                    let Some(estimate) = estimate(
                        a.mu0,
                        a.mu1,
                        variance(lin, &g0, rho) * PI * PI / 4.0,
                        variance(lin, &g1, rho) * 4.0,
                    ) else {
                        a.result = None;
                        return Some(self.conclude(job));
                    };
                    a.result = Some(Fitted {
                        estimate,
                        offset: a.offset,
                        shape,
                        curvature,
                    });
                    a.iteration += 1;
                    if a.iteration == AVERAGING_ITERATIONS {
                        return Some(self.conclude(job));
                    }
                    self.next_iteration(job);
                }
                Stage::Short { base, var } => {
                    // The decrement fit is linear in the peaks' regression but the peaks are in
                    // both its sides: the ± of μ0 and μ1 is propagated from every peak's variance
                    // (its window's residuals, pooled over the run) through the fit itself, by
                    // central differences, one peak a step. The textbook ± of a regression with
                    // 0–5 degrees of freedom means little (with 1 it is 1.8× too small one time
                    // in four).
                    let pooled = job.refit.pooled_variance();
                    if !(pooled.is_finite() && pooled > 0.0) {
                        return Some(self.conclude(job));
                    }
                    let h = fit::sqrt(pooled);
                    let refit = &job.refit;
                    let Some(b) = base.or_else(|| self.peaks_fit(refit, None, job.scale)) else {
                        job.dec = None;
                        return Some(self.conclude(job));
                    };
                    *base = Some(b);
                    while job.i < n {
                        if budget == 0 {
                            return None;
                        }
                        budget -= 1;
                        let up = self.peaks_fit(refit, Some((job.i, h)), job.scale);
                        let down = self.peaks_fit(refit, Some((job.i, -h)), job.scale);
                        let (Some(up), Some(down)) = (up, down) else {
                            job.dec = None;
                            return Some(self.conclude(job));
                        };
                        // the peak's own variance (a window that went wrong says so in its
                        // residuals), else the run's
                        let peak_var = refit
                            .vars
                            .get(job.i)
                            .copied()
                            .filter(|v| v.is_finite() && *v > 0.0)
                            .unwrap_or(pooled);
                        for j in 0..2 {
                            let d = (up[j] - down[j]) / (2.0 * h);
                            var[j] += d * d * peak_var;
                        }
                        job.i += 1;
                    }
                    job.dec = estimate(b[0], b[1], var[0], var[1]).map(|estimate| Fitted {
                        estimate,
                        offset: job.dec.as_ref().map_or(f64::NAN, |d| d.offset),
                        shape: EnvelopeShape::Straight,
                        curvature: f64::NAN,
                    });
                    job.short = true;
                    return Some(self.conclude(job));
                }
                Stage::Done => return Some(job.out),
            }
        }
    }

    /// Starts an iteration of the averaging fit: the envelope about each half-cycle's centre
    /// `offset − s_j r` and Ω from the previous iteration's μ0 and μ1, with the measured noise
    /// variance taken out of the mean square.
    pub(super) fn next_iteration(&self, job: &mut Finish) {
        let a = &mut job.avg;
        a.omega = job.omega_d / fit::sqrt((1.0 - 0.25 * a.mu1 * a.mu1).max(0.25));
        a.r_now = a.r;
        let (nx, nv) = self.st.noise_var;
        let gv = self.st.cal[Channel::Velocity as usize].gain as f64;
        let nv = nv.max(self.st.sv_motion * self.st.sv_motion * gv * gv);
        a.noise = nx + nv / (a.omega * a.omega);
        // Half-cycles last exactly π/ω_d (Coulomb or not): nominal spacing, free of the timing
        // noise of reversals at tiny amplitude.
        a.dtau = 2.0 * PI * a.omega / job.omega_d;
        job.i = 2;
        job.stage = Stage::Linear(OlsPasses::new());
    }

    /// Envelope of half-cycle `j` in y units (see [`Pipeline::next_iteration`]).
    pub(super) fn amplitude(&self, a: &Averaging, scale: f64, j: usize) -> Option<f64> {
        let centre = a.offset - self.sign(j) * a.r_now;
        let ms = self.usable().get(j)?.moments.mean_square(centre, a.omega) - a.noise;
        Some(fit::sqrt(ms.max(0.0)) * scale)
    }

    /// Row `j` of the averaging fit: the amplitude and its central difference over two
    /// half-cycles.
    pub(super) fn averaging_row(&self, a: &Averaging, scale: f64, j: usize) -> Option<(f64, f64)> {
        let amp = |j| self.amplitude(a, scale, j);
        Some((amp(j)?, (amp(j + 1)? - amp(j.checked_sub(1)?)?) / a.dtau))
    }

    /// The verdict, from the two estimators.
    pub(super) fn conclude(&self, job: &mut Finish) -> OnboardResult {
        let dec = job.dec.take();
        let avg = job.avg.result.take();
        let out = &mut job.out;
        if let Some(d) = &dec {
            out.decrement = d.estimate;
        }
        if let Some(a) = &avg {
            out.averaging = a.estimate;
            out.shape = a.shape;
            out.curvature = a.curvature as f32;
            let mu1 = a.estimate.mu1 as f64;
            let omega = job.omega_d / fit::sqrt((1.0 - 0.25 * mu1 * mu1).max(0.25));
            out.frequency_hz = (omega / (2.0 * PI)) as f32;
        }
        let centre = dec
            .as_ref()
            .map(|d| d.offset)
            .or(avg.as_ref().map(|a| a.offset));
        if let Some(c) = centre {
            out.initial_amplitude_m = (self.st.x_release as f64 - c).abs() as f32;
        }
        let (verdict, best) = match (&dec, &avg) {
            (None, None) => (Verdict::NoOscillation, NAN_ESTIMATE),
            // A short run: the peaks' fit is the only one there is (nothing to disagree with).
            (Some(d), None) if job.short => (Verdict::Ok, d.estimate),
            (Some(d), None) => (Verdict::EstimatorsDisagree, d.estimate),
            (None, Some(a)) => (Verdict::EstimatorsDisagree, a.estimate),
            (Some(d), Some(a)) => combine(&d.estimate, &a.estimate),
        };
        out.best = best;
        out.verdict = if verdict == Verdict::NoOscillation {
            verdict
        } else if self.st.saturated > 0 {
            Verdict::Saturated
        } else {
            verdict
        };
        let all_finite = [out.best.mu0, out.best.mu1, out.best.mu0_se, out.best.mu1_se]
            .iter()
            .all(|v| v.is_finite());
        if !all_finite && out.verdict == Verdict::Ok {
            out.verdict = Verdict::NoOscillation;
        }
        job.done()
    }

    /// μ0 and μ1 of the decrement fit `X_{n+1} = D X_n − r (1 + D)` over the usable peaks, solved
    /// directly (normal equations, centred), peak `i` moved by `dx` metres if asked: the short
    /// run's ± is propagated through this.
    pub(super) fn peaks_fit(
        &self,
        refit: &Refit,
        moved: Option<(usize, f64)>,
        scale: f64,
    ) -> Option<[f64; 2]> {
        let recs = self.usable();
        let peak = |i: usize| -> f64 {
            let p = refit.peak(recs, i);
            match moved {
                Some((j, dx)) if j == i => p + dx,
                _ => p,
            }
        };
        let rows = recs.len().checked_sub(1)?;
        if rows < 3 {
            return None;
        }
        // rows: y = β + D·x1 + γ·x2 with x1 = s_i P_i, x2 = s_{i+1}, y = s_{i+1} P_{i+1}
        let row = |i: usize| {
            let (sa, sb) = (self.sign(i), self.sign(i + 1));
            ([sa * peak(i), sb], sb * peak(i + 1))
        };
        let m = rows as f64;
        let (mut mx, mut my) = ([0.0f64; 2], 0.0f64);
        for i in 0..rows {
            let (x, y) = row(i);
            mx[0] += x[0] / m;
            mx[1] += x[1] / m;
            my += y / m;
        }
        let (mut a, mut b) = ([[0.0f64; 2]; 2], [0.0f64; 2]);
        for i in 0..rows {
            let (x, y) = row(i);
            let (u, w, z) = (x[0] - mx[0], x[1] - mx[1], y - my);
            a[0][0] += u * u;
            a[0][1] += u * w;
            a[1][1] += w * w;
            b[0] += u * z;
            b[1] += w * z;
        }
        let det = a[0][0] * a[1][1] - a[0][1] * a[0][1];
        if !(det.is_finite() && det > 0.0) {
            return None;
        }
        let d = (a[1][1] * b[0] - a[0][1] * b[1]) / det;
        let gamma = (a[0][0] * b[1] - a[0][1] * b[0]) / det;
        let beta = my - d * mx[0] - gamma * mx[1];
        if !(d > 0.0 && d < 2.0) {
            return None;
        }
        let r = -beta / (1.0 + d);
        let l = -fit::ln(d) / PI;
        let mu1 = 2.0 * l / fit::sqrt(1.0 + l * l);
        Some([r * scale, mu1])
    }

    /// Peak sign (+1 maximum) of reversal `i`.
    pub(super) fn sign(&self, i: usize) -> f64 {
        let s = self.st.first_sign as f64;
        if i & 1 == 0 {
            s
        } else {
            -s
        }
    }
}

pub(super) const NAN_ESTIMATE: Estimate = Estimate {
    mu0: f32::NAN,
    mu1: f32::NAN,
    mu0_se: f32::NAN,
    mu1_se: f32::NAN,
};

/// Largest weighted RMS deviation of the half periods from their mean, relative, for the
/// reversals to be taken as an oscillation's.
pub(super) const MAX_HALF_PERIOD_SPREAD: f64 = 0.05;

/// Iterations of the averaging fit (each refines the centres and Ω with the previous μ0, μ1).
pub(super) const AVERAGING_ITERATIONS: u8 = 4;

/// The end-of-run analysis in progress (see [`Pipeline::finish_step`]).
#[derive(Clone, Debug)]
pub struct Finish {
    pub(super) out: OnboardResult,
    pub(super) stage: Stage,
    /// Next row of the current pass.
    pub(super) i: usize,
    pub(super) omega_d: f64,
    /// Metres → y.
    pub(super) scale: f64,
    pub(super) dec: Option<Fitted>,
    pub(super) avg: Averaging,
    /// A short run: the peaks' fit alone (see [`Stage::Short`]).
    pub(super) short: bool,
    /// A short run's peaks fitted again from their windows (see [`Stage::Refit`]).
    pub(super) refit: Refit,
}

/// Window samples pushed, or read into the fit, in one step of [`Stage::Refit`].
const REFIT_UNIT: usize = 32;

/// A short run's peaks fitted again from the windows the pipeline kept (see [`Stage::Refit`]).
#[derive(Clone, Debug)]
pub(super) struct Refit {
    /// Window being fitted and its counts pushed into the fitter so far.
    i: usize,
    fed: usize,
    /// The peaks (metres from the zero) and their variances (m², NaN when unknown) of the
    /// windows fitted so far (`fitted` of them).
    peaks: [f64; SHORT_PEAKS],
    pub(super) vars: [f64; SHORT_PEAKS],
    fitted: usize,
    /// The phase step ω_d Δt of the run (set by the frequency stage, before this one).
    pub(super) step: f64,
}

impl Refit {
    fn new() -> Self {
        Self {
            i: 0,
            fed: 0,
            peaks: [f64::NAN; SHORT_PEAKS],
            vars: [f64::NAN; SHORT_PEAKS],
            fitted: 0,
            step: 0.0,
        }
    }

    /// Peak `i` (metres): refitted if it was, else as recorded during the run.
    pub(super) fn peak(&self, recs: &[HalfCycle], i: usize) -> f64 {
        match self.peaks.get(i) {
            Some(&p) if i < self.fitted && p.is_finite() => p,
            _ => recs.get(i).map_or(f64::NAN, |r| r.peak as f64),
        }
    }

    /// The mean of the refitted peaks' variances (m²; NaN when none is known).
    pub(super) fn pooled_variance(&self) -> f64 {
        let (mut sum, mut n) = (0.0, 0u32);
        for &v in self.vars.iter().take(self.fitted) {
            if v.is_finite() && v > 0.0 {
                sum += v;
                n += 1;
            }
        }
        if n > 0 {
            sum / n as f64
        } else {
            f64::NAN
        }
    }
}

impl Finish {
    /// True once [`Pipeline::finish_step`] has returned the result.
    pub fn is_done(&self) -> bool {
        matches!(self.stage, Stage::Done)
    }

    pub(super) fn done(&mut self) -> OnboardResult {
        self.stage = Stage::Done;
        self.out
    }
}

#[derive(Clone, Debug)]
pub(super) enum Stage {
    Frequency(OlsPasses<1>),
    Spread {
        half_period_s: f64,
        sw: f64,
        swd: f64,
    },
    /// A short run's peaks fitted again from their windows ([`Refit`]).
    Refit,
    Decrement(OlsPasses<2>),
    /// A run of [`MIN_HALF_CYCLES`] to `2·MIN_CYCLES − 1` half-cycles: the decrement fit's ±
    /// propagated from the peaks' (`var`: of μ0, μ1 so far; `base`: the fit's μ0, μ1).
    Short {
        base: Option<[f64; 2]>,
        var: [f64; 2],
    },
    Offset {
        sum: f64,
    },
    Linear(OlsPasses<1>),
    Quadratic {
        lin: Ols<1>,
        quad: OlsPasses<2>,
    },
    Range {
        lin: Ols<1>,
        quad: Option<Ols<2>>,
        lo: f64,
        hi: f64,
    },
    Done,
}

/// The averaging fit's state across its iterations.
#[derive(Clone, Debug, Default)]
pub(super) struct Averaging {
    /// Half-cycles used for the mean displacement (an even number).
    pub(super) even: usize,
    /// Mean displacement (the centre of oscillation), m.
    pub(super) offset: f64,
    /// Coulomb shift (m) and μ0, μ1 of the last iteration.
    pub(super) r: f64,
    pub(super) mu0: f64,
    pub(super) mu1: f64,
    pub(super) iteration: u8,
    /// This iteration's constants: Coulomb shift, Ω, noise mean square, half-cycle spacing in τ.
    pub(super) r_now: f64,
    pub(super) omega: f64,
    pub(super) noise: f64,
    pub(super) dtau: f64,
    pub(super) result: Option<Fitted>,
}

/// `a0`, `a1` of `dA/dτ = a0 + a1 A` from the regression of the central differences
/// `(A_{j+1} − A_{j−1}) / dτ` on `A_j` (rows `dτ` apart in τ, two half cycles), and the gradients
/// of `a0` and `a1` in its parameters (intercept, slope). The envelope `A = (A_0 + a0/a1) e^{a1 τ}
/// − a0/a1` makes that difference `(A + a0/a1) sinh(a1 h)/h` exactly, `h = dτ/2`: slope `S =
/// sinh(a1 h)/h`, intercept `a0 S / a1`. Taking the slope for `a1` (the first-order difference)
/// overstated μ1 by `(a1 h)²/6` of itself: 4e-4 at μ1 = 0.03, 11 of its σ.
pub(super) fn central(lin: &Ols<1>, dtau: f64) -> (f64, f64, [[f64; 2]; 2]) {
    let (b, s) = (lin.intercept, lin.coef[0]);
    let h = 0.5 * dtau;
    let x = s * h;
    // q = asinh(x)/x and its derivative in x
    let (q, dq) = if x.abs() < 1e-4 {
        (1.0 - x * x / 6.0, -x / 3.0)
    } else {
        let root = fit::sqrt(1.0 + x * x);
        let asinh = fit::ln(x + root);
        (asinh / x, (x / root - asinh) / (x * x))
    };
    // a1 = asinh(s h)/h = s q, a0 = b a1 / s = b q
    let a1 = s * q;
    let a0 = b * q;
    let da1_ds = q + s * dq * h;
    let da0_ds = b * dq * h;
    (a0, a1, [[q, da0_ds], [0.0, da1_ds]])
}

/// Variance of `Σ g_i p_i` of a regression whose rows share measurements, so that white noise
/// gives its residuals the correlation `rho` (rows one and two apart): the sandwich with `rho`
/// ([`Ols::var_of_correlated`]). When the residuals' own correlation differs from `rho` beyond its
/// scatter (2/√n), an error that varies slowly along the run is there too (the envelope's at the
/// simulator's default noise at 2 kS/s, the peaks' at any noise), which the white noise's
/// correlation does not describe: the sandwich with the correlation seen, if larger. Never less
/// than the white noise's.
pub(super) fn variance<const P: usize>(f: &Ols<P>, g: &[f64], rho: [f64; 2]) -> f64 {
    let white = f.var_of_correlated(g, rho);
    let seen = f.residual_correlation();
    let scatter = 2.0 / fit::sqrt(f.n as f64);
    let structured = (seen[0] - rho[0]).abs() > scatter || (seen[1] - rho[1]).abs() > scatter;
    if structured {
        white.max(f.var_of_correlated(g, seen))
    } else {
        white
    }
}

/// The decrement estimator from its regression `X_{n+1} = D X_n − r (1 + D)` on signed peaks.
pub(super) fn decrement(f: &Ols<2>, scale: f64) -> Option<Fitted> {
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
    let g0 = [
        -scale / (1.0 + d),
        scale * beta / ((1.0 + d) * (1.0 + d)),
        0.0,
    ];
    let g1 = [0.0, dmu1_dd, 0.0];
    // The textbook ±, which overstates this estimator's error (each peak is in two rows, and the
    // residuals `ε_{n+1} − D ε_n` of neighbouring rows nearly cancel along the run) yet not
    // uniformly: the sandwich for that correlation understated it 2–3× over the bench grid (the
    // peaks' errors are not white, and in the regressor too). It is used only to tell whether the
    // two estimators agree, where erring wide raises no false alarm; `best` is the averaging
    // estimator's.
    let estimate = estimate(mu0, mu1, f.var_of(&g0), f.var_of(&g1))?;
    Some(Fitted {
        estimate,
        offset,
        shape: EnvelopeShape::Straight,
        curvature: 0.0,
    })
}

#[derive(Clone, Debug)]
pub(super) struct Fitted {
    pub(super) estimate: Estimate,
    /// Displacement of the centre of oscillation in the calibrated frame (m).
    pub(super) offset: f64,
    pub(super) shape: EnvelopeShape,
    pub(super) curvature: f64,
}

pub(super) fn estimate(mu0: f64, mu1: f64, var0: f64, var1: f64) -> Option<Estimate> {
    let e = Estimate {
        mu0: mu0 as f32,
        mu1: mu1 as f32,
        mu0_se: fit::sqrt(var0.max(0.0)) as f32,
        mu1_se: fit::sqrt(var1.max(0.0)) as f32,
    };
    [e.mu0, e.mu1, e.mu0_se, e.mu1_se]
        .iter()
        .all(|v| v.is_finite())
        .then_some(e)
}

/// Shape of `F(A) = a0 + a1 A + a2 A²` over `[lo, hi]` from the sign of `F'` at both ends (3σ).
pub(super) fn shape_of(q: &Ols<2>, lo: f64, hi: f64) -> EnvelopeShape {
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

/// The result shown (the averaging estimator's: one estimator per quantity) and the verdict of
/// the cross-check between the two estimators.
///
/// `best` was the inverse-variance mean of the two with half their difference added to its ±: two
/// estimators of the same samples are far from independent, and the difference term made the ±
/// 1.5–2.7 times the error over the bench grid (0.32 on μ0 = 0.029 when they disagreed). The
/// averaging estimator's ± (its residuals' correlation accounted for) is what it says over the
/// grid (`examples/onboard_grid.rs` in the host crate); the decrement's stands only in the check.
pub(super) fn combine(d: &Estimate, a: &Estimate) -> (Verdict, Estimate) {
    let agree = |x: f32, sx: f32, y: f32, sy: f32, tol: f64| -> bool {
        let (x, sx, y, sy) = (x as f64, sx as f64, y as f64, sy as f64);
        (x - y).abs() <= tol + 3.0 * fit::sqrt(sx * sx + sy * sy)
    };
    let ok0 = agree(d.mu0, d.mu0_se, a.mu0, a.mu0_se, MU0_PRECISION);
    let ok1 = agree(d.mu1, d.mu1_se, a.mu1, a.mu1_se, MU1_PRECISION);
    (
        if ok0 && ok1 {
            Verdict::Ok
        } else {
            Verdict::EstimatorsDisagree
        },
        *a,
    )
}

impl Pipeline {
    /// One piece of [`Stage::Refit`] (all of it when `at_once`): pushes or reads
    /// [`REFIT_UNIT`] window samples, or takes one of the fit's later stages. True once every
    /// kept window is fitted.
    fn refit_step(&self, r: &mut Refit, at_once: bool) -> bool {
        let xc = self.st.cal[Channel::Displacement as usize];
        let (gain, zero) = (xc.gain as f64, xc.zero as f64);
        let recs = self.usable();
        let m = recs.len().min(SHORT_PEAKS);
        let w = &self.windows;
        // the fitter lives in the pipeline (a `&self` step, and no 2 KiB in the job the
        // application keeps); nothing else borrows it
        let Ok(mut fitter) = self.arc.try_borrow_mut() else {
            r.fitted = 0;
            return true;
        };
        while r.i < m {
            let i = r.i;
            let win = w.get(i);
            let len = win.map_or(0, |w| w.len as usize);
            let counts = win.and_then(|w| w.counts.get(..len)).unwrap_or(&[]);
            if r.fed == 0 {
                fitter.reset();
                // the run's own frequency (every reversal's time, set before this stage), not
                // the one each window was cut with: the first window's half period runs from the
                // release (0.8 % off on a 20 Hz rig), which an arc of fixed frequency turns into
                // a peak off by several of its σ
                fitter.set_step(r.step);
                fitter.set_half(len / 2);
                if len == 0 || 2 * fitter.half_window() + 1 > len {
                    // no window kept (two reversals within one: the record's peak stands)
                    r.vars[i] = f64::NAN;
                    r.peaks[i] = f64::NAN;
                    r.i += 1;
                    r.fitted = r.i;
                    continue;
                }
            }
            if r.fed < len {
                let end = if at_once {
                    len
                } else {
                    (r.fed + REFIT_UNIT).min(len)
                };
                for &c in counts.get(r.fed..end).unwrap_or(&[]) {
                    fitter.push(c);
                }
                r.fed = end;
                if r.fed == len {
                    let delta = win.map_or(0.0, |w| w.delta as f64);
                    if let Some(Some(raw)) = fitter.start(len / 2, delta) {
                        r.peaks[i] = gain * (raw.peak - zero);
                        r.vars[i] = f64::NAN;
                        r.fed = 0;
                        r.i += 1;
                        r.fitted = r.i;
                        continue;
                    }
                }
                if !at_once {
                    return false;
                }
                continue;
            }
            let done = fitter.step_unpaced(if at_once { usize::MAX } else { REFIT_UNIT });
            if let Some(f) = done {
                r.peaks[i] = gain * (f.peak - zero);
                r.vars[i] = quantised(f) * gain * gain;
                r.fed = 0;
                r.i += 1;
                r.fitted = r.i;
            }
            if !at_once {
                return r.i >= m;
            }
        }
        true
    }
}

/// A peak's variance (counts²) with what quantisation leaves when the noise does not dither it.
/// Without dither (noise under half a count) the counts' rounding errors near the vertex follow
/// the signal, not chance: they do not average out over the window, and the residuals' variance
/// (≈ 1/12) says nothing of them. Floor: the variance of the rounding error's first harmonic with
/// a Gaussian dither of the noise σ the residuals leave beyond the rounding itself,
/// `e^{−4π²σ²} / (2π²)` (0.051 without noise, 0.003 at σ = 0.3, nothing from σ = 0.6 on).
fn quantised(f: crate::peaks::arc::PeakFit) -> f64 {
    let sigma2 = (f.residual_variance - 1.0 / 12.0).max(0.0);
    let pi2 = core::f64::consts::PI * core::f64::consts::PI;
    let floor = fit::exp(-4.0 * pi2 * sigma2) / (2.0 * pi2);
    if f.variance.is_finite() {
        f.variance.max(floor)
    } else {
        f.variance
    }
}

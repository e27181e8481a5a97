//! What a model of the record is: the base law and the effects added to it ([`Effect`], [`Spec`]).

use super::*;

/// A physical effect the base law may be missing (names as in the JSON output).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Effect {
    /// Next pseudo-polynomial term (`μ2 y'² sgn(y')` on a Coulomb–viscous base).
    QuadraticVelocity,
    /// Exponential Stribeck rise at low sliding speed: static level `μ_s`, speed `v_s`, the
    /// curve's exponent `δ` (`e^{−(|y'|/v_s)^δ}`) 1 or 2, chosen from the record
    /// ([`Spec::stribeck_delta`]).
    Stribeck,
    /// Friction with memory: the friction force relaxes towards the steady law with a memory time
    /// `T` (a first-order lag; [`FrictionLaw::Lagged`]).
    FrictionalLag,
    /// Cubic spring `κ y³` (SI `k3 x³`).
    CubicStiffness,
    /// Coulomb level following the temperature channel: `μ0 + γ (T(t) − T(0))`.
    ThermalDrift,
    /// Force channel delayed by `τ_d` relative to the vibrometer.
    SensorLag,
    /// Running-in: the Coulomb level drifting in time at constant temperature towards a new
    /// level, first order in time, `μ0 + Δ S(c, τ/τ_end)` with `S(c, x) = (1 − e^{−c x}) /
    /// (1 − e^{−c})` (`Δ` the change over the compared motion, `τ_end` its length, `c = τ_end /
    /// τ_r` the motion in units of the running-in's time constant `τ_r`). Its rate at the release
    /// is `r = Δ c / ((1 − e^{−c}) τ_end)`: this is `μ0 + r τ_r (1 − e^{−τ/τ_r})`, whose limit `c → 0`
    /// (`τ_r → ∞`) is the linear drift `μ0 + Δ τ/τ_end`, nested at `c = 0`; `c < 0` is a drift
    /// that speeds up. A surface wearing in settles (real-bench.md: μ0 "drifts 10–30 % over the
    /// first minutes"), so a record shows the linear part of a slow running-in and the bend of
    /// one whose time constant is within the motion.
    RunningIn,
    /// Direction asymmetry: the Coulomb level differs between the sliding directions, `μ0 + δ`
    /// forward (y' > 0) and `μ0 − δ` backward. The friction force is `N[μ0 sgn v + δ + …]`: a
    /// constant force while sliding, which shifts the motion's centre by `−δ` (in y) and offsets
    /// the force channel by `+δ` — exactly what a displacement zero offset of `−δ` with a force
    /// zero offset of `+δ` give. It is only a candidate when the force channel's zero is stated
    /// ([`crate::Prepared::force_zero`]); the displacement centre is a fitted nuisance of every
    /// model.
    DirectionAsymmetry,
}

impl Effect {
    /// Every effect of the vocabulary.
    pub const ALL: [Effect; 8] = [
        Effect::QuadraticVelocity,
        Effect::Stribeck,
        Effect::FrictionalLag,
        Effect::CubicStiffness,
        Effect::ThermalDrift,
        Effect::SensorLag,
        Effect::RunningIn,
        Effect::DirectionAsymmetry,
    ];

    /// JSON name.
    pub fn name(&self) -> &'static str {
        match self {
            Effect::QuadraticVelocity => "quadratic-velocity",
            Effect::Stribeck => "stribeck",
            Effect::FrictionalLag => "frictional-lag",
            Effect::CubicStiffness => "cubic-stiffness",
            Effect::ThermalDrift => "thermal-drift",
            Effect::SensorLag => "sensor-lag",
            Effect::RunningIn => "running-in",
            Effect::DirectionAsymmetry => "direction-asymmetry",
        }
    }

    /// Parses a JSON name.
    pub fn from_name(s: &str) -> Option<Effect> {
        Effect::ALL.into_iter().find(|e| e.name() == s)
    }

    /// Number of parameters the effect adds.
    pub fn n_params(&self) -> usize {
        match self {
            Effect::Stribeck | Effect::RunningIn => 2,
            _ => 1,
        }
    }

    /// Dimensionless parameter names (in parameter-vector order).
    pub fn param_names(&self) -> &'static [&'static str] {
        match self {
            Effect::QuadraticVelocity => &["mu_next"],
            Effect::Stribeck => &["mu_s", "v_s"],
            Effect::FrictionalLag => &["memory_tau"],
            Effect::CubicStiffness => &["kappa"],
            Effect::ThermalDrift => &["dmu0_dT_per_c"],
            Effect::SensorLag => &["delay_tau"],
            Effect::RunningIn => &["dmu0_over_motion", "motion_over_tau"],
            Effect::DirectionAsymmetry => &["dmu0_half_difference"],
        }
    }
}

/// Largest force low-pass time constant explored (τ units: a cut-off at the rig's own
/// oscillation frequency; a charge amplifier filters far above it).
pub const LOWPASS_TAU_MAX: f64 = 1.0;

/// The shortest memory time of frictional lag the model simulates (rad; 64 µs at 25 Hz).
pub const MEMORY_TAU_MIN: f64 = 0.01;

/// Largest relative change of the stiffness at the release amplitude a cubic spring is explored
/// to, `|κ| a0²` (`|k3| x0² / k`; [`Spec::in_range`]). κ is in units of the load over the
/// stiffness (`κ = k3 N² / k³`), so a bound on κ alone is a different spring on every record: the
/// former `|κ| ≤ 0.05` allowed 0.5 % of k at `a0 = k x0 / N` = 0.3 and 30 times k at 25, and on
/// grid #421 (N 0.70 N, a0 0.79) it cut off the record's own −7.9 % (κ = −0.128, which the
/// frequency's slope against the amplitude read as −0.130), so every cubic fit stopped at the
/// bound or failed (3 of the grid's 68 cubic records, #376, #406 and #421, were outside it). A
/// quarter of k is well inside where a softening spring released from rest still oscillates
/// (`κ a0² > −1`) and above the strongest cubic the bench's table lists (10 %).
pub const CUBIC_STIFFNESS_MAX: f64 = 0.25;

/// The Stribeck curve's exponents a fit chooses from ([`Spec::stribeck_delta`]), the first the
/// default.
pub const STRIBECK_DELTAS: [f64; 2] = [2.0, 1.0];

/// Largest offset of the release instant from the one measured from the motion the fits explore
/// (τ units; [`Spec::release`]): half a radian, tens of samples at any rate, hundreds of the
/// measurement's ±.
pub const RELEASE_DELTA_MAX: f64 = 0.5;

/// Range of running-in's shape `c = τ_end / τ_r` ([`Effect::RunningIn`]): a time constant down
/// to a twentieth of the compared motion (a level that has settled after its first twentieth is a
/// step, not a drift the motion resolves), and a drift that speeds up by at most `e^5` over it.
pub const RUNNING_IN_SHAPE_MIN: f64 = -5.0;
/// Upper end of running-in's shape range ([`RUNNING_IN_SHAPE_MIN`]).
pub const RUNNING_IN_SHAPE_MAX: f64 = 20.0;

/// Running-in's drift at `x = τ / τ_end` of the compared motion relative to its change over it,
/// `S(c, x) = (1 − e^{−c x}) / (1 − e^{−c})` ([`Effect::RunningIn`]); `x` at `c = 0`.
pub fn running_in_shape(c: f64, x: f64) -> f64 {
    if c.abs() < 1e-9 {
        x
    } else {
        (-c * x).exp_m1() / (-c).exp_m1()
    }
}

/// Running-in's rate at the release relative to its mean rate over the motion, `h(c) = c / (1 −
/// e^{−c})`, and its derivative `h'(c)` (for the ± of the rate by the delta method).
pub fn running_in_rate_factor(c: f64) -> (f64, f64) {
    if c.abs() < 1e-6 {
        (1.0 + 0.5 * c, 0.5)
    } else {
        let d = -(-c).exp_m1(); // 1 − e^{−c}
        let h = c / d;
        let dh = (d - c * (-c).exp()) / (d * d);
        (h, dh)
    }
}

/// Model structure: base polynomial powers plus effects.
#[derive(Debug, Clone, PartialEq)]
pub struct Spec {
    /// Powers `j` of the fitted base constants `μ_j` (e.g. `[0, 1]` for Coulomb–viscous).
    pub powers: Vec<usize>,
    /// Added effects, in the order they were added.
    pub effects: Vec<Effect>,
    /// Whether the apparatus damping `μ_a` is a parameter (records with a force channel).
    pub apparatus: bool,
    /// Whether the force channel's low-pass is a parameter (a force channel whose filter the
    /// record does not state): its time constant `τ_f` (τ units, [`super::lowpass`]), fitted with
    /// everything else, in every model of the search.
    pub lowpass: bool,
    /// The fitted low-pass's order: 1 (a 1-pole filter) or 2 (the charge amplifier's 2-pole
    /// Butterworth). Chosen from the record ([`crate::explain_prepared`]) and held the same in
    /// every model a comparison sets side by side.
    pub lowpass_poles: u8,
    /// Whether the fitted 2-pole low-pass is a digital one: the bilinear Butterworth
    /// ([`tribo_physics::sensor::butterworth2`], the filter the rig's own records and a DAQ's
    /// digital filter apply to the sampled force, and the one a stated cut-off is) rather than
    /// the analog filter discretised exactly ([`super::lowpass`]). The two part where the cut-off
    /// nears the sampling rate (a force step at a reversal, 837 Hz at 6.9 kS/s: the exact one
    /// left a misfit in the samples after the reversals that a Stribeck rise was named for).
    /// Chosen from the record with the order and held in every model of the search.
    pub lowpass_digital: bool,
    /// Whether the release instant is a parameter (a record held before its release): its offset
    /// `δ` (τ units) from the instant measured from the motion ([`crate::Prepared::release_shift`],
    /// [`crate::release::release_from_motion`]), fitted with everything else in every model of
    /// the search under that measurement as a prior ([`crate::Prepared::release_prior`]).
    pub release: bool,
    /// The Stribeck curve's exponent `δ`, 1 or 2 (a contact shows either, real-bench.md): 2 when
    /// Stribeck is tried beside the other candidates, and, once it has won, the one of the two
    /// that fits the record better (`stribeck_exponent` in `lib.rs`), held in every model after.
    /// With 2 alone, a rise of exponent 1 was named with its constants off (its μs and vs were
    /// not scored) and a quadratic term beside it was fitted to the shape's misfit (grid #385: μ2
    /// five times the truth). Both exponents among the candidates, or δ fitted freely, made an
    /// exponential rise that mimics a quadratic velocity term (grid #63 and #183, quadratic
    /// alone, and #415 with a cubic, became *ambiguous*; measured, not kept).
    pub stribeck_delta: f64,
}

impl Spec {
    /// A base law without effects.
    pub fn base(powers: Vec<usize>) -> Spec {
        Spec {
            powers,
            effects: Vec::new(),
            apparatus: false,
            lowpass: false,
            lowpass_poles: 2,
            lowpass_digital: false,
            release: false,
            stribeck_delta: STRIBECK_DELTAS[0],
        }
    }

    /// Parameters before the effects': the law's constants, the start correction and the
    /// nuisances of the measurement chain (apparatus damping, force low-pass).
    pub fn n_lead(&self) -> usize {
        self.powers.len()
            + 1
            + usize::from(self.apparatus)
            + usize::from(self.lowpass)
            + usize::from(self.release)
    }

    /// Index of the release instant's offset `δ` in `p`, when it is a parameter.
    pub fn release_index(&self) -> Option<usize> {
        self.release.then(|| {
            self.powers.len() + 1 + usize::from(self.apparatus) + usize::from(self.lowpass)
        })
    }

    /// The release instant's offset `δ` (τ units) from the measured one in `p` (0 when it is not a
    /// parameter).
    pub fn release_delta(&self, p: &[f64]) -> f64 {
        self.release_index()
            .and_then(|i| p.get(i))
            .copied()
            .unwrap_or(0.0)
    }

    /// Index of the force low-pass time constant in `p`, when it is a parameter.
    pub fn lowpass_index(&self) -> Option<usize> {
        self.lowpass
            .then(|| self.powers.len() + 1 + usize::from(self.apparatus))
    }

    /// The force low-pass time constant `τ_f ≥ 0` (τ units) in `p`, when it is a parameter.
    pub fn lowpass_tau(&self, p: &[f64]) -> Option<f64> {
        self.lowpass_index().and_then(|i| p.get(i)).map(|v| v.abs())
    }

    /// The force `u` (sampled every `h`, τ units) through the fitted low-pass of time constant
    /// `tau_f` of this spec's order and kind ([`Spec::lowpass_poles`], [`Spec::lowpass_digital`]).
    pub fn filter_force(&self, u: &[f64], tau_f: f64, h: f64) -> Vec<f64> {
        if self.lowpass_digital && self.lowpass_poles == 2 && tau_f.abs() > 0.0 && h > 0.0 {
            // The bilinear filter takes the cut-off against the rate: `f_c / f_s = h / (2π τ_f)`.
            butterworth2(u, 1.0 / (2.0 * std::f64::consts::PI * tau_f.abs()), 1.0 / h)
        } else {
            lowpass_of_order(u, tau_f, h, self.lowpass_poles)
        }
    }

    /// Number of parameters.
    pub fn n_params(&self) -> usize {
        self.n_lead() + self.effects.iter().map(|e| e.n_params()).sum::<usize>()
    }

    /// Highest polynomial power of the law (base plus any quadratic-velocity terms).
    pub fn order(&self) -> usize {
        self.powers.iter().copied().max().unwrap_or(0) + self.count(Effect::QuadraticVelocity)
    }

    pub(super) fn count(&self, e: Effect) -> usize {
        self.effects.iter().filter(|&&x| x == e).count()
    }

    /// True if the effect is present.
    pub fn has(&self, e: Effect) -> bool {
        self.count(e) > 0
    }

    /// Whether `e` can be added (each effect once, except further polynomial terms up to order
    /// 4; Stribeck needs a law with a Coulomb term of order ≤ 2, and beside it the polynomial
    /// goes up to the quadratic term, [`FrictionLaw::Stribeck`]'s `μ2`; sensor lag needs a force
    /// channel, thermal drift a temperature).
    pub fn can_add(&self, e: Effect, has_force: bool, has_temp: bool) -> bool {
        let coulomb = self.powers.contains(&0);
        match e {
            Effect::QuadraticVelocity => {
                self.order() < if self.has(Effect::Stribeck) { 2 } else { 4 }
            }
            Effect::Stribeck => !self.has(e) && self.order() <= 2 && coulomb,
            Effect::FrictionalLag => !self.has(e),
            Effect::CubicStiffness => !self.has(e),
            Effect::ThermalDrift => !self.has(e) && has_temp && coulomb,
            Effect::SensorLag => !self.has(e) && has_force,
            Effect::RunningIn => !self.has(e) && coulomb,
            Effect::DirectionAsymmetry => !self.has(e) && has_force,
        }
    }

    /// The spec with `e` added.
    pub fn with(&self, e: Effect) -> Spec {
        let mut s = self.clone();
        s.effects.push(e);
        s
    }

    /// Offset of the first parameter of the `i`-th effect.
    pub fn offset(&self, i: usize) -> usize {
        self.n_lead()
            + self.effects[..i]
                .iter()
                .map(|e| e.n_params())
                .sum::<usize>()
    }

    /// Parameters of effect `e` (first occurrence) in `p`.
    pub fn effect_params<'a>(&self, e: Effect, p: &'a [f64]) -> Option<&'a [f64]> {
        let i = self.effects.iter().position(|&x| x == e)?;
        let o = self.offset(i);
        p.get(o..o + e.n_params())
    }

    /// `μ_j` of the polynomial part (base plus added terms), in order of `j`.
    pub fn mu(&self, p: &[f64]) -> Vec<f64> {
        let mut mu = vec![0.0; self.order() + 1];
        for (i, &j) in self.powers.iter().enumerate() {
            mu[j] = p[i];
        }
        let mut next = self.powers.iter().copied().max().unwrap_or(0);
        for (i, e) in self.effects.iter().enumerate() {
            if *e == Effect::QuadraticVelocity {
                next += 1;
                mu[next] = p[self.offset(i)];
            }
        }
        mu
    }

    /// Whether `p` is in the range the workflow explores on a record released at the amplitude
    /// `a0` (y units, [`crate::Prepared::a0`]); it keeps the integrator out of stiff or
    /// meaningless corners: Stribeck speed ≥ 0.02, memory time in [0.01, 3] rad, a cubic spring
    /// that changes the stiffness at the release amplitude by at most [`CUBIC_STIFFNESS_MAX`]
    /// (`|κ| a0² ≤ 0.25`), delay in [0, 3] rad.
    pub fn in_range(&self, p: &[f64], a0: f64) -> bool {
        if p.len() != self.n_params() || p.iter().any(|v| !v.is_finite()) {
            return false;
        }
        self.effects.iter().all(|&e| {
            let q = self.effect_params(e, p).unwrap_or(&[]);
            match e {
                Effect::Stribeck => q[0] > 0.0 && (0.02..=10.0).contains(&q[1]),
                Effect::FrictionalLag => (MEMORY_TAU_MIN..=3.0).contains(&q[0]),
                Effect::CubicStiffness => q[0].abs() * a0 * a0 <= CUBIC_STIFFNESS_MAX,
                Effect::SensorLag => (0.0..=3.0).contains(&q[0]),
                Effect::RunningIn => (RUNNING_IN_SHAPE_MIN..=RUNNING_IN_SHAPE_MAX).contains(&q[1]),
                Effect::QuadraticVelocity | Effect::ThermalDrift | Effect::DirectionAsymmetry => {
                    true
                }
            }
        }) && self.mu(p).iter().all(|m| m.abs() < 1.0)
            && self.start_scale(p).abs() < 0.1
            && (-0.01..=0.1).contains(&self.apparatus_mu1(p))
            && self.lowpass_tau(p).is_none_or(|t| t <= LOWPASS_TAU_MAX)
            && self.release_delta(p).abs() <= RELEASE_DELTA_MAX
    }

    /// The initial amplitude's relative correction `s` in `p`.
    pub fn start_scale(&self, p: &[f64]) -> f64 {
        p.get(self.powers.len()).copied().unwrap_or(0.0)
    }

    /// The apparatus damping `μ_a` in `p` (0 when not a parameter).
    pub fn apparatus_mu1(&self, p: &[f64]) -> f64 {
        if self.apparatus {
            p.get(self.powers.len() + 1).copied().unwrap_or(0.0)
        } else {
            0.0
        }
    }

    /// `p` of the law's constants followed by a zero initial correction and apparatus damping (a
    /// start for a fit).
    pub fn start(&self, law_params: &[f64]) -> Vec<f64> {
        self.start_with(law_params, 0.0)
    }

    /// [`Spec::start`] with the force low-pass time constant `tau_f` (when it is a parameter).
    pub fn start_with(&self, law_params: &[f64], tau_f: f64) -> Vec<f64> {
        let mut p = law_params.to_vec();
        p.push(0.0);
        if self.apparatus {
            p.push(0.0);
        }
        if self.lowpass {
            p.push(tau_f);
        }
        if self.release {
            p.push(0.0);
        }
        p
    }

    /// Typical magnitude of every parameter (finite-difference steps near 0: a thousandth of it)
    /// for the fits. The release instant's offset is 0.01 rad (its step 1e-5 rad, 4e-4 of a sample
    /// at 6.9 kS/s): what the subsets were measured with; its standard error takes a step of a
    /// tenth of a sample ([`Spec::se_scales`]).
    pub fn scales(&self) -> Vec<f64> {
        self.scales_with(0.01)
    }

    /// [`Spec::scales`] for the standard errors, on a record sampled every `dtau` (τ units): the
    /// release instant's offset a hundred samples, its step a tenth of a sample. The force a model
    /// gives at a sample instant jumps when a reversal crosses it, so the misfit is a staircase in
    /// the instant at the scale of a sample, and a step of 1e-5 rad saw none of those jumps or one:
    /// its ± was a lottery (CI-grid #4: ± 0.001 sample for an error of 0.04, where the motion's
    /// own measurement says ± 0.05; #10 ± 5e-4 µs).
    pub fn se_scales(&self, dtau: f64) -> Vec<f64> {
        self.scales_with(100.0 * dtau)
    }

    fn scales_with(&self, release: f64) -> Vec<f64> {
        let mut s = vec![1e-3; self.powers.len() + 1 + usize::from(self.apparatus)];
        if self.lowpass {
            s.push(0.01);
        }
        if self.release {
            s.push(release);
        }
        for e in &self.effects {
            s.extend_from_slice(match e {
                Effect::QuadraticVelocity => &[1e-3][..],
                Effect::Stribeck => &[1e-3, 0.03][..],
                Effect::FrictionalLag => &[0.1][..],
                Effect::CubicStiffness => &[1e-4][..],
                Effect::ThermalDrift => &[3e-4][..],
                Effect::SensorLag => &[0.01][..],
                Effect::RunningIn => &[1e-2, 0.3][..],
                Effect::DirectionAsymmetry => &[1e-3][..],
            });
        }
        s
    }

    /// Names of every parameter (dimensionless), in vector order.
    pub fn param_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.powers.iter().map(|j| format!("mu{j}")).collect();
        names.push("start_scale".into());
        if self.apparatus {
            names.push("apparatus_mu1".into());
        }
        if self.lowpass {
            names.push("force_lowpass_tau".into());
        }
        if self.release {
            names.push("release_shift_delta".into());
        }
        let mut next = self.powers.iter().copied().max().unwrap_or(0);
        for e in &self.effects {
            if *e == Effect::QuadraticVelocity {
                next += 1;
                names.push(format!("mu{next}"));
            } else {
                names.extend(e.param_names().iter().map(|s| s.to_string()));
            }
        }
        names
    }

    /// The friction law with the Coulomb level shifted by `dmu0` (thermal drift).
    pub fn law(&self, p: &[f64], dmu0: f64) -> FrictionLaw {
        let mut mu = self.mu(p);
        if let Some(m0) = mu.first_mut() {
            *m0 += dmu0;
        }
        let mu0 = mu.first().copied().unwrap_or(0.0);
        let mu1 = mu.get(1).copied().unwrap_or(0.0);
        let steady = match self.effect_params(Effect::Stribeck, p) {
            Some(s) => FrictionLaw::Stribeck {
                mu_c: mu0,
                mu_s: s[0] + dmu0,
                v_s: s[1],
                delta: self.stribeck_delta,
                mu_v: mu1,
                mu2: mu.get(2).copied().unwrap_or(0.0),
            },
            None => FrictionLaw::Polynomial { mu },
        };
        match self.effect_params(Effect::FrictionalLag, p) {
            Some(m) => FrictionLaw::Lagged {
                steady: Box::new(steady),
                memory: m[0],
            },
            None => steady,
        }
    }
}

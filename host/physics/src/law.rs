//! Friction laws, in the dimensionless form of the thesis (seed eq. 10–13).
//!
//! Every law is a value of [`FrictionLaw`]. It gives the dimensionless friction force
//! `f = F / N` as a function of the dimensionless velocity `y' = dy/dτ` (with `y = k x / N`,
//! `τ = Ω t`) and, for the laws with memory (Dahl, LuGre, modified LuGre), of an internal state `z`
//! (the dimensionless bristle deflection `k z_SI / N`).
//!
//! Laws with a `sgn(y')` term are discontinuous at `y' = 0`; the integrators evaluate them on a
//! *branch* (`dir = ±1`, the sign of the current sliding direction) and locate velocity zero
//! crossings as events, so the discontinuity is never integrated across.

use crate::invalid::InvalidParameter;
use serde::{Deserialize, Serialize};
use std::fmt;

mod form;

/// A friction law (dimensionless). Construct with the helpers ([`FrictionLaw::coulomb`], …) or the
/// variants directly; read from and written to configuration files with serde (a table with a
/// `kind` and the constants: `{ kind = "coulomb_viscous", mu0 = 0.02, mu1 = 0.004 }`), validated as
/// it is read; shown to people by
/// [`Display`](fmt::Display) (`coulomb-viscous (mu0 = 0.02, mu1 = 0.004)`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "form::Form", into = "form::Form")]
pub enum FrictionLaw {
    /// Pseudo-polynomial law of any order (eq. 12–13):
    /// `f = Σ_even μ_j |y'|^j sgn(y') + Σ_odd μ_j y'^j`, `mu[j] = μ_j`.
    /// Coulomb = `[μ0]`, viscous = `[0, μ1]`, Coulomb–viscous = `[μ0, μ1]`, quadratic = `[μ0, μ1, μ2]`.
    Polynomial {
        /// `μ_j` in order of `j`.
        mu: Vec<f64>,
    },
    /// Exponential Stribeck curve (Armstrong-Hélouvry / Olsson form, the `g(v)` of LuGre eq. 17):
    /// `f = sgn(y') [μ_c + (μ_s − μ_c) exp(−(|y'|/v_s)^δ)] + μ_v y' + μ2 y'² sgn(y')`, with the
    /// pseudo-polynomial law's quadratic term `μ2` (eq. 12–13; 0 for the plain curve) for a
    /// contact whose friction rises at low speed and also follows the speed's square above it.
    ///
    /// This is *not* the thesis's ch. 1 eq. 9 (a rational blend of two power laws: see
    /// [`FrictionLaw::StribeckPower`]). The two share the limits (`f(0+)` = static/boundary
    /// level, Coulomb + viscous or EHL power law at high speed) but not the mixed-regime shape,
    /// and neither reduces to the other.
    Stribeck {
        /// Coulomb (dynamic) level.
        mu_c: f64,
        /// Static (breakaway) level.
        mu_s: f64,
        /// Stribeck velocity (dimensionless, > 0).
        v_s: f64,
        /// Shape exponent δ (> 0, usually 1 or 2).
        delta: f64,
        /// Viscous coefficient.
        mu_v: f64,
        /// Quadratic coefficient (`μ2 y'² sgn(y')`, the pseudo-polynomial law's second term).
        mu2: f64,
    },
    /// The thesis's Stribeck law, ch. 1 eq. 7–9, with `y'` standing for `η ẋ` (η, K, h, B lumped
    /// into the dimensionless constants):
    /// `μ_EHL = K |y'|^n` (eq. 7), `μ_BL = h |y'|^p` (eq. 8),
    /// `f = sgn(y') [μ_EHL + (μ_BL − μ_EHL) / (1 + (|y'|/B)^M)]` (eq. 9).
    ///
    /// The thesis prints the numerator of eq. 9 as `μ_BL + μ_EHL`; that contradicts its own
    /// definition of B ("the value of η ẋ below which the boundary regime starts"): with a
    /// constant EHL level (n = 0) the printed form would give `μ_BL + 2K`, not `μ_BL`, below B.
    /// The form used here is the weighted blend `(1 − w) μ_EHL + w μ_BL`, `w = 1/(1 + (|y'|/B)^M)`,
    /// which gives μ_BL below B, μ_EHL above it and their mean at `|y'| = B`. (For n > 0 both
    /// forms have the same two limits.)
    StribeckPower {
        /// EHL power-law coefficient K (eq. 7).
        k_ehl: f64,
        /// EHL power-law index n (≥ 0).
        n_ehl: f64,
        /// Boundary power-law coefficient h (eq. 8).
        h_bl: f64,
        /// Boundary power-law index p (≥ 0; 0 = constant boundary friction, the usual case).
        p_bl: f64,
        /// Velocity B where the boundary regime starts (> 0).
        b: f64,
        /// Mixed-regime exponent M (> 0).
        m: f64,
    },
    /// Hess–Soom (ch. 1 eq. 10), Stribeck parameters lumped into dimensionless `c1`, `c2`:
    /// `f = sgn(y') μ_b / (1 + c1 y'^2) + c2 y'`.
    HessSoom {
        /// Boundary friction coefficient.
        mu_b: f64,
        /// Mixed-regime constant (≥ 0).
        c1: f64,
        /// Hydrodynamic (viscous) constant.
        c2: f64,
    },
    /// Dahl (ch. 1 eq. 11–15): `f = σ z`, `dz/dτ = y' (1 − σ z sgn(y') / μ_c)^α`
    /// (for α = 1: `dz/dτ = y' − σ |y'| z / μ_c`).
    Dahl {
        /// Dimensionless stiffness `σ_SI / k`.
        sigma: f64,
        /// Coulomb level (> 0).
        mu_c: f64,
        /// Shape exponent α (≥ 1 recommended; 1 = the usual choice).
        alpha: f64,
    },
    /// LuGre (ch. 1 eq. 16–18, ch. 4 eq. 12–16).
    LuGre(LuGre),
    /// Modified LuGre of Lu et al. (ch. 1 eq. 20–23).
    ModifiedLuGre(ModifiedLuGre),
    /// Friction with a memory time (a first-order lag, the "few-ms memory" of the force behind the
    /// velocity, ch. 4.4): the force `f = z` relaxes towards a memoryless law with time constant
    /// `memory` (dimensionless τ; in seconds `memory / Ω`): `dz/dτ = (f_steady(y') − z) / memory`.
    /// At the release `z = 0`: the friction builds up as the pin starts to slide.
    Lagged {
        /// The steady (memoryless) law.
        steady: Box<FrictionLaw>,
        /// Memory time (τ units, > 0).
        memory: f64,
    },
}

/// LuGre parameters, dimensionless: `f = σ0 z + σ1 dz/dτ + σ2 y'`,
/// `dz/dτ = y' − σ0 |y'| z / g(y')`, `g(v) = μ_c + (μ_s − μ_c) exp(−(|v|/v_s)^a)`.
///
/// From SI (`σ0` N/m, `σ1`, `σ2` N s/m, forces `F_c`, `F_s` N, `v_s` m/s), use
/// [`LuGre::from_si`]. (The thesis writes `dz/dt = v − |v| z / g` with `σ0 = 1 N/m`; this is the
/// standard form, identical when `σ0 = 1`.)
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LuGre {
    /// Bristle stiffness `σ0_SI / k`.
    pub sigma0: f64,
    /// Bristle damping `σ1_SI Ω / k`.
    pub sigma1: f64,
    /// Viscous term `σ2_SI Ω / k`.
    pub sigma2: f64,
    /// Coulomb level `F_c / N`.
    pub mu_c: f64,
    /// Static level `F_s / N`.
    pub mu_s: f64,
    /// Stribeck velocity, dimensionless `v_s k / (N Ω)`.
    pub v_s: f64,
    /// Stribeck exponent.
    pub a: f64,
}

/// Modified LuGre (Lu et al., ch. 1 eq. 20–23), dimensionless:
/// `f = σ0 s z + σ1 dz/dτ + μ_c sgn(y') (1 − s) + σ2 y'`, `dz/dτ = s (y' − σ0 |y'| z / g(y'))`,
/// `g(v) = α0 + α1 exp(−(v/v_s)^2)`, where `s(|v|)` goes from 1 (|v| ≤ l1) to 0 (|v| ≥ l2) by a
/// smooth cubic step.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ModifiedLuGre {
    /// Bristle stiffness.
    pub sigma0: f64,
    /// Bristle damping.
    pub sigma1: f64,
    /// Viscous term.
    pub sigma2: f64,
    /// High-speed Coulomb level.
    pub mu_c: f64,
    /// `g` constant part.
    pub alpha0: f64,
    /// `g` Stribeck part.
    pub alpha1: f64,
    /// Stribeck velocity.
    pub v_s: f64,
    /// Lower cut-off velocity (s = 1 below).
    pub l1: f64,
    /// Upper cut-off velocity (s = 0 above), `l2 > l1`.
    pub l2: f64,
}

impl LuGre {
    /// Converts SI LuGre parameters (thesis ch. 4) into dimensionless ones for a rig.
    #[allow(clippy::too_many_arguments)]
    pub fn from_si(
        rig: &crate::rig::Rig,
        sigma0_n_per_m: f64,
        sigma1_n_s_per_m: f64,
        sigma2_n_s_per_m: f64,
        fc_n: f64,
        fs_n: f64,
        vs_m_s: f64,
        a: f64,
    ) -> LuGre {
        let k = rig.stiffness_n_per_m;
        let om = rig.omega();
        LuGre {
            sigma0: sigma0_n_per_m / k,
            sigma1: sigma1_n_s_per_m * om / k,
            sigma2: sigma2_n_s_per_m * om / k,
            mu_c: fc_n / rig.load_n,
            mu_s: fs_n / rig.load_n,
            v_s: rig.ydot_of_v(vs_m_s),
            a,
        }
    }

    fn g(&self, v: f64) -> f64 {
        self.mu_c + (self.mu_s - self.mu_c) * (-(v.abs() / self.v_s).powf(self.a)).exp()
    }
}

impl ModifiedLuGre {
    fn s(&self, v: f64) -> f64 {
        let a = v.abs();
        if a <= self.l1 {
            1.0
        } else if a >= self.l2 {
            0.0
        } else {
            let u = (a - self.l1) / (self.l2 - self.l1);
            1.0 - u * u * (3.0 - 2.0 * u)
        }
    }
    fn g(&self, v: f64) -> f64 {
        self.alpha0 + self.alpha1 * (-(v / self.v_s).powi(2)).exp()
    }
}

/// The law's name (as `--law` and [`FrictionLaw::name`] write it) and its constants, as a
/// configuration file names them:
/// `coulomb-viscous (mu0 = 0.02, mu1 = 0.004)`, `lagged (memory = 0.5) of coulomb (mu0 = 0.02)`.
impl fmt::Display for FrictionLaw {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let named = |f: &mut fmt::Formatter<'_>, kv: &[(&str, f64)]| {
            write!(f, "{} (", self.name())?;
            for (i, (k, v)) in kv.iter().enumerate() {
                write!(f, "{}{k} = {v}", if i > 0 { ", " } else { "" })?;
            }
            f.write_str(")")
        };
        match self {
            FrictionLaw::Polynomial { mu } => match mu[..] {
                [mu0] => named(f, &[("mu0", mu0)]),
                [0.0, mu1] => named(f, &[("mu1", mu1)]),
                [mu0, mu1] => named(f, &[("mu0", mu0), ("mu1", mu1)]),
                [mu0, mu1, mu2] => named(f, &[("mu0", mu0), ("mu1", mu1), ("mu2", mu2)]),
                _ => write!(f, "{} (mu = {mu:?})", self.name()),
            },
            FrictionLaw::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            } => {
                let kv = [
                    ("mu_c", *mu_c),
                    ("mu_s", *mu_s),
                    ("v_s", *v_s),
                    ("delta", *delta),
                    ("mu_v", *mu_v),
                    ("mu2", *mu2),
                ];
                // The quadratic term only where there is one: the plain curve reads as before.
                named(f, &kv[..if *mu2 != 0.0 { 6 } else { 5 }])
            }
            FrictionLaw::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            } => named(
                f,
                &[
                    ("k_ehl", *k_ehl),
                    ("n_ehl", *n_ehl),
                    ("h_bl", *h_bl),
                    ("p_bl", *p_bl),
                    ("b", *b),
                    ("m", *m),
                ],
            ),
            FrictionLaw::HessSoom { mu_b, c1, c2 } => {
                named(f, &[("mu_b", *mu_b), ("c1", *c1), ("c2", *c2)])
            }
            FrictionLaw::Dahl { sigma, mu_c, alpha } => {
                named(f, &[("sigma", *sigma), ("mu_c", *mu_c), ("alpha", *alpha)])
            }
            FrictionLaw::LuGre(p) => named(
                f,
                &[
                    ("sigma0", p.sigma0),
                    ("sigma1", p.sigma1),
                    ("sigma2", p.sigma2),
                    ("mu_c", p.mu_c),
                    ("mu_s", p.mu_s),
                    ("v_s", p.v_s),
                    ("a", p.a),
                ],
            ),
            FrictionLaw::ModifiedLuGre(p) => named(
                f,
                &[
                    ("sigma0", p.sigma0),
                    ("sigma1", p.sigma1),
                    ("sigma2", p.sigma2),
                    ("mu_c", p.mu_c),
                    ("alpha0", p.alpha0),
                    ("alpha1", p.alpha1),
                    ("v_s", p.v_s),
                    ("l1", p.l1),
                    ("l2", p.l2),
                ],
            ),
            FrictionLaw::Lagged { steady, memory } => {
                named(f, &[("memory", *memory)])?;
                write!(f, " of {steady}")
            }
        }
    }
}

/// Sign used on a branch: the branch direction `dir` if it is non-zero (so that the law stays
/// smooth while an integrator stage overshoots the reversal), else `sgn(v)`.
#[inline]
pub(crate) fn sgn_on(v: f64, dir: f64) -> f64 {
    if dir != 0.0 {
        dir.signum()
    } else if v > 0.0 {
        1.0
    } else if v < 0.0 {
        -1.0
    } else {
        dir
    }
}

impl FrictionLaw {
    /// Coulomb law `f = μ0 sgn(y')`.
    pub fn coulomb(mu0: f64) -> Self {
        FrictionLaw::Polynomial { mu: vec![mu0] }
    }
    /// Viscous law `f = μ1 y'`.
    pub fn viscous(mu1: f64) -> Self {
        FrictionLaw::Polynomial { mu: vec![0.0, mu1] }
    }
    /// Coulomb–viscous law `f = μ0 sgn(y') + μ1 y'`.
    pub fn coulomb_viscous(mu0: f64, mu1: f64) -> Self {
        FrictionLaw::Polynomial { mu: vec![mu0, mu1] }
    }
    /// Quadratic law `f = (μ0 + μ2 y'^2) sgn(y') + μ1 y'` (eq. 39).
    pub fn quadratic(mu0: f64, mu1: f64, mu2: f64) -> Self {
        FrictionLaw::Polynomial {
            mu: vec![mu0, mu1, mu2],
        }
    }
    /// Pseudo-polynomial law with `mu[j] = μ_j`.
    pub fn polynomial(mu: Vec<f64>) -> Self {
        FrictionLaw::Polynomial { mu }
    }

    /// Short name (`coulomb`, `viscous`, `coulomb-viscous`, `quadratic`, `poly:N`, `stribeck`, …).
    pub fn name(&self) -> String {
        match self {
            FrictionLaw::Polynomial { mu } => match mu.len() {
                0 => "none".into(),
                1 => "coulomb".into(),
                2 if mu[0] == 0.0 => "viscous".into(),
                2 => "coulomb-viscous".into(),
                3 => "quadratic".into(),
                n => format!("poly:{}", n - 1),
            },
            FrictionLaw::Stribeck { .. } => "stribeck".into(),
            FrictionLaw::StribeckPower { .. } => "stribeck-power".into(),
            FrictionLaw::HessSoom { .. } => "hess-soom".into(),
            FrictionLaw::Dahl { .. } => "dahl".into(),
            FrictionLaw::LuGre(_) => "lugre".into(),
            FrictionLaw::ModifiedLuGre(_) => "modified-lugre".into(),
            FrictionLaw::Lagged { .. } => "lagged".into(),
        }
    }

    /// True if the law has an internal state `z` (Dahl, LuGre, modified LuGre, lagged).
    pub fn has_state(&self) -> bool {
        matches!(
            self,
            FrictionLaw::Dahl { .. }
                | FrictionLaw::LuGre(_)
                | FrictionLaw::ModifiedLuGre(_)
                | FrictionLaw::Lagged { .. }
        )
    }

    /// True if the law jumps at `y' = 0` (a `sgn(y')` term): integrators then treat velocity
    /// reversals as events and apply the stick rule there.
    pub fn is_discontinuous(&self) -> bool {
        match self {
            FrictionLaw::Polynomial { mu } => mu.iter().step_by(2).any(|&m| m != 0.0),
            FrictionLaw::Stribeck { mu_c, mu_s, .. } => *mu_c != 0.0 || *mu_s != 0.0,
            FrictionLaw::StribeckPower { .. } => self.static_level().is_some_and(|l| l != 0.0),
            FrictionLaw::HessSoom { mu_b, .. } => *mu_b != 0.0,
            FrictionLaw::ModifiedLuGre(p) => p.mu_c != 0.0,
            FrictionLaw::Dahl { .. } | FrictionLaw::LuGre(_) => false,
            // The force is continuous, but its rate jumps with the steady law's sgn(y').
            FrictionLaw::Lagged { steady, .. } => steady.is_discontinuous(),
        }
    }

    /// Breakaway (static) level `f(0+)` of a memoryless law: the largest spring force the contact
    /// holds at rest (eq. 14). `None` for laws with memory (their presliding does the job).
    pub fn static_level(&self) -> Option<f64> {
        match self {
            FrictionLaw::Polynomial { mu } => Some(mu.first().copied().unwrap_or(0.0)),
            FrictionLaw::Stribeck { mu_s, .. } => Some(*mu_s),
            FrictionLaw::StribeckPower { h_bl, p_bl, .. } => {
                // f(0+) = μ_BL(0+): h if p = 0, else 0 (the EHL part is weighted out at v → 0).
                Some(if *p_bl == 0.0 { *h_bl } else { 0.0 })
            }
            FrictionLaw::HessSoom { mu_b, .. } => Some(*mu_b),
            _ => None,
        }
    }

    /// Rate of the internal state, `dz/dτ` (0 for memoryless laws).
    pub fn dz(&self, v: f64, z: f64) -> f64 {
        self.dz_on(v, z, 0.0)
    }

    /// [`FrictionLaw::dz`] on the branch `dir` (see [`FrictionLaw::force`]).
    pub fn dz_on(&self, v: f64, z: f64, dir: f64) -> f64 {
        match self {
            FrictionLaw::Lagged { steady, memory } => (steady.force(v, 0.0, dir) - z) / memory,
            FrictionLaw::Dahl { sigma, mu_c, alpha } => {
                let s = sgn_on(v, 0.0);
                let base = (1.0 - sigma * z * s / mu_c).max(0.0);
                if *alpha == 1.0 {
                    v * base
                } else {
                    v * base.powf(*alpha)
                }
            }
            FrictionLaw::LuGre(p) => v - p.sigma0 * v.abs() * z / p.g(v),
            FrictionLaw::ModifiedLuGre(p) => p.s(v) * (v - p.sigma0 * v.abs() * z / p.g(v)),
            _ => 0.0,
        }
    }

    /// Dimensionless friction force `f(y', z)` on the branch `dir`: `dir = ±1` is the sliding
    /// direction that every `sgn(y')` takes (integrators stop at the reversal, so it equals
    /// `sgn(y')` on the solution); `dir = 0` uses `sgn(y')` itself.
    pub fn force(&self, v: f64, z: f64, dir: f64) -> f64 {
        match self {
            FrictionLaw::Polynomial { mu } => {
                // |v|^j = v^j for even j, so on a branch the law is a smooth polynomial.
                let s = sgn_on(v, dir);
                let (mut even, mut odd) = (0.0, 0.0);
                let mut p = 1.0; // v^j
                for (j, &m) in mu.iter().enumerate() {
                    if j % 2 == 0 {
                        even += m * p;
                    } else {
                        odd += m * p;
                    }
                    p *= v;
                }
                s * even + odd
            }
            FrictionLaw::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            } => {
                let s = sgn_on(v, dir);
                s * (mu_c + (mu_s - mu_c) * (-(v.abs() / v_s).powf(*delta)).exp() + mu2 * v * v)
                    + mu_v * v
            }
            FrictionLaw::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            } => {
                let a = v.abs();
                let pw = |c: f64, e: f64| if e == 0.0 { c } else { c * a.powf(e) };
                let (ehl, bl) = (pw(*k_ehl, *n_ehl), pw(*h_bl, *p_bl));
                let w = 1.0 / (1.0 + (a / b).powf(*m));
                sgn_on(v, dir) * (ehl + (bl - ehl) * w)
            }
            FrictionLaw::HessSoom { mu_b, c1, c2 } => {
                sgn_on(v, dir) * mu_b / (1.0 + c1 * v * v) + c2 * v
            }
            FrictionLaw::Dahl { sigma, .. } => sigma * z,
            FrictionLaw::Lagged { .. } => z,
            FrictionLaw::LuGre(p) => p.sigma0 * z + p.sigma1 * self.dz(v, z) + p.sigma2 * v,
            FrictionLaw::ModifiedLuGre(p) => {
                let s = p.s(v);
                p.sigma0 * s * z
                    + p.sigma1 * self.dz(v, z)
                    + p.mu_c * sgn_on(v, dir) * (1.0 - s)
                    + p.sigma2 * v
            }
        }
    }

    /// Steady-state (constant-velocity) force, i.e. the Stribeck curve of the law: for memoryless
    /// laws `f(v)`, for Dahl/LuGre the force once `z` has settled.
    pub fn steady_force(&self, v: f64) -> f64 {
        match self {
            FrictionLaw::Dahl { mu_c, .. } => mu_c * sgn_on(v, 0.0),
            FrictionLaw::Lagged { steady, .. } => steady.steady_force(v),
            FrictionLaw::LuGre(p) => p.g(v) * sgn_on(v, 0.0) + p.sigma2 * v,
            FrictionLaw::ModifiedLuGre(p) => {
                let s = p.s(v);
                (s * p.g(v) + p.mu_c * (1.0 - s)) * sgn_on(v, 0.0) + p.sigma2 * v
            }
            _ => self.force(v, 0.0, 0.0),
        }
    }

    /// Polynomial constants `μ_j` if the law is pseudo-polynomial.
    pub fn mu(&self) -> Option<&[f64]> {
        match self {
            FrictionLaw::Polynomial { mu } => Some(mu),
            _ => None,
        }
    }

    /// `(μ0, μ1)` if the law is Coulomb–viscous or one of its halves (a pseudo-polynomial of
    /// order ≤ 1), the law an envelope fit of the rig finds exactly.
    pub fn as_coulomb_viscous(&self) -> Option<(f64, f64)> {
        match self.mu()? {
            [] => Some((0.0, 0.0)),
            [mu0] => Some((*mu0, 0.0)),
            [mu0, mu1] => Some((*mu0, *mu1)),
            _ => None,
        }
    }

    /// Checks the parameters are finite and in range; a clear message otherwise.
    pub fn validate(&self) -> Result<(), InvalidParameter> {
        let bad = |rule: &'static str| {
            Err(InvalidParameter::Law {
                law: self.name(),
                rule,
            })
        };
        let fin = |xs: &[f64]| xs.iter().all(|x| x.is_finite());
        match self {
            FrictionLaw::Polynomial { mu } => {
                if !fin(mu) {
                    return bad("non-finite constant");
                }
            }
            FrictionLaw::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            } => {
                if !fin(&[*mu_c, *mu_s, *v_s, *delta, *mu_v, *mu2]) || *v_s <= 0.0 || *delta <= 0.0
                {
                    return bad("need finite constants, v_s > 0 and delta > 0");
                }
            }
            FrictionLaw::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            } => {
                if !fin(&[*k_ehl, *n_ehl, *h_bl, *p_bl, *b, *m])
                    || *n_ehl < 0.0
                    || *p_bl < 0.0
                    || *b <= 0.0
                    || *m <= 0.0
                {
                    return bad("need finite constants, n >= 0, p >= 0, B > 0 and M > 0");
                }
            }
            FrictionLaw::HessSoom { mu_b, c1, c2 } => {
                if !fin(&[*mu_b, *c1, *c2]) || *c1 < 0.0 {
                    return bad("need finite constants and c1 >= 0");
                }
            }
            FrictionLaw::Dahl { sigma, mu_c, alpha } => {
                if !fin(&[*sigma, *mu_c, *alpha]) || *sigma <= 0.0 || *mu_c <= 0.0 || *alpha <= 0.0
                {
                    return bad("need sigma > 0, mu_c > 0, alpha > 0");
                }
            }
            FrictionLaw::LuGre(p) => {
                if !fin(&[p.sigma0, p.sigma1, p.sigma2, p.mu_c, p.mu_s, p.v_s, p.a])
                    || p.sigma0 <= 0.0
                    || p.mu_c <= 0.0
                    || p.mu_s <= 0.0
                    || p.v_s <= 0.0
                {
                    return bad("need sigma0, mu_c, mu_s, v_s > 0");
                }
            }
            FrictionLaw::ModifiedLuGre(p) => {
                if !fin(&[
                    p.sigma0, p.sigma1, p.sigma2, p.mu_c, p.alpha0, p.alpha1, p.v_s, p.l1, p.l2,
                ]) || p.sigma0 <= 0.0
                    || p.alpha0 <= 0.0
                    || p.v_s <= 0.0
                    || p.l2 <= p.l1
                {
                    return bad("need sigma0, alpha0, v_s > 0 and l2 > l1");
                }
            }
            FrictionLaw::Lagged { steady, memory } => {
                if !(memory.is_finite() && *memory > 0.0) {
                    return bad("need a memory time > 0");
                }
                if steady.has_state() {
                    return bad("the steady law must be memoryless");
                }
                steady.validate()?;
            }
        }
        Ok(())
    }
}

/// Averaging coefficients `a_n` of `dA/dτ = Σ a_n A^n` for a pseudo-polynomial law (eq. 27–28):
/// `a_{2k} = −(2/π) μ_{2k} Π_{j=1..k} 2j/(2j+1)`, `a_{2k+1} = −μ_{2k+1} Π_{j=1..k+1} (2j−1)/(2j)`.
pub fn averaging_coefficients(mu: &[f64]) -> Vec<f64> {
    mu.iter()
        .enumerate()
        .map(|(n, &m)| -m * averaging_factor(n))
        .collect()
}

/// The factor `c_n > 0` with `a_n = −c_n μ_n`.
pub fn averaging_factor(n: usize) -> f64 {
    if n & 1 == 0 {
        let k = n / 2;
        (1..=k).fold(2.0 / std::f64::consts::PI, |acc, j| {
            acc * (2 * j) as f64 / (2 * j + 1) as f64
        })
    } else {
        let k = (n - 1) / 2;
        (1..=k + 1).fold(1.0, |acc, j| acc * (2 * j - 1) as f64 / (2 * j) as f64)
    }
}

/// Inverse of [`averaging_coefficients`]: `μ_n = −a_n / c_n`.
pub fn mu_from_averaging(a: &[f64]) -> Vec<f64> {
    a.iter()
        .enumerate()
        .map(|(n, &an)| -an / averaging_factor(n))
        .collect()
}

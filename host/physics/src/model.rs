//! The rig as a single-degree-of-freedom oscillator (thesis ch. 2.2.1.1, seed eq. 6–13).
//!
//! SI: `m x'' + c x' + k x + k3 x³ = −N μ(x', …)`.
//! Dimensionless (`Ω = √(k/m)`, `τ = Ω t`, `y = k x / N`):
//! `y'' + μ_a y' + y + κ y³ = −f(y', z)` with `μ_a = c / (m Ω)` the apparatus damping and
//! `κ = k3 N² / k³` the cubic-spring term.

use crate::invalid::InvalidParameter;
use crate::law::FrictionLaw;
// The rig constants live in their own module (the law converts SI parameters with them); they
// stay reachable here, where they always were.
pub use crate::rig::Rig;

/// The oscillator model (dimensionless): friction law plus apparatus damping, cubic spring and
/// stick rule.
#[derive(Debug, Clone, PartialEq)]
pub struct Model {
    /// The contact friction law.
    pub law: FrictionLaw,
    /// Apparatus viscous damping μ_a (dimensionless, = 2ζ; the real rig: ≈ 0.0011).
    pub apparatus_mu1: f64,
    /// Cubic spring term κ in `y + κ y³`.
    pub cubic: f64,
    /// Static level μ_s of the stick rule (eq. 5, 14): at a velocity reversal the pin stays at
    /// rest if `|y + κ y³| ≤ μ_s`. `None` = the law's breakaway level
    /// ([`FrictionLaw::static_level`]); ignored for laws with memory.
    pub static_mu: Option<f64>,
}

impl Model {
    /// A model with only the contact law (no apparatus damping, linear spring, default stick rule).
    pub fn new(law: FrictionLaw) -> Model {
        Model {
            law,
            apparatus_mu1: 0.0,
            cubic: 0.0,
            static_mu: None,
        }
    }
    /// Adds apparatus damping.
    pub fn with_apparatus_damping(mut self, mu_a: f64) -> Model {
        self.apparatus_mu1 = mu_a;
        self
    }
    /// Adds a cubic spring term.
    pub fn with_cubic(mut self, kappa: f64) -> Model {
        self.cubic = kappa;
        self
    }
    /// Sets the static friction level of the stick rule.
    pub fn with_static_mu(mut self, mu_s: f64) -> Model {
        self.static_mu = Some(mu_s);
        self
    }

    /// Validates the law and constants.
    pub fn validate(&self) -> Result<(), InvalidParameter> {
        self.law.validate()?;
        if !self.apparatus_mu1.is_finite() || !self.cubic.is_finite() {
            return Err(InvalidParameter::ModelTerms);
        }
        if let Some(s) = self.static_mu {
            if !s.is_finite() || s < 0.0 {
                return Err(InvalidParameter::StaticLevel(s));
            }
        }
        Ok(())
    }

    /// The stick threshold used at velocity reversals, or `None` if the law never sticks.
    pub fn stick_level(&self) -> Option<f64> {
        if self.law.has_state() {
            None
        } else {
            self.static_mu.or_else(|| self.law.static_level())
        }
    }

    /// Restoring force `y + κ y³`.
    #[inline]
    pub fn spring(&self, y: f64) -> f64 {
        y + self.cubic * y * y * y
    }

    /// Right-hand side on branch `dir`: d/dτ of `[y, y', z]`.
    #[inline]
    pub fn rhs(&self, s: &[f64; 3], dir: f64) -> [f64; 3] {
        let (y, v, z) = (s[0], s[1], s[2]);
        let f = self.law.force(v, z, dir);
        [
            v,
            -self.spring(y) - self.apparatus_mu1 * v - f,
            self.law.dz_on(v, z, dir),
        ]
    }

    /// Total energy `y²/2 + κ y⁴/4 + y'²/2` (dimensionless, in units of N²/k).
    pub fn energy(&self, y: f64, ydot: f64) -> f64 {
        0.5 * y * y + 0.25 * self.cubic * y.powi(4) + 0.5 * ydot * ydot
    }
}

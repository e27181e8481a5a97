//! The rig as a single-degree-of-freedom oscillator (thesis ch. 2.2.1.1, seed eq. 6–13).
//!
//! SI: `m x'' + c x' + k x + k3 x³ = −N μ(x', …)`.
//! Dimensionless (`Ω = √(k/m)`, `τ = Ω t`, `y = k x / N`):
//! `y'' + μ_a y' + y + κ y³ = −f(y', z)` with `μ_a = c / (m Ω)` the apparatus damping and
//! `κ = k3 N² / k³` the cubic-spring term.

use crate::law::FrictionLaw;

/// Physical constants of the rig. `Rig::UNIT` (all ones) makes SI and dimensionless coincide.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Rig {
    /// Moving mass m (kg).
    pub mass_kg: f64,
    /// Blade stiffness k (N/m).
    pub stiffness_n_per_m: f64,
    /// Normal load N (N).
    pub load_n: f64,
}

impl Default for Rig {
    /// The real rig: m = 0.04 kg, k = 1150 N/m, N = 0.3 N.
    fn default() -> Self {
        Rig::REAL
    }
}

impl Rig {
    /// The real rig (chapter 2.2), with a mid-range load of 0.3 N.
    pub const REAL: Rig = Rig {
        mass_kg: 0.04,
        stiffness_n_per_m: 1150.0,
        load_n: 0.3,
    };
    /// m = k = N = 1: SI quantities equal dimensionless ones (used for `tau,y,ydot` records).
    pub const UNIT: Rig = Rig {
        mass_kg: 1.0,
        stiffness_n_per_m: 1.0,
        load_n: 1.0,
    };

    /// Builds a rig, rejecting non-finite or non-positive constants.
    pub fn new(mass_kg: f64, stiffness_n_per_m: f64, load_n: f64) -> Result<Rig, String> {
        let r = Rig {
            mass_kg,
            stiffness_n_per_m,
            load_n,
        };
        r.validate()?;
        Ok(r)
    }

    /// Checks every constant is finite and > 0.
    pub fn validate(&self) -> Result<(), String> {
        for (name, v) in [
            ("mass_kg", self.mass_kg),
            ("stiffness_n_per_m", self.stiffness_n_per_m),
            ("load_n", self.load_n),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(format!(
                    "rig constant {name} must be finite and > 0, got {v}"
                ));
            }
        }
        Ok(())
    }

    /// Natural angular frequency Ω = √(k/m) (rad/s).
    pub fn omega(&self) -> f64 {
        (self.stiffness_n_per_m / self.mass_kg).sqrt()
    }
    /// Length scale N/k (m): x = y · N/k.
    pub fn length_scale_m(&self) -> f64 {
        self.load_n / self.stiffness_n_per_m
    }
    /// τ = Ω t.
    pub fn tau_of_t(&self, t_s: f64) -> f64 {
        self.omega() * t_s
    }
    /// t = τ / Ω.
    pub fn t_of_tau(&self, tau: f64) -> f64 {
        tau / self.omega()
    }
    /// y = k x / N.
    pub fn y_of_x(&self, x_m: f64) -> f64 {
        x_m / self.length_scale_m()
    }
    /// x = y N / k.
    pub fn x_of_y(&self, y: f64) -> f64 {
        y * self.length_scale_m()
    }
    /// y' = k v / (N Ω).
    pub fn ydot_of_v(&self, v_m_s: f64) -> f64 {
        v_m_s / (self.length_scale_m() * self.omega())
    }
    /// v = y' N Ω / k.
    pub fn v_of_ydot(&self, ydot: f64) -> f64 {
        ydot * self.length_scale_m() * self.omega()
    }
    /// μ_j = (N Ω / k)^j p_j (eq. 10): SI coefficient `p_j` of `μ(v) = Σ p_j v^j` (v in m/s) to
    /// dimensionless `μ_j`.
    pub fn mu_of_p(&self, p: &[f64]) -> Vec<f64> {
        let s = self.length_scale_m() * self.omega();
        p.iter()
            .enumerate()
            .map(|(j, &pj)| pj * s.powi(j as i32))
            .collect()
    }
    /// Inverse of [`Rig::mu_of_p`].
    pub fn p_of_mu(&self, mu: &[f64]) -> Vec<f64> {
        let s = self.length_scale_m() * self.omega();
        mu.iter()
            .enumerate()
            .map(|(j, &m)| m / s.powi(j as i32))
            .collect()
    }
    /// Dimensionless apparatus damping μ_a = c/(mΩ) (= 2ζ) of a viscous damper c (N s/m).
    pub fn mu_a_of_damping(&self, c_n_s_per_m: f64) -> f64 {
        c_n_s_per_m / (self.mass_kg * self.omega())
    }
    /// Dimensionless cubic-spring term κ = k3 N² / k³ of an SI term k3 (N/m³).
    pub fn kappa_of_k3(&self, k3_n_per_m3: f64) -> f64 {
        k3_n_per_m3 * self.load_n.powi(2) / self.stiffness_n_per_m.powi(3)
    }
}

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
    pub fn validate(&self) -> Result<(), String> {
        self.law.validate()?;
        if !self.apparatus_mu1.is_finite() || !self.cubic.is_finite() {
            return Err("apparatus damping and cubic term must be finite".into());
        }
        if let Some(s) = self.static_mu {
            if !s.is_finite() || s < 0.0 {
                return Err(format!(
                    "static friction level must be finite and >= 0, got {s}"
                ));
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

//! The rig's physical constants (mass, blade stiffness, normal load) and the conversions between SI
//! and the dimensionless form of the thesis (`Ω = √(k/m)`, `τ = Ω t`, `y = k x / N`).
//!
//! A module of its own so that both the friction laws (SI → dimensionless parameters) and the
//! oscillator model use it without importing each other.

use crate::invalid::InvalidParameter;

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
    pub fn new(mass_kg: f64, stiffness_n_per_m: f64, load_n: f64) -> Result<Rig, InvalidParameter> {
        let r = Rig {
            mass_kg,
            stiffness_n_per_m,
            load_n,
        };
        r.validate()?;
        Ok(r)
    }

    /// Checks every constant is finite and > 0.
    pub fn validate(&self) -> Result<(), InvalidParameter> {
        for (name, v) in [
            ("mass_kg", self.mass_kg),
            ("stiffness_n_per_m", self.stiffness_n_per_m),
            ("load_n", self.load_n),
        ] {
            if !v.is_finite() || v <= 0.0 {
                return Err(InvalidParameter::RigConstant { name, value: v });
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

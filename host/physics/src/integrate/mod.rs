//! Integrators and the stepping simulator.
//!
//! [`Simulator`] integrates the dimensionless model `y'' + μ_a y' + y + κ y³ = −f(y', z)` with either
//! fixed-step RK4 (as the thesis) or adaptive Dormand–Prince 5(4) with dense output. For laws with a
//! `sgn(y')` term both integrators work on a branch (fixed sliding direction), locate the velocity
//! zero crossing as an event, stop exactly there, apply the stick rule (eq. 14) and restart on the
//! new branch — so the discontinuous friction is integrated exactly, never smeared over a step.
//!
//! It is a stepping API: [`Simulator::step_to`] advances to any later time and returns the
//! interpolated state there, so a real-time virtual rig can pull samples one by one. The batch
//! helper [`simulate`] samples a whole grid.

use crate::invalid::InvalidParameter;
use crate::law::FrictionLaw;
use crate::model::Model;

mod dopri;
mod segment;
mod trajectory;
use dopri::*;
use segment::*;
pub use trajectory::*;

/// Integration method.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Method {
    /// Classical fixed-step RK4 with step `h` (dimensionless time), events located by re-stepping.
    Rk4 {
        /// Step (rad of τ); 0.01 is accurate to ~1e-9 in amplitude per cycle.
        h: f64,
    },
    /// Adaptive Dormand–Prince 5(4) with 4th-order dense output and event location.
    Dopri45 {
        /// Relative tolerance.
        rtol: f64,
        /// Absolute tolerance (in y units).
        atol: f64,
        /// Largest step (rad of τ).
        h_max: f64,
    },
}

impl Default for Method {
    /// Dormand–Prince with rtol = 1e-10, atol = 1e-12, h_max = 0.5.
    fn default() -> Self {
        Method::Dopri45 {
            rtol: 1e-10,
            atol: 1e-12,
            h_max: 0.5,
        }
    }
}

impl Method {
    /// Dormand–Prince with the given relative tolerance (atol = rtol/100, h_max = 0.5).
    pub fn dopri(rtol: f64) -> Method {
        Method::Dopri45 {
            rtol,
            atol: rtol * 1e-2,
            h_max: 0.5,
        }
    }
}

/// Simulation failure: bad parameters, or the integration itself (non-finite state, step size
/// underflow, a request it cannot meet).
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SimError {
    /// A constant of the rig, law, model or sensor chain is out of its range.
    #[error("simulation refused: {0}")]
    Invalid(#[from] InvalidParameter),
    /// The integration itself failed (non-finite state, step-size underflow, a request it
    /// cannot meet).
    #[error("simulation failed: {0}")]
    Run(String),
}

/// Dimensionless state at one instant.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct State {
    /// Dimensionless time τ = Ω t.
    pub tau: f64,
    /// Displacement y = k x / N.
    pub y: f64,
    /// Velocity y' = dy/dτ.
    pub ydot: f64,
    /// Internal friction state z (0 for memoryless laws).
    pub z: f64,
    /// Contact friction force f = F/N (while stuck: the static force holding the pin).
    pub f: f64,
    /// True once the pin has stuck for good (eq. 14).
    pub stuck: bool,
}

/// Stepping simulator of one model from one initial state.
///
/// ```
/// use tribo_physics::{law::FrictionLaw, model::Model, integrate::{Simulator, Method}};
/// let mut sim = Simulator::new(Model::new(FrictionLaw::coulomb(0.2)), 10.0, 0.0, Method::default());
/// let s = sim.step_to(std::f64::consts::PI).unwrap(); // first half cycle: y = -(10 - 2·0.2)
/// assert!((s.y + 9.6).abs() < 1e-8);
/// ```
#[derive(Debug, Clone)]
pub struct Simulator {
    model: Model,
    method: Method,
    t: f64,
    s: [f64; 3],
    dir: f64,
    stuck: bool,
    k1: Option<[f64; 3]>,
    h: f64,
    seg: Option<Segment>,
    events: bool,
    stick: Option<f64>,
    reversals: Vec<(f64, f64)>,
    steps: usize,
}

impl Simulator {
    /// A simulator at τ = 0 in state `(y0, ydot0)` with `z = 0`. If `y0` is within the stick band
    /// and `ydot0 = 0`, the pin starts (and stays) stuck.
    pub fn new(model: Model, y0: f64, ydot0: f64, method: Method) -> Simulator {
        Self::with_state(model, 0.0, [y0, ydot0, 0.0], method)
    }

    /// A simulator at time `tau0` in state `[y, y', z]`.
    pub fn with_state(model: Model, tau0: f64, s0: [f64; 3], method: Method) -> Simulator {
        let events = model.law.is_discontinuous();
        let stick = model.stick_level();
        let h = match method {
            Method::Rk4 { h } => h,
            Method::Dopri45 { h_max, .. } => (0.01f64).min(h_max),
        };
        let mut sim = Simulator {
            model,
            method,
            t: tau0,
            s: s0,
            dir: 1.0,
            stuck: false,
            k1: None,
            h,
            seg: None,
            events,
            stick,
            reversals: Vec::new(),
            steps: 0,
        };
        if s0[1] != 0.0 {
            sim.dir = s0[1].signum();
        } else {
            sim.at_rest();
        }
        sim
    }

    /// Velocity is zero: apply the stick rule and pick the new sliding direction.
    fn at_rest(&mut self) {
        // A law with memory keeps pushing through the reversal: its force joins the spring's.
        let r = if self.model.law.has_state() {
            self.model.spring(self.s[0]) + self.model.law.force(0.0, self.s[2], 0.0)
        } else {
            self.model.spring(self.s[0])
        };
        if let Some(mus) = self.stick {
            if r.abs() <= mus {
                self.stuck = true;
                self.s[1] = 0.0;
                return;
            }
        }
        if r != 0.0 {
            self.dir = -r.signum();
        } else if self.stick.is_some() {
            self.stuck = true;
        }
    }

    /// The model being simulated.
    pub fn model(&self) -> &Model {
        &self.model
    }
    /// Time reached by the integration (≥ any time already returned).
    pub fn tau(&self) -> f64 {
        self.t
    }
    /// True once the pin is stuck for good.
    pub fn is_stuck(&self) -> bool {
        self.stuck
    }
    /// Number of accepted integration steps so far.
    pub fn steps(&self) -> usize {
        self.steps
    }
    /// Velocity reversals found so far, as `(τ, y)` (the extrema of the displacement). Only
    /// tracked for discontinuous laws.
    pub fn reversals(&self) -> &[(f64, f64)] {
        &self.reversals
    }

    fn state_of(&self, tau: f64, s: [f64; 3], dir: f64) -> State {
        let f = if self.stuck && tau >= self.t {
            -self.model.spring(s[0])
        } else {
            self.model.law.force(s[1], s[2], dir)
        };
        State {
            tau,
            y: s[0],
            ydot: s[1],
            z: s[2],
            f,
            stuck: self.stuck && tau >= self.t,
        }
    }

    /// Current state at [`Simulator::tau`].
    pub fn state(&self) -> State {
        self.state_of(self.t, self.s, self.dir)
    }

    /// Advances to time `tau` and returns the state there. Times must not go back before the
    /// start of the last internal step (sampling an increasing grid is always fine).
    pub fn step_to(&mut self, tau: f64) -> Result<State, SimError> {
        if !tau.is_finite() {
            return Err(SimError::Run(format!("requested time {tau} is not finite")));
        }
        loop {
            if let Some(seg) = &self.seg {
                let (t0, t1) = seg.span();
                if tau < t0 - 1e-12 * t0.abs().max(1.0) {
                    return Err(SimError::Run(format!(
                        "cannot step back to τ = {tau} (last step starts at {t0})"
                    )));
                }
                if tau <= t1 {
                    let (s, dir) = seg.at(tau);
                    return Ok(self.state_of(tau, s, dir));
                }
            } else if tau <= self.t {
                return Ok(self.state_of(tau, self.s, self.dir));
            }
            if self.stuck {
                return Ok(self.state_of(tau.max(self.t), self.s, self.dir));
            }
            self.advance(tau)?;
        }
    }

    /// Samples the increasing times `taus`.
    pub fn sample(&mut self, taus: &[f64]) -> Result<Vec<State>, SimError> {
        taus.iter().map(|&t| self.step_to(t)).collect()
    }

    /// Iterator over states at `tau0 + i·dtau`, i = 0, 1, … (endless; take what you need).
    pub fn samples(&mut self, dtau: f64) -> impl Iterator<Item = Result<State, SimError>> + '_ {
        let t0 = self.t;
        (0u64..).map(move |i| self.step_to(t0 + i as f64 * dtau))
    }

    /// One internal step (at most up to the next event).
    fn advance(&mut self, _target: f64) -> Result<(), SimError> {
        match self.method {
            Method::Rk4 { h } => self.advance_rk4(h),
            Method::Dopri45 { rtol, atol, h_max } => self.advance_dopri(rtol, atol, h_max),
        }
    }

    fn rk4(&self, s: &[f64; 3], f0: &[f64; 3], h: f64) -> [f64; 3] {
        let m = &self.model;
        let d = self.dir;
        let k2 = m.rhs(&comb(s, &[(0.5, f0)], h), d);
        let k3 = m.rhs(&comb(s, &[(0.5, &k2)], h), d);
        let k4 = m.rhs(&comb(s, &[(1.0, &k3)], h), d);
        comb(
            s,
            &[
                (1.0 / 6.0, f0),
                (1.0 / 3.0, &k2),
                (1.0 / 3.0, &k3),
                (1.0 / 6.0, &k4),
            ],
            h,
        )
    }

    fn advance_rk4(&mut self, h: f64) -> Result<(), SimError> {
        if !(h > 0.0 && h.is_finite()) {
            return Err(SimError::Run(format!("RK4 step must be > 0, got {h}")));
        }
        let s0 = self.s;
        let f0 = self.model.rhs(&s0, self.dir);
        let mut s1 = self.rk4(&s0, &f0, h);
        let mut hs = h;
        let mut event = false;
        if self.events && self.dir * s1[1] < 0.0 {
            // Find h* with v(rk4(s0, h*)) = 0 (Illinois regula falsi on the step length).
            let (mut lo, mut hi) = (0.0, h);
            let (mut vlo, mut vhi) = (self.dir * s0[1], self.dir * s1[1]);
            let mut side = 0;
            for _ in 0..100 {
                let mut m = if vlo - vhi != 0.0 {
                    lo + (hi - lo) * vlo / (vlo - vhi)
                } else {
                    0.5 * (lo + hi)
                };
                if !(m > lo && m < hi) {
                    m = 0.5 * (lo + hi);
                }
                let sm = self.rk4(&s0, &f0, m);
                let vm = self.dir * sm[1];
                if vm >= 0.0 {
                    lo = m;
                    vlo = vm;
                    if side == -1 {
                        vhi *= 0.5;
                    }
                    side = -1;
                } else {
                    hi = m;
                    vhi = vm;
                    if side == 1 {
                        vlo *= 0.5;
                    }
                    side = 1;
                }
                if hi - lo <= 1e-15 * (1.0 + self.t.abs()) || vm.abs() < 1e-15 {
                    break;
                }
            }
            hs = hi;
            s1 = self.rk4(&s0, &f0, hs);
            s1[1] = 0.0;
            event = true;
        }
        check_finite(&s1, self.t)?;
        let f1 = self.model.rhs(&s1, self.dir);
        self.seg = Some(Segment::Hermite {
            t0: self.t,
            t1: self.t + hs,
            s0,
            s1,
            f0,
            f1,
            dir: self.dir,
        });
        self.t += hs;
        self.s = s1;
        self.steps += 1;
        if event {
            self.reversal();
        }
        Ok(())
    }

    fn reversal(&mut self) {
        self.reversals.push((self.t, self.s[0]));
        self.k1 = None;
        self.at_rest();
    }

    fn advance_dopri(&mut self, rtol: f64, atol: f64, h_max: f64) -> Result<(), SimError> {
        if !(rtol > 0.0 && atol > 0.0 && h_max > 0.0) {
            return Err(SimError::Run(
                "Dormand–Prince tolerances and h_max must be > 0".into(),
            ));
        }
        let d = self.dir;
        let s = self.s;
        let k1 = match self.k1 {
            Some(k) => k,
            None => self.model.rhs(&s, d),
        };
        let (h0, t) = (self.h.min(h_max), self.t);
        // The law's dispatch is taken once a step: a pseudo-polynomial law of up to four constants
        // (every fitted one but poly:N ≥ 4) is inlined into the stages, with the same arithmetic
        // as `Model::rhs`, so the steps are the same to the last bit.
        let (mu_a, cubic) = (self.model.apparatus_mu1, self.model.cubic);
        let st = match &self.model.law {
            FrictionLaw::Polynomial { mu } => match *mu.as_slice() {
                [a] => PolyRhs::new([a], mu_a, cubic).step(s, k1, d, h0, t, rtol, atol),
                [a, b] => PolyRhs::new([a, b], mu_a, cubic).step(s, k1, d, h0, t, rtol, atol),
                [a, b, c] => PolyRhs::new([a, b, c], mu_a, cubic).step(s, k1, d, h0, t, rtol, atol),
                [a, b, c, e] => {
                    PolyRhs::new([a, b, c, e], mu_a, cubic).step(s, k1, d, h0, t, rtol, atol)
                }
                _ => dopri_step(|x| self.model.rhs(x, d), s, k1, h0, t, rtol, atol),
            },
            _ => dopri_step(|x| self.model.rhs(x, d), s, k1, h0, t, rtol, atol),
        }?;
        let DopriStep { h, fac, s1, k7, rc } = st;
        let t0 = self.t;
        self.steps += 1;
        self.h = (h * fac).min(h_max);
        if self.events && d * s1[1] < 0.0 {
            let th = find_reversal(&rc, d);
            let mut se = dense_eval(&rc, th);
            se[1] = 0.0;
            self.seg = Some(Segment::Dense {
                t0,
                h,
                t1: t0 + th * h,
                rc,
                dir: d,
            });
            self.t = t0 + th * h;
            self.s = se;
            self.reversal();
        } else {
            self.seg = Some(Segment::Dense {
                t0,
                h,
                t1: t0 + h,
                rc,
                dir: d,
            });
            self.t = t0 + h;
            self.s = s1;
            self.k1 = Some(k7);
        }
        Ok(())
    }
}

fn check_finite(s: &[f64; 3], t: f64) -> Result<(), SimError> {
    if s.iter().all(|x| x.is_finite()) {
        Ok(())
    } else {
        Err(SimError::Run(format!("non-finite state at τ = {t}")))
    }
}

//! Mark & Crandall envelope `A = sqrt(x² + (v/Ω)²)`, averaged over each half-cycle.
//!
//! Per sample only exact integer sums of the two vibrometer channels are kept ([`Moments`]): the
//! count, Σx, Σx², Σv, Σv² (counts relative to a reference). At each velocity reversal they are turned
//! into the half-cycle's mean displacement, displacement variance and mean square velocity in SI
//! ([`HalfCycleMoments`]). From those, the mean square envelope about *any* centre `c` follows exactly:
//!
//! `⟨(x − c)² + (v/Ω)²⟩ = var(x) + (x̄ − c)² + ⟨v²⟩/Ω²`
//!
//! so the analysis can choose the centre (the displacement zero, and the Coulomb shift ±r of the
//! half-cycle's equilibrium) and Ω (the measured natural frequency) *after* the run, without having
//! stored the samples and without any per-sample square root. Over a half-cycle (phase 0 → π between
//! two reversals) the first-order ripple of the envelope (`2 e R cos φ` for a centre error `e`)
//! averages to zero, so `sqrt(⟨A²⟩)` is the half-cycle amplitude up to second-order terms.
use crate::wire::ChannelCal;

/// Instantaneous Mark & Crandall envelope of one sample (SI): `sqrt(x² + (v/Ω)²)`.
pub fn mark_crandall(x: f64, v: f64, omega: f64) -> f64 {
    crate::fit::sqrt(x * x + (v / omega) * (v / omega))
}

/// Exact integer sums of the two vibrometer channels over the current half-cycle.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Moments {
    n: u32,
    sx: i64,
    sxx: i64,
    sv: i64,
    svv: i64,
}

impl Moments {
    /// Adds one sample, counts relative to the references (|dx|, |dv| ≤ 65535).
    /// Wrapping arithmetic: the sums cannot overflow before 2^31 samples in one half-cycle, and a
    /// run is cut long before that; wrapping keeps garbage input panic-free regardless.
    pub fn add(&mut self, dx: i32, dv: i32) {
        let (dx, dv) = (dx as i64, dv as i64);
        self.n = self.n.wrapping_add(1);
        self.sx = self.sx.wrapping_add(dx);
        self.sxx = self.sxx.wrapping_add(dx * dx);
        self.sv = self.sv.wrapping_add(dv);
        self.svv = self.svv.wrapping_add(dv * dv);
    }

    /// Number of samples.
    pub fn len(&self) -> u32 {
        self.n
    }

    /// Σ(dv)² of the velocity counts relative to their reference.
    pub fn sum_sq_v(&self) -> i64 {
        self.svv
    }

    /// True before any sample.
    pub fn is_empty(&self) -> bool {
        self.n == 0
    }

    /// SI summary, given the calibrations and the integer references the counts were taken from.
    /// `None` when empty.
    pub fn summarise(
        &self,
        x_cal: ChannelCal,
        x_ref: i32,
        v_cal: ChannelCal,
        v_ref: i32,
    ) -> Option<HalfCycleMoments> {
        if self.n == 0 {
            return None;
        }
        let n = self.n as f64;
        let mx = self.sx as f64 / n;
        let var_c = (self.sxx as f64 / n - mx * mx).max(0.0);
        let gx = x_cal.gain as f64;
        let mean_x = gx * (x_ref as f64 + mx - x_cal.zero as f64);
        // v − zero = (v − v_ref) − (zero − v_ref)
        let mv = self.sv as f64 / n;
        let dz = v_cal.zero as f64 - v_ref as f64;
        let msq = (self.svv as f64 / n - 2.0 * dz * mv + dz * dz).max(0.0);
        let gv = v_cal.gain as f64;
        Some(HalfCycleMoments {
            mean_x: mean_x as f32,
            var_x: (gx * gx * var_c) as f32,
            mean_v2: (gv * gv * msq) as f32,
        })
    }
}

/// A half-cycle's displacement mean (m), displacement variance (m²) and mean square velocity (m²/s²).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct HalfCycleMoments {
    pub mean_x: f32,
    pub var_x: f32,
    pub mean_v2: f32,
}

impl HalfCycleMoments {
    /// Root-mean-square Mark & Crandall envelope about the centre `centre` (m) with natural angular
    /// frequency `omega` (rad/s).
    pub fn envelope(&self, centre: f64, omega: f64) -> f64 {
        crate::fit::sqrt(self.mean_square(centre, omega))
    }

    /// Mean square Mark & Crandall envelope `⟨(x − c)² + (v/Ω)²⟩` (m²).
    pub fn mean_square(&self, centre: f64, omega: f64) -> f64 {
        let d = self.mean_x as f64 - centre;
        self.var_x as f64 + d * d + self.mean_v2 as f64 / (omega * omega)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Over a half-cycle of a harmonic oscillation about `c` with amplitude R, the RMS envelope about
    /// `c` is R, whatever the calibration; about another centre it is sqrt(R² + e²).
    #[test]
    fn half_cycle_envelope_of_a_sinusoid() {
        let (r_amp, c, omega) = (5e-4, 3e-5, 160.0);
        let x_cal = ChannelCal {
            gain: 2e-8,
            zero: 30000.0,
        };
        let v_cal = ChannelCal {
            gain: -4e-6,
            zero: 32000.25,
        };
        let mut m = Moments::default();
        let n = 4000;
        for i in 0..n {
            let phi = core::f64::consts::PI * (i as f64 + 0.5) / n as f64;
            let x = c + r_amp * phi.cos();
            let v = -r_amp * omega * phi.sin();
            let cx = (x / x_cal.gain as f64 + x_cal.zero as f64).round() as i32;
            let cv = (v / v_cal.gain as f64 + v_cal.zero as f64).round() as i32;
            m.add(cx - 30000, cv - 32000);
        }
        let h = m.summarise(x_cal, 30000, v_cal, 32000).unwrap();
        assert!((h.mean_x as f64 - c).abs() < 1e-8, "{}", h.mean_x);
        assert!((h.envelope(c, omega) - r_amp).abs() < 2e-8 * 10.0);
        let e = 2e-5;
        let off = h.envelope(c + e, omega);
        assert!((off - (r_amp * r_amp + e * e).sqrt()).abs() < 2e-7);
        assert!((mark_crandall(3.0, 4.0 * omega, omega) - 5.0).abs() < 1e-12);
        assert!(Moments::default().summarise(x_cal, 0, v_cal, 0).is_none());
    }
}

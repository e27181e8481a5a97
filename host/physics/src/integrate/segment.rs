//! What lies between two accepted steps: the interpolant a step leaves behind (the dense output
//! of a Dormand–Prince step, or a cubic Hermite between two RK4 points).

use super::dopri::dense_eval;

#[derive(Debug, Clone)]
pub(super) enum Segment {
    /// Dense output of a Dormand–Prince step started at t0 with step h, valid to t1 ≤ t0 + h.
    Dense {
        t0: f64,
        h: f64,
        t1: f64,
        rc: [[f64; 3]; 5],
        dir: f64,
    },
    /// Cubic Hermite between two RK4 points.
    Hermite {
        t0: f64,
        t1: f64,
        s0: [f64; 3],
        s1: [f64; 3],
        f0: [f64; 3],
        f1: [f64; 3],
        dir: f64,
    },
}

impl Segment {
    /// The times `(t0, t1)` the segment covers.
    pub(super) fn span(&self) -> (f64, f64) {
        match self {
            Segment::Dense { t0, t1, .. } | Segment::Hermite { t0, t1, .. } => (*t0, *t1),
        }
    }

    /// The state `(y, y', z)` at `tau` (clamped to the segment's start) and the sliding direction.
    pub(super) fn at(&self, tau: f64) -> ([f64; 3], f64) {
        match self {
            Segment::Dense { t0, h, rc, dir, .. } => {
                (dense_eval(rc, ((tau - t0) / h).max(0.0)), *dir)
            }
            Segment::Hermite {
                t0,
                t1,
                s0,
                s1,
                f0,
                f1,
                dir,
            } => {
                let h = t1 - t0;
                let th = if h > 0.0 {
                    ((tau - t0) / h).max(0.0)
                } else {
                    1.0
                };
                (hermite(s0, s1, f0, f1, h, th), *dir)
            }
        }
    }
}

fn hermite(
    s0: &[f64; 3],
    s1: &[f64; 3],
    f0: &[f64; 3],
    f1: &[f64; 3],
    h: f64,
    th: f64,
) -> [f64; 3] {
    let h00 = (1.0 + 2.0 * th) * (1.0 - th) * (1.0 - th);
    let h10 = th * (1.0 - th) * (1.0 - th);
    let h01 = th * th * (3.0 - 2.0 * th);
    let h11 = th * th * (th - 1.0);
    let mut o = [0.0; 3];
    for i in 0..3 {
        o[i] = h00 * s0[i] + h10 * h * f0[i] + h01 * s1[i] + h11 * h * f1[i];
    }
    o
}

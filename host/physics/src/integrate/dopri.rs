//! Dormand–Prince 5(4): the tableau, the combination of stages, the dense-output polynomial of
//! a step and the first velocity reversal on it.

// Dormand–Prince 5(4) tableau.
pub(super) const A21: f64 = 1.0 / 5.0;
pub(super) const A31: f64 = 3.0 / 40.0;
pub(super) const A32: f64 = 9.0 / 40.0;
pub(super) const A41: f64 = 44.0 / 45.0;
pub(super) const A42: f64 = -56.0 / 15.0;
pub(super) const A43: f64 = 32.0 / 9.0;
pub(super) const A51: f64 = 19372.0 / 6561.0;
pub(super) const A52: f64 = -25360.0 / 2187.0;
pub(super) const A53: f64 = 64448.0 / 6561.0;
pub(super) const A54: f64 = -212.0 / 729.0;
pub(super) const A61: f64 = 9017.0 / 3168.0;
pub(super) const A62: f64 = -355.0 / 33.0;
pub(super) const A63: f64 = 46732.0 / 5247.0;
pub(super) const A64: f64 = 49.0 / 176.0;
pub(super) const A65: f64 = -5103.0 / 18656.0;
pub(super) const A71: f64 = 35.0 / 384.0;
pub(super) const A73: f64 = 500.0 / 1113.0;
pub(super) const A74: f64 = 125.0 / 192.0;
pub(super) const A75: f64 = -2187.0 / 6784.0;
pub(super) const A76: f64 = 11.0 / 84.0;
pub(super) const E1: f64 = 71.0 / 57600.0;
pub(super) const E3: f64 = -71.0 / 16695.0;
pub(super) const E4: f64 = 71.0 / 1920.0;
pub(super) const E5: f64 = -17253.0 / 339200.0;
pub(super) const E6: f64 = 22.0 / 525.0;
pub(super) const E7: f64 = -1.0 / 40.0;
pub(super) const D1: f64 = -12715105075.0 / 11282082432.0;
pub(super) const D3: f64 = 87487479700.0 / 32700410799.0;
pub(super) const D4: f64 = -10690763975.0 / 1880347072.0;
pub(super) const D5: f64 = 701980252875.0 / 199316789632.0;
pub(super) const D6: f64 = -1453857185.0 / 822651844.0;
pub(super) const D7: f64 = 69997945.0 / 29380423.0;

#[inline]
pub(super) fn comb(s: &[f64; 3], terms: &[(f64, &[f64; 3])], h: f64) -> [f64; 3] {
    let mut out = *s;
    for (c, k) in terms {
        for i in 0..3 {
            out[i] += h * c * k[i];
        }
    }
    out
}

pub(super) fn dense_eval(rc: &[[f64; 3]; 5], th: f64) -> [f64; 3] {
    let th1 = 1.0 - th;
    let mut o = [0.0; 3];
    for (i, oi) in o.iter_mut().enumerate() {
        *oi = rc[0][i] + th * (rc[1][i] + th1 * (rc[2][i] + th * (rc[3][i] + th1 * rc[4][i])));
    }
    o
}

/// The first θ in (0, 1] where `dir · v(θ)` turns negative on a dense-output polynomial.
pub(super) fn find_reversal(rc: &[[f64; 3]; 5], dir: f64) -> f64 {
    let v = |th: f64| dir * dense_eval(rc, th)[1];
    // Bracket: first of 16 sub-intervals where the sign turns.
    let n = 16;
    let mut lo = 0.0;
    let mut hi = 1.0;
    for i in 1..=n {
        let th = i as f64 / n as f64;
        if v(th) < 0.0 {
            hi = th;
            lo = (i - 1) as f64 / n as f64;
            break;
        }
    }
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if v(mid) >= 0.0 {
            lo = mid;
        } else {
            hi = mid;
        }
        if hi - lo < 1e-16 {
            break;
        }
    }
    0.5 * (lo + hi)
}

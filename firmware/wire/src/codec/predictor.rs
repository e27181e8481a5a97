//! Choosing how a channel is coded: the predictor (level, slope, curve, verbatim) whose residuals
//! are smallest, and the Rice parameter `k` that codes them in the fewest bits.

use super::*;

#[inline]
pub(super) fn zigzag(r: u16) -> u16 {
    let r = r as i16;
    ((r << 1) ^ (r >> 15)) as u16
}

#[inline]
pub(super) fn unzigzag(u: u16) -> u16 {
    (u >> 1) ^ (u & 1).wrapping_neg()
}

/// A predictor of one channel.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Mode {
    Level = 0,
    Slope = 1,
    Curve = 2,
    Verbatim = 3,
}

impl Mode {
    pub(super) fn from_bits(b: u32) -> Mode {
        match b & 3 {
            0 => Mode::Level,
            1 => Mode::Slope,
            2 => Mode::Curve,
            _ => Mode::Verbatim,
        }
    }
}

/// The zig-zagged residuals of `mode` for the lane `x` (those past the warm-up), modulo 2^16,
/// into `out`; returns how many.
pub(super) fn residuals(x: &[u16], mode: Mode, base: u16, out: &mut [u16; BLOCK_LEN]) -> usize {
    match mode {
        Mode::Level => {
            for (o, &v) in out.iter_mut().zip(x) {
                *o = zigzag(v.wrapping_sub(base));
            }
        }
        Mode::Slope => {
            for (o, w) in out.iter_mut().zip(x.windows(2)) {
                *o = zigzag(w[1].wrapping_sub(w[0]));
            }
        }
        Mode::Curve => {
            for (o, w) in out.iter_mut().zip(x.windows(3)) {
                *o = zigzag(w[2].wrapping_sub(w[1].wrapping_mul(2).wrapping_sub(w[0])));
            }
        }
        Mode::Verbatim => return 0,
    }
    x.len() - warm_up(mode, x.len())
}

/// Counts sent verbatim before the residuals of `mode` start (the base of `Level` aside).
pub(super) fn warm_up(mode: Mode, n: usize) -> usize {
    match mode {
        Mode::Level => 0,
        Mode::Slope => n.min(1),
        Mode::Curve => n.min(2),
        Mode::Verbatim => n,
    }
}

/// The plan for one channel: predictor, base and Rice parameter.
#[derive(Debug, Clone, Copy)]
pub(super) struct Plan {
    pub(super) mode: Mode,
    pub(super) base: u16,
    pub(super) k: u32,
}

/// Residuals of one predictor summarised by bit length: `count[b]` residuals of `b` significant
/// bits (`b = 0` for zero), `sum[b]` their total. Enough to price any Rice parameter closely.
#[derive(Default, Clone, Copy)]
pub(super) struct Histogram {
    pub(super) count: [u32; 17],
    pub(super) sum: [u32; 17],
    pub(super) n: u32,
    pub(super) total: u32,
    /// Highest bucket used.
    pub(super) hi: u32,
}

impl Histogram {
    #[inline]
    pub(super) fn add(&mut self, u: u16) {
        let b = 16 - u.leading_zeros();
        self.count[b as usize] += 1;
        self.sum[b as usize] += u as u32;
        self.n += 1;
        self.total += u as u32;
        self.hi = self.hi.max(b);
    }

    /// Bits of the residuals under `k`, over-estimated by less than one per residual whose
    /// quotient is not zero.
    pub(super) fn bits(&self, k: u32) -> u32 {
        let mut bits = 0;
        for b in 0..=self.hi {
            let cnt = self.count[b as usize];
            if cnt == 0 {
                continue;
            }
            if b <= k {
                // Quotient 0: a zero and k bits each.
                bits += cnt * (1 + k);
                continue;
            }
            // Σ⌊u / 2^k⌋ ≤ ⌊Σu / 2^k⌋ < Σ⌊u / 2^k⌋ + cnt.
            let plain = cnt * (1 + k) + (self.sum[b as usize] >> k);
            let qmin = (1u32 << (b - 1)) >> k;
            let qmax = ((1u32 << b) - 1) >> k;
            bits += if qmin >= ESCAPE {
                cnt * (ESCAPE + 16)
            } else if qmax < ESCAPE {
                plain
            } else {
                plain.min(cnt * (ESCAPE + 16))
            };
        }
        bits
    }

    /// The best parameter and its cost (header included): from the mean's bit length, a local
    /// search (the cost is unimodal in k for these distributions; a worse pick only costs bits).
    pub(super) fn best(&self) -> (u32, u32) {
        if self.n == 0 {
            return (K_ZERO, 0);
        }
        if self.count[0] == self.n {
            return (K_ZERO, 4);
        }
        let mean = self.total / self.n;
        let mut k = (u32::BITS - mean.leading_zeros()).min(K_MAX);
        let mut bits = self.bits(k);
        while k > 0 {
            let b = self.bits(k - 1);
            if b > bits {
                break;
            }
            k -= 1;
            bits = b;
        }
        while k < K_MAX {
            let b = self.bits(k + 1);
            if b >= bits {
                break;
            }
            k += 1;
            bits = b;
        }
        (k, 4 + bits)
    }
}

/// Rough bits of `n` residuals summing to `sum` under the Rice parameter their mean suggests: what
/// the predictors are compared by.
pub(super) fn rough_bits(sum: u32, n: u32) -> u32 {
    if n == 0 {
        return 0;
    }
    if sum == 0 {
        return 4;
    }
    let k = (u32::BITS - (sum / n).leading_zeros())
        .saturating_sub(1)
        .min(K_MAX);
    4 + n * (1 + k) + (sum >> k)
}

/// Picks the cheapest predictor (by the sums of its residuals) and its Rice parameter (by their
/// histogram), and leaves its residuals in `r` (how many: the second value). Four passes over the
/// lane's counts.
pub(super) fn plan(x: &[u16], r: &mut [u16; BLOCK_LEN]) -> (Plan, usize) {
    let n = x.len();
    // Pass 1: the lane's sum (for the level's base), and the slope and curve residuals.
    // (The first two counts apart, so that the loop over the rest has no branch: on the M7 this
    // pass is a fifth of packing a block.)
    let mut sum = 0u32;
    let mut s = [0u32; 3];
    if let Some(&a) = x.first() {
        sum += a as u32;
    }
    if let [a, b, ..] = *x {
        sum += b as u32;
        s[1] += zigzag(b.wrapping_sub(a)) as u32;
    }
    for w in x.windows(3) {
        let (p2, p1, v) = (w[0], w[1], w[2]);
        sum += v as u32;
        s[1] += zigzag(v.wrapping_sub(p1)) as u32;
        s[2] += zigzag(v.wrapping_sub(p1.wrapping_mul(2).wrapping_sub(p2))) as u32;
    }
    let base = if n == 0 {
        0
    } else {
        ((sum + n as u32 / 2) / n as u32) as u16
    };
    // Pass 2: the level residuals.
    s[0] = x.iter().map(|&v| zigzag(v.wrapping_sub(base)) as u32).sum();
    let mut mode = Mode::Verbatim;
    let mut least = 16 * n as u32;
    for (m, sum) in [Mode::Level, Mode::Slope, Mode::Curve].into_iter().zip(s) {
        let warm = warm_up(m, n);
        let fixed = 16 * warm as u32 + if m == Mode::Level { 16 } else { 0 };
        let bits = fixed + rough_bits(sum, (n - warm) as u32);
        if bits < least {
            least = bits;
            mode = m;
        }
    }
    let verbatim = Plan {
        mode: Mode::Verbatim,
        base,
        k: 0,
    };
    if mode == Mode::Verbatim {
        return (verbatim, 0);
    }
    // Pass 3: the residuals and, from their histogram (robust to a few spikes), the parameter.
    let m = residuals(x, mode, base, r);
    let mut h = Histogram::default();
    for &u in &r[..m] {
        h.add(u);
    }
    let (k, bits) = h.best();
    let fixed = 16 * warm_up(mode, n) as u32 + if mode == Mode::Level { 16 } else { 0 };
    if fixed + bits >= 16 * n as u32 {
        return (verbatim, 0);
    }
    (Plan { mode, base, k }, m)
}

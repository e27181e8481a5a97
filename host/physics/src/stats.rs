//! The small statistics every part of the host uses, defined once: the least-squares line, mean ±
//! sample standard deviation, and the seeded random generator of the simulations and tests.

/// Ordinary least-squares line through `(x, y)`: `(slope, intercept)`. `None` with fewer than two
/// points, all `x` equal, or a non-finite result.
pub fn linreg(x: &[f64], y: &[f64]) -> Option<(f64, f64)> {
    let n = x.len().min(y.len());
    if n < 2 {
        return None;
    }
    let (x, y) = (&x[..n], &y[..n]);
    let mx = x.iter().sum::<f64>() / n as f64;
    let my = y.iter().sum::<f64>() / n as f64;
    let sxx: f64 = x.iter().map(|v| (v - mx).powi(2)).sum();
    let sxy: f64 = x.iter().zip(y).map(|(a, b)| (a - mx) * (b - my)).sum();
    if sxx.is_nan() || sxx <= 0.0 {
        return None;
    }
    let s = sxy / sxx;
    Some((s, my - s * mx)).filter(|(a, b)| a.is_finite() && b.is_finite())
}

/// Mean and sample standard deviation (`n − 1` in the denominator; 0 for a single value, NaN for
/// none).
pub fn mean_sd(v: &[f64]) -> (f64, f64) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let sd = if v.len() > 1 {
        (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt()
    } else {
        0.0
    };
    (m, sd)
}

/// Small deterministic PRNG (SplitMix64) with Gaussian draws (Box–Muller).
#[derive(Debug, Clone)]
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    /// Seeded generator.
    pub fn new(seed: u64) -> Rng {
        Rng {
            state: seed ^ 0x9E37_79B9_7F4A_7C15,
            spare: None,
        }
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.state = self.state.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.state;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }
    /// Standard normal.
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (2.0 * std::f64::consts::PI * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn linreg_recovers_a_line_and_refuses_what_has_none() {
        let x: Vec<f64> = (0..10).map(f64::from).collect();
        let y: Vec<f64> = x.iter().map(|v| 3.0 - 0.5 * v).collect();
        let (s, c) = linreg(&x, &y).unwrap();
        assert!(
            (s + 0.5).abs() < 1e-12 && (c - 3.0).abs() < 1e-12,
            "{s} {c}"
        );
        assert_eq!(linreg(&[1.0], &[2.0]), None);
        assert_eq!(linreg(&[2.0, 2.0, 2.0], &[1.0, 2.0, 3.0]), None);
        assert_eq!(linreg(&[0.0, 1.0], &[0.0, f64::NAN]), None);
    }

    #[test]
    fn mean_sd_is_the_sample_estimate() {
        let (m, sd) = mean_sd(&[2.0, 4.0, 4.0, 4.0, 5.0, 5.0, 7.0, 9.0]);
        assert_eq!(m, 5.0);
        // population sd 2, sample sd 2·√(8/7)
        assert!((sd - 2.0 * (8.0f64 / 7.0).sqrt()).abs() < 1e-12, "{sd}");
        assert_eq!(mean_sd(&[3.0]), (3.0, 0.0));
    }

    #[test]
    fn the_generator_is_reproducible_and_its_normals_are_standard() {
        let (mut a, mut b) = (Rng::new(11), Rng::new(11));
        assert!((0..100).all(|_| a.next_u64() == b.next_u64()));
        let mut r = Rng::new(5);
        let v: Vec<f64> = (0..20_000).map(|_| r.normal()).collect();
        let (m, sd) = mean_sd(&v);
        // 20 000 draws: the mean within 4 standard errors (0.028), the sd within 3 %.
        assert!(m.abs() < 0.03 && (sd - 1.0).abs() < 0.03, "{m} {sd}");
    }
}

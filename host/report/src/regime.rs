//! Lubrication regime from the electrical contact resistance (thesis ch. 2.3–2.4).
//!
//! The ECR source is limited to 2 mV / 5 mA and reads 1 Ω … 1e8 Ω. While the pin slides:
//! - a **constant, high** `log10 R` (≈ 7) means the surfaces are separated by a continuous film:
//!   full-film (elastohydrodynamic) lubrication;
//! - a **fluctuating** one means asperities touch through the film now and then: mixed lubrication;
//! - a **constant, low** one (metallic contact, `R` ≲ 1 kΩ) means the load is carried by the
//!   asperities through boundary films only: boundary lubrication.
//!
//! The value at rest after the stop is not used: it is not zero (insulating products) and says
//! nothing about the sliding contact.

use crate::ReportError;

/// Median `log10 R` at or above which a steady signal counts as a full film.
pub const FULL_FILM_MIN_LOG10: f64 = 6.0;
/// Median `log10 R` at or below which a steady signal counts as metallic (boundary) contact.
pub const BOUNDARY_MAX_LOG10: f64 = 3.0;
/// Largest robust spread (decades) of a steady signal.
pub const STEADY_MAX_SPREAD: f64 = 0.25;
/// Largest fraction of samples more than one decade away from the median in a steady signal
/// (catches intermittent breakdowns that leave the median and the MAD untouched).
pub const STEADY_MAX_EXCURSIONS: f64 = 0.05;

/// Lubrication regime.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Regime {
    /// Steady high resistance: a continuous film separates the surfaces (EHL).
    FullFilm,
    /// Fluctuating resistance: intermittent asperity contact.
    Mixed,
    /// Steady low resistance: metallic contact through boundary films.
    Boundary,
}

impl Regime {
    /// Human-readable name.
    pub fn name(self) -> &'static str {
        match self {
            Regime::FullFilm => "full film (EHL)",
            Regime::Mixed => "mixed",
            Regime::Boundary => "boundary",
        }
    }
}

/// The classifier's verdict and the numbers it was based on.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RegimeAssessment {
    /// The regime named.
    pub regime: Regime,
    /// Median `log10(R / Ω)` over the samples classified.
    pub median_log10: f64,
    /// Robust spread in decades: 1.4826 × median absolute deviation (σ for Gaussian noise).
    pub spread_decades: f64,
    /// Fraction of samples more than one decade from the median.
    pub excursions: f64,
    /// Samples classified.
    pub samples: usize,
}

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Classifies a series of `log10(R / Ω)` taken while sliding. Needs at least 8 finite values.
pub fn classify_regime(log10_r: &[f64]) -> Result<RegimeAssessment, ReportError> {
    if log10_r.len() < 8 {
        return Err(ReportError::Input(format!(
            "ECR regime: need at least 8 samples while sliding, got {}",
            log10_r.len()
        )));
    }
    if let Some(i) = log10_r.iter().position(|v| !v.is_finite()) {
        return Err(ReportError::Input(format!(
            "ECR regime: non-finite log10 R at sample {i}"
        )));
    }
    let mut v = log10_r.to_vec();
    let med = median(&mut v);
    let mut dev: Vec<f64> = log10_r.iter().map(|x| (x - med).abs()).collect();
    let spread = 1.4826 * median(&mut dev);
    let excursions =
        log10_r.iter().filter(|x| (*x - med).abs() > 1.0).count() as f64 / log10_r.len() as f64;
    let steady = spread <= STEADY_MAX_SPREAD && excursions <= STEADY_MAX_EXCURSIONS;
    let regime = if steady && med >= FULL_FILM_MIN_LOG10 {
        Regime::FullFilm
    } else if steady && med <= BOUNDARY_MAX_LOG10 {
        Regime::Boundary
    } else {
        Regime::Mixed
    };
    Ok(RegimeAssessment {
        regime,
        median_log10: med,
        spread_decades: spread,
        excursions,
        samples: log10_r.len(),
    })
}

/// `log10 R` of an ECR channel in Ω; zero or negative readings are an error.
pub fn log10_ohm(ecr_ohm: &[f64]) -> Result<Vec<f64>, ReportError> {
    ecr_ohm
        .iter()
        .enumerate()
        .map(|(i, &r)| {
            if r.is_finite() && r > 0.0 {
                Ok(r.log10())
            } else {
                Err(ReportError::Input(format!(
                    "ECR channel: sample {i} is {r} Ω; a resistance must be finite and > 0"
                )))
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_physics::sensor::Rng;

    fn series(level: f64, sigma: f64, n: usize, seed: u64) -> Vec<f64> {
        let mut rng = Rng::new(seed);
        (0..n).map(|_| level + sigma * rng.normal()).collect()
    }

    #[test]
    fn steady_high_is_full_film() {
        let a = classify_regime(&series(7.0, 0.03, 500, 1)).unwrap();
        assert_eq!(a.regime, Regime::FullFilm);
        assert!((a.median_log10 - 7.0).abs() < 0.01);
        // The spread estimates σ of Gaussian noise.
        assert!(
            (a.spread_decades - 0.03).abs() < 0.006,
            "{}",
            a.spread_decades
        );
    }

    #[test]
    fn fluctuating_is_mixed_even_when_high() {
        for (level, sigma) in [(7.0, 1.0), (5.0, 0.6), (2.0, 0.8)] {
            let a = classify_regime(&series(level, sigma, 500, 2)).unwrap();
            assert_eq!(a.regime, Regime::Mixed, "level {level} σ {sigma}: {a:?}");
            assert!((a.spread_decades - sigma).abs() < 0.2 * sigma);
        }
    }

    #[test]
    fn steady_low_is_boundary_and_steady_middle_is_mixed() {
        assert_eq!(
            classify_regime(&series(1.0, 0.05, 300, 3)).unwrap().regime,
            Regime::Boundary
        );
        // Neither a film nor metallic contact: partial separation.
        assert_eq!(
            classify_regime(&series(4.5, 0.05, 300, 4)).unwrap().regime,
            Regime::Mixed
        );
    }

    #[test]
    fn intermittent_breakdowns_are_mixed() {
        // A film at 7 that breaks down to 2 on 15 % of the samples: median and MAD stay those of
        // the film, the excursions give it away.
        let mut s = series(7.0, 0.02, 400, 5);
        for (i, v) in s.iter_mut().enumerate() {
            if i % 7 == 0 {
                *v = 2.0;
            }
        }
        let a = classify_regime(&s).unwrap();
        assert!(a.spread_decades < STEADY_MAX_SPREAD);
        assert!(a.excursions > 0.1);
        assert_eq!(a.regime, Regime::Mixed);
    }

    #[test]
    fn bad_input_is_an_error() {
        assert!(classify_regime(&[7.0; 5]).is_err());
        let mut s = vec![7.0; 20];
        s[3] = f64::NAN;
        let msg = classify_regime(&s).unwrap_err().to_string();
        assert!(msg.contains("sample 3"), "{msg}");
        assert!(log10_ohm(&[1e7, 0.0]).is_err());
        assert!(log10_ohm(&[1e7, -5.0]).is_err());
        assert_eq!(log10_ohm(&[1e7, 10.0]).unwrap(), vec![7.0, 1.0]);
    }
}

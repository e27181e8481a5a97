//! The friction law *named*: which law a fit, a simulation, an explanation or a report is about
//! (`coulomb`, `viscous`, `coulomb-viscous`, `quadratic`, `poly:N`, `lugre`), with its parsing
//! ([`FromStr`], errors of type [`UnknownLaw`]), its canonical name ([`Display`](fmt::Display)), serde
//! (as that name) and the map from fitted parameters to the [`FrictionLaw`] value. Command-line
//! options take it directly (clap reads any `FromStr` type).

use crate::law::{FrictionLaw, LuGre};
use serde::{Deserialize, Serialize};
use std::fmt;
use std::str::FromStr;

/// Which law to fit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LawSpec {
    /// `μ0 sgn(y')`.
    Coulomb,
    /// `μ1 y'`.
    Viscous,
    /// `μ0 sgn(y') + μ1 y'`.
    CoulombViscous,
    /// `(μ0 + μ2 y'²) sgn(y') + μ1 y'`.
    Quadratic,
    /// Pseudo-polynomial of order N (N + 1 constants μ0…μN).
    Poly(usize),
    /// LuGre: fitted `μ_c`, `μ_s`, `σ2`, with bristle stiffness/damping and Stribeck velocity fixed
    /// (see [`LUGRE_FIXED`]); `mu` reports `[μ_c, σ2]` (its Coulomb–viscous equivalent).
    LuGre,
}

/// Fixed LuGre constants used by [`LawSpec::LuGre`] fits: `(σ0, σ1, v_s, a)`, dimensionless.
pub const LUGRE_FIXED: (f64, f64, f64, f64) = (200.0, 2.0, 1.0, 2.0);

/// Why a law name was not understood.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum UnknownLaw {
    /// `poly:N` whose N is not a whole number.
    #[error("bad polynomial order in {0:?}: write poly:N with N a whole number, e.g. poly:3")]
    BadOrder(String),
    /// `poly:N` above the highest order fitted.
    #[error("polynomial order {0} too high (max {MAX_POLY_ORDER})")]
    OrderTooHigh(usize),
    /// A name that is no law.
    #[error(
        "unknown law {0:?}: use coulomb, viscous, coulomb-viscous, quadratic, poly:N or lugre"
    )]
    Name(String),
}

/// Highest order of a [`LawSpec::Poly`] law.
pub const MAX_POLY_ORDER: usize = 8;

impl FromStr for LawSpec {
    type Err = UnknownLaw;
    fn from_str(s: &str) -> Result<Self, UnknownLaw> {
        Ok(match s.trim().to_ascii_lowercase().as_str() {
            "coulomb" | "constant" => LawSpec::Coulomb,
            "viscous" => LawSpec::Viscous,
            "coulomb-viscous" | "coulomb_viscous" | "cv" | "linear" => LawSpec::CoulombViscous,
            "quadratic" => LawSpec::Quadratic,
            "lugre" => LawSpec::LuGre,
            other => {
                let Some(n) = other.strip_prefix("poly:") else {
                    return Err(UnknownLaw::Name(other.to_string()));
                };
                let n: usize = n
                    .parse()
                    .map_err(|_| UnknownLaw::BadOrder(other.to_string()))?;
                if n > MAX_POLY_ORDER {
                    return Err(UnknownLaw::OrderTooHigh(n));
                }
                LawSpec::Poly(n)
            }
        })
    }
}

/// The canonical name, as [`FromStr`] reads it back.
impl fmt::Display for LawSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LawSpec::Coulomb => f.write_str("coulomb"),
            LawSpec::Viscous => f.write_str("viscous"),
            LawSpec::CoulombViscous => f.write_str("coulomb-viscous"),
            LawSpec::Quadratic => f.write_str("quadratic"),
            LawSpec::Poly(n) => write!(f, "poly:{n}"),
            LawSpec::LuGre => f.write_str("lugre"),
        }
    }
}

/// In JSON, TOML and the catalogue a law is its canonical name (`"coulomb-viscous"`, `"poly:3"`).
impl Serialize for LawSpec {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for LawSpec {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let s = <std::borrow::Cow<'de, str>>::deserialize(d)?;
        s.parse().map_err(serde::de::Error::custom)
    }
}

impl LawSpec {
    /// Canonical name (as accepted by `FromStr`; the same as `Display`).
    pub fn name(&self) -> String {
        self.to_string()
    }

    /// Indices `j` of the fitted `μ_j` (polynomial laws).
    pub fn powers(&self) -> Vec<usize> {
        match self {
            LawSpec::Coulomb => vec![0],
            LawSpec::Viscous => vec![1],
            LawSpec::CoulombViscous | LawSpec::LuGre => vec![0, 1],
            LawSpec::Quadratic => vec![0, 1, 2],
            LawSpec::Poly(n) => (0..=*n).collect(),
        }
    }

    /// Number of fitted parameters.
    pub fn n_params(&self) -> usize {
        match self {
            LawSpec::LuGre => 3,
            _ => self.powers().len(),
        }
    }

    /// The law for parameter vector `p`.
    pub fn law(&self, p: &[f64]) -> FrictionLaw {
        match self {
            LawSpec::LuGre => {
                let (s0, s1, vs, a) = LUGRE_FIXED;
                FrictionLaw::LuGre(LuGre {
                    sigma0: s0,
                    sigma1: s1,
                    sigma2: p[2],
                    mu_c: p[0].abs().max(1e-9),
                    mu_s: p[1].abs().max(1e-9),
                    v_s: vs,
                    a,
                })
            }
            _ => FrictionLaw::Polynomial { mu: self.mu(p) },
        }
    }

    /// Standard errors of [`LawSpec::mu`] from those of the parameters (0 for powers not fitted).
    pub fn mu_se(&self, se: &[f64]) -> Vec<f64> {
        match self {
            LawSpec::LuGre => vec![se[0], se[2]],
            _ => self.mu(se),
        }
    }

    /// `μ_j` in order of `j` for parameter vector `p` (zeros for powers not fitted).
    pub fn mu(&self, p: &[f64]) -> Vec<f64> {
        match self {
            LawSpec::LuGre => vec![p[0], p[2]],
            _ => {
                let pw = self.powers();
                let mut mu = vec![0.0; pw.last().map_or(0, |m| m + 1)];
                for (i, &j) in pw.iter().enumerate() {
                    mu[j] = p[i];
                }
                mu
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn every_spec() -> Vec<LawSpec> {
        let mut all = vec![
            LawSpec::Coulomb,
            LawSpec::Viscous,
            LawSpec::CoulombViscous,
            LawSpec::Quadratic,
            LawSpec::LuGre,
        ];
        all.extend((0..=MAX_POLY_ORDER).map(LawSpec::Poly));
        all
    }

    #[test]
    fn the_name_reads_back_as_the_same_law() {
        for spec in every_spec() {
            assert_eq!(spec.to_string().parse::<LawSpec>(), Ok(spec));
            assert_eq!(spec.name(), spec.to_string());
        }
        // aliases and case
        assert_eq!(" CV ".parse(), Ok(LawSpec::CoulombViscous));
        assert_eq!("coulomb_viscous".parse(), Ok(LawSpec::CoulombViscous));
        assert_eq!("Constant".parse(), Ok(LawSpec::Coulomb));
    }

    #[test]
    fn serde_carries_the_canonical_name() {
        for spec in every_spec() {
            let json = serde_json::to_value(spec).unwrap();
            assert_eq!(json, serde_json::Value::String(spec.to_string()));
            let back: LawSpec = serde_json::from_value(json).unwrap();
            assert_eq!(back, spec);
        }
        let err = serde_json::from_str::<LawSpec>("\"cubic-spline\"").unwrap_err();
        assert!(err.to_string().contains("unknown law"), "{err}");
    }

    #[test]
    fn bad_names_say_which_and_what_to_write() {
        assert_eq!(
            "cubic".parse::<LawSpec>(),
            Err(UnknownLaw::Name("cubic".into()))
        );
        assert_eq!(
            "poly:x".parse::<LawSpec>(),
            Err(UnknownLaw::BadOrder("poly:x".into()))
        );
        assert_eq!(
            "poly:9".parse::<LawSpec>(),
            Err(UnknownLaw::OrderTooHigh(9))
        );
        let msg = UnknownLaw::Name("cubic".into()).to_string();
        for name in [
            "coulomb",
            "viscous",
            "coulomb-viscous",
            "quadratic",
            "poly:N",
            "lugre",
        ] {
            assert!(msg.contains(name), "{msg} does not list {name}");
        }
    }

    #[test]
    fn parameters_map_to_the_law_of_the_name() {
        // Every polynomial spec puts its parameters at its powers, zeros elsewhere.
        for spec in every_spec() {
            let p: Vec<f64> = (1..=spec.n_params()).map(|i| i as f64 / 100.0).collect();
            match (spec, spec.law(&p)) {
                (LawSpec::LuGre, FrictionLaw::LuGre(l)) => {
                    assert_eq!((l.mu_c, l.mu_s, l.sigma2), (p[0], p[1], p[2]))
                }
                (_, FrictionLaw::Polynomial { mu }) => {
                    for (i, &j) in spec.powers().iter().enumerate() {
                        assert_eq!(mu[j], p[i], "{spec}: μ{j}");
                    }
                    let fitted = spec.powers();
                    for (j, &m) in mu.iter().enumerate() {
                        if !fitted.contains(&j) {
                            assert_eq!(m, 0.0, "{spec}: μ{j} not fitted");
                        }
                    }
                }
                (s, l) => panic!("{s} gave {l:?}"),
            }
        }
    }
}

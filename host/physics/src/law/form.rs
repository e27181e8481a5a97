//! The friction law as a configuration file writes it (serde): a table with a `kind` and the
//! law's constants, e.g. in TOML
//!
//! ```toml
//! kind = "coulomb_viscous"   # coulomb, viscous, coulomb_viscous, quadratic, polynomial, stribeck,
//! mu0 = 0.02                 # stribeck_power, hess_soom, dahl, lugre, modified_lugre, lagged
//! mu1 = 0.004
//! ```
//!
//! The pseudo-polynomial laws have their short forms (`coulomb { mu0 }`, `viscous { mu1 }`,
//! `coulomb_viscous { mu0, mu1 }`, `quadratic { mu0, mu1, mu2 }`) besides `polynomial { mu = […] }`;
//! the names of two words read with `-` too (`coulomb-viscous`, as `--law` and `Display` write them);
//! a law is written in the shortest form that holds it. A law read is validated
//! ([`FrictionLaw::validate`]): a NaN or out-of-range constant is refused as it is read.

use super::{FrictionLaw, LuGre, ModifiedLuGre};
use crate::invalid::InvalidParameter;
use serde::{Deserialize, Serialize};

fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

#[derive(Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub(super) enum Form {
    Coulomb {
        mu0: f64,
    },
    Viscous {
        mu1: f64,
    },
    #[serde(alias = "coulomb-viscous")]
    CoulombViscous {
        mu0: f64,
        mu1: f64,
    },
    Quadratic {
        mu0: f64,
        mu1: f64,
        mu2: f64,
    },
    Polynomial {
        mu: Vec<f64>,
    },
    Stribeck {
        mu_c: f64,
        mu_s: f64,
        v_s: f64,
        delta: f64,
        mu_v: f64,
        /// Optional (0 when absent, not written when 0): the quadratic term.
        #[serde(default, skip_serializing_if = "is_zero")]
        mu2: f64,
    },
    #[serde(alias = "stribeck-power")]
    StribeckPower {
        k_ehl: f64,
        n_ehl: f64,
        h_bl: f64,
        p_bl: f64,
        b: f64,
        m: f64,
    },
    #[serde(alias = "hess-soom")]
    HessSoom {
        mu_b: f64,
        c1: f64,
        c2: f64,
    },
    Dahl {
        sigma: f64,
        mu_c: f64,
        alpha: f64,
    },
    #[serde(rename = "lugre")]
    LuGre(LuGre),
    #[serde(rename = "modified_lugre", alias = "modified-lugre")]
    ModifiedLuGre(ModifiedLuGre),
    Lagged {
        steady: Box<FrictionLaw>,
        memory: f64,
    },
}

impl TryFrom<Form> for FrictionLaw {
    type Error = InvalidParameter;
    fn try_from(f: Form) -> Result<FrictionLaw, InvalidParameter> {
        let law = match f {
            Form::Coulomb { mu0 } => FrictionLaw::coulomb(mu0),
            Form::Viscous { mu1 } => FrictionLaw::viscous(mu1),
            Form::CoulombViscous { mu0, mu1 } => FrictionLaw::coulomb_viscous(mu0, mu1),
            Form::Quadratic { mu0, mu1, mu2 } => FrictionLaw::quadratic(mu0, mu1, mu2),
            Form::Polynomial { mu } => FrictionLaw::polynomial(mu),
            Form::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            } => FrictionLaw::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            },
            Form::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            } => FrictionLaw::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            },
            Form::HessSoom { mu_b, c1, c2 } => FrictionLaw::HessSoom { mu_b, c1, c2 },
            Form::Dahl { sigma, mu_c, alpha } => FrictionLaw::Dahl { sigma, mu_c, alpha },
            Form::LuGre(p) => FrictionLaw::LuGre(p),
            Form::ModifiedLuGre(p) => FrictionLaw::ModifiedLuGre(p),
            Form::Lagged { steady, memory } => FrictionLaw::Lagged { steady, memory },
        };
        law.validate()?;
        Ok(law)
    }
}

impl From<FrictionLaw> for Form {
    fn from(law: FrictionLaw) -> Form {
        match law {
            FrictionLaw::Polynomial { mu } => match mu[..] {
                [mu0] => Form::Coulomb { mu0 },
                [0.0, mu1] => Form::Viscous { mu1 },
                [mu0, mu1] => Form::CoulombViscous { mu0, mu1 },
                [mu0, mu1, mu2] => Form::Quadratic { mu0, mu1, mu2 },
                _ => Form::Polynomial { mu },
            },
            FrictionLaw::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            } => Form::Stribeck {
                mu_c,
                mu_s,
                v_s,
                delta,
                mu_v,
                mu2,
            },
            FrictionLaw::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            } => Form::StribeckPower {
                k_ehl,
                n_ehl,
                h_bl,
                p_bl,
                b,
                m,
            },
            FrictionLaw::HessSoom { mu_b, c1, c2 } => Form::HessSoom { mu_b, c1, c2 },
            FrictionLaw::Dahl { sigma, mu_c, alpha } => Form::Dahl { sigma, mu_c, alpha },
            FrictionLaw::LuGre(p) => Form::LuGre(p),
            FrictionLaw::ModifiedLuGre(p) => Form::ModifiedLuGre(p),
            FrictionLaw::Lagged { steady, memory } => Form::Lagged { steady, memory },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn every_kind() -> Vec<FrictionLaw> {
        let lugre = LuGre {
            sigma0: 200.0,
            sigma1: 2.0,
            sigma2: 0.004,
            mu_c: 0.02,
            mu_s: 0.03,
            v_s: 1.0,
            a: 2.0,
        };
        vec![
            FrictionLaw::coulomb(0.02),
            FrictionLaw::viscous(0.004),
            FrictionLaw::coulomb_viscous(0.02, 0.004),
            FrictionLaw::quadratic(0.02, 0.004, 1e-4),
            FrictionLaw::polynomial(vec![0.02, 0.004, 1e-4, 2e-6]),
            FrictionLaw::Stribeck {
                mu_c: 0.02,
                mu_s: 0.03,
                v_s: 0.5,
                delta: 2.0,
                mu_v: 0.004,
                mu2: 0.0,
            },
            FrictionLaw::StribeckPower {
                k_ehl: 0.01,
                n_ehl: 0.5,
                h_bl: 0.1,
                p_bl: 0.0,
                b: 0.3,
                m: 2.0,
            },
            FrictionLaw::HessSoom {
                mu_b: 0.05,
                c1: 2.0,
                c2: 0.004,
            },
            FrictionLaw::Dahl {
                sigma: 100.0,
                mu_c: 0.02,
                alpha: 1.0,
            },
            FrictionLaw::LuGre(lugre),
            FrictionLaw::ModifiedLuGre(ModifiedLuGre {
                sigma0: 200.0,
                sigma1: 2.0,
                sigma2: 0.004,
                mu_c: 0.02,
                alpha0: 0.02,
                alpha1: 0.01,
                v_s: 1.0,
                l1: 0.01,
                l2: 0.1,
            }),
            FrictionLaw::Lagged {
                steady: Box::new(FrictionLaw::coulomb_viscous(0.02, 0.004)),
                memory: 0.5,
            },
        ]
    }

    #[test]
    fn every_law_is_read_back_as_it_was_written() {
        let laws = every_kind();
        let mut kinds: Vec<String> = vec![];
        for law in &laws {
            law.validate().unwrap();
            let text = serde_json::to_string(law).unwrap();
            let back: FrictionLaw = serde_json::from_str(&text).unwrap();
            assert_eq!(&back, law, "{text}");
            let v: serde_json::Value = serde_json::from_str(&text).unwrap();
            kinds.push(v["kind"].as_str().unwrap().to_string());
        }
        // Each law in its own (shortest) form: no two kinds alike.
        let mut unique = kinds.clone();
        unique.sort();
        unique.dedup();
        assert_eq!(unique.len(), laws.len(), "{kinds:?}");
        assert_eq!(
            kinds[..4],
            ["coulomb", "viscous", "coulomb_viscous", "quadratic"]
        );
    }

    #[test]
    fn a_stribeck_curve_with_a_quadratic_term_is_written_with_it_and_without_it_when_zero() {
        let plain =
            r#"{"kind":"stribeck","mu_c":0.02,"mu_s":0.03,"v_s":0.5,"delta":2.0,"mu_v":0.004}"#;
        let law: FrictionLaw = serde_json::from_str(plain).unwrap();
        assert!(matches!(law, FrictionLaw::Stribeck { mu2, .. } if mu2 == 0.0));
        assert_eq!(serde_json::to_string(&law).unwrap(), plain);
        let with = FrictionLaw::Stribeck {
            mu_c: 0.02,
            mu_s: 0.03,
            v_s: 0.5,
            delta: 1.0,
            mu_v: -0.004,
            mu2: 1e-4,
        };
        let text = serde_json::to_string(&with).unwrap();
        assert!(text.contains(r#""mu2":0.0001"#), "{text}");
        assert_eq!(serde_json::from_str::<FrictionLaw>(&text).unwrap(), with);
        assert!(with.to_string().contains("mu2 = 0.0001"), "{with}");
        assert!(!law.to_string().contains("mu2"), "{law}");
    }

    #[test]
    fn the_short_forms_are_the_polynomial_laws() {
        let read = |s: &str| serde_json::from_str::<FrictionLaw>(s).unwrap();
        assert_eq!(
            read(r#"{"kind": "coulomb_viscous", "mu0": 0.02, "mu1": 0.004}"#),
            read(r#"{"kind": "polynomial", "mu": [0.02, 0.004]}"#)
        );
        assert_eq!(
            read(r#"{"kind": "coulomb-viscous", "mu0": 0.02, "mu1": 0.004}"#),
            FrictionLaw::coulomb_viscous(0.02, 0.004)
        );
        assert_eq!(
            read(r#"{"kind": "viscous", "mu1": 0.004}"#),
            FrictionLaw::polynomial(vec![0.0, 0.004])
        );
    }

    #[test]
    fn a_law_out_of_range_or_misspelt_is_refused_as_it_is_read() {
        for (bad, why) in [
            (
                r#"{"kind": "stribeck", "mu_c": 0.02, "mu_s": 0.03, "v_s": -1, "delta": 2, "mu_v": 0}"#,
                "v_s > 0",
            ),
            (
                r#"{"kind": "dahl", "sigma": 0, "mu_c": 0.02, "alpha": 1}"#,
                "sigma > 0",
            ),
            (
                r#"{"kind": "coulomb", "mu0": 0.02, "mu1": 0.004}"#,
                "unknown field",
            ),
            (
                r#"{"kind": "cv", "mu0": 0.02, "mu1": 0.004}"#,
                "unknown variant",
            ),
            (
                r#"{"kind": "lugre", "sigma0": 200, "sigma1": 2, "sigma2": 0, "mu_c": 0.02, "mu_s": 0.03, "v_s": 1, "a": 2, "x": 1}"#,
                "unknown field",
            ),
        ] {
            let e = serde_json::from_str::<FrictionLaw>(bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains(why), "{bad}: {e}");
        }
    }

    #[test]
    fn a_person_reads_the_law_with_the_names_a_file_uses() {
        assert_eq!(
            FrictionLaw::coulomb_viscous(0.02, 0.004).to_string(),
            "coulomb-viscous (mu0 = 0.02, mu1 = 0.004)"
        );
        assert_eq!(
            FrictionLaw::viscous(0.004).to_string(),
            "viscous (mu1 = 0.004)"
        );
        let lagged = FrictionLaw::Lagged {
            steady: Box::new(FrictionLaw::coulomb(0.02)),
            memory: 0.5,
        };
        assert_eq!(
            lagged.to_string(),
            "lagged (memory = 0.5) of coulomb (mu0 = 0.02)"
        );
    }
}

//! Why a rig, a law, a model or a sensor chain was refused before anything was simulated or fitted:
//! one error type, with the constant at fault and the rule it breaks.

/// A constant out of its range. The message names the constant and the rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidParameter {
    /// A rig constant (mass, stiffness, load…) that is not finite and positive.
    #[error("rig constant {name} must be finite and > 0, got {value}")]
    RigConstant {
        /// The constant's name.
        name: &'static str,
        /// The value given.
        value: f64,
    },
    /// A friction law's constants break one of its rules.
    #[error("{law}: {rule}")]
    Law {
        /// The law as written.
        law: String,
        /// The rule its constants break.
        rule: &'static str,
    },
    /// The apparatus damping or the cubic spring term is not finite.
    #[error("apparatus damping and cubic term must be finite")]
    ModelTerms,
    /// A static friction level that is negative or not finite.
    #[error("static friction level must be finite and >= 0, got {0}")]
    StaticLevel(f64),
    /// A sensor noise, range or lag that is negative or not finite.
    #[error("sensor noises, ranges and lag must be finite and >= 0")]
    SensorLevels,
    /// A converter resolution outside 2–32 bits.
    #[error("ADC bits must be 2..=32, got {0}")]
    AdcBits(u32),
    /// Quantisation asked with a full-scale range that is not positive.
    #[error("quantisation needs full-scale ranges > 0")]
    FullScale,
    /// A force-channel low-pass cut-off that is not positive.
    #[error("force cut-off must be > 0 Hz, got {0}")]
    ForceCutoff(f64),
}

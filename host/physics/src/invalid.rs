//! Why a rig, a law, a model or a sensor chain was refused before anything was simulated or fitted:
//! one error type, with the constant at fault and the rule it breaks.

/// A constant out of its range. The message names the constant and the rule.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum InvalidParameter {
    #[error("rig constant {name} must be finite and > 0, got {value}")]
    RigConstant { name: &'static str, value: f64 },
    #[error("{law}: {rule}")]
    Law { law: String, rule: &'static str },
    #[error("apparatus damping and cubic term must be finite")]
    ModelTerms,
    #[error("static friction level must be finite and >= 0, got {0}")]
    StaticLevel(f64),
    #[error("sensor noises, ranges and lag must be finite and >= 0")]
    SensorLevels,
    #[error("ADC bits must be 2..=32, got {0}")]
    AdcBits(u32),
    #[error("quantisation needs full-scale ranges > 0")]
    FullScale,
    #[error("force cut-off must be > 0 Hz, got {0}")]
    ForceCutoff(f64),
}

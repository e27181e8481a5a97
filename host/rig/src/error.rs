//! Why a virtual rig cannot be built or served as asked.

use tribo_physics::InvalidParameter;

/// Why a virtual rig cannot be built or served as asked. The message says which setting and why;
/// the source, where there is one, the detail (the TOML parser's line and column, the model's
/// rule).
#[derive(Debug, thiserror::Error)]
pub enum RigError {
    /// The TOML text is not a rig description: its syntax, a key the rig does not know, a value of
    /// the wrong type, or a friction law out of its range (the law is checked as it is read).
    #[error("the virtual rig's configuration cannot be read")]
    Toml(#[source] toml::de::Error),
    /// A setting out of its range.
    #[error("{name} must be {rule}, got {value}")]
    Setting {
        /// The setting, as the TOML file names it.
        name: &'static str,
        /// What it must be.
        rule: &'static str,
        /// The value given.
        value: f64,
    },
    /// The rig constants and the contact law do not make a model the simulator can run.
    #[error("the virtual rig's model cannot be simulated")]
    Model(#[from] InvalidParameter),
}

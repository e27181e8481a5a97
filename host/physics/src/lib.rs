//! Physics of the oscillating tribometer (f64): the rig as a single-degree-of-freedom oscillator,
//! friction laws, integrators, sensor model, envelopes and friction-law identification.
//!
//! Conventions follow the thesis (F. Majdoub, 2013): dimensionless time `τ = Ω t`, displacement
//! `y = k x / N`, friction `f = F / N`, constants `μ_j` of seed eq. 10–13.
//!
//! - [`law`]: [`law::FrictionLaw`], one value per law (Coulomb … LuGre).
//! - [`law_spec`]: [`LawSpec`], a law by name (parsing, display, serde), as options and files give it.
//! - [`rig`]: [`rig::Rig`] constants and SI ↔ dimensionless conversion.
//! - [`model`]: [`model::Model`], the oscillator (law, apparatus damping, cubic spring).
//! - [`integrate`]: RK4 / Dormand–Prince with velocity-reversal events; [`integrate::Simulator`]
//!   is a stepping API, [`integrate::simulate`] a batch one.
//! - [`bench`](mod@bench): records made the way a lab bench makes them, and the grid every estimator is checked over.
//! - [`sensor`]: noise, 16-bit quantisation, 300 Hz force channel, lag, temperature, ECR.
//! - [`stats`]: least-squares line, mean ± sd, the seeded random generator (defined once).
//! - [`record`]: [`record::Record`] and its CSV formats.
//! - [`envelope`]: Mark & Crandall, Hilbert, averaging envelopes, closed forms, shape.
//! - [`identify`]: Levenberg–Marquardt fits, fast estimators, windowed fits.

#![warn(missing_docs)]

pub mod bench;
pub mod envelope;
pub mod identify;
pub mod integrate;
pub mod invalid;
pub mod law;
pub mod law_spec;
pub mod model;
pub mod record;
pub mod rig;
pub mod sensor;
pub mod stats;
pub mod uncertainty;

pub use identify::FitResult;
pub use integrate::{simulate, Method, SimError, Simulator, State, Trajectory};
pub use invalid::InvalidParameter;
pub use law::FrictionLaw;
pub use law_spec::{LawSpec, UnknownLaw};
pub use model::{Model, Rig};
pub use record::Record;

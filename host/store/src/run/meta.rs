//! What a run folder says of its run in `meta.toml` and `result.toml`: status, device, settings,
//! the host's fit.

use super::*;

/// Where a run stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum RunStatus {
    /// Being recorded (or the recorder was killed: see [`Run::is_complete`]).
    Recording,
    /// Every block and the run's end were received.
    Complete,
    /// Aborted by the operator (Ctrl-C) or the rig; what was received is kept.
    Aborted,
    /// The link was lost before the end; `tribo pull` can fetch the rest.
    Incomplete,
}

impl RunStatus {
    /// Every status, in the order a run goes through them.
    pub const ALL: [RunStatus; 4] = [
        RunStatus::Recording,
        RunStatus::Complete,
        RunStatus::Aborted,
        RunStatus::Incomplete,
    ];

    /// The status's name in `meta.toml` and the catalog.
    pub fn name(self) -> &'static str {
        match self {
            RunStatus::Recording => "recording",
            RunStatus::Complete => "complete",
            RunStatus::Aborted => "aborted",
            RunStatus::Incomplete => "incomplete",
        }
    }
}

impl std::str::FromStr for RunStatus {
    type Err = StoreError;
    fn from_str(s: &str) -> Result<RunStatus> {
        RunStatus::ALL
            .into_iter()
            .find(|x| x.name() == s)
            .ok_or_else(|| {
                StoreError::new(
                    ErrorKind::Invalid,
                    format!(
                        "unknown run status {s:?}: use {}",
                        RunStatus::ALL.map(RunStatus::name).join(", ")
                    ),
                )
            })
    }
}

/// The rig the run was taken on.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct DeviceMeta {
    /// `major.minor.patch`.
    pub firmware: String,
    /// Serial number, 16 hex digits.
    pub serial: String,
    /// The wire protocol version it speaks.
    pub protocol: u16,
    /// Port it was reached through (`COM3`, `/dev/ttyACM0`, `tcp://127.0.0.1:7411`…).
    pub port: String,
}

/// Everything known about a run besides its samples (`meta.toml`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunMeta {
    /// Folder layout version ([`RUN_FORMAT`]).
    pub format: u32,
    /// The run's id in the store (its folder name).
    pub id: String,
    /// Creation time, UTC, `YYYY-MM-DDTHH:MM:SSZ`.
    pub created: String,
    /// The run's status.
    pub status: RunStatus,
    /// Free-text label.
    #[serde(default)]
    pub label: Option<String>,
    /// The sample tested.
    #[serde(default)]
    pub sample: Option<String>,
    /// The lubricant.
    #[serde(default)]
    pub lubricant: Option<String>,
    /// Campaign name and this run's repetition index (from 1), if part of one.
    #[serde(default)]
    pub campaign: Option<String>,
    /// This run's repetition index in its campaign (from 1).
    #[serde(default)]
    pub repeat: Option<u32>,
    /// Normal load N.
    pub load_n: f64,
    /// Moving mass (kg).
    pub mass_kg: f64,
    /// Blade stiffness (N/m).
    pub stiffness_n_per_m: f64,
    /// Sample rate (samples per second).
    pub sample_rate_hz: u32,
    /// Initial amplitude the pin was released from (m).
    pub initial_amplitude_m: f64,
    /// Heater setpoint asked for (`None` = heater off, room temperature).
    #[serde(default)]
    pub temp_setpoint_c: Option<f64>,
    /// Plane temperature measured at the release.
    #[serde(default)]
    pub temp_c: Option<f64>,
    /// The rig it was taken on, if known.
    #[serde(default)]
    pub device: Option<DeviceMeta>,
    /// The rig's own number for the run (what `Pull` asks for).
    #[serde(default)]
    pub device_run_id: Option<u32>,
    /// The full configuration sent to the rig.
    pub config: Configure,
    /// Rig constants (`mass_kg`, `stiffness_n_per_m`, `x0_m`, …) that no plan or flag gave, for
    /// which a default stood in (a campaign plan that leaves them out takes the real rig's).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub defaults: Vec<String>,
}

impl RunMeta {
    /// Metadata for a run about to be taken with `config`.
    pub fn new(config: Configure) -> RunMeta {
        RunMeta {
            format: RUN_FORMAT,
            id: String::new(),
            created: crate::utc_now_rfc3339(),
            status: RunStatus::Recording,
            label: None,
            sample: None,
            lubricant: None,
            campaign: None,
            repeat: None,
            load_n: clean(config.rig.load_n),
            mass_kg: clean(config.rig.mass_kg),
            stiffness_n_per_m: clean(config.rig.stiffness_n_per_m),
            sample_rate_hz: config.sample_rate_hz,
            initial_amplitude_m: clean(config.initial_amplitude_m),
            temp_setpoint_c: None,
            temp_c: None,
            device: None,
            device_run_id: None,
            config,
            defaults: Vec::new(),
        }
    }

    /// The temperature a table groups by: the setpoint if the heater was on, else the measured one.
    pub fn nominal_temp_c(&self) -> Option<f64> {
        self.temp_setpoint_c.or(self.temp_c)
    }

    pub(super) fn folder_name(&self) -> String {
        let stamp: String = self
            .created
            .chars()
            .filter(|c| c.is_ascii_alphanumeric())
            .collect();
        let mut name = format!("{stamp}-N{:.3}", self.load_n);
        if let Some(t) = self.temp_setpoint_c {
            name.push_str(&format!("-T{t:.0}"));
        }
        if let Some(l) = &self.label {
            let clean: String = l
                .chars()
                .map(|c| {
                    if c.is_ascii_alphanumeric() || c == '-' || c == '_' {
                        c
                    } else {
                        '_'
                    }
                })
                .take(40)
                .collect();
            if !clean.is_empty() {
                name.push('-');
                name.push_str(&clean);
            }
        }
        name
    }
}

/// Host-side fit of the run's samples (Coulomb–viscous, tribo-physics' Levenberg–Marquardt).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct HostFit {
    /// The law fitted (stored as its name).
    pub law: tribo_physics::LawSpec,
    /// The Coulomb constant μ0.
    pub mu0: f64,
    /// The viscous constant μ1.
    pub mu1: f64,
    /// RMS envelope misfit relative to the initial amplitude.
    pub gap: f64,
    /// Whether the fit converged.
    pub converged: bool,
    /// Standard errors of μ0 and μ1 (`NaN` in results written before they were recorded).
    #[serde(default = "nan")]
    pub mu0_se: f64,
    /// μ1's standard error (`NaN` in older results).
    #[serde(default = "nan")]
    pub mu1_se: f64,
    /// The fit's verdict (`adequate`, `inadequate`, `not-converged`); `None` in older results.
    #[serde(default)]
    pub verdict: Option<String>,
}

pub(super) fn nan() -> f64 {
    f64::NAN
}

/// `result.toml`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
pub struct Results {
    /// The rig's on-board analysis, if it sent one.
    #[serde(default)]
    pub onboard: Option<OnboardResult>,
    /// The host's fit, if one was made.
    #[serde(default)]
    pub host: Option<HostFit>,
    /// Why the host fit failed, if it did.
    #[serde(default)]
    pub host_error: Option<String>,
}

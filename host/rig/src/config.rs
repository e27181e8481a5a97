//! Configuration of the virtual rig, readable from TOML. Every field has a default (the thesis's
//! rig, a Coulomb–viscous contact, realistic noise), so an empty file is a valid rig:
//!
//! ```toml
//! mass_kg = 0.04
//! stiffness_n_per_m = 1150.0
//! load_n = 0.3
//! x0_m = 667e-6
//! apparatus_mu1 = 0.0011
//! seed = 7
//!
//! [law]
//! kind = "coulomb_viscous"   # any `tribo_physics::FrictionLaw`: "coulomb", "viscous", "quadratic",
//!                            # "polynomial" (mu = […]), "stribeck", "lugre", "lagged", …
//! mu0 = 0.02
//! mu1 = 0.004
//!
//! [noise]
//! displacement_m = 2e-8
//! velocity_m_s = 2e-5
//! force_n = 2e-4
//!
//! [ecr]
//! log10_film = 7.0
//! fluctuation_decades = 0.0   # ~1 for mixed lubrication
//! log10_rest = 9.0
//! ```

use crate::RigError;
use serde::Deserialize;
use tribo_physics::FrictionLaw;

/// Sensor noise, standard deviations (SI).
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Noise {
    /// Displacement, m.
    pub displacement_m: f64,
    /// Velocity, m/s.
    pub velocity_m_s: f64,
    /// Force, N.
    pub force_n: f64,
    /// Thermocouple, °C.
    pub temperature_c: f64,
    /// ECR transimpedance output, V.
    pub ecr_v: f64,
}

impl Default for Noise {
    fn default() -> Self {
        Noise {
            displacement_m: 2e-8,
            velocity_m_s: 2e-5,
            force_n: 2e-4,
            temperature_c: 0.03,
            ecr_v: 2e-4,
        }
    }
}

/// The heated plate: `C dT/dt = P duty − (T − T_ambient) / R`.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ThermalModel {
    /// `T_ambient`, °C.
    pub ambient_c: f64,
    /// `P`, the heater's power at full duty, W.
    pub heater_power_w: f64,
    /// `R`, the plate's thermal resistance to the room, K/W.
    pub resistance_k_per_w: f64,
    /// `C`, the plate's heat capacity, J/K.
    pub capacity_j_per_k: f64,
}

impl Default for ThermalModel {
    fn default() -> Self {
        ThermalModel {
            ambient_c: 22.0,
            heater_power_w: 30.0,
            resistance_k_per_w: 4.0,
            capacity_j_per_k: 20.0,
        }
    }
}

/// The contact's resistance: log10(R/Ω) is `log10_film` while sliding, with Gaussian fluctuations of
/// `fluctuation_decades` (0 = full film, ~1 = mixed lubrication) correlated over `correlation_s`,
/// and `log10_rest` while the pin is at rest.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct EcrModel {
    /// log10(R/Ω) while sliding.
    pub log10_film: f64,
    /// Standard deviation of its fluctuations, decades.
    pub fluctuation_decades: f64,
    /// Correlation time of the fluctuations, s.
    pub correlation_s: f64,
    /// log10(R/Ω) while the pin is at rest.
    pub log10_rest: f64,
}

impl Default for EcrModel {
    fn default() -> Self {
        EcrModel {
            log10_film: 7.0,
            fluctuation_decades: 0.0,
            correlation_s: 0.005,
            log10_rest: 9.0,
        }
    }
}

/// The constants of the rig itself that a configuration may give (the rest — noise, thermal, ECR —
/// describe the simulation).
pub const RIG_CONSTANTS: [&str; 6] = [
    "mass_kg",
    "stiffness_n_per_m",
    "load_n",
    "x0_m",
    "apparatus_mu1",
    "law",
];

/// Acquisition faults to induce (test flags), each at most once per run, timed from the release:
///
/// ```toml
/// [acquisition]
/// stall_reader_after_ms = 500   # the firmware stops reading the converter's ring ...
/// stall_reader_ms = 300         # ... for this long: the DMA laps it, samples are lost
/// adc_overrun_after_ms = 900    # the ADC overruns: the converter is restarted, samples are lost
/// ```
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct AcquisitionFaults {
    /// The firmware stops reading the converter's ring this long after the release, ms.
    pub stall_reader_after_ms: Option<u64>,
    /// How long it stops reading, ms.
    pub stall_reader_ms: u64,
    /// The ADC overruns this long after the release, ms.
    pub adc_overrun_after_ms: Option<u64>,
}

/// The simulated rig.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct VirtualRigConfig {
    /// Moving mass, kg.
    pub mass_kg: f64,
    /// Blade stiffness, N/m.
    pub stiffness_n_per_m: f64,
    /// Normal load, N (0 = unloaded: only the apparatus damping acts).
    pub load_n: f64,
    /// Where the electromagnet holds the pin, m.
    pub x0_m: f64,
    /// Apparatus viscous damping, dimensionless (= 2ζ; the real rig: 0.0011).
    pub apparatus_mu1: f64,
    /// The contact's friction law, dimensionless as in the thesis (μ_j of eq. 10–13); in TOML a
    /// `[law]` table with its `kind` and constants, checked as it is read.
    pub law: FrictionLaw,
    /// A magnet switched off without the reverse pulse lets go this much later (remanence), s.
    pub remanence_s: f64,
    /// Charge-amplifier low-pass of the force channel, Hz.
    pub force_cutoff_hz: f64,
    /// Time lag of the force channel behind the velocity, s (the thesis observed ~3 ms, ch. 4.4).
    pub force_lag_s: f64,
    /// Sensor noise.
    pub noise: Noise,
    /// The heated plate.
    pub thermal: ThermalModel,
    /// The contact's electrical resistance.
    pub ecr: EcrModel,
    /// Seed of every random draw: the same seed gives the same run.
    pub seed: u64,
    /// Serial number announced in the hello.
    pub serial: u64,
    /// Induced acquisition faults (none by default).
    pub acquisition: AcquisitionFaults,
}

impl Default for VirtualRigConfig {
    fn default() -> Self {
        VirtualRigConfig {
            mass_kg: 0.04,
            stiffness_n_per_m: 1150.0,
            load_n: 0.3,
            x0_m: 667e-6,
            apparatus_mu1: 0.0011,
            law: FrictionLaw::coulomb_viscous(0.02, 0.004),
            remanence_s: 0.005,
            force_cutoff_hz: 300.0,
            force_lag_s: 0.003,
            noise: Noise::default(),
            thermal: ThermalModel::default(),
            ecr: EcrModel::default(),
            seed: 1,
            serial: 0x7472_6962_6f00_0001,
            acquisition: AcquisitionFaults::default(),
        }
    }
}

impl VirtualRigConfig {
    /// Parses a TOML description (missing fields take their defaults).
    pub fn from_toml(text: &str) -> Result<VirtualRigConfig, RigError> {
        let c: VirtualRigConfig = toml::from_str(text).map_err(RigError::Toml)?;
        c.validate()?;
        Ok(c)
    }

    /// The rig constants a TOML description leaves to their defaults (of `mass_kg`,
    /// `stiffness_n_per_m`, `load_n`, `x0_m`, `apparatus_mu1`, `law`): what `tribo rig` says stood
    /// in for them.
    pub fn defaulted(text: &str) -> Result<Vec<&'static str>, RigError> {
        let t: toml::Table = toml::from_str(text).map_err(RigError::Toml)?;
        Ok(RIG_CONSTANTS
            .into_iter()
            .filter(|k| !t.contains_key(*k))
            .collect())
    }

    /// Checks the ranges the simulator needs.
    pub fn validate(&self) -> Result<(), RigError> {
        let check = |name: &'static str, rule: &'static str, v: f64, ok: bool| {
            if ok && v.is_finite() {
                Ok(())
            } else {
                Err(RigError::Setting {
                    name,
                    rule,
                    value: v,
                })
            }
        };
        for (name, v) in [
            ("mass_kg", self.mass_kg),
            ("stiffness_n_per_m", self.stiffness_n_per_m),
            ("x0_m", self.x0_m),
            ("force_cutoff_hz", self.force_cutoff_hz),
            ("thermal.heater_power_w", self.thermal.heater_power_w),
            (
                "thermal.resistance_k_per_w",
                self.thermal.resistance_k_per_w,
            ),
            ("thermal.capacity_j_per_k", self.thermal.capacity_j_per_k),
            ("ecr.correlation_s", self.ecr.correlation_s),
        ] {
            check(name, "a positive number", v, v > 0.0)?;
        }
        check(
            "force_lag_s",
            "at most 1 s",
            self.force_lag_s,
            self.force_lag_s <= 1.0,
        )?;
        for (name, v) in [
            ("load_n", self.load_n),
            ("apparatus_mu1", self.apparatus_mu1),
            ("remanence_s", self.remanence_s),
            ("force_lag_s", self.force_lag_s),
            ("noise.displacement_m", self.noise.displacement_m),
            ("noise.velocity_m_s", self.noise.velocity_m_s),
            ("noise.force_n", self.noise.force_n),
            ("noise.temperature_c", self.noise.temperature_c),
            ("noise.ecr_v", self.noise.ecr_v),
            ("ecr.fluctuation_decades", self.ecr.fluctuation_decades),
        ] {
            check(name, ">= 0", v, v >= 0.0)?;
        }
        for (name, v) in [
            ("thermal.ambient_c", self.thermal.ambient_c),
            ("ecr.log10_film", self.ecr.log10_film),
            ("ecr.log10_rest", self.ecr.log10_rest),
        ] {
            check(name, "a finite number", v, true)?;
        }
        // One source of limits: the loads the firmware (and so `tribo run --load`) takes.
        let loads = tribo_wire::limits::LOAD_N;
        check(
            "load_n",
            "within the rig's 0–0.7 N (what `tribo run --load` takes)",
            self.load_n,
            self.load_n >= *loads.start() as f64 && self.load_n <= *loads.end() as f64,
        )?;
        self.law.validate()?;
        // Friction opposes the motion: f(v) ≥ 0 at every sliding speed the rig reaches (y' up to
        // the release amplitude k·x0/N; the lightest load and stiffest blade give about 20).
        if let Some(v) = (1..=400)
            .map(|i| 1e-4 * 1.04f64.powi(i))
            .find(|&v| self.law.steady_force(v) < 0.0)
        {
            return Err(RigError::Setting {
                name: "law",
                rule: "a friction that opposes the motion (f(v) ≥ 0 at every sliding speed; a Coulomb \
                       level μ0 ≥ 0)",
                value: self.law.steady_force(v),
            });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_constants_a_file_leaves_out_are_named() {
        let d = VirtualRigConfig::defaulted("load_n = 0.2\n[law]\nkind = \"coulomb\"\nmu0 = 0.1\n")
            .unwrap();
        assert_eq!(d, ["mass_kg", "stiffness_n_per_m", "x0_m", "apparatus_mu1"]);
        assert_eq!(VirtualRigConfig::defaulted("").unwrap(), RIG_CONSTANTS);
        assert!(VirtualRigConfig::defaulted("load_n = = 1").is_err());
    }

    /// One source of limits: a load `tribo run --load` would refuse, or a friction that pushes the
    /// sphere along, is refused as the rig is described; the thesis's quadratic fits (μ1 < 0 with
    /// μ2 > 0, a friction that stays positive) are not.
    #[test]
    fn the_rig_takes_only_loads_and_laws_a_rig_can_have() {
        let law = |t: &str| VirtualRigConfig::from_toml(&format!("load_n = 0.3\n[law]\n{t}"));
        let e = law("kind = \"coulomb\"\nmu0 = -3\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("opposes the motion"), "{e}");
        assert!(law("kind = \"coulomb_viscous\"\nmu0 = -0.01\nmu1 = 0.01\n").is_err());
        assert!(law("kind = \"quadratic\"\nmu0 = 0.02\nmu1 = -0.004\nmu2 = 0.003\n").is_ok());
        let e = VirtualRigConfig::from_toml("load_n = 5\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("0–0.7 N"), "{e}");
        assert!(VirtualRigConfig::from_toml("load_n = 0\n").is_ok());
    }
}

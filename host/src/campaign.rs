//! Campaign plans (`tribo campaign PLAN.toml`): a series of runs over loads × temperatures × repetitions (the
//! thesis's temperature studies), resumable after an interruption without redoing finished runs.
//!
//! ```toml
//! name = "pao-temperature"    # stored with every run; identifies finished points on resume
//! loads_n = [0.2, 0.4]
//! temps_c = [25, 60]          # optional: omit for runs with the heater off
//! repeats = 3
//! sample = "steel AISI 52100"   # optional: label, sample, lubricant
//! lubricant = "PAO 6"
//! # optional: rate_hz, max_duration_s, mass_kg, stiffness_n_per_m, x0_m,
//! #           ramp_c_per_min, settle_tol_c, settle_s, settle_timeout_s, prompt_load
//! ```
//!
//! The settle defaults are `tribo run`'s (`tribo_wire::limits`: within 0.5 °C for 30 s, giving up
//! after 1800 s). While the campaign runs, prompts included, a heartbeat keeps the rig's lease; every
//! way the campaign ends switches heater and magnet off.

use anyhow::{bail, Context};
use serde::Deserialize;
use std::path::Path;
use tribo_store::run::{list_run_dirs, META_FILE};
use tribo_store::{RunMeta, RunStatus};
use tribo_wire::Configure;

/// A campaign plan (PLAN.toml).
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Plan {
    /// The campaign's name, stored with every run; finished points are found by it on resume.
    pub name: String,
    /// Normal loads (N), one series of runs each.
    pub loads_n: Vec<f32>,
    /// Plate temperatures (°C); empty: every run with the heater off.
    #[serde(default)]
    pub temps_c: Vec<f32>,
    /// Runs per load and temperature (default 1).
    #[serde(default = "one")]
    pub repeats: u32,
    /// Label stored with every run.
    #[serde(default)]
    pub label: Option<String>,
    /// The sample (pin and plate materials) stored with every run.
    #[serde(default)]
    pub sample: Option<String>,
    /// The lubricant stored with every run.
    #[serde(default)]
    pub lubricant: Option<String>,
    /// Sampling rate (Hz); default the rig's.
    #[serde(default)]
    pub rate_hz: Option<u32>,
    /// Longest run (s); default the rig's.
    #[serde(default)]
    pub max_duration_s: Option<f32>,
    /// Moving mass m (kg); default the real rig's.
    #[serde(default)]
    pub mass_kg: Option<f32>,
    /// Blade stiffness k (N/m); default the real rig's.
    #[serde(default)]
    pub stiffness_n_per_m: Option<f32>,
    /// Initial displacement x0 at the release (m); default the real rig's.
    #[serde(default)]
    pub x0_m: Option<f32>,
    /// Heater ramp (°C/min, default 10).
    #[serde(default = "ramp")]
    pub ramp_c_per_min: f32,
    /// Settled when the plate is within this of its setpoint (°C; `tribo run`'s default).
    #[serde(default = "tol")]
    pub settle_tol_c: f32,
    /// …for this long (s; `tribo run`'s default).
    #[serde(default = "settle")]
    pub settle_s: f64,
    /// Give up settling after this long (s; `tribo run`'s default).
    #[serde(default = "settle_timeout")]
    pub settle_timeout_s: f64,
    /// Ask the operator to turn the load knob when the load changes (on a terminal).
    #[serde(default = "yes")]
    pub prompt_load: bool,
}

fn one() -> u32 {
    1
}
fn ramp() -> f32 {
    10.0
}
fn tol() -> f32 {
    tribo_wire::limits::SETTLE_TOL_C
}
fn settle() -> f64 {
    tribo_wire::limits::SETTLE_S
}
fn settle_timeout() -> f64 {
    tribo_wire::limits::SETTLE_TIMEOUT_S
}
fn yes() -> bool {
    true
}

/// One run of a campaign.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Point {
    /// Plate temperature (°C); `None`: heater off.
    pub temp_c: Option<f32>,
    /// Normal load (N).
    pub load_n: f32,
    /// Which repetition (from 1).
    pub repeat: u32,
}

impl Plan {
    /// Reads and checks the plan at `path` (a plan that cannot be right is a usage error, status 2).
    pub fn load(path: &Path) -> anyhow::Result<Plan> {
        let text = std::fs::read_to_string(path)
            .with_context(|| format!("cannot read the plan {}", path.display()))?;
        // A plan that cannot be right is a usage error (status 2), as a wrong command line is.
        let p: Plan = toml::from_str(&text).map_err(|e| {
            crate::exit::Usage(format!("the campaign plan {}: {e}", path.display()))
        })?;
        p.check()
            .map_err(|e| crate::exit::Usage(format!("{}: {e:#}", path.display())))?;
        Ok(p)
    }

    fn check(&self) -> anyhow::Result<()> {
        crate::link::plan::check_settle(self.settle_tol_c, self.settle_s, self.settle_timeout_s)
            .map_err(|why| {
                anyhow::anyhow!(
                    "settle_tol_c = {}, settle_s = {}, settle_timeout_s = {}: {why}",
                    self.settle_tol_c,
                    self.settle_s,
                    self.settle_timeout_s
                )
            })?;
        if self.name.trim().is_empty() {
            bail!("`name` must not be empty (it identifies the campaign's runs when resuming)");
        }
        if self.loads_n.is_empty() || self.repeats == 0 {
            bail!("nothing to do: give at least one load in `loads_n` and `repeats` ≥ 1");
        }
        for p in self.points() {
            self.config(p.load_n).validate().map_err(|f| {
                anyhow::anyhow!(
                    "load {} N: {} is out of the rig's range",
                    p.load_n,
                    crate::link::field_name(f)
                )
            })?;
            if let Some(t) = p.temp_c {
                tribo_wire::HeaterSetpoint {
                    setpoint_c: t,
                    ramp_c_per_min: self.ramp_c_per_min,
                }
                .validate()
                .map_err(|f| {
                    anyhow::anyhow!(
                        "temperature {t} °C: {} is out of the rig's range",
                        crate::link::field_name(f)
                    )
                })?;
            }
        }
        Ok(())
    }

    /// Every run, temperatures outermost (heating is the slow part), then loads, then repetitions.
    pub fn points(&self) -> Vec<Point> {
        let temps: Vec<Option<f32>> = if self.temps_c.is_empty() {
            vec![None]
        } else {
            self.temps_c.iter().map(|t| Some(*t)).collect()
        };
        let mut v = vec![];
        for t in &temps {
            for l in &self.loads_n {
                for r in 1..=self.repeats {
                    v.push(Point {
                        temp_c: *t,
                        load_n: *l,
                        repeat: r,
                    });
                }
            }
        }
        v
    }

    /// The rig constants the plan leaves out, for which the real rig's values stand in (said at the
    /// start and recorded in every run's metadata).
    pub fn defaults(&self) -> Vec<String> {
        let real = Configure::real_rig(0.3);
        [
            (
                "mass_kg",
                self.mass_kg.is_none(),
                format!("{} kg", real.rig.mass_kg),
            ),
            (
                "stiffness_n_per_m",
                self.stiffness_n_per_m.is_none(),
                format!("{} N/m", real.rig.stiffness_n_per_m),
            ),
            (
                "x0_m",
                self.x0_m.is_none(),
                format!("{} m", real.initial_amplitude_m),
            ),
        ]
        .into_iter()
        .filter(|(_, missing, _)| *missing)
        .map(|(k, _, v)| format!("{k}={v}"))
        .collect()
    }

    /// The rig's configuration for a run of this plan at `load` (N).
    pub fn config(&self, load: f32) -> Configure {
        let mut c = Configure::real_rig(load);
        if let Some(v) = self.rate_hz {
            c.sample_rate_hz = v;
        }
        if let Some(v) = self.max_duration_s {
            c.max_duration_s = v;
        }
        if let Some(v) = self.mass_kg {
            c.rig.mass_kg = v;
        }
        if let Some(v) = self.stiffness_n_per_m {
            c.rig.stiffness_n_per_m = v;
        }
        if let Some(v) = self.x0_m {
            c.initial_amplitude_m = v;
        }
        c
    }
}

/// The points of `plan` already done: a complete run of this campaign in `store` with the same
/// load, temperature setpoint and repetition.
pub fn finished(plan: &Plan, store: &Path) -> anyhow::Result<Vec<Point>> {
    // What the metadata claims, checked against the frame log: a run whose log was damaged or
    // cut since it was taken is not done (it is taken again; `tribo table` names it).
    let metas: Vec<RunMeta> = list_run_dirs(store)?
        .iter()
        .filter_map(|d| {
            let m = toml::from_str::<RunMeta>(&std::fs::read_to_string(d.join(META_FILE)).ok()?)
                .ok()?;
            let ours = m.status == RunStatus::Complete
                && m.campaign.as_deref() == Some(plan.name.as_str());
            (ours && tribo_store::Run::open(d).is_ok_and(|r| r.is_complete())).then_some(m)
        })
        .collect();
    Ok(plan
        .points()
        .into_iter()
        .filter(|p| {
            metas.iter().any(|m| {
                m.repeat == Some(p.repeat)
                    && (m.load_n - p.load_n as f64).abs() < 5e-4
                    && match (m.temp_setpoint_c, p.temp_c) {
                        (None, None) => true,
                        (Some(a), Some(b)) => (a - b as f64).abs() < 0.05,
                        _ => false,
                    }
            })
        })
        .collect())
}

//! Writes the report of a simulated run (Coulomb + viscous contact, 16-bit sensors, 300 Hz force
//! channel with a 3 ms lag, ECR and thermocouple) into the directory given (default
//! `target/simulated-report`).
//!
//! `cargo run -p tribo-report --release --example simulated_report -- OUT_DIR [mixed | RECORD.csv]`
//! (`mixed`: a fluctuating ECR; a CSV path: report that record instead of simulating one).
use std::path::PathBuf;
use tribo_physics::integrate::Method;
use tribo_physics::model::Model;
use tribo_physics::sensor::{generate, Ecr, RecordSpec, SensorModel, Thermal};
use tribo_physics::{FrictionLaw, Rig};
use tribo_report::{write_record_report, ReportInputs};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let out = PathBuf::from(
        args.next()
            .unwrap_or_else(|| "target/simulated-report".into()),
    );
    let second = args.next();
    if let Some(csv) = second.as_deref().filter(|a| a.ends_with(".csv")) {
        let rec = tribo_physics::Record::load(std::path::Path::new(csv))?;
        let inputs = ReportInputs {
            title: format!("Record {csv}"),
            ..ReportInputs::default()
        };
        println!(
            "{}",
            write_record_report(&rec, &inputs, &out)?.html.display()
        );
        return Ok(());
    }
    let mixed = second.as_deref() == Some("mixed");
    let model = Model::new(FrictionLaw::quadratic(0.01, 0.02, 0.002)).with_static_mu(0.012);
    let spec = RecordSpec {
        rig: Rig::REAL,
        x0_m: 667e-6,
        v0_m_s: 0.0,
        duration_s: 3.0,
        rate_hz: 5000.0,
    };
    let sensor = SensorModel {
        force_lag_s: 0.003,
        thermal: Some(Thermal {
            start_c: 60.0,
            drift_c_per_s: 0.05,
            noise_c: 0.05,
        }),
        ecr: Some(Ecr {
            log10_sliding: if mixed { 5.0 } else { 7.0 },
            log10_rest: 3.0,
            fluctuation_decades: if mixed { 0.8 } else { 0.05 },
        }),
        ..SensorModel::default()
    };
    let rec = generate(&spec, &model, Method::dopri(1e-9), Some(&sensor))?;
    let inputs = ReportInputs {
        title: "Simulated run: quadratic law μ = (0.01, 0.02, 0.002), N = 0.3 N".into(),
        meta: vec![(
            "source".into(),
            "tribo-physics simulator + sensor model".into(),
        )],
        ..ReportInputs::default()
    };
    let files = write_record_report(&rec, &inputs, &out)?;
    println!("{}", files.html.display());
    for n in files.notes {
        println!("note: {n}");
    }
    Ok(())
}

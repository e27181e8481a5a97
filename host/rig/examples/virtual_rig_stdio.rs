//! Serves a virtual rig over stdin/stdout (wire frames both ways), e.g. behind `socat` or a pipe:
//!
//! ```text
//! cargo run -p tribo-rig --example virtual_rig_stdio -- [rig.toml] [speed]
//! ```
//!
//! Ends at end of input (the "cable" is pulled).
use std::error::Error;
use std::process::ExitCode;
use tribo_rig::{serve, ServeOptions, VirtualRig, VirtualRigConfig};

fn main() -> ExitCode {
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            // The error, then each of its causes.
            let mut line = format!("virtual rig: {e}");
            let mut cause = e.source();
            while let Some(c) = cause {
                line += &format!(": {c}");
                cause = c.source();
            }
            eprintln!("{line}");
            ExitCode::FAILURE
        }
    }
}

fn run() -> Result<(), Box<dyn Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cfg = match args.first() {
        Some(path) => {
            let text = std::fs::read_to_string(path).map_err(|e| format!("{path}: {e}"))?;
            VirtualRigConfig::from_toml(&text)?
        }
        None => VirtualRigConfig::default(),
    };
    let speed = match args.get(1) {
        None => 1.0,
        Some(s) => s.parse::<f64>().map_err(|e| format!("speed {s:?}: {e}"))?,
    };
    let mut rig = VirtualRig::new(cfg)?;
    let opts = ServeOptions {
        speed,
        ..Default::default()
    };
    serve(&mut rig, std::io::stdin(), std::io::stdout(), &opts)?;
    Ok(())
}

//! Serves a virtual rig over stdin/stdout (wire frames both ways), e.g. behind `socat` or a pipe:
//!
//! ```text
//! cargo run -p tribo-rig --example virtual_rig_stdio -- [rig.toml] [speed]
//! ```
//!
//! Ends at end of input (the "cable" is pulled).
use std::process::ExitCode;
use tribo_rig::{serve, ServeOptions, VirtualRig, VirtualRigConfig};

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let cfg = match args.first() {
        Some(path) => match std::fs::read_to_string(path) {
            Ok(text) => VirtualRigConfig::from_toml(&text),
            Err(e) => Err(format!("{path}: {e}")),
        },
        None => Ok(VirtualRigConfig::default()),
    };
    let speed = match args.get(1).map(|s| s.parse::<f64>()) {
        None => Ok(1.0),
        Some(Ok(s)) => Ok(s),
        Some(Err(e)) => Err(format!("speed: {e}")),
    };
    let run = || -> Result<(), String> {
        let mut rig = VirtualRig::new(cfg?)?;
        let opts = ServeOptions {
            speed: speed?,
            ..Default::default()
        };
        serve(&mut rig, std::io::stdin(), std::io::stdout(), &opts).map_err(|e| e.to_string())
    };
    match run() {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("virtual rig: {e}");
            ExitCode::FAILURE
        }
    }
}

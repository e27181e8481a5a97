//! `tribo rig --virtual`: the firmware's application against the physics simulator, behind a
//! pseudo-terminal, so that `tribo run --port …` reaches it through the very code path used for USB.

use crate::link::pty::{make_link, VirtualPort};
use anyhow::{bail, Context};
use std::path::PathBuf;
use std::time::Duration;
use tribo_rig::{LawConfig, ServeOptions, VirtualRigConfig};

/// The simulated rig, from a TOML file and/or flags (flags win).
#[derive(clap::Args, Debug, Clone)]
pub struct VirtualArgs {
    /// Virtual rig description (TOML: mass_kg, stiffness_n_per_m, load_n, [law], [noise], [thermal],
    /// [ecr], seed; see the tribo-rig docs). Missing fields take the thesis's rig.
    #[arg(long)]
    pub config: Option<PathBuf>,
    /// Normal load on the simulated knob, N.
    #[arg(long)]
    pub rig_load: Option<f64>,
    /// Coulomb constant μ0 of the simulated contact (Coulomb–viscous law).
    #[arg(long)]
    pub mu0: Option<f64>,
    /// Viscous constant μ1 of the simulated contact (Coulomb–viscous law).
    #[arg(long)]
    pub mu1: Option<f64>,
    /// Quadratic constant μ2 of the simulated contact (makes the law quadratic: μ0 + μ1 y' + μ2 y'²).
    #[arg(long)]
    pub mu2: Option<f64>,
    /// Room temperature of the simulated plate, °C.
    #[arg(long)]
    pub ambient: Option<f64>,
    /// Multiplies every sensor noise of the simulated rig (0 = noiseless).
    #[arg(long)]
    pub noise: Option<f64>,
    /// Seed of the simulated noise.
    #[arg(long)]
    pub seed: Option<u64>,
    /// Keep the simulated load at --rig-load / the file's `load_n` whatever the host configures
    /// (by default the virtual knob follows each run's --load, rebuilding the rig between runs).
    #[arg(long)]
    pub fixed_load: bool,
    /// Press the rig's button this many seconds after each arming (for `tribo run --button`).
    #[arg(long)]
    pub button_after: Option<f64>,
    /// Device seconds per wall-clock second (`inf`: as fast as the simulation goes).
    #[arg(long, default_value_t = 1.0)]
    pub speed: f64,
}

impl Default for VirtualArgs {
    /// The thesis's rig in real time.
    fn default() -> Self {
        VirtualArgs {
            config: None,
            rig_load: None,
            mu0: None,
            mu1: None,
            mu2: None,
            ambient: None,
            noise: None,
            seed: None,
            fixed_load: false,
            button_after: None,
            speed: 1.0,
        }
    }
}

impl VirtualArgs {
    /// The rig configuration these arguments describe.
    pub fn rig_config(&self) -> anyhow::Result<VirtualRigConfig> {
        let mut c = match &self.config {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("cannot read {}", p.display()))?;
                VirtualRigConfig::from_toml(&text)
                    .map_err(|e| anyhow::anyhow!("{}: {e}", p.display()))?
            }
            None => VirtualRigConfig::default(),
        };
        if let Some(l) = self.rig_load {
            c.load_n = l;
        }
        if self.mu0.is_some() || self.mu1.is_some() || self.mu2.is_some() {
            let (m0, m1) = match &c.law {
                LawConfig::Quadratic { mu0, mu1, .. } => (*mu0, *mu1),
                l => l.coulomb_viscous().unwrap_or((0.02, 0.004)),
            };
            let (mu0, mu1) = (self.mu0.unwrap_or(m0), self.mu1.unwrap_or(m1));
            c.law = match self.mu2 {
                Some(mu2) => LawConfig::Quadratic { mu0, mu1, mu2 },
                None => LawConfig::CoulombViscous { mu0, mu1 },
            };
        }
        if let Some(t) = self.ambient {
            c.thermal.ambient_c = t;
        }
        if let Some(k) = self.noise {
            if !(k.is_finite() && k >= 0.0) {
                bail!("--noise must be a factor ≥ 0 (1 = the default noise, 0 = none)");
            }
            let n = &mut c.noise;
            n.displacement_m *= k;
            n.velocity_m_s *= k;
            n.force_n *= k;
            n.temperature_c *= k;
            n.ecr_v *= k;
        }
        if let Some(s) = self.seed {
            c.seed = s;
        }
        c.validate()
            .map_err(|e| anyhow::anyhow!("virtual rig: {e}"))?;
        if self.speed.is_nan() || self.speed <= 0.0 {
            bail!("--speed must be a positive number (1 = real time, inf = as fast as possible)");
        }
        Ok(c)
    }

    /// Starts the virtual rig on a new pseudo-terminal (served on a thread); returns the port.
    pub fn start(&self) -> anyhow::Result<(PathBuf, VirtualRigConfig)> {
        let cfg = self.rig_config()?;
        let port = VirtualPort::open()?;
        let path = port.path().to_owned();
        let opts = ServeOptions {
            speed: self.speed,
            max_wait: Duration::from_millis(2),
        };
        if let Some(b) = self.button_after {
            if !(b.is_finite() && b >= 0.0) {
                bail!("--button-after must be a number of seconds ≥ 0");
            }
        }
        port.spawn_with(cfg.clone(), opts, !self.fixed_load, self.button_after)?;
        Ok((path, cfg))
    }
}

/// Arguments of `tribo rig`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Run the virtual rig (the only kind this command can start).
    #[arg(long = "virtual")]
    pub virtual_rig: bool,
    #[command(flatten)]
    pub rig: VirtualArgs,
    /// Symlink to the pseudo-terminal.
    #[arg(long, default_value = super::run::DEFAULT_VIRTUAL_LINK)]
    pub link: PathBuf,
}

/// Runs the subcommand (until Ctrl-C).
pub fn run(args: Args) -> anyhow::Result<()> {
    if !args.virtual_rig {
        bail!("`tribo rig` starts the virtual rig: add --virtual (a real rig needs no command: plug it in and use --port)");
    }
    let (path, cfg) = args.rig.start()?;
    make_link(&args.link, &path)?;
    let link = args.link.clone();
    ctrlc::set_handler(move || {
        let _ = std::fs::remove_file(&link);
        eprintln!("\nvirtual rig stopped");
        std::process::exit(0);
    })
    .context("cannot install the Ctrl-C handler")?;
    println!(
        "virtual rig listening on {} (linked as {})",
        path.display(),
        args.link.display()
    );
    println!(
        "  m = {} kg, k = {} N/m, load {} N{}, contact {:?}, apparatus μ1 {}, seed {}, speed ×{}",
        cfg.mass_kg,
        cfg.stiffness_n_per_m,
        cfg.load_n,
        if args.rig.fixed_load {
            " (fixed)"
        } else {
            " (follows each run's --load)"
        },
        cfg.law,
        cfg.apparatus_mu1,
        cfg.seed,
        args.rig.speed
    );
    if let Some(p) = &args.rig.config {
        let d = std::fs::read_to_string(p)
            .map_err(|e| e.to_string())
            .and_then(|t| VirtualRigConfig::defaulted(&t))
            .unwrap_or_default();
        if !d.is_empty() {
            println!(
                "  {} does not give {}: the thesis's rig stands in (values above)",
                p.display(),
                d.join(", ")
            );
        }
    }
    println!(
        "  try: tribo run --port {} --load {}",
        args.link.display(),
        cfg.load_n
    );
    println!("  Ctrl-C stops it");
    loop {
        std::thread::park();
    }
}

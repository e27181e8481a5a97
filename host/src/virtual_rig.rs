//! The virtual rig as the host starts it: the firmware's application against the physics
//! simulator ([`tribo_rig`]), configured from a TOML file and/or flags ([`VirtualArgs`]), in this
//! process (`tribo demo`, the tests) or served on a local TCP address (`tribo rig --virtual`).

use crate::link::Link;
use anyhow::{bail, Context};
use std::net::TcpListener;
use std::path::PathBuf;
use std::time::Duration;
use tribo_physics::FrictionLaw;
use tribo_rig::{
    ChannelFault, ConverterFault, HostEvent, OutputFault, ServeOptions, TcpRig, VirtualRig,
    VirtualRigConfig,
};

/// The simulated rig, from a TOML file and/or flags (flags win).
#[derive(clap::Args, Debug, Clone)]
pub struct VirtualArgs {
    /// Virtual rig description (TOML: mass_kg, stiffness_n_per_m, load_n, `[law]`, `[noise]`,
    /// `[thermal]`, `[ecr]`, seed; see the tribo-rig docs). Missing fields take the thesis's rig.
    ///
    /// The contact's law is a `[law]` table with its kind and constants, e.g.
    /// `kind = "coulomb_viscous"`, `mu0 = 0.02`, `mu1 = 0.004`. Kinds: coulomb (mu0), viscous
    /// (mu1), coulomb_viscous (mu0, mu1), quadratic (mu0, mu1, mu2), polynomial (mu = [μ0, μ1,
    /// …]), stribeck (mu_c, mu_s, v_s, delta, mu_v, and optionally mu2), stribeck_power,
    /// hess_soom, dahl, lugre, modified_lugre, lagged (steady = { kind = …, … }, memory). A
    /// constant out of its range is refused with the rule it breaks.
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
    /// Break an analog input of the simulated converter, to see `tribo selftest` (or a run)
    /// catch it: `stuck:CH` (the channel reads one code, mid-scale, or `stuck:CH=CODE`) or
    /// `dead:CH` (its front end dead: the bottom rail, code 0) or `ground:CH` (the input grounded
    /// through a small offset: code 300, or `ground:CH=CODE`, plus the converter's noise). CH: x
    /// (displacement), v (velocity), f (force), ecr. Repeat the flag for several.
    #[arg(long = "fault", value_name = "FAULT", value_parser = parse_fault)]
    pub faults: Vec<(usize, ChannelFault)>,
    /// Break the simulated thermocouple or its converter: `open` (a broken wire: the chip's
    /// open-circuit flag), `shorted` (over/under-voltage), `zero` or `ones` (MISO stuck: every
    /// byte 0x00 or 0xFF), `stale` (the chip stops answering), `reset` (its configuration lost) or
    /// `cj=C` (the cold junction reads C °C).
    #[arg(long = "tc-fault", value_name = "FAULT", value_parser = parse_tc_fault)]
    pub tc_fault: Option<ConverterFault>,
    /// Wire two analog inputs to each other's signal, e.g. `x,v` (channels as for --fault): the
    /// self-test's channel identity must catch it.
    #[arg(long = "swap-channels", value_name = "A,B", value_parser = parse_swap)]
    pub swap_channels: Option<(usize, usize)>,
    /// Make an output read back wrong: `heater` (its pin high while off), `magnet` (the hold leg
    /// high while off), `ecr-source` (the DAC converts 0), `ecr-range` (PG1 stuck low) or `lamps`
    /// (the red lamp's pin stuck low).
    #[arg(long = "stuck-output", value_name = "OUTPUT", value_parser = parse_output_fault)]
    pub stuck_output: Option<OutputFault>,
    /// Run the simulated HSE this many ppm off its 8 MHz (e.g. 100000: 10 % fast; a negative
    /// value as --hse-error=-60000): the self-test's hse-vs-lsi row must catch an error beyond the
    /// LSI's spread.
    #[arg(long = "hse-error", value_name = "PPM", allow_hyphen_values = true)]
    pub hse_error_ppm: Option<f64>,
    /// Print the rig's console (state-changing commands, faults, resets) on standard output.
    #[arg(skip)]
    pub log_events: bool,
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
            faults: Vec::new(),
            tc_fault: None,
            swap_channels: None,
            stuck_output: None,
            hse_error_ppm: None,
            log_events: false,
        }
    }
}

/// A channel's letter or name: its converter index.
fn channel_index(ch: &str) -> Option<usize> {
    Some(match ch {
        "x" | "displacement" => 0,
        "v" | "velocity" => 1,
        "f" | "force" => 2,
        "ecr" => 3,
        _ => return None,
    })
}

/// A `--swap-channels` value: `A,B`, two different channels of x, v, f, ecr.
pub fn parse_swap(s: &str) -> Result<(usize, usize), String> {
    let usage = "expected A,B: two different channels of x, v, f, ecr (e.g. v,f)";
    let (a, b) = s.split_once(',').ok_or_else(|| format!("{s:?}: {usage}"))?;
    match (channel_index(a.trim()), channel_index(b.trim())) {
        (Some(a), Some(b)) if a != b => Ok((a, b)),
        _ => Err(format!("{s:?}: {usage}")),
    }
}

/// A `--stuck-output` value (see [`VirtualArgs::stuck_output`]).
pub fn parse_output_fault(s: &str) -> Result<OutputFault, String> {
    Ok(match s {
        "heater" => OutputFault::Heater,
        "magnet" => OutputFault::Magnet,
        "ecr-source" => OutputFault::EcrSource,
        "ecr-range" => OutputFault::EcrRange,
        "lamps" => OutputFault::Lamps,
        _ => {
            return Err(format!(
                "{s:?}: expected heater, magnet, ecr-source, ecr-range or lamps"
            ))
        }
    })
}

/// A `--fault` value: `stuck:CH[=CODE]`, `dead:CH` or `ground:CH[=CODE]`, CH one of x, v, f, ecr
/// (or their names).
pub fn parse_fault(s: &str) -> Result<(usize, ChannelFault), String> {
    let usage =
        "expected stuck:CH, stuck:CH=CODE, dead:CH, ground:CH or ground:CH=CODE, CH one of \
                 x, v, f, ecr (e.g. stuck:x)";
    let (kind, rest) = s.split_once(':').ok_or_else(|| format!("{s:?}: {usage}"))?;
    let (ch, code) = match rest.split_once('=') {
        Some((c, code)) => (c, Some(code)),
        None => (rest, None),
    };
    let channel = channel_index(ch).ok_or_else(|| format!("{s:?}: no channel {ch:?}; {usage}"))?;
    let fault = match (kind, code) {
        ("stuck", None) => ChannelFault::Stuck(32_768),
        ("stuck", Some(c)) => ChannelFault::Stuck(
            c.parse()
                .map_err(|_| format!("{s:?}: the code must be a count 0–65535"))?,
        ),
        ("dead", None) => ChannelFault::Dead,
        ("ground", None) => ChannelFault::Grounded(300),
        ("ground", Some(c)) => ChannelFault::Grounded(
            c.parse()
                .map_err(|_| format!("{s:?}: the code must be a count 0–65535"))?,
        ),
        _ => return Err(format!("{s:?}: {usage}")),
    };
    Ok((channel, fault))
}

/// A `--tc-fault` value (see [`VirtualArgs::tc_fault`]).
pub fn parse_tc_fault(s: &str) -> Result<ConverterFault, String> {
    let usage = "expected open, shorted, zero, ones, stale, reset or cj=C (°C)";
    Ok(match s {
        "open" => ConverterFault::Open,
        "shorted" => ConverterFault::Shorted,
        "zero" => ConverterFault::AllZero,
        "ones" => ConverterFault::AllOnes,
        "stale" => ConverterFault::Stale,
        "reset" => ConverterFault::Reset,
        _ => match s.strip_prefix("cj=").map(str::parse::<f32>) {
            Some(Ok(c)) if c.is_finite() => ConverterFault::ColdJunction(c),
            _ => return Err(format!("{s:?}: {usage}")),
        },
    })
}

/// A serial number for a virtual rig: `tribo` in ASCII, then 24 bits from the clock and the
/// process id (the hello shows it as `747269626fXXXXXX`).
pub fn fresh_serial() -> u64 {
    let t = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos() as u64);
    let mut x = t ^ ((std::process::id() as u64) << 32) ^ 0x9e37_79b9_7f4a_7c15;
    // splitmix64's finaliser: every bit of the clock and the pid reaches the low 24.
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^= x >> 31;
    0x7472_6962_6f00_0000 | (x & 0x00ff_ffff)
}

impl VirtualArgs {
    /// The rig configuration these arguments describe.
    pub fn rig_config(&self) -> anyhow::Result<VirtualRigConfig> {
        let (mut c, serial_given) = match &self.config {
            Some(p) => {
                let text = std::fs::read_to_string(p)
                    .with_context(|| format!("cannot read {}", p.display()))?;
                let c =
                    VirtualRigConfig::from_toml(&text).with_context(|| p.display().to_string())?;
                let given =
                    toml::from_str::<toml::Table>(&text).is_ok_and(|t| t.contains_key("serial"));
                (c, given)
            }
            None => (VirtualRigConfig::default(), false),
        };
        // Each virtual rig is a rig of its own: its own serial number (unless its TOML names one),
        // so that "run 3 of rig S" never names runs of two rigs.
        if !serial_given {
            c.serial = fresh_serial();
        }
        if let Some(l) = self.rig_load {
            c.load_n = l;
        }
        if self.mu0.is_some() || self.mu1.is_some() || self.mu2.is_some() {
            // The flags replace the contact's first constants; those they leave keep the
            // file's values when its law is pseudo-polynomial of order ≤ 2.
            let mu = c
                .law
                .mu()
                .filter(|m| m.len() <= 3)
                .unwrap_or(&[0.02, 0.004]);
            let at = |j: usize| mu.get(j).copied().unwrap_or(0.0);
            let (mu0, mu1) = (self.mu0.unwrap_or(at(0)), self.mu1.unwrap_or(at(1)));
            c.law = match self.mu2 {
                Some(mu2) => FrictionLaw::quadratic(mu0, mu1, mu2),
                None => FrictionLaw::coulomb_viscous(mu0, mu1),
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
        c.validate().context("virtual rig")?;
        if self.speed.is_nan() || self.speed <= 0.0 {
            return Err(crate::exit::Usage(format!(
                "--speed {}: must be a positive number (1 = real time, inf = as fast as possible)",
                self.speed
            ))
            .into());
        }
        Ok(c)
    }

    /// How the rig is served: speed, the knob following each run's load (unless `--fixed-load`),
    /// the finger on the button.
    pub fn serve_options(&self) -> anyhow::Result<ServeOptions> {
        let opts = ServeOptions {
            speed: self.speed,
            max_wait: Duration::from_millis(2),
            follow_load: !self.fixed_load,
            button_after_s: self.button_after,
            log_events: self.log_events,
        };
        if self
            .button_after
            .is_some_and(|b| !(b.is_finite() && b >= 0.0))
        {
            bail!("--button-after must be a number of seconds ≥ 0");
        }
        opts.validate().context("virtual rig")?;
        Ok(opts)
    }

    /// The rig these arguments describe, and how to serve it.
    pub fn build(&self) -> anyhow::Result<(VirtualRig, ServeOptions)> {
        let cfg = self.rig_config()?;
        let opts = self.serve_options()?;
        let mut rig = VirtualRig::new(cfg).context("virtual rig")?;
        for &(channel, fault) in &self.faults {
            rig.set_channel_fault(channel, Some(fault));
        }
        rig.set_thermocouple_fault(self.tc_fault);
        rig.swap_channels(self.swap_channels);
        rig.set_output_fault(self.stuck_output);
        if let Some(ppm) = self.hse_error_ppm {
            // ±50 % is far past any error the check must show (the LSI's spread is ~±6 %).
            if !(ppm.is_finite() && (-500_000.0..=500_000.0).contains(&ppm)) {
                bail!("--hse-error takes -500000 to 500000 ppm (±50 %)");
            }
            rig.set_hse_error_ppm(ppm);
        }
        Ok((rig, opts))
    }

    /// Serves the rig on `listen` (`HOST:PORT`, port 0 for any free one) on a thread of its own
    /// until the returned handle is dropped; `events` hears of each host.
    pub fn listen(
        &self,
        listen: &str,
        events: impl FnMut(HostEvent) + Send + 'static,
    ) -> anyhow::Result<(TcpRig, VirtualRigConfig)> {
        let (rig, opts) = self.build()?;
        let cfg = rig.config().clone();
        let listener = TcpListener::bind(listen).map_err(|e| match e.kind() {
            std::io::ErrorKind::AddrInUse => anyhow::anyhow!(
                "{listen} is in use (by another virtual rig?): choose another address with --listen, e.g. \
                 --listen 127.0.0.1:0 for any free port"
            ),
            _ => anyhow::anyhow!("cannot listen on {listen}: {e}"),
        })?;
        let tcp = TcpRig::spawn(rig, listener, opts, events).context("virtual rig")?;
        Ok((tcp, cfg))
    }

    /// The rig in this process, and a link to it: no socket, no terminal. The rig stops when the
    /// link is dropped.
    pub fn in_process(&self) -> anyhow::Result<(Link, VirtualRigConfig)> {
        let (rig, opts) = self.build()?;
        let cfg = rig.config().clone();
        let (from_rig, to_rig, _serving) =
            tribo_rig::in_process(rig, opts).context("cannot start the in-process virtual rig")?;
        Ok((
            Link::from_stream("the in-process virtual rig", from_rig, to_rig),
            cfg,
        ))
    }
}

//! The simulated hardware: every trait of `tribo_firmware::hal` backed by a model.
//!
//! * Pin: `tribo_physics::Simulator` of `m x'' + k x = −N μ(v)` (plus apparatus damping), started at
//!   rest at `x0` when the magnet lets go: at once on the reverse pulse, `remanence_s` later if the
//!   coil is merely switched off. Until then the magnet really holds it at `x0`.
//! * Converter: the board's sample timer (200 MHz kernel clock, the prescaler and reload chosen by
//!   the firmware's own arithmetic, so an unreachable rate is answered with the same rate as the
//!   board's), one scan per trigger at the trigger's instant, written by a modelled DMA round the
//!   same ring the board uses and read back by position (`tribo_firmware::acquisition::
//!   ConverterModel`). Displacement and velocity with white noise, force through the charge
//!   amplifier's 2nd-order 300 Hz low-pass, ECR as the transimpedance output of the range and source
//!   the firmware set; 16-bit counts through the board front end's calibration
//!   (`Configure::real_rig`). Test flags: stall the reader ([`SimHardware::stall_reader_for`]), make
//!   the ADC overrun ([`SimHardware::inject_adc_overrun`]), keep every converted sample
//!   ([`SimHardware::record_truth`]).
//! * Heater: first-order thermal model of the plate; a dead heater or a switch stuck on injectable.
//! * Thermocouple: a MAX31856 model, read every 100 ms by a simulated converter task into its whole
//!   register file (plate with noise at 1/128 °C, cold junction at room temperature), so the
//!   firmware checks what it checks on the board; every converter fault injectable
//!   ([`ConverterFault`]).
//! * Safe state: [`SimHardware::drive_safe`] does what the board's register-level safe state does
//!   (heater, magnet and ECR source off, the pins taken from their timers until the next reset).

use crate::config::VirtualRigConfig;
use crate::RigError;
use tribo_firmware::acquisition::clock::BOARD_TIMER_HZ;
use tribo_firmware::acquisition::{Batch, ConverterModel};
use tribo_firmware::ecr::{FULL_SCALE_V, GAIN_V_PER_A, RANGES};
use tribo_firmware::hal::*;
use tribo_firmware::runstore::memflash::MemFlash;
use tribo_firmware::thermocouple::{self, sr, Registers};
use tribo_firmware::wire::{ChannelCal, Configure, CHANNELS};
use tribo_physics::sensor::{Butterworth2, Rng};
use tribo_physics::{FrictionLaw, Method, Model, Rig, Simulator};

mod hal;

/// What can go wrong with the thermocouple and its converter (fault injection).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ConverterFault {
    /// The thermocouple is open (a wire broke): the converter's OPEN flag.
    Open,
    /// The thermocouple touches a supply or ground: the converter's over/under-voltage flag.
    Shorted,
    /// MISO stuck low or the converter unpowered: every byte reads 0x00.
    AllZero,
    /// MISO stuck high or no converter: every byte reads 0xFF.
    AllOnes,
    /// The cold junction reads this temperature (a broken or overheated converter board).
    ColdJunction(f32),
    /// The converter stops answering: no new reading arrives (the last one grows old).
    Stale,
    /// The converter was reset (brown-out, ESD): its configuration is gone.
    Reset,
}

/// What can go wrong with an analog channel's front end (fault injection: `tribo rig --virtual
/// --fault`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ChannelFault {
    /// The channel reads this code whatever its input (a converter input shorted to a fixed
    /// voltage, a DMA that does not write it).
    Stuck(u16),
    /// The front end is dead: the channel sits at the converter's bottom rail (code 0).
    Dead,
    /// The input is tied to ground through a small offset (a cable shorted, a sensor unplugged
    /// with the input grounded): it reads this code plus the converter's own noise (±1 count),
    /// off the rail, moving, so the rail and stuck checks pass it.
    Grounded(u16),
}

/// An output the board drives that reads back wrong (fault injection: `tribo rig --virtual
/// --stuck-output`): the pin or register as the board's read-back sees it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum OutputFault {
    /// The heater gate pin (PD12) reads high with the heater off (shorted to 3V3, a driver
    /// holding it).
    Heater,
    /// The magnet's hold leg (PE9) reads high with the coil off.
    Magnet,
    /// The ECR DAC converts 0 whatever is written (the DAC not enabled).
    EcrSource,
    /// The range-select pin PG1 reads low whatever is driven.
    EcrRange,
    /// The red lamp's pin (PB14) reads low whatever is driven.
    Lamps,
}

/// The simulated LSI, Hz: a part 0.5 % slow (inside DS12110's 31.4–32.6 kHz at 3.3 V and 25 °C).
pub const SIM_LSI_HZ: f64 = 31_840.0;
/// The clock check's timer as the board runs it: 200 MHz / 8, a capture every 8 LSI periods.
pub const SIM_LSI_TIMER_HZ: u32 = 25_000_000;

/// What can go wrong with the heater's power stage (fault injection).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HeaterStage {
    /// Works as driven.
    Ok,
    /// Does not heat whatever the duty (element open, fuse blown).
    Dead,
    /// Heats at full power whatever the duty (MOSFET shorted).
    StuckOn,
}

/// Where the pin is.
#[derive(Debug, Clone)]
enum Pin {
    /// Held by the magnet at x0 (or resting there before the first arm).
    Held,
    /// Free since `t0_us`.
    Free { t0_us: u64, sim: Box<Simulator> },
}

/// The rig constants, the contact model and the converters' calibration of a configuration
/// (validated). Unloaded: the contact transmits no force whatever its law; only the apparatus
/// damps. The dimensionless model needs N > 0, so it runs at a token load with no contact law.
fn contact(cfg: &VirtualRigConfig) -> Result<(Rig, Model, [ChannelCal; CHANNELS]), RigError> {
    cfg.validate()?;
    let (load, law) = if cfg.load_n > 0.0 {
        (cfg.load_n, cfg.law.clone())
    } else {
        (1e-3, FrictionLaw::polynomial(vec![0.0, 0.0]))
    };
    let rig = Rig::new(cfg.mass_kg, cfg.stiffness_n_per_m, load)?;
    let model = Model::new(law).with_apparatus_damping(cfg.apparatus_mu1);
    model.validate()?;
    let cal = Configure::real_rig(cfg.load_n.min(0.7) as f32).calibration;
    Ok((rig, model, cal))
}

/// The simulated hardware of one rig.
pub struct SimHardware {
    cfg: VirtualRigConfig,
    rig: Rig,
    model: Model,
    cal: [ChannelCal; CHANNELS],
    rng: Rng,
    now_us: u64,
    pin: Pin,
    /// Last free state (x m, v m/s, friction N, stuck).
    last: (f64, f64, f64, bool),
    magnet: MagnetDrive,
    /// The coil was switched off without a reverse pulse at this time: the remanent field holds the
    /// pin until `remanence_s` later.
    remanent_since_us: Option<u64>,
    // Heater.
    temp_c: f64,
    heater_duty: f64,
    pub(crate) heater_stage: HeaterStage,
    // Thermocouple converter: its register file as last read, when, and the next read.
    tc_regs: Option<Registers>,
    tc_read_us: u64,
    tc_next_us: u64,
    pub(crate) tc_fault: Option<ConverterFault>,
    /// The converter task is stuck (no reads at all).
    pub(crate) tc_task_stalled: bool,
    /// Reads the converter task made (its liveness check-ins).
    tc_reads: u64,
    /// The safe state was applied: outputs off and deaf to the application until a reset.
    outputs_locked: bool,
    /// The next thermocouple read panics with this message (a panic inside a task).
    pub(crate) panic_next: Option<String>,
    // ECR.
    ecr_range: u8,
    ecr_source_v: f64,
    ecr_dev: f64,
    // ADC.
    adc: Box<ConverterModel>,
    rate_hz: f64,
    /// Every sample converted since the last start, by stream index (when recording).
    truth: Option<Vec<AnalogSample>>,
    /// Induced acquisition faults still to come in this run (device times).
    stall_at_us: Option<u64>,
    overrun_at_us: Option<u64>,
    force_lp: Butterworth2,
    /// Force samples waiting out the channel's lag.
    force_delay: std::collections::VecDeque<f64>,
    /// Faults of the analog channels' front ends, by converter channel.
    channel_faults: [Option<ChannelFault>; ANALOG_CHANNELS],
    /// Two converter inputs wired to each other's signal (fault injection).
    swapped: Option<(usize, usize)>,
    /// An output that reads back wrong (fault injection).
    pub(crate) output_fault: Option<OutputFault>,
    /// The HSE's error, ppm (fault injection: the crystal or the clock tree not what the firmware
    /// assumes): the clock check's timer ticks that much fast.
    pub(crate) hse_error_ppm: f64,
    /// The clock check's timer is running, and the fraction of a tick carried between intervals
    /// (a counter's quantisation).
    pub(crate) lsi_running: bool,
    pub(crate) lsi_phase: f64,
    // User interface.
    pub(crate) button: bool,
    lamps: Lamps,
    pub(crate) connected: bool,
    pub(crate) out: Vec<u8>,
    /// Bank 2: kept across a rig reset (power loss), with the STM32H743's erase and program times.
    pub(crate) flash: MemFlash<Vec<u8>>,
}

impl SimHardware {
    /// The simulated hardware of a rig configured by `cfg`, at rest.
    pub fn new(cfg: &VirtualRigConfig) -> Result<SimHardware, RigError> {
        let (rig, model, cal) = contact(cfg)?;
        let mut hw = SimHardware {
            cfg: cfg.clone(),
            rig,
            model,
            cal,
            rng: Rng::new(cfg.seed),
            now_us: 0,
            pin: Pin::Held,
            last: (cfg.x0_m, 0.0, 0.0, true),
            magnet: MagnetDrive::Off,
            remanent_since_us: None,
            temp_c: cfg.thermal.ambient_c,
            heater_duty: 0.0,
            heater_stage: HeaterStage::Ok,
            tc_regs: None,
            tc_read_us: 0,
            tc_next_us: 0,
            tc_fault: None,
            tc_task_stalled: false,
            tc_reads: 0,
            outputs_locked: false,
            panic_next: None,
            ecr_range: 0,
            ecr_source_v: 0.0,
            ecr_dev: 0.0,
            adc: Box::new(ConverterModel::new(BOARD_TIMER_HZ)),
            rate_hz: 10_000.0,
            truth: None,
            stall_at_us: None,
            overrun_at_us: None,
            force_lp: Butterworth2::new(cfg.force_cutoff_hz, 10_000.0),
            force_delay: std::collections::VecDeque::new(),
            channel_faults: [None; ANALOG_CHANNELS],
            swapped: None,
            output_fault: None,
            hse_error_ppm: 0.0,
            lsi_running: false,
            lsi_phase: 0.0,
            button: false,
            lamps: Lamps::default(),
            connected: true,
            out: Vec::new(),
            flash: MemFlash::new(
                vec![0xFF; FlashGeometry::H743_BANK2.bytes() as usize],
                FlashGeometry::H743_BANK2,
            )
            .with_h743_timing(),
        };
        // The converter task's first read, at power-on.
        hw.tc_regs = hw.converter_registers();
        hw.tc_next_us = 100_000;
        Ok(hw)
    }

    /// The load knob turned to `load_n` (the rig stays powered: a load is a weight on the arm, not
    /// a setting of the board). Refuses a load the rig cannot take, and leaves the knob where it is.
    pub fn set_load(&mut self, load_n: f64) -> Result<(), RigError> {
        let mut cfg = self.cfg.clone();
        cfg.load_n = load_n;
        let (rig, model, cal) = contact(&cfg)?;
        self.cal = cal;
        self.rig = rig;
        self.model = model;
        self.cfg = cfg;
        Ok(())
    }

    /// Makes converter channel `channel` (0 displacement, 1 velocity, 2 force, 3 ECR) misbehave,
    /// or heals it (`None`). Out-of-range channels are ignored.
    pub fn set_channel_fault(&mut self, channel: usize, fault: Option<ChannelFault>) {
        if let Some(f) = self.channel_faults.get_mut(channel) {
            *f = fault;
        }
    }

    /// Wires converter inputs `a` and `b` to each other's signal (`None`: as built). Out-of-range
    /// channels or `a == b` leave the wiring as built.
    pub fn swap_channels(&mut self, pair: Option<(usize, usize)>) {
        self.swapped = pair.filter(|&(a, b)| a != b && a < ANALOG_CHANNELS && b < ANALOG_CHANNELS);
    }

    /// The run store's flash (to inspect or damage it).
    pub fn flash(&mut self) -> &mut MemFlash<Vec<u8>> {
        &mut self.flash
    }

    /// (μ0, μ1) a Coulomb–viscous fit should find (contact law + apparatus damping).
    pub fn truth(&self) -> Option<(f64, f64)> {
        if self.cfg.load_n == 0.0 {
            return None;
        }
        self.cfg
            .law
            .as_coulomb_viscous()
            .map(|(m0, m1)| (m0, m1 + self.cfg.apparatus_mu1))
    }

    /// Plate temperature, °C (the truth, not the thermocouple's reading).
    pub fn plate_temp_c(&self) -> f64 {
        self.temp_c
    }

    /// Sets the plate temperature (e.g. to provoke the over-temperature cut-off).
    pub fn set_plate_temp_c(&mut self, t: f64) {
        self.temp_c = t;
    }

    /// Duty the heater is driven at (0 once the safe state is applied).
    pub fn heater_duty(&self) -> f64 {
        self.heater_duty
    }

    /// Heating power actually delivered, as a fraction of full power (what the stage does with
    /// the duty: a dead stage 0, a stuck one 1).
    pub fn heater_power(&self) -> f64 {
        match self.heater_stage {
            HeaterStage::Ok => self.heater_duty,
            HeaterStage::Dead => 0.0,
            HeaterStage::StuckOn => 1.0,
        }
    }

    /// The ECR source voltage the firmware set, V.
    pub fn ecr_source_v(&self) -> f64 {
        self.ecr_source_v
    }

    /// Whether heater, magnet and ECR source are all off.
    pub fn outputs_safe(&self) -> bool {
        self.heater_duty == 0.0 && self.magnet == MagnetDrive::Off && self.ecr_source_v == 0.0
    }

    /// Whether the safe state was applied (and holds until the next reset).
    pub fn safe_state_applied(&self) -> bool {
        self.outputs_locked
    }

    /// The board's register-level safe state: heater and magnet off and the ECR source at 0 V, the
    /// pins taken from their timers, so the application's later writes do not reach them until
    /// the next reset.
    pub fn drive_safe(&mut self) {
        self.outputs_locked = false;
        self.set_heater_duty(0.0);
        self.magnet_drive(MagnetDrive::Off);
        self.set_ecr_source(0.0);
        self.outputs_locked = true;
    }

    /// A reset of the MCU: outputs back to their reset state (off), the converter unread, the
    /// injected faults of the MCU's own tasks gone (the rig's physical state, and injected faults
    /// of the hardware around it, remain).
    pub(crate) fn reset_mcu(&mut self) {
        self.outputs_locked = false;
        self.set_heater_duty(0.0);
        self.magnet_drive(MagnetDrive::Off);
        self.set_ecr_source(0.0);
        self.adc.stop();
        self.tc_task_stalled = false;
        self.panic_next = None;
        self.tc_regs = None;
        self.tc_next_us = self.now_us;
    }

    /// Reads the converter task has made so far.
    pub(crate) fn tc_reads(&self) -> u64 {
        self.tc_reads
    }

    /// The converter's register file now, as the board's SPI read would return it.
    fn converter_registers(&mut self) -> Option<Registers> {
        let cj = self.cfg.thermal.ambient_c as f32;
        let t = self.temp_c + self.cfg.noise.temperature_c * self.rng.normal();
        let t = t as f32;
        Some(match self.tc_fault {
            None => thermocouple::encode(t, cj, 0),
            Some(ConverterFault::Open) => thermocouple::encode(t, cj, sr::OPEN),
            Some(ConverterFault::Shorted) => thermocouple::encode(t, cj, sr::OVUV),
            Some(ConverterFault::AllZero) => [0x00; thermocouple::REGISTERS],
            Some(ConverterFault::AllOnes) => [0xFF; thermocouple::REGISTERS],
            Some(ConverterFault::ColdJunction(c)) => thermocouple::encode(t, c, 0),
            Some(ConverterFault::Stale) => return None,
            Some(ConverterFault::Reset) => {
                let mut r = thermocouple::encode(t, cj, 0);
                // Power-on defaults: normally-off, nothing converted since.
                r[0] = 0x00;
                r[12..15].fill(0);
                r
            }
        })
    }

    /// What the electromagnet is driven with now.
    pub fn magnet(&self) -> MagnetDrive {
        self.magnet
    }

    /// The front panel's lamps as they are lit now.
    pub fn lamps(&self) -> Lamps {
        self.lamps
    }

    /// Whether the pin is free (released and not yet caught again).
    pub fn pin_free(&self) -> bool {
        matches!(self.pin, Pin::Free { .. })
    }

    /// Test flag: the converter's reader takes nothing for the next `us` of device time, while the
    /// timer and the DMA go on (a stalled application: the DMA laps the reader).
    pub fn stall_reader_for(&mut self, us: u64) {
        self.adc.stall_reader(self.now_us + us);
    }

    /// Test flag: the ADC overruns at its next conversion (the DMA takes no more conversions until
    /// the reader restarts the converter).
    pub fn inject_adc_overrun(&mut self) {
        self.adc.inject_overrun();
    }

    /// Keeps every sample converted from the next start on (or stops keeping them).
    pub fn record_truth(&mut self, on: bool) {
        self.truth = on.then(Vec::new);
    }

    /// The samples converted since the converter last started, by stream index, if recording.
    pub fn converted(&self) -> Option<&[AnalogSample]> {
        self.truth.as_deref()
    }

    /// The converter's sample clock, if it ran.
    pub fn sample_clock(&self) -> Option<tribo_firmware::wire::SampleClock> {
        self.adc.clock()
    }

    /// The true ECR, log10 Ω, at this instant.
    pub fn log10_ecr(&self) -> f64 {
        let sliding = matches!(self.pin, Pin::Free { .. }) && !self.last.3;
        if sliding {
            self.cfg.ecr.log10_film + self.ecr_dev
        } else {
            self.cfg.ecr.log10_rest
        }
    }

    /// Advances every model to `t_us` (converting the samples due on the way).
    pub(crate) fn advance(&mut self, t_us: u64) {
        if t_us <= self.now_us {
            return;
        }
        self.flash.advance(t_us);
        let dt = (t_us - self.now_us) as f64 * 1e-6;
        // Heater: exact step of the first-order plate model.
        let th = self.cfg.thermal;
        let t_inf = th.ambient_c + th.heater_power_w * self.heater_power() * th.resistance_k_per_w;
        let a = (-dt / (th.resistance_k_per_w * th.capacity_j_per_k)).exp();
        self.temp_c = t_inf + (self.temp_c - t_inf) * a;
        // The converter task reads the MAX31856 every 100 ms (a stale converter answers nothing new).
        while self.tc_next_us <= t_us && !self.tc_task_stalled {
            self.tc_reads += 1;
            if let Some(r) = self.converter_registers() {
                self.tc_regs = Some(r);
                self.tc_read_us = self.tc_next_us;
            }
            self.tc_next_us += 100_000;
        }
        // Remanence: the pin goes once it has faded.
        if let Some(t0) = self.remanent_since_us {
            let t_go = t0 + (self.cfg.remanence_s * 1e6) as u64;
            if t_go <= t_us {
                self.remanent_since_us = None;
                self.free_pin(t_go);
            }
        }
        // Induced acquisition faults, once per run.
        if let Some(at) = self.stall_at_us.filter(|&at| at <= t_us) {
            self.stall_at_us = None;
            self.adc
                .stall_reader(at + self.cfg.acquisition.stall_reader_ms * 1000);
        }
        if self.overrun_at_us.is_some_and(|at| at <= t_us) {
            self.overrun_at_us = None;
            self.adc.inject_overrun();
        }
        // Converter triggers due up to t_us, each at its own instant.
        while let Some(ts) = self.adc.due(t_us) {
            let s = self.sample_at(ts);
            if let Some(t) = &mut self.truth {
                t.push(s);
            }
            self.adc.convert(&s);
        }
        self.now_us = t_us;
    }

    fn free_pin(&mut self, t0_us: u64) {
        if matches!(self.pin, Pin::Free { .. }) {
            return;
        }
        let after = |ms: Option<u64>| ms.map(|ms| t0_us + ms * 1000);
        self.stall_at_us = after(self.cfg.acquisition.stall_reader_after_ms);
        self.overrun_at_us = after(self.cfg.acquisition.adc_overrun_after_ms);
        let y0 = self.rig.y_of_x(self.cfg.x0_m);
        let sim = Simulator::new(self.model.clone(), y0, 0.0, Method::default());
        self.pin = Pin::Free {
            t0_us,
            sim: Box::new(sim),
        };
    }

    fn state_at(&mut self, t_us: u64) -> (f64, f64, f64, bool) {
        let x0 = self.cfg.x0_m;
        match &mut self.pin {
            Pin::Held => (x0, 0.0, 0.0, true),
            Pin::Free { t0_us, sim } => {
                if t_us < *t0_us {
                    return (x0, 0.0, 0.0, true);
                }
                let tau = self.rig.tau_of_t((t_us - *t0_us) as f64 * 1e-6);
                match sim.step_to(tau) {
                    Ok(s) => {
                        let f_n = if self.cfg.load_n > 0.0 {
                            s.f * self.cfg.load_n
                        } else {
                            0.0
                        };
                        self.last = (
                            self.rig.x_of_y(s.y),
                            self.rig.v_of_ydot(s.ydot),
                            f_n,
                            s.stuck,
                        );
                        self.last
                    }
                    Err(_) => self.last,
                }
            }
        }
    }

    /// The counts a scan triggered at `t_us` converts.
    fn sample_at(&mut self, t_us: u64) -> AnalogSample {
        let (x, v, f, _) = self.state_at(t_us);
        let n = self.cfg.noise;
        let x = x + n.displacement_m * self.rng.normal();
        let v = v + n.velocity_m_s * self.rng.normal();
        // Charge amplifier: lag (a delay line of whole samples), then its low-pass.
        let lag = (self.cfg.force_lag_s * self.rate_hz).round() as usize;
        self.force_delay.push_back(f);
        let f_lagged = if self.force_delay.len() > lag {
            self.force_delay.pop_front().unwrap_or(f)
        } else {
            self.force_delay.front().copied().unwrap_or(f)
        };
        let f = self.force_lp.step(f_lagged) + n.force_n * self.rng.normal();
        // ECR: correlated fluctuation of log10 R (AR(1) at the sample rate).
        let dt = 1.0 / self.rate_hz;
        let rho = (-dt / self.cfg.ecr.correlation_s).exp();
        self.ecr_dev = rho * self.ecr_dev
            + (1.0 - rho * rho).sqrt() * self.cfg.ecr.fluctuation_decades * self.rng.normal();
        let e = self.ecr_output() + n.ecr_v * self.rng.normal();
        let mut s = [
            self.cal[0].to_count(x as f32),
            self.cal[1].to_count(v as f32),
            self.cal[2].to_count(f as f32),
            self.cal[3].to_count(e as f32),
        ];
        if let Some((a, b)) = self.swapped {
            s.swap(a, b);
        }
        for (c, fault) in s.iter_mut().zip(self.channel_faults) {
            match fault {
                Some(ChannelFault::Stuck(code)) => *c = code,
                Some(ChannelFault::Dead) => *c = 0,
                Some(ChannelFault::Grounded(offset)) => {
                    *c = (offset as f64 + self.rng.normal())
                        .round()
                        .clamp(0.0, 65535.0) as u16
                }
                None => {}
            }
        }
        s
    }

    fn ecr_output(&self) -> f64 {
        let r = 10f64.powf(self.log10_ecr());
        let gain = GAIN_V_PER_A[(self.ecr_range.min(RANGES - 1)) as usize] as f64;
        (self.ecr_source_v / r * gain).clamp(0.0, FULL_SCALE_V as f64)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn magnet_holds_until_released_and_remanence_delays_a_plain_switch_off() {
        let cfg = VirtualRigConfig::default();
        let mut hw = SimHardware::new(&cfg).unwrap();
        hw.magnet_drive(MagnetDrive::Hold { duty: 0.6 });
        hw.advance(100_000);
        assert!(!hw.pin_free());
        assert_eq!(hw.state_at(100_000).0, cfg.x0_m);
        hw.magnet_drive(MagnetDrive::Off);
        hw.advance(104_000);
        assert!(!hw.pin_free(), "let go before the remanent field faded");
        hw.advance(106_000);
        assert!(hw.pin_free());
        // Re-held, then released with the reverse pulse: free at once, and moving towards 0.
        hw.magnet_drive(MagnetDrive::Hold { duty: 0.6 });
        hw.advance(200_000);
        hw.magnet_drive(MagnetDrive::Reverse { duty: 0.3 });
        assert!(hw.pin_free());
        let (x, v, _, _) = hw.state_at(205_000);
        assert!(x < cfg.x0_m && v < 0.0);
    }

    fn force_counts(lag_s: f64) -> Vec<f64> {
        let cfg = VirtualRigConfig {
            force_lag_s: lag_s,
            noise: crate::config::Noise {
                displacement_m: 0.0,
                velocity_m_s: 0.0,
                force_n: 0.0,
                temperature_c: 0.0,
                ecr_v: 0.0,
            },
            ..Default::default()
        };
        let mut hw = SimHardware::new(&cfg).unwrap();
        hw.magnet_drive(MagnetDrive::Hold { duty: 0.6 });
        hw.adc_start(10_000);
        hw.magnet_drive(MagnetDrive::Reverse { duty: 0.3 });
        let mut f = Vec::new();
        let mut out = [[0u16; 4]; 256];
        let mut next = 0;
        for ms in 1..=300 {
            hw.advance(ms * 1000);
            let b = hw.adc_read(&mut out);
            assert_eq!(b.first, next, "no sample lost");
            next = b.end();
            f.extend(out[..b.len].iter().map(|s| s[2] as f64));
        }
        f
    }

    #[test]
    fn force_channel_lags_by_the_configured_delay() {
        let f0 = force_counts(0.0);
        let f3 = force_counts(0.003);
        assert!(f0.len() >= 2999);
        let mismatch =
            |shift: usize| -> f64 { (100..2500).map(|i| (f3[i + shift] - f0[i]).abs()).sum() };
        let best = (0..60)
            .min_by(|&a, &b| mismatch(a).total_cmp(&mismatch(b)))
            .unwrap();
        assert_eq!(best, 30, "3 ms at 10 kS/s");
        assert!(
            mismatch(30) < 1e-9 * mismatch(0).max(1.0) + 1.0,
            "the lag must be a pure delay"
        );
    }
}

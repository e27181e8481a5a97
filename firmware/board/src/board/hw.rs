//! The hardware the application task drives directly ([`BoardHw`]): magnet and heater PWM, the
//! thermocouple reading the thermocouple task leaves, the ECR DAC and range switches, the sampler,
//! the button, the lamps and the USB pipe, each behind its `tribo_firmware::hal` trait.

use super::*;

/// The hardware the application task drives directly.
pub(super) struct BoardHw {
    pub(super) shared: &'static Shared,
    pub(super) flash: &'static FlashLink,
    pub(super) magnet_hold: SimplePwmChannel<'static, TIM1>,
    pub(super) magnet_reverse: SimplePwmChannel<'static, TIM1>,
    pub(super) heater: SimplePwmChannel<'static, TIM4>,
    pub(super) ecr_dac: DacChannel<'static, Blocking>,
    pub(super) ecr_range: [Output<'static>; 3],
    pub(super) button: Input<'static>,
    pub(super) lamps: [Output<'static>; 3],
    pub(super) sampler: Sampler,
    /// The safe-state table matched the PAC at boot (`safety::check_table`). When it did not,
    /// heater, magnet and ECR source stay off whatever the application asks: the fatal paths could
    /// not drive them safe.
    pub(super) outputs_allowed: bool,
    /// The boot recovery is reading bank 2: each read is marked first (`flash_read`).
    pub(super) recovering: bool,
    /// TIM16 on the LSI (the self-test's clock check).
    pub(super) lsi: super::lsi::LsiCapture,
}

pub(super) fn fraction(duty: f32) -> u32 {
    if duty.is_finite() {
        (duty.clamp(0.0, 1.0) * 1000.0) as u32
    } else {
        0
    }
}

impl Magnet for BoardHw {
    fn magnet_drive(&mut self, drive: MagnetDrive) {
        let drive = if self.outputs_allowed {
            drive
        } else {
            MagnetDrive::Off
        };
        let (hold, reverse) = match drive {
            MagnetDrive::Off => (0.0, 0.0),
            MagnetDrive::Hold { duty } => (duty, 0.0),
            MagnetDrive::Reverse { duty } => (0.0, duty),
        };
        // Both bridge legs low before the other one is driven.
        self.magnet_hold
            .set_duty_cycle_fraction(fraction(hold), 1000);
        self.magnet_reverse
            .set_duty_cycle_fraction(fraction(reverse), 1000);
    }
}

impl Thermocouple for BoardHw {
    fn read_thermocouple(&mut self) -> Option<ConverterRead> {
        let (regs, at_us) = self.shared.thermocouple.lock(|c| c.get());
        regs.map(|regs| ConverterRead {
            regs,
            age_us: now_us().saturating_sub(at_us),
        })
    }
}

impl HeaterOutput for BoardHw {
    fn set_heater_duty(&mut self, duty: f32) {
        let duty = if self.outputs_allowed { duty } else { 0.0 };
        self.heater.set_duty_cycle_fraction(fraction(duty), 1000);
    }
}

impl EcrFrontEnd for BoardHw {
    fn set_ecr_source(&mut self, volts: f32) {
        let volts = if self.outputs_allowed { volts } else { 0.0 };
        self.ecr_dac
            .set(Value::Bit12Right(tribo_firmware::ecr::source_dac_code(
                volts,
            )));
    }
    fn set_ecr_range(&mut self, range: u8) {
        for (bit, pin) in self.ecr_range.iter_mut().enumerate() {
            pin.set_level(if range & (1 << bit) != 0 {
                Level::High
            } else {
                Level::Low
            });
        }
    }
    fn read_ecr_output(&mut self) -> f32 {
        // The sampler always runs (at its idle rate between runs): the latest scan's ECR channel.
        self.sampler
            .latest_ecr()
            .map_or(f32::NAN, |c| count_to_volts(c as f32))
    }
}

impl SampleSource for BoardHw {
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock> {
        self.sampler.clock_for(rate_hz)
    }
    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        self.sampler.start(rate_hz)
    }
    fn adc_stop(&mut self) {
        self.sampler.stop();
    }
    fn adc_running(&self) -> bool {
        self.sampler.is_acquiring()
    }
    fn adc_next_index(&mut self) -> u64 {
        self.sampler.next_index()
    }
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch {
        self.sampler.read(out)
    }
    fn force_lowpass(&self) -> tribo_firmware::wire::LowPass {
        super::FORCE_LOWPASS
    }
}

impl Button for BoardHw {
    fn button_pressed(&mut self) -> bool {
        self.button.is_high()
    }
}

impl Led for BoardHw {
    fn set_lamps(&mut self, lamps: Lamps) {
        for (pin, on) in self
            .lamps
            .iter_mut()
            .zip([lamps.green, lamps.amber, lamps.red])
        {
            pin.set_level(if on { Level::High } else { Level::Low });
        }
    }
}

impl OutputSense for BoardHw {
    fn sense_outputs(&mut self) -> SensedOutputs {
        use embassy_stm32::pac::{self, gpio::vals::Idr};
        let high = |port: pac::gpio::Gpio, pin: usize| port.idr().read().idr(pin) == Idr::HIGH;
        let bits = |levels: [bool; 3]| {
            levels
                .iter()
                .enumerate()
                .fold(0u8, |b, (i, &l)| b | (l as u8) << i)
        };
        SensedOutputs {
            // The PWM pins are in alternate-function mode: their input buffer is on, so IDR is the
            // pad's level (low at duty 0 unless something else pulls it up).
            heater_pin: Some(high(pac::GPIOD, 12)),
            magnet_pins: Some(high(pac::GPIOE, 9) as u8 | (high(pac::GPIOE, 11) as u8) << 1),
            // The DAC converts DOR1; the pin itself (PA4, analog mode) has no input buffer and
            // the divider's output has no sense wire.
            ecr_dac_code: Some(pac::DAC1.dor(0).read().dor()),
            ecr_range_pins: Some(bits([
                high(pac::GPIOG, 0),
                high(pac::GPIOG, 1),
                high(pac::GPIOG, 2),
            ])),
            lamp_pins: Some(bits([
                high(pac::GPIOB, 0),
                high(pac::GPIOE, 1),
                high(pac::GPIOB, 14),
            ])),
        }
    }
}

impl ClockCheck for BoardHw {
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        self.lsi.lsi_start()
    }
    fn lsi_ready(&mut self) -> bool {
        self.lsi.lsi_ready()
    }
    fn lsi_interval(&mut self) -> LsiInterval {
        self.lsi.lsi_interval()
    }
    fn lsi_stop(&mut self) {
        self.lsi.lsi_stop()
    }
}

impl Link for BoardHw {
    fn send_frame(&mut self, frame: &[u8]) -> bool {
        // No host: refused, so that run frames wait in the store rather than in a pipe that is
        // emptied when the next host connects.
        if !self.shared.connected.load(Ordering::Acquire)
            || self.shared.tx.free_capacity() < frame.len()
        {
            return false;
        }
        // Only this task writes the pipe, so the free space cannot shrink meanwhile.
        let mut rest = frame;
        while !rest.is_empty() {
            match self.shared.tx.try_write(rest) {
                Ok(n) => rest = &rest[n..],
                Err(_) => return false,
            }
        }
        true
    }
}

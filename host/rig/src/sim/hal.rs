//! The firmware's hardware traits (`tribo_firmware::hal`) on the simulated rig: what the
//! application drives and reads, answered by the models of [`super::SimHardware`].

use super::*;

impl Magnet for SimHardware {
    fn magnet_drive(&mut self, drive: MagnetDrive) {
        if self.outputs_locked {
            return;
        }
        let was_holding = matches!(self.magnet, MagnetDrive::Hold { .. });
        match drive {
            MagnetDrive::Hold { duty } if duty > 0.2 => {
                // The magnet pulls the head back to x0 and holds it there.
                self.pin = Pin::Held;
                self.last = (self.cfg.x0_m, 0.0, 0.0, true);
                self.remanent_since_us = None;
            }
            MagnetDrive::Hold { .. } => {}
            MagnetDrive::Reverse { .. } => {
                self.remanent_since_us = None;
                if was_holding || matches!(self.pin, Pin::Held) {
                    self.free_pin(self.now_us);
                }
            }
            MagnetDrive::Off => {
                if was_holding {
                    self.remanent_since_us = Some(self.now_us);
                }
            }
        }
        self.magnet = drive;
    }
}

impl Thermocouple for SimHardware {
    fn read_thermocouple(&mut self) -> Option<ConverterRead> {
        if let Some(msg) = self.panic_next.take() {
            // A panic inside a task, injected: the virtual rig's "panic handler" catches it.
            panic!("{msg}");
        }
        self.tc_regs.map(|regs| ConverterRead {
            regs,
            age_us: self.now_us.saturating_sub(self.tc_read_us),
        })
    }
}

impl HeaterOutput for SimHardware {
    fn set_heater_duty(&mut self, duty: f32) {
        if self.outputs_locked {
            return;
        }
        self.heater_duty = if duty.is_finite() {
            duty.clamp(0.0, 1.0) as f64
        } else {
            0.0
        };
    }
}

impl EcrFrontEnd for SimHardware {
    fn set_ecr_source(&mut self, volts: f32) {
        if self.outputs_locked {
            return;
        }
        self.ecr_source_v = volts as f64;
    }
    fn set_ecr_range(&mut self, range: u8) {
        self.ecr_range = range.min(RANGES - 1);
    }
    fn read_ecr_output(&mut self) -> f32 {
        (self.ecr_output() + self.cfg.noise.ecr_v * self.rng.normal())
            .clamp(0.0, FULL_SCALE_V as f64) as f32
    }
}

impl SampleSource for SimHardware {
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock> {
        self.adc.clock_for(rate_hz)
    }
    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        let clock = self.adc.start(rate_hz, self.now_us)?;
        self.rate_hz = clock.rate_hz();
        if let Some(t) = &mut self.truth {
            t.clear();
        }
        self.force_lp = Butterworth2::new(self.cfg.force_cutoff_hz, self.rate_hz);
        self.force_lp.reset(self.last.2);
        self.force_delay.clear();
        Some(clock)
    }
    fn adc_stop(&mut self) {
        self.adc.stop();
    }
    fn adc_running(&self) -> bool {
        self.adc.is_running()
    }
    fn adc_next_index(&mut self) -> u64 {
        self.adc.next_index()
    }
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch {
        self.adc.read(out)
    }
    fn force_lowpass(&self) -> tribo_wire::LowPass {
        tribo_wire::LowPass::butterworth(2, self.cfg.force_cutoff_hz as f32)
    }
}

impl RunFlash for SimHardware {
    fn flash_geometry(&self) -> FlashGeometry {
        self.flash.flash_geometry()
    }
    fn flash_busy(&mut self) -> bool {
        self.flash.flash_busy()
    }
    fn flash_erase(&mut self, sector: u32) -> bool {
        self.flash.flash_erase(sector)
    }
    fn flash_program(&mut self, offset: u32, data: &[u8]) -> bool {
        self.flash.flash_program(offset, data)
    }
    fn flash_read(&mut self, offset: u32, out: &mut [u8]) -> bool {
        self.flash.flash_read(offset, out)
    }
    fn flash_take_error(&mut self) -> bool {
        self.flash.flash_take_error()
    }
}

impl Button for SimHardware {
    fn button_pressed(&mut self) -> bool {
        self.button
    }
}

impl Led for SimHardware {
    fn set_lamps(&mut self, lamps: Lamps) {
        self.lamps = lamps;
    }
}

impl OutputSense for SimHardware {
    /// The pins as the board would read them: what the models were driven to, or what an injected
    /// [`OutputFault`] makes one read.
    fn sense_outputs(&mut self) -> SensedOutputs {
        let f = self.output_fault;
        let magnet = match self.magnet {
            MagnetDrive::Off => 0,
            MagnetDrive::Hold { duty } => u8::from(duty > 0.0),
            MagnetDrive::Reverse { duty } => u8::from(duty > 0.0) << 1,
        };
        let lamps =
            self.lamps.green as u8 | (self.lamps.amber as u8) << 1 | (self.lamps.red as u8) << 2;
        SensedOutputs {
            heater_pin: Some(self.heater_duty > 0.0 || f == Some(OutputFault::Heater)),
            magnet_pins: Some(if f == Some(OutputFault::Magnet) {
                magnet | 1
            } else {
                magnet
            }),
            ecr_dac_code: Some(if f == Some(OutputFault::EcrSource) {
                0
            } else {
                tribo_firmware::ecr::source_dac_code(self.ecr_source_v as f32)
            }),
            ecr_range_pins: Some(if f == Some(OutputFault::EcrRange) {
                self.ecr_range & !2
            } else {
                self.ecr_range
            }),
            lamp_pins: Some(if f == Some(OutputFault::Lamps) {
                lamps & !4
            } else {
                lamps
            }),
        }
    }
}

impl ClockCheck for SimHardware {
    /// The board's TIM16 on the LSI, simulated: a 25 MHz timer from the HSE (off by the injected
    /// error) capturing every 8 periods of an LSI at [`SIM_LSI_HZ`].
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        self.lsi_running = true;
        Some(LsiTimer {
            timer_hz: SIM_LSI_TIMER_HZ,
            periods_per_capture: 8,
        })
    }
    fn lsi_ready(&mut self) -> bool {
        self.lsi_running
    }
    fn lsi_interval(&mut self) -> LsiInterval {
        if !self.lsi_running {
            return LsiInterval::Timeout;
        }
        let exact = SIM_LSI_TIMER_HZ as f64 * (1.0 + self.hse_error_ppm * 1e-6) * 8.0 / SIM_LSI_HZ;
        let t = exact + self.lsi_phase;
        let ticks = t.floor();
        self.lsi_phase = t - ticks;
        // A 16-bit counter: an interval past its wrap reads modulo 65 536, as on the board.
        LsiInterval::Ticks(ticks as u32 % 65_536)
    }
    fn lsi_stop(&mut self) {
        self.lsi_running = false;
    }
}

impl Link for SimHardware {
    fn send_frame(&mut self, frame: &[u8]) -> bool {
        if self.connected {
            self.out.extend_from_slice(frame);
        }
        self.connected
    }
}

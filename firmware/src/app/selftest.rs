//! The bring-up self-test's checks ([`HostMsg::SelfTest`]), run between runs by the measurements
//! of [`crate::selftest`], one bounded step per poll.

use super::*;
use crate::selftest::{
    ClockProbe, ConverterProbe, Deliberate, FlashProbe, OutputsProbe, Throughput, CONVERTER_MS,
};
use crate::wire::{SelfTestCheck, SelfTestReport, FILLER_MAX};

/// A self-test check in progress.
pub(super) enum SelfTestRun {
    Converter(ConverterProbe),
    Flash(FlashProbe),
    Throughput(Throughput),
    Outputs(OutputsProbe),
    Clock(ClockProbe),
    /// A report that the link did not take yet.
    Report(SelfTestReport),
}

impl App<'_> {
    /// Starts a check: refused while a run is armed, running or ending, while another check runs,
    /// (the flash check) while the last run is still being written to flash, and (a deliberate
    /// panic or stall) while the heater heats or the magnet holds; an accepted deliberate act
    /// first sets the ECR source to 0 V.
    pub(super) fn start_selftest<H: Hardware>(
        &mut self,
        hw: &mut H,
        check: SelfTestCheck,
    ) -> Result<(), ErrorCode> {
        if matches!(self.state, RigState::Armed | RigState::Running)
            || self.ending.is_some()
            || self.selftest.is_some()
            || self.deliberate.is_some()
        {
            return Err(ErrorCode::Busy);
        }
        let run = match check {
            SelfTestCheck::Converter { rate_hz, ms } => {
                if !limits::SAMPLE_RATE_HZ.contains(&rate_hz) {
                    return Err(ErrorCode::OutOfRange(Field::SampleRate));
                }
                if !CONVERTER_MS.contains(&ms) {
                    return Err(ErrorCode::OutOfRange(Field::MaxDuration));
                }
                hw.adc_stop();
                let clock = hw
                    .adc_start(rate_hz)
                    .ok_or(ErrorCode::Interlock(Interlock::NotSampling))?;
                SelfTestRun::Converter(ConverterProbe::new(clock, self.now_us, ms))
            }
            SelfTestCheck::Flash { bytes } => {
                let g = hw.flash_geometry();
                if self.store.flash_state() == crate::runstore::FlashState::Writing {
                    return Err(ErrorCode::Busy);
                }
                let sector = self.store.spare_sector(g).ok_or(ErrorCode::Busy)?;
                SelfTestRun::Flash(FlashProbe::new(sector, bytes, g))
            }
            SelfTestCheck::Throughput { frames, len } => SelfTestRun::Throughput(Throughput {
                next: 0,
                frames,
                len: len.min(FILLER_MAX as u16),
                refused: 0,
            }),
            // Nothing to measure over time: the register file as the thermocouple task last read
            // it, reported at the next poll.
            SelfTestCheck::Thermocouple => {
                let read = hw.read_thermocouple();
                SelfTestRun::Report(SelfTestReport::Thermocouple(
                    crate::wire::ThermocoupleReport {
                        registers: read.map(|r| r.regs),
                        age_us: read.map_or(u64::MAX, |r| r.age_us),
                    },
                ))
            }
            SelfTestCheck::Outputs => {
                // Heater and magnet are checked off (their pins must read low): a live output is
                // not switched off for a check, nor read while it switches.
                if self.heater.heating() {
                    return Err(ErrorCode::Interlock(Interlock::HeaterOn));
                }
                if self.release.is_on() {
                    return Err(ErrorCode::Busy);
                }
                SelfTestRun::Outputs(OutputsProbe::new())
            }
            // Switches nothing the rig drives: the LSI (already on while the IWDG runs) and a
            // timer with no pin.
            SelfTestCheck::Clock { intervals } => {
                SelfTestRun::Clock(ClockProbe::start(hw, intervals, self.now_us))
            }
            SelfTestCheck::Panic | SelfTestCheck::Stall => {
                // The reset it provokes makes the heater safe as well, but a bring-up check must
                // not be the way a live output goes off: the plate is let cool first.
                if self.heater.heating() {
                    return Err(ErrorCode::Interlock(Interlock::HeaterOn));
                }
                // Nor while the coil is on (holding, or its reverse pulse): a disarmed rig keeps holding the pin until its budget
                // runs out, and the reset would drop it. `Busy` (no interlock names the magnet
                // holding; the host's refusal text says it).
                if self.release.is_on() {
                    return Err(ErrorCode::Busy);
                }
                // The ECR source is on whenever the rig is idle (the controller keeps measuring
                // the contact, at most 2 mV and 5 mA): it is not a reason to refuse, but it goes to
                // 0 V now and stays there until the reset, so that the reset switches nothing off.
                hw.set_ecr_source(0.0);
                self.ecr_parked = true;
                self.deliberate = Some(if check == SelfTestCheck::Panic {
                    Deliberate::Panic
                } else {
                    Deliberate::Stall
                });
                return Ok(());
            }
        };
        info!("self-test check started");
        self.selftest = Some(run);
        Ok(())
    }

    /// What the board must do on purpose now that the command was answered (once).
    pub fn take_deliberate(&mut self) -> Option<Deliberate> {
        self.deliberate.take()
    }

    /// The lamps an outputs check drives now, if one runs.
    pub(super) fn selftest_lamps(&self) -> Option<Lamps> {
        match &self.selftest {
            Some(SelfTestRun::Outputs(p)) => Some(p.lamps()),
            _ => None,
        }
    }

    /// An outputs check drives the ECR front end: its controller waits.
    pub(super) fn selftest_drives_ecr(&self) -> bool {
        matches!(self.selftest, Some(SelfTestRun::Outputs(_)))
    }

    /// Ends the check under way without its report (a run armed meanwhile): the clock check's
    /// timer is stopped.
    pub(super) fn selftest_cancel<H: Hardware>(&mut self, hw: &mut H) {
        if let Some(SelfTestRun::Clock(p)) = &mut self.selftest {
            p.cancel(hw);
        }
        self.selftest = None;
    }

    /// A self-test check is under way.
    pub fn selftest_running(&self) -> bool {
        self.selftest.is_some()
    }

    /// Sends one self-test frame; false (nothing counted as dropped: it is sent again) when the
    /// link cannot take it now.
    fn send_selftest<H: Hardware>(&mut self, hw: &mut H, r: &SelfTestReport) -> bool {
        let seq = self.seq;
        match self
            .encoder
            .encode(seq, &DeviceMsg::SelfTest(r.clone()), &mut self.out)
        {
            Ok(bytes) if hw.send_frame(bytes) => {
                self.next_seq();
                true
            }
            _ => false,
        }
    }

    /// One step of the check under way (a poll's share of its work).
    pub(super) fn selftest_step<H: Hardware>(&mut self, hw: &mut H) {
        let Some(mut run) = self.selftest.take() else {
            return;
        };
        let now = self.now_us;
        let report = match &mut run {
            SelfTestRun::Converter(p) => p.step(hw, now).map(|r| {
                hw.adc_stop();
                SelfTestReport::Converter(r)
            }),
            SelfTestRun::Flash(p) => p.step(hw, now).map(SelfTestReport::Flash),
            SelfTestRun::Clock(p) => p.step(hw, now).map(SelfTestReport::Clock),
            SelfTestRun::Outputs(p) => p.step(hw).map(|r| {
                // The ECR front end back as its controller left it.
                hw.set_ecr_range(self.ecr.range());
                hw.set_ecr_source(if self.ecr_parked {
                    0.0
                } else {
                    self.ecr.source_v()
                });
                SelfTestReport::Outputs(r)
            }),
            // One filler per poll: it is built and encoded here (~12k instructions on the M7 for
            // 256 bytes, `cargo xtask target-test app::selftest_checks`), where a run frame is
            // only copied from the store; two would break the poll's budget. That offers the link
            // 512 kB/s, past the 200 kB/s the check asks for: a figure near it is the rig's own
            // limit, not the link's.
            SelfTestRun::Throughput(t) if t.next >= t.frames => Some(SelfTestReport::FillerDone {
                frames: t.frames,
                refused: t.refused,
            }),
            SelfTestRun::Throughput(t) => {
                let mut data = heapless::Vec::<u8, FILLER_MAX>::new();
                for i in 0..t.len as usize {
                    let _ = data.push(crate::wire::filler_byte(t.next, i));
                }
                let index = t.next;
                if self.send_selftest(hw, &SelfTestReport::Filler { index, data }) {
                    t.next += 1;
                } else {
                    t.refused = t.refused.saturating_add(1);
                }
                None
            }
            SelfTestRun::Report(r) => Some(r.clone()),
        };
        self.selftest = match report {
            None => Some(run),
            Some(r) if self.send_selftest(hw, &r) => {
                info!("self-test check done");
                None
            }
            Some(r) => Some(SelfTestRun::Report(r)),
        };
    }
}

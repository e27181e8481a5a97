//! Commands from the host (and the release the button asks for): configure, arm, release.

use super::*;

impl App<'_> {
    pub(super) fn handle<H: Hardware>(&mut self, hw: &mut H, frame: Frame<HostMsg>) {
        let seq = frame.seq;
        if crate::lease::renews(&frame.msg) {
            self.lease.renew(self.now_us);
        }
        let r = match frame.msg {
            HostMsg::Hello { protocol } => {
                let info = self.cfg.device;
                self.send(hw, &DeviceMsg::Hello(info));
                if let Some(b) = self.boot.take() {
                    let msg = DeviceMsg::Boot(b);
                    if !self.send(hw, &msg) {
                        // Not delivered: the next hello gets it.
                        if let DeviceMsg::Boot(b) = msg {
                            self.boot = Some(b);
                        }
                    }
                }
                if protocol == PROTOCOL_VERSION {
                    Ok(())
                } else {
                    Err(ErrorCode::ProtocolMismatch {
                        device: PROTOCOL_VERSION,
                    })
                }
            }
            HostMsg::Configure(c) => self.configure(c),
            HostMsg::SetHeater(sp) => match sp.validate() {
                Ok(()) => {
                    self.heater.set(sp);
                    self.last_setpoint = Some(sp);
                    Ok(())
                }
                Err(f) => Err(ErrorCode::OutOfRange(f)),
            },
            HostMsg::HeaterOff => {
                self.heater.off();
                self.last_setpoint = None;
                hw.set_heater_duty(0.0);
                Ok(())
            }
            HostMsg::Arm => self.arm(hw),
            HostMsg::Disarm => {
                if self.state == RigState::Armed {
                    hw.adc_stop();
                    self.state = RigState::Configured;
                }
                Ok(())
            }
            HostMsg::Release => self.try_release(hw),
            HostMsg::Abort => {
                match self.state {
                    RigState::Running => self.end_run(hw, EndReason::Aborted),
                    RigState::Armed => {
                        hw.adc_stop();
                        self.state = RigState::Configured;
                    }
                    _ => {}
                }
                Ok(())
            }
            HostMsg::Status => {
                let s = self.status();
                self.send(hw, &DeviceMsg::Status(s));
                Ok(())
            }
            HostMsg::Pull { run_id, from_block } => {
                if self.store.run_id() == Some(run_id) && run_id != 0 {
                    self.want = Some(Want::Header { from_block });
                    Ok(())
                } else {
                    Err(ErrorCode::NoRun)
                }
            }
            HostMsg::PullBlocks {
                run_id,
                first,
                count,
            } => {
                if self.store.run_id() == Some(run_id) && run_id != 0 {
                    self.range = Some((first, first.saturating_add(count)));
                    Ok(())
                } else {
                    Err(ErrorCode::NoRun)
                }
            }
            HostMsg::Heartbeat => Ok(()),
            HostMsg::SelfTest(check) => self.start_selftest(hw, check),
            HostMsg::RunFloor { run_id } => {
                self.run_floor = self.run_floor.max(run_id);
                Ok(())
            }
            HostMsg::Safe => {
                info!("safe (host)");
                self.make_safe(hw);
                self.last_setpoint = None;
                Ok(())
            }
        };
        self.reply(hw, seq, r);
    }

    pub(super) fn configure(&mut self, c: Configure) -> Result<(), ErrorCode> {
        c.validate().map_err(ErrorCode::OutOfRange)?;
        if matches!(self.state, RigState::Armed | RigState::Running) {
            return Err(ErrorCode::Busy);
        }
        // What the on-board analysis cannot take is refused now rather than discovered after the run,
        // except an unloaded run (load 0: the apparatus alone), which runs without on-board analysis.
        // (No pipeline is built here, even as a fallback: its 43 KiB would be in this call's stack
        // frame. App::new allocates the one pipeline.)
        let refused = match &mut self.pipeline {
            Some(p) => p.reset(&c).err(),
            None => None,
        };
        match refused {
            None | Some(ConfigError::Load) => {}
            Some(e) => return Err(ErrorCode::OutOfRange(field_of(e))),
        }
        self.config = Some(c);
        self.state = RigState::Configured;
        Ok(())
    }

    pub(super) fn arm<H: Hardware>(&mut self, hw: &mut H) -> Result<(), ErrorCode> {
        self.arm_for(hw, u64::MAX)
    }

    /// Arms with the magnet holding for at most `hold_limit_us` (and the coil's own limits).
    pub(super) fn arm_for<H: Hardware>(
        &mut self,
        hw: &mut H,
        hold_limit_us: u64,
    ) -> Result<(), ErrorCode> {
        let cfg = match (self.state, self.config) {
            (RigState::Running, _) => return Err(ErrorCode::Busy),
            (RigState::Armed, _) => return Ok(()),
            (_, None) => return Err(ErrorCode::NotConfigured),
            (_, Some(c)) => c,
        };
        if let Err(wait_us) = self.release.hold(hw, self.now_us, hold_limit_us) {
            let wait_ms = wait_us.div_ceil(1000).min(u32::MAX as u64) as u32;
            return Err(ErrorCode::MagnetCooling { wait_ms });
        }
        self.pipeline_ready = match &mut self.pipeline {
            Some(p) => p.reset(&cfg).is_ok(),
            None => false,
        };
        // A self-test check of the converter or the flash gives way to the run; an outputs check
        // gives the ECR front end back to its controller first (the run's range track starts
        // from the controller's range).
        if self.selftest_drives_ecr() {
            hw.set_ecr_range(self.ecr.range());
            hw.set_ecr_source(self.ecr.source_v());
        }
        self.selftest_cancel(hw);
        hw.adc_stop();
        // A converter that does not start is caught by the release interlock (NotSampling).
        self.clock = hw.adc_start(cfg.sample_rate_hz);
        self.next_index = 0;
        self.ecr_track = RangeTrack::new(self.ecr.range());
        self.state = RigState::Armed;
        info!("armed");
        Ok(())
    }

    pub(super) fn try_release<H: Hardware>(&mut self, hw: &mut H) -> Result<(), ErrorCode> {
        let Some(cfg) = self.config else {
            return Err(ErrorCode::NotConfigured);
        };
        if self.state == RigState::Running {
            return Err(ErrorCode::Busy);
        }
        let clock = self.clock.filter(|_| hw.adc_running());
        check_interlocks(
            self.state == RigState::Armed,
            self.release.is_holding(),
            clock.is_some(),
            self.heater.healthy(),
        )
        .map_err(ErrorCode::Interlock)?;
        let Some(clock) = clock else {
            return Err(ErrorCode::Interlock(Interlock::NotSampling));
        };
        // Samples converted before this instant belong to the hold.
        self.drain(hw, self.cfg.samples_per_poll as usize);
        if self.state != RigState::Armed {
            return Err(ErrorCode::Interlock(Interlock::NotArmed));
        }
        let now = self.now_us;
        // The run's sample 0 is the first conversion to begin after the magnet lets go.
        self.release.release(hw, now);
        self.run_base = hw.adc_next_index();
        if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
            p.release();
        }
        let step = if core::mem::take(&mut self.skip_run_number) {
            2
        } else {
            1
        };
        // Above every number the host holds, and above the one a reset may have spent.
        self.run_id = self
            .run_id
            .wrapping_add(step)
            .max(self.run_floor.saturating_add(1))
            .max(1);
        self.run_start_us = now;
        self.run_overruns = 0;
        self.ecr.set_hold(false);
        self.builder = Some(BlockBuilder::new(
            self.run_id,
            cfg.channels,
            cfg.calibration[Channel::Temperature.index()],
            clock,
            now,
        ));
        let header = RunHeader {
            run_id: self.run_id,
            config: cfg,
            temp_c: self.heater.temp_c(),
            t_us: now,
            clock,
        };
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::RunStarted(header), &mut self.out)
        {
            self.store.begin(hw, self.run_id, frame);
        }
        // The range the run starts on, and what is left of its settling after a change made while
        // holding: from here on every sample's range is known from these frames.
        let settling = self
            .ecr_track
            .settled_from()
            .saturating_sub(self.run_base)
            .min(u16::MAX as u64) as u16;
        // The analog chain the run's channels go through, as the board is built: a record states
        // its force channel's low-pass, which an analysis would otherwise fit.
        self.push_event(DeviceMsg::Chain(AnalogChain {
            run_id: self.run_id,
            force_lowpass: hw.force_lowpass(),
        }));
        self.push_event(DeviceMsg::EcrRange(EcrRangeChange {
            run_id: self.run_id,
            first_sample: 0,
            range: self.ecr.range(),
            settling,
        }));
        self.want = Some(Want::Header { from_block: 0 });
        self.range = None;
        self.state = RigState::Running;
        info!("released: run {}", self.run_id);
        Ok(())
    }
}

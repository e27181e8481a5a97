//! Samples from the converter into blocks, gaps and ECR range changes as run events, and
//! completed blocks packed into the store.

use super::*;

impl App<'_> {
    /// Stores a run event (a [`DeviceMsg::Gap`] or [`DeviceMsg::EcrRange`] frame, sent in its place
    /// among the blocks). False when the run has used its [`MAX_RUN_EVENTS`] or the store refused it.
    pub(super) fn push_event(&mut self, event: DeviceMsg) -> bool {
        if self.events_free() == 0 {
            return false;
        }
        // The block being packed goes first: records stay in the order they happened.
        self.finish_packing();
        let seq = self.next_seq();
        match self.encoder.encode(seq, &event, &mut self.out) {
            Ok(frame) => self.store.push_event(frame),
            Err(_) => false,
        }
    }

    /// Events the run may still record.
    pub(super) fn events_free(&self) -> usize {
        MAX_RUN_EVENTS.saturating_sub(self.store.events() as usize)
    }

    /// Samples arriving per poll period at the run's rate (at least 8).
    pub(super) fn samples_arriving(&self) -> usize {
        let rate = self.config.map_or(0, |c| c.sample_rate_hz) as u64;
        let per_poll = rate * self.cfg.poll_period_us as u64 / 1_000_000;
        (per_poll.max(8) as usize).min(self.cfg.samples_per_poll as usize)
    }

    /// Most samples one poll takes (see [`AppConfig::samples_per_poll`]).
    pub fn samples_per_poll(&self) -> usize {
        (2 * self.samples_arriving())
            .max(16)
            .min(self.cfg.samples_per_poll as usize)
    }

    /// Moves converted samples to the hold capture or to the run, at most `limit` (the converter's
    /// ring holds the rest until the next poll; a reader that falls a whole ring behind loses
    /// samples, which the indices then show). Returns true when it stopped at that limit (samples
    /// may still be waiting).
    pub(super) fn drain<H: Hardware>(&mut self, hw: &mut H, limit: usize) -> bool {
        const CHUNK: usize = 32;
        let mut buf = [[0u16; ANALOG_CHANNELS]; CHUNK];
        let mut budget = limit;
        while budget > 0 {
            if !matches!(self.state, RigState::Armed | RigState::Running) || self.ending.is_some() {
                return false;
            }
            let want = budget.min(CHUNK);
            let batch = hw.adc_read(&mut buf[..want]);
            if batch.first > self.next_index {
                self.lost(hw, self.next_index, batch.first);
                if !matches!(self.state, RigState::Armed | RigState::Running) {
                    return false;
                }
            }
            self.next_index = self.next_index.max(batch.end());
            let n = batch.len.min(want);
            for (k, s) in buf.iter().take(n).enumerate() {
                if self.take_sample(hw, s, batch.first + k as u64) {
                    return false;
                }
            }
            budget -= n;
            if n < want {
                return false;
            }
        }
        true
    }

    /// Stream samples `from .. to` were lost by the acquisition. In a run: the block in progress is
    /// closed, a [`DeviceMsg::Gap`] frame records exactly which samples of the run are missing, and
    /// the run goes on (the on-board analysis keeps what came before the first gap). Never silent:
    /// also counted in the status and the run's end frame.
    pub(super) fn lost<H: Hardware>(&mut self, hw: &mut H, from: u64, to: u64) {
        let count = to.saturating_sub(from);
        self.overruns = self
            .overruns
            .saturating_add(count.min(u32::MAX as u64) as u32);
        info!("acquisition: samples {} .. {} lost", from, to);
        if self.state != RigState::Running || to <= self.run_base {
            // Hold samples: the zero capture simply has fewer of them.
            return;
        }
        let first = from.max(self.run_base) - self.run_base;
        let end = to - self.run_base;
        let (Ok(first), Ok(end)) = (u32::try_from(first), u32::try_from(end)) else {
            self.end_run(hw, EndReason::MaxDuration);
            return;
        };
        let count = end - first;
        self.run_overruns = self.run_overruns.saturating_add(count);
        if let Some(blk) = self.builder.as_mut().and_then(|b| b.gap(end)) {
            self.store_block(hw, blk);
        }
        if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
            p.gap(count);
        }
        let gap = Gap {
            run_id: self.run_id,
            first_sample: first,
            count,
        };
        if !self.push_event(DeviceMsg::Gap(gap)) {
            // More gaps than a run can list: what is recorded can no longer be described exactly,
            // so the run ends here (its end frame says so).
            self.end_run(hw, EndReason::Overrun);
        }
    }

    /// One sample, with its index in the converter's stream; returns true when it ended the run.
    pub(super) fn take_sample<H: Hardware>(
        &mut self,
        hw: &mut H,
        s: &AnalogSample,
        index: u64,
    ) -> bool {
        let temp = self.heater.temp_c();
        let Some(cfg) = &self.config else {
            return false;
        };
        match self.state {
            RigState::Armed => {
                if let Some(p) = self.pipeline.as_mut().filter(|_| self.pipeline_ready) {
                    let mut sel = [0u16; CHANNELS];
                    let n = select(
                        cfg.channels,
                        cfg.calibration[Channel::Temperature.index()],
                        s,
                        temp,
                        &mut sel,
                    );
                    p.capture(&sel[..n]);
                }
                false
            }
            RigState::Running => {
                // Converted before the release: part of the hold, not of the run.
                let Some(i) = index.checked_sub(self.run_base) else {
                    return false;
                };
                let Ok(i) = u32::try_from(i) else {
                    self.end_run(hw, EndReason::MaxDuration);
                    return true;
                };
                self.ecr_track.add(index, s[3]);
                let Some(b) = &mut self.builder else {
                    return false;
                };
                let mut sel = [0u16; CHANNELS];
                let n = b.select(s, temp, &mut sel);
                let block = b.push_selected(&sel[..n], temp, i);
                let max_samples = cfg.max_samples();
                let ready = self.pipeline_ready;
                let phase = self
                    .pipeline
                    .as_mut()
                    .filter(|_| ready)
                    .map(|p| p.push(&sel[..n]));
                if let Some(blk) = block {
                    self.store_block(hw, blk);
                }
                let reason = match phase {
                    Some(Phase::Finished(StopReason::MaxDuration)) => Some(EndReason::MaxDuration),
                    Some(Phase::Finished(_)) => Some(EndReason::Stopped),
                    _ if i.saturating_add(1) >= max_samples => Some(EndReason::MaxDuration),
                    _ => None,
                };
                if let Some(r) = reason {
                    self.end_run(hw, r);
                    return true;
                }
                false
            }
            _ => false,
        }
    }

    /// The ECR range or source changed (`before` = range and source before the last update): the
    /// samples from the next conversion on settle for the new range's settling time; during a run,
    /// a range change is recorded as a [`DeviceMsg::EcrRange`] frame.
    pub(super) fn ecr_changed<H: Hardware>(&mut self, hw: &mut H, before: (u8, f32)) {
        let (range, source) = (self.ecr.range(), self.ecr.source_v());
        if (range, source.to_bits()) == (before.0, before.1.to_bits()) {
            return;
        }
        let at = if hw.adc_running() {
            hw.adc_next_index()
        } else {
            0
        };
        let settling = self.clock.map_or(0, |c| settling_samples(range, c));
        self.ecr_track.switch(at, range, settling);
        if self.state == RigState::Running && range != before.0 {
            let first_sample = at.saturating_sub(self.run_base).min(u32::MAX as u64) as u32;
            let change = EcrRangeChange {
                run_id: self.run_id,
                first_sample,
                range,
                settling,
            };
            // Keep room for gaps: a run whose range changes this often holds its range instead
            // (switched back at once; the samples settle again from the same instant).
            if self.events_free() <= GAP_RESERVE || !self.push_event(DeviceMsg::EcrRange(change)) {
                self.ecr.set_hold(true);
                self.ecr.set_range(before.0, hw);
                let settling =
                    settling.max(self.clock.map_or(0, |c| settling_samples(before.0, c)));
                self.ecr_track.switch(at, before.0, settling);
            }
        }
    }

    /// Completes a block's ECR and temperature fields (the ECR range is the one used during the
    /// block; the reading at its end sets the next one) and stores it.
    ///
    /// The resistance is computed from the mean of the block's ECR samples converted on the current
    /// range and source after they settled (NaN when the block has none, e.g. all settling, or when
    /// they were outside the range's span); that reading then sets the range and source for what
    /// follows.
    pub(super) fn store_block<H: Hardware>(&mut self, hw: &mut H, mut blk: SampleBlock) {
        blk.ecr_range = self
            .ecr_track
            .range_at(self.run_base + blk.first_sample as u64);
        blk.log10_ecr_ohm = match self.ecr_track.take_mean() {
            Some(count) => {
                let before = (self.ecr.range(), self.ecr.source_v());
                let l = self.ecr.update(count_to_volts(count), hw);
                self.ecr_changed(hw, before);
                // A reading out of the range's span only moves the range: no resistance for it.
                if self.ecr.measured() {
                    l
                } else {
                    f32::NAN
                }
            }
            None => f32::NAN,
        };
        blk.temp_c = self.heater.temp_c();
        // Both places taken: the oldest is packed and stored now, whatever it costs.
        if self.packing.is_full() {
            while self.pack_step() && self.packing.is_full() {}
        }
        let seq = self.next_seq();
        self.blocks_completed = self.blocks_completed.wrapping_add(1);
        // Cannot fail for a block the builder made (consistent, at most BLOCK_LEN samples).
        if let Ok(packed) = PackedBlock::start(&blk) {
            let _ = self.packing.push_back(Packing {
                seq,
                blk,
                packed,
                packer: Packer::new(),
                packed_all: false,
            });
        }
    }

    /// Packs one channel of the block on its way to the store, or, once all are, frames it and
    /// stores it. False when there was nothing to do.
    pub(super) fn pack_step(&mut self) -> bool {
        let Some(p) = self.packing.front_mut() else {
            return false;
        };
        if !p.packed_all {
            match p.packed.pack_step(&p.blk, &mut p.packer) {
                Ok(done) => p.packed_all = done,
                // Cannot happen for a block the builder made; dropped rather than stalling.
                Err(_) => {
                    self.packing.pop_front();
                }
            }
            return true;
        }
        if let Some(p) = self.packing.pop_front() {
            let k = p.packed.block;
            if let Ok(frame) =
                self.encoder
                    .encode(p.seq, &DeviceMsg::Packed(p.packed), &mut self.out)
            {
                self.store.push_block(k, frame);
            }
        }
        true
    }

    /// Packs and stores the blocks on their way to the store now, whatever it costs (another record
    /// must follow them: an event, the end of the run).
    pub(super) fn finish_packing(&mut self) {
        while self.pack_step() {}
    }
}

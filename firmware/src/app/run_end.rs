//! The end of a run: the end-of-run analysis spread over polls, then the result and end frames.

use super::*;

impl App<'_> {
    /// Ends the run: no sample is taken after this; the result and end frames follow once the
    /// end-of-run analysis is done ([`App::analyse_step`], a bounded part of it per poll).
    pub(super) fn end_run<H: Hardware>(&mut self, hw: &mut H, reason: EndReason) {
        if self.state != RigState::Running || self.ending.is_some() {
            return;
        }
        if let Some(blk) = self.builder.as_mut().and_then(BlockBuilder::flush) {
            self.store_block(hw, blk);
        }
        hw.adc_stop();
        let (blocks, samples) = self
            .builder
            .as_ref()
            .map_or((0, 0), |b| (b.blocks(), b.samples()));
        // The result and end frames wait for the last blocks to be packed and, in an analysed
        // run, for the fit: both spread over the next polls.
        let job = self
            .pipeline
            .as_ref()
            .filter(|_| self.pipeline_ready)
            .map(|p| p.start_finish(self.run_id));
        self.ending = Some(Ending {
            job,
            reason,
            blocks,
            samples,
        });
        info!("run {} over", self.run_id);
    }

    /// Advances the end-of-run analysis, if one is pending, by a bounded number of rows; once it
    /// is done and the last block is stored, stores the result and end frames.
    pub(super) fn analyse_step(&mut self) {
        if !self.packing.is_empty() {
            return;
        }
        let rate = self.config.map_or(1, |c| c.sample_rate_hz);
        let Some(e) = &mut self.ending else { return };
        let result = match (self.pipeline.as_ref(), &mut e.job) {
            (Some(p), Some(job)) => p.finish_step(job, self.cfg.finish_rows_per_poll),
            _ => Some(unanalysed(self.run_id, e.samples, rate)),
        };
        let Some(result) = result else { return };
        if let Some(e) = self.ending.take() {
            self.complete_run(result, e.reason, e.blocks, e.samples);
        }
    }

    /// Stores the result and end frames of the run; it is finished.
    pub(super) fn complete_run(
        &mut self,
        mut result: OnboardResult,
        reason: EndReason,
        blocks: u32,
        samples: u32,
    ) {
        if reason == EndReason::Aborted {
            result.verdict = Verdict::Aborted;
        }
        self.finish_packing();
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::Result(result), &mut self.out)
        {
            self.store.set_result(frame);
        }
        let end = RunEnd {
            run_id: self.run_id,
            blocks,
            samples,
            overruns: self.run_overruns,
            reason,
        };
        let seq = self.next_seq();
        if let Ok(frame) = self
            .encoder
            .encode(seq, &DeviceMsg::RunEnded(end), &mut self.out)
        {
            self.store.set_end(frame);
        }
        self.ecr.set_hold(false);
        self.state = RigState::Finished;
        info!("run {} ended", self.run_id);
    }
}

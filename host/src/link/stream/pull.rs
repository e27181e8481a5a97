//! Pulls: what the live stream missed, asked for again in rounds (`PullBlocks` for the missing
//! ranges, then `Pull` for the tail), with backoff, until the run is whole or the rig is known
//! not to hold the rest.

use super::{run_of, Streamer};
use crate::link::progress::Progress;
use crate::link::{LinkError, LinkErrorKind};
use std::time::{Duration, Instant};
use tribo_store::run::block_ranges;
use tribo_wire::{DeviceMsg, ErrorCode, HostMsg, RigState};

/// How one pull round ended.
enum RoundEnd {
    /// The run's end frame came after its header: the rig sent all it holds of what was asked.
    Answered,
    /// Silence, with the rig not running: it sent all it will send (a run without an end).
    Quiet,
    /// The rig does not hold the run (it answered `NoRun`).
    NoRun(String),
    /// The rig did not answer the pull (after the link's retries).
    NoAnswer(LinkError),
    /// The link is gone.
    Lost(LinkError),
}

/// Answered pulls after which a block (or the end) the rig never sent counts as not held; twice as
/// many on a line that has garbled frames (a held block lost four times in a row on a line that
/// loses one frame in five would otherwise pass for one the rig lacks, once in a few hundred).
const NOT_HELD_AFTER: u32 = 4;
/// Fruitless rounds in a row (nothing new, or no answer) after which the pulls stop.
const MAX_FRUITLESS: u32 = 2 * NOT_HELD_AFTER + 2;
/// Most pull rounds for one run (each fetches a range of missing blocks, or fails to).
const MAX_ROUNDS: u32 = 400;
/// Unanswered pull rounds in a row after which the rig counts as gone.
const MAX_UNANSWERED: u32 = 3;
/// First wait after a fruitless round; doubled after each one in a row, up to [`BACKOFF_MAX`].
const BACKOFF_START: Duration = Duration::from_millis(50);
const BACKOFF_MAX: Duration = Duration::from_secs(2);
/// Held blocks between two missing ranges that are asked again rather than split the request:
/// the rig serves one `PullBlocks` range at a time, and a round costs a round trip.
const MERGE_SLACK: u32 = 64;

/// Merges missing blocks into ranges `(first, count)`, joining ranges less than [`MERGE_SLACK`]
/// blocks apart.
fn merged_ranges(blocks: &[u32]) -> Vec<(u32, u32)> {
    let mut out: Vec<(u32, u32)> = vec![];
    for &b in blocks {
        match out.last_mut() {
            Some((first, count)) if b < *first + *count + MERGE_SLACK => *count = b - *first + 1,
            _ => out.push((b, 1)),
        }
    }
    out
}

impl Streamer<'_, '_> {
    /// Sends a pull command; its refusal or silence as a round's end.
    fn ask(&mut self, msg: HostMsg) -> anyhow::Result<Option<RoundEnd>> {
        match self.link.command(msg) {
            Ok(()) => Ok(None),
            Err(e) if e.code == Some(ErrorCode::NoRun) => Ok(Some(RoundEnd::NoRun(e.msg))),
            Err(e) if e.kind == LinkErrorKind::Closed => Ok(Some(RoundEnd::Lost(e))),
            Err(e) if e.kind == LinkErrorKind::NoAnswer => Ok(Some(RoundEnd::NoAnswer(e))),
            Err(e) => Err(e.into()),
        }
    }

    /// One pull round: `PullBlocks` for `range` (if any), then `Pull` from block `tail_from`, which
    /// the rig serves after the range: the run's header, its blocks from `tail_from` on, the events
    /// after them, its result and its end. Receives until that end frame (after the header), or
    /// until the rig, not running, sends nothing more.
    fn round(
        &mut self,
        run_id: u32,
        range: Option<(u32, u32)>,
        tail_from: u32,
    ) -> anyhow::Result<RoundEnd> {
        self.pulling = true;
        if let Some((first, count)) = range {
            if let Some(end) = self.ask(HostMsg::PullBlocks {
                run_id,
                first,
                count,
            })? {
                return Ok(end);
            }
        }
        if let Some(end) = self.ask(HostMsg::Pull {
            run_id,
            from_block: tail_from,
        })? {
            return Ok(end);
        }
        let quiet = self.link.timeouts.reply.max(Duration::from_millis(100));
        let mut seen_header = false;
        let mut last = Instant::now();
        loop {
            match self.link.next(Duration::from_millis(50)) {
                Ok(Some(f)) => {
                    last = Instant::now();
                    let ours = run_of(&f.frame.msg) == Some(run_id);
                    let header = ours && matches!(f.frame.msg, DeviceMsg::RunStarted(_));
                    let end = ours && matches!(f.frame.msg, DeviceMsg::RunEnded(_));
                    self.file(f)?;
                    seen_header |= header;
                    if end && seen_header {
                        return Ok(RoundEnd::Answered);
                    }
                }
                Ok(None) if last.elapsed() >= quiet => match self.link.status() {
                    // A run in progress: its frames are still to come.
                    Ok(s) if matches!(s.state, RigState::Running) && s.run_id == run_id => {
                        last = Instant::now();
                    }
                    Ok(_) => return Ok(RoundEnd::Quiet),
                    Err(e) if e.kind == LinkErrorKind::Closed => return Ok(RoundEnd::Lost(e)),
                    Err(e) => return Ok(RoundEnd::NoAnswer(e)),
                },
                Ok(None) => {}
                Err(e) => return Ok(RoundEnd::Lost(e)),
            }
        }
    }

    /// Pulls what the stored run lacks until it is complete, or the rig shows it does not hold the
    /// rest, or stops answering. Each round asks for one range of missing blocks (`PullBlocks`)
    /// and for the run's end (`Pull` from past the last block held, which also brings the blocks
    /// after it, and the run's header to check the run is the rig's); events that look missing
    /// are asked for with a `Pull` from a little before them. A round that brings nothing waits
    /// longer before the next (backoff); a block the rig does not send in [`NOT_HELD_AFTER`]
    /// rounds it answered is one it no longer holds. With `check`, at least one round is made
    /// even for a run stored whole (to check it is the rig's run).
    pub(in crate::link) fn fill(&mut self, check: bool) -> anyhow::Result<Option<LinkError>> {
        let mut absent: std::collections::BTreeMap<u32, u32> = Default::default();
        let mut tail_absent = 0u32;
        let mut event_absent = 0u32;
        let mut unanswered = 0u32;
        let mut fruitless = 0u32;
        let mut backoff = BACKOFF_START;
        let mut checked = !check;
        for _ in 0..MAX_ROUNDS {
            let needed = self.evidence_needed();
            let Some(run_id) = self
                .run_id
                .or_else(|| self.writer.as_ref().and_then(|w| w.meta().device_run_id))
            else {
                return Ok(None);
            };
            let (missing, end_blocks, last, holes, has_header, has_result, complete) =
                match self.writer.as_ref() {
                    Some(w) => (
                        w.missing_blocks()
                            .into_iter()
                            .filter(|b| !w.undecodable_blocks().contains(b))
                            .collect::<Vec<u32>>(),
                        w.end().map(|e| e.blocks),
                        w.last_block(),
                        w.event_holes(),
                        w.header().is_some(),
                        w.has_result(),
                        w.is_complete(),
                    ),
                    None => (vec![], None, None, vec![], false, false, false),
                };
            if complete && checked {
                return Ok(None);
            }
            let ask: Vec<u32> = missing
                .iter()
                .copied()
                .filter(|b| absent.get(b).copied().unwrap_or(0) < needed)
                .collect();
            // Blocks only once the stored run is known to be the rig's (else they could go into
            // an older run with the same number).
            let range = if self.verified && has_header {
                merged_ranges(&ask).first().copied()
            } else {
                None
            };
            let want_end = end_blocks.is_none() || !has_result;
            let events = !holes.is_empty() && event_absent < needed;
            let tail_from = if !has_header {
                0
            } else if events {
                // An ECR change is stored just before the block that ends the stretch it was
                // decided on: from two blocks before the first one it shows in.
                holes[0].saturating_sub(2)
            } else {
                match (end_blocks, last) {
                    (Some(n), _) => n,
                    (None, Some(l)) => l + 1,
                    (None, None) => 0,
                }
            };
            let useful = range.is_some()
                || (want_end && tail_absent < needed)
                || events
                || !has_header
                || !checked;
            if !useful || fruitless >= MAX_FRUITLESS {
                break;
            }
            self.rounds += 1;
            (self.obs)(Progress::PullRound {
                round: self.rounds,
                first: range.map(|r| r.0),
                blocks: range.map_or(0, |r| r.1),
                missing: missing.len(),
                tail_from,
            });
            let before = self.writer.as_ref().map_or(0, |w| w.frames_held());
            let end = self.round(run_id, range, tail_from)?;
            match end {
                RoundEnd::Answered | RoundEnd::Quiet => {
                    unanswered = 0;
                    checked |= self.verified;
                }
                RoundEnd::NoRun(msg) => {
                    self.not_held = Some(format!(
                        "the rig does not hold run {run_id} any more ({msg}); what is missing is lost"
                    ));
                    return Ok(None);
                }
                RoundEnd::Lost(e) => return Ok(Some(e)),
                RoundEnd::NoAnswer(e) => {
                    unanswered += 1;
                    fruitless += 1;
                    if unanswered >= MAX_UNANSWERED {
                        return Ok(Some(e));
                    }
                    let why = format!("the rig did not answer a pull ({e})");
                    self.back_off(&mut backoff, why);
                    continue;
                }
            }
            let Some(w) = self.writer.as_ref() else {
                // The stored run was an older one: the next round fetches the rig's into a new
                // folder, from its start.
                absent.clear();
                tail_absent = 0;
                event_absent = 0;
                continue;
            };
            let gained = w.frames_held().saturating_sub(before);
            if let Some((first, count)) = range {
                for b in first..first + count {
                    if w.block(b).is_none() && missing.binary_search(&b).is_ok() {
                        *absent.entry(b).or_default() += 1;
                    }
                }
            }
            if want_end && (w.end().is_none() || !w.has_result()) {
                tail_absent += 1;
            }
            if events && w.event_holes() == holes {
                event_absent += 1;
            }
            if gained == 0 {
                fruitless += 1;
                self.back_off(&mut backoff, "the last pull brought nothing new".into());
            } else {
                fruitless = 0;
                backoff = BACKOFF_START;
            }
        }
        let needed = self.evidence_needed();
        self.conclude(&absent, tail_absent, event_absent, needed);
        Ok(None)
    }

    /// Answered pulls without a frame after which the rig counts as not holding it.
    fn evidence_needed(&self) -> u32 {
        if self.link.stats().bad_frames > 0 {
            2 * NOT_HELD_AFTER
        } else {
            NOT_HELD_AFTER
        }
    }

    fn back_off(&mut self, backoff: &mut Duration, why: String) {
        (self.obs)(Progress::Backoff {
            wait: *backoff,
            why,
        });
        std::thread::sleep(*backoff);
        *backoff = (*backoff * 2).min(BACKOFF_MAX);
    }

    /// Says what the rig showed it no longer holds (after the pulls it answered).
    fn conclude(
        &mut self,
        absent: &std::collections::BTreeMap<u32, u32>,
        tail_absent: u32,
        event_absent: u32,
        needed: u32,
    ) {
        let Some(w) = self.writer.as_ref() else {
            return;
        };
        if w.is_complete() {
            return;
        }
        let mut said: Vec<String> = vec![];
        let gone: Vec<u32> = w
            .missing_blocks()
            .into_iter()
            .filter(|b| absent.get(b).copied().unwrap_or(0) >= needed)
            .collect();
        if !gone.is_empty() {
            said.push(format!(
                "the rig answered {needed} pulls for sample block{} {} ({} in all) without sending \
                 them, so it no longer holds them: the rig keeps a whole run in RAM and flash (about 60 s with \
                 all five channels at 10 kS/s, half that at 20 kS/s; after a power cut, what its flash held, \
                 about the first 35 s), and this run was longer, or the power went during it",
                if gone.len() == 1 { "" } else { "s" },
                block_ranges(&gone),
                gone.len()
            ));
        }
        if (w.end().is_none() || !w.has_result()) && tail_absent >= needed {
            said.push(format!(
                "the rig answered {needed} pulls for the run's end without sending it and is not \
                 running the run: it holds the run only up to block {} with no end — it restarted during the \
                 run (a power cut or a reset) and kept what had reached its flash; the rest was never stored",
                w.last_block().map_or("0".into(), |b| b.to_string())
            ));
        }
        if !w.event_holes().is_empty() && event_absent >= needed {
            said.push(format!(
                "the rig answered {needed} pulls without sending the run events (acquisition gaps, ECR \
                 range changes) that blocks {} show are missing",
                block_ranges(&w.event_holes())
            ));
        }
        if !said.is_empty() {
            let msg = said.join("; ");
            self.warn(msg.clone());
            self.not_held = Some(msg);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn missing_blocks_are_asked_for_in_few_ranges() {
        assert_eq!(merged_ranges(&[]), vec![]);
        assert_eq!(merged_ranges(&[5]), vec![(5, 1)]);
        // Ranges closer than the slack are joined (the held blocks between are asked again).
        assert_eq!(merged_ranges(&[3, 4, 5, 40, 41]), vec![(3, 39)]);
        let far = 5 + MERGE_SLACK + 1;
        assert_eq!(merged_ranges(&[3, 4, 5, far]), vec![(3, 3), (far, 1)]);
        // Every missing block is in exactly one range.
        let missing: Vec<u32> = (0..2000).filter(|b| b % 97 == 0 || b % 211 < 3).collect();
        let r = merged_ranges(&missing);
        for b in &missing {
            assert_eq!(r.iter().filter(|(f, c)| (*f..f + c).contains(b)).count(), 1);
        }
        assert!(r
            .windows(2)
            .all(|w| w[0].0 + w[0].1 + MERGE_SLACK <= w[1].0));
    }
}

//! A run's frames put together: each in its slot (header, block, event, result, end), a second copy
//! compared with the first, the blocks and events in order.

use super::*;

/// Where a run frame belongs in a run (what a second copy of it is compared with).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) enum Slot {
    Header,
    Block(u32),
    Gap(u32),
    Ecr(u32),
    Chain,
    Result,
    End,
}

impl Slot {
    pub(super) fn of(msg: &DeviceMsg) -> Option<Slot> {
        Some(match msg {
            DeviceMsg::RunStarted(_) => Slot::Header,
            DeviceMsg::Samples(b) => Slot::Block(b.block),
            DeviceMsg::Packed(p) => Slot::Block(p.block),
            DeviceMsg::Gap(g) => Slot::Gap(g.first_sample),
            DeviceMsg::EcrRange(e) => Slot::Ecr(e.first_sample),
            DeviceMsg::Chain(_) => Slot::Chain,
            DeviceMsg::Result(_) => Slot::Result,
            DeviceMsg::RunEnded(_) => Slot::End,
            _ => return None,
        })
    }

    pub(super) fn name(self) -> String {
        match self {
            Slot::Header => "its run header".into(),
            Slot::Block(k) => format!("its block {k}"),
            Slot::Gap(s) => format!("its acquisition gap at sample {s}"),
            Slot::Ecr(s) => format!("its ECR range change at sample {s}"),
            Slot::Chain => "its analog chain".into(),
            Slot::Result => "its on-board result".into(),
            Slot::End => "its end frame".into(),
        }
    }
}

/// What filing a frame into a run did ([`RunWriter::file_frame`]).
#[derive(Debug, Clone, PartialEq)]
pub enum Filed {
    /// A frame of the run not held before: logged.
    New,
    /// The very frame (same bytes) is already held: not logged again.
    Same,
    /// The run holds another frame in its place: the frame is of another run (not logged). Says
    /// which part differs.
    Differs(String),
    /// Not a run frame (hello, status, …): not logged.
    Other,
}

/// The messages of a log, sorted into a run.
#[derive(Debug, Clone, Default)]
pub(super) struct Assembled {
    pub(super) header: Option<RunHeader>,
    pub(super) blocks: BTreeMap<u32, SampleBlock>,
    pub(super) result: Option<OnboardResult>,
    pub(super) end: Option<RunEnd>,
    /// Records that were not frames of this protocol, or packed blocks that did not unpack (count).
    pub(super) undecodable: usize,
    /// Run frames received twice with different contents.
    pub(super) conflicts: Vec<String>,
    /// Acquisition gaps the rig reported, by first sample.
    pub(super) gaps: BTreeMap<u32, Gap>,
    /// ECR range changes the rig reported, by first sample.
    pub(super) ecr_changes: BTreeMap<u32, EcrRangeChange>,
    /// The analog chain the rig said the run's channels went through (protocol v3 on).
    pub(super) chain: Option<AnalogChain>,
    /// The protocol the log says the rig spoke (`None`: not recorded).
    pub(super) protocol: Option<u16>,
    /// Every run frame held, as received (sequence number, bytes), by its place in the run.
    pub(super) raw: BTreeMap<Slot, (u32, Vec<u8>)>,
    /// Some sample block came packed (protocol v2 firmware, which records each ECR range change).
    pub(super) packed: bool,
    /// The first block index not held (all before it are).
    pub(super) next_missing: u32,
    /// Blocks held whose counts this tribo cannot unpack (a newer codec).
    pub(super) undecodable_blocks: Vec<u32>,
}

impl Assembled {
    /// Files one decoded frame (`raw`: its bytes, `seq`: its sequence number).
    pub(super) fn add(&mut self, seq: u32, raw: &[u8], msg: DeviceMsg) -> Filed {
        let Some(slot) = Slot::of(&msg) else {
            return Filed::Other;
        };
        if let Some((_, held)) = self.raw.get(&slot) {
            if held[..] == *raw {
                return Filed::Same;
            }
            let what = slot.name();
            self.conflicts.push(what.clone());
            return Filed::Differs(what);
        }
        self.packed |= matches!(msg, DeviceMsg::Packed(_));
        match msg {
            DeviceMsg::RunStarted(h) => self.header = Some(h),
            DeviceMsg::Samples(_) | DeviceMsg::Packed(_) => match msg.sample_block() {
                Some(Ok(b)) => {
                    self.blocks.insert(b.block, b);
                    while self.blocks.contains_key(&self.next_missing) {
                        self.next_missing += 1;
                    }
                }
                // A packed block whose counts do not decode (a CRC-valid frame from a newer codec):
                // kept in the log, counted as missing.
                _ => {
                    self.undecodable += 1;
                    if let Slot::Block(k) = slot {
                        self.undecodable_blocks.push(k);
                    }
                }
            },
            DeviceMsg::Result(r) => self.result = Some(r),
            DeviceMsg::RunEnded(e) => self.end = Some(e),
            DeviceMsg::Gap(g) => {
                self.gaps.insert(g.first_sample, g);
            }
            DeviceMsg::EcrRange(e) => {
                self.ecr_changes.insert(e.first_sample, e);
            }
            DeviceMsg::Chain(c) => self.chain = Some(c),
            _ => {}
        }
        self.raw.insert(slot, (seq, raw.to_vec()));
        Filed::New
    }

    /// Whether this event frame is already filed.
    pub(super) fn has_event(&self, msg: &DeviceMsg) -> bool {
        match msg {
            DeviceMsg::Gap(g) => self.gaps.get(&g.first_sample) == Some(g),
            DeviceMsg::EcrRange(e) => self.ecr_changes.get(&e.first_sample) == Some(e),
            DeviceMsg::Chain(c) => self.chain.as_ref() == Some(c),
            _ => false,
        }
    }

    pub(super) fn from_records(records: &[Vec<u8>], protocol: Option<u16>) -> Assembled {
        let mut a = Assembled {
            protocol,
            ..Assembled::default()
        };
        for r in records {
            match decode_record(protocol, r) {
                Some(f) => {
                    a.add(f.seq, r, f.msg);
                }
                None => a.undecodable += 1,
            }
        }
        a
    }

    /// Block indices missing before the last one expected.
    pub(super) fn missing(&self) -> Vec<u32> {
        let expected = match (&self.end, self.blocks.keys().next_back()) {
            (Some(e), _) => e.blocks,
            (None, Some(&last)) => last + 1,
            (None, None) => 0,
        };
        (0..expected)
            .filter(|b| !self.blocks.contains_key(b))
            .collect()
    }

    /// Blocks before which run events (acquisition gaps, ECR range changes) the rig must have sent
    /// are not held, judged from what the held blocks say: a jump in sample index that the gaps
    /// held do not cover exactly, or a packed block (v2 firmware) converted on an ECR range that the
    /// range changes held do not explain. (Events after the last block show in no block: a pull of
    /// the run's end brings them.)
    pub(super) fn event_holes(&self) -> Vec<u32> {
        let mut holes = vec![];
        // A packed run (protocol v2) opens with the range its first sample was converted on: a
        // change at sample 0, sent right after the header. Without it, the first range is a guess
        // (the soak caught a lossy line that lost it while every block agreed with the guess).
        // A protocol v3 rig says the run's analog chain right after the header, as well.
        let chain_lost = self.chain.is_none() && self.protocol.is_some_and(|p| p >= 3);
        if self.packed && (!self.ecr_changes.contains_key(&0) || chain_lost) {
            if let Some(&first) = self.blocks.keys().next() {
                holes.push(first);
            }
        }
        let mut prev: Option<&SampleBlock> = None;
        let first_range = self.blocks.get(&0).map(|b| b.ecr_range);
        let mut assumed: Option<(u32, u8)> = None;
        for b in self.blocks.values() {
            if let Some(p) = prev.filter(|p| p.block + 1 == b.block) {
                let end = p.first_sample as u64 + p.samples() as u64;
                let jump = (b.first_sample as u64).saturating_sub(end);
                let covered: u64 = self
                    .gaps
                    .range(end.min(u32::MAX as u64) as u32..b.first_sample)
                    .map(|(_, g)| g.count as u64)
                    .sum();
                if jump != covered {
                    holes.push(b.block);
                    prev = Some(b);
                    continue;
                }
            }
            // The range in force at the block's first sample, from the changes held (firmware
            // before protocol v2 changed ranges without saying so). After a hole, the block's own
            // range stands in for the change not held, so that one lost change is one hole.
            if self.packed {
                let held = self
                    .ecr_changes
                    .range(..=b.first_sample)
                    .next_back()
                    .map(|(&s, c)| (s, c.range));
                let range = match (held, assumed) {
                    (Some((s, _)), Some((since, r))) if since > s => Some(r),
                    (Some((_, r)), _) => Some(r),
                    (None, Some((_, r))) => Some(r),
                    (None, None) => first_range,
                };
                if range.is_some_and(|r| r != b.ecr_range) {
                    holes.push(b.block);
                    assumed = Some((b.first_sample, b.ecr_range));
                }
            }
            prev = Some(b);
        }
        holes
    }

    /// Samples the gaps held account for, against what the end frame says the rig lost.
    pub(super) fn gaps_unaccounted(&self) -> Option<(u64, u64)> {
        let held: u64 = self.gaps.values().map(|g| g.count as u64).sum();
        let end = self.end?;
        (end.overruns as u64 != held).then_some((held, end.overruns as u64))
    }

    pub(super) fn completeness(&self) -> Completeness {
        let held = self.blocks.len() as u32;
        Completeness {
            header: self.header.is_some(),
            result: self.result.is_some(),
            end: self.end.is_some(),
            blocks_held: held,
            blocks_expected: self.end.map(|e| e.blocks),
            blocks_known: self
                .end
                .map(|e| e.blocks)
                .or(self.blocks.keys().next_back().map(|b| b + 1))
                .unwrap_or(0),
            missing: self.missing(),
            undecodable: self.undecodable_blocks.clone(),
            event_holes: self.event_holes(),
            gaps_unaccounted: self.gaps_unaccounted(),
            lost_samples: self.gaps.values().map(|g| g.count as u64).sum(),
            conflicts: self.conflicts.len(),
        }
    }

    /// The block a resumed pull should start from: the first one missing (or the next one).
    pub(super) fn resume_from(&self) -> u32 {
        self.next_missing
    }

    /// The run frames held, in the order the rig sent them (by sequence number).
    pub(super) fn frames(&self) -> Vec<&[u8]> {
        let mut v: Vec<&(u32, Vec<u8>)> = self.raw.values().collect();
        v.sort_by_key(|(seq, _)| *seq);
        v.into_iter().map(|(_, r)| &r[..]).collect()
    }
}

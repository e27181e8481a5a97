//! How much of a run is held, and the words for it ("complete: N of N blocks", "incomplete: …").

/// How much of a run is held: what a command says before it calls a run complete.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Completeness {
    /// The run header (configuration, clock) is held.
    pub header: bool,
    /// The on-board result is held (every run the rig ends has one, even aborted ones).
    pub result: bool,
    /// The end frame is held: then the run's number of blocks is known.
    pub end: bool,
    /// Sample blocks held.
    pub blocks_held: u32,
    /// Blocks the run has, from its end frame.
    pub blocks_expected: Option<u32>,
    /// Blocks known to exist: from the end frame, else up to the highest block held.
    pub blocks_known: u32,
    /// Blocks known to exist and not held (those below included).
    pub missing: Vec<u32>,
    /// Blocks received whose counts this tribo cannot unpack (a newer rig's codec: update tribo).
    pub undecodable: Vec<u32>,
    /// Blocks before which run events (gaps, ECR range changes) look missing.
    pub event_holes: Vec<u32>,
    /// Samples the gaps held account for and samples the end frame says were lost, when they
    /// differ.
    pub gaps_unaccounted: Option<(u64, u64)>,
    /// Samples the rig itself lost (its gap frames): part of a complete run, not missing data.
    pub lost_samples: u64,
    /// Run frames received twice with different contents.
    pub conflicts: usize,
}

/// Block indices as ranges: `3, 7–9, 12`.
pub fn block_ranges(blocks: &[u32]) -> String {
    let mut out: Vec<String> = vec![];
    let mut i = 0;
    while i < blocks.len() {
        let mut j = i;
        while j + 1 < blocks.len() && blocks[j + 1] == blocks[j] + 1 {
            j += 1;
        }
        out.push(if i == j {
            blocks[i].to_string()
        } else {
            format!("{}–{}", blocks[i], blocks[j])
        });
        i = j + 1;
    }
    out.join(", ")
}

impl Completeness {
    /// Header, every block, the run's events, its result and its end.
    pub fn is_complete(&self) -> bool {
        self.header
            && self.result
            && self.end
            && self.missing.is_empty()
            && self.event_holes.is_empty()
            && self.gaps_unaccounted.is_none()
    }

    /// One line: `complete: 156 of 156 blocks`, or `incomplete: 79 of 156 blocks (missing …)`.
    pub fn summary(&self) -> String {
        let mut s = if self.is_complete() {
            format!(
                "complete: {} of {} blocks",
                self.blocks_held, self.blocks_held
            )
        } else {
            match self.blocks_expected {
                Some(m) => format!("incomplete: {} of {m} blocks", self.blocks_held),
                None => format!(
                    "incomplete: {} of at least {} blocks",
                    self.blocks_held, self.blocks_known
                ),
            }
        };
        let mut why: Vec<String> = vec![];
        if !self.header {
            why.push("no run header".into());
        }
        if !self.missing.is_empty() {
            why.push(format!("missing {}", block_ranges(&self.missing)));
        }
        if !self.undecodable.is_empty() {
            why.push(format!(
                "block{} {} arrived but this tribo cannot unpack {} (a newer rig's codec: update tribo)",
                if self.undecodable.len() == 1 { "" } else { "s" },
                block_ranges(&self.undecodable),
                if self.undecodable.len() == 1 { "it" } else { "them" }
            ));
        }
        if !self.end {
            why.push(
                "the run's end was not received, so how many blocks it has is not known".into(),
            );
        } else if !self.result {
            why.push("the on-board result was not received".into());
        }
        if !self.event_holes.is_empty() {
            why.push(format!(
                "run events (acquisition gaps, ECR range changes) missing before block{} {}",
                if self.event_holes.len() == 1 { "" } else { "s" },
                block_ranges(&self.event_holes)
            ));
        }
        if let Some((held, said)) = self.gaps_unaccounted {
            why.push(format!(
                "the rig reported {said} lost samples, the gap frames held account for {held}"
            ));
        }
        if self.conflicts > 0 {
            why.push(format!(
                "{} frames arrived twice with different contents (kept the first)",
                self.conflicts
            ));
        }
        if self.lost_samples > 0 {
            why.push(format!(
                "the rig's acquisition lost {} samples (its gap frames say which)",
                self.lost_samples
            ));
        }
        if !why.is_empty() {
            s.push_str(&format!(" ({})", why.join("; ")));
        }
        s
    }
}

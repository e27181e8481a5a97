//! Reading the converter's DMA ring by sample index.
//!
//! The ADC converts one *scan* (one word per analog channel) per timer trigger and the DMA writes the
//! words round a ring in circular mode. The reader never counts samples itself: the index of every
//! sample comes from where the DMA wrote it. The DMA's position in the ring (`ring words − NDTR`)
//! is extended into a monotonic word count with [`extend_position`], using the sample clock to tell
//! how many times the DMA went round; scan `k` of the DMA's *epoch* (its run from word 0 since it was
//! last started) is stream sample `base + k`.
//!
//! What the reader cannot get any more is reported, never stitched over: when the DMA has lapped
//! the reader (it wrote over scans not yet read), or the converter was restarted after an ADC
//! overrun, the next [`Batch`] starts at a later index than the one expected, and the difference is
//! exactly the samples lost.

use crate::hal::{AnalogSample, ANALOG_CHANNELS};

/// Words the DMA writes per scan (one per analog channel, in scan order).
pub const SCAN_WORDS: usize = ANALOG_CHANNELS;

/// Scans the converter's ring holds (board and virtual rig alike): 2048 scans, 16 KiB; 205 ms of
/// samples at 10 kS/s, 102 ms at 20 kS/s, before a reader that stopped reading loses any.
pub const RING_SCANS: usize = 2048;
/// Words of the converter's ring.
pub const RING_WORDS: usize = RING_SCANS * SCAN_WORDS;

/// Read access to the ring the DMA writes (on the board: volatile reads of a buffer the DMA owns).
pub trait RingView {
    /// Length in words (a whole number of scans).
    fn words(&self) -> usize;
    /// Word `i` of the ring (`i < words()`).
    fn word(&self, i: usize) -> u16;
}

impl RingView for [u16] {
    fn words(&self) -> usize {
        self.len()
    }
    fn word(&self, i: usize) -> u16 {
        self.get(i).copied().unwrap_or(0)
    }
}

/// The DMA's count of words written in its epoch, from its position in the ring `pos` (`ring words
/// − NDTR`, `0..ring_words`) and an `estimate` of that count good to better than half a ring (on the
/// board: the sample clock's periods elapsed since the epoch began, times [`SCAN_WORDS`]). Returns
/// the count that is `pos` modulo the ring and nearest to the estimate.
///
/// The position is exact, the estimate only says how many times the DMA went round; so the result is
/// exact whatever the estimate's error below half a ring (51 ms of samples at 20 kS/s with
/// [`RING_SCANS`]; the board's estimate is good to a few µs), and however long the reader was away.
pub fn extend_position(pos: usize, ring_words: usize, estimate: u64) -> u64 {
    if ring_words == 0 {
        return 0;
    }
    let n = ring_words as u64;
    let pos = pos as u64 % n;
    let lap = estimate - estimate % n;
    let same = lap + pos;
    // Candidates one lap either side of `same`; the nearest to the estimate wins (ties: the earlier).
    let mut best = same;
    if same >= n && estimate.abs_diff(same - n) <= estimate.abs_diff(best) {
        best = same - n;
    }
    if estimate.abs_diff(same + n) < estimate.abs_diff(best) {
        best = same + n;
    }
    best
}

/// Samples read at once: `len` samples, the first of which has stream index `first`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Batch {
    pub first: u64,
    pub len: usize,
}

impl Batch {
    /// Index of the sample after the batch's last one.
    pub fn end(&self) -> u64 {
        self.first + self.len as u64
    }
}

/// Takes scans out of the ring in index order (see the module docs).
#[derive(Debug, Clone)]
pub struct RingReader {
    /// Ring capacity, scans.
    scans: u64,
    /// Stream index of the epoch's first scan (word 0 of the ring).
    base: u64,
    /// Stream index of the next scan to read.
    next: u64,
    /// Highest epoch word count seen (so that a position read twice never goes backwards).
    written: u64,
}

impl RingReader {
    /// A reader of a ring of `ring_scans` scans, before any sample.
    pub const fn new(ring_scans: usize) -> Self {
        RingReader {
            scans: ring_scans as u64,
            base: 0,
            next: 0,
            written: 0,
        }
    }

    /// A new stream: the DMA starts at word 0 with sample 0.
    pub fn start(&mut self) {
        self.base = 0;
        self.next = 0;
        self.written = 0;
    }

    /// The DMA was restarted at word 0 (a new epoch) with stream sample `base` as its first scan:
    /// after an ADC overrun, the converter is re-armed and `base` is the index of the trigger it
    /// will see first ([`super::clock::next_trigger`]). The samples from the next unread one up to
    /// `base` are lost; the next batch starts at `base`.
    pub fn restart(&mut self, base: u64) {
        self.base = base.max(self.next);
        self.written = 0;
    }

    /// Stream index of the next sample to read.
    pub fn next_index(&self) -> u64 {
        self.next
    }

    /// Stream index of the epoch's first scan.
    pub fn base(&self) -> u64 {
        self.base
    }

    /// Stream index one past the last scan the DMA completed, given its epoch word count.
    pub fn written_end(&self, written: u64) -> u64 {
        self.base + written.max(self.written) / SCAN_WORDS as u64
    }

    /// Oldest scan of the epoch still whole in the ring when the DMA has written `written` words:
    /// the scan being written (if a part of it is) has taken the slot of the scan one ring earlier.
    fn oldest(&self, written: u64) -> u64 {
        let complete = written / SCAN_WORDS as u64;
        let partial = u64::from(!written.is_multiple_of(SCAN_WORDS as u64));
        (complete + partial).saturating_sub(self.scans)
    }

    /// Copies the oldest unread scans into `out` (at most `out.len()`: the caller bounds the work)
    /// and returns which they are. `written` is the DMA's epoch word count read before the copy
    /// ([`extend_position`]); `after` reads it again after the copy, and any scan the DMA wrote over
    /// meanwhile is dropped from the front of the batch (its slot held newer data by then).
    ///
    /// A batch that starts after the index the caller expected means the samples in between are
    /// lost; an empty batch still says where reading goes on (its `first`).
    pub fn read<R: RingView + ?Sized>(
        &mut self,
        written: u64,
        ring: &R,
        out: &mut [AnalogSample],
        after: impl FnOnce() -> u64,
    ) -> Batch {
        let ring_scans = (ring.words() / SCAN_WORDS) as u64;
        if ring_scans == 0 || ring_scans != self.scans {
            return Batch {
                first: self.next,
                len: 0,
            };
        }
        let written = written.max(self.written);
        self.written = written;
        let complete = written / SCAN_WORDS as u64;
        // Epoch-relative index of the first scan to copy.
        let mut from = self
            .next
            .saturating_sub(self.base)
            .max(self.oldest(written));
        let mut len = complete.saturating_sub(from).min(out.len() as u64) as usize;
        for (k, o) in out.iter_mut().take(len).enumerate() {
            let slot = ((from + k as u64) % self.scans) as usize * SCAN_WORDS;
            for (c, v) in o.iter_mut().enumerate() {
                *v = ring.word(slot + c);
            }
        }
        let again = after().max(written);
        self.written = again;
        let oldest = self.oldest(again);
        if oldest > from {
            let drop = ((oldest - from) as usize).min(len);
            out.copy_within(drop..len, 0);
            len -= drop;
            from = oldest;
        }
        let first = self.base + from;
        self.next = first + len as u64;
        Batch { first, len }
    }
}

/// A software model of the converter's DMA in circular mode, for tests and the virtual rig: words
/// are written round a ring of `WORDS` words, and [`DmaModel::ndtr`] reads like the stream's NDTR.
#[derive(Debug, Clone)]
pub struct DmaModel<const WORDS: usize> {
    ring: [u16; WORDS],
    written: u64,
}

impl<const WORDS: usize> Default for DmaModel<WORDS> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const WORDS: usize> DmaModel<WORDS> {
    pub const fn new() -> Self {
        DmaModel {
            ring: [0; WORDS],
            written: 0,
        }
    }

    /// The stream is (re)enabled: writing starts again at word 0.
    pub fn restart(&mut self) {
        self.written = 0;
    }

    /// One transfer.
    pub fn write_word(&mut self, w: u16) {
        if WORDS == 0 {
            return;
        }
        self.ring[(self.written % WORDS as u64) as usize] = w;
        self.written += 1;
    }

    /// The transfers of one whole scan.
    pub fn write_scan(&mut self, s: &AnalogSample) {
        for &w in s {
            self.write_word(w);
        }
    }

    /// Words written since the last restart (what [`extend_position`] reconstructs).
    pub fn written(&self) -> u64 {
        self.written
    }

    /// Transfers left before the wrap, as the stream's NDTR register shows it (`WORDS` at the start
    /// of every lap).
    pub fn ndtr(&self) -> usize {
        if WORDS == 0 {
            return 0;
        }
        WORDS - (self.written % WORDS as u64) as usize
    }

    /// The position in the ring, as the board computes it from NDTR.
    pub fn position(&self) -> usize {
        (WORDS - self.ndtr()) % WORDS.max(1)
    }

    pub fn ring(&self) -> &[u16] {
        &self.ring
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const SCANS: usize = 16;
    const WORDS: usize = SCANS * SCAN_WORDS;

    /// The scan of stream sample `i`: its index spread over the four words, so that any sample
    /// read says which it is.
    fn scan(i: u64) -> AnalogSample {
        [
            i as u16,
            (i >> 16) as u16,
            (i >> 32) as u16,
            0xA5A5 ^ i as u16,
        ]
    }

    fn index_of(s: &AnalogSample) -> u64 {
        assert_eq!(s[3], 0xA5A5 ^ s[0], "a scan torn apart: {s:?}");
        s[0] as u64 | (s[1] as u64) << 16 | (s[2] as u64) << 32
    }

    #[test]
    fn the_position_extends_to_the_count_nearest_the_estimate() {
        let n = 64;
        assert_eq!(extend_position(10, n, 10), 10);
        assert_eq!(extend_position(10, n, 64 * 7 + 12), 64 * 7 + 10);
        // The estimate just past a wrap, the position just before it.
        assert_eq!(extend_position(62, n, 64 * 3 + 1), 64 * 3 - 2);
        // The estimate just before a wrap, the position just after it.
        assert_eq!(extend_position(1, n, 64 * 3 - 2), 64 * 3 + 1);
        // Near the start the count cannot go below zero.
        assert_eq!(extend_position(60, n, 0), 60);
        assert_eq!(extend_position(0, 0, 5), 0);
    }

    proptest! {
        #[test]
        fn extension_is_exact_for_any_estimate_within_half_a_ring(
            count in 0u64..1u64 << 40,
            err in -31i64..=31,
        ) {
            let n = 64usize;
            let estimate = (count as i64 + err).max(0) as u64;
            prop_assert_eq!(extend_position((count % n as u64) as usize, n, estimate), count);
        }
    }

    /// A DMA and a reader; the test drives both.
    struct Bench {
        dma: DmaModel<WORDS>,
        reader: RingReader,
        converted: u64,
    }

    impl Bench {
        fn new() -> Self {
            Bench {
                dma: DmaModel::new(),
                reader: RingReader::new(SCANS),
                converted: 0,
            }
        }
        fn convert(&mut self, n: u64) {
            for _ in 0..n {
                self.dma.write_scan(&scan(self.converted));
                self.converted += 1;
            }
        }
        /// Reads as the board does: position from NDTR, extended with an estimate off by `err` words.
        fn read(&mut self, out: &mut [AnalogSample], err: i64) -> Batch {
            let est = (self.dma.written() as i64 + err).max(0) as u64;
            let w = extend_position(self.dma.position(), WORDS, est);
            let w2 = self.dma.written();
            self.reader.read(w, self.dma.ring(), out, || w2)
        }
    }

    #[test]
    fn indices_run_on_across_the_half_and_full_ring_boundaries() {
        let mut b = Bench::new();
        let mut out = [[0u16; 4]; 5];
        let mut expected = 0u64;
        // 5 scans read per 3 converted, 7 converted per read...: every read crosses the half (8) or
        // the full (16) mark at some point, many times over.
        for round in 0..200u64 {
            b.convert(1 + round % 7);
            loop {
                let got = b.read(&mut out, (round % 5) as i64 - 2);
                assert_eq!(got.first, expected, "round {round}");
                for (k, s) in out[..got.len].iter().enumerate() {
                    assert_eq!(index_of(s), got.first + k as u64);
                }
                expected = got.end();
                if got.len < out.len() {
                    break;
                }
            }
        }
        assert_eq!(expected, b.converted);
    }

    #[test]
    fn a_reader_lapped_by_the_dma_sees_exactly_the_samples_it_lost() {
        let mut b = Bench::new();
        let mut out = [[0u16; 4]; 64];
        b.convert(10);
        let got = b.read(&mut out, 0);
        assert_eq!((got.first, got.len), (0, 10));
        // The reader stalls for 3 rings and 5 scans: the ring holds the last 16 of them.
        b.convert(3 * SCANS as u64 + 5);
        let got = b.read(&mut out, 0);
        let end = 10 + 3 * SCANS as u64 + 5;
        assert_eq!((got.first, got.len), (end - SCANS as u64, SCANS));
        for (k, s) in out[..got.len].iter().enumerate() {
            assert_eq!(index_of(s), got.first + k as u64);
        }
        // Lost: 10 .. end − 16.
        assert_eq!(got.first - 10, 3 * SCANS as u64 + 5 - SCANS as u64);
    }

    #[test]
    fn a_scan_in_progress_is_not_read_and_the_slot_it_overwrites_is_lost() {
        let mut b = Bench::new();
        let mut out = [[0u16; 4]; 64];
        b.convert(SCANS as u64);
        // Two words of scan 16 are written: they went into slot 0, over scan 0.
        b.dma.write_word(scan(16)[0]);
        b.dma.write_word(scan(16)[1]);
        let got = b.read(&mut out, 0);
        assert_eq!((got.first, got.len), (1, SCANS - 1));
        assert_eq!(index_of(&out[0]), 1);
        // The rest of scan 16 arrives; it is read whole, with its index.
        b.dma.write_word(scan(16)[2]);
        b.dma.write_word(scan(16)[3]);
        b.converted = 17;
        let got = b.read(&mut out, 0);
        assert_eq!((got.first, got.len), (16, 1));
        assert_eq!(index_of(&out[0]), 16);
    }

    #[test]
    fn scans_overwritten_during_the_copy_are_dropped_from_the_front() {
        let mut dma = DmaModel::<WORDS>::new();
        let mut reader = RingReader::new(SCANS);
        for i in 0..SCANS as u64 {
            dma.write_scan(&scan(i));
        }
        let mut out = [[0u16; 4]; SCANS];
        // While the reader copied, the DMA went on by 3 scans and one word: scans 0..=3 were
        // overwritten (the copy of them is stale), 4.. are good.
        let before = dma.written();
        let got = reader.read(before, dma.ring(), &mut out, || before + 3 * 4 + 1);
        assert_eq!((got.first, got.len), (4, SCANS - 4));
        for (k, s) in out[..got.len].iter().enumerate() {
            assert_eq!(index_of(s), 4 + k as u64);
        }
        assert_eq!(reader.next_index(), SCANS as u64);
    }

    #[test]
    fn a_restart_after_an_overrun_resumes_at_the_trigger_index_it_was_given() {
        let mut b = Bench::new();
        let mut out = [[0u16; 4]; 64];
        b.convert(12);
        // The ADC overran after 12 scans (two words of the 13th got through); the converter is
        // re-armed and its first trigger will be sample 40.
        b.dma.write_word(1);
        b.dma.write_word(2);
        let got = b.read(&mut out, 0);
        assert_eq!((got.first, got.len), (0, 12));
        b.dma.restart();
        b.reader.restart(40);
        b.converted = 40;
        b.convert(20);
        let got = b.read(&mut out, 0);
        // Samples 12..40 are the gap; 40.. come with their own indices across the new epoch's wrap.
        assert_eq!((got.first, got.len), (40 + 20 - SCANS as u64, SCANS));
        assert_eq!(index_of(&out[0]), got.first);
        let mut b2 = Bench::new();
        b2.convert(3);
        b2.dma.restart();
        b2.reader.restart(7);
        b2.converted = 7;
        b2.convert(2);
        let got = b2.read(&mut out, 0);
        assert_eq!((got.first, got.len), (7, 2));
        assert_eq!(index_of(&out[1]), 8);
    }

    proptest! {
        /// Any schedule of conversions and reads of any size, with estimate errors below half a ring:
        /// every sample the reader returns carries its true index, indices only go up, and a sample
        /// is missing exactly when the DMA overwrote it before it was read.
        #[test]
        fn every_sample_read_is_where_the_index_says_and_only_overwritten_ones_are_lost(
            steps in prop::collection::vec((0u64..40, 0usize..24, -7i64..=7), 1..60),
        ) {
            let mut b = Bench::new();
            let mut out = [[0u16; 4]; 24];
            let mut expected = 0u64;
            let mut lost = 0u64;
            for (conv, want, err) in steps {
                b.convert(conv);
                let got = b.read(&mut out[..want], err);
                prop_assert!(got.first >= expected);
                // A jump is only allowed over samples no longer in the ring.
                if got.first > expected {
                    prop_assert!(got.first <= b.converted.saturating_sub(SCANS as u64) + 1);
                    lost += got.first - expected;
                }
                for (k, s) in out[..got.len].iter().enumerate() {
                    prop_assert_eq!(index_of(s), got.first + k as u64);
                }
                prop_assert!(got.end() <= b.converted);
                expected = got.end();
            }
            // Drain: everything still in the ring comes out.
            loop {
                let got = b.read(&mut out, 0);
                if got.first > expected {
                    lost += got.first - expected;
                }
                expected = got.end();
                if got.len == 0 {
                    break;
                }
            }
            prop_assert_eq!(expected, b.converted);
            prop_assert!(lost <= b.converted.saturating_sub(SCANS as u64));
        }
    }
}

//! Replay hardware: the [`tribo_firmware::hal`] traits fed from a simulated [`Record`].
//!
//! Time is virtual: the test sets [`Replay::now_us`] before each call into the application. The
//! converter "converts" on a fixed clock from `adc_start`: sample `k` is complete at
//! `start + (k + 1) / rate`. While the magnet holds the pin, samples come from the record's hold
//! (cycled if the hold runs longer than the record's); once the magnet lets go (its drive leaves
//! `Hold`), samples converted after that instant come from the record's motion, from its first
//! sample after the hold; past the record's end the last sample repeats (the pin at rest). The
//! converter's ring holds [`RING`] samples: a larger backlog is dropped and counted as lost, like
//! the board's ring.
//!
//! The link models the board's USB pipe: [`PIPE`] bytes of room; a frame that does not fit is
//! refused (nothing queued), as the board's `send_frame` does; the test takes the bytes out
//! (the host reading) whenever it likes. Every hardware method is cheap (a copy at most), because its
//! instructions are counted as the application's, like the board's would be.

use crate::bundle::Record;
use tribo_firmware::hal::{
    AnalogSample, Button, EcrFrontEnd, HeaterOutput, Lamps, Led, Link, Magnet, MagnetDrive,
    SampleSource, Thermocouple, ThermocoupleFault, ANALOG_CHANNELS,
};

/// Samples the converter's ring holds.
pub const RING: u64 = 4096;
/// Bytes the link's pipe holds (the board's USB pipe is 4 KiB).
pub const PIPE: usize = 4096;

/// Reads an instruction clock (`None` on the host): a plain function, so that hardware methods can
/// time themselves while the probe is busy measuring the call around them.
pub type Clock = fn() -> Option<u64>;

fn no_clock() -> Option<u64> {
    None
}

/// Timing of the converter's ring reads, in application instructions.
#[derive(Debug, Clone, Copy, Default)]
pub struct ReadTiming {
    /// Application instructions executed before the current call.
    pub base: u64,
    /// Clock at the start of the current call.
    pub call_start: Option<u64>,
    /// Application time of the last ring read of this acquisition.
    pub last: Option<u64>,
    /// Largest application time between two ring reads of one acquisition.
    pub worst_gap: u64,
    /// Ring reads.
    pub reads: u64,
}

/// The replay hardware (see the module docs).
pub struct Replay<'r> {
    rec: Record<'r>,
    /// Virtual time, µs (set by the test).
    pub now_us: u64,
    /// The instruction clock for [`ReadTiming`].
    pub clock: Clock,
    pub timing: ReadTiming,
    // magnet
    drive: MagnetDrive,
    released_at_us: Option<u64>,
    /// Samples of the converter completed when the magnet let go (the first motion sample's `k`).
    released_k: Option<u64>,
    // converter
    running: bool,
    rate: u32,
    start_us: u64,
    /// Samples converted and handed over (or lost) since `start_us`.
    next: u64,
    lost: u32,
    // heater, ECR, button, lamps
    /// What the thermocouple reads.
    pub temp: Result<f32, ThermocoupleFault>,
    pub heater_duty: f32,
    /// Transimpedance output the ECR front end reads, V.
    pub ecr_output_v: f32,
    pub ecr_source_v: f32,
    pub ecr_range: u8,
    pub button: bool,
    pub lamps: Lamps,
    // link
    outbox: [u8; PIPE],
    outbox_len: usize,
    /// Frames the link refused (pipe full).
    pub refused: u32,
    /// Frames the link took.
    pub sent: u32,
}

impl<'r> Replay<'r> {
    pub fn new(rec: Record<'r>) -> Self {
        Replay {
            rec,
            now_us: 0,
            clock: no_clock,
            timing: ReadTiming::default(),
            drive: MagnetDrive::Off,
            released_at_us: None,
            released_k: None,
            running: false,
            rate: 0,
            start_us: 0,
            next: 0,
            lost: 0,
            temp: Ok(25.0),
            heater_duty: 0.0,
            ecr_output_v: 1.0,
            ecr_source_v: 0.0,
            ecr_range: 0,
            button: false,
            lamps: Lamps::default(),
            outbox: [0; PIPE],
            outbox_len: 0,
            refused: 0,
            sent: 0,
        }
    }

    pub fn record(&self) -> &Record<'r> {
        &self.rec
    }

    /// When the magnet let the pin go, µs.
    pub fn released_at_us(&self) -> Option<u64> {
        self.released_at_us
    }

    pub fn magnet(&self) -> MagnetDrive {
        self.drive
    }

    /// The bytes the link took since the last call (the host reads them all; the pipe empties).
    pub fn take_output(&mut self, mut f: impl FnMut(&[u8])) {
        f(&self.outbox[..self.outbox_len]);
        self.outbox_len = 0;
    }

    /// Samples completed by `now_us` since the converter started.
    fn due(&self) -> u64 {
        if !self.running || self.now_us < self.start_us {
            return 0;
        }
        (self.now_us - self.start_us) * self.rate as u64 / 1_000_000
    }

    /// Index in the record of sample `k` since the start (see the module docs). No 64-bit
    /// division here (the M7 has none in hardware): this runs for every sample, inside the
    /// measured calls.
    fn index(&self, k: u64) -> usize {
        match self.released_k {
            Some(r) if k >= r => {
                let i = self.rec.hold as u64 + (k - r);
                i.min(self.rec.len().max(1) as u64 - 1) as usize
            }
            _ => (k as u32 % self.rec.hold.max(1)) as usize,
        }
    }

    fn note_read(&mut self) {
        let t = &mut self.timing;
        t.reads += 1;
        let (Some(start), Some(now)) = (t.call_start, (self.clock)()) else {
            return;
        };
        let at = t.base + now.saturating_sub(start);
        if let Some(last) = t.last {
            t.worst_gap = t.worst_gap.max(at.saturating_sub(last));
        }
        t.last = Some(at);
    }
}

impl Magnet for Replay<'_> {
    fn magnet_drive(&mut self, drive: MagnetDrive) {
        if self.released_at_us.is_none()
            && matches!(self.drive, MagnetDrive::Hold { .. })
            && !matches!(drive, MagnetDrive::Hold { .. })
        {
            self.released_at_us = Some(self.now_us);
            self.released_k = Some(self.due());
        }
        self.drive = drive;
    }
}

impl Thermocouple for Replay<'_> {
    fn read_thermocouple(&mut self) -> Result<f32, ThermocoupleFault> {
        self.temp
    }
}

impl HeaterOutput for Replay<'_> {
    fn set_heater_duty(&mut self, duty: f32) {
        self.heater_duty = duty;
    }
}

impl EcrFrontEnd for Replay<'_> {
    fn set_ecr_source(&mut self, volts: f32) {
        self.ecr_source_v = volts;
    }
    fn set_ecr_range(&mut self, range: u8) {
        self.ecr_range = range;
    }
    fn read_ecr_output(&mut self) -> f32 {
        self.ecr_output_v
    }
}

impl SampleSource for Replay<'_> {
    fn adc_start(&mut self, rate_hz: u32) -> bool {
        if rate_hz == 0 {
            return false;
        }
        self.running = true;
        self.rate = rate_hz;
        self.start_us = self.now_us;
        self.next = 0;
        self.lost = 0;
        self.timing.last = None;
        true
    }

    fn adc_stop(&mut self) {
        self.running = false;
        self.timing.last = None;
    }

    fn adc_running(&self) -> bool {
        self.running
    }

    fn adc_read(&mut self, out: &mut [AnalogSample]) -> usize {
        self.note_read();
        let due = self.due();
        let backlog = due.saturating_sub(self.next);
        if backlog > RING {
            let dropped = backlog - RING;
            self.lost = self
                .lost
                .saturating_add(dropped.min(u32::MAX as u64) as u32);
            self.next += dropped;
        }
        let n = (due.saturating_sub(self.next)).min(out.len() as u64) as usize;
        for (k, o) in out.iter_mut().take(n).enumerate() {
            let s = self.rec.sample(self.index(self.next + k as u64));
            o.copy_from_slice(&s[..ANALOG_CHANNELS]);
        }
        self.next += n as u64;
        n
    }

    fn adc_lost(&self) -> u32 {
        self.lost
    }
}

impl Button for Replay<'_> {
    fn button_pressed(&mut self) -> bool {
        self.button
    }
}

impl Led for Replay<'_> {
    fn set_lamps(&mut self, lamps: Lamps) {
        self.lamps = lamps;
    }
}

impl Link for Replay<'_> {
    fn send_frame(&mut self, frame: &[u8]) -> bool {
        // One block copy, like the board's pipe write.
        let at = self.outbox_len;
        match self.outbox.get_mut(at..at + frame.len()) {
            Some(room) => {
                room.copy_from_slice(frame);
                self.outbox_len += frame.len();
                self.sent += 1;
                true
            }
            None => {
                self.refused += 1;
                false
            }
        }
    }
}

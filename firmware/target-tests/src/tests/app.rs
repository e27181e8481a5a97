//! The application state machine through whole runs on the target, with the replay hardware fed
//! from the simulated records: configure, settle, arm, release, stream, finish, pull again.
//!
//! Every call into the application (`App::poll` every virtual millisecond, `App::on_bytes` for each
//! command) is measured: instructions and stack depth. The bench plays the host: it reads every
//! frame the link took, checks each streamed sample against the record, and keeps a CRC of every
//! run frame so that a later `Pull` can be compared byte for byte.

use crate::bundle::{same_bits, ulps, Record};
use crate::replay::Replay;
use crate::{check, check_eq, Cost, Cx, Failure, Outcome};
use tribo_firmware::app::{App, AppConfig};
use tribo_firmware::hal::FlashGeometry;
use tribo_firmware::runstore::{RunStore, BOARD_RING_BYTES, MAX_RUN_BLOCKS};
use tribo_firmware::wire::crc32::Crc32;
use tribo_firmware::wire::frame::MAX_FRAME;
use tribo_firmware::wire::{filler_byte, SelfTestCheck, SelfTestReport, FILLER_MAX};
use tribo_firmware::wire::{
    Channel, Configure, Decoder, DeviceError, DeviceMsg, Encoder, EndReason, FaultReport, HostMsg,
    OnboardResult, RigState, RunEnd, RunHeader, SampleBlock, Verdict, CHANNELS, PROTOCOL_VERSION,
};

/// Budget of one `App::poll` or `App::on_bytes`, instructions (≈ 50 µs of the M7 at its 400 MHz, one instruction a cycle).
pub const CALL_BUDGET: u64 = 20_000;
/// Budget of the stack one call may use, bytes.
pub const STACK_BUDGET: u64 = 16 * 1024;
/// Budget of the whole per-sample path, instructions per five-channel sample.
pub const SAMPLE_BUDGET: u64 = 1_000;
/// Poll period of the board's application task, µs (`AppConfig::poll_period_us`).
pub const POLL_US: u64 = 500;
/// Temperature the replayed thermocouple reads, °C (the records' temperature channel holds its
/// count).
pub const TEMP_C: f32 = 25.0;

/// Most run frames remembered for the comparison with a pull (a 3 s five-channel run at 10 kS/s has
/// 470 blocks).
const MAX_RUN_FRAMES: usize = 2048;

/// What the bench saw coming back (see [`Host::frame`]).
#[derive(Default)]
pub struct Host {
    pub frames: u32,
    pub malformed: u32,
    pub last_ack: Option<u32>,
    pub errors: heapless::Vec<DeviceError, 16>,
    pub hello: bool,
    pub header: Option<RunHeader>,
    /// Next block index expected in the live stream.
    pub next_block: u32,
    /// Samples checked against the record.
    pub samples_checked: u32,
    /// The first streamed count that differed from the record: (block, index in block, got, want).
    pub mismatch: Option<(u32, usize, [u16; CHANNELS], [u16; CHANNELS])>,
    /// Blocks out of order or of another run.
    pub out_of_order: u32,
    pub result: Option<OnboardResult>,
    pub end: Option<RunEnd>,
    /// (sequence number, CRC of the frame's bytes) of every live run frame.
    pub run_frames: heapless::Vec<(u32, u32), MAX_RUN_FRAMES>,
    /// Pull phase: run frames received again, those whose bytes matched the live frame with the
    /// same sequence number, the first block pulled, and whether the end came.
    pub pulling: bool,
    pub pulled: u32,
    pub pulled_same: u32,
    pub pulled_first_block: Option<u32>,
    pub pulled_end: bool,
    /// Run frames' sequence numbers increase in the live stream (other frames are numbered when
    /// sent, run frames when stored, so the two interleave).
    pub last_seq: Option<u32>,
    pub seq_backwards: u32,
    /// `Fault` frames, with the bench's time when read (µs).
    pub faults: heapless::Vec<(u64, FaultReport), 8>,
    /// Time the bench read at (set before each read).
    pub now_us: u64,
    /// The self-test's reports: the last one that is not a filler frame, and the filler frames
    /// received whole and in order.
    pub selftest: Option<SelfTestReport>,
    pub fillers: u32,
}

impl Host {
    /// One decoded frame and the CRC of its bytes.
    fn frame(&mut self, rec: &Record<'_>, seq: u32, crc: u32, msg: DeviceMsg) {
        self.frames += 1;
        if msg.is_run_frame() {
            if self.pulling {
                self.pulled += 1;
                if let Ok(i) = self.run_frames.binary_search_by_key(&seq, |f| f.0) {
                    if self.run_frames[i].1 == crc {
                        self.pulled_same += 1;
                    }
                }
                match &msg {
                    DeviceMsg::Samples(b) if self.pulled_first_block.is_none() => {
                        self.pulled_first_block = Some(b.block)
                    }
                    DeviceMsg::Packed(p) if self.pulled_first_block.is_none() => {
                        self.pulled_first_block = Some(p.block)
                    }
                    DeviceMsg::RunEnded(_) => self.pulled_end = true,
                    _ => {}
                }
                return;
            }
            if let Some(last) = self.last_seq {
                if seq <= last {
                    self.seq_backwards += 1;
                }
            }
            self.last_seq = Some(seq);
            let _ = self.run_frames.push((seq, crc));
        }
        match msg {
            DeviceMsg::Hello(_) => self.hello = true,
            DeviceMsg::Ack { seq } => self.last_ack = Some(seq),
            DeviceMsg::Error(e) => {
                let _ = self.errors.push(e);
            }
            DeviceMsg::RunStarted(h) => self.header = Some(h),
            DeviceMsg::Samples(b) => self.block(rec, &b),
            DeviceMsg::Packed(p) => match p.unpack() {
                Ok(b) => self.block(rec, &b),
                Err(_) => self.malformed += 1,
            },
            DeviceMsg::Result(r) => self.result = Some(r),
            DeviceMsg::RunEnded(e) => self.end = Some(e),
            DeviceMsg::Fault(r) => {
                let _ = self.faults.push((self.now_us, r));
            }
            DeviceMsg::SelfTest(SelfTestReport::Filler { index, data }) => {
                let whole = index == self.fillers
                    && data
                        .iter()
                        .enumerate()
                        .all(|(i, &b)| b == filler_byte(index, i));
                if whole {
                    self.fillers += 1;
                }
            }
            DeviceMsg::SelfTest(r) => self.selftest = Some(r),
            _ => {}
        }
    }

    /// A live block: in order, and every count equal to the record's (the converter's four channels
    /// from the record, the temperature from the thermocouple through its calibration).
    fn block(&mut self, rec: &Record<'_>, b: &SampleBlock) {
        let run = self.header.map_or(0, |h| h.run_id);
        if b.block != self.next_block || b.run_id != run {
            self.out_of_order += 1;
        }
        self.next_block = b.block + 1;
        let temp = rec.configure.calibration[Channel::Temperature.index()].to_count(TEMP_C);
        for i in 0..b.samples() {
            let mut got = [0u16; CHANNELS];
            if let Some(s) = b.sample(i) {
                for (g, c) in got.iter_mut().zip(s) {
                    *g = *c;
                }
            }
            let mut want = rec.sample(rec.hold as usize + b.first_sample as usize + i);
            want[Channel::Temperature.index()] = temp;
            if got == want {
                self.samples_checked += 1;
            } else if self.mismatch.is_none() {
                self.mismatch = Some((b.block, i, got, want));
            }
        }
    }
}

/// Costs of the calls made in one state.
#[derive(Debug, Default, Clone, Copy)]
pub struct StateCost {
    pub calls: u64,
    pub total: u64,
    pub worst: u64,
    pub stack: u32,
}

/// Worst costs of the application's calls.
#[derive(Debug, Default, Clone, Copy)]
pub struct Worst {
    /// Polls by the state they started in (`RigState as usize`).
    pub by_state: [StateCost; 6],
    /// Worst `on_bytes` by command: instructions, stack bytes.
    pub by_command: [(u64, u32); 16],
    pub poll: u64,
    pub on_bytes: u64,
    pub stack: u32,
    /// Virtual time of the worst poll, µs.
    pub poll_at_us: u64,
    /// What the worst poll did: samples taken, frames the link took.
    pub poll_did: (u32, u32),
    /// Ordinal of the worst poll among all measured polls (to find it in an execution trace:
    /// the n-th call of [`poll_mark`]).
    pub poll_ordinal: u64,
    pub polls: u64,
    /// Application instructions since the bench started.
    pub total: u64,
}

/// The application, the replay hardware and the host, in virtual time.
pub struct Bench<'a, 'r> {
    pub app: App<'a>,
    pub hw: Replay<'r>,
    pub host: Host,
    pub worst: Worst,
    pub now_us: u64,
    /// False: the host stops reading (cable out); the pipe fills and the link refuses frames.
    pub reading: bool,
    seq: u32,
    enc: Encoder,
    dec: Decoder<DeviceMsg>,
    crc: Crc32,
    buf: [u8; MAX_FRAME],
}

impl<'a, 'r> Bench<'a, 'r> {
    pub fn new(cx: &Cx<'_>, rec: Record<'r>, store: RunStore<'a>, flash: &'r mut [u8]) -> Self {
        let mut hw = Replay::new(rec, flash);
        hw.clock = cx.probe_clock();
        hw.temp = TEMP_C;
        Bench {
            app: App::new(AppConfig::new(0x7E57), store),
            hw,
            host: Host::default(),
            worst: Worst::default(),
            now_us: 0,
            reading: true,
            seq: 0,
            enc: Encoder::new(),
            dec: Decoder::new(),
            crc: Crc32::new(),
            buf: [0; MAX_FRAME],
        }
    }

    fn account(
        &mut self,
        c: Cost,
        poll: Option<RigState>,
        command: Option<usize>,
        did: (u32, u32),
    ) {
        let n = c.instructions.unwrap_or(0);
        self.worst.total += n;
        self.hw.timing.base = self.worst.total;
        let stack = c.stack.unwrap_or(0);
        if let Some(st) = poll.and_then(|s| self.worst.by_state.get_mut(s as usize)) {
            st.calls += 1;
            st.total += n;
            st.worst = st.worst.max(n);
            st.stack = st.stack.max(stack);
        }
        if let Some(w) = command.and_then(|k| self.worst.by_command.get_mut(k)) {
            *w = (w.0.max(n), w.1.max(stack));
        }
        if poll.is_some() {
            self.worst.polls += 1;
            if n > self.worst.poll {
                self.worst.poll = n;
                self.worst.poll_at_us = self.now_us;
                self.worst.poll_did = did;
                self.worst.poll_ordinal = self.worst.polls;
            }
        } else {
            self.worst.on_bytes = self.worst.on_bytes.max(n);
        }
        if let Some(s) = c.stack {
            self.worst.stack = self.worst.stack.max(s);
        }
        if self.reading {
            self.read();
        }
    }

    /// The host reads what the link took.
    pub fn read(&mut self) {
        self.host.now_us = self.now_us;
        let rec = *self.hw.record();
        let (dec, crc, host) = (&mut self.dec, &mut self.crc, &mut self.host);
        self.hw.take_output(|bytes| {
            for &b in bytes {
                crc.update(&[b]);
                match dec.push(b) {
                    Some(Ok(f)) => {
                        let c = core::mem::take(crc).finish();
                        host.frame(&rec, f.seq, c, f.msg);
                    }
                    Some(Err(_)) => {
                        *crc = Crc32::new();
                        host.malformed += 1;
                    }
                    None if b == 0 => *crc = Crc32::new(),
                    None => {}
                }
            }
        });
    }

    /// One `App::poll` at the current time, measured.
    pub fn poll(&mut self, cx: &mut Cx<'_>) {
        self.hw.advance(self.now_us);
        let now = self.now_us;
        let clock = self.hw.clock;
        let state = self.app.state();
        let (samples, sent) = (self.app.status().samples, self.hw.sent);
        let (app, hw) = (&mut self.app, &mut self.hw);
        poll_mark();
        let c = cx.measure(|| {
            hw.timing.call_start = clock();
            app.poll(hw, now);
        });
        let did = (
            self.app.status().samples.wrapping_sub(samples),
            self.hw.sent - sent,
        );
        self.account(c, Some(state), None, did);
    }

    /// Polls every [`POLL_US`] until `until_us`.
    pub fn run_until(&mut self, cx: &mut Cx<'_>, until_us: u64) {
        while self.now_us + POLL_US <= until_us {
            self.now_us += POLL_US;
            self.poll(cx);
        }
    }

    /// Sends one command (a whole frame in one `App::on_bytes`), measured; returns its sequence
    /// number.
    pub fn send(&mut self, cx: &mut Cx<'_>, msg: &HostMsg) -> u32 {
        let seq = self.seq;
        self.seq += 1;
        let n = self
            .enc
            .encode(seq, msg, &mut self.buf)
            .map_or(0, |b| b.len());
        self.hw.advance(self.now_us);
        let now = self.now_us;
        let clock = self.hw.clock;
        let (app, hw, buf) = (&mut self.app, &mut self.hw, &self.buf[..n]);
        let c = cx.measure(|| {
            hw.timing.call_start = clock();
            app.on_bytes(hw, buf, now);
        });
        self.account(c, None, Some(command_index(msg)), (0, 0));
        seq
    }

    /// Sends a command and fails unless it is acknowledged.
    pub fn command(&mut self, cx: &mut Cx<'_>, msg: &HostMsg) -> Outcome {
        let seq = self.send(cx, msg);
        check!(
            self.host.last_ack == Some(seq),
            "{msg:?} (seq {seq}) not acknowledged; errors {:?}",
            self.host.errors
        );
        Ok(())
    }
}

/// Names of the commands, by [`command_index`].
const COMMANDS: [&str; 14] = [
    "Hello",
    "Configure",
    "SetHeater",
    "HeaterOff",
    "Arm",
    "Disarm",
    "Release",
    "Abort",
    "Status",
    "Pull",
    "Heartbeat",
    "Safe",
    "PullBlocks",
    "other",
];

fn command_index(m: &HostMsg) -> usize {
    match m {
        HostMsg::Hello { .. } => 0,
        HostMsg::Configure(_) => 1,
        HostMsg::SetHeater(_) => 2,
        HostMsg::HeaterOff => 3,
        HostMsg::Arm => 4,
        HostMsg::Disarm => 5,
        HostMsg::Release => 6,
        HostMsg::Abort => 7,
        HostMsg::Status => 8,
        HostMsg::Pull { .. } => 9,
        HostMsg::Heartbeat => 10,
        HostMsg::Safe => 11,
        HostMsg::PullBlocks { .. } => 12,
        #[allow(unreachable_patterns)]
        _ => 13,
    }
}

/// The costs by state and by command, as notes.
fn breakdown(cx: &mut Cx<'_>, w: &Worst) {
    if !cx.counting() {
        return;
    }
    const STATES: [&str; 6] = [
        "Idle",
        "Configured",
        "Armed",
        "Running",
        "Finished",
        "Fault",
    ];
    for (name, s) in STATES.iter().zip(w.by_state.iter()) {
        if s.calls > 0 {
            cx.note(format_args!(
                "polls in {name}: {} calls, mean {} instructions, worst {}, stack {} bytes",
                s.calls,
                s.total / s.calls,
                s.worst,
                s.stack
            ));
        }
    }
    for (name, &(worst, stack)) in COMMANDS.iter().zip(w.by_command.iter()) {
        if worst > 0 {
            cx.note(format_args!(
                "on_bytes({name}): {worst} instructions, stack {stack} bytes"
            ));
        }
    }
}

/// Marks the start of each measured poll in an execution trace (`qemu -d exec`), for profiling
/// one poll; does nothing.
#[inline(never)]
pub fn poll_mark() {
    core::hint::black_box(());
}

/// What a run should end with.
struct Expect {
    /// The on-board result must equal the host's, bit for bit (analysed runs).
    analysed: bool,
    /// Stop the host reading for this long during the run (cable out), µs.
    outage_us: u64,
    /// Do not poll the application for this long during the run (its task held up), µs: the
    /// converter's ring fills meanwhile and the polls after must catch up in bounded steps.
    stall_us: u64,
}

/// A whole run of `record` through the application; checks the stream, the result and a pull, and
/// reports the figures.
fn whole_run(cx: &mut Cx<'_>, name: &str, configure: Configure, expect: Expect) -> Outcome {
    let rec = record(cx, name)?;
    // The board's run store: its RAM ring buffers, block index and flash bank.
    let mut r0 = [0u8; BOARD_RING_BYTES[0]];
    let mut r1 = [0u8; BOARD_RING_BYTES[1]];
    let mut r2 = [0u8; BOARD_RING_BYTES[2]];
    let mut r3 = [0u8; BOARD_RING_BYTES[3]];
    let mut index = [0u32; MAX_RUN_BLOCKS];
    let mut flash = [0xFFu8; FlashGeometry::H743_BANK2.bytes() as usize];
    let store = RunStore::new(
        [&mut r0[..], &mut r1[..], &mut r2[..], &mut r3[..]],
        &mut index,
    );
    let mut b = Bench::new(cx, rec, store, &mut flash);
    // start-up, then the host says hello and configures
    b.run_until(cx, 10 * POLL_US);
    b.command(
        cx,
        &HostMsg::Hello {
            protocol: PROTOCOL_VERSION,
        },
    )?;
    check!(b.host.hello, "no Hello back");
    b.command(cx, &HostMsg::Configure(configure))?;
    // the heater settles (here: the thermocouple reads a steady ambient)
    b.run_until(cx, b.now_us + 300 * POLL_US);
    check_eq!(b.app.state(), RigState::Configured);
    // arm: the magnet holds and the converter starts; exactly the record's hold is converted
    b.command(cx, &HostMsg::Arm)?;
    check_eq!(b.app.state(), RigState::Armed);
    let rate = configure.sample_rate_hz as u64;
    let hold_us = rec.hold as u64 * 1_000_000 / rate;
    let release_at = b.now_us + hold_us;
    b.run_until(cx, release_at);
    b.now_us = release_at;
    let at_release = b.worst.total;
    b.command(cx, &HostMsg::Release)?;
    check_eq!(b.app.state(), RigState::Running);
    check_eq!(b.hw.released_at_us(), Some(release_at));
    // stream until the run's end frame, with a cable-out outage early in the run
    let limit = release_at + (configure.max_duration_s as u64 + 10) * 1_000_000;
    let outage = (release_at + 20_000, release_at + 20_000 + expect.outage_us);
    // the stall after the outage (the backlog it leaves takes a while to catch up)
    let stall_at = outage.1 + 20_000;
    let stall = (stall_at, stall_at + expect.stall_us);
    while b.host.end.is_none() && b.now_us < limit {
        b.reading = !(outage.0..outage.1).contains(&b.now_us);
        b.now_us += POLL_US;
        if (stall.0..stall.1).contains(&b.now_us) {
            continue;
        }
        b.poll(cx);
    }
    b.reading = true;
    b.run_until(cx, b.now_us + 20 * POLL_US);
    let refused = b.hw.refused;
    let stream_end_us = b.now_us;
    let h = &b.host;
    check!(
        h.end.is_some(),
        "no RunEnded within {} s",
        limit / 1_000_000
    );
    check_eq!(h.malformed, 0);
    check_eq!(h.seq_backwards, 0, "run frames out of sequence");
    check_eq!(h.out_of_order, 0, "blocks out of order");
    if let Some((blk, i, got, want)) = h.mismatch {
        check!(
            false,
            "block {blk} sample {i}: streamed {got:?}, record {want:?}"
        );
    }
    let end = h.end.unwrap_or(RunEnd {
        run_id: 0,
        blocks: 0,
        samples: 0,
        overruns: 0,
        reason: EndReason::Aborted,
    });
    check_eq!(end.overruns, 0);
    check_eq!(end.samples, h.samples_checked, "every sample streamed once");
    check_eq!(end.blocks, h.next_block);
    check!(
        matches!(end.reason, EndReason::Stopped | EndReason::MaxDuration),
        "ended by {:?}",
        end.reason
    );
    if expect.outage_us > 0 {
        check!(
            refused > 0,
            "the outage made the link refuse nothing ({} frames sent)",
            b.hw.sent
        );
    }
    let result = h.result;
    check!(result.is_some(), "no Result frame");
    let result = result.unwrap_or(rec.host.result);
    if expect.analysed {
        check_eq!(end.samples, rec.host.pushed, "samples analysed");
        let mut host = rec.host.result;
        host.run_id = result.run_id;
        check!(
            same_bits(&result, &host),
            "on-board result differs from the host's: μ0 {} vs {} ({} ulp), μ1 {} vs {} ({} ulp)\n      \
             target {:?}\n      host   {:?}",
            result.best.mu0,
            host.best.mu0,
            ulps(result.best.mu0, host.best.mu0),
            result.best.mu1,
            host.best.mu1,
            ulps(result.best.mu1, host.best.mu1),
            result,
            host
        );
    } else {
        check_eq!(result.verdict, Verdict::NotAnalysed);
    }
    check_eq!(b.app.state(), RigState::Finished);
    let during_run = b.worst.total - at_release;
    let gap = b.hw.timing.worst_gap;

    // pull the whole run again: the same frames, byte for byte, from the oldest block held
    let run_id = end.run_id;
    b.host.pulling = true;
    b.command(
        cx,
        &HostMsg::Pull {
            run_id,
            from_block: 0,
        },
    )?;
    b.run_until(cx, b.now_us + 2_000 * POLL_US);
    let h = &b.host;
    check!(h.pulled_end, "the pull did not reach the end frame");
    check_eq!(h.pulled_first_block, Some(0));
    check_eq!(
        h.pulled as usize,
        h.run_frames.len(),
        "run frames pulled (header, blocks, events, result, end)"
    );
    check_eq!(
        h.pulled_same,
        h.pulled,
        "pulled frames byte-identical to the live ones"
    );
    cx.note(format_args!(
        "{} samples in {} blocks streamed and checked; {} frames refused during a {} ms outage and \
         sent later; a {} ms stall caught up; pull: {} frames, identical; \
         stream ended {} ms after release",
        end.samples,
        end.blocks,
        refused,
        expect.outage_us / 1000,
        expect.stall_us / 1000,
        h.pulled,
        (stream_end_us - release_at) / 1000
    ));
    // figures (the pull's polls included)
    let w = b.worst;
    breakdown(cx, &w);
    cx.note(format_args!(
        "worst poll at {} ms after release ({} samples taken, {} frames sent; poll #{}); {} polls",
        w.poll_at_us.saturating_sub(release_at) / 1000,
        w.poll_did.0,
        w.poll_did.1,
        w.poll_ordinal,
        w.polls
    ));
    let per_sample = during_run / (end.samples as u64).max(1);
    figures(cx, name, w, gap, per_sample)
}

/// Figure names of one record's run.
macro_rules! names {
    ($rec:literal) => {
        [
            concat!("app.", $rec, ".worst_poll"),
            concat!("app.", $rec, ".worst_on_bytes"),
            concat!("app.", $rec, ".stack_bytes"),
            concat!("app.", $rec, ".worst_between_ring_reads"),
            concat!("app.", $rec, ".instructions_per_sample"),
        ]
    };
}

fn figures(cx: &mut Cx<'_>, name: &str, w: Worst, gap: u64, per_sample: u64) -> Outcome {
    let counting = cx.counting();
    let on = |v: u64| counting.then_some(v);
    let [poll, bytes, stack, ring, sample] = match name {
        "coulomb_viscous" => names!("coulomb_viscous"),
        "short" => names!("short"),
        _ => names!("unloaded"),
    };
    let r0 = cx.figure(sample, on(per_sample), "instructions/sample", None);
    let r1 = cx.figure(poll, on(w.poll), "instructions", Some(CALL_BUDGET));
    let r2 = cx.figure(bytes, on(w.on_bytes), "instructions", Some(CALL_BUDGET));
    let r3 = cx.figure(stack, on(w.stack as u64), "bytes", Some(STACK_BUDGET));
    let r4 = cx.figure(ring, on(gap), "instructions", None);
    r0.and(r1).and(r2).and(r3).and(r4)
}

pub fn record<'b>(cx: &Cx<'b>, name: &str) -> Result<Record<'b>, Failure> {
    let b = cx.bundle()?;
    b.record(name).ok_or_else(|| {
        Failure::new(
            file!(),
            line!(),
            format_args!("the bundle has no record {name:?}"),
        )
    })
}

/// A Coulomb–viscous run, analysed on board: the result frame equals the host's analysis of the
/// same counts bit for bit; the application is not polled for 30 ms, and nothing is lost.
pub fn coulomb_viscous_run(cx: &mut Cx) -> Outcome {
    let rec = record(cx, "coulomb_viscous")?;
    whole_run(
        cx,
        "coulomb_viscous",
        rec.configure,
        Expect {
            analysed: true,
            outage_us: 0,
            stall_us: 30_000,
        },
    )
}

/// A run of five half-cycles (the `short` record, 5 kS/s): analysed from its peaks, each fitted
/// again at the end of the run from its kept window, within the application's budgets.
pub fn short_run(cx: &mut Cx) -> Outcome {
    let rec = record(cx, "short")?;
    whole_run(
        cx,
        "short",
        rec.configure,
        Expect {
            analysed: true,
            outage_us: 0,
            stall_us: 30_000,
        },
    )
}

/// The apparatus alone configured as unloaded (load 0): streamed in full and not analysed on
/// board; the link is cut for a second of the run (the 4 KiB pipe fills and refuses frames), the
/// application is not polled for 30 ms, and nothing is lost; pulled again whole.
pub fn unloaded_run(cx: &mut Cx) -> Outcome {
    let rec = record(cx, "unloaded")?;
    let mut configure = rec.configure;
    configure.rig.load_n = 0.0;
    whole_run(
        cx,
        "unloaded",
        configure,
        Expect {
            analysed: false,
            outage_us: 1_000_000,
            stall_us: 30_000,
        },
    )
}

/// The bring-up self-test's checks between runs (`HostMsg::SelfTest`): the converter's rate and
/// inputs, a flash sector erased, programmed, read back and erased again, filler frames through
/// the link, and the outputs' patterns; each polled to its report within the application's
/// budgets.
pub fn selftest_checks(cx: &mut Cx) -> Outcome {
    let rec = record(cx, "unloaded")?;
    let mut r0 = [0u8; BOARD_RING_BYTES[0]];
    let mut r1 = [0u8; BOARD_RING_BYTES[1]];
    let mut r2 = [0u8; BOARD_RING_BYTES[2]];
    let mut r3 = [0u8; BOARD_RING_BYTES[3]];
    let mut index = [0u32; MAX_RUN_BLOCKS];
    let mut flash = [0xFFu8; FlashGeometry::H743_BANK2.bytes() as usize];
    let store = RunStore::new(
        [&mut r0[..], &mut r1[..], &mut r2[..], &mut r3[..]],
        &mut index,
    );
    let mut b = Bench::new(cx, rec, store, &mut flash);
    b.run_until(cx, 10 * POLL_US);
    b.command(
        cx,
        &HostMsg::Hello {
            protocol: PROTOCOL_VERSION,
        },
    )?;
    let checks = [
        SelfTestCheck::Converter {
            rate_hz: 10_000,
            ms: 200,
        },
        SelfTestCheck::Flash { bytes: 4096 },
        SelfTestCheck::Throughput {
            frames: 64,
            len: FILLER_MAX as u16,
        },
        SelfTestCheck::Outputs,
        SelfTestCheck::Clock { intervals: 16 },
    ];
    for check in checks {
        b.host.selftest = None;
        b.command(cx, &HostMsg::SelfTest(check))?;
        let limit = b.now_us + 5_000_000;
        while b.app.selftest_running() && b.now_us < limit {
            b.now_us += POLL_US;
            b.poll(cx);
        }
        check!(!b.app.selftest_running(), "{check:?}: no report within 5 s");
        match (check, &b.host.selftest) {
            (SelfTestCheck::Converter { .. }, Some(SelfTestReport::Converter(r))) => {
                let (rate, ppm, ok) = tribo_firmware::selftest::judge_rate(r);
                check!(ok, "converter at {rate} S/s: {ppm} ppm ({r:?})");
                check!(r.samples >= 1900, "{r:?}");
            }
            (SelfTestCheck::Flash { .. }, Some(SelfTestReport::Flash(r))) => {
                check_eq!(tribo_firmware::selftest::judge_flash(r), Ok(()));
                check_eq!((r.sector, r.bytes, r.mismatches), (7, 4096, 0));
            }
            (SelfTestCheck::Throughput { .. }, Some(SelfTestReport::FillerDone { frames, .. })) => {
                check_eq!((*frames, b.host.fillers), (64, 64));
            }
            // The replayed hardware has no pins: every pattern driven, nothing sensed.
            (SelfTestCheck::Outputs, Some(SelfTestReport::Outputs(r))) => {
                check_eq!(r.steps, 5);
                check!(r.outputs.iter().all(|o| !o.sensed), "{r:?}");
            }
            // No TIM16 or LSI on the emulated chip: the check says "not available here", which
            // the host reads as not measurable, never as a pass.
            (SelfTestCheck::Clock { .. }, Some(SelfTestReport::Clock(r))) => {
                check!(!r.available && r.intervals == 0, "{r:?}");
                check_eq!(
                    tribo_firmware::selftest::judge_clock(r),
                    Err(tribo_firmware::selftest::ClockProblem::NotAvailable)
                );
            }
            (c, r) => check!(false, "{c:?} answered by {r:?}"),
        }
    }
    let w = b.worst;
    let counting = cx.counting();
    let on = |v: u64| counting.then_some(v);
    cx.note(format_args!(
        "self-test: worst poll at {} ms ({} polls)",
        w.poll_at_us / 1000,
        w.polls
    ));
    let r1 = cx.figure(
        "app.selftest.worst_poll",
        on(w.poll),
        "instructions",
        Some(CALL_BUDGET),
    );
    let r2 = cx.figure(
        "app.selftest.worst_on_bytes",
        on(w.on_bytes),
        "instructions",
        Some(CALL_BUDGET),
    );
    let r3 = cx.figure(
        "app.selftest.stack_bytes",
        on(w.stack as u64),
        "bytes",
        Some(STACK_BUDGET),
    );
    r1.and(r2).and(r3)
}

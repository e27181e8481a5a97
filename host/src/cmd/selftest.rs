//! `tribo selftest`: the bring-up self-test. The rig measures (`tribo_firmware::selftest`, the
//! same code on the board and on the virtual rig), this command judges each measurement by the
//! limits that module documents and prints one row per check: pass, FAIL, or "hardware only" (a
//! figure only the real chip has, e.g. the flash controller's flags on the virtual rig).

use crate::link::args::LinkArgs;
use crate::link::{firmware_version, reset_cause_text, Address, Link, LinkError, LinkErrorKind};
use crate::out::text as out;
use anyhow::bail;
use serde_json::json;
use std::time::{Duration, Instant};
use tribo_firmware::selftest::{
    judge_channel, judge_clock, judge_flash, judge_identity, judge_output, judge_rate, judge_reset,
    judge_thermocouple, rest_window, ChannelProblem, ClockProblem, Deliberate, ERASE_MAX_US,
    LSI_MAX_HZ, LSI_MIN_HZ, LSI_READY_US, MIN_THROUGHPUT_BYTES_S, OUTPUT_NAMES, RATE_TOLERANCE_PPM,
};
use tribo_firmware::thermocouple::BadRead;
use tribo_wire::{
    filler_byte, BootReport, Channel, ClockReport, Configure, ConverterReport, DeviceError,
    DeviceMsg, ErrorCode, FlashReport, HostMsg, OutputsReport, SelfTestCheck, SelfTestReport,
    ThermocoupleReport, FILLER_MAX,
};

/// Arguments of `tribo selftest`.
#[derive(clap::Args, Debug)]
#[command(
    after_help = "Rows (the README's \"Bring-up on a NUCLEO-H743ZI\" says what to check when one fails):
  sample-rate         samples the ADC delivered (DMA index) against the crystal time base, ppm
  hse-vs-lsi          the LSI (an RC oscillator independent of the crystal) measured by a timer
                        clocked from the HSE, against the LSI's datasheet limits: a wrong HSE
  input-displacement  each analog input: not at a rail, not one code, and its signature at rest
  input-velocity        (x within ±1.1·x0, v and F near zero, ECR above the controller's floor:
  input-force           a grounded or swapped input fails; --open-inputs on a bare board)
  input-ecr             (pins PA3, PC0, PB1, PF11)
  flash               a bank-2 sector the stored run does not use: erase, program, read back, erase
  flash-flags         the flash controller's error flags after it (hardware only on the virtual rig)
  thermocouple        the MAX31856: answers, configured (type K, open-circuit detection on), no
                        fault flag (open, shorted, ranges), cold junction 5–50 °C
  output-heater       each output driven through a few patterns and read back where the board
  output-magnet         can (pin levels, the DAC's output register); each row says what it
  output-ecr-source     cannot sense (no sense wire on a NUCLEO-H743ZI)
  output-ecr-range
  output-lamps
  link-throughput     filler frames from the rig through the link, bytes/s and checked byte for byte
  reset-record        a deliberate panic: the rig resets and its boot report says Panic and why
  watchdog            a deliberately stalled task: outputs safe, reset, the report names the task

--json prints one JSON object: {\"port\", \"firmware\", \"serial\", \"passed\", \"failed\": [row names],
\"rows\": [{\"row\", \"verdict\": \"pass\" | \"fail\" | \"hardware-only\", \"summary\", \"figures\"}]}.

Exit status: 0 every measured row passed; 1 a row failed (named on standard error) or the rig
could not be tested.

Examples:
  tribo selftest --port /dev/ttyACM0
  tribo rig --virtual --listen 127.0.0.1:7411 &   tribo selftest --port tcp://127.0.0.1:7411 --json"
)]
pub struct Args {
    /// The rig to test.
    #[command(flatten)]
    pub link: LinkArgs,
    /// Print one JSON object (set by the global `--json`; its shape is in the command's help).
    #[arg(skip)]
    pub json: bool,
    /// Sample rate of the converter check, S/s.
    #[arg(long, default_value_t = 10_000, value_name = "HZ")]
    pub rate: u32,
    /// Length of the converter check, s (the rate's resolution is about 2 samples over it).
    #[arg(long, default_value_t = 2.0, value_name = "S")]
    pub seconds: f64,
    /// Leave out the two checks that reset the rig (reset-record, watchdog).
    #[arg(long)]
    pub no_reset: bool,
    /// The analog inputs are open (a bare board, no front ends): do not judge each input's
    /// signature at rest (the channel identity), only that it converts.
    #[arg(long)]
    pub open_inputs: bool,
}

/// A row's outcome.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    /// Measured and within its limits.
    Pass,
    /// Measured and out of its limits.
    Fail,
    /// Only the real chip can measure it; neither pass nor fail.
    HardwareOnly,
}

impl Verdict {
    /// The verdict as printed and in `--json` (`pass`, `fail`, `hardware-only`).
    pub fn name(self) -> &'static str {
        match self {
            Verdict::Pass => "pass",
            Verdict::Fail => "fail",
            Verdict::HardwareOnly => "hardware-only",
        }
    }
}

/// One row of the table.
#[derive(Debug, Clone)]
pub struct Row {
    /// The row's name (`sample-rate`, `flash`, …).
    pub name: String,
    /// Its outcome.
    pub verdict: Verdict,
    /// The figures, in words.
    pub summary: String,
    /// The figures, for `--json`.
    pub figures: serde_json::Value,
}

impl Row {
    fn new(name: impl Into<String>, ok: bool, summary: String, figures: serde_json::Value) -> Row {
        Row {
            name: name.into(),
            verdict: if ok { Verdict::Pass } else { Verdict::Fail },
            summary,
            figures,
        }
    }

    fn failed(name: impl Into<String>, why: impl std::fmt::Display) -> Row {
        Row::new(name, false, why.to_string(), json!({}))
    }
}

/// Rows of a converter report: the rate, then one per analog input, each judged by its signature
/// at rest too unless `open_inputs`.
pub fn converter_rows(r: &ConverterReport, open_inputs: bool) -> Vec<Row> {
    let (rate, ppm, ok) = judge_rate(r);
    let dt = r.last_us.saturating_sub(r.first_us) as f64 * 1e-6;
    let n = r.last_index.saturating_sub(r.first_index);
    let mut rows = vec![Row::new(
        "sample-rate",
        ok && r.lost == 0,
        format!(
            "{rate:.2} S/s against the timer's {:.2} S/s: {ppm:+.0} ppm ({n} samples in {dt:.3} s, {} lost){}",
            r.clock.rate_hz(),
            r.lost,
            if !ok {
                format!("; more than {RATE_TOLERANCE_PPM} ppm off")
            } else if r.lost > 0 {
                "; samples were lost".into()
            } else {
                String::new()
            }
        ),
        json!({"rate_hz": rate, "timer_rate_hz": r.clock.rate_hz(), "ppm": ppm, "samples": n,
               "seconds": dt, "lost": r.lost}),
    )];
    let cal = Configure::real_rig(0.3).calibration;
    let pins = tribo_firmware::selftest::ANALOG_PINS;
    for (i, s) in r.channels.iter().enumerate() {
        let ch = Channel::ALL[i];
        let verdict = judge_channel(s, r.samples);
        let why = match verdict {
            Ok(()) => String::new(),
            Err(ChannelProblem::NoSamples) => "; no sample was read".into(),
            Err(ChannelProblem::AtRail) => {
                format!("; at a rail in {} of {} samples", s.at_rail, r.samples)
            }
            Err(ChannelProblem::Stuck) => format!("; stuck at code {}", s.min),
        };
        let si = cal[i].to_si(s.mean.clamp(0.0, 65535.0) as u16);
        let (lo, hi) = rest_window(i);
        let identity = if open_inputs {
            None
        } else {
            Some(judge_identity(s, i, &cal[i]).is_ok())
        };
        let identity_text =
            match identity {
                None => "; identity not judged (--open-inputs)".to_string(),
                Some(true) => format!("; at rest within {lo:+.3e}…{hi:+.3e} {}", ch.unit()),
                // Only the judge of the converting comes first: a rail or a stuck code says more.
                Some(false) if verdict.is_err() => String::new(),
                Some(false) => format!(
                "; not the {}'s signature at rest ({lo:+.3e}…{hi:+.3e} {}): {}",
                ch.name(),
                ch.unit(),
                match i {
                    3 => "the input grounded, another channel's signal on this pin, or the contact \
                          open (unloaded)",
                    _ => "the input grounded (a small offset) or another channel's signal on \
                          this pin (swapped cables)",
                }
            ),
            };
        rows.push(Row::new(
            format!("input-{}", ch.name()),
            verdict.is_ok() && identity != Some(false),
            format!(
                "{}: mean {:.1}, sd {:.1}, {}…{} counts ({:+.4e} {}){why}{identity_text}",
                pins[i],
                s.mean,
                s.sd,
                s.min,
                s.max,
                si,
                ch.unit()
            ),
            json!({"pin": pins[i], "mean": s.mean, "sd": s.sd, "min": s.min, "max": s.max,
                   "at_rail": s.at_rail, "samples": r.samples, "si": si,
                   "rest_window": [lo, hi], "identity": identity}),
        ));
    }
    rows
}

/// Intervals a clock check measures (one per poll of the rig: ~16 ms on the board).
pub const CLOCK_INTERVALS: u16 = 32;

/// The clock row: the LSI as the HSE-clocked timer measures it, against the LSI's limits.
pub fn clock_row(r: &ClockReport) -> Row {
    let name = "hse-vs-lsi";
    let figures = json!({"available": r.available, "lsi_ready": r.lsi_ready,
        "timer_hz": r.timer_hz, "periods_per_capture": r.periods_per_capture,
        "intervals": r.intervals, "overcaptures": r.overcaptures, "timeouts": r.timeouts,
        "ticks_sum": r.ticks_sum, "ticks_min": r.ticks_min, "ticks_max": r.ticks_max,
        "lsi_limits_hz": [LSI_MIN_HZ, LSI_MAX_HZ]});
    let khz = |hz: f64| hz * 1e-3;
    let limits = format!(
        "DS12110's {:.2}–{:.2} kHz",
        khz(LSI_MIN_HZ),
        khz(LSI_MAX_HZ)
    );
    let measured = |f: &tribo_firmware::selftest::ClockFigures| {
        format!(
            "LSI {:.3} kHz through the HSE-clocked timer ({:.1} ticks of {:.3} MHz per {} periods, \
             {}…{}; {} intervals, {} overwritten and dropped)",
            khz(f.lsi_hz),
            f.ticks_mean,
            r.timer_hz as f64 * 1e-6,
            r.periods_per_capture,
            r.ticks_min,
            r.ticks_max,
            r.intervals,
            r.overcaptures
        )
    };
    let pct = |x: f64| (x - 1.0) * 100.0;
    match judge_clock(r) {
        Ok(f) => Row::new(
            name,
            true,
            format!(
                "{}; within {limits}: the HSE is within {:+.1}…{:+.1} % of its 8 MHz ({:+.2} % if \
                 the LSI is typical)",
                measured(&f),
                pct(f.hse_ratio.0),
                pct(f.hse_ratio.1),
                pct(f.hse_ratio_typ)
            ),
            figures,
        ),
        Err(ClockProblem::OutOfRange(f)) => Row::new(
            name,
            false,
            format!(
                "{}; outside {limits}: the HSE is {:+.1}…{:+.1} % off its 8 MHz ({:+.2} % if the \
                 LSI is typical): not the clock the firmware assumes",
                measured(&f),
                pct(f.hse_ratio.0),
                pct(f.hse_ratio.1),
                pct(f.hse_ratio_typ)
            ),
            figures,
        ),
        Err(ClockProblem::NotAvailable) => Row {
            name: name.into(),
            verdict: Verdict::HardwareOnly,
            summary: "not measurable on this rig: it has no timer input on the LSI (an emulator \
                      or replayed hardware)"
                .into(),
            figures,
        },
        Err(ClockProblem::LsiNotReady) => Row::new(
            name,
            false,
            format!(
                "not measurable: the LSI did not report ready within {} ms (RCC_CSR LSIRDY)",
                LSI_READY_US / 1000
            ),
            figures,
        ),
        Err(ClockProblem::NoInterval) => Row::new(
            name,
            false,
            format!(
                "not measurable: no interval measured ({} waits without a capture, {} intervals \
                 overwritten): the LSI does not reach TIM16 (TISEL) or the timer does not count",
                r.timeouts, r.overcaptures
            ),
            figures,
        ),
    }
}

/// What each output's row reads back on the NUCLEO-H743ZI, and what it cannot sense.
const OUTPUT_TEXT: [(&str, &str); 5] = [
    (
        "PD12 (gate pin) read low with the heater off",
        "the gate driver, the MOSFET and the element (no sense wire: a dead element or a shorted \
         MOSFET shows as the heater's faults once it heats)",
    ),
    (
        "PE9/PE11 (bridge inputs) read low with the coil off",
        "the bridge's outputs and the coil current (no sense wire: a coil that does not hold shows \
         as the pin not held at x0)",
    ),
    (
        "DAC1 DOR1 converted each code written (0 and 2 mV)",
        "the DAC pin PA4 (analog mode, no input buffer) and the divider's output (no sense wire)",
    ),
    (
        "PG0–PG2 read back each range address",
        "the mux's switches and the feedback resistors (no sense wire)",
    ),
    (
        "PB0/PE1/PB14 read back each pattern",
        "whether the LEDs light (no sense wire)",
    ),
];

/// Rows of an outputs report: one per output.
pub fn outputs_rows(r: &OutputsReport) -> Vec<Row> {
    OUTPUT_NAMES
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let o = r.outputs[i];
            let (reads, blind) = OUTPUT_TEXT[i];
            let name = format!("output-{name}");
            let fig = json!({"sensed": o.sensed, "steps": r.steps, "mismatches": o.mismatches,
                             "driven": o.driven, "read": o.read});
            let width = if i == 2 { 3 } else { 1 };
            match judge_output(r, i) {
                None => Row {
                    name,
                    verdict: Verdict::HardwareOnly,
                    summary: format!("not sensed on this rig; on the board: {reads}; not sensed: {blind}"),
                    figures: fig,
                },
                Some(Ok(())) => Row::new(
                    name,
                    true,
                    format!("{reads}, {} steps; not sensed: {blind}", r.steps),
                    fig,
                ),
                Some(Err(e)) => Row::new(
                    name,
                    false,
                    format!(
                        "{e}: {} of {} steps wrong, first drove {:#0w$x}, read {:#0w$x}; not sensed: {blind}",
                        o.mismatches,
                        r.steps,
                        o.driven,
                        o.read,
                        w = width + 2
                    ),
                    fig,
                ),
            }
        })
        .collect()
}

/// The flash controller's error flags (FLASH_SR2 bits 17–28 on the STM32H743).
const FLASH_ERROR_FLAGS: u32 = tribo_firmware::selftest::FLASH_SR2_FLAGS;

/// Rows of a flash report: the check, then the controller's flags.
pub fn flash_rows(r: &FlashReport) -> Vec<Row> {
    let verdict = judge_flash(r);
    let ms = |us: u32| us as f64 * 1e-3;
    let flash = Row::new(
        "flash",
        verdict.is_ok(),
        format!(
            "sector {}: erase {:.0} ms, program {} B {:.1} ms, read back {} bad bytes, erase again {:.0} ms (limit {:.0} ms){}",
            r.sector,
            ms(r.erase_us),
            r.bytes,
            ms(r.program_us),
            r.mismatches,
            ms(r.erase2_us),
            ms(ERASE_MAX_US),
            verdict.err().map(|e| format!("; {e}")).unwrap_or_default()
        ),
        json!({"sector": r.sector, "bytes": r.bytes, "erase_ok": r.erase_ok,
               "program_ok": r.program_ok, "mismatches": r.mismatches, "erase_us": r.erase_us,
               "program_us": r.program_us, "read_us": r.read_us, "erase2_us": r.erase2_us}),
    );
    let flags = match r.flags {
        None => Row {
            name: "flash-flags".into(),
            verdict: Verdict::HardwareOnly,
            summary: "hardware only: this rig's flash has no controller flags (a simulated flash)"
                .into(),
            figures: json!({"flags": null}),
        },
        Some(f) => Row::new(
            "flash-flags",
            f & FLASH_ERROR_FLAGS == 0,
            format!(
                "FLASH_SR2 {f:#010x}{}",
                if f & FLASH_ERROR_FLAGS == 0 {
                    ": no error flag".to_string()
                } else {
                    format!(": error flags {:#010x}", f & FLASH_ERROR_FLAGS)
                }
            ),
            json!({"flags": f, "errors": f & FLASH_ERROR_FLAGS}),
        ),
    };
    vec![flash, flags]
}

/// The thermocouple row: the converter's register file judged as the heater judges every read.
pub fn thermocouple_row(r: &ThermocoupleReport) -> Row {
    let figures = json!({"registers": r.registers, "age_us": r.age_us});
    match judge_thermocouple(r) {
        Ok(t) => Row::new(
            "thermocouple",
            true,
            format!(
                "MAX31856 configured (type K, 50 Hz filter, open-circuit detection on), no fault \
                 flag; cold junction {:.2} °C, plate {:.2} °C (read {:.0} ms before the check)",
                t.cold_junction_c,
                t.plate_c,
                r.age_us as f64 * 1e-3
            ),
            figures,
        ),
        Err(b) => {
            let cr = r.registers.map_or([0, 0], |g| [g[0], g[1]]);
            let cj = tribo_wire::limits::COLD_JUNCTION_C;
            let why = match b {
                BadRead::Missing { age_ms: u32::MAX } => "the MAX31856 never answered: check SPI1 \
                    (SCK PA5, MISO PA6, MOSI PB5), chip select PD14 and its supply"
                    .to_string(),
                BadRead::Missing { age_ms } => format!(
                    "the MAX31856's last read is {age_ms} ms old (the task reads it every 100 ms): \
                     it stopped answering on SPI1"
                ),
                BadRead::AllZero => "every register reads 0x00: MISO (PA6) stuck low or the chip \
                    unpowered"
                    .into(),
                BadRead::AllOnes => {
                    "every register reads 0xFF: MISO (PA6) stuck high or no chip".into()
                }
                BadRead::Config => format!(
                    "the configuration does not read back (CR0 {:#04x}, CR1 {:#04x}; expected \
                     0x91, 0x03): the chip did not take its writes (chip select PD14, MOSI PB5) \
                     or is another chip",
                    cr[0], cr[1]
                ),
                BadRead::Open => "open thermocouple (the chip's open-circuit detection): a wire \
                    broken or the probe not plugged in"
                    .into(),
                BadRead::OverUnderVoltage => "over/under-voltage on the thermocouple inputs: \
                    shorted to a supply or to ground"
                    .into(),
                BadRead::ThermocoupleRange => "the thermocouple reading is out of range (fault \
                    flag)"
                    .into(),
                BadRead::ColdJunctionRange => {
                    "the cold junction is out of range (fault flag)".into()
                }
                BadRead::StuckWord => "a temperature word reads all zeros or all ones: the chip \
                    converts nothing"
                    .into(),
                BadRead::ColdJunctionImplausible(c) => format!(
                    "cold junction {c:.1} °C, outside {:.0}–{:.0} °C: the converter board is \
                     broken or heated",
                    cj.start(),
                    cj.end()
                ),
                BadRead::PlateImplausible(c) => {
                    format!("plate {c:.1} °C: below anything the rig can be (polarity reversed?)")
                }
            };
            Row::new("thermocouple", false, why, figures)
        }
    }
}

/// What a refused self-test command means.
fn refusal(e: &LinkError) -> anyhow::Error {
    match e.code {
        Some(ErrorCode::Malformed) => anyhow::anyhow!(
            "the rig's firmware does not know the self-test (it is older than this tribo): flash the \
             current firmware (the README's \"Bring-up on a NUCLEO-H743ZI\" says how) and run \
             `tribo selftest` again"
        ),
        Some(ErrorCode::Busy) => anyhow::anyhow!(
            "the rig is busy (armed, running a run, still writing its last run to flash, its \
             stored run fills the flash, or, for the reset and output checks, its magnet still \
             holds): let it finish or abort it, let the magnet go (it lets go once no host has held \
             its lease for 3 s), then run `tribo selftest` again"
        ),
        _ => anyhow::anyhow!("{e}"),
    }
}

/// Whether the rig answered a frame it could not decode since the last command: a firmware
/// older than the self-test answers its command so (without the command's sequence number).
fn saw_malformed(link: &mut Link) -> bool {
    let mut seen = false;
    while let Ok(Some(f)) = link.next(Duration::from_millis(50)) {
        seen |= matches!(
            f.frame.msg,
            DeviceMsg::Error(DeviceError {
                code: ErrorCode::Malformed,
                ..
            })
        );
    }
    seen
}

/// Sends a check and waits for its report.
fn measure(
    link: &mut Link,
    check: SelfTestCheck,
    wait: Duration,
) -> anyhow::Result<SelfTestReport> {
    if let Err(e) = link.command(HostMsg::SelfTest(check)) {
        if e.kind == LinkErrorKind::NoAnswer && saw_malformed(link) {
            let old = LinkError {
                code: Some(ErrorCode::Malformed),
                ..e
            };
            return Err(refusal(&old));
        }
        return Err(refusal(&e));
    }
    let deadline = Instant::now() + wait;
    while let Some(left) = deadline.checked_duration_since(Instant::now()) {
        match link.next(left)? {
            Some(f) => match f.frame.msg {
                DeviceMsg::SelfTest(r) => return Ok(r),
                _ => continue,
            },
            None => break,
        }
    }
    bail!(
        "the rig did not report its {} check within {:.0} s: check the cable; if it persists, \
         power-cycle the rig",
        check_name(&check),
        wait.as_secs_f64()
    )
}

fn check_name(c: &SelfTestCheck) -> &'static str {
    match c {
        SelfTestCheck::Converter { .. } => "converter",
        SelfTestCheck::Flash { .. } => "flash",
        SelfTestCheck::Throughput { .. } => "throughput",
        SelfTestCheck::Panic => "panic",
        SelfTestCheck::Stall => "stall",
        SelfTestCheck::Thermocouple => "thermocouple",
        SelfTestCheck::Outputs => "outputs",
        SelfTestCheck::Clock { .. } => "clock",
    }
}

/// Filler frames of the throughput check.
const FILLER_FRAMES: u32 = 2000;

/// The link's throughput: filler frames timed from the first to the last, every byte checked.
fn throughput(link: &mut Link) -> anyhow::Result<Row> {
    let len = FILLER_MAX as u16;
    link.command(HostMsg::SelfTest(SelfTestCheck::Throughput {
        frames: FILLER_FRAMES,
        len,
    }))
    .map_err(|e| refusal(&e))?;
    let deadline = Instant::now() + Duration::from_secs(30);
    let (mut first, mut last) = (None::<Instant>, Instant::now());
    let (mut got, mut bytes, mut bad, mut expect) = (0u32, 0u64, 0u32, 0u32);
    let refused = loop {
        let Some(left) = deadline.checked_duration_since(Instant::now()) else {
            bail!(
                "{got} of {FILLER_FRAMES} filler frames arrived within 30 s and the rig did not say it \
                 was done: the link stalls; check the cable and the port"
            );
        };
        let Some(f) = link.next(left)? else { continue };
        match &f.frame.msg {
            DeviceMsg::SelfTest(SelfTestReport::Filler { index, data }) => {
                let now = Instant::now();
                if first.is_none() {
                    first = Some(now);
                } else {
                    bytes += f.raw.len() as u64;
                }
                last = now;
                got += 1;
                let whole = *index == expect
                    && data.len() == len as usize
                    && data
                        .iter()
                        .enumerate()
                        .all(|(i, &b)| b == filler_byte(*index, i));
                if !whole {
                    bad += 1;
                }
                expect = index.wrapping_add(1);
            }
            DeviceMsg::SelfTest(SelfTestReport::FillerDone { refused, .. }) => break *refused,
            _ => {}
        }
    };
    let secs = first.map_or(0.0, |t| last.duration_since(t).as_secs_f64());
    let rate = if secs > 0.0 { bytes as f64 / secs } else { 0.0 };
    let missing = FILLER_FRAMES.saturating_sub(got);
    let ok = bad == 0 && missing == 0 && rate >= MIN_THROUGHPUT_BYTES_S;
    Ok(Row::new(
        "link-throughput",
        ok,
        format!(
            "{:.0} kB/s ({got} frames of {len} B in {secs:.3} s; {bad} wrong, {missing} missing; the rig waited {refused} times for room){}",
            rate / 1000.0,
            if rate < MIN_THROUGHPUT_BYTES_S {
                format!("; below the {:.0} kB/s a 20 kS/s run needs", MIN_THROUGHPUT_BYTES_S / 1000.0)
            } else {
                String::new()
            }
        ),
        json!({"bytes_per_s": rate, "frames": got, "frame_bytes": len, "seconds": secs,
               "wrong": bad, "missing": missing, "rig_waited": refused}),
    ))
}

/// A deliberate panic or stall, then the boot report after the reboot: the link it came on, the
/// row.
fn deliberate(mut link: Link, d: Deliberate, again: &LinkArgs) -> (Option<Link>, Row) {
    let (name, check) = match d {
        Deliberate::Panic => ("reset-record", SelfTestCheck::Panic),
        Deliberate::Stall => ("watchdog", SelfTestCheck::Stall),
    };
    // The report kept from our own hello is not this reset's.
    link.take_boot_report();
    if let Err(e) = link.command(HostMsg::SelfTest(check)) {
        let why = refusal(&e);
        return (Some(link), Row::failed(name, why));
    }
    let t0 = Instant::now();
    match await_boot(link, again, Duration::from_secs(20)) {
        Ok((link, boot)) => {
            let secs = t0.elapsed().as_secs_f64();
            let verdict = judge_reset(d, &boot);
            let row = Row::new(
                name,
                verdict.is_ok(),
                format!(
                    "reset after {secs:.1} s, boot report: {}{}{}",
                    reset_cause_text(boot.cause),
                    if boot.message.is_empty() {
                        String::new()
                    } else {
                        format!(": \"{}\"", boot.message)
                    },
                    verdict.err().map(|e| format!("; {e}")).unwrap_or_default()
                ),
                json!({"cause": format!("{:?}", boot.cause), "message": boot.message.as_str(),
                       "seconds": secs}),
            );
            (Some(link), row)
        }
        Err(e) => (None, Row::failed(name, format!("{e:#}"))),
    }
}

/// Says hello until the rig answers with a boot report (its first hello after the reset),
/// reopening the port as `again` names it (or finds it) when the reset took it away (a USB rig
/// enumerates again; the port is closed meanwhile, so the system gives it its name back).
fn await_boot(link: Link, again: &LinkArgs, wait: Duration) -> anyhow::Result<(Link, BootReport)> {
    let deadline = Instant::now() + wait;
    let mut link = Some(link);
    let mut last_err = String::from("no answer");
    while Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(200));
        let mut l = match link.take() {
            Some(l) => l,
            None => match again.connect() {
                Ok((l, _)) => l,
                Err(e) => {
                    last_err = format!("{e:#}");
                    continue;
                }
            },
        };
        if l.boot_report().is_none() {
            match l.hello() {
                Ok(_) => {}
                Err(e) if matches!(e.kind, LinkErrorKind::Closed | LinkErrorKind::NoAnswer) => {
                    last_err = e.to_string();
                    continue; // reopened on the next round
                }
                Err(e) => return Err(e.into()),
            }
        }
        if let Some(b) = l.take_boot_report() {
            return Ok((l, b));
        }
        link = Some(l);
    }
    bail!(
        "the rig did not come back with a boot report within {:.0} s ({last_err}): it did not reset, \
         or it did not come back; power-cycle it and run `tribo status`",
        wait.as_secs_f64()
    )
}

/// The table as text.
pub fn render(rows: &[Row]) -> String {
    let mut t = String::new();
    for r in rows {
        let v = match r.verdict {
            Verdict::Pass => "pass",
            Verdict::Fail => "FAIL",
            Verdict::HardwareOnly => "--",
        };
        t.push_str(&format!("{:<19}{v:<6}{}\n", r.name, r.summary));
    }
    t
}

/// Runs the subcommand.
pub fn run(args: Args) -> anyhow::Result<()> {
    if !(args.seconds.is_finite() && (0.1..=60.0).contains(&args.seconds)) {
        return Err(crate::exit::Usage("--seconds takes 0.1 to 60 s".into()).into());
    }
    if !tribo_wire::limits::SAMPLE_RATE_HZ.contains(&args.rate) {
        return Err(crate::exit::Usage(format!(
            "--rate takes {}–{} S/s",
            tribo_wire::limits::SAMPLE_RATE_HZ.start(),
            tribo_wire::limits::SAMPLE_RATE_HZ.end()
        ))
        .into());
    }
    let (mut link, info) = args.link.connect()?;
    let port = link.name().to_string();
    if !args.json {
        out(&format!(
            "self-test of the rig on {port}: firmware {}, serial {:016x}\n",
            firmware_version(&info),
            info.serial
        ))?;
    }
    let mut rows = Vec::new();
    let ms = (args.seconds * 1000.0).round() as u32;
    let wait = Duration::from_millis(ms as u64) + Duration::from_secs(10);
    match measure(
        &mut link,
        SelfTestCheck::Converter {
            rate_hz: args.rate,
            ms,
        },
        wait,
    ) {
        Ok(SelfTestReport::Converter(r)) => rows.extend(converter_rows(&r, args.open_inputs)),
        Ok(other) => rows.push(Row::failed(
            "sample-rate",
            format!("unexpected report {other:?}"),
        )),
        // Refused (busy, old firmware) or gone: nothing else would do better.
        Err(e) => return Err(e.context("the converter check")),
    }
    match measure(
        &mut link,
        SelfTestCheck::Clock {
            intervals: CLOCK_INTERVALS,
        },
        Duration::from_secs(5),
    ) {
        Ok(SelfTestReport::Clock(r)) => rows.insert(1, clock_row(&r)),
        Ok(other) => rows.insert(
            1,
            Row::failed("hse-vs-lsi", format!("unexpected report {other:?}")),
        ),
        Err(e) => rows.insert(1, Row::failed("hse-vs-lsi", format!("{e:#}"))),
    }
    match measure(
        &mut link,
        SelfTestCheck::Flash { bytes: 4096 },
        Duration::from_secs(15),
    ) {
        Ok(SelfTestReport::Flash(r)) => rows.extend(flash_rows(&r)),
        Ok(other) => rows.push(Row::failed("flash", format!("unexpected report {other:?}"))),
        Err(e) => rows.push(Row::failed("flash", format!("{e:#}"))),
    }
    match measure(
        &mut link,
        SelfTestCheck::Thermocouple,
        Duration::from_secs(5),
    ) {
        Ok(SelfTestReport::Thermocouple(r)) => rows.push(thermocouple_row(&r)),
        Ok(other) => rows.push(Row::failed(
            "thermocouple",
            format!("unexpected report {other:?}"),
        )),
        Err(e) => rows.push(Row::failed("thermocouple", format!("{e:#}"))),
    }
    match measure(&mut link, SelfTestCheck::Outputs, Duration::from_secs(5)) {
        Ok(SelfTestReport::Outputs(r)) => rows.extend(outputs_rows(&r)),
        Ok(other) => rows.push(Row::failed(
            "output-heater",
            format!("unexpected report {other:?}"),
        )),
        Err(e) => {
            for n in OUTPUT_NAMES {
                rows.push(Row::failed(format!("output-{n}"), format!("{e:#}")));
            }
        }
    }
    match throughput(&mut link) {
        Ok(r) => rows.push(r),
        Err(e) => rows.push(Row::failed("link-throughput", format!("{e:#}"))),
    }
    if !args.no_reset {
        // After a reset: the port the rig was found on (a virtual rig's address, a serial port
        // named or found), or found again as the first time when it was not named.
        let again = if link.name().starts_with("tcp://") {
            LinkArgs {
                port: Address::parse(link.name()).ok(),
                store: None,
            }
        } else {
            args.link.clone()
        };
        let mut link = Some(link);
        for d in [Deliberate::Panic, Deliberate::Stall] {
            let Some(l) = link.take() else {
                let name = if d == Deliberate::Panic {
                    "reset-record"
                } else {
                    "watchdog"
                };
                rows.push(Row::failed(
                    name,
                    "not run: the rig did not come back from the previous check",
                ));
                continue;
            };
            let (l, row) = deliberate(l, d, &again);
            link = l;
            rows.push(row);
        }
    }
    let failed: Vec<&str> = rows
        .iter()
        .filter(|r| r.verdict == Verdict::Fail)
        .map(|r| r.name.as_str())
        .collect();
    if args.json {
        crate::out::print_json(json!({
            "port": port,
            "firmware": firmware_version(&info),
            "serial": format!("{:016x}", info.serial),
            "passed": failed.is_empty(),
            "failed": failed,
            "rows": rows.iter().map(|r| json!({
                "row": r.name,
                "verdict": r.verdict.name(),
                "summary": r.summary,
                "figures": r.figures,
            })).collect::<Vec<_>>(),
        }))?;
    } else {
        out(&render(&rows))?;
    }
    if !failed.is_empty() {
        bail!(
            "self-test failed: {} (the README's \"Bring-up on a NUCLEO-H743ZI\" says what each row checks \
             and what to look at)",
            failed.join(", ")
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use tribo_wire::{ChannelStats, SampleClock};

    /// The pins `tribo selftest` names are the ones the board scans, in its order.
    #[test]
    fn the_pins_named_are_the_boards() {
        let board = include_str!("../../../firmware/board/src/board/mod.rs");
        let scanned: Vec<&str> = board
            .lines()
            .filter_map(|l| l.trim().strip_prefix("p.")?.strip_suffix(".degrade_adc(),"))
            .collect();
        assert_eq!(scanned, tribo_firmware::selftest::ANALOG_PINS);
    }

    fn report() -> ConverterReport {
        let s = ChannelStats {
            min: 32_700,
            max: 32_800,
            mean: 32_750.0,
            sd: 12.0,
            at_rail: 0,
        };
        ConverterReport {
            clock: SampleClock::exact(10_000),
            first_index: 100,
            last_index: 20_101,
            first_us: 10_000,
            last_us: 2_010_000,
            lost: 0,
            samples: 20_050,
            channels: [s; 4],
        }
    }

    #[test]
    fn a_converter_report_reads_as_rows_and_a_stuck_input_is_named() {
        let rows = converter_rows(&report(), false);
        let names: Vec<_> = rows.iter().map(|r| r.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "sample-rate",
                "input-displacement",
                "input-velocity",
                "input-force",
                "input-ecr"
            ]
        );
        assert!(rows.iter().all(|r| r.verdict == Verdict::Pass), "{rows:?}");
        assert!(rows[0].summary.contains("+50 ppm"), "{}", rows[0].summary);
        let mut r = report();
        r.channels[1] = ChannelStats {
            min: 40_000,
            max: 40_000,
            mean: 40_000.0,
            sd: 0.0,
            at_rail: 0,
        };
        r.last_index = 19_000;
        let rows = converter_rows(&r, false);
        assert_eq!(rows[0].verdict, Verdict::Fail, "{:?}", rows[0]);
        assert_eq!(rows[2].verdict, Verdict::Fail);
        assert!(
            rows[2].summary.contains("stuck at code 40000"),
            "{}",
            rows[2].summary
        );
        let t = render(&rows);
        assert!(t.contains("input-velocity     FAIL  PC0"), "{t}");
    }

    #[test]
    fn flash_flags_are_hardware_only_without_a_controller_and_judged_with_one() {
        let mut r = FlashReport {
            sector: 7,
            bytes: 4096,
            erase_ok: true,
            program_ok: true,
            mismatches: 0,
            erase_us: 1_100_000,
            program_us: 8_000,
            read_us: 2_000,
            erase2_us: 1_100_000,
            flags: None,
        };
        let rows = flash_rows(&r);
        assert_eq!(rows[0].verdict, Verdict::Pass);
        assert_eq!(rows[1].verdict, Verdict::HardwareOnly);
        r.flags = Some(0x0001_0000);
        assert_eq!(flash_rows(&r)[1].verdict, Verdict::Pass);
        r.flags = Some(0x0400_0000);
        let rows = flash_rows(&r);
        assert_eq!(rows[1].verdict, Verdict::Fail);
        assert!(
            rows[1].summary.contains("0x04000000"),
            "{}",
            rows[1].summary
        );
    }

    #[test]
    fn the_clock_row_says_not_measurable_without_the_timer_input_or_the_lsi_and_never_passes_then()
    {
        let ok = ClockReport {
            available: true,
            lsi_ready: true,
            timer_hz: 25_000_000,
            periods_per_capture: 8,
            intervals: 32,
            overcaptures: 2,
            timeouts: 0,
            ticks_sum: 32 * 6250,
            ticks_min: 6249,
            ticks_max: 6251,
        };
        let r = clock_row(&ok);
        assert_eq!(r.verdict, Verdict::Pass, "{r:?}");
        assert!(r.summary.contains("LSI 32.000 kHz") && r.summary.contains("2 overwritten"));
        // An emulator or replayed hardware: not measurable, neither pass nor fail.
        let r = clock_row(&ClockReport::default());
        assert_eq!(r.verdict, Verdict::HardwareOnly);
        assert!(r.summary.starts_with("not measurable on this rig"), "{r:?}");
        // A board whose LSI or capture does not come: not measurable, and a failure.
        let mut bad = ok;
        bad.lsi_ready = false;
        let r = clock_row(&bad);
        assert_eq!(r.verdict, Verdict::Fail);
        assert!(r.summary.starts_with("not measurable: the LSI"), "{r:?}");
        let mut bad = ok;
        (bad.intervals, bad.ticks_sum, bad.timeouts) = (0, 0, 3);
        let r = clock_row(&bad);
        assert_eq!(r.verdict, Verdict::Fail);
        assert!(r.summary.contains("3 waits without a capture"), "{r:?}");
        // 7 % fewer ticks: the HSE 7 % slow, the LSI reads 34.4 kHz.
        let mut bad = ok;
        bad.ticks_sum = 32 * 5812;
        let r = clock_row(&bad);
        assert_eq!(r.verdict, Verdict::Fail);
        assert!(r.summary.contains("outside DS12110's"), "{r:?}");
    }
}

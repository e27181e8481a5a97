use super::*;
use crate::acquisition::{Batch, ConverterModel};
use crate::hal::{AnalogSample, FlashGeometry};
use crate::runstore::memflash::MemFlash;
use crate::wire::{BootReport, ResetCause};

/// The board's converter (timer, DMA ring, reader) modelled, with a signal per channel.
struct Adc {
    model: ConverterModel,
    signal: fn(u64) -> AnalogSample,
}

impl SampleSource for Adc {
    fn adc_clock(&self, rate_hz: u32) -> Option<SampleClock> {
        self.model.clock_for(rate_hz)
    }
    fn adc_start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        self.model.start(rate_hz, 0)
    }
    fn adc_stop(&mut self) {
        self.model.stop()
    }
    fn adc_running(&self) -> bool {
        self.model.is_running()
    }
    fn adc_next_index(&mut self) -> u64 {
        self.model.next_index()
    }
    fn adc_read(&mut self, out: &mut [AnalogSample]) -> Batch {
        self.model.read(out)
    }
    fn force_lowpass(&self) -> crate::wire::LowPass {
        crate::wire::LowPass::NONE
    }
}

/// Noisy mid-scale displacement and velocity, a constant force, an ECR at the bottom rail.
fn signal(k: u64) -> AnalogSample {
    let noise = (k.wrapping_mul(2_654_435_761) >> 7) as u16 % 9;
    [30_000 + noise, 33_000 - noise, 12_345, 0]
}

/// Runs a converter check of `ms` at 10 kS/s with 500 µs polls; `claimed` replaces the clock the
/// probe is told (a converter running at another rate than the timer says).
fn converter_check(
    ms: u32,
    claimed: Option<SampleClock>,
    stall_at_us: Option<u64>,
) -> ConverterReport {
    let mut adc = Adc {
        model: ConverterModel::new(crate::acquisition::clock::BOARD_TIMER_HZ),
        signal,
    };
    let clock = adc.adc_start(10_000).unwrap();
    let mut probe = ConverterProbe::new(claimed.unwrap_or(clock), 0, ms);
    let mut t = 0;
    loop {
        t += 500;
        while let Some(ts) = adc.model.due(t) {
            let k = adc.model.next_index();
            let _ = ts;
            adc.model.convert(&(adc.signal)(k));
        }
        if stall_at_us == Some(t) {
            adc.model.stall_reader(t + 300_000);
        }
        if let Some(r) = probe.step(&mut adc, t) {
            return r;
        }
        assert!(t < 100_000_000, "the check never ended");
    }
}

#[test]
fn a_converter_on_time_passes_and_its_channels_are_judged_on_what_they_read() {
    let r = converter_check(2000, None, None);
    let (rate, ppm, ok) = judge_rate(&r);
    assert!(ok, "rate {rate} S/s, {ppm} ppm: {r:?}");
    assert!(ppm.abs() < 100.0, "{ppm}");
    assert_eq!(r.lost, 0);
    assert!((19_990..=20_010).contains(&r.samples), "{}", r.samples);
    // Displacement and velocity move around mid-scale: in range, not stuck.
    assert_eq!(judge_channel(&r.channels[0], r.samples), Ok(()));
    assert_eq!(judge_channel(&r.channels[1], r.samples), Ok(()));
    assert!(
        (r.channels[0].mean - 30_004.0).abs() < 1.0,
        "{:?}",
        r.channels[0]
    );
    assert!(r.channels[0].sd > 1.0 && r.channels[0].sd < 4.0);
    // One code throughout: stuck. The bottom rail: at a rail.
    assert_eq!(
        judge_channel(&r.channels[2], r.samples),
        Err(ChannelProblem::Stuck)
    );
    assert_eq!(
        judge_channel(&r.channels[3], r.samples),
        Err(ChannelProblem::AtRail)
    );
    assert_eq!(
        judge_channel(&ChannelStats::default(), 0),
        Err(ChannelProblem::NoSamples)
    );
}

#[test]
fn a_converter_off_its_timer_by_a_thousandth_fails_the_rate_and_lost_samples_are_counted() {
    // The timer delivers 10 kS/s, the clock claims 10.01 kS/s: −1000 ppm.
    let r = converter_check(2000, Some(SampleClock::exact(10_010)), None);
    let (_, ppm, ok) = judge_rate(&r);
    assert!(!ok, "{ppm}");
    assert!((ppm + 999.0).abs() < 60.0, "{ppm}");
    // A reader stalled for 300 ms is lapped by the DMA (its ring holds 205 ms at 10 kS/s): the
    // samples it lost are counted, and the rate stands (the count is the DMA's, not the reader's).
    let r = converter_check(2000, None, Some(500_000));
    assert!(r.lost > 500, "{r:?}");
    assert!(judge_rate(&r).2, "{r:?}");
}

fn flash() -> MemFlash<Vec<u8>> {
    MemFlash::new(
        vec![0xFF; FlashGeometry::H743_BANK2.bytes() as usize],
        FlashGeometry::H743_BANK2,
    )
    .with_h743_timing()
}

fn flash_check(f: &mut MemFlash<Vec<u8>>, sector: u32, bytes: u32) -> FlashReport {
    let mut p = FlashProbe::new(sector, bytes, FlashGeometry::H743_BANK2);
    let mut t = 0;
    loop {
        t += 500;
        f.advance(t);
        if let Some(r) = p.step(f, t) {
            return r;
        }
        assert!(t < 60_000_000, "the check never ended");
    }
}

#[test]
fn a_flash_check_erases_programs_reads_back_and_leaves_the_sector_erased() {
    let mut f = flash();
    // Another sector holds something that must survive.
    f.bytes_mut()[0..4].copy_from_slice(&[1, 2, 3, 4]);
    let r = flash_check(&mut f, 7, 4096);
    assert_eq!(judge_flash(&r), Ok(()), "{r:?}");
    assert_eq!((r.sector, r.bytes, r.mismatches), (7, 4096, 0));
    // The model's erase takes 1.1 s, seen at the next poll.
    assert!((1_100_000..=1_100_500).contains(&r.erase_us), "{r:?}");
    assert!((1_100_000..=1_100_500).contains(&r.erase2_us), "{r:?}");
    // 16 programs of 256 bytes, one per poll.
    assert!(
        r.program_us >= 16 * 500 && r.program_us <= 18 * 500,
        "{r:?}"
    );
    assert_eq!(r.flags, None, "a model has no controller flags");
    assert_eq!(f.erase_count(7), 2);
    assert_eq!(f.violations(), 0);
    assert!(f.bytes()[7 * 128 * 1024..].iter().all(|&b| b == 0xFF));
    assert_eq!(&f.bytes()[0..4], &[1, 2, 3, 4]);
}

#[test]
fn a_flash_that_fails_or_erases_slowly_fails_the_check() {
    let mut f = flash();
    f.fail_next_operation();
    let r = flash_check(&mut f, 3, 1024);
    assert_eq!(
        judge_flash(&r),
        Err("an erase was refused or failed"),
        "{r:?}"
    );
    // An erase at a slower parallelism (three times the typical time).
    let mut f = MemFlash::new(
        vec![0xFF; FlashGeometry::H743_BANK2.bytes() as usize],
        FlashGeometry::H743_BANK2,
    )
    .with_timing(3_300_000, 20);
    let r = flash_check(&mut f, 3, 1024);
    assert_eq!(
        judge_flash(&r),
        Err("a sector erase took longer than the datasheet's maximum")
    );
    // Bytes that do not read back as programmed.
    let mut r = flash_check(&mut flash(), 2, 256);
    r.mismatches = 1;
    assert_eq!(judge_flash(&r), Err("bytes read back wrong"));
}

#[test]
fn the_boot_report_after_a_deliberate_act_must_name_it() {
    let boot = |cause, msg: &str| BootReport {
        cause,
        message: heapless::String::try_from(msg).unwrap(),
    };
    let panic = boot(ResetCause::Panic, "panicked: self-test: deliberate panic");
    assert_eq!(judge_reset(Deliberate::Panic, &panic), Ok(()));
    assert!(judge_reset(Deliberate::Panic, &boot(ResetCause::Software, "")).is_err());
    assert!(judge_reset(
        Deliberate::Panic,
        &boot(ResetCause::Panic, "index out of bounds")
    )
    .is_err());
    let wd = boot(ResetCause::Watchdog, "task thermocouple silent for 301 ms");
    assert_eq!(judge_reset(Deliberate::Stall, &wd), Ok(()));
    assert!(judge_reset(Deliberate::Stall, &boot(ResetCause::Watchdog, "")).is_err());
    assert!(judge_reset(Deliberate::Stall, &panic).is_err());
}

#[test]
fn the_thermocouple_row_judges_each_fault_the_chip_can_show() {
    use crate::thermocouple::{encode, sr, BadRead};
    use crate::wire::ThermocoupleReport;
    let at = |registers: Option<[u8; 16]>, age_us: u64| ThermocoupleReport { registers, age_us };
    // A sound chip: configured, 23 °C on the board, the plate at 25 °C, read 100 ms ago.
    let good = encode(25.0, 23.0, 0);
    let r = judge_thermocouple(&at(Some(good), 100_000)).unwrap();
    assert!((r.cold_junction_c - 23.0).abs() < 0.02 && (r.plate_c - 25.0).abs() < 0.01);
    // Open thermocouple (the chip's open-circuit detection, on in CR0), shorted, no chip.
    assert_eq!(
        judge_thermocouple(&at(Some(encode(25.0, 23.0, sr::OPEN)), 0)),
        Err(BadRead::Open)
    );
    assert_eq!(
        judge_thermocouple(&at(Some(encode(25.0, 23.0, sr::OVUV)), 0)),
        Err(BadRead::OverUnderVoltage)
    );
    assert_eq!(
        judge_thermocouple(&at(Some([0xFF; 16]), 0)),
        Err(BadRead::AllOnes)
    );
    assert_eq!(
        judge_thermocouple(&at(None, u64::MAX)),
        Err(BadRead::Missing { age_ms: u32::MAX })
    );
    // Not configured (a chip reset to its defaults: conversions off, detection off).
    let mut reset = good;
    reset[0] = 0x00;
    assert_eq!(
        judge_thermocouple(&at(Some(reset), 0)),
        Err(BadRead::Config)
    );
    // Cold junction at the edges of the plausible range (limits::COLD_JUNCTION_C), and beyond.
    let cj = crate::wire::limits::COLD_JUNCTION_C;
    assert!(judge_thermocouple(&at(Some(encode(25.0, *cj.start(), 0)), 0)).is_ok());
    assert!(judge_thermocouple(&at(Some(encode(25.0, *cj.end(), 0)), 0)).is_ok());
    assert!(matches!(
        judge_thermocouple(&at(Some(encode(25.0, cj.end() + 1.0, 0)), 0)),
        Err(BadRead::ColdJunctionImplausible(_))
    ));
    // A read older than the heater accepts.
    let old = crate::wire::limits::TC_MAX_AGE_MS as u64 * 1000 + 1;
    assert!(matches!(
        judge_thermocouple(&at(Some(good), old)),
        Err(BadRead::Missing { .. })
    ));
}

#[test]
fn each_input_s_rest_window_holds_at_its_edges_and_fails_just_past_them() {
    let cal = crate::wire::Configure::real_rig(0.3).calibration;
    let at = |ch: usize, si: f32| ChannelStats {
        min: 0,
        max: 1,
        mean: cal[ch].to_count(si) as f32,
        sd: 1.0,
        at_rail: 0,
    };
    // One count inside each edge passes; a few counts beyond fails.
    for (ch, c) in cal.iter().enumerate().take(4) {
        let (lo, hi) = rest_window(ch);
        let count = c.gain;
        for (edge, inward) in [(lo, 1.0f32), (hi, -1.0)] {
            assert!(
                judge_identity(&at(ch, edge + inward * 1.5 * count), ch, c).is_ok(),
                "channel {ch} at {edge}"
            );
            assert!(
                judge_identity(&at(ch, edge - inward * 3.0 * count), ch, c).is_err()
                    || (ch == 3 && edge == hi),
                "channel {ch} past {edge}"
            );
        }
    }
    // A grounded input with an offset of 300 counts fails on every channel.
    for (ch, c) in cal.iter().enumerate().take(4) {
        let g = ChannelStats {
            mean: 300.0,
            ..at(ch, 0.0)
        };
        assert!(judge_identity(&g, ch, c).is_err(), "grounded {ch}");
    }
    // At rest as the virtual rig reads (x held at x0, v and F at zero, ECR 0.1 V): every swap
    // but velocity <-> force fails some channel.
    let rest = [
        cal[0].to_count(REST_X0_M),
        cal[1].to_count(0.0),
        cal[2].to_count(0.0),
        cal[3].to_count(0.1),
    ];
    for a in 0..4 {
        for b in a + 1..4 {
            let mut w = rest;
            w.swap(a, b);
            let fails = (0..4).any(|ch| {
                let s = ChannelStats {
                    mean: w[ch] as f32,
                    ..at(ch, 0.0)
                };
                judge_identity(&s, ch, &cal[ch]).is_err()
            });
            assert_eq!(fails, (a, b) != (1, 2), "swap {a},{b}");
        }
    }
}

#[test]
fn an_output_row_is_judged_only_where_the_board_senses_it_and_only_after_every_pattern() {
    use crate::wire::{OutputCheck, OutputsReport, SELFTEST_OUTPUTS};
    let ok = OutputCheck {
        sensed: true,
        mismatches: 0,
        driven: 3,
        read: 3,
    };
    let mut r = OutputsReport {
        steps: RANGE_PATTERNS.len() as u8,
        outputs: [ok; SELFTEST_OUTPUTS],
    };
    r.outputs[2].sensed = false;
    r.outputs[4].mismatches = 1;
    assert_eq!(judge_output(&r, 0), Some(Ok(())));
    assert_eq!(judge_output(&r, 2), None, "not sensed: no verdict");
    assert!(matches!(judge_output(&r, 4), Some(Err(_))));
    assert_eq!(judge_output(&r, SELFTEST_OUTPUTS), None);
    // Cut short (a step fewer): no sensed output passes.
    r.steps -= 1;
    assert!(matches!(judge_output(&r, 0), Some(Err(_))));
}

/// A clock report of `n` intervals of `ticks` each from a 25 MHz timer capturing every 8 LSI
/// periods.
fn clock_report(n: u16, ticks: u32) -> ClockReport {
    ClockReport {
        available: true,
        lsi_ready: true,
        timer_hz: 25_000_000,
        periods_per_capture: 8,
        intervals: n,
        overcaptures: 0,
        timeouts: 0,
        ticks_sum: n as u64 * ticks as u64,
        ticks_min: ticks,
        ticks_max: ticks,
    }
}

/// Timer ticks per interval (fractional: a mean) for an LSI at `hz` through a true HSE.
fn ticks_for(hz: f64) -> f64 {
    25e6 * 8.0 / hz
}

#[test]
fn the_clock_is_judged_at_the_lsi_limits_just_inside_and_just_outside_each() {
    // Means just inside and just outside each limit: 1000 intervals, so the sum carries the mean
    // to a thousandth of a tick.
    let at = |hz: f64| {
        let n = 1000u16;
        let mut r = clock_report(n, 0);
        r.ticks_sum = (ticks_for(hz) * n as f64).round() as u64;
        judge_clock(&r)
    };
    for hz in [LSI_MIN_HZ + 0.5, LSI_TYP_HZ, LSI_MAX_HZ - 0.5] {
        let f = at(hz).unwrap_or_else(|e| panic!("{hz}: {e:?}"));
        assert!((f.lsi_hz - hz).abs() < 0.01, "{hz}: {f:?}");
        assert!(f.hse_ratio.0 <= 1.0 && 1.0 <= f.hse_ratio.1, "{f:?}");
    }
    for hz in [LSI_MIN_HZ - 0.5, LSI_MAX_HZ + 0.5] {
        assert!(
            matches!(at(hz), Err(ClockProblem::OutOfRange(f)) if (f.lsi_hz - hz).abs() < 0.01),
            "{hz}: {:?}",
            at(hz)
        );
    }
    // The HSE 5 % slow: the typical LSI reads 33.68 kHz, above the maximum; the ratio it allows
    // does not hold 1, and at the typical LSI it says 0.95.
    let mut r = clock_report(1, 0);
    r.ticks_sum = (ticks_for(LSI_TYP_HZ) * 0.95).round() as u64;
    let Err(ClockProblem::OutOfRange(f)) = judge_clock(&r) else {
        panic!("{r:?}")
    };
    assert!(
        f.hse_ratio.1 < 1.0 && (f.hse_ratio_typ - 0.95).abs() < 1e-4,
        "{f:?}"
    );
}

#[test]
fn a_clock_check_without_the_timer_input_the_lsi_or_an_interval_is_not_measurable() {
    let ok = clock_report(16, 6250);
    assert!(judge_clock(&ok).is_ok());
    let mut r = ok;
    r.available = false;
    assert_eq!(judge_clock(&r), Err(ClockProblem::NotAvailable));
    let mut r = ok;
    r.lsi_ready = false;
    assert_eq!(judge_clock(&r), Err(ClockProblem::LsiNotReady));
    // Every interval overwritten (or every wait timed out): nothing measured, no verdict.
    let mut r = clock_report(0, 0);
    r.overcaptures = 40;
    assert_eq!(judge_clock(&r), Err(ClockProblem::NoInterval));
    let mut r = clock_report(0, 0);
    r.timeouts = CLOCK_MAX_TIMEOUTS;
    assert_eq!(judge_clock(&r), Err(ClockProblem::NoInterval));
    // Some intervals overwritten: thrown away, the others judged.
    let mut r = ok;
    r.overcaptures = 3;
    assert!(judge_clock(&r).is_ok());
}

/// An LSI path for the probe: a script of what each interval gives.
struct Lsi {
    present: bool,
    ready_after: u32,
    polls: u32,
    script: Vec<LsiInterval>,
    running: bool,
    stopped: u32,
}

impl ClockCheck for Lsi {
    fn lsi_start(&mut self) -> Option<LsiTimer> {
        self.running = self.present;
        self.present.then_some(LsiTimer {
            timer_hz: 25_000_000,
            periods_per_capture: 8,
        })
    }
    fn lsi_ready(&mut self) -> bool {
        self.polls += 1;
        self.polls > self.ready_after
    }
    fn lsi_interval(&mut self) -> LsiInterval {
        if self.script.is_empty() {
            LsiInterval::Timeout
        } else {
            self.script.remove(0)
        }
    }
    fn lsi_stop(&mut self) {
        self.running = false;
        self.stopped += 1;
    }
}

fn lsi(script: Vec<LsiInterval>) -> Lsi {
    Lsi {
        present: true,
        ready_after: 2,
        polls: 0,
        script,
        running: false,
        stopped: 0,
    }
}

/// Steps a probe every 500 µs until its report.
fn run_clock(hw: &mut Lsi, n: u16) -> ClockReport {
    let mut p = ClockProbe::start(hw, n, 0);
    for k in 1..10_000u64 {
        if let Some(r) = p.step(hw, k * 500) {
            return r;
        }
    }
    panic!("no report")
}

#[test]
fn the_clock_probe_waits_for_the_lsi_drops_overcaptured_intervals_and_stops_the_timer() {
    use LsiInterval::*;
    let mut hw = lsi(vec![
        Ticks(6250),
        Overcapture,
        Ticks(6252),
        Timeout,
        Ticks(6248),
    ]);
    let r = run_clock(&mut hw, 3);
    assert_eq!(
        (r.intervals, r.overcaptures, r.timeouts),
        (3, 1, 1),
        "{r:?}"
    );
    assert_eq!(
        (r.ticks_sum, r.ticks_min, r.ticks_max),
        (18_750, 6248, 6252)
    );
    assert!(!hw.running && hw.stopped == 1);
    // The LSI never ready: the report after LSI_READY_US, not ready, the timer stopped.
    let mut hw = lsi(vec![]);
    hw.ready_after = u32::MAX;
    let r = run_clock(&mut hw, 3);
    assert!(r.available && !r.lsi_ready && r.intervals == 0, "{r:?}");
    assert_eq!(hw.stopped, 1);
    // No capture ever: gives up after CLOCK_MAX_TIMEOUTS waits.
    let mut hw = lsi(vec![]);
    let r = run_clock(&mut hw, 100);
    assert_eq!(
        (r.intervals, r.timeouts, r.ticks_min),
        (0, CLOCK_MAX_TIMEOUTS, 0)
    );
    // Overcaptures only: gives up after 2n + 8 tries, nothing measured.
    let mut hw = lsi(vec![Overcapture; 100]);
    let r = run_clock(&mut hw, 4);
    assert_eq!((r.intervals, r.overcaptures), (0, 16));
    assert_eq!(judge_clock(&r), Err(ClockProblem::NoInterval));
    // No timer input: reported at the first step, not available, nothing stopped.
    let mut hw = lsi(vec![]);
    hw.present = false;
    let r = run_clock(&mut hw, 4);
    assert!(!r.available);
    assert_eq!(hw.stopped, 0);
}

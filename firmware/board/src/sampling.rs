//! Hardware-timed sampling: TIM6's update event (TRGO) triggers one ADC1 scan of the four analog
//! channels; DMA1 stream 0, in circular mode, writes the scans round a ring in SRAM3 that the MPU
//! makes non-cacheable; the application reads the ring by the DMA's position (NDTR) through the
//! firmware library's `RingReader`, which gives every sample its index in the stream.
//!
//! embassy-stm32 0.6 has no triggered or ring-buffered mode for this ADC (v4): the ADC and the
//! timer are configured through the PAC, the DMA stream through embassy's `ReadableRingBuffer`
//! (configuration, start, stop and its interrupts). All the `unsafe` of the board's acquisition is
//! in this module; the arithmetic it relies on (timer settings, position extension, ring reading,
//! trigger index after a restart) is in `tribo_firmware::acquisition` and tested on the host.
//!
//! The sampler always runs: at the application's rate while it acquires, at [`IDLE_RATE_HZ`]
//! otherwise, so that the ECR channel's latest value is there for the autoranger between runs.
#![allow(unsafe_code)]

use core::mem::MaybeUninit;
use core::ptr::{addr_of, addr_of_mut};
use core::sync::atomic::{compiler_fence, fence, Ordering};

use embassy_stm32::adc::{Adc, AnyAdcChannel, RxDma};
use embassy_stm32::dma::{ReadableRingBuffer, TransferOptions};
use embassy_stm32::pac;
use embassy_stm32::pac::adc::vals::{Adstp, Dmngt, Exten, Ovrmod, Pcsel, Res, SampleTime};
use embassy_stm32::pac::timer::vals::{Mms, Urs};
use embassy_stm32::peripherals::{ADC1, DMA1_CH0, TIM6};
use embassy_stm32::Peri;
use embassy_time::Instant;
use tribo_firmware::acquisition::clock::{next_trigger, scan_time_ns, TimerSetting, SAMPLING};
use tribo_firmware::acquisition::ring::SCAN_WORDS;
use tribo_firmware::acquisition::{
    choose, extend_position, Batch, RingReader, RingView, RING_SCANS, RING_WORDS,
};
use tribo_firmware::hal::{AnalogSample, SampleClock};

/// Rate the sampler runs at while the application is not acquiring (ECR monitoring), S/s.
pub const IDLE_RATE_HZ: u32 = 1_000;
/// ADC1 external trigger number of TIM6 TRGO (RM0433, "ADC external trigger for regular channels":
/// adc_ext_trg13 = tim6_trgo).
const EXTSEL_TIM6_TRGO: u8 = 13;
/// DMA stream carrying ADC1 (DMA1 stream 0, DMAMUX1 request 9 = adc1_dma).
const STREAM: usize = 0;
/// ADC1 channels of the scan, in the order of `tribo_firmware::hal::AnalogSample`.
pub const SCAN_CHANNELS: usize = 4;

/// The converter's ring: 16 KiB, alone in the `.dma_ring` section (region `DMA_RING` of
/// `memory.x`, SRAM3 in the D2 domain, reachable by DMA1), which MPU region 7 ([`ring_region`])
/// makes non-cacheable. Written only by the DMA after [`Sampler::new`] zeroed it.
#[link_section = ".dma_ring"]
static mut DMA_RING: MaybeUninit<[u16; RING_WORDS]> = MaybeUninit::uninit();

/// Size of the `.dma_ring` section's region (`DMA_RING` in `memory.x`).
const DMA_RING_BYTES: u32 = 16 * 1024;
const _: () = assert!(RING_WORDS * 2 == DMA_RING_BYTES as usize);

/// MPU region 7 (the highest priority, so that no other region can cover the ring with a cacheable
/// attribute): the ring's 16 KiB, normal, non-cacheable, shareable, execute-never; `None` unless
/// the ring's actual address (where the linker put the static) is the base of a region of its size
/// (`memory.x` asserts the same at link time).
///
/// Why non-cacheable rather than clean/invalidate: the reader looks at the ring at any moment, by
/// position, down to a single scan; invalidating 32-byte lines the DMA may be writing into at that
/// instant would be racy, and per-read invalidation costs more than uncached reads of 8 bytes.
pub fn ring_region() -> Option<crate::mpu::Region> {
    let base = addr_of!(DMA_RING) as u32;
    let region = crate::mpu::Region {
        number: 7,
        base,
        bytes: DMA_RING_BYTES,
        attrs: crate::mpu::NORMAL_UNCACHED_SHARED,
    };
    (base.is_multiple_of(DMA_RING_BYTES)
        && crate::mpu::holds(
            &region,
            base,
            core::mem::size_of::<[u16; RING_WORDS]>() as u32,
        ))
    .then_some(region)
}

/// The ring as the reader sees it: volatile reads of memory the DMA writes.
struct DmaView(*const u16);

impl RingView for DmaView {
    fn words(&self) -> usize {
        RING_WORDS
    }
    fn word(&self, i: usize) -> u16 {
        if i >= RING_WORDS {
            return 0;
        }
        // SAFETY: `i` is inside the static ring; the memory is plain u16s (any bit pattern is
        // valid), never in the D-cache (MPU region 7, or the D-cache left off when that region
        // could not be placed: `mpu::configure_and_enable_caches`), and only the DMA writes it: a
        // volatile read sees what the DMA last wrote (a torn scan is detected by the reader from
        // the DMA position). Aliasing: while the DMA runs, the ring buffer driver holds a
        // `&'static mut [u16]` to the same memory (`start_ring`). This pointer is not derived from
        // it (it comes from `addr_of_mut!(DMA_RING)`), so a read through it ends that reference's
        // uniqueness, and any later access through the reference would be undefined behaviour.
        // There is none: the driver uses the reference only in `new` (its address and length, for
        // the stream's registers); its `read*` methods, the only ones that touch the memory
        // through it, are never called (`Sampler` keeps the ring buffer only to keep the stream
        // running and to stop it). The DMA's writes are outside the Rust memory model.
        unsafe { self.0.add(i).read_volatile() }
    }
}

/// The sampling hardware: ADC1, TIM6, DMA1 stream 0 and the ring.
pub struct Sampler {
    _adc: Adc<'static, ADC1>,
    dma: Peri<'static, DMA1_CH0>,
    ring: Option<ReadableRingBuffer<'static, u16>>,
    view: DmaView,
    reader: RingReader,
    timer_hz: u32,
    setting: TimerSetting,
    clock: Option<SampleClock>,
    /// Device time TIM6 was started, µs (the sample clock's origin: trigger `k` comes `k + 1`
    /// periods later).
    timer_start_us: u64,
    /// The application is acquiring (else the sampler runs at the idle rate).
    acquiring: bool,
}

impl Sampler {
    /// Takes the calibrated ADC (`Adc::new_with_config` ran its calibration and enabled it), the
    /// DMA stream and the scan's channels (their pins were put in analog mode by `degrade_adc`),
    /// and starts sampling at the idle rate.
    pub fn new(
        adc: Adc<'static, ADC1>,
        dma: Peri<'static, DMA1_CH0>,
        channels: [AnyAdcChannel<'static, ADC1>; SCAN_CHANNELS],
    ) -> Self {
        // SAFETY: `DMA_RING` is touched here once, before any DMA transfer; zeroing it makes every
        // word initialised, so that the ring can be handed out as `[u16]`.
        let base = unsafe {
            let p = addr_of_mut!(DMA_RING) as *mut u16;
            core::ptr::write_bytes(p, 0, RING_WORDS);
            p
        };
        embassy_stm32::rcc::enable_and_reset::<TIM6>();
        let timer_hz = embassy_stm32::rcc::frequency::<TIM6>().0;
        if timer_hz != tribo_firmware::acquisition::clock::BOARD_TIMER_HZ {
            defmt::warn!(
                "TIM6 kernel clock {} Hz differs from the virtual rig's: rates still exact to it",
                timer_hz
            );
        }
        configure_adc(&channels);
        let mut s = Sampler {
            _adc: adc,
            dma,
            ring: None,
            view: DmaView(base),
            reader: RingReader::new(RING_SCANS),
            timer_hz,
            setting: TimerSetting { psc: 0, arr: 0 },
            clock: None,
            timer_start_us: 0,
            acquiring: false,
        };
        s.run_at(IDLE_RATE_HZ);
        s
    }

    /// The clock the timer makes for `rate_hz`.
    pub fn clock_for(&self, rate_hz: u32) -> Option<SampleClock> {
        choose(self.timer_hz, rate_hz).map(|(_, c)| c)
    }

    /// A new stream at `rate_hz` for the application.
    pub fn start(&mut self, rate_hz: u32) -> Option<SampleClock> {
        let c = self.run_at(rate_hz)?;
        self.acquiring = true;
        Some(c)
    }

    /// Back to the idle rate.
    pub fn stop(&mut self) {
        if self.acquiring {
            self.acquiring = false;
            self.run_at(IDLE_RATE_HZ);
        }
    }

    pub fn is_acquiring(&self) -> bool {
        self.acquiring
    }

    /// Stops the chain, sets the timer for `rate_hz` and starts a new stream from sample 0.
    fn run_at(&mut self, rate_hz: u32) -> Option<SampleClock> {
        let (setting, clock) = choose(self.timer_hz, rate_hz)?;
        self.halt();
        let tim = pac::TIM6;
        tim.cr1().modify(|w| {
            w.set_cen(false);
            w.set_urs(Urs::COUNTER_ONLY);
        });
        tim.psc().write_value(setting.psc);
        tim.arr().write(|w| w.set_arr(setting.arr));
        tim.cr2().modify(|w| w.set_mms(Mms::UPDATE));
        // Load the prescaler now (the ADC is not armed: this update's TRGO converts nothing).
        tim.egr().write(|w| w.set_ug(true));
        tim.sr().write(|w| w.set_uif(false));
        tim.cnt().write(|w| w.set_cnt(0));
        self.setting = setting;
        self.clock = Some(clock);
        self.start_ring();
        self.reader.start();
        pac::ADC1.cr().modify(|w| w.set_adstart(true));
        cortex_m::interrupt::free(|_| {
            self.timer_start_us = Instant::now().as_micros();
            tim.cr1().modify(|w| w.set_cen(true));
        });
        Some(clock)
    }

    /// Stops conversions and the DMA (the timer may keep counting).
    fn halt(&mut self) {
        let adc = pac::ADC1;
        if adc.cr().read().adstart() {
            adc.cr().modify(|w| w.set_adstp(Adstp::STOP));
            while adc.cr().read().adstart() {}
        }
        // Dropping the ring buffer resets the stream and waits for it to stop.
        self.ring = None;
        adc.isr().write(|w| {
            w.set_ovr(true);
            w.set_eoc(true);
            w.set_eos(true);
        });
        compiler_fence(Ordering::SeqCst);
    }

    /// (Re)starts the DMA stream at word 0 of the ring.
    fn start_ring(&mut self) {
        let mut opts = TransferOptions::default();
        opts.priority = embassy_stm32::dma::Priority::VeryHigh;
        // SAFETY: the previous ring buffer (if any) was dropped by `halt`, which reset the stream:
        // no other `Channel` for DMA1 stream 0 exists while this one does, so cloning the
        // peripheral handle cannot create two live drivers of it.
        let ch = unsafe { self.dma.clone_unchecked() };
        let request = RxDma::<ADC1>::request(&*ch);
        let channel = embassy_stm32::dma::Channel::new(ch, crate::irqs::Irqs);
        // SAFETY: `DMA_RING` is zeroed, 'static, and given to this one ring buffer (the previous
        // one was dropped, so no other reference to it exists). The reference lives on in the
        // ring buffer while `DmaView` reads the same memory through a raw pointer that is not
        // derived from it: sound only because the reference is never used to access the memory
        // after `new` (see `DmaView::word`; never call the ring buffer's `read*` methods). The
        // peripheral address is ADC1's data register, read 16 bits at a time.
        let mut ring = unsafe {
            let buf: &'static mut [u16] =
                core::slice::from_raw_parts_mut(addr_of_mut!(DMA_RING) as *mut u16, RING_WORDS);
            ReadableRingBuffer::new(
                channel,
                request,
                pac::ADC1.dr().as_ptr() as *mut u16,
                buf,
                opts,
            )
        };
        ring.start();
        self.ring = Some(ring);
    }

    /// Ticks of the timer clock since the timer started (coarse: the µs time base, same clock).
    fn elapsed_ticks(&self, now_us: u64) -> u64 {
        (now_us.saturating_sub(self.timer_start_us) as u128 * self.timer_hz as u128 / 1_000_000)
            as u64
    }

    /// Triggers so far (= index of the next one), exact: the coarse time fixes the period, the
    /// timer's counter the phase.
    fn triggers_now(&self) -> (u64, u32) {
        cortex_m::interrupt::free(|_| {
            let now = Instant::now().as_micros();
            let cnt = pac::TIM6.cnt().read().cnt() as u32;
            let counter_ticks = cnt * (self.setting.psc as u32 + 1);
            let ticks = self.setting.ticks();
            (
                next_trigger(self.elapsed_ticks(now), counter_ticks, ticks),
                counter_ticks,
            )
        })
    }

    /// Index of the first sample whose ECR conversion cannot have begun before now: the next
    /// trigger's, or the last one's if its scan may still be converting.
    pub fn next_index(&self) -> u64 {
        let (k, since_ticks) = self.triggers_now();
        let since_ns = since_ticks as u64 * 1_000_000_000 / self.timer_hz as u64;
        if since_ns < scan_time_ns() as u64 {
            k.saturating_sub(1)
        } else {
            k
        }
    }

    /// The DMA's word count in the current epoch.
    fn written_words(&self) -> u64 {
        written_words(self.clock, self.timer_start_us, self.reader.base())
    }

    /// Reads the oldest unread samples (see `SampleSource::adc_read`). After an ADC overrun (the
    /// DMA then takes no more conversions), what got through is read, then the converter is
    /// re-armed at the next trigger: the samples in between show as a jump in index.
    pub fn read(&mut self, out: &mut [AnalogSample]) -> Batch {
        let (clock, start, base) = (self.clock, self.timer_start_us, self.reader.base());
        let written = written_words(clock, start, base);
        let view = DmaView(self.view.0);
        let batch = self
            .reader
            .read(written, &view, out, || written_words(clock, start, base));
        if pac::ADC1.isr().read().ovr() && batch.len < out.len() {
            defmt::warn!("ADC1 overrun: converter restarted");
            self.restart_after_overrun();
        }
        batch
    }

    /// Re-arms the ADC and the DMA after an overrun, the timer running on; the next trigger's
    /// index comes from the timer (`clock::next_trigger`), so the stream's indices stay exact.
    fn restart_after_overrun(&mut self) {
        self.halt();
        self.start_ring();
        let ticks = self.setting.ticks();
        let psc = self.setting.psc as u32 + 1;
        loop {
            // Arm well inside a period (in its first half), so that no trigger can fall between
            // reading the counter and arming.
            while pac::TIM6.cnt().read().cnt() as u32 * psc > ticks / 2 {}
            let armed = cortex_m::interrupt::free(|_| {
                let now = Instant::now().as_micros();
                let c0 = pac::TIM6.cnt().read().cnt() as u32 * psc;
                pac::ADC1.cr().modify(|w| w.set_adstart(true));
                let c1 = pac::TIM6.cnt().read().cnt() as u32 * psc;
                (c1 >= c0 && c1 <= ticks / 2)
                    .then(|| next_trigger(self.elapsed_ticks(now), c0, ticks))
            });
            match armed {
                Some(next) => {
                    self.reader.restart(next);
                    return;
                }
                None => {
                    // A trigger may have come while arming: start over.
                    self.halt();
                    self.start_ring();
                }
            }
        }
    }

    /// The ECR channel of the latest complete scan, if any.
    pub fn latest_ecr(&self) -> Option<u16> {
        let w = self.written_words();
        let complete = w / SCAN_WORDS as u64;
        let last = complete.checked_sub(1)?;
        let slot = (last % RING_SCANS as u64) as usize * SCAN_WORDS;
        Some(self.view.word(slot + 3))
    }
}

/// The DMA's word count in the epoch whose first scan is stream sample `base`: its position in the
/// ring (from NDTR) extended by the sample clock's count of triggers since the timer started at
/// `timer_start_us` (see `tribo_firmware::acquisition::extend_position`).
fn written_words(clock: Option<SampleClock>, timer_start_us: u64, base: u64) -> u64 {
    let ndt = pac::DMA1.st(STREAM).ndtr().read().ndt() as usize;
    let pos = (RING_WORDS - ndt.min(RING_WORDS)) % RING_WORDS;
    let Some(clock) = clock else { return 0 };
    let now = Instant::now().as_micros();
    let triggers = clock.samples_in_us(now.saturating_sub(timer_start_us));
    let estimate = triggers.saturating_sub(base) * SCAN_WORDS as u64;
    // What the DMA wrote before NDTR moved is read after it.
    fence(Ordering::Acquire);
    extend_position(pos, RING_WORDS, estimate)
}

/// ADC1 for triggered scans: 16 bits, TIM6 TRGO on the rising edge, DMA circular, overrun keeps
/// the old data (and stops DMA requests: detected and restarted by the reader), the scan of the
/// four channels with their sampling times, each channel preselected.
fn configure_adc(channels: &[AnyAdcChannel<'static, ADC1>; SCAN_CHANNELS]) {
    let adc = pac::ADC1;
    if adc.cr().read().adstart() {
        adc.cr().modify(|w| w.set_adstp(Adstp::STOP));
        while adc.cr().read().adstart() {}
    }
    adc.cfgr().modify(|w| {
        w.set_res(Res::BITS16);
        w.set_extsel(EXTSEL_TIM6_TRGO);
        w.set_exten(Exten::RISING_EDGE);
        w.set_dmngt(Dmngt::DMA_CIRCULAR);
        w.set_ovrmod(Ovrmod::PRESERVE);
        w.set_cont(false);
        w.set_discen(false);
    });
    adc.sqr1().modify(|w| w.set_l(SCAN_CHANNELS as u8 - 1));
    for (rank, (ch, st)) in channels.iter().zip(SAMPLING).enumerate() {
        let n = ch.get_hw_channel();
        let smp = SampleTime::from_bits(st.code());
        if n <= 9 {
            adc.smpr(0).modify(|w| w.set_smp(n as usize, smp));
        } else {
            adc.smpr(1).modify(|w| w.set_smp(n as usize - 10, smp));
        }
        adc.pcsel()
            .modify(|w| w.set_pcsel(n as usize, Pcsel::PRESELECTED));
        // Ranks 1..=4 are SQ1..SQ4 of SQR1.
        adc.sqr1().modify(|w| w.set_sq(rank, n));
    }
    adc.isr().write(|w| {
        w.set_ovr(true);
        w.set_eoc(true);
        w.set_eos(true);
    });
}

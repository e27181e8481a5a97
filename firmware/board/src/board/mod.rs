//! Binding of the rig logic to the NUCLEO-H743ZI (pin map and assumptions: `firmware/README.md`).
//!
//! One embassy task per concern, hardware handed to each at start-up, no global mutable state: the
//! tasks share one [`Shared`] value (initialised once in a `StaticCell`) made of embassy-sync
//! primitives and atomics.
//!
//! * `app`: the rig's state machine (`tribo_firmware::app::App`), polled every millisecond and on
//!   every USB packet; it owns the magnet and heater PWM, the ECR DAC and range switches, the button,
//!   the lamps and the sampler (TIM6 → ADC1 scans → DMA ring, [`crate::sampling`]: it reads the ring
//!   by the DMA's position at every poll) through [`BoardHw`].
//! * `thermocouple`: the MAX31856 over SPI1 every 100 ms: only moves its register file (the library
//!   checks it, `tribo_firmware::thermocouple`).
//! * `flash`: erases and programs bank 2 for the run store, one operation at a time as the
//!   application asks ([`FlashLink`]), interrupt-driven, so the application keeps running meanwhile.
//! * `watchdog`: the IWDG runs from the first instruction after reset with a boot timeout of ~33 s
//!   (`memory::BOOT_WATCHDOG`); once the app's first poll (the flash recovery) is over, this task
//!   sets the run timeout and feeds the IWDG
//!   while the periodic tasks (app, thermocouple) check in; otherwise
//!   drives the outputs safe, notes which task and lets the IWDG reset the chip
//!   (`tribo_firmware::watchdog`). The flash and USB tasks wait on their peripherals and do not
//!   check in; the sampler is hardware (its reader is the app task).
//! * `usb`, `usb_tx`, `usb_rx`: embassy-usb device and CDC-ACM class. The bus events (power, bus
//!   reset, suspend/resume, configuration) go through `tribo_firmware::link_tx::BusState`; a
//!   suspend, a loss of VBUS (sensed on PA9: a cable pull) or a bus reset is "link down", and
//!   a bus reset also ends a suspend: frames are refused (they wait in the run store) until a host
//!   is back; then the sender resends, whole, the first frame the host did not acknowledge, and the
//!   application forgets any half-received frame (`host_link`).
//!
//! Panics and HardFaults go to `crate::safety` (safe state, reset record, reset).
//!
//! Here: the shared state, the app, thermocouple and watchdog tasks, and `main`, which takes the
//! peripherals and hands them out. Beside it: `hw` ([`BoardHw`], the hardware traits on this
//! board), `flash` (bank 2 and its task), `host_link` (the USB tasks), `clocks` (the clock tree),
//! `lsi` (TIM16 capturing the LSI: the HSE against an independent clock, for the self-test).
use core::cell::Cell;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use defmt_rtt as _;
use embassy_executor::Spawner;
use embassy_futures::select::{select, Either};
use embassy_stm32::adc::{Adc, AdcChannel, AdcConfig, AnyAdcChannel, Resolution};
use embassy_stm32::dac::{DacChannel, Value};
use embassy_stm32::flash::{Async, Bank2Region, Flash};
use embassy_stm32::gpio::{Input, Level, Output, OutputType, Pull, Speed};
use embassy_stm32::mode::Blocking;
use embassy_stm32::peripherals::{ADC1, IWDG1, TIM1, TIM4, USB_OTG_FS};
use embassy_stm32::spi::{self, Spi};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::{PwmPin, SimplePwm, SimplePwmChannel};
use embassy_stm32::usb;
use embassy_stm32::wdg::IndependentWatchdog;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::channel::Channel;
use embassy_sync::pipe::Pipe;
use embassy_sync::signal::Signal;
use embassy_time::{Duration, Instant, Ticker, Timer};
use embassy_usb::class::cdc_acm::{CdcAcmClass, Receiver, Sender, State};
use static_cell::{ConstStaticCell, StaticCell};
use tribo_firmware::app::{App, AppConfig};
use tribo_firmware::ecr::count_to_volts;
use tribo_firmware::hal::*;
use tribo_firmware::link_tx::BusState;
use tribo_firmware::reset::{self, BootRecovery};
use tribo_firmware::runstore::RunStore;
use tribo_firmware::selftest::Deliberate;

use tribo_firmware::thermocouple::{self as tc, Registers};
use tribo_firmware::watchdog::{task, Liveness, BOARD_TASKS, FEED_PERIOD_MS};
use tribo_firmware::wire::{limits, BootReport, ResetCause};

use crate::irqs::Irqs;
use crate::memory;
use crate::safety;

use crate::sampling::Sampler;

mod clocks;
mod flash;
mod host_link;
mod hw;
mod lsi;
use clocks::*;
use flash::*;
use host_link::*;
use hw::*;

type Cs = CriticalSectionRawMutex;
type UsbDriver = usb::Driver<'static, USB_OTG_FS>;

/// Bytes of frames waiting for the USB sender.
const TX_PIPE: usize = 4096;
/// The force channel's analog chain as the rig is built: the charge amplifier's 2-pole 300 Hz
/// low-pass (`shared/docs/rig-and-physics.md`). Every run states it (`DeviceMsg::Chain`); change
/// it with the hardware.
const FORCE_LOWPASS: tribo_firmware::wire::LowPass =
    tribo_firmware::wire::LowPass::butterworth(2, 300.0);

/// The converter's register file as last read (`None` before any good SPI transfer) and when
/// (µs of uptime). The application decides how old is too old.
type TcReading = (Option<Registers>, u64);

/// What the tasks share.
struct Shared {
    thermocouple: &'static Mutex<Cs, Cell<TcReading>>,
    /// The periodic tasks' check-ins, for the watchdog.
    liveness: Liveness<{ BOARD_TASKS.len() }>,
    /// A host is connected (the CDC class is configured and the bus not suspended): frames may be
    /// queued for it.
    connected: AtomicBool,
    /// The USB bus as the device's handler was told of it (`host_link::UsbEvents`): whether the
    /// link is up, and in which session.
    usb_bus: Mutex<Cs, Cell<BusState>>,
    /// A bus event happened (`host_link::UsbEvents`), for the sender.
    usb_event: Signal<Cs, ()>,
    /// The application's first poll (the recovery of the last run from flash) is over: the
    /// watchdog may start.
    app_started: Signal<Cs, ()>,
    /// The self-test asked for a stalled thermocouple task: it waits forever from its next round
    /// (the watchdog must catch it).
    stall_thermocouple: AtomicBool,
    tx: Pipe<Cs, TX_PIPE>,
    rx: Channel<Cs, heapless::Vec<u8, 64>, 8>,
}

// The thermocouple cell apart: its non-zero initial value would put all of `Shared` (4 KiB of
// pipe) in `.data`, i.e. in flash too.
static THERMOCOUPLE: ConstStaticCell<Mutex<Cs, Cell<TcReading>>> =
    ConstStaticCell::new(Mutex::new(Cell::new((None, 0))));
static SHARED: StaticCell<Shared> = StaticCell::new();
static FLASH_LINK: StaticCell<FlashLink> = StaticCell::new();
static EP_OUT: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static CONFIG_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static BOS_DESC: ConstStaticCell<[u8; 256]> = ConstStaticCell::new([0; 256]);
static CONTROL_BUF: ConstStaticCell<[u8; 64]> = ConstStaticCell::new([0; 64]);
static CDC_STATE: StaticCell<State> = StaticCell::new();
static USB_EVENTS: StaticCell<UsbEvents> = StaticCell::new();

fn now_us() -> u64 {
    Instant::now().as_micros()
}

#[embassy_executor::task]
async fn app_task(
    shared: &'static Shared,
    mut hw: BoardHw,
    serial: u64,
    mut boot: BootReport,
    recovery: BootRecovery,
) {
    let Some(mem) = memory::take() else {
        defmt::error!("run store memory already taken");
        return;
    };
    // The last boot's recovery faulted reading a sector (a torn flash word: its ECC is a bus
    // error): that sector is erased unread, and the boot report says its run is lost.
    if let BootRecovery::EraseFirst { sector } = recovery {
        defmt::error!(
            "last recovery faulted in bank 2 sector {}: erasing it",
            sector
        );
        let mut region = hw.flash.region.lock().await;
        if !erase_sector(&mut region, sector, &hw.flash.flags).await {
            defmt::error!("erase of bank 2 sector {} failed", sector);
        }
        reset::note_torn_sector(&mut boot, sector);
    }
    let store = RunStore::new(mem.ring, mem.index);
    let cfg = AppConfig::new(serial);
    let mut app = App::new(cfg, store);
    app.set_boot_report(boot);
    // The first poll recovers the last run from flash (up to 1 MiB, read without yielding), each
    // read marked in the no-init RAM; the watchdog starts only after it, so a long recovery cannot
    // trip it, and the marker is cleared only after it, so a fault inside it is known at the next
    // boot.
    hw.recovering = true;
    app.poll(&mut hw, now_us());
    hw.recovering = false;
    safety::recovering(None);
    shared.liveness.check_in(task::APP, now_ms());
    shared.app_started.signal(());
    // The application's period (500 µs: a poll's share of the work stays within its budget, see
    // `AppConfig::poll_period_us`).
    let mut ticker = Ticker::every(Duration::from_micros(cfg.poll_period_us as u64));
    loop {
        match select(shared.rx.receive(), ticker.next()).await {
            // The receiver's mark of a new host connection: no half frame of the previous one is
            // completed by the new host's bytes, which come after it.
            Either::First(bytes) if bytes.is_empty() => app.link_reset(),
            Either::First(bytes) => {
                app.on_bytes(&mut hw, &bytes, now_us());
                if let Some(d) = app.take_deliberate() {
                    deliberate(shared, d).await;
                }
            }
            Either::Second(()) => app.poll(&mut hw, now_us()),
        }
        shared.liveness.check_in(task::APP, now_ms());
    }
}

/// The self-test's deliberate acts, after the command's `Ack` (queued for the USB sender, which
/// gets 10 ms to send it: well inside the app task's 50 ms allowance): a panic, which the panic
/// handler must turn into safe outputs, a reset record and a reset; or a stalled thermocouple
/// task, which the watchdog task must catch, name and let the IWDG reset.
async fn deliberate(shared: &'static Shared, d: Deliberate) {
    defmt::warn!("self-test: deliberate {}", d);
    match d {
        Deliberate::Panic => {
            Timer::after_millis(10).await;
            panic!("{}", tribo_firmware::wire::DELIBERATE_PANIC);
        }
        Deliberate::Stall => shared.stall_thermocouple.store(true, Ordering::Release),
    }
}

/// Milliseconds of uptime, wrapping, for the watchdog's check-ins.
fn now_ms() -> u32 {
    Instant::now().as_millis() as u32
}

/// Feeds the IWDG only while every periodic task checks in. A silent task: the outputs go safe at
/// once, the reset record names it, and the IWDG, no longer fed, resets the chip within its
/// timeout. (A core stuck in one task never runs this: the IWDG resets it all the same.)
#[embassy_executor::task]
async fn watchdog_task(shared: &'static Shared, iwdg: embassy_stm32::Peri<'static, IWDG1>) {
    // The IWDG has run since the first instruction after reset with the boot timeout
    // (`memory::BOOT_WATCHDOG`, ~33 s), unfed: through the clocks' start (the HSE-ready wait has
    // no timeout of its own), the run store's recovery and its erase-first step. The run
    // timeout, and the feeding by check-ins, start once the application's first poll (the
    // recovery) is over; every task's allowance counts from here.
    shared.app_started.wait().await;
    for i in 0..BOARD_TASKS.len() {
        shared.liveness.check_in(i, now_ms());
    }
    let mut wdg = IndependentWatchdog::new(iwdg, limits::WATCHDOG_TIMEOUT_MS * 1000);
    wdg.unleash();
    // Reload now: the counter still holds boot-timeout ticks, which the new prescaler shortens
    // but does not bring under the run timeout's reload.
    wdg.pet();
    let mut ticker = Ticker::every(Duration::from_millis(FEED_PERIOD_MS as u64));
    loop {
        ticker.next().await;
        match shared.liveness.verdict(now_ms()) {
            Ok(()) => wdg.pet(),
            Err(stuck) => {
                safety::safe_state();
                safety::record(ResetCause::Watchdog, stuck.message().as_bytes());
                defmt::error!(
                    "task {} silent for {} ms: outputs safe, watchdog no longer fed",
                    stuck.name,
                    stuck.silent_ms
                );
                loop {
                    // Starve the IWDG; keep the outputs safe whatever the other tasks write.
                    ticker.next().await;
                    safety::safe_state();
                }
            }
        }
    }
}

/// MAX31856: configured as the library says, then its whole register file read at once and every
/// 100 ms and handed over as bytes; configured again when the configuration does not read back (a
/// converter reset by a glitch), at most once a second. Whether to trust a read is the
/// application's call.
///
/// Chip select is driven by software, with the datasheet's timing as explicit core-cycle delays
/// (`tc::cs_delays`, twice each minimum at [`CORE_HZ`]): t_CC after it falls, t_CCH before it
/// rises, and t_CWH of high after every transfer, so that the three configuration writes are three
/// transfers to the chip, not one burst.
#[embassy_executor::task]
async fn thermocouple_task(
    shared: &'static Shared,
    mut spi: Spi<'static, Blocking, spi::mode::Master>,
    mut cs: Output<'static>,
) {
    const CS: tc::CsDelays = tc::cs_delays(CORE_HZ);
    /// One transfer framed by chip select. The DSB after each pin write waits until the store has
    /// left the core's write buffer, so that the delay counts from the pin change and the SPI
    /// (on another bus) cannot start before chip select is low; the last SCK edge is over when
    /// the blocking transfer has read its last byte (mode 1 samples on it), so the hold counts
    /// from there.
    fn transfer(
        spi: &mut Spi<'static, Blocking, spi::mode::Master>,
        cs: &mut Output<'static>,
        buf: &mut [u8],
    ) -> bool {
        cs.set_low();
        cortex_m::asm::dsb();
        cortex_m::asm::delay(CS.setup);
        let ok = spi.blocking_transfer_in_place(buf).is_ok();
        cortex_m::asm::delay(CS.hold);
        cs.set_high();
        cortex_m::asm::dsb();
        cortex_m::asm::delay(CS.inactive);
        ok
    }
    fn configure(spi: &mut Spi<'static, Blocking, spi::mode::Master>, cs: &mut Output<'static>) {
        for (reg, value) in tc::CONFIG_WRITES {
            let mut w = [0x80 | reg, value];
            let _ = transfer(spi, cs, &mut w);
        }
    }
    configure(&mut spi, &mut cs);
    let mut last_config_ms = now_ms();
    let mut ticker = Ticker::every(Duration::from_millis(100));
    loop {
        if shared.stall_thermocouple.load(Ordering::Acquire) {
            // The self-test's deliberate stall: silent from here on.
            core::future::pending::<()>().await;
        }
        shared.liveness.check_in(task::THERMOCOUPLE, now_ms());
        // Address 0x00 (read), then the 16 registers 0x00..=0x0F.
        let mut buf = [0u8; 1 + tc::REGISTERS];
        let ok = transfer(&mut spi, &mut cs, &mut buf);
        // On an SPI error nothing new is published: the reading ages, and the application counts
        // it missing.
        if ok {
            let mut regs: Registers = [0; tc::REGISTERS];
            regs.copy_from_slice(&buf[1..]);
            let at = now_us();
            shared.thermocouple.lock(|c| c.set((Some(regs), at)));
            if !tc::config_ok(&regs) && now_ms().wrapping_sub(last_config_ms) >= 1000 {
                defmt::warn!("MAX31856 configuration lost: configuring again");
                configure(&mut spi, &mut cs);
                last_config_ms = now_ms();
            }
        }
        ticker.next().await;
    }
}

macro_rules! spawn {
    ($spawner:expr, $task:expr) => {
        match $task {
            Ok(token) => $spawner.spawn(token),
            Err(_) => defmt::error!("task could not be spawned"),
        }
    };
}

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    // Why the last reset, and whether the last recovery faulted (read before anything else
    // touches RCC_RSR, the record or the marker; the caches are still off).
    let safety::Boot {
        report: mut boot,
        recovery,
    } = safety::boot_report();
    // The MPU (bank 2, the no-init RAM and the DMA ring non-cacheable; the stack's guard), then the
    // caches on (before anything uses DMA or the flash).
    match cortex_m::Peripherals::take() {
        Some(mut cp) => {
            let regions = [
                Some(crate::mpu::bank2()),
                crate::mpu::stack_guard(),
                safety::noinit_region(),
                crate::sampling::ring_region(),
            ];
            if let Err(e) = crate::mpu::configure_and_enable_caches(
                &mut cp.MPU,
                &mut cp.SCB,
                &mut cp.CPUID,
                &regions,
            ) {
                defmt::error!("{}: D-cache left off", e);
            }
        }
        None => defmt::error!("core peripherals already taken: caches left off"),
    }
    let p = embassy_stm32::init(clocks());
    // The safe-state table against the PAC: if it does not match, the fatal paths cannot drive
    // the outputs safe, so the application never drives them on (`BoardHw::outputs_allowed`) and
    // the host is told in the boot report.
    let outputs_allowed = safety::check_table();
    if !outputs_allowed {
        boot.message.clear();
        let _ = boot.message.push_str(
            "safe-state table does not match the PAC: heater, magnet, ECR source kept off",
        );
    }
    safety::freeze_watchdog_when_halted();
    if !memory::boot_watchdog_matches_pac() {
        defmt::error!("the start-up code's IWDG1 address is not the PAC's: no boot watchdog");
    }
    defmt::info!("last reset: {}", boot.cause);
    // SRAM3 (the DMA ring) allocated to the CPU's domain, so D2 stays on while the CPU runs.
    embassy_stm32::pac::RCC
        .ahb2enr()
        .modify(|w| w.set_sram3en(true));
    defmt::info!(
        "tribo-board, protocol v{}",
        tribo_firmware::wire::PROTOCOL_VERSION
    );
    let shared: &'static Shared = SHARED.init(Shared {
        thermocouple: THERMOCOUPLE.take(),
        liveness: Liveness::new(BOARD_TASKS, now_ms()),
        connected: AtomicBool::new(false),
        usb_bus: Mutex::new(Cell::new(BusState::new())),
        usb_event: Signal::new(),
        app_started: Signal::new(),
        stall_thermocouple: AtomicBool::new(false),
        tx: Pipe::new(),
        rx: Channel::new(),
    });
    let uid = embassy_stm32::uid::uid();
    let serial = uid.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| {
        (h ^ b as u64).wrapping_mul(0x100_0000_01b3)
    });

    // Magnet H-bridge on TIM1 CH1 (hold) / CH2 (reverse), 20 kHz; heater MOSFET on TIM4 CH1, 1 kHz.
    let magnet = SimplePwm::new(
        p.TIM1,
        Some(PwmPin::new(p.PE9, OutputType::PushPull)),
        Some(PwmPin::new(p.PE11, OutputType::PushPull)),
        None,
        None,
        Hertz(20_000),
        CountingMode::EdgeAlignedUp,
    )
    .split();
    let heater = SimplePwm::new(
        p.TIM4,
        Some(PwmPin::new(p.PD12, OutputType::PushPull)),
        None,
        None,
        None,
        Hertz(1_000),
        CountingMode::EdgeAlignedUp,
    )
    .split();
    let (mut magnet_hold, mut magnet_reverse, mut heater_ch) = (magnet.ch1, magnet.ch2, heater.ch1);
    for ch in [&mut magnet_hold, &mut magnet_reverse] {
        ch.set_duty_cycle_fully_off();
        ch.enable();
    }
    heater_ch.set_duty_cycle_fully_off();
    heater_ch.enable();

    // Bank 2 of the flash: the run store's (bank 1 holds this program).
    let flash: &'static FlashLink = FLASH_LINK.init(FlashLink {
        region: embassy_sync::mutex::Mutex::new(
            Flash::new(p.FLASH, Irqs).into_regions().bank2_region,
        ),
        op: Signal::new(),
        busy: AtomicBool::new(false),
        failed: AtomicBool::new(false),
        flags: AtomicU32::new(0),
    });

    // ADC1, 16 bits, calibrated by the driver; scans of displacement PA3, velocity PC0, force PB1,
    // ECR PF11 (pins set analog by `degrade_adc`; `tribo_firmware::selftest::ANALOG_PINS` names
    // them, in this order), triggered by TIM6, DMA1 stream 0 into the ring.
    let adc = Adc::new_with_config(
        p.ADC1,
        AdcConfig {
            resolution: Some(Resolution::BITS16),
            averaging: None,
        },
    );
    let channels: [AnyAdcChannel<'static, ADC1>; 4] = [
        p.PA3.degrade_adc(),
        p.PC0.degrade_adc(),
        p.PB1.degrade_adc(),
        p.PF11.degrade_adc(),
    ];
    let sampler = Sampler::new(adc, p.DMA1_CH0, channels);

    let hw = BoardHw {
        shared,
        sampler,
        flash,
        magnet_hold,
        magnet_reverse,
        heater: heater_ch,
        ecr_dac: DacChannel::new_blocking(p.DAC1, p.PA4),
        ecr_range: [
            Output::new(p.PG0, Level::Low, Speed::Low),
            Output::new(p.PG1, Level::Low, Speed::Low),
            Output::new(p.PG2, Level::Low, Speed::Low),
        ],
        button: Input::new(p.PC13, Pull::Down),
        lamps: [
            Output::new(p.PB0, Level::Low, Speed::Low),
            Output::new(p.PE1, Level::Low, Speed::Low),
            Output::new(p.PB14, Level::Low, Speed::Low),
        ],
        outputs_allowed,
        recovering: false,
        lsi: lsi::LsiCapture::new(p.TIM16),
    };

    // MAX31856 on SPI1 (mode 1, 1 MHz), chip select PD14.
    let mut spi_cfg = spi::Config::default();
    spi_cfg.mode = spi::MODE_1;
    spi_cfg.frequency = Hertz(1_000_000);
    let spi = Spi::new_blocking(p.SPI1, p.PA5, p.PB5, p.PA6, spi_cfg);
    let cs = Output::new(p.PD14, Level::High, Speed::Medium);

    // USB OTG FS (PA11/PA12), CDC-ACM.
    let mut usb_cfg = usb::Config::default();
    // VBUS sensed on PA9 (the NUCLEO-H743ZI wires CN13's VBUS to it; the OTG core's own sensing,
    // no GPIO set-up): the board is self-powered from the USB's point of view (the ST-LINK's
    // cable powers it), so a pull must be seen as such (`BusEvent::Enabled(false)`), not only as
    // a suspend. Without VBUS on PA9 the device never connects: a board without that wire needs
    // `false` here.
    usb_cfg.vbus_detection = true;
    let driver = usb::Driver::new_fs(p.USB_OTG_FS, Irqs, p.PA12, p.PA11, EP_OUT.take(), usb_cfg);
    let mut config = embassy_usb::Config::new(0x1209, 0x0001);
    config.manufacturer = Some("tribo");
    config.product = Some("oscillating tribometer");
    // The chip's unique id: two rigs on one host are told apart by `tribo devices`.
    config.serial_number = Some(embassy_stm32::uid::uid_hex());
    config.max_power = 100;
    config.max_packet_size_0 = 64;
    let mut builder = embassy_usb::Builder::new(
        driver,
        config,
        CONFIG_DESC.take(),
        BOS_DESC.take(),
        &mut [],
        CONTROL_BUF.take(),
    );
    builder.handler(USB_EVENTS.init(UsbEvents { shared }));
    let class = CdcAcmClass::new(&mut builder, CDC_STATE.init(State::new()), 64);
    let (tx, rx) = class.split();
    let usb = builder.build();

    spawn!(spawner, usb_task(usb));
    spawn!(spawner, usb_tx_task(shared, tx));
    spawn!(spawner, usb_rx_task(shared, rx));
    spawn!(spawner, thermocouple_task(shared, spi, cs));
    spawn!(spawner, flash_task(flash));
    spawn!(spawner, app_task(shared, hw, serial, boot, recovery));
    // Last: every task is running when the watchdog's run timeout starts, which is after the
    // application's first poll (see `watchdog_task`); until then the boot timeout runs.
    spawn!(spawner, watchdog_task(shared, p.IWDG1));
}

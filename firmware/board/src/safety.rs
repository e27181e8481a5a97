//! The board's fail-safe: the one safe state reached from everywhere, the panic and HardFault
//! handlers, the reset record kept across resets, and the reset cause read at boot.
//!
//! One of the board's small modules with `unsafe` (with `memory.rs`, `mpu.rs` and `sampling.rs`), each
//! block with its `// SAFETY:` reason. What it writes is data from the library ([`tribo_firmware::safety::H743_SAFE_STATE`], the
//! reset record's words from [`tribo_firmware::reset`]), tested there (on the host; the same
//! functions run unchanged on the target); this module only moves it to the registers and to the
//! no-init RAM.
//!
//! Order on every fatal path: the outputs go safe first (register writes, no lock, no allocation,
//! nothing that can fail), then the reason is kept, then the chip resets. Reset puts every pin in
//! its reset state (analog, high impedance); the external pull-downs of `firmware/README.md` keep
//! heater and magnet off from there until the application drives them.
#![allow(unsafe_code)]

use core::fmt::Write;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};

use cortex_m_rt::{exception, ExceptionFrame};
use tribo_firmware::hal::FlashGeometry;
use tribo_firmware::reset::{
    self, BootRecovery, Marker, MessageBuf, Record, ResetFlags, RECORD_WORDS,
};
use tribo_firmware::safety;
use tribo_firmware::wire::{BootReport, ResetCause};

/// The reset record, in `.reset_record` (`memory.x`: the no-init RAM, SRAM4's last KiB, which the
/// start-up code does not initialise). It survives a reset that keeps the D3 domain powered (a
/// panic's or fault's `sys_reset`, the watchdog, the reset pin), not a power-on or brown-out, after
/// which it is garbage and is not read (`RCC_RSR`, [`ResetFlags::ram_kept`]). MPU region 5 makes
/// this RAM non-cacheable ([`noinit_region`]) and every store here cleans its cache lines
/// ([`clean_dcache`]: inside HardFault and NMI the MPU is off), so the fatal paths' stores are in
/// the SRAM, not in a D-cache line, when the chip resets: `sys_reset` does not clean the cache.
#[link_section = ".reset_record"]
static mut RECORD: MaybeUninit<Record> = MaybeUninit::uninit();

/// The "recovering" marker (see [`tribo_firmware::reset::Marker`]), beside the record, with the
/// same lifetime and the same MPU region.
#[link_section = ".reset_record"]
static mut MARKER: MaybeUninit<Marker> = MaybeUninit::uninit();

/// The safe-state table did not match the PAC at boot ([`check_table`]): the table's addresses are
/// then not written by [`safe_state`] (they might be another peripheral's); the board keeps the
/// heater and magnet off through the HAL instead (`BoardHw::outputs_allowed`).
static TABLE_BAD: AtomicBool = AtomicBool::new(false);

/// Drives heater, magnet and ECR source to their safe values (see the library's table). Callable
/// from any context, any number of times.
#[inline(never)]
pub fn safe_state() {
    if TABLE_BAD.load(Ordering::Relaxed) {
        return;
    }
    safety::apply(|addr, clear, set| {
        let reg = addr as *mut u32;
        // SAFETY: the table holds addresses of the STM32H743's GPIOD/GPIOE/TIM1/TIM4/DAC1 registers
        // (RM0433), checked against the PAC at boot by `check_table` (after a failed check this is
        // not reached, see above; before the check, the addresses are the library's, tested on the
        // host); those registers are always mapped, and a volatile read-modify-write of a
        // peripheral register has no memory-safety effect on Rust objects. An interrupted
        // read-modify-write at worst loses a concurrent HAL write, which the next application of
        // the safe state (idempotent) overrides.
        unsafe { reg.write_volatile((reg.read_volatile() & !clear) | set) };
    });
}

/// Writes `words` into the no-init static at `p`, word by word.
///
/// # Safety
/// `p` is `RECORD` or `MARKER` cast to `*mut u32` and `words` is no longer than it.
unsafe fn store(p: *mut u32, words: &[u32]) {
    for (i, w) in words.iter().enumerate() {
        // SAFETY: the caller's contract: `p + i` is inside the static.
        unsafe { p.add(i).write_volatile(*w) };
    }
    cortex_m::asm::dsb();
    clean_dcache(p as u32, 4 * words.len() as u32);
}

/// Cleans the D-cache lines holding `[addr, addr + bytes)` to the SRAM, then a DSB: what was
/// stored there is in the SRAM before anything that follows, a reset included.
///
/// Needed although MPU region 5 makes the no-init RAM non-cacheable: the MPU is enabled without
/// HFNMIENA (`mpu.rs`), so inside the HardFault and NMI handlers it is off, the default memory map
/// applies, and SRAM4 is then normal write-back write-allocate memory: the handler's record would
/// sit in a D-cache line, and `SCB::sys_reset` does not clean the cache. On the normal path (MPU
/// on, the lines uncached) and with the D-cache off, cleaning is a no-op. Not testable under QEMU
/// (it does not model caches): argued from the ARMv7-M architecture manual (MPU_CTRL.HFNMIENA;
/// DCCMVAC, clean by address to the point of coherency, acts on the line holding the address
/// whatever the attributes of the current access).
fn clean_dcache(addr: u32, bytes: u32) {
    /// The Cortex-M7's D-cache line.
    const LINE: u32 = 32;
    let end = addr.saturating_add(bytes);
    let mut line = addr & !(LINE - 1);
    while line < end {
        // SAFETY: DCCMVAC (CBP, 0xE000_EF68) is a write-only, stateless System Control Space
        // register, always mapped on a Cortex-M7; cleaning a line writes its dirty data back to
        // memory and changes no value any code can observe.
        unsafe { (*cortex_m::peripheral::CBP::PTR).dccmvac.write(line) };
        line += LINE;
    }
    cortex_m::asm::dsb();
}

/// Keeps `cause` and `message` for the next boot.
pub fn record(cause: ResetCause, message: &[u8]) {
    let words = reset::encode(cause, message);
    // SAFETY: RECORD is a static of exactly RECORD_WORDS `u32`s, touched only through raw pointers
    // with volatile word accesses (here, `boot_report` and `record_empty`), never through a
    // reference, so concurrent writers (a fault inside a panic, a panic inside the watchdog task's
    // write) can at worst leave a mix of two records, which the CRC refuses: no undefined
    // behaviour. Any bit pattern is a valid `u32`.
    unsafe { store(core::ptr::addr_of_mut!(RECORD).cast(), &words) }
}

/// The recovery of the last run is about to read bank 2 at `offset` (`Some`), or is over (`None`).
pub fn recovering(offset: Option<u32>) {
    let words = offset.map_or(reset::MARKER_CLEAR, reset::marker);
    // SAFETY: as for RECORD in `record`: MARKER is MARKER_WORDS `u32`s, only ever accessed through
    // raw pointers with volatile word accesses (here and in `boot_report`); only the app task
    // writes it after boot.
    unsafe { store(core::ptr::addr_of_mut!(MARKER).cast(), &words) }
}

/// MPU region 5: the no-init RAM (`NOINIT` in `memory.x`, 1 KiB), non-cacheable; `None` unless it
/// holds the record and the marker where the linker actually put them.
pub fn noinit_region() -> Option<crate::mpu::Region> {
    const BYTES: u32 = 1024;
    let record = core::ptr::addr_of!(RECORD) as u32;
    let marker = core::ptr::addr_of!(MARKER) as u32;
    let region = crate::mpu::Region {
        number: 5,
        base: record & !(BYTES - 1),
        bytes: BYTES,
        attrs: crate::mpu::NORMAL_UNCACHED_SHARED,
    };
    let ok = crate::mpu::holds(&region, record, 4 * RECORD_WORDS as u32)
        && crate::mpu::holds(&region, marker, 4 * reset::MARKER_WORDS as u32);
    ok.then_some(region)
}

/// What the boot learns before anything else runs: why the chip last reset, and whether the last
/// recovery of the flash faulted.
pub struct Boot {
    pub report: BootReport,
    pub recovery: BootRecovery,
}

/// Why the chip last reset (RCC_RSR and the record) and whether the last recovery faulted (the
/// marker), then erases all three, so each is told once. Called first in `main`, caches still off.
pub fn boot_report() -> Boot {
    let rcc = embassy_stm32::pac::RCC;
    let flags = ResetFlags::from_h7_rsr(rcc.rsr().read().0);
    let report = reset::boot_report(flags, || {
        let mut r = reset::EMPTY;
        // SAFETY: see `record`. Only called when RAM was kept (not after a power-on or brown-out),
        // so the words are those written by the last boot's `record_empty` or a later `record`
        // (every boot writes them all), with a valid ECC.
        unsafe {
            let p = core::ptr::addr_of!(RECORD) as *const u32;
            for (i, w) in r.iter_mut().enumerate() {
                *w = p.add(i).read_volatile();
            }
        }
        r
    });
    let g = FlashGeometry::H743_BANK2;
    let recovery = reset::boot_recovery(
        flags,
        report.cause,
        || {
            let mut m = reset::MARKER_CLEAR;
            // SAFETY: as for the record just above (see `recovering`).
            unsafe {
                let p = core::ptr::addr_of!(MARKER) as *const u32;
                for (i, w) in m.iter_mut().enumerate() {
                    *w = p.add(i).read_volatile();
                }
            }
            m
        },
        g.sector_bytes,
        g.sectors,
    );
    record_empty();
    recovering(None);
    rcc.rsr().modify(|w| w.set_rmvf(true));
    Boot { report, recovery }
}

fn record_empty() {
    // SAFETY: see `record`.
    unsafe { store(core::ptr::addr_of_mut!(RECORD).cast(), &reset::EMPTY) }
}

/// The IWDG stops while a debugger halts the core (DBGMCU_APB4FZ1.DBG_IWDG1), so that stepping
/// through code does not reset the chip.
pub fn freeze_watchdog_when_halted() {
    embassy_stm32::pac::DBGMCU
        .apb4fzr1()
        .modify(|w| w.set_iwdg1(true));
}

/// Checks the library's register table against the PAC's addresses (a wrong address would make
/// the safe state write somewhere else). On a mismatch: logs it, and from then on [`safe_state`]
/// writes nothing (the caller keeps the outputs off another way and reports it); returns whether
/// the table matched.
pub fn check_table() -> bool {
    use embassy_stm32::pac;
    use safety::h743;
    let ok = pac::GPIOA.as_ptr() as u32 == h743::GPIOA
        && pac::GPIOD.as_ptr() as u32 == h743::GPIOD
        && pac::GPIOE.as_ptr() as u32 == h743::GPIOE
        && pac::TIM1.as_ptr() as u32 == h743::TIM1
        && pac::TIM4.as_ptr() as u32 == h743::TIM4
        && pac::DAC1.as_ptr() as u32 == h743::DAC1
        && pac::TIM4.ccr(0).as_ptr() as u32 == h743::TIM4 + h743::CCR1
        && pac::TIM1.bdtr().as_ptr() as u32 == h743::TIM1 + h743::BDTR
        && pac::DAC1.dhr12r(0).as_ptr() as u32 == h743::DAC1 + h743::DHR12R1
        && pac::GPIOD.bsrr().as_ptr() as u32 == h743::GPIOD + h743::BSRR
        && pac::GPIOD.moder().as_ptr() as u32 == h743::GPIOD + h743::MODER;
    if !ok {
        TABLE_BAD.store(true, Ordering::Relaxed);
        defmt::error!(
            "safe-state register table does not match the PAC: heater and magnet kept off"
        );
    }
    ok
}

/// Set by the first panic: a panic inside the panic handler goes straight to the reset.
static PANICKING: AtomicBool = AtomicBool::new(false);

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    safe_state();
    if !PANICKING.swap(true, Ordering::Relaxed) {
        let mut m = MessageBuf::new();
        let _ = write!(m, "{info}");
        record(ResetCause::Panic, m.as_bytes());
        defmt::error!("panic, outputs safe, resetting: {=[u8]:a}", m.as_bytes());
    }
    cortex_m::peripheral::SCB::sys_reset()
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    safe_state();
    // SAFETY: reads of the System Control Block's fault status and address registers, always
    // mapped on a Cortex-M7; no Rust object is involved.
    let (cfsr, hfsr, bfar, mmfar) = unsafe {
        let scb = &*cortex_m::peripheral::SCB::PTR;
        (
            scb.cfsr.read(),
            scb.hfsr.read(),
            scb.bfar.read(),
            scb.mmfar.read(),
        )
    };
    // This handler runs on the main stack (SRAM4), whatever the task stack did. A task stack that
    // ran into its guard: the frame the core tried to stack on the PSP is not there (`ef` would be
    // read from the guard; the MPU is off here, so that would not fault, but it is garbage), and
    // the record says what happened instead.
    let psp = cortex_m::register::psp::read();
    let overflow = crate::mpu::stack_guard()
        .is_some_and(|g| tribo_firmware::stack::task_overflow(cfsr, mmfar, psp, g.base, g.bytes));
    let m = if overflow {
        tribo_firmware::stack::overflow_message(psp, cfsr, hfsr, mmfar)
    } else {
        reset::cpu_fault_message(ef.pc(), ef.lr(), cfsr, hfsr, bfar)
    };
    record(ResetCause::CpuFault, m.as_bytes());
    // A bus fault reading flash bank 2 (a torn word's double ECC error), whoever read it: the
    // next boot erases that sector before its recovery (`reset::boot_recovery`).
    let g = FlashGeometry::H743_BANK2;
    if let Some(offset) = reset::bank2_fault_offset(cfsr, bfar, crate::mpu::BANK2_BASE, g.bytes()) {
        recovering(Some(offset));
    }
    cortex_m::peripheral::SCB::sys_reset()
}

/// A non-maskable interrupt: on the H743 the HSE clock security system (the ST-LINK's clock
/// stopped; the core runs on the HSI from here), or a source nothing here enables. Nothing can
/// mask it, nothing here clears its cause, and a return would only take it again: the same path
/// as a HardFault (outputs safe, record, reset). The recovery marker is left as it is: should an
/// NMI ever come from a flash read during the recovery, the next boot erases that sector rather
/// than read it again (a lost run, never a boot loop).
#[exception]
unsafe fn NonMaskableInt() {
    safe_state();
    record(ResetCause::CpuFault, reset::nmi_message().as_bytes());
    // No defmt here: the NMI can preempt a log write in progress (defmt-rtt's critical section
    // does not mask it), and the logger taken twice panics, overwriting this record.
    cortex_m::peripheral::SCB::sys_reset()
}

/// An exception or interrupt with no handler of its own (an interrupt enabled with nothing bound
/// to it, a debug monitor or SVCall nobody uses): before, it spun here with the outputs as they
/// were. Now it takes the fatal path: outputs safe, record (with the exception number), reset.
/// The recovery marker is cleared: this is not a flash read, and the sector the recovery was
/// reading is good.
#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    safe_state();
    recovering(None);
    record(
        ResetCause::CpuFault,
        reset::unhandled_message(irqn).as_bytes(),
    );
    defmt::error!("unhandled irqn={=i16}, outputs safe, resetting", irqn);
    cortex_m::peripheral::SCB::sys_reset()
}

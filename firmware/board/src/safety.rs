//! The board's fail-safe: the one safe state reached from everywhere, the panic and HardFault
//! handlers, the reset record kept across resets, and the reset cause read at boot.
//!
//! One of the two board modules with `unsafe` (with `memory.rs`), each block with its `// SAFETY:`
//! reason. What it writes is data from the library ([`tribo_firmware::safety::H743_SAFE_STATE`], the
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
use tribo_firmware::reset::{self, MessageBuf, Record, ResetFlags, RECORD_WORDS};
use tribo_firmware::safety;
use tribo_firmware::wire::{BootReport, ResetCause};

/// The reset record: in `.reset_record` (`memory.x`: the last KiB of SRAM4, not initialised by the
/// start-up code, kept across every reset but a power cycle).
#[link_section = ".reset_record"]
static mut RECORD: MaybeUninit<Record> = MaybeUninit::uninit();

/// Drives heater, magnet and ECR source to their safe values (see the library's table). Callable
/// from any context, any number of times.
#[inline(never)]
pub fn safe_state() {
    safety::apply(|addr, clear, set| {
        let reg = addr as *mut u32;
        // SAFETY: the table holds addresses of the STM32H743's GPIOD/GPIOE/TIM1/TIM4/DAC1 registers
        // (RM0433; checked against the PAC at boot by `check_table`), which are always mapped; a
        // volatile read-modify-write of a peripheral register has no memory-safety effect on Rust
        // objects. An interrupted read-modify-write at worst loses a concurrent HAL write, which the
        // next application of the safe state (idempotent) overrides.
        unsafe { reg.write_volatile((reg.read_volatile() & !clear) | set) };
    });
}

/// Keeps `cause` and `message` for the next boot.
pub fn record(cause: ResetCause, message: &[u8]) {
    let words = reset::encode(cause, message);
    // SAFETY: RECORD is only written here and read in `boot_report` (before any task runs); both go
    // through raw pointers with volatile accesses of plain `u32`s, so no reference to the static
    // is ever made and a write interrupted by another (a fault inside a panic) leaves a record the
    // CRC refuses, not undefined behaviour.
    unsafe {
        let p = core::ptr::addr_of_mut!(RECORD) as *mut u32;
        for (i, w) in words.iter().enumerate() {
            p.add(i).write_volatile(*w);
        }
    }
}

/// Why the chip last reset (RCC_RSR and the record), then erases both, so each is told once.
pub fn boot_report() -> BootReport {
    let rcc = embassy_stm32::pac::RCC;
    let flags = ResetFlags::from_h7_rsr(rcc.rsr().read().0);
    let report = reset::boot_report(flags, || {
        let mut r = reset::EMPTY;
        // SAFETY: see `record`. RAM was kept (not a power-on or brown-out: `boot_report` only reads
        // then), so the words were written by this firmware and their ECC is valid.
        unsafe {
            let p = core::ptr::addr_of!(RECORD) as *const u32;
            for (i, w) in r.iter_mut().enumerate() {
                *w = p.add(i).read_volatile();
            }
        }
        r
    });
    record_empty();
    rcc.rsr().modify(|w| w.set_rmvf(true));
    report
}

fn record_empty() {
    // SAFETY: see `record`.
    unsafe {
        let p = core::ptr::addr_of_mut!(RECORD) as *mut u32;
        for i in 0..RECORD_WORDS {
            p.add(i).write_volatile(0);
        }
    }
}

/// The IWDG stops while a debugger halts the core (DBGMCU_APB4FZ1.DBG_IWDG1), so that stepping
/// through code does not reset the chip.
pub fn freeze_watchdog_when_halted() {
    embassy_stm32::pac::DBGMCU
        .apb4fzr1()
        .modify(|w| w.set_iwdg1(true));
}

/// Checks the library's register table against the PAC's addresses (a wrong address would make
/// the safe state write somewhere else): logs an error if they disagree.
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
        defmt::error!("safe-state register table does not match the PAC");
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
    let (cfsr, hfsr, bfar) = unsafe {
        let scb = &*cortex_m::peripheral::SCB::PTR;
        (scb.cfsr.read(), scb.hfsr.read(), scb.bfar.read())
    };
    let m = reset::cpu_fault_message(ef.pc(), ef.lr(), cfsr, hfsr, bfar);
    record(ResetCause::CpuFault, m.as_bytes());
    cortex_m::peripheral::SCB::sys_reset()
}

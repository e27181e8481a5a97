//! The platform under the tests: QEMU's `mps2-an500` (Cortex-M7, double-precision FPU) run with
//! `-icount shift=0 -semihosting-config enable=on,target=native`.
//!
//! * Output and exit status through semihosting (`debug::exit`: 0 when every test passed).
//! * Instructions: the CMSDK APB timer 0 (25 MHz) counts down once per 40 instructions under
//!   `-icount shift=0` (one instruction = 1 ns of virtual time), exact and repeatable; DWT CYCCNT
//!   reads 0 in this QEMU.
//! * Stack: [`Qemu::measure`] paints [`WINDOW`] bytes below the caller's stack pointer, runs the
//!   call, and finds the lowest word no longer painted (the high-water mark of that call).
//! * Panics and faults print what happened and exit non-zero (QEMU's default handlers would loop),
//!   except in a run of a fatal test ([`tribo_target_tests::fatal`]: the filter is exactly its
//!   name), where they do what the board's handlers do and check it.
//!
//! The only `unsafe` of the crate is here: memory-mapped timer registers, stack painting, the
//! semihosting command line, the fault handler signature.
#![allow(unsafe_code)]

use core::fmt::Write;
use core::ptr::{read_volatile, write_volatile};
use core::sync::atomic::{AtomicU32, AtomicU8, Ordering};
use cortex_m_rt::{entry, exception, ExceptionFrame};
use cortex_m_semihosting::{debug, hio, nr, syscall1};
use tribo_firmware::reset::{self, MessageBuf};
use tribo_firmware::stack;
use tribo_firmware::wire::ResetCause;
use tribo_target_tests::fatal::{self, Fatal, FATAL};
use tribo_target_tests::replay::Clock;
use tribo_target_tests::{run, tests::TESTS, Bundle, Cost, Cx, Probe};

#[cfg(tribo_bundle)]
static BUNDLE: &[u8] = include_bytes!(env!("TRIBO_TARGET_BUNDLE"));
#[cfg(not(tribo_bundle))]
static BUNDLE: &[u8] = &[];

const TIMER0_CTRL: *mut u32 = 0x4000_0000 as *mut u32;
const TIMER0_VALUE: *mut u32 = 0x4000_0004 as *mut u32;
const TIMER0_RELOAD: *mut u32 = 0x4000_0008 as *mut u32;
/// Instructions per timer tick (25 MHz timer, 1 GHz of instructions under `-icount shift=0`).
const INSTRUCTIONS_PER_TICK: u64 = 40;
/// Bytes painted below the caller's stack pointer by [`Qemu::measure`]: twice the budget, so a
/// call over budget is measured, not just detected.
const WINDOW: usize = 32 * 1024;
const PAINT: u32 = 0xCCCC_CCCC;

extern "C" {
    /// Lowest address of the stack (cortex-m-rt's linker script).
    static _stack_end: u32;
}

fn start_timer() {
    // SAFETY: the CMSDK APB timer 0 registers of the mps2-an500 are at these addresses; nothing
    // else uses the timer.
    unsafe {
        write_volatile(TIMER0_RELOAD, u32::MAX);
        write_volatile(TIMER0_VALUE, u32::MAX);
        write_volatile(TIMER0_CTRL, 1);
    }
}

/// Timer ticks since [`start_timer`] (it counts down from `u32::MAX`).
#[inline(always)]
fn ticks() -> u32 {
    // SAFETY: reading the timer's VALUE register has no side effect.
    u32::MAX - unsafe { read_volatile(TIMER0_VALUE) }
}

fn instructions() -> Option<u64> {
    Some(ticks() as u64 * INSTRUCTIONS_PER_TICK)
}

/// The call being measured, never inlined into the measuring frame (its stack must lie below the
/// painted stack pointer).
#[inline(never)]
fn call(f: &mut dyn FnMut()) {
    f()
}

struct Qemu {
    stack_end: usize,
}

impl Probe for Qemu {
    fn platform(&self) -> &'static str {
        "Cortex-M7 (QEMU mps2-an500, -icount shift=0)"
    }

    fn resolution(&self) -> u64 {
        INSTRUCTIONS_PER_TICK
    }

    fn count(&mut self, f: &mut dyn FnMut()) -> Option<u64> {
        let t0 = ticks();
        call(f);
        let t1 = ticks();
        Some(t1.wrapping_sub(t0) as u64 * INSTRUCTIONS_PER_TICK)
    }

    #[inline(never)]
    fn measure(&mut self, f: &mut dyn FnMut()) -> Cost {
        let sp = cortex_m::register::msp::read() as usize & !3;
        let lo = sp.saturating_sub(WINDOW).max(self.stack_end);
        let mut a = lo;
        while a < sp {
            // SAFETY: [lo, sp) is stack below this frame's stack pointer: unused until `call` below,
            // no interrupt is enabled, and it lies inside the RAM reserved for the stack.
            unsafe { write_volatile(a as *mut u32, PAINT) };
            a += 4;
        }
        let t0 = ticks();
        call(f);
        let t1 = ticks();
        let mut a = lo;
        // SAFETY: reading back the same stack words.
        while a < sp && unsafe { read_volatile(a as *const u32) } == PAINT {
            a += 4;
        }
        Cost {
            instructions: Some(t1.wrapping_sub(t0) as u64 * INSTRUCTIONS_PER_TICK),
            stack: Some((sp - a) as u32),
        }
    }

    fn clock(&self) -> Clock {
        instructions
    }
}

/// Semihosting stdout (writes nothing if the host refused it).
struct Out(Option<hio::HostStream>);

impl Write for Out {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        match &mut self.0 {
            Some(h) => h.write_str(s),
            None => Ok(()),
        }
    }
}

fn out() -> Out {
    Out(hio::hstdout().ok())
}

/// The test filter: what follows the program name on the semihosting command line (QEMU's
/// `-append`), if anything.
fn filter(buf: &mut [u8; 128]) -> &str {
    #[repr(C)]
    struct Block {
        ptr: *mut u8,
        len: usize,
    }
    let mut block = Block {
        ptr: buf.as_mut_ptr(),
        len: buf.len() - 1,
    };
    // SAFETY: SYS_GET_CMDLINE writes at most `len` bytes into `buf` and updates `len`; the block
    // outlives the call.
    let r = unsafe { syscall1(nr::GET_CMDLINE, &mut block as *mut Block as usize) };
    if r != 0 {
        return "";
    }
    let line = core::str::from_utf8(&buf[..block.len.min(buf.len())]).unwrap_or("");
    let line = line.trim_end_matches('\0').trim();
    line.split_once(' ').map_or("", |(_, rest)| rest.trim())
}

/// Checks the counter against straight-line code of known length: 10,000 `nop`s (the counter's
/// word, not ours, is what every figure rests on).
fn calibrate(probe: &mut Qemu) -> (Option<u64>, Option<u64>) {
    let empty = probe.count(&mut || {});
    let nops = probe.count(&mut || {
        // SAFETY: `nop` has no effect.
        unsafe {
            core::arch::asm!(
                ".rept 10000",
                "nop",
                ".endr",
                options(nomem, nostack, preserves_flags)
            )
        }
    });
    (empty, nops)
}

#[entry]
fn main() -> ! {
    start_timer();
    let mut out = out();
    let stack_end = core::ptr::addr_of!(_stack_end) as usize;
    let mut probe = Qemu { stack_end };
    let (empty, nops) = calibrate(&mut probe);
    let _ = writeln!(
        out,
        "instruction counter: an empty call counts {}, 10000 nops count {} (±{})",
        empty.unwrap_or(0),
        nops.unwrap_or(0),
        INSTRUCTIONS_PER_TICK
    );
    let mut cmdline = [0u8; 128];
    let filter = filter(&mut cmdline);
    if let Some((name, which)) = fatal::named(filter) {
        run_fatal(&mut out, probe.platform(), name, which);
    }
    let bundle = match Bundle::parse(BUNDLE) {
        Ok(b) => Some(b),
        Err(e) => {
            let _ = writeln!(
                out,
                "no usable record bundle ({e:?}, {} bytes): the tests that need one fail",
                BUNDLE.len()
            );
            None
        }
    };
    let summary = {
        let mut cx = Cx::new(&mut probe, &mut out, bundle.as_ref());
        run(&mut cx, TESTS, filter)
    };
    debug::exit(if summary.ok() {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}

/// The fatal test of this run (index in [`FATAL`] + 1; 0: none).
static FATAL_RUN: AtomicU8 = AtomicU8::new(0);
/// Timer ticks when the fatal test's fault was triggered.
static TRIGGERED_AT: AtomicU32 = AtomicU32::new(0);

fn fatal_run() -> Option<(&'static str, Fatal)> {
    let k = FATAL_RUN.load(Ordering::SeqCst) as usize;
    k.checked_sub(1).and_then(|i| FATAL.get(i)).copied()
}

/// Runs the fatal test `name`: triggers its fault; the handler finishes the run.
fn run_fatal(out: &mut Out, platform: &str, name: &'static str, which: Fatal) -> ! {
    let _ = writeln!(
        out,
        "\nrunning 1 test on {platform} (a fatal path: its handler ends the run)"
    );
    let _ = write!(out, "test {name} ... ");
    let k = FATAL.iter().position(|(n, _)| *n == name).unwrap_or(0);
    FATAL_RUN.store(k as u8 + 1, Ordering::SeqCst);
    TRIGGERED_AT.store(ticks(), Ordering::SeqCst);
    match which {
        Fatal::Panic => {
            let table = [1u8, 2, 3, 4];
            let v = fatal::heater_step_that_panics(&table, core::hint::black_box(9));
            let _ = write!(out, "read {v} ");
        }
        // SAFETY: an undefined instruction, to take the HardFault this test is about (UsageFault
        // is not enabled, so it escalates); the handler ends the run.
        Fatal::HardFault => unsafe { core::arch::asm!("udf #0") },
        // SAFETY: ICSR (0xE000_ED04) of the System Control Block, always mapped: NMIPENDSET
        // (bit 31) pends the NMI this test is about; the other bits written as 0 have no effect.
        // The NMI is taken at once and its handler ends the run.
        Fatal::Nmi => unsafe { write_volatile(0xE000_ED04 as *mut u32, 1 << 31) },
        // SAFETY: NVIC_ISER0 (0xE000_E100) and NVIC_ISPR0 (0xE000_E200), always mapped: IRQ 0 is
        // enabled and pended; nothing in this binary binds a handler to it (cortex-m-rt fills every
        // interrupt vector with `DefaultHandler`), which ends the run.
        Fatal::UnboundIrq => unsafe {
            write_volatile(0xE000_E100 as *mut u32, 1);
            write_volatile(0xE000_E200 as *mut u32, 1);
            cortex_m::asm::dsb();
            cortex_m::asm::isb();
        },
        Fatal::StackOverflow => overflow_the_task_stack(out),
    }
    let _ = writeln!(
        out,
        "\n    failed: the fault did not happen\ntest {name} ... FAILED\n\ntest result: FAILED. 0 \
         passed; 1 failed; 0 filtered out"
    );
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

/// The stack overflow test's task stack: its lowest [`stack::TASK_GUARD_BYTES`] the guard, the
/// rest ([`stack::MIN_TASK_STACK_BYTES`]) the stack, aligned for the MPU region.
#[repr(C, align(8192))]
struct TaskStack([u8; (stack::TASK_GUARD_BYTES + stack::MIN_TASK_STACK_BYTES) as usize]);
static mut TASK_STACK: TaskStack =
    TaskStack([0; (stack::TASK_GUARD_BYTES + stack::MIN_TASK_STACK_BYTES) as usize]);
/// The guard of this run's task stack (base; 0 before it is set up).
static GUARD_BASE: AtomicU32 = AtomicU32::new(0);

/// The guard region of [`TASK_STACK`] (`stack::guard`, as the board places its own).
fn task_stack_guard() -> Option<(u32, u32, u32)> {
    let bottom = core::ptr::addr_of!(TASK_STACK) as u32;
    let top = bottom + core::mem::size_of::<TaskStack>() as u32;
    stack::guard(bottom, top, stack::TASK_GUARD_BYTES).map(|(base, bytes)| (base, bytes, top))
}

/// The board's layout, then a recursion on the task stack until it overflows: region 1 of the MPU
/// a no-access guard below the task stack (background map on, HFNMIENA off: `mpu.rs`), thread
/// mode moved to the PSP at the stack's top (`memory.rs`'s `__pre_init`), the MSP left to the
/// handlers.
fn overflow_the_task_stack(out: &mut Out) {
    let Some((base, bytes, top)) = task_stack_guard() else {
        let _ = write!(out, "(the task stack's guard could not be placed) ");
        return;
    };
    GUARD_BASE.store(base, Ordering::SeqCst);
    let rasr = 1 << 28 | (bytes.trailing_zeros() - 1) << 1 | 1;
    // SAFETY: the MPU's RNR/RBAR/RASR/CTRL (0xE000_ED98…ED94), always mapped on a Cortex-M7:
    // region 1 made a no-access guard over the lowest 8 KiB of TASK_STACK, which nothing else
    // uses; the background map stays on (PRIVDEFENA), so every other access is as before.
    unsafe {
        cortex_m::asm::dsb();
        write_volatile(0xE000_ED94 as *mut u32, 0);
        write_volatile(0xE000_ED98 as *mut u32, 1);
        write_volatile(0xE000_ED9C as *mut u32, base);
        write_volatile(0xE000_EDA0 as *mut u32, rasr);
        write_volatile(0xE000_ED94 as *mut u32, 1 << 2 | 1);
        cortex_m::asm::dsb();
        cortex_m::asm::isb();
    }
    // SAFETY: the PSP is set to the top of TASK_STACK (8-aligned), which nothing else uses, and
    // thread mode switched to it (CONTROL.SPSEL) by the only code that runs from here on: the
    // recursion, called on the new stack, which never returns (its overflow ends the run in the
    // HardFault handler).
    unsafe {
        core::arch::asm!(
            "msr psp, r0",
            "mrs r1, control",
            "orr r1, r1, #2",
            "msr control, r1",
            "isb",
            "bl {task}",
            "udf #0",
            in("r0") top,
            task = sym overflowing_task,
            options(noreturn),
        )
    }
}

/// The task that overflows: a recursion of 1 KiB frames (each filled, as a frame of locals would
/// be), on the PSP.
extern "C" fn overflowing_task() -> ! {
    let n = deep(0);
    let _ = writeln!(out(), "the recursion returned {n}");
    exit(false)
}

#[inline(never)]
fn deep(depth: u32) -> u32 {
    TRIGGERED_AT.store(ticks(), Ordering::SeqCst);
    let mut frame = core::hint::black_box([depth as u8; 1024]);
    if depth == u32::MAX {
        return 0;
    }
    frame[depth as usize % 1024] ^= 1;
    deep(depth + 1).wrapping_add(core::hint::black_box(frame)[7] as u32)
}

/// Instructions since the fatal test's trigger.
fn since_trigger(now: u32) -> u64 {
    now.wrapping_sub(TRIGGERED_AT.load(Ordering::SeqCst)) as u64 * INSTRUCTIONS_PER_TICK
}

fn exit(ok: bool) -> ! {
    debug::exit(if ok {
        debug::EXIT_SUCCESS
    } else {
        debug::EXIT_FAILURE
    });
    #[allow(clippy::empty_loop)]
    loop {}
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo<'_>) -> ! {
    if let Some((name, Fatal::Panic)) = fatal_run() {
        // The board's order: outputs safe, then the message, then the record.
        let image = fatal::safe_state();
        let n = since_trigger(ticks());
        let mut m = MessageBuf::new();
        let _ = write!(m, "{info}");
        let record = reset::encode(ResetCause::Panic, m.as_bytes());
        exit(fatal::finish(
            &mut out(),
            name,
            Fatal::Panic,
            &image,
            &record,
            Some(n),
        ));
    }
    let mut out = out();
    let _ = writeln!(out, "\npanicked: {info}\n\ntest result: FAILED (panic)");
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[exception]
unsafe fn HardFault(ef: &ExceptionFrame) -> ! {
    if let Some((name, Fatal::HardFault)) = fatal_run() {
        let image = fatal::safe_state();
        let n = since_trigger(ticks());
        // SAFETY: reads of the System Control Block's fault status and address registers, always
        // mapped on a Cortex-M7.
        let (cfsr, hfsr, bfar) = unsafe {
            let scb = &*cortex_m::peripheral::SCB::PTR;
            (scb.cfsr.read(), scb.hfsr.read(), scb.bfar.read())
        };
        let m = reset::cpu_fault_message(ef.pc(), ef.lr(), cfsr, hfsr, bfar);
        let record = reset::encode(ResetCause::CpuFault, m.as_bytes());
        exit(fatal::finish(
            &mut out(),
            name,
            Fatal::HardFault,
            &image,
            &record,
            Some(n),
        ));
    }
    if let Some((name, Fatal::StackOverflow)) = fatal_run() {
        // The board's handler (`firmware/board/src/safety.rs`): outputs safe, then the record,
        // told from the fault status without reading `ef` (the frame the core could not stack).
        let image = fatal::safe_state();
        let n = since_trigger(ticks());
        let msp = cortex_m::register::msp::read();
        let psp = cortex_m::register::psp::read();
        // SAFETY: as above, and MMFAR.
        let (cfsr, hfsr, mmfar) = unsafe {
            let scb = &*cortex_m::peripheral::SCB::PTR;
            (scb.cfsr.read(), scb.hfsr.read(), scb.mmfar.read())
        };
        let base = GUARD_BASE.load(Ordering::SeqCst);
        let top = task_stack_guard().map_or(0, |g| g.2);
        let mut out = out();
        let _ = writeln!(
            out,
            "\n    in the handler: msp={msp:#010x} psp={psp:#010x} cfsr={cfsr:#010x} \
             hfsr={hfsr:#010x} mmfar={mmfar:#010x}; guard {base:#010x}+{}, task stack top \
             {top:#010x}",
            stack::TASK_GUARD_BYTES
        );
        let on_msp = !(base..top).contains(&msp);
        let told = stack::task_overflow(cfsr, mmfar, psp, base, stack::TASK_GUARD_BYTES);
        let m = if told {
            stack::overflow_message(psp, cfsr, hfsr, mmfar)
        } else {
            reset::cpu_fault_message(0, 0, cfsr, hfsr, 0)
        };
        let record = reset::encode(ResetCause::CpuFault, m.as_bytes());
        let mut ok = fatal::finish(
            &mut out,
            name,
            Fatal::StackOverflow,
            &image,
            &record,
            Some(n),
        );
        if !on_msp {
            let _ = writeln!(
                out,
                "    failed: the HardFault handler ran on the task stack (msp={msp:#010x})"
            );
            ok = false;
        }
        exit(ok);
    }
    let mut out = out();
    let _ = writeln!(out, "\nHardFault: {ef:?}\n\ntest result: FAILED (fault)");
    debug::exit(debug::EXIT_FAILURE);
    #[allow(clippy::empty_loop)]
    loop {}
}

#[exception]
unsafe fn NonMaskableInt() {
    if let Some((name, Fatal::Nmi)) = fatal_run() {
        // The board's order (`firmware/board/src/safety.rs`): outputs safe, then the record.
        let image = fatal::safe_state();
        let n = since_trigger(ticks());
        let record = reset::encode(ResetCause::CpuFault, reset::nmi_message().as_bytes());
        exit(fatal::finish(
            &mut out(),
            name,
            Fatal::Nmi,
            &image,
            &record,
            Some(n),
        ));
    }
    let mut out = out();
    let _ = writeln!(out, "\nunexpected NMI\n\ntest result: FAILED (fault)");
    debug::exit(debug::EXIT_FAILURE);
}

#[exception]
unsafe fn DefaultHandler(irqn: i16) {
    if let Some((name, Fatal::UnboundIrq)) = fatal_run() {
        let image = fatal::safe_state();
        let n = since_trigger(ticks());
        let m = reset::unhandled_message(irqn);
        let record = reset::encode(ResetCause::CpuFault, m.as_bytes());
        exit(fatal::finish(
            &mut out(),
            name,
            Fatal::UnboundIrq,
            &image,
            &record,
            Some(n),
        ));
    }
    let mut out = out();
    let _ = writeln!(
        out,
        "\nunexpected exception {irqn}\n\ntest result: FAILED (fault)"
    );
    debug::exit(debug::EXIT_FAILURE);
}

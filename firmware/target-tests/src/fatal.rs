//! The fatal paths on the target: a panic inside a task, a HardFault, an NMI and an interrupt with
//! no handler of its own, each in a run of the binary of its own (`cargo xtask target-test` starts
//! one QEMU per fatal test after the others: none returns to the runner).
//!
//! The binary's panic, HardFault, NMI and default handlers (`src/qemu.rs`), when the run is one of
//! these tests, do what the board's do (`firmware/board/src/safety.rs`), in the same order and with the same
//! library code: the safe state first ([`tribo_firmware::safety::apply`], here on a register image of
//! live outputs, since QEMU's machine has no STM32 peripherals), then the message formatted into the
//! same [`reset::MessageBuf`] (the HardFault's from the exception frame and the fault status
//! registers with [`reset::cpu_fault_message`]; the NMI's and the unbound interrupt's with
//! [`reset::nmi_message`] and [`reset::unhandled_message`]) and kept as a [`reset::encode`]d record. Then
//! [`finish`] checks what a board would find after its reset: outputs safe, and a record that
//! decodes to the cause and message (the `Boot` report the next `Hello` gets), and prints the
//! instructions from the fault to safe outputs.
//!
//! The stack overflow test runs the board's two-stack layout (`firmware/board/src/memory.rs` and
//! `mpu.rs`, from the same [`tribo_firmware::stack`] numbers): the overflowing "task" on the PSP
//! above an MPU no-access guard, the HardFault on the MSP; its handler checks it runs on the MSP,
//! outside the task stack, that the library tells the overflow from the fault status
//! ([`tribo_firmware::stack::task_overflow`]), and records what the board records.
//!
//! What this does not cover: the board's volatile writes reaching real STM32 registers (the
//! addresses are checked against the PAC at boot by `check_table`) and the reset itself.

use core::fmt::Write;

use crate::tests::failsafe::RegisterImage;
use tribo_firmware::reset::{self, Record};
use tribo_firmware::wire::ResetCause;

/// A fatal test.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fatal {
    /// A task panics (an index out of bounds in the heater's step).
    Panic,
    /// The core takes a HardFault (an undefined instruction, escalated).
    HardFault,
    /// A non-maskable interrupt (pended through ICSR.NMIPENDSET).
    Nmi,
    /// An enabled interrupt with no handler of its own (IRQ 0, pended through the NVIC).
    UnboundIrq,
    /// A task stack overflow: thread mode on the PSP with the board's layout
    /// ([`tribo_firmware::stack`]: an MPU no-access guard of `TASK_GUARD_BYTES` below the task
    /// stack, handlers on the MSP), a recursion of 1 KiB frames until it runs into the guard.
    StackOverflow,
}

/// The fatal tests by name (the binary runs one when the filter is exactly its name).
pub const FATAL: [(&str, Fatal); 5] = [
    ("failsafe::panic_inside_a_task", Fatal::Panic),
    ("failsafe::hard_fault", Fatal::HardFault),
    ("failsafe::nmi", Fatal::Nmi),
    ("failsafe::unbound_interrupt", Fatal::UnboundIrq),
    ("failsafe::stack_overflow", Fatal::StackOverflow),
];

/// The fatal test named exactly `filter`, if any.
pub fn named(filter: &str) -> Option<(&'static str, Fatal)> {
    FATAL.iter().copied().find(|(n, _)| *n == filter)
}

/// A task's step that indexes out of bounds at `i` ≥ 4 (the panic of the panic test).
#[inline(never)]
pub fn heater_step_that_panics(table: &[u8; 4], i: usize) -> u8 {
    table[i]
}

/// The handler's first work: the safe state, applied to a register image of live outputs (a panic
/// in the middle of a heated, holding run). Returns the image.
#[inline(always)]
pub fn safe_state() -> RegisterImage {
    let mut image = RegisterImage::live();
    tribo_firmware::safety::apply(|a, c, s| {
        image.rmw(a, c, s);
    });
    image
}

/// Checks what the handler left (`image` after the safe state, `record` kept) and prints the test's
/// lines and summary, libtest style; `instructions` from the fault to safe outputs. True: passed.
pub fn finish(
    out: &mut dyn Write,
    name: &str,
    which: Fatal,
    image: &RegisterImage,
    record: &Record,
    instructions: Option<u64>,
) -> bool {
    let _ = writeln!(out);
    let (cause, expect) = match which {
        Fatal::Panic => (ResetCause::Panic, "index out of bounds"),
        Fatal::HardFault => (ResetCause::CpuFault, "HardFault at pc="),
        Fatal::Nmi => (ResetCause::CpuFault, "NMI"),
        Fatal::UnboundIrq => (
            ResetCause::CpuFault,
            "unhandled exception or interrupt irqn=0",
        ),
        Fatal::StackOverflow => (
            ResetCause::CpuFault,
            "stack overflow: task stack hit its guard",
        ),
    };
    let mut failure: Option<heapless::String<256>> = None;
    let mut fail = |args: core::fmt::Arguments<'_>| {
        if failure.is_none() {
            let mut s = heapless::String::new();
            let _ = s.write_fmt(args);
            failure = Some(s);
        }
    };
    if let Err(what) = image.safe() {
        fail(format_args!(
            "after the handler's safe state, {what} is not safe"
        ));
    }
    match reset::decode(record) {
        None => fail(format_args!(
            "the reset record does not decode: {record:08x?}"
        )),
        Some((c, m)) => {
            let _ = writeln!(out, "    reset record: {c:?}, \"{m}\"");
            if c != cause || !m.contains(expect) {
                fail(format_args!(
                    "the reset record says {c:?} \"{m}\", expected {cause:?} with \"{expect}\""
                ));
            }
        }
    }
    /// Budget from the fault to safe outputs, instructions (≈ 10 µs of a 480 MHz M7).
    const BUDGET: u64 = 5_000;
    if let Some(n) = instructions {
        let _ = writeln!(
            out,
            "    figure failsafe.{}_to_safe_outputs = {n} instructions (budget {BUDGET})",
            match which {
                Fatal::Panic => "panic",
                Fatal::HardFault => "hard_fault",
                Fatal::Nmi => "nmi",
                Fatal::UnboundIrq => "unbound_interrupt",
                Fatal::StackOverflow => "stack_overflow",
            }
        );
        if n > BUDGET {
            fail(format_args!(
                "{n} instructions from the fault to safe outputs, over the budget of {BUDGET}"
            ));
        }
    }
    let ok = failure.is_none();
    if let Some(f) = &failure {
        let _ = writeln!(out, "    failed: {f}");
    }
    let _ = writeln!(out, "test {name} ... {}", if ok { "ok" } else { "FAILED" });
    let _ = writeln!(
        out,
        "\ntest result: {}. {} passed; {} failed; 0 filtered out",
        if ok { "ok" } else { "FAILED" },
        ok as u8,
        !ok as u8
    );
    ok
}

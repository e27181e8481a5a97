//! The two stacks of the board and the task stack's guard, as data (the board's `memory.x`,
//! `memory.rs` and `mpu.rs` apply it; `cargo xtask firmware` checks the binary's frames against it;
//! the on-target test `failsafe::stack_overflow` runs the same layout under QEMU).
//!
//! * Thread mode (`main`, the embassy executor and every task it polls) runs on the **process stack
//!   (PSP)**: the top of the AXI SRAM down to the end of the statics, whose lowest
//!   [`TASK_GUARD_BYTES`] (aligned) are an MPU no-access region. A frame never skips the guard:
//!   every frame of the binary is at most [`TASK_GUARD_BYTES`] (checked by `cargo xtask firmware`
//!   from the ELF), and a function touches its frame only after moving SP below it, so the first
//!   access of an overflowing frame lands in the guard (Cortex-M7 has no stack probes: this is the
//!   rule that replaces them).
//! * Handler mode (interrupts, HardFault, NMI) runs on the **main stack (MSP)**, [`MAIN_STACK_BYTES`]
//!   of its own at the bottom of SRAM4: a task that overflows into its guard takes a MemManage fault,
//!   escalated to HardFault (MemManage is not enabled); the core's stacking of that exception's frame
//!   on the PSP faults too (MSTKERR), which does not lock up the core: the handler still runs, on the
//!   MSP, which is intact. It drives the outputs safe, keeps a record saying "stack overflow", and
//!   resets. Below the main stack is unmapped address space (the flip-link layout): a handler that
//!   overflows it takes a bus fault it cannot stack, the core locks up, and the IWDG resets it
//!   (outputs then in their reset state, without a record).

use core::fmt::Write;

use crate::reset::MessageBuf;

/// Bytes of the task stack's no-access guard (an MPU region: a power of two, aligned to itself).
/// No frame of the firmware may be larger (`cargo xtask firmware` fails otherwise).
pub const TASK_GUARD_BYTES: u32 = 8192;
/// Least task stack above the guard (`cargo xtask firmware` and the board check the same).
pub const MIN_TASK_STACK_BYTES: u32 = 32 * 1024;
/// Bytes of the main stack (handlers only), at the bottom of SRAM4 (`memory.x`, `MSP_STACK`).
pub const MAIN_STACK_BYTES: u32 = 8192;

/// Where the guard goes for a task stack from `bottom` (the end of the statics) up to `top`: the
/// first `guard`-aligned `guard` bytes above `bottom`, as `(base, bytes)`; `None` unless a power of
/// two of at least 32 bytes and [`MIN_TASK_STACK_BYTES`] of stack above it fit.
pub fn guard(bottom: u32, top: u32, guard: u32) -> Option<(u32, u32)> {
    if guard < 32 || !guard.is_power_of_two() || top < bottom {
        return None;
    }
    let base = bottom.checked_next_multiple_of(guard)?;
    (base.checked_add(guard)?.checked_add(MIN_TASK_STACK_BYTES)? <= top).then_some((base, guard))
}

/// CFSR bits of the MemManage status (RM: ARMv7-M B3.2.15).
pub mod cfsr {
    /// Data access violation.
    pub const DACCVIOL: u32 = 1 << 1;
    /// Fault while stacking an exception's frame.
    pub const MSTKERR: u32 = 1 << 4;
    /// MMFAR holds the faulting address.
    pub const MMARVALID: u32 = 1 << 7;
    /// Bus fault while stacking an exception's frame.
    pub const STKERR: u32 = 1 << 12;
}

/// Whether a fault with these status registers is the task stack overflowing into its guard
/// `[guard_base, guard_base + guard_bytes)`: the frame's stacking on the PSP failed and the PSP is in
/// or below the guard, or a data access faulted inside the guard.
pub fn task_overflow(cfsr: u32, mmfar: u32, psp: u32, guard_base: u32, guard_bytes: u32) -> bool {
    let top = guard_base.saturating_add(guard_bytes);
    let stacking = cfsr & (cfsr::MSTKERR | cfsr::STKERR) != 0;
    let access = cfsr & (cfsr::DACCVIOL | cfsr::MMARVALID) == (cfsr::DACCVIOL | cfsr::MMARVALID)
        && (guard_base..top).contains(&mmfar);
    (stacking && psp < top) || access
}

/// The reset record's message for a task stack overflow.
pub fn overflow_message(psp: u32, cfsr: u32, hfsr: u32, mmfar: u32) -> MessageBuf {
    let mut m = MessageBuf::new();
    let _ = write!(
        m,
        "stack overflow: task stack hit its guard, psp={psp:#010x} cfsr={cfsr:#010x} \
         hfsr={hfsr:#010x} mmfar={mmfar:#010x}"
    );
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_guard_goes_above_the_statics_aligned() {
        // The board's AXI SRAM (its end is the stack's top): statics ending 28 KiB below it.
        assert_eq!(
            guard(0x2407_9000, 0x2408_0000, TASK_GUARD_BYTES),
            None,
            "less than 32 KiB above the guard: refused"
        );
        assert_eq!(
            guard(0x2406_0004, 0x2408_0000, 8192),
            Some((0x2406_2000, 8192))
        );
        // Already aligned: the guard starts at the end of the statics.
        assert_eq!(
            guard(0x2406_0000, 0x2408_0000, 8192),
            Some((0x2406_0000, 8192))
        );
        // Exactly 32 KiB left above it: accepted; one byte less: refused.
        assert_eq!(
            guard(0x2407_6000, 0x2408_0000, 8192),
            Some((0x2407_6000, 8192))
        );
        assert_eq!(guard(0x2407_6001, 0x2408_0000, 8192), None);
        // Not a region the MPU can make.
        assert_eq!(guard(0x2400_0000, 0x2408_0000, 6000), None);
        assert_eq!(guard(0x2400_0000, 0x2408_0000, 16), None);
        // At the top of the address space: no overflow.
        assert_eq!(guard(0xFFFF_F000, 0xFFFF_FFFF, 8192), None);
        assert_eq!(guard(0x2408_0000, 0x2400_0000, 8192), None);
    }

    #[test]
    fn an_overflow_is_told_from_other_faults() {
        let (base, bytes) = (0x2406_2000, 8192);
        // Stacking failed with the PSP inside the guard, or below it.
        assert!(task_overflow(cfsr::MSTKERR, 0, 0x2406_2F00, base, bytes));
        assert!(task_overflow(cfsr::MSTKERR, 0, 0x2406_1000, base, bytes));
        // The PSP at the guard's top (one word above is stack): not yet.
        assert!(!task_overflow(cfsr::MSTKERR, 0, 0x2406_4000, base, bytes));
        // A store into the guard, the PSP still above it (a frame bigger than what is left).
        let access = cfsr::DACCVIOL | cfsr::MMARVALID;
        assert!(task_overflow(access, 0x2406_3FFC, 0x2406_4100, base, bytes));
        assert!(task_overflow(access, base, 0x2406_4100, base, bytes));
        // A violation elsewhere (bank 2 written, say), or without a valid address: not the stack.
        assert!(!task_overflow(
            access,
            0x2406_4000,
            0x2406_4100,
            base,
            bytes
        ));
        assert!(!task_overflow(
            access,
            0x0810_0000,
            0x2406_4100,
            base,
            bytes
        ));
        assert!(!task_overflow(
            cfsr::DACCVIOL,
            0x2406_3000,
            0x2406_4100,
            base,
            bytes
        ));
        // An undefined instruction.
        assert!(!task_overflow(1 << 16, 0, 0x2407_0000, base, bytes));
        let m = overflow_message(0x2406_2F00, 0x91, 0x4000_0000, 0x2406_2EE0);
        let m = core::str::from_utf8(m.as_bytes()).unwrap();
        assert!(
            m.starts_with("stack overflow: task stack hit its guard"),
            "{m}"
        );
        assert!(
            m.contains("psp=0x24062f00") && m.ends_with("mmfar=0x24062ee0"),
            "{m}"
        );
    }
}

//! The memory protection unit and the caches: which memory the D-cache may hold, and the stack's
//! guard. Programmed once at the top of `main`, before the caches are turned on and before any DMA,
//! flash operation or task.
//!
//! | region | memory | attributes | why |
//! |---|---|---|---|
//! | 0 | flash bank 2 (0x0810_0000, 1 MiB) | normal, non-cacheable, execute-never | the run store erases and programs it behind the cache's back: a cached line would keep the bytes from before an erase or a program |
//! | 1 | the task stack's guard: the lowest aligned [`STACK_GUARD_BYTES`] (8 KiB) of the process stack (PSP), above the statics | no access, execute-never | a task stack that grows into it faults at once instead of writing over `.bss` (the app task's future, the USB buffers); no frame of the binary is larger (`cargo xtask firmware` checks), so none can skip it. The fault is taken on the main stack (MSP, SRAM4), which the overflow did not touch (`tribo_firmware::stack`) |
//! | 5 | the no-init RAM (`NOINIT`, SRAM4's last KiB: reset record, recovery marker) | normal, non-cacheable, shareable, execute-never | what the fatal paths write there must be in the SRAM when `sys_reset` cuts the core off: `SCB::sys_reset` does not clean the D-cache. The MPU is enabled without HFNMIENA, so inside HardFault and NMI it is off and this region does not apply: `safety::clean_dcache` cleans the lines after every store there |
//! | 7 | the converter's DMA ring (`DMA_RING`, 16 KiB of SRAM3) | normal, non-cacheable, shareable, execute-never | the DMA writes it under the reader at any moment (see `sampling.rs`) |
//!
//! The RTT control block and the defmt buffer need no region: they are in the DTCM (`memory.x`,
//! `.rtt`), which the D-cache never holds, so the probe reads what the core wrote.
//!
//! Every region's base and size are checked before anything is programmed (size a power of two of
//! at least 32 bytes, base aligned to it, and, for the sections, the region holding the actual
//! addresses of the statics the linker placed). If one does not check out, the D-cache is left off
//! (every access then reaches memory: correct, slower) and the reason is returned.
#![allow(unsafe_code)]

use tribo_firmware::hal::FlashGeometry;

/// Flash bank 2 (RM0433: 0x0810_0000, 1 MiB).
pub const BANK2_BASE: u32 = 0x0810_0000;
/// Size of the task stack's guard region.
pub const STACK_GUARD_BYTES: u32 = tribo_firmware::stack::TASK_GUARD_BYTES;

/// An MPU region: number (higher wins where regions overlap), base, size, attributes.
#[derive(Clone, Copy, defmt::Format)]
pub struct Region {
    pub number: u32,
    pub base: u32,
    pub bytes: u32,
    /// RASR without SIZE and ENABLE: XN, AP, TEX, S, C, B.
    pub attrs: u32,
}

/// Execute-never, full access, TEX = 0b001 C = 0 B = 0: normal memory, non-cacheable.
pub const NORMAL_UNCACHED: u32 = 1 << 28 | 0b011 << 24 | 0b001 << 19;
/// The same, shareable.
pub const NORMAL_UNCACHED_SHARED: u32 = NORMAL_UNCACHED | 1 << 18;
/// Execute-never, no access (AP = 0b000).
pub const NO_ACCESS: u32 = 1 << 28;

impl Region {
    /// `base` aligned to `bytes`, a power of two of at least 32 (the MPU's rules).
    fn valid(&self) -> bool {
        self.bytes >= 32
            && self.bytes.is_power_of_two()
            && self.base.is_multiple_of(self.bytes)
            && self.number < 8
    }

    fn rasr(&self) -> u32 {
        // SIZE: the region is 2^(SIZE + 1) bytes.
        let size = self.bytes.trailing_zeros() - 1;
        self.attrs | size << 1 | 1
    }
}

/// Region 0: bank 2, non-cacheable.
pub fn bank2() -> Region {
    Region {
        number: 0,
        base: BANK2_BASE,
        bytes: FlashGeometry::H743_BANK2.bytes(),
        attrs: NORMAL_UNCACHED,
    }
}

extern "C" {
    // cortex-m-rt's link.x: the end of the statics in RAM, the task stack's lowest address; and
    // `memory.x`: the task stack's top (the end of the AXI SRAM).
    static _stack_end: u32;
    static _task_stack_top: u32;
}

/// Region 1: the task stack's guard, the first aligned [`STACK_GUARD_BYTES`] above the end of the
/// statics (`tribo_firmware::stack::guard`); `None` if the stack is too small to give them up.
pub fn stack_guard() -> Option<Region> {
    // Only the addresses of the linker's symbols are taken, never their contents.
    let (end, top) = (
        core::ptr::addr_of!(_stack_end) as u32,
        core::ptr::addr_of!(_task_stack_top) as u32,
    );
    let (base, bytes) = tribo_firmware::stack::guard(end, top, STACK_GUARD_BYTES)?;
    Some(Region {
        number: 1,
        base,
        bytes,
        attrs: NO_ACCESS,
    })
}

/// Checks `region` holds `[addr, addr + len)` (the actual address of a static the linker placed).
pub fn holds(region: &Region, addr: u32, len: u32) -> bool {
    addr >= region.base && addr.saturating_add(len) <= region.base.saturating_add(region.bytes)
}

/// Programs `regions` (each checked first), then turns the I-cache on, and the D-cache too unless a
/// region did not check out (`Err` says which).
pub fn configure_and_enable_caches(
    mpu: &mut cortex_m::peripheral::MPU,
    scb: &mut cortex_m::peripheral::SCB,
    cpuid: &mut cortex_m::peripheral::CPUID,
    regions: &[Option<Region>],
) -> Result<(), &'static str> {
    let mut result = Ok(());
    cortex_m::asm::dsb();
    cortex_m::asm::dmb();
    // SAFETY: the MPU is programmed once, at the top of `main`, with the caches still off (the
    // reset state), before any task, DMA transfer or flash operation, so no access is in flight
    // under a changing attribute. The regions are disabled while they are written (CTRL = 0), and
    // the background map stays enabled (PRIVDEFENA), so every address outside the regions keeps
    // the default map: the only accesses the regions change are those they are meant to change
    // (uncached, or a fault in the stack's guard, which is below every live frame).
    unsafe {
        mpu.ctrl.write(0);
        for r in regions {
            match r {
                Some(r) if r.valid() => {
                    mpu.rnr.write(r.number);
                    mpu.rbar.write(r.base);
                    mpu.rasr.write(r.rasr());
                }
                Some(_) => result = Err("an MPU region is misaligned"),
                None => result = Err("an MPU region could not be placed"),
            }
        }
        mpu.ctrl.write(1 << 2 | 1);
    }
    cortex_m::asm::dsb();
    cortex_m::asm::isb();
    scb.enable_icache();
    if result.is_ok() {
        scb.enable_dcache(cpuid);
    }
    result
}

//! Where the run store's big buffers live (the map is in `firmware/README.md`):
//!
//! * the RAM ring: 384 KiB in the AXI SRAM (`.bss`, next to everything else), SRAM1 and SRAM2
//!   (128 KiB each, D2 domain) and 48 KiB of the DTCM, 688 KiB in all;
//! * the block index (73 KiB): in the DTCM too. Only the CPU reaches the DTCM, and only the CPU
//!   touches these (no DMA).
//!
//! SRAM1, SRAM2 and the DTCM buffers are not in the runtime's `.bss`: their sections (see `memory.x`) are
//! `NOLOAD`, so this module zeroes them before handing them out, once. SRAM3 (DMA buffers) and
//! SRAM4 are left to the other concerns. Also here: the copy of defmt-rtt's control block into the
//! DTCM at reset (`__pre_init`, at the end).
// `#[link_section]`, the raw pointers and the start-up assembly need `unsafe`.
#![allow(unsafe_code)]

use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, Ordering};
use static_cell::ConstStaticCell;
use tribo_firmware::runstore::{BOARD_RING_BYTES, MAX_RUN_BLOCKS};

const AXI: usize = BOARD_RING_BYTES[0];
const SRAM1: usize = BOARD_RING_BYTES[1];
const SRAM2: usize = BOARD_RING_BYTES[2];
const DTCM: usize = BOARD_RING_BYTES[3];

static RING_AXI: ConstStaticCell<[u8; AXI]> = ConstStaticCell::new([0; AXI]);

#[link_section = ".sram1"]
static mut RING_SRAM1: MaybeUninit<[u8; SRAM1]> = MaybeUninit::uninit();
#[link_section = ".sram2"]
static mut RING_SRAM2: MaybeUninit<[u8; SRAM2]> = MaybeUninit::uninit();
#[link_section = ".dtcm"]
static mut INDEX: MaybeUninit<[u32; MAX_RUN_BLOCKS]> = MaybeUninit::uninit();
#[link_section = ".dtcm"]
static mut RING_DTCM: MaybeUninit<[u8; DTCM]> = MaybeUninit::uninit();

static TAKEN: AtomicBool = AtomicBool::new(false);

/// The run store's memory, handed out once.
pub struct RunStoreMemory {
    pub ring: [&'static mut [u8]; 4],
    pub index: &'static mut [u32],
}

/// The run store's buffers, zeroed; `None` after the first call.
pub fn take() -> Option<RunStoreMemory> {
    if TAKEN.swap(true, Ordering::AcqRel) {
        return None;
    }
    // The CPU allocates SRAM1 and SRAM2 (they stay powered with it in every run mode).
    embassy_stm32::pac::RCC.ahb2enr().modify(|w| {
        w.set_sram1en(true);
        w.set_sram2en(true);
    });
    cortex_m::asm::dsb();
    // SAFETY: `TAKEN` lets this run once, so the four `&'static mut` made here are the only
    // references to these statics for the life of the program (nothing else names them). The
    // statics live in NOLOAD sections that the runtime does not initialise: each is fully written
    // (zeroed) through a raw pointer before a reference to it is made, so the slices cover
    // initialised bytes of exactly the statics' sizes.
    let (sram1, sram2, dtcm, index) = unsafe {
        let p1 = (&raw mut RING_SRAM1).cast::<u8>();
        let p2 = (&raw mut RING_SRAM2).cast::<u8>();
        let pd = (&raw mut RING_DTCM).cast::<u8>();
        let pi = (&raw mut INDEX).cast::<u32>();
        core::ptr::write_bytes(p1, 0, SRAM1);
        core::ptr::write_bytes(p2, 0, SRAM2);
        core::ptr::write_bytes(pd, 0, DTCM);
        core::ptr::write_bytes(pi, 0, MAX_RUN_BLOCKS);
        (
            core::slice::from_raw_parts_mut(p1, SRAM1),
            core::slice::from_raw_parts_mut(p2, SRAM2),
            core::slice::from_raw_parts_mut(pd, DTCM),
            core::slice::from_raw_parts_mut(pi, MAX_RUN_BLOCKS),
        )
    };
    Some(RunStoreMemory {
        ring: [RING_AXI.take(), sram1, sram2, dtcm],
        index,
    })
}

// defmt-rtt's control block lives in the DTCM (`.rtt` in `memory.x`: never in the D-cache, so the
// probe and the core see each other's writes), outside cortex-m-rt's `.data`, whose copy from flash
// does not cover it. This `__pre_init` (called by cortex-m-rt's reset handler before it initialises
// RAM, and before any Rust code runs) copies its initial value from its load address, word by word,
// as the reset handler does for `.data`: in assembly, because no Rust code may run before RAM is
// initialised. It also zeroes the buffer (`.rtt_buffer`), so that its ECC is written before
// defmt-rtt's byte writes. The DTCM is enabled out of reset. `memory.x` aligns both sections and
// `.rtt`'s load address to 4 bytes and pads their sizes to multiples of 4.
//
// Before that, it moves thread mode to the process stack (see the comment in the assembly).
//
// Before that, first of all, it starts the independent watchdog with its longest timeout
// ([`BOOT_WATCHDOG`]): from the first instruction after reset, a boot stuck anywhere (the HSE-ready
// wait, which has no timeout when the ST-LINK's clock output is absent; the run store's recovery;
// its erase-first step) resets the chip, outputs in their reset state. `board::watchdog_task`
// shortens it to the run timeout once the application runs.
core::arch::global_asm!(
    ".section .text.__pre_init, \"ax\"",
    ".global __pre_init",
    ".type __pre_init, %function",
    ".thumb_func",
    "__pre_init:",
    "    ldr r0, ={iwdg}",
    "    ldr r1, ={start}",
    "    str r1, [r0]",
    "    ldr r1, ={unlock}",
    "    str r1, [r0]",
    "    movs r1, #{pr}",
    "    str r1, [r0, #4]",
    "    ldr r1, ={rl}",
    "    str r1, [r0, #8]",
    "    ldr r1, ={reload}",
    "    str r1, [r0]",
    // ES0392 (STM32H743 errata), revision Y only (DBGMCU_IDCODE.REV_ID < 0x2000): AXI SRAM reads
    // can return corrupted data unless the AXI switch matrix issues one read at a time to its
    // target 7 (the AXI SRAM): AXI_TARG7_FN_MOD.READ_ISS_OVERRIDE = 1, as ST's SystemInit does,
    // before `.bss` and `.data` (in the AXI SRAM) are touched.
    "    ldr r0, ={idcode}",
    "    ldr r0, [r0]",
    "    lsrs r0, r0, #16",
    "    cmp r0, #0x2000",
    "    bhs 4f",
    "    ldr r0, ={targ7}",
    "    movs r1, #1",
    "    str r1, [r0]",
    "    dsb",
    "4:",
    // The two stacks (`tribo_firmware::stack`). The main stack (MSP, the vector table's initial
    // stack pointer: the bottom 8 KiB of SRAM4, `MSP_STACK` in `memory.x`) is zeroed, so that its
    // ECC is written before a handler's byte or half-word stores; nothing is on it yet (the reset
    // handler pushes nothing before `main`). Then thread mode moves to the process stack
    // (CONTROL.SPSEL = 1, PSP = the top of the AXI SRAM): the rest of the reset handler, `main`
    // and every task run on the PSP, whose MPU guard `mpu.rs` programs, and the handlers on the
    // MSP, which a task's overflow does not touch.
    "    ldr r0, =_msp_stack_bottom",
    "    ldr r1, =_stack_start",
    "    movs r2, #0",
    "5:  cmp r1, r0",
    "    beq 6f",
    "    stm r0!, {{r2}}",
    "    b 5b",
    "6:  ldr r0, =_task_stack_top",
    "    msr psp, r0",
    "    mrs r0, control",
    "    orr r0, r0, #2",
    "    msr control, r0",
    "    isb",
    "    ldr r0, =__srtt",
    "    ldr r1, =__ertt",
    "    ldr r2, =__sirtt",
    "0:  cmp r1, r0",
    "    beq 1f",
    "    ldm r2!, {{r3}}",
    "    stm r0!, {{r3}}",
    "    b 0b",
    "1:  ldr r0, =__srttbuf",
    "    ldr r1, =__erttbuf",
    "    movs r2, #0",
    "2:  cmp r1, r0",
    "    beq 3f",
    "    stm r0!, {{r2}}",
    "    b 2b",
    "3:  bx lr",
    ".size __pre_init, . - __pre_init",
    iwdg = const BOOT_WATCHDOG.base,
    start = const 0xCCCC,
    unlock = const 0x5555,
    reload = const 0xAAAA,
    pr = const BOOT_WATCHDOG.pr,
    rl = const BOOT_WATCHDOG.rl,
    idcode = const 0x5C00_1000u32,
    targ7 = const 0x5100_8108u32,
);

/// The watchdog at boot: IWDG1 (RM0433: 0x5800_4800; KR at +0, PR at +4, RLR at +8), prescaler
/// /256 (PR = 6), reload 0xFFF: 4096 × 256 ticks of the LSI (32 kHz nominal; the part's range is
/// the self-test's, `tribo_firmware::selftest::LSI_MIN_HZ`…`LSI_MAX_HZ`, 29.76–33.6 kHz), 31.2–35.2 s. Long enough for a boot that works (the recovery reads at most the
/// 1 MiB bank, an erase-first step is one sector, ≤ 2.2 s), short enough that a stuck one resets.
/// The base is checked against the PAC at boot ([`boot_watchdog_matches_pac`]).
pub struct BootWatchdog {
    pub base: u32,
    pub pr: u32,
    pub rl: u32,
}
pub const BOOT_WATCHDOG: BootWatchdog = BootWatchdog {
    base: 0x5800_4800,
    pr: 6,
    rl: 0xFFF,
};

/// Whether [`BOOT_WATCHDOG`]'s base is the PAC's IWDG1 (if not, the start-up code wrote to
/// something else: logged by the caller).
pub fn boot_watchdog_matches_pac() -> bool {
    embassy_stm32::pac::IWDG1.as_ptr() as u32 == BOOT_WATCHDOG.base
}

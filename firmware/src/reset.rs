//! Why the rig last reset, kept across the reset and told to the host at the next boot.
//!
//! The panic handler, the HardFault handler and the watchdog task write a [`Record`] (cause and
//! message, CRC-protected) into a small RAM section that start-up code does not initialise
//! (`.reset_record` in `memory.x`), then reset the chip. At the next boot the board reads the
//! hardware's reset flags ([`ResetFlags::from_h7_rsr`]) and the record, and [`boot_report`] makes the
//! [`BootReport`] the application answers the first `Hello` with. The record is then erased, so it
//! is told once.
//!
//! After a power-on the section holds garbage (the CRC refuses it), and on the H7 its ECC may never
//! have been written: [`boot_report`] does not read it then.

use core::fmt::Write;

use crate::wire::crc32::crc32;
use crate::wire::{BootReport, ResetCause, BOOT_MESSAGE_LEN};

/// Words of a record: magic, cause and length, the message, CRC-32.
pub const RECORD_WORDS: usize = 3 + BOOT_MESSAGE_LEN / 4;
/// A record as it lies in memory.
pub type Record = [u32; RECORD_WORDS];

const MAGIC: u32 = 0x5452_4942; // "TRIB"
/// A record that says nothing (what the board writes once it has read the last one).
pub const EMPTY: Record = [0; RECORD_WORDS];

const _: () = assert!(BOOT_MESSAGE_LEN.is_multiple_of(4));

fn cause_code(c: ResetCause) -> u8 {
    match c {
        ResetCause::PowerOn => 0,
        ResetCause::Pin => 1,
        ResetCause::Software => 2,
        ResetCause::Watchdog => 3,
        ResetCause::Panic => 4,
        ResetCause::CpuFault => 5,
        ResetCause::Brownout => 6,
        ResetCause::Unknown => 7,
    }
}

fn cause_of(code: u8) -> Option<ResetCause> {
    ResetCause::ALL.get(code as usize).copied()
}

fn crc_of(words: &[u32]) -> u32 {
    let mut bytes = [0u8; 4 * (RECORD_WORDS - 1)];
    for (c, w) in bytes.chunks_exact_mut(4).zip(words) {
        c.copy_from_slice(&w.to_le_bytes());
    }
    crc32(&bytes[..4 * words.len()])
}

/// The record of `cause` with `message` (cut to [`BOOT_MESSAGE_LEN`] bytes).
pub fn encode(cause: ResetCause, message: &[u8]) -> Record {
    let len = message.len().min(BOOT_MESSAGE_LEN);
    let mut r = EMPTY;
    r[0] = MAGIC;
    r[1] = cause_code(cause) as u32 | (len as u32) << 8;
    let mut bytes = [0u8; BOOT_MESSAGE_LEN];
    bytes[..len].copy_from_slice(&message[..len]);
    for (w, c) in r[2..RECORD_WORDS - 1].iter_mut().zip(bytes.chunks_exact(4)) {
        *w = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
    }
    r[RECORD_WORDS - 1] = crc_of(&r[..RECORD_WORDS - 1]);
    r
}

/// The cause and message of a record, if it is one (magic, CRC, known cause, valid length).
/// Message bytes that are not UTF-8 end the message there.
pub fn decode(r: &Record) -> Option<(ResetCause, heapless::String<BOOT_MESSAGE_LEN>)> {
    if r[0] != MAGIC || r[RECORD_WORDS - 1] != crc_of(&r[..RECORD_WORDS - 1]) {
        return None;
    }
    let cause = cause_of((r[1] & 0xFF) as u8)?;
    let len = ((r[1] >> 8) & 0xFF) as usize;
    if len > BOOT_MESSAGE_LEN || r[1] >> 16 != 0 {
        return None;
    }
    let mut bytes = [0u8; BOOT_MESSAGE_LEN];
    for (c, w) in bytes.chunks_exact_mut(4).zip(&r[2..RECORD_WORDS - 1]) {
        c.copy_from_slice(&w.to_le_bytes());
    }
    let text = match core::str::from_utf8(&bytes[..len]) {
        Ok(s) => s,
        Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or(""),
    };
    let mut s = heapless::String::new();
    let _ = s.push_str(text);
    Some((cause, s))
}

/// A [`core::fmt::Write`] into a fixed buffer that keeps what fits (whole characters) and drops the
/// rest: the panic handler formats its message through it without allocating or failing.
#[derive(Debug, Clone)]
pub struct MessageBuf {
    buf: [u8; BOOT_MESSAGE_LEN],
    len: usize,
}

impl MessageBuf {
    pub const fn new() -> Self {
        MessageBuf {
            buf: [0; BOOT_MESSAGE_LEN],
            len: 0,
        }
    }

    pub fn as_bytes(&self) -> &[u8] {
        &self.buf[..self.len]
    }
}

impl Default for MessageBuf {
    fn default() -> Self {
        Self::new()
    }
}

impl Write for MessageBuf {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        for ch in s.chars() {
            let mut b = [0u8; 4];
            let e = ch.encode_utf8(&mut b).as_bytes();
            if self.len + e.len() > BOOT_MESSAGE_LEN {
                // Full: the rest is dropped, and that is not an error (formatting goes on harmlessly).
                return Ok(());
            }
            self.buf[self.len..self.len + e.len()].copy_from_slice(e);
            self.len += e.len();
        }
        Ok(())
    }
}

/// The reset flags of the chip, as the hardware latched them.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ResetFlags {
    pub power_on: bool,
    pub brownout: bool,
    pub pin: bool,
    pub software: bool,
    pub independent_watchdog: bool,
    pub window_watchdog: bool,
    pub low_power: bool,
}

impl ResetFlags {
    /// From the STM32H7's RCC_RSR (RM0433 §8.7.35): LPWRRSTF 30, WWDG1RSTF 28, IWDG1RSTF 26,
    /// SFTRSTF 24, PORRSTF 23, PINRSTF 22, BORRSTF 21.
    pub fn from_h7_rsr(rsr: u32) -> Self {
        let bit = |n: u32| rsr & (1 << n) != 0;
        ResetFlags {
            power_on: bit(23),
            brownout: bit(21),
            pin: bit(22),
            software: bit(24),
            independent_watchdog: bit(26),
            window_watchdog: bit(28),
            low_power: bit(30),
        }
    }

    /// Whether RAM contents from before the reset may be read (not after a power-on or brown-out).
    pub fn ram_kept(&self) -> bool {
        !(self.power_on || self.brownout)
    }
}

/// The boot report from the reset flags and, when RAM was kept, the record (`read_record` is only
/// called then). The firmware's own account (a valid record) wins over the flags: it says which
/// panic, fault or silent task it was. On the H7 the reset pin flag is set by every reset (the chip
/// drives its NRST pin), so it counts only when nothing else is set.
pub fn boot_report(flags: ResetFlags, read_record: impl FnOnce() -> Record) -> BootReport {
    let mut message = heapless::String::new();
    let cause = if flags.power_on {
        ResetCause::PowerOn
    } else if flags.brownout {
        ResetCause::Brownout
    } else {
        match decode(&read_record()) {
            Some((c, m)) => {
                message = m;
                c
            }
            None if flags.independent_watchdog || flags.window_watchdog => ResetCause::Watchdog,
            None if flags.software => ResetCause::Software,
            None if flags.pin => ResetCause::Pin,
            None => ResetCause::Unknown,
        }
    };
    BootReport { cause, message }
}

/// The message of a non-maskable interrupt (kept with [`ResetCause::CpuFault`]): on the H743 the
/// HSE clock security system, the one source the firmware could meet.
pub fn nmi_message() -> MessageBuf {
    let mut m = MessageBuf::new();
    let _ = m.write_str("NMI (HSE clock security system?)");
    m
}

/// The message of an exception or interrupt with no handler of its own (kept with
/// [`ResetCause::CpuFault`]): its number as cortex-m-rt gives it (negative: a system exception).
pub fn unhandled_message(irqn: i16) -> MessageBuf {
    let mut m = MessageBuf::new();
    let _ = write!(m, "unhandled exception or interrupt irqn={irqn}");
    m
}

/// The message of a CPU fault: where it happened and the fault status registers.
pub fn cpu_fault_message(pc: u32, lr: u32, cfsr: u32, hfsr: u32, bfar: u32) -> MessageBuf {
    let mut m = MessageBuf::new();
    let _ = write!(
        m,
        "HardFault at pc={pc:#010x} lr={lr:#010x} cfsr={cfsr:#010x} hfsr={hfsr:#010x} bfar={bfar:#010x}"
    );
    m
}

/// The "recovering" marker: kept in the no-init RAM beside the record while the boot recovery reads
/// flash bank 2 (the board sets it, with the offset of every read, before the read; and clears it
/// when the recovery is over). A word of bank 2 whose programming or erase a power cut tore has an
/// inconsistent ECC, and reading it is a bus error: HardFault, reset, and the same read again at
/// the next boot. With the marker the next boot knows which sector the recovery was reading when
/// the chip faulted, erases it unread, and reports the run it held as lost ([`boot_recovery`]):
/// at most one lost sector per fault, never a loop.
pub type Marker = [u32; MARKER_WORDS];
/// Words of a [`Marker`]: magic, the offset in bank 2, its complement.
pub const MARKER_WORDS: usize = 3;
/// No recovery under way.
pub const MARKER_CLEAR: Marker = [0; MARKER_WORDS];
const MARKER_MAGIC: u32 = 0x5245_4356; // "RECV"

/// The marker of a recovery about to read bank 2 at `offset`.
pub fn marker(offset: u32) -> Marker {
    [MARKER_MAGIC, offset, !offset]
}

/// What the boot does before recovering the last run from flash.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BootRecovery {
    /// Recover as usual.
    Recover,
    /// The last boot's recovery faulted reading `sector`: erase it first (unread), then recover
    /// what the others hold; the run that sector held is lost.
    EraseFirst { sector: u32 },
}

/// Decides from the reset flags, the boot report's cause and (only when RAM was kept)
/// the marker whether the last recovery faulted. Only a panic or a CPU fault counts: a reset by
/// the pin or the debugger during a recovery says nothing about the flash. A marker that does not
/// check out (garbage, or a sector outside the bank) is no marker.
pub fn boot_recovery(
    flags: ResetFlags,
    cause: ResetCause,
    read_marker: impl FnOnce() -> Marker,
    sector_bytes: u32,
    sectors: u32,
) -> BootRecovery {
    if !flags.ram_kept() || !matches!(cause, ResetCause::Panic | ResetCause::CpuFault) {
        return BootRecovery::Recover;
    }
    let [magic, offset, check] = read_marker();
    if magic != MARKER_MAGIC || check != !offset || sector_bytes == 0 {
        return BootRecovery::Recover;
    }
    let sector = offset / sector_bytes;
    if sector >= sectors {
        return BootRecovery::Recover;
    }
    BootRecovery::EraseFirst { sector }
}

/// The offset in flash bank 2 (at `base`, `bytes` long) of the data access a CPU fault reports, if
/// the fault is a bus fault with a valid address inside the bank (CFSR.BFARVALID, bit 15): what a
/// double ECC error does on the H7. The HardFault handler sets the marker from it, so that the next
/// boot erases that sector even when the read was not the boot recovery's (a pull, say).
pub fn bank2_fault_offset(cfsr: u32, bfar: u32, base: u32, bytes: u32) -> Option<u32> {
    let offset = bfar.checked_sub(base)?;
    (cfsr & 1 << 15 != 0 && offset < bytes).then_some(offset)
}

/// Says in the boot report that the recovery faulted on `sector`, which was erased with the run it
/// held (the cause stays: the fault or panic that reset the chip).
pub fn note_torn_sector(report: &mut BootReport, sector: u32) {
    let mut m = MessageBuf::new();
    let _ = write!(
        m,
        "recovery faulted reading bank 2 sector {sector}: sector erased, its run lost; "
    );
    let _ = m.write_str(&report.message);
    report.message.clear();
    if let Ok(s) = core::str::from_utf8(m.as_bytes()) {
        let _ = report.message.push_str(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const ALL: [ResetCause; 8] = ResetCause::ALL;

    #[test]
    fn records_round_trip_and_damage_is_refused() {
        for c in ALL {
            let r = encode(c, b"panicked at heater.rs:12: index out of bounds");
            let (c2, m) = decode(&r).unwrap();
            assert_eq!(c2, c);
            assert_eq!(m.as_str(), "panicked at heater.rs:12: index out of bounds");
            for w in 0..RECORD_WORDS {
                let mut bad = r;
                bad[w] ^= 1 << (w % 32);
                assert_eq!(decode(&bad), None, "word {w} flipped");
            }
        }
        assert_eq!(decode(&EMPTY), None);
        // Too long: cut at 120 bytes.
        let long = [b'x'; 200];
        let (_, m) = decode(&encode(ResetCause::Panic, &long)).unwrap();
        assert_eq!(m.len(), BOOT_MESSAGE_LEN);
    }

    #[test]
    fn message_buffer_keeps_whole_characters() {
        let mut m = MessageBuf::new();
        write!(m, "{}", "é".repeat(100)).unwrap();
        assert_eq!(m.as_bytes().len(), 120);
        assert!(core::str::from_utf8(m.as_bytes()).is_ok());
        let mut m = MessageBuf::new();
        write!(m, "a{}", "é".repeat(100)).unwrap();
        assert_eq!(m.as_bytes().len(), 119);
        let f = cpu_fault_message(
            0x0800_1234,
            0xFFFF_FFF9,
            0x0000_8200,
            0x4000_0000,
            0x2004_0000,
        );
        assert_eq!(
            core::str::from_utf8(f.as_bytes()).unwrap(),
            "HardFault at pc=0x08001234 lr=0xfffffff9 cfsr=0x00008200 hfsr=0x40000000 bfar=0x20040000"
        );
        assert_eq!(
            core::str::from_utf8(unhandled_message(i16::MIN).as_bytes()).unwrap(),
            "unhandled exception or interrupt irqn=-32768"
        );
        for (cause, m) in [
            (ResetCause::CpuFault, nmi_message()),
            (ResetCause::CpuFault, unhandled_message(149)),
        ] {
            let (c, back) = decode(&encode(cause, m.as_bytes())).unwrap();
            assert_eq!((c, back.as_bytes()), (cause, m.as_bytes()));
        }
    }

    #[test]
    fn a_recovery_that_faulted_erases_its_sector_once() {
        const SECTOR: u32 = 128 * 1024;
        let kept = ResetFlags::from_h7_rsr(1 << 24 | 1 << 22);
        let por = ResetFlags::from_h7_rsr(1 << 23 | 1 << 22 | 1 << 21);
        let at = |off: u32| move || marker(off);
        // A HardFault while reading sector 5: erase it first.
        assert_eq!(
            boot_recovery(kept, ResetCause::CpuFault, at(5 * SECTOR + 96), SECTOR, 8),
            BootRecovery::EraseFirst { sector: 5 }
        );
        assert_eq!(
            boot_recovery(kept, ResetCause::Panic, at(0), SECTOR, 8),
            BootRecovery::EraseFirst { sector: 0 }
        );
        // The marker cleared after a recovery that ended: recover.
        let clear = || MARKER_CLEAR;
        assert_eq!(
            boot_recovery(kept, ResetCause::CpuFault, clear, SECTOR, 8),
            BootRecovery::Recover
        );
        // After a power-on the RAM is garbage: not even read.
        let never = || -> Marker { panic!("marker read after a power-on") };
        assert_eq!(
            boot_recovery(por, ResetCause::PowerOn, never, SECTOR, 8),
            BootRecovery::Recover
        );
        // A reset by the pin or the watchdog during a recovery: the flash is not to blame.
        for cause in [ResetCause::Pin, ResetCause::Software, ResetCause::Watchdog] {
            assert_eq!(
                boot_recovery(kept, cause, at(SECTOR), SECTOR, 8),
                BootRecovery::Recover
            );
        }
        // Garbage or an offset outside the bank: no marker.
        let mut bad = marker(SECTOR);
        bad[2] ^= 1;
        assert_eq!(
            boot_recovery(kept, ResetCause::CpuFault, || bad, SECTOR, 8),
            BootRecovery::Recover
        );
        assert_eq!(
            boot_recovery(kept, ResetCause::CpuFault, at(8 * SECTOR), SECTOR, 8),
            BootRecovery::Recover
        );
        // The report says which sector went, and keeps what it can of the fault.
        let mut r = BootReport {
            cause: ResetCause::CpuFault,
            message: heapless::String::try_from("HardFault at pc=0x08001234").unwrap(),
        };
        note_torn_sector(&mut r, 5);
        assert_eq!(r.cause, ResetCause::CpuFault);
        assert!(r.message.starts_with(
            "recovery faulted reading bank 2 sector 5: sector erased, its run lost; HardFault"
        ));
    }

    #[test]
    fn a_bus_fault_in_bank_2_names_its_offset() {
        const BASE: u32 = 0x0810_0000;
        const BYTES: u32 = 1 << 20;
        let valid = 1 << 15 | 1 << 9; // BFARVALID, PRECISERR
        assert_eq!(
            bank2_fault_offset(valid, BASE + 0x4_0020, BASE, BYTES),
            Some(0x4_0020)
        );
        assert_eq!(bank2_fault_offset(1 << 9, BASE + 0x20, BASE, BYTES), None);
        assert_eq!(bank2_fault_offset(valid, BASE - 4, BASE, BYTES), None);
        assert_eq!(bank2_fault_offset(valid, BASE + BYTES, BASE, BYTES), None);
        assert_eq!(bank2_fault_offset(valid, 0x2400_0000, BASE, BYTES), None);
    }

    /// The board's loop: a torn word faults every recovery that reads it; with the marker each
    /// boot after a fault erases the sector instead, so the rig comes back after one more boot.
    #[test]
    fn a_torn_word_is_not_a_boot_loop() {
        const SECTOR: u32 = 4096;
        let kept = ResetFlags::from_h7_rsr(1 << 24 | 1 << 22);
        let mut torn = Some(3 * SECTOR + 64); // the offset whose read faults
        let mut ram = MARKER_CLEAR;
        let mut cause = ResetCause::PowerOn;
        let mut flags = ResetFlags::from_h7_rsr(1 << 23);
        let mut boots = 0;
        loop {
            boots += 1;
            assert!(boots < 4, "boot loop");
            if let BootRecovery::EraseFirst { sector } =
                boot_recovery(flags, cause, || ram, SECTOR, 8)
            {
                if torn.is_some_and(|o| o / SECTOR == sector) {
                    torn = None;
                }
            }
            // The recovery reads every sector's first word, then the run.
            let mut faulted = false;
            for off in (0..8 * SECTOR).step_by(32) {
                ram = marker(off);
                if torn == Some(off) {
                    faulted = true;
                    break;
                }
            }
            if !faulted {
                // (the board clears the marker here)
                break;
            }
            (flags, cause) = (kept, ResetCause::CpuFault);
        }
        assert_eq!(boots, 2);
    }

    #[test]
    fn the_cause_from_flags_and_record() {
        let panic = encode(ResetCause::Panic, b"boom");
        let never = || -> Record { panic!("RAM read after a power-on") };
        // Power-on (the H7 sets POR, BOR and PIN together): the record is not even read.
        let por = ResetFlags::from_h7_rsr(1 << 23 | 1 << 22 | 1 << 21);
        assert_eq!(boot_report(por, never).cause, ResetCause::PowerOn);
        let bor = ResetFlags::from_h7_rsr(1 << 22 | 1 << 21);
        assert_eq!(boot_report(bor, never).cause, ResetCause::Brownout);
        // After a panic: software reset + pin, and the record.
        let sw = ResetFlags::from_h7_rsr(1 << 24 | 1 << 22);
        let b = boot_report(sw, || panic);
        assert_eq!((b.cause, b.message.as_str()), (ResetCause::Panic, "boom"));
        // Watchdog with the feeder's note, and without (a core stuck in a loop).
        let iwdg = ResetFlags::from_h7_rsr(1 << 26 | 1 << 22);
        let note = encode(ResetCause::Watchdog, b"watchdog: task app silent for 80 ms");
        assert_eq!(
            boot_report(iwdg, || note).message.as_str(),
            "watchdog: task app silent for 80 ms"
        );
        let b = boot_report(iwdg, || EMPTY);
        assert_eq!((b.cause, b.message.as_str()), (ResetCause::Watchdog, ""));
        assert_eq!(boot_report(sw, || EMPTY).cause, ResetCause::Software);
        let pin = ResetFlags::from_h7_rsr(1 << 22);
        assert_eq!(boot_report(pin, || EMPTY).cause, ResetCause::Pin);
        assert_eq!(
            boot_report(ResetFlags::default(), || EMPTY).cause,
            ResetCause::Unknown
        );
    }

    proptest! {
        #[test]
        fn any_memory_decodes_without_panic(words in prop::array::uniform32(any::<u32>()), extra in any::<u32>()) {
            let mut r = EMPTY;
            r[..32].copy_from_slice(&words);
            r[32] = extra;
            let _ = decode(&r);
            r[0] = MAGIC;
            r[RECORD_WORDS - 1] = crc_of(&r[..RECORD_WORDS - 1]);
            if let Some((_, m)) = decode(&r) {
                prop_assert!(m.len() <= BOOT_MESSAGE_LEN);
            }
        }
    }
}

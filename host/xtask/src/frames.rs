//! The stack frames of the firmware binary, read from its machine code, so that `cargo xtask
//! firmware` can check them against the task stack's guard (`tribo_firmware::stack`): thumbv7em
//! has no stack probes, so a frame larger than the guard could step over it into `.bss`.
//!
//! A function's frame is taken as the sum of every instruction in its body that moves SP down:
//! `push` (16 and 32 bits, and `str rX, [sp, #-4]!`), `vpush`, `sub sp, #imm` (T1, T2/T3 and the
//! 12-bit `subw`) and `sub sp, sp, rX` with `rX` loaded by `movw`/`movt` before it. Summing them all
//! (not only a prologue's) is an upper bound whatever the compiler's shrink-wrapping did. Literal
//! pools are skipped through the ARM mapping symbols (`$d` … `$t`). An SP decrement the reader
//! cannot size (`sub sp, rX` with `rX` not from `movw`) is reported as such, never guessed.

use crate::elf::{self, Symbol};

/// One function's frame.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Frame {
    pub name: String,
    pub addr: u32,
    /// Bytes SP moves down in its body, at most.
    pub bytes: u32,
    /// An SP decrement of unknown size was found.
    pub unknown: bool,
}

/// ThumbExpandImm of the 12-bit `i:imm3:imm8` (ARMv7-M A5.3.2).
fn thumb_expand_imm(imm12: u32) -> u32 {
    let imm8 = imm12 & 0xFF;
    if imm12 >> 10 == 0 {
        match (imm12 >> 8) & 3 {
            0 => imm8,
            1 => imm8 << 16 | imm8,
            2 => imm8 << 24 | imm8 << 8,
            _ => imm8 * 0x0101_0101,
        }
    } else {
        (0x80 | (imm12 & 0x7F)).rotate_right(imm12 >> 7)
    }
}

/// What one instruction does to SP.
#[derive(Debug, PartialEq, Eq)]
enum Effect {
    None,
    Down(u32),
    /// `sub sp, sp, rX`.
    DownBy(usize),
    /// `movw rX, #v` / `movt rX, #v`.
    Movw(usize, u32),
    Movt(usize, u32),
}

/// Decodes the instruction at the start of `code`: its length in bytes and its effect on SP.
fn decode(code: &[u8]) -> (usize, Effect) {
    let h = |i: usize| {
        code.get(i..i + 2)
            .map(|s| u16::from_le_bytes([s[0], s[1]]) as u32)
    };
    let Some(hw1) = h(0) else {
        return (2, Effect::None);
    };
    if !matches!(hw1 >> 11, 0b11101..=0b11111) {
        let e = if hw1 & 0xFE00 == 0xB400 {
            // PUSH T1: register list and LR (M).
            Effect::Down(4 * ((hw1 & 0xFF).count_ones() + (hw1 >> 8 & 1)))
        } else if hw1 & 0xFF80 == 0xB080 {
            // SUB SP, SP, #imm7 × 4 (T1).
            Effect::Down(4 * (hw1 & 0x7F))
        } else {
            Effect::None
        };
        return (2, e);
    }
    let Some(hw2) = h(2) else {
        return (4, Effect::None);
    };
    let e = if hw1 == 0xE92D {
        // PUSH.W (STMDB SP!, list).
        Effect::Down(4 * (hw2 & 0x5FFF).count_ones())
    } else if hw1 == 0xF84D && hw2 & 0x0FFF == 0x0D04 {
        // PUSH.W of one register (STR Rt, [SP, #-4]!).
        Effect::Down(4)
    } else if hw1 & 0xFFBF == 0xED2D && hw2 & 0x0E00 == 0x0A00 {
        // VPUSH (VSTMDB SP!, list): imm8 words.
        Effect::Down(4 * (hw2 & 0xFF))
    } else if hw1 & 0xFBEF == 0xF1AD && hw2 & 0x8F00 == 0x0D00 {
        // SUB{S}.W SP, SP, #const (T2).
        let imm12 = (hw1 >> 10 & 1) << 11 | (hw2 >> 12 & 7) << 8 | (hw2 & 0xFF);
        Effect::Down(thumb_expand_imm(imm12))
    } else if hw1 & 0xFBFF == 0xF2AD && hw2 & 0x8F00 == 0x0D00 {
        // SUBW SP, SP, #imm12 (T3).
        Effect::Down((hw1 >> 10 & 1) << 11 | (hw2 >> 12 & 7) << 8 | (hw2 & 0xFF))
    } else if hw1 & 0xFFEF == 0xEBAD && hw2 & 0x8F00 == 0x0D00 {
        // SUB{S}.W SP, SP, Rm (no shift taken: LLVM emits none here).
        Effect::DownBy((hw2 & 0xF) as usize)
    } else if hw1 & 0xFBF0 == 0xF240 || hw1 & 0xFBF0 == 0xF2C0 {
        // MOVW / MOVT Rd, #imm16.
        let v = (hw1 & 0xF) << 12 | (hw1 >> 10 & 1) << 11 | (hw2 >> 12 & 7) << 8 | (hw2 & 0xFF);
        let rd = (hw2 >> 8 & 0xF) as usize;
        if hw1 & 0xFBF0 == 0xF240 {
            Effect::Movw(rd, v)
        } else {
            Effect::Movt(rd, v)
        }
    } else {
        Effect::None
    };
    (4, e)
}

/// The frame of the code in `code` (one function, data already cut out: `ranges` are the code
/// ranges as offsets into it).
fn frame_of(code: &[u8], ranges: &[(usize, usize)]) -> (u32, bool) {
    let (mut bytes, mut unknown) = (0u32, false);
    for &(start, end) in ranges {
        let mut regs: [Option<u32>; 16] = [None; 16];
        let mut at = start;
        while at + 2 <= end {
            let (len, e) = decode(&code[at..end]);
            match e {
                Effect::None => {}
                Effect::Down(n) => bytes = bytes.saturating_add(n),
                Effect::DownBy(r) => match regs[r] {
                    Some(v) => bytes = bytes.saturating_add(v),
                    None => unknown = true,
                },
                Effect::Movw(r, v) => regs[r] = Some(v),
                Effect::Movt(r, v) => regs[r] = regs[r].map(|lo| (lo & 0xFFFF) | v << 16),
            }
            at += len;
        }
    }
    (bytes, unknown)
}

/// Every function's frame in the ELF `b`, largest first.
pub fn frames(b: &[u8]) -> Result<Vec<Frame>, String> {
    let syms = elf::symbols(b)?;
    // Mapping symbols, by address: where code ($t, $a) and data ($d) start.
    let mut maps: Vec<(u32, bool)> = syms
        .iter()
        .filter_map(|s| {
            let is = |p: &str| s.name == p || s.name.starts_with(&format!("{p}."));
            if is("$d") {
                Some((s.value, false))
            } else if is("$t") || is("$a") {
                Some((s.value & !1, true))
            } else {
                None
            }
        })
        .collect();
    maps.sort();
    if !maps.iter().any(|m| !m.1) && !maps.iter().any(|m| m.1) {
        return Err(
            "the ELF has no ARM mapping symbols ($t, $d): cannot tell code from data".into(),
        );
    }
    let mut out = vec![];
    let funcs = syms
        .iter()
        .filter(|s: &&Symbol| s.kind == 2 && s.size >= 2 && s.value & 1 == 1);
    for f in funcs {
        let addr = f.value & !1;
        let Some(code) = elf::bytes_at(b, addr, f.size) else {
            continue;
        };
        // The code ranges inside the function: split at its mapping symbols (a function starts as
        // code).
        let mut ranges = vec![];
        let mut start = Some(0usize);
        for &(a, is_code) in maps.iter().filter(|m| m.0 > addr && m.0 < addr + f.size) {
            let off = (a - addr) as usize;
            match (start, is_code) {
                (Some(s), false) => {
                    ranges.push((s, off));
                    start = None;
                }
                (None, true) => start = Some(off),
                _ => {}
            }
        }
        if let Some(s) = start {
            ranges.push((s, f.size as usize));
        }
        let (bytes, unknown) = frame_of(code, &ranges);
        out.push(Frame {
            name: f.name.clone(),
            addr,
            bytes,
            unknown,
        });
    }
    out.sort_by(|a, b| b.bytes.cmp(&a.bytes).then(a.addr.cmp(&b.addr)));
    out.dedup_by(|a, b| a.addr == b.addr && a.bytes == b.bytes);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn code(halfwords: &[u16]) -> Vec<u8> {
        halfwords.iter().flat_map(|h| h.to_le_bytes()).collect()
    }

    #[test]
    fn reads_the_sp_decrements_llvm_emits() {
        // push {r4, r5, r6, r7, lr}; sub sp, #8 (what the board's small functions open with).
        let c = code(&[0xB5F0, 0xB082]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (20 + 8, false));
        // push.w {r4-r11, lr}; vpush {d8-d15}; sub.w sp, sp, #6016 (`ad f5 bc 5d` in the binary,
        // the board's main task).
        let c = code(&[0xE92D, 0x4FF0, 0xED2D, 0x8B10, 0xF5AD, 0x5DBC]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (36 + 64 + 6016, false));
        // subw sp, sp, #2652 (`ad f6 5c 2d` in the binary: 0xF6AD 0x2D5C).
        let c = code(&[0xF6AD, 0x2D5C]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (2652, false));
        // subw sp, sp, #1220 (`ad f2 c4 4d`: 0xF2AD 0x4DC4).
        let c = code(&[0xF2AD, 0x4DC4]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (1220, false));
        // movw r12, #0x2010; movt r12, #1; sub.w sp, sp, r12: 0x1_2010 bytes.
        let c = code(&[0xF242, 0x0C10, 0xF2C0, 0x0C01, 0xEBAD, 0x0D0C]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (0x1_2010, false));
        // sub.w sp, sp, r3 with r3 unknown: said, not guessed.
        let c = code(&[0xEBAD, 0x0D03]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (0, true));
        // str lr, [sp, #-4]!; and the epilogue's add sp / pop count nothing.
        let c = code(&[0xF84D, 0xED04, 0xB002, 0xBD00, 0xF85D, 0xFB04]);
        assert_eq!(frame_of(&c, &[(0, c.len())]), (4, false));
        // A literal pool that would read as `push {…}` is skipped.
        let c = code(&[0xB510, 0xB5FF, 0xB5FF, 0xB082]);
        assert_eq!(frame_of(&c, &[(0, 2), (6, 8)]), (8 + 8, false));
    }

    #[test]
    fn thumb_modified_immediates() {
        assert_eq!(thumb_expand_imm(0x0AB), 0xAB);
        assert_eq!(thumb_expand_imm(0x1AB), 0x00AB_00AB);
        assert_eq!(thumb_expand_imm(0x2AB), 0xAB00_AB00);
        assert_eq!(thumb_expand_imm(0x3AB), 0xABAB_ABAB);
        // 6016 = 0xBC << 5: rotation 27 of 0xBC.
        assert_eq!(thumb_expand_imm(27 << 7 | 0x3C), 6016);
    }
}

//! The `MEMORY` regions of `memory.x`, and what the firmware ELF puts in each.

use crate::elf::Section;

/// A region of the chip's memory map.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Region {
    pub name: String,
    pub origin: u64,
    pub length: u64,
}

impl Region {
    pub fn contains(&self, addr: u64) -> bool {
        addr >= self.origin && addr < self.origin + self.length
    }
}

/// Parses `0x2400_0000`, `512K`, `2M`, `1024`.
fn number(s: &str) -> Option<u64> {
    let s = s.trim().replace('_', "");
    let (digits, mult) = match s.chars().last()? {
        'K' | 'k' => (&s[..s.len() - 1], 1024),
        'M' | 'm' => (&s[..s.len() - 1], 1024 * 1024),
        _ => (&s[..], 1),
    };
    let v = match digits
        .strip_prefix("0x")
        .or_else(|| digits.strip_prefix("0X"))
    {
        Some(hex) => u64::from_str_radix(hex, 16).ok()?,
        None => digits.parse().ok()?,
    };
    Some(v * mult)
}

/// The regions of the `MEMORY { … }` block (comments skipped).
pub fn regions(memory_x: &str) -> Result<Vec<Region>, String> {
    // Drop /* … */ comments.
    let mut text = String::new();
    let mut rest = memory_x;
    while let Some(i) = rest.find("/*") {
        text.push_str(&rest[..i]);
        rest = match rest[i..].find("*/") {
            Some(j) => &rest[i + j + 2..],
            None => "",
        };
    }
    text.push_str(rest);
    let start = text.find("MEMORY").ok_or("memory.x has no MEMORY block")?;
    let open = text[start..].find('{').ok_or("MEMORY without {")? + start;
    let close = text[open..].find('}').ok_or("MEMORY without }")? + open;
    let mut out = vec![];
    for line in text[open + 1..close].lines() {
        let line = line.trim();
        if line.is_empty() {
            continue;
        }
        let (name, spec) = line
            .split_once(':')
            .ok_or_else(|| format!("memory.x: cannot read `{line}`"))?;
        let field = |key: &str| -> Result<u64, String> {
            let at = spec
                .find(key)
                .ok_or_else(|| format!("memory.x: `{line}` has no {key}"))?;
            let v = spec[at + key.len()..]
                .trim_start()
                .strip_prefix('=')
                .ok_or_else(|| format!("memory.x: `{line}`: {key} without ="))?;
            let v = v.split(',').next().unwrap_or("");
            number(v).ok_or_else(|| format!("memory.x: `{line}`: bad {key}"))
        };
        out.push(Region {
            name: name.split_whitespace().next().unwrap_or("").to_string(),
            origin: field("ORIGIN")?,
            length: field("LENGTH")?,
        });
    }
    Ok(out)
}

/// Bytes of each region taken by the sections placed there (by address).
pub fn usage(regions: &[Region], sections: &[Section]) -> Vec<u64> {
    regions
        .iter()
        .map(|r| {
            sections
                .iter()
                .filter(|s| s.size > 0 && r.contains(s.addr))
                .map(|s| s.size)
                .sum()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_the_workspace_memory_x() {
        let text = include_str!("../../../memory.x");
        let r = regions(text).unwrap();
        let flash = r.iter().find(|r| r.name == "FLASH").unwrap();
        assert_eq!(
            (flash.origin, flash.length),
            (0x0800_0000, 1024 * 1024),
            "bank 1 only"
        );
        let ram = r.iter().find(|r| r.name == "RAM").unwrap();
        assert_eq!((ram.origin, ram.length), (0x2400_0000, 512 * 1024));
        assert!(r
            .iter()
            .any(|r| r.name == "SRAM1" && r.origin == 0x3000_0000));
    }

    #[test]
    fn numbers_and_usage() {
        assert_eq!(number("0x2400_0000"), Some(0x2400_0000));
        assert_eq!(number("512K"), Some(512 * 1024));
        assert_eq!(number("2M"), Some(2 << 20));
        assert_eq!(number("x"), None);
        let r = regions(
            "MEMORY {\n A : ORIGIN = 0x100, LENGTH = 1K\n B : ORIGIN = 0x1000, LENGTH = 16\n}",
        )
        .unwrap();
        let s = |addr, size| Section {
            name: String::new(),
            addr,
            size,
        };
        assert_eq!(
            usage(&r, &[s(0x100, 10), s(0x4FF, 1), s(0x1000, 3), s(0x2000, 7)]),
            vec![11, 3]
        );
    }
}

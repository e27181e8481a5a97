//! Just enough of ELF32 (little endian) to sum a firmware's sections, so that `cargo xtask firmware`
//! needs no binutils.

#[derive(Debug, Default)]
pub struct Size {
    pub vectors: u64,
    pub text: u64,
    pub rodata: u64,
    pub data: u64,
    pub bss: u64,
    pub uninit: u64,
}

impl Size {
    /// Bytes written to flash: code, constants and the initial values of `.data`.
    pub fn flash(&self) -> u64 {
        self.vectors + self.text + self.rodata + self.data
    }
}

pub fn u16_at(b: &[u8], o: usize) -> Result<u16, String> {
    b.get(o..o + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or_else(|| "truncated ELF".into())
}

pub fn u32_at(b: &[u8], o: usize) -> Result<u32, String> {
    b.get(o..o + 4)
        .map(|s| u32::from_le_bytes([s[0], s[1], s[2], s[3]]))
        .ok_or_else(|| "truncated ELF".into())
}

/// An allocated section: name, address (VMA), size.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Section {
    pub name: String,
    pub addr: u64,
    pub size: u64,
}

/// The allocated sections of the ELF, in header order.
pub fn sections(b: &[u8]) -> Result<Vec<Section>, String> {
    let mut out = vec![];
    for_each_alloc(b, |name, addr, size| {
        out.push(Section {
            name: name.to_string(),
            addr,
            size,
        })
    })?;
    Ok(out)
}

fn for_each_alloc(b: &[u8], mut f: impl FnMut(&str, u64, u64)) -> Result<(), String> {
    if b.get(..4) != Some(b"\x7fELF") || b.get(4) != Some(&1) || b.get(5) != Some(&1) {
        return Err("not a 32-bit little-endian ELF".into());
    }
    let shoff = u32_at(b, 0x20)? as usize;
    let shentsize = u16_at(b, 0x2E)? as usize;
    let shnum = u16_at(b, 0x30)? as usize;
    let shstrndx = u16_at(b, 0x32)? as usize;
    let section = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(b, section(shstrndx) + 0x10)? as usize;
    for i in 0..shnum {
        let s = section(i);
        let name_off = strtab + u32_at(b, s)? as usize;
        let tail = b.get(name_off..).ok_or("bad section name")?;
        let name_end = tail
            .iter()
            .position(|&c| c == 0)
            .ok_or("bad section name")?;
        let name = std::str::from_utf8(&tail[..name_end]).unwrap_or("");
        let flags = u32_at(b, s + 0x08)?;
        let addr = u32_at(b, s + 0x0C)? as u64;
        let sz = u32_at(b, s + 0x14)? as u64;
        const SHF_ALLOC: u32 = 2;
        if flags & SHF_ALLOC != 0 {
            f(name, addr, sz);
        }
    }
    Ok(())
}

/// Flash and static RAM of the ELF by kind of section.
pub fn size(b: &[u8]) -> Result<Size, String> {
    let mut size = Size::default();
    for_each_alloc(b, |name, _, sz| match name {
        ".vector_table" => size.vectors += sz,
        ".text" => size.text += sz,
        ".rodata" => size.rodata += sz,
        ".data" => size.data += sz,
        ".bss" => size.bss += sz,
        ".uninit" => size.uninit += sz,
        n if n.starts_with(".text") => size.text += sz,
        n if n.starts_with(".rodata") || n == ".gnu.sgstubs" => size.rodata += sz,
        n if n.starts_with(".bss")
            || n.starts_with(".axisram")
            || n.starts_with(".sram")
            || n.starts_with(".dtcm") =>
        {
            size.bss += sz
        }
        n if n.starts_with(".data") => size.data += sz,
        _ => {}
    })?;
    Ok(size)
}

/// A symbol of `.symtab`: name, value (a Thumb function's with its low bit), size, type
/// (`st_info & 0xF`: 2 is a function).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Symbol {
    pub name: String,
    pub value: u32,
    pub size: u32,
    pub kind: u8,
}

/// Every symbol of `.symtab` (mapping symbols such as `$t` and `$d` included).
pub fn symbols(b: &[u8]) -> Result<Vec<Symbol>, String> {
    let shoff = u32_at(b, 0x20)? as usize;
    let shentsize = u16_at(b, 0x2E)? as usize;
    let shnum = u16_at(b, 0x30)? as usize;
    let section = |i: usize| shoff + i * shentsize;
    let mut out = vec![];
    for i in 0..shnum {
        let s = section(i);
        const SHT_SYMTAB: u32 = 2;
        if u32_at(b, s + 0x04)? != SHT_SYMTAB {
            continue;
        }
        let (off, size) = (u32_at(b, s + 0x10)? as usize, u32_at(b, s + 0x14)? as usize);
        let strtab = section(u32_at(b, s + 0x18)? as usize);
        let str_off = u32_at(b, strtab + 0x10)? as usize;
        for k in 0..size / 16 {
            let e = off + 16 * k;
            let name_off = str_off + u32_at(b, e)? as usize;
            let tail = b.get(name_off..).ok_or("bad symbol name")?;
            let end = tail.iter().position(|&c| c == 0).ok_or("bad symbol name")?;
            out.push(Symbol {
                name: String::from_utf8_lossy(&tail[..end]).into_owned(),
                value: u32_at(b, e + 4)?,
                size: u32_at(b, e + 8)?,
                kind: *b.get(e + 12).ok_or("truncated ELF")? & 0xF,
            });
        }
    }
    Ok(out)
}

/// The bytes at `[addr, addr + len)` of the allocated section holding them, if it has contents
/// in the file.
pub fn bytes_at(b: &[u8], addr: u32, len: u32) -> Option<&[u8]> {
    let shoff = u32_at(b, 0x20).ok()? as usize;
    let shentsize = u16_at(b, 0x2E).ok()? as usize;
    let shnum = u16_at(b, 0x30).ok()? as usize;
    for i in 0..shnum {
        let s = shoff + i * shentsize;
        const SHT_PROGBITS: u32 = 1;
        if u32_at(b, s + 0x04).ok()? != SHT_PROGBITS {
            continue;
        }
        let (sa, off, size) = (
            u32_at(b, s + 0x0C).ok()?,
            u32_at(b, s + 0x10).ok()?,
            u32_at(b, s + 0x14).ok()?,
        );
        if sa != 0 && addr >= sa && addr.checked_add(len)? <= sa.checked_add(size)? {
            let start = (off + (addr - sa)) as usize;
            return b.get(start..start + len as usize);
        }
    }
    None
}

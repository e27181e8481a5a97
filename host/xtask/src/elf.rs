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

fn u16_at(b: &[u8], o: usize) -> Result<u16, String> {
    b.get(o..o + 2)
        .map(|s| u16::from_le_bytes([s[0], s[1]]))
        .ok_or_else(|| "truncated ELF".into())
}

fn u32_at(b: &[u8], o: usize) -> Result<u32, String> {
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

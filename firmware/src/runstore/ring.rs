//! The RAM ring: the run's most recent records, over several buffers taken as one circle.

use super::LEN_BYTES;

/// Bytes `lo..hi` of the run's stream, over several buffers taken as one circle (stream position
/// `p` lives at offset `p mod cap`).
pub(super) struct Ring<'a> {
    pub(super) segs: heapless::Vec<&'a mut [u8], 4>,
    pub(super) cap: u32,
    pub(super) lo: u32,
    pub(super) hi: u32,
}

impl<'a> Ring<'a> {
    pub(super) fn new(buffers: impl IntoIterator<Item = &'a mut [u8]>) -> Self {
        let mut segs = heapless::Vec::new();
        let mut cap = 0u32;
        for b in buffers {
            let len = b.len().min(u32::MAX as usize / 2) as u32;
            if len > 0 && cap.checked_add(len).is_some_and(|c| c <= u32::MAX / 2) {
                cap += len;
                let _ = segs.push(b);
            }
        }
        Ring {
            segs,
            cap,
            lo: 0,
            hi: 0,
        }
    }

    pub(super) fn reset(&mut self, at: u32) {
        self.lo = at;
        self.hi = at;
    }

    pub(super) fn holds(&self, pos: u32, len: u32) -> bool {
        pos >= self.lo && pos.checked_add(len).is_some_and(|e| e <= self.hi)
    }

    /// Buffer and offset in it of ring offset `off` (< `cap`).
    pub(super) fn locate(&self, off: usize) -> (usize, usize) {
        let mut start = 0;
        for (i, s) in self.segs.iter().enumerate() {
            if off < start + s.len() {
                return (i, off - start);
            }
            start += s.len();
        }
        (0, 0)
    }

    /// Copies `out.len()` bytes from stream position `pos` (the caller checked they are held).
    pub(super) fn read(&self, pos: u32, out: &mut [u8]) {
        if self.cap == 0 {
            return;
        }
        let cap = self.cap as usize;
        let mut off = (pos % self.cap) as usize;
        let mut done = 0;
        while done < out.len() {
            let (s, o) = self.locate(off);
            let seg = &self.segs[s];
            let n = (seg.len() - o).min(out.len() - done);
            out[done..done + n].copy_from_slice(&seg[o..o + n]);
            done += n;
            off = (off + n) % cap;
        }
    }

    /// Appends at `hi` (the caller made room).
    pub(super) fn append(&mut self, bytes: &[u8]) {
        if self.cap == 0 {
            return;
        }
        let cap = self.cap as usize;
        let mut off = (self.hi % self.cap) as usize;
        let mut done = 0;
        while done < bytes.len() {
            let (s, o) = self.locate(off);
            let seg = &mut self.segs[s];
            let n = (seg.len() - o).min(bytes.len() - done);
            seg[o..o + n].copy_from_slice(&bytes[done..done + n]);
            done += n;
            off = (off + n) % cap;
        }
        self.hi += bytes.len() as u32;
    }

    pub(super) fn read_len(&self, pos: u32) -> Option<u32> {
        if !self.holds(pos, LEN_BYTES) {
            return None;
        }
        let mut b = [0u8; 2];
        self.read(pos, &mut b);
        Some(u16::from_le_bytes(b) as u32)
    }
}

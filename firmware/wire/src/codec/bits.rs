//! The bit stream of the Rice format: bits written and read most significant first, refusing to
//! run past the end of the slice.

use super::CodecError;

/// Writes bits most significant first into a byte slice; refuses to overrun it.
pub(super) struct BitWriter<'a> {
    pub(super) out: &'a mut [u8],
    pub(super) pos: usize,
    pub(super) acc: u64,
    pub(super) bits: u32,
}

impl<'a> BitWriter<'a> {
    /// Appends the low `n` (≤ 32) bits of `v`.
    #[inline]
    pub(super) fn put(&mut self, v: u32, n: u32) -> Result<(), CodecError> {
        if n == 0 {
            return Ok(());
        }
        let v = (v as u64) & ((1u64 << n) - 1);
        self.acc = (self.acc << n) | v;
        self.bits += n;
        while self.bits >= 8 {
            self.bits -= 8;
            let byte = (self.acc >> self.bits) as u8;
            *self.out.get_mut(self.pos).ok_or(CodecError::Overflow)? = byte;
            self.pos += 1;
        }
        Ok(())
    }

    /// Pads with zeros to the byte boundary; returns the bytes written.
    pub(super) fn finish(mut self) -> Result<usize, CodecError> {
        if self.bits > 0 {
            let pad = 8 - self.bits;
            self.put(0, pad)?;
        }
        Ok(self.pos)
    }
}

/// Reads bits most significant first.
pub(super) struct BitReader<'a> {
    pub(super) data: &'a [u8],
    pub(super) pos: usize,
    pub(super) acc: u64,
    pub(super) bits: u32,
}

impl<'a> BitReader<'a> {
    pub(super) fn new(data: &'a [u8]) -> Self {
        BitReader {
            data,
            pos: 0,
            acc: 0,
            bits: 0,
        }
    }

    #[inline]
    pub(super) fn get(&mut self, n: u32) -> Result<u32, CodecError> {
        if n == 0 {
            return Ok(0);
        }
        while self.bits < n {
            let b = *self.data.get(self.pos).ok_or(CodecError::Truncated)?;
            self.pos += 1;
            self.acc = (self.acc << 8) | b as u64;
            self.bits += 8;
        }
        self.bits -= n;
        Ok(((self.acc >> self.bits) & ((1u64 << n) - 1)) as u32)
    }

    /// Counts one bits up to a zero, or up to `limit` ones (then no zero is read).
    pub(super) fn unary(&mut self, limit: u32) -> Result<u32, CodecError> {
        let mut q = 0;
        while q < limit {
            if self.get(1)? == 0 {
                return Ok(q);
            }
            q += 1;
        }
        Ok(q)
    }

    /// Checks that only zero padding remains.
    pub(super) fn finish(self) -> Result<(), CodecError> {
        let mask = (1u64 << self.bits) - 1;
        if self.acc & mask != 0 || self.pos != self.data.len() {
            return Err(CodecError::Trailing);
        }
        Ok(())
    }
}

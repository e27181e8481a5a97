//! Framing: `COBS( seq:u32le ‖ postcard(msg) ‖ crc32le(seq ‖ postcard(msg)) ) ‖ 0x00`.
//!
//! The zero byte closes every frame and appears nowhere else, so a receiver that starts in the middle
//! of a stream, or meets garbage, loses at most the frame it is in. The CRC catches what COBS cannot
//! (bit flips, spliced frames); the sequence number lets the host see a lost frame and ask again.

use crate::crc32::{crc32, Crc32};
use core::marker::PhantomData;
use serde::{de::DeserializeOwned, Serialize};

/// Largest postcard body of any message (a full [`crate::SampleBlock`] is about 680 bytes).
pub const MAX_BODY: usize = 1024;
/// Largest frame before stuffing: sequence number, body, CRC.
pub const MAX_RAW: usize = 4 + MAX_BODY + 4;
/// Largest frame on the wire: stuffed, plus the closing zero.
pub const MAX_FRAME: usize = MAX_RAW + MAX_RAW / 254 + 2;

/// A decoded frame.
#[derive(Debug, Clone, PartialEq)]
pub struct Frame<M> {
    pub seq: u32,
    pub msg: M,
}

/// Why a message could not be framed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The message does not fit in [`MAX_BODY`] bytes, or the output buffer is too small.
    TooLarge,
}

/// Why bytes between two zeros were not a frame. The decoder has already dropped them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// More than [`MAX_FRAME`] bytes without a zero: the rest up to the next zero was skipped.
    Overflow,
    /// The COBS stuffing is broken.
    Cobs,
    /// Too short to hold a sequence number and a CRC.
    Short,
    /// The CRC does not match: corrupted in transit.
    Crc,
    /// CRC good but the body is not a message of this protocol (another version?).
    Decode,
}

impl core::fmt::Display for FrameError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FrameError::Overflow => "frame too long (no delimiter): skipped to the next frame",
            FrameError::Cobs => "broken byte stuffing (COBS)",
            FrameError::Short => "frame too short",
            FrameError::Crc => "CRC mismatch: frame corrupted in transit",
            FrameError::Decode => "CRC good but not a message of this protocol version",
        })
    }
}

#[cfg(any(test, feature = "std"))]
impl std::error::Error for FrameError {}

/// COBS-encodes `src` into `dst` (no closing zero). Returns the length written, or `None` when `dst`
/// is too small.
///
/// Block by block, with one copy loop per block that stops at the zero (no per-byte bounds
/// check or block-length test: on the M7 framing a sample block is mostly this loop). The output
/// is the classic encoder's byte for byte, including the `0x01` block that follows a trailing
/// zero or a final full block.
///
/// Hand-written rather than the `cobs` crate: over a full sample-block frame on the M7 this takes
/// 4 800 instructions, `cobs::try_encode` 15 520 (`cargo xtask target-test wire`, figure
/// `wire.cobs_of_that_frame`), and the crate leaves out the closing `0x01` block after a final full
/// block, which would change the bytes on the wire (`tests/pinned.rs`). The crate is the referee in
/// the tests below: it decodes what this encodes, and this decodes what it encodes.
pub fn cobs_encode(src: &[u8], dst: &mut [u8]) -> Option<usize> {
    let mut rest = src;
    let mut out = 0usize;
    loop {
        let chunk = &rest[..rest.len().min(254)];
        let (code, body) = dst.get_mut(out..)?.split_first_mut()?;
        let mut run = 0usize;
        for (d, &b) in body.iter_mut().zip(chunk) {
            if b == 0 {
                break;
            }
            *d = b;
            run += 1;
        }
        let zero = match chunk.get(run) {
            Some(0) => true,
            // `body` ended before the run did: no room
            Some(_) => return None,
            None => false,
        };
        *code = run as u8 + 1;
        out += 1 + run;
        if zero {
            // the zero is implied by the code; a block follows, empty if the data ends here
            rest = &rest[run + 1..];
        } else if run == 254 {
            // 254 non-zero bytes: code 0xFF, no implied zero, another block follows
            rest = &rest[run..];
        } else {
            return Some(out);
        }
    }
}

/// Decodes COBS in place (the input holds no zero byte). Returns the decoded length.
pub fn cobs_decode_in_place(buf: &mut [u8]) -> Option<usize> {
    let (mut read, mut write) = (0usize, 0usize);
    while read < buf.len() {
        let code = buf[read] as usize;
        if code == 0 || read + code > buf.len() {
            return None;
        }
        read += 1;
        for _ in 1..code {
            buf[write] = buf[read];
            write += 1;
            read += 1;
        }
        if code != 0xFF && read < buf.len() {
            buf[write] = 0;
            write += 1;
        }
    }
    Some(write)
}

/// Frames messages. Holds the scratch buffer so that encoding needs no heap and little stack.
pub struct Encoder {
    raw: [u8; MAX_RAW],
}

impl Default for Encoder {
    fn default() -> Self {
        Self::new()
    }
}

impl Encoder {
    pub const fn new() -> Self {
        Encoder { raw: [0; MAX_RAW] }
    }

    /// Frames `msg` with sequence number `seq` into `out`, closing zero included. Returns the bytes
    /// to send. The same as [`Encoder::prepare`] then [`Encoder::stuff`].
    pub fn encode<'o, M: Serialize>(
        &mut self,
        seq: u32,
        msg: &M,
        out: &'o mut [u8],
    ) -> Result<&'o [u8], EncodeError> {
        let raw = self.prepare(seq, msg)?;
        self.stuff(raw, out)
    }

    /// The first part of framing: `seq`, the postcard body and the CRC, in this encoder's buffer.
    /// Returns their length, for [`Encoder::stuff`]. The same as [`Encoder::serialise`] then
    /// [`Encoder::seal`]. (The parts let a caller with a time budget, the firmware's millisecond
    /// poll, spread a frame over several calls.)
    pub fn prepare<M: Serialize>(&mut self, seq: u32, msg: &M) -> Result<usize, EncodeError> {
        let n = self.serialise(seq, msg)?;
        self.seal(n)
    }

    /// `seq` and the postcard body in this encoder's buffer; returns their length, for
    /// [`Encoder::seal`].
    pub fn serialise<M: Serialize>(&mut self, seq: u32, msg: &M) -> Result<usize, EncodeError> {
        self.raw[..4].copy_from_slice(&seq.to_le_bytes());
        let body = postcard::to_slice(msg, &mut self.raw[4..4 + MAX_BODY])
            .map_err(|_| EncodeError::TooLarge)?
            .len();
        Ok(4 + body)
    }

    /// Appends the CRC of the `len` bytes [`Encoder::serialise`] left; returns the new length, for
    /// [`Encoder::stuff`].
    pub fn seal(&mut self, len: usize) -> Result<usize, EncodeError> {
        let data = self.raw.get(..len).ok_or(EncodeError::TooLarge)?;
        let crc = crc32(data);
        self.raw
            .get_mut(len..len + 4)
            .ok_or(EncodeError::TooLarge)?
            .copy_from_slice(&crc.to_le_bytes());
        Ok(len + 4)
    }

    /// The second half: byte-stuffs the `raw_len` bytes [`Encoder::prepare`] left into `out`, closing
    /// zero included. Returns the bytes to send.
    pub fn stuff<'o>(&self, raw_len: usize, out: &'o mut [u8]) -> Result<&'o [u8], EncodeError> {
        let raw = self.raw.get(..raw_len).ok_or(EncodeError::TooLarge)?;
        let n = cobs_encode(raw, out).ok_or(EncodeError::TooLarge)?;
        *out.get_mut(n).ok_or(EncodeError::TooLarge)? = 0;
        Ok(&out[..=n])
    }
}

/// Frames one message into a new vector (host convenience).
#[cfg(any(test, feature = "std"))]
pub fn encode_vec<M: Serialize>(seq: u32, msg: &M) -> Result<Vec<u8>, EncodeError> {
    let mut enc = Box::new(Encoder::new());
    let mut out = vec![0u8; MAX_FRAME];
    let n = enc.encode(seq, msg, &mut out)?.len();
    out.truncate(n);
    Ok(out)
}

/// Turns a byte stream back into frames of `M`, one byte at a time, with a fixed buffer.
///
/// Never panics, whatever the bytes: garbage, truncated frames and flipped bits each give one
/// [`FrameError`], and the next frame after a zero byte decodes normally.
pub struct Decoder<M> {
    buf: [u8; MAX_FRAME],
    len: usize,
    overflowed: bool,
    _msg: PhantomData<fn() -> M>,
}

impl<M: DeserializeOwned> Default for Decoder<M> {
    fn default() -> Self {
        Self::new()
    }
}

impl<M: DeserializeOwned> Decoder<M> {
    pub const fn new() -> Self {
        Decoder {
            buf: [0; MAX_FRAME],
            len: 0,
            overflowed: false,
            _msg: PhantomData,
        }
    }

    /// Bytes of an unfinished frame held so far.
    pub fn pending(&self) -> usize {
        self.len
    }

    /// Forgets any partial frame (e.g. after the link was reopened).
    pub fn reset(&mut self) {
        self.len = 0;
        self.overflowed = false;
    }

    /// Feeds one byte. Returns a frame or an error when `byte` closes one; `None` otherwise (including
    /// for empty frames, i.e. repeated zeros, which senders may use to flush a receiver).
    pub fn push(&mut self, byte: u8) -> Option<Result<Frame<M>, FrameError>> {
        if byte != 0 {
            if self.len < self.buf.len() {
                self.buf[self.len] = byte;
                self.len += 1;
            } else {
                self.overflowed = true;
            }
            return None;
        }
        let (len, overflowed) = (self.len, self.overflowed);
        self.reset();
        if overflowed {
            return Some(Err(FrameError::Overflow));
        }
        if len == 0 {
            return None;
        }
        Some(decode_stuffed(&mut self.buf[..len]))
    }

    /// Feeds a slice, calling `on_frame` for each frame or error it completes.
    pub fn feed(&mut self, bytes: &[u8], mut on_frame: impl FnMut(Result<Frame<M>, FrameError>)) {
        for &b in bytes {
            if let Some(r) = self.push(b) {
                on_frame(r);
            }
        }
    }
}

fn decode_stuffed<M: DeserializeOwned>(stuffed: &mut [u8]) -> Result<Frame<M>, FrameError> {
    let n = cobs_decode_in_place(stuffed).ok_or(FrameError::Cobs)?;
    let raw = &stuffed[..n];
    if raw.len() < 8 {
        return Err(FrameError::Short);
    }
    let (data, crc) = raw.split_at(raw.len() - 4);
    let mut c = Crc32::new();
    c.update(data);
    if c.finish().to_le_bytes() != crc {
        return Err(FrameError::Crc);
    }
    let seq = u32::from_le_bytes([data[0], data[1], data[2], data[3]]);
    match postcard::take_from_bytes::<M>(&data[4..]) {
        Ok((msg, [])) => Ok(Frame { seq, msg }),
        _ => Err(FrameError::Decode),
    }
}

/// Decodes one complete frame held in a slice (closing zero optional).
pub fn decode_one<M: DeserializeOwned>(frame: &[u8]) -> Result<Frame<M>, FrameError> {
    let frame = frame.strip_suffix(&[0]).unwrap_or(frame);
    if frame.len() > MAX_FRAME {
        return Err(FrameError::Overflow);
    }
    if frame.contains(&0) {
        return Err(FrameError::Cobs);
    }
    let mut buf = [0u8; MAX_FRAME];
    buf[..frame.len()].copy_from_slice(frame);
    decode_stuffed(&mut buf[..frame.len()])
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// The byte-at-a-time encoder this crate used first: the reference for the block encoder.
    fn reference(src: &[u8], dst: &mut [u8]) -> Option<usize> {
        let mut code_at = 0usize;
        let mut out = 1usize;
        let mut code = 1u8;
        *dst.get_mut(code_at)? = 0;
        for &b in src {
            if b == 0 {
                *dst.get_mut(code_at)? = code;
                code_at = out;
                *dst.get_mut(code_at)? = 0;
                out += 1;
                code = 1;
            } else {
                *dst.get_mut(out)? = b;
                out += 1;
                code += 1;
                if code == 0xFF {
                    *dst.get_mut(code_at)? = code;
                    code_at = out;
                    *dst.get_mut(code_at)? = 0;
                    out += 1;
                    code = 1;
                }
            }
        }
        *dst.get_mut(code_at)? = code;
        Some(out)
    }

    fn same_as_reference(data: &[u8]) {
        let mut a = vec![0u8; data.len() + data.len() / 254 + 2];
        let mut b = a.clone();
        let n = cobs_encode(data, &mut a);
        assert_eq!(n, reference(data, &mut b), "{data:?}");
        let n = n.unwrap();
        assert_eq!(a[..n], b[..n]);
        // one byte short: both refuse
        if n > 0 {
            assert_eq!(cobs_encode(data, &mut a[..n - 1]), None);
        }
    }

    #[test]
    fn block_encoder_equals_the_reference_at_the_block_boundaries() {
        for len in [0usize, 1, 2, 253, 254, 255, 256, 507, 508, 509, 1000] {
            for zero_at in [None, Some(0), Some(len / 2), Some(len.saturating_sub(1))] {
                let mut d: Vec<u8> = (0..len).map(|i| (i % 255) as u8 + 1).collect();
                if let Some(z) = zero_at.filter(|&z| z < len) {
                    d[z] = 0;
                }
                same_as_reference(&d);
            }
        }
        same_as_reference(&[0; 300]);
    }

    proptest! {
        #[test]
        fn block_encoder_equals_the_reference(
            data in proptest::collection::vec(prop_oneof![Just(0u8), any::<u8>(), 1u8..], 0..1200)
        ) {
            same_as_reference(&data);
        }

        /// Interoperability with the `cobs` crate, both ways: its decoder reads our stuffing, ours
        /// reads its, and the two stuffings differ only by the empty block the crate leaves out
        /// after a final full block (or an empty input).
        #[test]
        fn the_cobs_crate_agrees(
            data in proptest::collection::vec(prop_oneof![Just(0u8), any::<u8>(), 1u8..], 1..1200)
        ) {
            let room = data.len() + data.len() / 254 + 2;
            let (mut ours, mut theirs) = (vec![0u8; room], vec![0u8; room]);
            let n = cobs_encode(&data, &mut ours).unwrap();
            let m = cobs::try_encode(&data, &mut theirs).unwrap();
            if n == m + 1 {
                prop_assert_eq!(ours[m], 0x01);
            } else {
                prop_assert_eq!(n, m);
            }
            prop_assert_eq!(&ours[..m], &theirs[..m]);
            let mut back = ours[..n].to_vec();
            let k = cobs::decode_in_place(&mut back).unwrap();
            prop_assert_eq!(&back[..k], &data[..]);
            let mut back = theirs[..m].to_vec();
            let k = cobs_decode_in_place(&mut back).unwrap();
            prop_assert_eq!(&back[..k], &data[..]);
        }
    }

    #[test]
    fn the_cobs_crate_leaves_out_the_block_after_a_full_one() {
        // The reason the hand-written encoder stays: 254 non-zero bytes end in a full block.
        let data = [7u8; 254];
        let (mut ours, mut theirs) = ([0u8; 300], [0u8; 300]);
        let n = cobs_encode(&data, &mut ours).unwrap();
        let m = cobs::try_encode(&data, &mut theirs).unwrap();
        assert_eq!((n, m), (256, 255));
        assert_eq!(ours[255], 0x01);
    }
}

//! The USB sender's two rules, as plain logic the board's sender task follows (tested here on the
//! host): what to send again after the cable was pulled, and when a zero-length packet ends a
//! transfer.
//!
//! **Resend.** The application hands whole frames to a byte queue and counts them as sent; the
//! sender takes bytes from the queue and sends them in packets of at most 64 bytes. A packet counts
//! as delivered when the USB stack says the host took it. [`TxResend`] holds what the sender took
//! from the queue, from the start of the first frame not yet wholly delivered: when the link goes
//! down (a cable pull shows as a suspend, or a bus reset) and comes back, sending starts again from
//! that frame's first byte, preceded by a frame delimiter (`0x00`) when some of its bytes already
//! went out, so that a host still holding those bytes closes them as one bad frame (which the host
//! drops) rather than splicing them onto the resent one. Frames wholly delivered are never sent
//! twice; the bytes still in the queue are not touched (they are sent after). So a pull loses
//! nothing the host cannot have had: the first frame it may lack is the one sent again.
//!
//! **Zero-length packet.** A bulk transfer ends with a packet shorter than the endpoint's maximum.
//! When the bytes to send end exactly on a packet boundary (the last packet was full) and nothing
//! more is ready, the sender adds a zero-length packet ([`zlp_after`]), or the host would wait for
//! the next frame before handing over this one.

use crate::wire::frame::MAX_FRAME;

/// Largest packet of the full-speed bulk IN endpoint.
pub const PACKET: usize = 64;
/// Bytes [`TxResend`] holds: the longest frame and one packet more (a packet taken from the queue
/// may hold the end of one frame and the start of the next).
pub const HELD: usize = MAX_FRAME + PACKET;

/// What the sender took from the queue and may have to send again (see the module docs).
pub struct TxResend<const N: usize = HELD> {
    buf: [u8; N],
    /// Bytes held (`buf[..len]`): from the start of the first frame not wholly delivered.
    len: usize,
    /// Of them, delivered.
    sent: usize,
    /// A delimiter goes out before the next held byte.
    delimit: bool,
}

impl<const N: usize> Default for TxResend<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> TxResend<N> {
    pub const fn new() -> Self {
        TxResend {
            buf: [0; N],
            len: 0,
            sent: 0,
            delimit: false,
        }
    }

    /// Bytes that can be taken from the queue now.
    pub fn room(&self) -> usize {
        N - self.len
    }

    /// Something is held that was not delivered (or a delimiter is due): send it before taking
    /// more from the queue.
    pub fn pending(&self) -> bool {
        self.delimit || self.sent < self.len
    }

    /// Bytes taken from the queue; returns how many were kept (at most [`TxResend::room`]).
    pub fn take(&mut self, bytes: &[u8]) -> usize {
        let n = bytes.len().min(self.room());
        self.buf[self.len..self.len + n].copy_from_slice(&bytes[..n]);
        self.len += n;
        n
    }

    /// Fills `out` with the next packet (at most `out.len()` bytes) and returns its length; 0 when
    /// nothing is pending.
    pub fn next_packet(&self, out: &mut [u8]) -> usize {
        let mut i = 0;
        if self.delimit && !out.is_empty() {
            out[0] = 0;
            i = 1;
        }
        let n = (self.len - self.sent).min(out.len() - i);
        out[i..i + n].copy_from_slice(&self.buf[self.sent..self.sent + n]);
        i + n
    }

    /// The packet of `n` bytes that [`TxResend::next_packet`] made was delivered: the frames it
    /// completed are forgotten.
    pub fn delivered(&mut self, mut n: usize) {
        if self.delimit && n > 0 {
            self.delimit = false;
            n -= 1;
        }
        self.sent = (self.sent + n).min(self.len);
        match self.buf[..self.sent].iter().rposition(|&b| b == 0) {
            Some(end) => self.drop_front(end + 1),
            // A frame longer than the buffer (never made by the application): what was delivered
            // of it cannot be sent again; keep going with the rest.
            None if self.sent == N => self.drop_front(N),
            None => {}
        }
    }

    /// The link came back (or a new host connected): what is held goes again from its start.
    pub fn reconnected(&mut self) {
        if self.sent > 0 {
            self.delimit = true;
        }
        self.sent = 0;
    }

    fn drop_front(&mut self, k: usize) {
        self.buf.copy_within(k..self.len, 0);
        self.len -= k;
        self.sent -= k;
    }
}

/// Whether a zero-length packet must follow a packet of `len` bytes on an endpoint of `max_packet`
/// bytes: the transfer ended on a packet boundary and nothing more is `ready` to send at once.
pub fn zlp_after(len: usize, max_packet: usize, ready: bool) -> bool {
    len == max_packet && !ready
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A frame of `len` bytes: `len - 1` non-zero bytes and the delimiter.
    fn frame(tag: u8, len: usize) -> Vec<u8> {
        let mut f = vec![tag; len - 1];
        f.push(0);
        f
    }

    /// Sends until nothing is pending or `packets` packets went out; returns what went out.
    fn send<const N: usize>(t: &mut TxResend<N>, queue: &mut Vec<u8>, packets: usize) -> Vec<u8> {
        let mut wire = vec![];
        let mut pkt = [0u8; PACKET];
        for _ in 0..packets {
            if !t.pending() {
                let n = queue.len().min(t.room()).min(PACKET);
                if n == 0 {
                    break;
                }
                let taken: Vec<u8> = queue.drain(..n).collect();
                assert_eq!(t.take(&taken), n);
            }
            let n = t.next_packet(&mut pkt);
            wire.extend_from_slice(&pkt[..n]);
            t.delivered(n);
        }
        wire
    }

    /// The frames a host decodes from `bytes` (non-empty runs closed by a zero).
    fn frames(bytes: &[u8]) -> Vec<Vec<u8>> {
        bytes
            .split_inclusive(|&b| b == 0)
            .filter(|f| f.len() > 1 && f.ends_with(&[0]))
            .map(|f| f.to_vec())
            .collect()
    }

    #[test]
    fn a_link_that_stays_up_sends_every_byte_once() {
        let sent: Vec<u8> = [frame(1, 100), frame(2, 64), frame(3, 1100), frame(4, 5)].concat();
        let mut q = sent.clone();
        let mut t = TxResend::<HELD>::new();
        let wire = send(&mut t, &mut q, 1000);
        assert_eq!(wire, sent);
        assert!(!t.pending());
        assert_eq!(t.room(), HELD);
    }

    #[test]
    fn a_pull_mid_frame_resends_that_frame_whole_after_a_delimiter() {
        let (a, b, c) = (frame(1, 100), frame(2, 300), frame(3, 40));
        let mut q = [a.clone(), b.clone(), c.clone()].concat();
        let mut t = TxResend::<HELD>::new();
        // Two packets delivered (all of frame a, 28 bytes of b), then the cable is pulled: the
        // third packet was not acknowledged.
        let old_host = send(&mut t, &mut q, 2);
        assert_eq!(frames(&old_host), vec![a.clone()]);
        let taken: Vec<u8> = q.drain(..PACKET).collect();
        t.take(&taken);
        let mut pkt = [0u8; PACKET];
        let n = t.next_packet(&mut pkt);
        assert_eq!(n, PACKET, "a packet in flight when the link went down");
        // (not delivered)
        t.reconnected();
        let new_host = send(&mut t, &mut q, 1000);
        assert_eq!(
            new_host[0], 0,
            "a delimiter closes the part of b the host may hold"
        );
        assert_eq!(frames(&new_host), vec![b.clone(), c.clone()]);
        // Had the same host stayed (a suspend, then a resume), it decodes every frame once: the
        // bytes of b it had and the delimiter are one bad frame, dropped.
        let all = [old_host, new_host].concat();
        let good: Vec<_> = frames(&all)
            .into_iter()
            .filter(|f| [&a, &b, &c].contains(&f))
            .collect();
        assert_eq!(good, vec![a, b, c]);
    }

    #[test]
    fn a_pull_between_frames_sends_nothing_twice() {
        let (a, b) = (frame(1, 64), frame(2, 10));
        let mut q = [a.clone(), b.clone()].concat();
        let mut t = TxResend::<HELD>::new();
        let first = send(&mut t, &mut q, 1);
        assert_eq!(first, a);
        assert!(!t.pending());
        t.reconnected();
        let rest = send(&mut t, &mut q, 1000);
        assert_eq!(rest, b, "no delimiter, no repeat: a was delivered whole");
    }

    #[test]
    fn repeated_pulls_never_lose_the_frame() {
        let b = frame(7, 500);
        let mut q = b.clone();
        let mut t = TxResend::<HELD>::new();
        for _ in 0..5 {
            send(&mut t, &mut q, 3);
            t.reconnected();
        }
        let last = send(&mut t, &mut q, 1000);
        assert_eq!(frames(&last), vec![b]);
    }

    #[test]
    fn an_oversized_frame_does_not_block_the_sender() {
        // Never made by the application, but the sender must not stall on it.
        let big = frame(9, 300);
        let small = frame(3, 10);
        let mut q = [big, small.clone()].concat();
        let mut t = TxResend::<128>::new();
        let wire = send(&mut t, &mut q, 1000);
        assert_eq!(wire.len(), 310);
        assert!(wire.ends_with(&small));
        assert!(!t.pending());
    }

    #[test]
    fn zero_length_packet_only_after_a_full_last_packet() {
        assert!(zlp_after(64, 64, false));
        assert!(
            !zlp_after(64, 64, true),
            "more follows: the transfer goes on"
        );
        assert!(
            !zlp_after(63, 64, false),
            "a short packet ends the transfer itself"
        );
        assert!(!zlp_after(0, 64, false));
        // A frame of exactly 128 bytes ends on a boundary: a ZLP after its second packet.
        let mut q = frame(5, 128);
        let mut t = TxResend::<HELD>::new();
        let mut pkt = [0u8; PACKET];
        let mut zlps = 0;
        while t.pending() || !q.is_empty() {
            if !t.pending() {
                let n = q.len().min(PACKET);
                let taken: Vec<u8> = q.drain(..n).collect();
                t.take(&taken);
            }
            let n = t.next_packet(&mut pkt);
            t.delivered(n);
            if zlp_after(n, PACKET, t.pending() || !q.is_empty()) {
                zlps += 1;
            }
        }
        assert_eq!(zlps, 1);
    }
}

//! The USB sender's rules, as plain logic the board's sender task follows (tested here on the
//! host): when the link is up ([`BusState`]), what to send again after the cable was pulled, and
//! when a zero-length packet ends a transfer.
//!
//! **Link state.** embassy-usb tells the device's handler of power (`enabled`), bus resets,
//! suspends and resumes, and (un)configuration; [`BusState`] folds them into "the link is up, in
//! session n". A bus reset ends a suspend (embassy-usb calls `reset()` and never
//! `suspended(false)` then), so a suspend during the host's first debounce, or a pull and re-plug,
//! does not leave the link down for good.
//!
//! **Resend.** The application hands whole frames to a byte queue and counts them as sent; the
//! sender takes bytes from the queue and sends them in packets of at most 64 bytes. A packet counts
//! as delivered when the host is known to have acknowledged it: the endpoint's write returns once
//! the packet is in the FIFO, but the OTG core takes the next packet (a zero-length one included)
//! only once the previous transfer completed, so a packet is delivered when the next write
//! returns; an idle sender writes a zero-length packet to learn it. [`TxResend`] holds what the sender took
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
    /// Of them, acknowledged by the host (`sent <= written <= len`).
    sent: usize,
    /// Of them, written to the endpoint: `written - sent` are the held bytes of the one packet in
    /// flight (in the FIFO, or on the wire, not yet acknowledged).
    written: usize,
    /// A delimiter goes out before the next held byte.
    delimit: bool,
    /// The packet in flight starts with a delimiter.
    delimit_in_flight: bool,
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
            written: 0,
            delimit: false,
            delimit_in_flight: false,
        }
    }

    /// Bytes that can be taken from the queue now.
    pub fn room(&self) -> usize {
        N - self.len
    }

    /// Something is held that was not written (or a delimiter is due): send it before taking
    /// more from the queue.
    pub fn pending(&self) -> bool {
        self.delimit || self.written < self.len
    }

    /// A packet was written and the host has not yet been seen to take it: when nothing else is
    /// to be sent, the sender writes a zero-length packet to learn that it did
    /// ([`TxResend::acknowledged`]).
    pub fn unacknowledged(&self) -> bool {
        self.delimit_in_flight || self.sent < self.written
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
        let n = (self.len - self.written).min(out.len() - i);
        out[i..i + n].copy_from_slice(&self.buf[self.written..self.written + n]);
        i + n
    }

    /// The write of the packet of `n` bytes that [`TxResend::next_packet`] made returned. That
    /// does not mean the host has it: the endpoint's write returns once the packet is in the
    /// FIFO. It does mean that the host took the packet written before it: the OTG core takes a
    /// new IN packet only once the previous transfer completed, i.e. the host acknowledged it. So
    /// the previous packet counts as delivered now, and this one is in flight.
    pub fn wrote(&mut self, mut n: usize) {
        self.acknowledged();
        if self.delimit && n > 0 {
            self.delimit = false;
            self.delimit_in_flight = true;
            n -= 1;
        }
        self.written = (self.written + n).min(self.len);
    }

    /// The packet in flight was acknowledged (a later write, a zero-length one included,
    /// returned): the frames it completed are forgotten.
    pub fn acknowledged(&mut self) {
        self.sent = self.written;
        self.delimit_in_flight = false;
        match self.buf[..self.sent].iter().rposition(|&b| b == 0) {
            Some(end) => self.drop_front(end + 1),
            // A frame longer than the buffer (never made by the application): what was delivered
            // of it cannot be sent again; keep going with the rest.
            None if self.sent == N => self.drop_front(N),
            None => {}
        }
    }

    /// The link came back (or a new host connected): what is held goes again from its start,
    /// the packet that was in flight included (the host may never have had it). A delimiter
    /// goes first when some held bytes may have reached the host, or when a delimiter that was
    /// due or in flight may not have.
    pub fn reconnected(&mut self) {
        if self.written > 0 || self.delimit_in_flight {
            self.delimit = true;
        }
        self.delimit_in_flight = false;
        self.sent = 0;
        self.written = 0;
    }

    fn drop_front(&mut self, k: usize) {
        self.buf.copy_within(k..self.len, 0);
        self.len -= k;
        self.sent -= k;
        self.written -= k;
    }
}

/// Whether a zero-length packet must follow a packet of `len` bytes on an endpoint of `max_packet`
/// bytes: the transfer ended on a packet boundary and nothing more is `ready` to send at once.
pub fn zlp_after(len: usize, max_packet: usize, ready: bool) -> bool {
    len == max_packet && !ready
}

/// What the device's handler was told, in the order embassy-usb tells it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BusEvent {
    /// `Handler::enabled`: VBUS came (the peripheral is enabled) or went. The board senses VBUS
    /// (PA9): power comes with the OTG core's session request, goes with its session end (a
    /// pull). With VBUS sensing off the driver reports power once, at start, and never its loss.
    Enabled(bool),
    /// `Handler::reset`: a bus reset (a new enumeration starts; the device is unconfigured and
    /// no longer suspended).
    Reset,
    /// `Handler::suspended`: the bus was idle for 3 ms (a pulled cable with VBUS sensing off, a
    /// sleeping host, or the host's debounce before its first reset), or resumed.
    Suspended(bool),
    /// `Handler::configured`: the host set (or cleared) the configuration.
    Configured(bool),
}

/// The device's bus state as the sender needs it (see the module docs).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct BusState {
    powered: bool,
    suspended: bool,
    configured: bool,
    /// Times the link went down (wraps): a sender that saw session n up and later sees another
    /// number knows the link went down in between, though it is up again.
    downs: u32,
}

impl Default for BusState {
    fn default() -> Self {
        Self::new()
    }
}

impl BusState {
    /// Before the driver has reported power: down.
    pub const fn new() -> Self {
        BusState {
            powered: false,
            suspended: false,
            configured: false,
            downs: 0,
        }
    }

    /// Applies one event.
    pub fn on(&mut self, event: BusEvent) {
        let was_up = self.up();
        match event {
            BusEvent::Enabled(on) => {
                self.powered = on;
                self.suspended = false;
                self.configured = false;
            }
            BusEvent::Reset => {
                self.suspended = false;
                self.configured = false;
            }
            BusEvent::Suspended(s) => self.suspended = s,
            BusEvent::Configured(c) => self.configured = c,
        }
        if was_up && !self.up() {
            self.downs = self.downs.wrapping_add(1);
        }
    }

    /// The link is up: powered, configured and not suspended.
    pub fn up(&self) -> bool {
        self.powered && self.configured && !self.suspended
    }

    /// The current session while the link is up: equal for two calls only if the link did not
    /// go down in between.
    pub fn session(&self) -> Option<u32> {
        self.up().then_some(self.downs)
    }
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

    /// Sends until nothing is pending or `packets` packets went out, the host taking every packet;
    /// returns what went out. Like the board's sender, when nothing more can be taken it writes a
    /// zero-length packet, whose return acknowledges the last packet.
    fn send<const N: usize>(t: &mut TxResend<N>, queue: &mut Vec<u8>, packets: usize) -> Vec<u8> {
        let mut wire = vec![];
        let mut pkt = [0u8; PACKET];
        for _ in 0..packets {
            if !t.pending() {
                if t.unacknowledged() && (queue.is_empty() || t.room() == 0) {
                    t.acknowledged();
                }
                let n = queue.len().min(t.room()).min(PACKET);
                if n == 0 {
                    break;
                }
                let taken: Vec<u8> = queue.drain(..n).collect();
                assert_eq!(t.take(&taken), n);
            }
            let n = t.next_packet(&mut pkt);
            wire.extend_from_slice(&pkt[..n]);
            t.wrote(n);
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
        // Three packets written: the third's write returning acknowledged the second (so all of
        // frame a and 28 bytes of b are delivered); the third (64 more bytes of b) is in flight
        // when the cable is pulled.
        let old_host = send(&mut t, &mut q, 3);
        assert_eq!(old_host.len(), 3 * PACKET);
        assert_eq!(frames(&old_host), vec![a.clone()]);
        assert!(
            t.unacknowledged(),
            "a packet in flight when the link went down"
        );
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
        assert!(t.unacknowledged());
        // The zero-length packet after the full packet returned: the host took `a`.
        t.acknowledged();
        t.reconnected();
        let rest = send(&mut t, &mut q, 1000);
        assert_eq!(rest, b, "no delimiter, no repeat: a was delivered whole");
    }

    #[test]
    fn the_last_packet_in_the_fifo_at_a_pull_is_sent_again() {
        // The endpoint's write returned (the packet is in the FIFO), the queue is empty, and the
        // cable is pulled before the zero-length packet that would prove the host took it.
        let a = frame(4, 30);
        let mut t = TxResend::<HELD>::new();
        t.take(&a);
        let mut pkt = [0u8; PACKET];
        let n = t.next_packet(&mut pkt);
        t.wrote(n);
        assert!(!t.pending());
        assert!(
            t.unacknowledged(),
            "a write that returned is not an acknowledgement"
        );
        t.reconnected();
        let mut q = vec![];
        let again = send(&mut t, &mut q, 1000);
        assert_eq!(
            again[0], 0,
            "a delimiter first: the host may hold some of a"
        );
        assert_eq!(frames(&again), vec![a.clone()]);
        assert!(!t.unacknowledged());
        assert_eq!(t.room(), HELD, "acknowledged, then forgotten");

        // The same, but the zero-length packet's write returned before the pull: nothing goes
        // again.
        let mut t = TxResend::<HELD>::new();
        t.take(&a);
        let n = t.next_packet(&mut pkt);
        t.wrote(n);
        t.acknowledged();
        t.reconnected();
        assert!(!t.pending());
        assert_eq!(send(&mut t, &mut vec![], 1000), Vec::<u8>::new());
    }

    #[test]
    fn a_delimiter_lost_in_flight_is_sent_again() {
        let b = frame(2, 200);
        let mut q = b.clone();
        let mut t = TxResend::<HELD>::new();
        send(&mut t, &mut q, 2);
        t.reconnected();
        // The packet with the delimiter is written, then the link drops again before the host is
        // seen to take it: after the next reconnection the delimiter still goes first.
        let mut pkt = [0u8; PACKET];
        let n = t.next_packet(&mut pkt);
        assert_eq!(pkt[0], 0);
        t.wrote(n);
        t.reconnected();
        let n = t.next_packet(&mut pkt);
        assert_eq!((pkt[0], pkt[1]), (0, 2));
        t.wrote(n);
        let rest = send(&mut t, &mut q, 1000);
        let all = [&pkt[..n], &rest[..]].concat();
        assert_eq!(frames(&all), vec![b]);
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
            t.wrote(n);
            if zlp_after(n, PACKET, t.pending() || !q.is_empty()) {
                zlps += 1;
            }
        }
        assert_eq!(zlps, 1);
    }

    // --- The link state against the events embassy-usb 0.6 gives the handler ---------------

    use BusEvent::*;

    fn after(events: &[BusEvent]) -> BusState {
        let mut s = BusState::new();
        for &e in events {
            s.on(e);
        }
        s
    }

    #[test]
    fn enumeration_brings_the_link_up() {
        assert!(!after(&[]).up(), "down before the driver reports power");
        assert!(!after(&[Enabled(true)]).up());
        assert!(!after(&[Enabled(true), Reset]).up(), "not configured yet");
        assert!(after(&[Enabled(true), Reset, Configured(true)]).up());
    }

    #[test]
    fn a_suspend_during_the_first_debounce_is_ended_by_the_bus_reset() {
        // The host sees the device attach, waits (the bus idles: a suspend), then resets it and
        // enumerates. embassy-usb calls `reset()`, never `suspended(false)`.
        let s = after(&[Enabled(true), Suspended(true), Reset, Configured(true)]);
        assert!(s.up());
        assert!(s.session().is_some());
    }

    #[test]
    fn a_pull_and_replug_without_vbus_sensing_is_a_new_session() {
        let mut s = after(&[Enabled(true), Reset, Configured(true)]);
        let first = s.session().unwrap();
        // The cable is pulled: no more SOFs, a suspend (VBUS sensing is off: no power event).
        s.on(Suspended(true));
        assert_eq!(s.session(), None);
        // Plugged in again (to the same or another host): a bus reset and a new enumeration.
        s.on(Reset);
        assert_eq!(s.session(), None, "reset, not yet configured");
        s.on(Configured(true));
        let second = s.session().unwrap();
        assert_ne!(
            first, second,
            "the sender must resend what the old host may lack"
        );
        // And again, a pull while unconfigured then a re-plug.
        s.on(Suspended(true));
        s.on(Reset);
        s.on(Suspended(true));
        s.on(Reset);
        s.on(Configured(true));
        assert!(s.up());
    }

    #[test]
    fn a_pull_with_vbus_sensing_is_power_removed_then_a_new_session() {
        // The board senses VBUS (PA9): a pull is `enabled(false)` (the OTG core's session-end
        // interrupt), before or after the 3 ms of idle bus that make a suspend; a re-plug is
        // `enabled(true)` (session request), a bus reset and a new enumeration.
        for pull in [
            &[Suspended(true), Enabled(false)][..],
            &[Enabled(false)][..],
        ] {
            let mut s = after(&[Enabled(true), Reset, Configured(true)]);
            let first = s.session().unwrap();
            for &e in pull {
                s.on(e);
            }
            assert_eq!(s.session(), None, "down after {pull:?}");
            // A suspend the core reports while unpowered changes nothing.
            s.on(Suspended(true));
            s.on(Enabled(true));
            assert!(!s.up(), "power back is not a configuration");
            s.on(Reset);
            assert!(!s.up());
            s.on(Configured(true));
            let second = s.session().expect("up after the re-plug's enumeration");
            assert_ne!(first, second, "a new session: the sender resends");
        }
        // VBUS present at boot: the first event is the session request's power, as without
        // sensing; no power, no link, whatever else arrives.
        assert!(after(&[Enabled(true), Reset, Configured(true)]).up());
        assert!(!after(&[Reset, Configured(true)]).up());
    }

    #[test]
    fn a_suspend_then_resume_is_up_again_in_a_new_session() {
        let mut s = after(&[Enabled(true), Reset, Configured(true)]);
        let first = s.session().unwrap();
        s.on(Suspended(true));
        assert!(!s.up());
        s.on(Suspended(false));
        assert!(s.up());
        assert_ne!(s.session(), Some(first));
    }

    #[test]
    fn a_bus_reset_while_up_takes_the_link_down_until_configured() {
        let mut s = after(&[Enabled(true), Reset, Configured(true)]);
        let first = s.session().unwrap();
        s.on(Reset);
        assert!(!s.up());
        s.on(Configured(true));
        assert_ne!(s.session(), Some(first));
    }

    #[test]
    fn power_loss_and_unconfiguration_take_the_link_down() {
        let mut s = after(&[Enabled(true), Reset, Configured(true)]);
        s.on(Enabled(false));
        assert!(!s.up());
        s.on(Enabled(true));
        assert!(!s.up(), "power back is not a configuration");
        s.on(Reset);
        s.on(Configured(true));
        assert!(s.up());
        s.on(Configured(false));
        assert!(!s.up());
        // A suspend while unconfigured, then configuration: still suspended, so down.
        let s = after(&[Enabled(true), Reset, Suspended(true), Configured(true)]);
        assert!(!s.up());
    }

    #[test]
    fn events_that_do_not_take_the_link_down_keep_the_session() {
        let mut s = after(&[Enabled(true), Reset, Configured(true)]);
        let first = s.session();
        s.on(Configured(true));
        s.on(Suspended(false));
        assert_eq!(s.session(), first);
    }

    /// A model of the bus: the device's sender (the board's loop, step by step), one FIFO
    /// packet that the host takes (and thereby acknowledges) while the link is up, and link
    /// events between steps. A packet in the FIFO when the link goes down is lost (the core
    /// flushes it at the bus reset). Returns what the host received, per session.
    fn run_bus(frames_in: &[Vec<u8>], script: &[(usize, &[BusEvent])]) -> Vec<Vec<u8>> {
        let mut queue: Vec<u8> = frames_in.concat();
        let mut t = TxResend::<HELD>::new();
        let mut bus = after(&[Enabled(true), Reset, Configured(true)]);
        let mut seen = bus.session();
        let mut fifo: Option<Vec<u8>> = None;
        let mut hosts: Vec<Vec<u8>> = vec![vec![]];
        let mut pkt = [0u8; PACKET];
        for step in 0..10_000 {
            for (at, events) in script {
                if *at == step {
                    for &e in *events {
                        bus.on(e);
                    }
                }
            }
            let Some(session) = bus.session() else {
                fifo = None;
                continue;
            };
            if seen != Some(session) {
                // The sender saw the link go down (and come back): the FIFO was flushed.
                fifo = None;
                hosts.push(vec![]);
                t.reconnected();
                seen = Some(session);
            }
            // The host takes the packet in the FIFO: the previous transfer completes, and the
            // sender's next write returns.
            if let Some(p) = fifo.take() {
                hosts.last_mut().unwrap().extend_from_slice(&p);
            }
            if !t.pending() {
                if t.unacknowledged() && (queue.is_empty() || t.room() == 0) {
                    fifo = Some(vec![]);
                    t.acknowledged();
                    continue;
                }
                let n = queue.len().min(t.room()).min(PACKET);
                if n == 0 {
                    if step > 9_000 {
                        break;
                    }
                    continue;
                }
                let taken: Vec<u8> = queue.drain(..n).collect();
                t.take(&taken);
            }
            let n = t.next_packet(&mut pkt);
            fifo = Some(pkt[..n].to_vec());
            t.wrote(n);
        }
        hosts
    }

    #[test]
    fn on_the_bus_model_every_frame_reaches_the_host_through_pulls_and_resets() {
        let sent: Vec<Vec<u8>> = (1..=12u8).map(|k| frame(k, 20 + 37 * k as usize)).collect();
        let script: &[(usize, &[BusEvent])] = &[
            // A pull mid-frame, re-plugged 5 steps later (bus reset and enumeration).
            (3, &[Suspended(true)]),
            (8, &[Reset, Configured(true)]),
            // A sleeping host, then resume.
            (14, &[Suspended(true)]),
            (16, &[Suspended(false)]),
            // A bus reset while up.
            (25, &[Reset]),
            (27, &[Configured(true)]),
            // A pull right after the last data packet went into the FIFO, before the
            // zero-length packet.
            (41, &[Suspended(true)]),
            (45, &[Suspended(true), Reset, Configured(true)]),
        ];
        let hosts = run_bus(&sent, script);
        assert!(
            hosts.len() >= 5,
            "every scripted drop was seen: {}",
            hosts.len()
        );
        let got: Vec<Vec<u8>> = hosts.iter().flat_map(|h| frames(h)).collect();
        let good: Vec<Vec<u8>> = got.iter().filter(|f| sent.contains(f)).cloned().collect();
        // In this model a packet the host took is acknowledged before the link can drop, so
        // nothing arrives twice; what the host holds of a frame cut by a drop is closed by a
        // delimiter and dropped (not one of `sent`).
        assert_eq!(good, sent, "every frame, once, in order");
    }

    #[test]
    fn on_the_bus_model_every_frame_reaches_the_host_through_vbus_pulls() {
        let sent: Vec<Vec<u8>> = (1..=10u8).map(|k| frame(k, 30 + 41 * k as usize)).collect();
        let script: &[(usize, &[BusEvent])] = &[
            // A pull seen as VBUS gone at once (mid-frame), re-plugged.
            (4, &[Enabled(false)]),
            (9, &[Enabled(true)]),
            (11, &[Reset, Configured(true)]),
            // A pull seen as a suspend first, then VBUS gone; re-plugged to another host.
            (20, &[Suspended(true)]),
            (21, &[Enabled(false)]),
            (30, &[Enabled(true), Reset, Configured(true)]),
            // Power back but never configured for a while (a host still enumerating).
            (38, &[Enabled(false)]),
            (40, &[Enabled(true), Reset]),
            (47, &[Configured(true)]),
        ];
        let hosts = run_bus(&sent, script);
        assert!(
            hosts.len() >= 4,
            "every scripted pull was seen: {}",
            hosts.len()
        );
        let got: Vec<Vec<u8>> = hosts.iter().flat_map(|h| frames(h)).collect();
        let good: Vec<Vec<u8>> = got.iter().filter(|f| sent.contains(f)).cloned().collect();
        assert_eq!(good, sent, "every frame, once, in order");
    }
}

//! Frames to the host: replies made now, and run frames sent from the store.

use super::*;

impl App<'_> {
    /// Sends a frame made now (not part of a run). Returns whether the link took it.
    pub(super) fn send<H: Hardware>(&mut self, hw: &mut H, msg: &DeviceMsg) -> bool {
        let seq = self.next_seq();
        let ok = match self.encoder.encode(seq, msg, &mut self.out) {
            Ok(bytes) => hw.send_frame(bytes),
            Err(_) => false,
        };
        if !ok {
            self.dropped_frames = self.dropped_frames.saturating_add(1);
        }
        ok
    }

    pub(super) fn ack<H: Hardware>(&mut self, hw: &mut H, seq: u32) {
        self.send(hw, &DeviceMsg::Ack { seq });
    }

    pub(super) fn error<H: Hardware>(
        &mut self,
        hw: &mut H,
        code: ErrorCode,
        about_seq: Option<u32>,
    ) {
        self.send(hw, &DeviceMsg::Error(DeviceError { code, about_seq }));
    }

    pub(super) fn reply<H: Hardware>(&mut self, hw: &mut H, seq: u32, r: Result<(), ErrorCode>) {
        match r {
            Ok(()) => self.ack(hw, seq),
            Err(code) => self.error(hw, code, Some(seq)),
        }
    }

    /// Sends run frames from the store while the link takes them: first the blocks a
    /// [`HostMsg::PullBlocks`] asked for, then the stream (live, or a [`HostMsg::Pull`]). At most
    /// `frames` records are looked at per call; every frame is sent as stored, so this is copying
    /// only. Returns how many frames the link took.
    pub(super) fn pump<H: Hardware>(&mut self, hw: &mut H, frames: u8) -> u8 {
        let mut sent = 0;
        for _ in 0..frames {
            if let Some((k, end)) = self.range {
                if k >= end || k >= self.store.blocks() {
                    self.range = None;
                    continue;
                }
                let Some(pos) = self.store.block_pos(k) else {
                    self.range = None;
                    continue;
                };
                match self.store.read(hw, pos, &mut self.out) {
                    Read::Frame { len, .. } => {
                        if !hw.send_frame(&self.out[..len]) {
                            return sent;
                        }
                        sent += 1;
                        self.range = Some((k + 1, end));
                    }
                    Read::Busy => return sent,
                    Read::Lost { .. } | Read::End => self.range = Some((k + 1, end)),
                }
                continue;
            }
            let Some(want) = self.want else { return sent };
            let (len, next) = match want {
                Want::Header { from_block } => {
                    let Some(h) = self.store.header() else {
                        self.want = None;
                        return sent;
                    };
                    // The run's number leaves the rig only once flash holds it: a power cut
                    // after that cannot let the next run take it again.
                    if !self.store.header_durable() {
                        return sent;
                    }
                    self.out[..h.len()].copy_from_slice(h);
                    (h.len(), Some(Want::Blocks(from_block)))
                }
                Want::Blocks(k) => {
                    match self.store.start_of_block(hw, k) {
                        Some(pos) => self.want = Some(Want::From(pos)),
                        None => return sent,
                    }
                    continue;
                }
                Want::From(pos) => match self.store.read(hw, pos, &mut self.out) {
                    Read::Frame { len, next } => (len, Some(Want::From(next))),
                    Read::Busy => return sent,
                    Read::Lost { next } => {
                        self.want = Some(Want::From(next));
                        continue;
                    }
                    Read::End => {
                        if self.store.result().is_none() {
                            // More may come (a run in progress).
                            return sent;
                        }
                        self.want = Some(Want::Result);
                        continue;
                    }
                },
                Want::Result => {
                    let Some(r) = self.store.result() else {
                        return sent;
                    };
                    self.out[..r.len()].copy_from_slice(r);
                    (r.len(), Some(Want::End))
                }
                Want::End => {
                    let Some(e) = self.store.end() else {
                        return sent;
                    };
                    self.out[..e.len()].copy_from_slice(e);
                    (e.len(), None)
                }
            };
            if !hw.send_frame(&self.out[..len]) {
                return sent;
            }
            sent += 1;
            self.want = next;
        }
        sent
    }
}

//! After a power loss: the newest run read back from flash, record by record, each one checked.

use super::*;

impl RunStore<'_> {
    /// Reads the newest run back from flash (at boot). Returns what was found, and holds it.
    pub fn recover<F: RunFlash>(&mut self, flash: &mut F) -> Option<Recovered> {
        let g = flash.flash_geometry();
        if g.sectors == 0 || g.sector_bytes < FLASH_WORD as u32 || flash.flash_busy() {
            return None;
        }
        // The newest header at the start of a sector.
        let mut best: Option<(u32, u32)> = None;
        let mut buf = [0u8; MAX_FRAME];
        for s in 0..g.sectors {
            let probe = Writer {
                geometry: g,
                start: s,
                ..Writer::OFF
            };
            if let Some((len, DeviceMsg::RunStarted(h))) = read_record(flash, &probe, 0, &mut buf) {
                let _ = len;
                if best.is_none_or(|(id, _)| h.run_id > id) {
                    best = Some((h.run_id, s));
                }
            }
        }
        let (run_id, start) = best?;
        let mut w = Writer {
            geometry: g,
            start,
            erased: g.sectors,
            written: g.bytes(),
            state: FlashState::Done,
            ..Writer::OFF
        };
        let (hlen, _) = read_record(flash, &w, 0, &mut buf)?;
        let header = Slot::from_slice(&buf[..hlen]).ok()?;
        let mut q = LEN_BYTES + hlen as u32;
        let (mut blocks, mut events) = (0u32, 0u32);
        let mut result = Slot::new();
        let mut end = Slot::new();
        let mut tail_at = None;
        while let Some((len, msg)) = read_record(flash, &w, q, &mut buf) {
            let rec = q;
            let same = |id: u32| id == run_id;
            let ok = match &msg {
                DeviceMsg::Packed(p)
                    if tail_at.is_none() && same(p.run_id) && p.block == blocks =>
                {
                    match self.index.get_mut(blocks as usize) {
                        Some(slot) => {
                            *slot = rec;
                            blocks += 1;
                            true
                        }
                        None => false,
                    }
                }
                DeviceMsg::Gap(g) if tail_at.is_none() && same(g.run_id) => {
                    events += 1;
                    true
                }
                DeviceMsg::EcrRange(e) if tail_at.is_none() && same(e.run_id) => {
                    events += 1;
                    true
                }
                DeviceMsg::Chain(c) if tail_at.is_none() && same(c.run_id) => {
                    events += 1;
                    true
                }
                DeviceMsg::Result(r) if tail_at.is_none() && same(r.run_id) => {
                    tail_at = Some(rec);
                    result = Slot::from_slice(&buf[..len]).ok()?;
                    true
                }
                DeviceMsg::RunEnded(e) if tail_at.is_some() && same(e.run_id) => {
                    end = Slot::from_slice(&buf[..len]).ok()?;
                    q += LEN_BYTES + len as u32;
                    break;
                }
                _ => false,
            };
            if !ok {
                break;
            }
            q += LEN_BYTES + len as u32;
        }
        if end.is_empty() {
            // A result without its end is not a finished run (and the end is what says so).
            result.clear();
        }
        let stream_end = tail_at.filter(|_| !end.is_empty()).unwrap_or(q);
        w.written = q;
        w.erased = w.sectors_used();
        w.cut = Some(stream_end);
        self.header = header;
        self.result = result;
        self.end = end;
        self.run_id = Some(run_id);
        self.blocks = blocks;
        self.events = events;
        self.refused = 0;
        self.ring.reset(stream_end);
        self.writer = w;
        self.ahead = None;
        Some(Recovered {
            run_id,
            blocks,
            events,
            finished: self.is_finished(),
        })
    }
}

/// Reads and checks the record at image position `q`: its length, then a frame that decodes.
fn read_record<F: RunFlash>(
    flash: &mut F,
    w: &Writer,
    q: u32,
    buf: &mut [u8; MAX_FRAME],
) -> Option<(usize, DeviceMsg)> {
    let mut b = [0u8; 2];
    if q + LEN_BYTES > w.capacity() || !read_image(flash, w, q, &mut b) {
        return None;
    }
    let len = u16::from_le_bytes(b) as usize;
    if len == 0 || len > MAX_FRAME || q + LEN_BYTES + len as u32 > w.capacity() {
        return None;
    }
    if !read_image(flash, w, q + LEN_BYTES, &mut buf[..len]) {
        return None;
    }
    let frame = decode_one::<DeviceMsg>(&buf[..len]).ok()?;
    Some((len, frame.msg))
}

//! Protocol v1, frozen: the rig's messages as firmware speaking protocol v1 framed them, for reading
//! the frame logs of runs recorded then (decode only: no rig speaks v1 to a current host).
//!
//! Of the run frames, only the run header changed in v2 (it gained the sample clock); sample blocks,
//! results and ends kept their layout and variant numbers, so their v1 types here *are* today's. If
//! a later protocol changes one of them, copy its v1 form into this module (the archive tests in
//! `tribo-store` pin the bytes of a v1 log, so such a change cannot pass unnoticed).
//!
//! [`decode`] reads one v1 frame as today's [`crate::DeviceMsg`] ([`DeviceMsg::upgrade`]): a v1 run
//! header gets the clock v1 implied, exactly the configured rate.

use crate::frame::{decode_one, Frame, FrameError};
use crate::{
    Configure, DeviceError, DeviceInfo, OnboardResult, RunEnd, SampleBlock, SampleClock, Status,
};
use serde::{Deserialize, Serialize};

/// The protocol number this module reads.
pub const PROTOCOL: u16 = 1;

/// Protocol v1's run header: no sample clock (samples were at exactly `config.sample_rate_hz`).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RunHeader {
    pub run_id: u32,
    pub config: Configure,
    pub temp_c: f32,
    /// Device time of the release.
    pub t_us: u64,
}

/// Protocol v1's `DeviceMsg`, every variant in its order.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[allow(clippy::large_enum_variant)]
pub enum DeviceMsg {
    Hello(DeviceInfo),
    Ack { seq: u32 },
    Error(DeviceError),
    Status(Status),
    RunStarted(RunHeader),
    Samples(SampleBlock),
    Result(OnboardResult),
    RunEnded(RunEnd),
}

impl DeviceMsg {
    /// The same message in today's protocol.
    pub fn upgrade(self) -> crate::DeviceMsg {
        match self {
            DeviceMsg::Hello(i) => crate::DeviceMsg::Hello(i),
            DeviceMsg::Ack { seq } => crate::DeviceMsg::Ack { seq },
            DeviceMsg::Error(e) => crate::DeviceMsg::Error(e),
            DeviceMsg::Status(s) => crate::DeviceMsg::Status(s),
            DeviceMsg::RunStarted(h) => crate::DeviceMsg::RunStarted(crate::RunHeader {
                run_id: h.run_id,
                config: h.config,
                temp_c: h.temp_c,
                t_us: h.t_us,
                clock: SampleClock::exact(h.config.sample_rate_hz),
            }),
            DeviceMsg::Samples(b) => crate::DeviceMsg::Samples(b),
            DeviceMsg::Result(r) => crate::DeviceMsg::Result(r),
            DeviceMsg::RunEnded(e) => crate::DeviceMsg::RunEnded(e),
        }
    }
}

/// Decodes one v1 frame (closing zero optional) into today's message.
pub fn decode(frame: &[u8]) -> Result<Frame<crate::DeviceMsg>, FrameError> {
    let f = decode_one::<DeviceMsg>(frame)?;
    Ok(Frame {
        seq: f.seq,
        msg: f.msg.upgrade(),
    })
}

/// Decodes one frame of a rig that spoke `protocol` (`None`: not recorded, as in logs written
/// before the log header said; then today's protocol is tried first, v1 second — a frame decodes
/// in at most one of them whenever their layouts differ, as every frame must be read to its last
/// byte).
pub fn decode_as(
    protocol: Option<u16>,
    frame: &[u8],
) -> Result<Frame<crate::DeviceMsg>, FrameError> {
    match protocol {
        Some(PROTOCOL) => decode(frame),
        Some(_) => decode_one(frame),
        None => decode_one(frame).or_else(|e| decode(frame).map_err(|_| e)),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::frame::encode_vec;

    #[test]
    fn a_v1_header_reads_with_the_configured_rate_and_never_as_v2() {
        let c = Configure::real_rig(0.3);
        let raw = encode_vec(
            5,
            &DeviceMsg::RunStarted(RunHeader {
                run_id: 3,
                config: c,
                temp_c: 21.0,
                t_us: 77,
            }),
        )
        .unwrap();
        assert_eq!(
            decode_one::<crate::DeviceMsg>(&raw),
            Err(FrameError::Decode)
        );
        for p in [Some(1), None] {
            let f = decode_as(p, &raw).unwrap();
            assert_eq!(f.seq, 5);
            let crate::DeviceMsg::RunStarted(h) = f.msg else {
                panic!("{:?}", f.msg)
            };
            assert_eq!((h.run_id, h.t_us), (3, 77));
            assert_eq!(h.clock, SampleClock::exact(c.sample_rate_hz));
        }
        // A log that says v2 does not guess.
        assert!(decode_as(Some(2), &raw).is_err());
        // A v2 header is not a v1 frame.
        let v2 = encode_vec(
            5,
            &crate::DeviceMsg::RunStarted(crate::RunHeader {
                run_id: 3,
                config: c,
                temp_c: 21.0,
                t_us: 77,
                clock: SampleClock::exact(10_000),
            }),
        )
        .unwrap();
        assert_eq!(decode(&v2).map(|_| ()), Err(FrameError::Decode));
        assert!(decode_as(None, &v2).is_ok());
    }
}

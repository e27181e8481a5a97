//! Wire protocol of the oscillating tribometer, compiled by both the firmware and the host so that the
//! two can never disagree.
//!
//! * [`msg`]: what is said: commands from the host ([`HostMsg`]) and everything the rig sends back
//!   ([`DeviceMsg`]): hello, status, sample blocks, on-board results, errors.
//! * [`frame`]: how it is said: each message is postcard-encoded behind a sequence number, followed by
//!   a CRC-32 of both, COBS-stuffed and closed by a zero byte. The [`frame::Decoder`] never panics,
//!   reports every bad frame and resynchronises on the next zero byte.
//! * [`codec`]: block compression (per-channel prediction, Rice codes) of [`PackedBlock`]s.
//! * [`crc32`]: the CRC-32 (IEEE 802.3 / ISO-HDLC) used by the frames.
//! * [`v1`]: protocol v1's messages, frozen, to read the frame logs of runs recorded with it.
//!
//! Compatibility rule: variant 0 of [`HostMsg`] and [`DeviceMsg`] is `Hello`, and [`DeviceInfo`] starts
//! with the protocol number. Those never change, so any host can read any firmware's hello and refuse
//! a protocol it does not understand with a clear message (see [`check_protocol`]).
#![cfg_attr(not(any(test, feature = "std")), no_std)]

pub mod codec;
pub mod crc32;
pub mod frame;
pub mod msg;
pub mod v1;

pub use frame::{Decoder, EncodeError, Encoder, Frame, FrameError};
pub use msg::*;

/// Version of the message set. Bump it on any change to [`msg`] that changes the encoding.
///
/// v3 added [`DeviceMsg::Chain`] (the run's analog chain) as the last variant: every v2 message
/// keeps its bytes, so a v2 frame log reads as v3.
pub const PROTOCOL_VERSION: u16 = 3;

/// Checks the protocol number announced by the other side's hello.
pub fn check_protocol(theirs: u16) -> Result<(), ProtocolMismatch> {
    if theirs == PROTOCOL_VERSION {
        Ok(())
    } else {
        Err(ProtocolMismatch {
            ours: PROTOCOL_VERSION,
            theirs,
        })
    }
}

/// The two sides speak different versions of the protocol.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProtocolMismatch {
    pub ours: u16,
    pub theirs: u16,
}

impl core::fmt::Display for ProtocolMismatch {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        if self.theirs > self.ours {
            write!(
                f,
                "the rig speaks protocol v{} but this program only knows v{}: update tribo to the \
                 version that matches the firmware",
                self.theirs, self.ours
            )
        } else {
            write!(
                f,
                "the rig speaks protocol v{} but this program needs v{}: reflash the firmware \
                 (`cargo xtask firmware`, then flash the ELF it prints)",
                self.theirs, self.ours
            )
        }
    }
}

#[cfg(any(test, feature = "std"))]
impl std::error::Error for ProtocolMismatch {}

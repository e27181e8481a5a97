//! Coverage-guided fuzzing of the frame decoder: `cargo fuzz run decoder` from firmware/wire
//! (on a stable toolchain: `RUSTC_BOOTSTRAP=1 cargo fuzz run decoder`).
//!
//! Whatever the bytes: no panic, every frame that decodes re-encodes to a frame that decodes to the
//! same message, and a valid frame appended after the garbage always comes through.
#![no_main]

use libfuzzer_sys::fuzz_target;
use tribo_wire::frame::encode_vec;
use tribo_wire::{Decoder, DeviceMsg, Frame, HostMsg};

fn check<M>(data: &[u8], sentinel: M)
where
    M: serde::Serialize + serde::de::DeserializeOwned + PartialEq + Clone + core::fmt::Debug,
{
    let mut d = Decoder::<M>::new();
    let mut got = Vec::new();
    d.feed(data, |r| {
        if let Ok(f) = r {
            got.push(f)
        }
    });
    for f in &got {
        let again = encode_vec(f.seq, &f.msg).expect("a decoded message re-encodes");
        let back = tribo_wire::frame::decode_one::<M>(&again).expect("and decodes");
        // NaN payloads are compared by their encoding rather than by value.
        assert_eq!(encode_vec(back.seq, &back.msg), Ok(again));
    }
    let mut tail = vec![0u8];
    tail.extend(encode_vec(u32::MAX, &sentinel).unwrap());
    let mut last = None;
    d.feed(&tail, |r| last = r.ok());
    assert_eq!(
        last,
        Some(Frame {
            seq: u32::MAX,
            msg: sentinel
        })
    );
}

fuzz_target!(|data: &[u8]| {
    check(data, HostMsg::Status);
    check(data, DeviceMsg::Ack { seq: 7 });
});

//! Coverage-guided fuzzing of the block codec: `cargo fuzz run codec` from firmware/wire
//! (on a stable toolchain: `RUSTC_BOOTSTRAP=1 cargo fuzz run codec`).
//!
//! The first two bytes choose the shape (samples, channels); the rest is either decoded as packed
//! data (no panic; what decodes re-encodes to data that decodes to the same counts) or taken as
//! counts to encode (the round trip is bit-exact and never longer than raw).
#![no_main]

use libfuzzer_sys::fuzz_target;
use tribo_wire::codec::{decode, encode, raw_len};
use tribo_wire::{BLOCK_LEN, CHANNELS};

fuzz_target!(|data: &[u8]| {
    let [a, b, rest @ ..] = data else { return };
    let n = *a as usize % (BLOCK_LEN + 1);
    let c = 1 + *b as usize % CHANNELS;
    let mut counts = [0u16; BLOCK_LEN * CHANNELS];
    let mut packed = [0u8; 1 + 2 * BLOCK_LEN * CHANNELS];
    // As packed data.
    if decode(rest, n, c, &mut counts).is_ok() {
        let len = encode(&counts[..n * c], n, c, &mut packed).expect("decoded counts encode");
        let mut again = [0u16; BLOCK_LEN * CHANNELS];
        decode(&packed[..len], n, c, &mut again).expect("and decode");
        assert_eq!(&again[..n * c], &counts[..n * c]);
    }
    // As counts.
    let want: Vec<u16> = rest
        .chunks_exact(2)
        .map(|p| u16::from_le_bytes([p[0], p[1]]))
        .chain(core::iter::repeat(0))
        .take(n * c)
        .collect();
    let len = encode(&want, n, c, &mut packed).expect("any counts encode");
    assert!(len <= raw_len(n, c));
    decode(&packed[..len], n, c, &mut counts).expect("and decode");
    assert_eq!(&counts[..n * c], &want[..]);
});

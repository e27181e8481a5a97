use super::*;

fn round_trip(counts: &[u16], n: usize, c: usize) -> usize {
    let mut out = [0u8; raw_len(BLOCK_LEN, CHANNELS)];
    let len = encode(counts, n, c, &mut out).unwrap();
    assert!(len <= raw_len(n, c));
    let mut back = [0u16; BLOCK_LEN * CHANNELS];
    decode(&out[..len], n, c, &mut back).unwrap();
    assert_eq!(&back[..n * c], counts);
    len
}

/// Bits of one residual under parameter `k`.
#[inline]
fn rice_bits(u: u16, k: u32) -> u32 {
    let q = (u as u32) >> k;
    if q < ESCAPE {
        q + 1 + k
    } else {
        ESCAPE + 16
    }
}

#[test]
fn the_histogram_prices_every_parameter_within_a_bit_per_residual() {
    let mut x = 77u32;
    for spread in [0u32, 1, 5, 40, 300, 5000, 65535] {
        let us: Vec<u16> = (0..200)
            .map(|_| {
                x = x.wrapping_mul(1_103_515_245).wrapping_add(12345);
                ((x >> 8) % (spread + 1)) as u16
            })
            .collect();
        let mut h = Histogram::default();
        us.iter().for_each(|&u| h.add(u));
        for k in 0..=K_MAX {
            let exact: u32 = us.iter().map(|&u| rice_bits(u, k)).sum();
            let est = h.bits(k);
            assert!(
                exact <= est && est <= exact + us.len() as u32,
                "spread {spread} k {k}: estimate {est}, exact {exact}"
            );
        }
    }
}

#[test]
fn zigzag_is_a_bijection_on_16_bits() {
    for r in 0..=u16::MAX {
        assert_eq!(unzigzag(zigzag(r)), r);
    }
    assert_eq!(
        [0, 0xFFFF, 1, 0xFFFE].map(zigzag),
        [0, 1, 2, 3],
        "0, −1, 1, −2 fold to 0, 1, 2, 3"
    );
}

#[test]
fn a_constant_channel_costs_its_first_count_and_a_flag() {
    let counts = [1234u16; BLOCK_LEN];
    // format byte + mode 2 bits + count 16 bits + k 4 bits = 22 bits → 3 bytes.
    assert_eq!(round_trip(&counts, BLOCK_LEN, 1), 1 + 3);
}

#[test]
fn a_parabola_is_coded_by_its_second_difference() {
    let counts: Vec<u16> = (0..BLOCK_LEN as i32)
        .map(|i| (30_000 + 3 * i * i - 100 * i) as u16)
        .collect();
    // Second difference is the constant 6: curve mode, k chosen so each residual is ~4 bits.
    // Each residual 6 → zig-zag 12: k = 3, 5 bits (a zero and 4 bits)... or k = 2 with a
    // quotient of 3: 6 bits. Header 2 + 32 + 4 bits.
    let len = round_trip(&counts, BLOCK_LEN, 1);
    assert_eq!(
        len,
        1 + (2 + 32 + 4 + 62 * 5usize).div_ceil(8),
        "{len} bytes"
    );
}

#[test]
fn full_scale_noise_falls_back_to_raw() {
    let mut x = 0x1234_5678u32;
    let counts: Vec<u16> = (0..BLOCK_LEN * CHANNELS)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u16
        })
        .collect();
    assert_eq!(
        round_trip(&counts, BLOCK_LEN, CHANNELS),
        raw_len(BLOCK_LEN, CHANNELS)
    );
}

#[test]
fn escapes_carry_spikes_at_either_end_of_the_range() {
    let mut counts = [32768u16; BLOCK_LEN];
    counts[10] = 0;
    counts[11] = 65535;
    counts[40] = 1;
    let len = round_trip(&counts, BLOCK_LEN, 1);
    assert!(len < 40, "{len} bytes");
}

#[test]
fn empty_and_short_blocks_round_trip() {
    for n in 0..4 {
        for c in 1..=CHANNELS {
            let counts: Vec<u16> = (0..n * c).map(|i| (i * 7919) as u16).collect();
            round_trip(&counts, n, c);
        }
    }
}

#[test]
fn bad_shapes_are_refused() {
    let mut out = [0u8; 1024];
    assert_eq!(encode(&[], 0, 0, &mut out), Err(CodecError::Shape));
    assert_eq!(encode(&[0; 6], 1, 6, &mut out), Err(CodecError::Shape));
    assert_eq!(encode(&[0; 3], 2, 2, &mut out), Err(CodecError::Shape));
    assert_eq!(
        encode(&[0; 130], 65, 2, &mut out),
        Err(CodecError::Shape),
        "more than a block"
    );
    let mut back = [0u16; 8];
    assert_eq!(decode(&[0], 1, 0, &mut back), Err(CodecError::Shape));
    assert_eq!(decode(&[], 1, 1, &mut back), Err(CodecError::Empty));
    assert_eq!(
        decode(&[7, 0, 0], 1, 1, &mut back),
        Err(CodecError::UnknownFormat(7))
    );
    assert_eq!(decode(&[0, 1], 1, 1, &mut back), Err(CodecError::RawLength));
}

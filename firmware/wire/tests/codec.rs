//! The block codec: bit-exact round trips for any counts, and a decoder that never panics and
//! refuses what the encoder cannot have written.

use proptest::prelude::*;
use tribo_wire::codec::{decode, encode, raw_len, CodecError};
use tribo_wire::frame::{decode_one, encode_vec, MAX_FRAME};
use tribo_wire::*;

/// `(samples, channels, counts)` with counts anywhere in the 16-bit range.
fn any_block() -> impl Strategy<Value = (usize, usize, Vec<u16>)> {
    (0..=BLOCK_LEN, 1..=CHANNELS)
        .prop_flat_map(|(n, c)| (Just(n), Just(c), prop::collection::vec(any::<u16>(), n * c)))
}

/// Signal-like counts: each channel a random walk whose step changes slowly (a smooth curve), plus
/// bounded noise, occasionally a spike, clamped at the ends of the range like a saturated ADC.
fn smooth_block() -> impl Strategy<Value = (usize, usize, Vec<u16>)> {
    walk_block(0..=BLOCK_LEN, 0..12, 0..200, 1000)
}

/// [`smooth_block`] with the block length, noise bits and spike period drawn from these ranges,
/// and the first step at most `step` counts (the walk starts anywhere with `step` ≥ 1000, in the
/// middle third of the range otherwise).
fn walk_block(
    n: impl Strategy<Value = usize>,
    noise_bits: core::ops::Range<u32>,
    spike_every: core::ops::Range<u32>,
    step: i64,
) -> impl Strategy<Value = (usize, usize, Vec<u16>)> {
    (n, 1..=CHANNELS, any::<u64>(), noise_bits, spike_every).prop_map(
        move |(n, c, seed, noise_bits, spike_every)| {
            let mut s = seed | 1;
            let mut rnd = move || {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                s
            };
            let mut lanes = vec![];
            for _ in 0..c {
                let mut x = if step >= 1000 {
                    (rnd() % 65536) as i64
                } else {
                    21_845 + (rnd() % 21_845) as i64
                };
                let mut v = (rnd() % (2 * step as u64 + 1)) as i64 - step;
                let mut lane = vec![];
                for i in 0..n {
                    v += (rnd() % 21) as i64 - 10;
                    x += v;
                    let noise = if noise_bits == 0 {
                        0
                    } else {
                        (rnd() % (1 << noise_bits)) as i64 - (1 << (noise_bits - 1))
                    };
                    let spike = spike_every > 0 && i as u32 % spike_every == spike_every - 1;
                    let y = if spike {
                        (rnd() % 65536) as i64
                    } else {
                        x + noise
                    };
                    lane.push(y.clamp(0, 65535) as u16);
                }
                lanes.push(lane);
            }
            let counts = (0..n * c).map(|j| lanes[j % c][j / c]).collect();
            (n, c, counts)
        },
    )
}

fn encoded(n: usize, c: usize, counts: &[u16]) -> Vec<u8> {
    let mut out = vec![0u8; raw_len(BLOCK_LEN, CHANNELS)];
    let len = encode(counts, n, c, &mut out).expect("a well-shaped block always encodes");
    out.truncate(len);
    out
}

fn decoded(data: &[u8], n: usize, c: usize) -> Result<Vec<u16>, CodecError> {
    let mut out = vec![0u16; BLOCK_LEN * CHANNELS];
    decode(data, n, c, &mut out)?;
    out.truncate(n * c);
    Ok(out)
}

fn config() -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(2000);
    ProptestConfig {
        cases,
        ..ProptestConfig::default()
    }
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn any_counts_round_trip_bit_exact_and_never_exceed_raw((n, c, counts) in any_block()) {
        let data = encoded(n, c, &counts);
        prop_assert!(data.len() <= raw_len(n, c));
        prop_assert_eq!(decoded(&data, n, c), Ok(counts));
    }

    #[test]
    fn smooth_counts_round_trip_and_compress((n, c, counts) in smooth_block()) {
        let data = encoded(n, c, &counts);
        prop_assert_eq!(decoded(&data, n, c), Ok(counts.clone()));
        prop_assert!(data.len() <= raw_len(n, c));
    }

    #[test]
    fn quiet_smooth_counts_take_less_than_half_their_raw_size(
        (n, c, counts) in walk_block(Just(BLOCK_LEN), 0..5, 0..1, 100),
    ) {
        // (A walk from the middle third with steps under 100 + 64 · 10 never reaches the ends.)
        prop_assert!(counts.iter().all(|&x| x != 0 && x != 65535));
        // Second differences of the walk are within ±10, the noise within ±8: the residuals
        // take about 6 bits, a 64-sample channel well under 8 bits a count.
        let data = encoded(n, c, &counts);
        prop_assert!(2 * data.len() < raw_len(n, c), "{} of {} bytes", data.len(), raw_len(n, c));
    }

    #[test]
    fn any_bytes_decode_without_panic(
        data in prop::collection::vec(any::<u8>(), 0..700),
        n in 0usize..80,
        c in 0usize..8,
    ) {
        let _ = decoded(&data, n, c);
    }

    #[test]
    fn rice_garbage_never_panics(
        body in prop::collection::vec(any::<u8>(), 0..700),
        n in 0..=BLOCK_LEN,
        c in 1..=CHANNELS,
    ) {
        let mut data = vec![1u8];
        data.extend(body);
        let _ = decoded(&data, n, c);
    }

    #[test]
    fn truncated_or_extended_data_is_refused((n, c, counts) in smooth_block(), extra in any::<u8>()) {
        let data = encoded(n, c, &counts);
        for cut in 0..data.len() {
            prop_assert!(decoded(&data[..cut], n, c).is_err(), "cut at {} of {}", cut, data.len());
        }
        let mut longer = data.clone();
        longer.push(extra);
        prop_assert!(decoded(&longer, n, c).is_err());
    }

    #[test]
    fn packed_blocks_round_trip_through_a_frame(
        (n, c, counts) in smooth_block(),
        seq in any::<u32>(),
        fields in (any::<u32>(), any::<u32>(), any::<u32>(), any::<u64>(), any::<u8>(), -1e3f32..1e3, -3f32..12.0),
    ) {
        let channels = ChannelSet::ALL.iter().take(c).collect::<ChannelSet>();
        let (run_id, block, first_sample, t_us, ecr_range, temp_c, log10_ecr_ohm) = fields;
        let b = SampleBlock {
            run_id, block, first_sample, t_us, channels, ecr_range, log10_ecr_ohm, temp_c,
            counts: Counts::from_slice(&counts).unwrap(),
        };
        let p = PackedBlock::pack(&b).unwrap();
        prop_assert_eq!(p.samples as usize, n);
        let frame = encode_vec(seq, &DeviceMsg::Packed(p.clone())).unwrap();
        prop_assert!(frame.len() <= MAX_FRAME);
        let back = decode_one::<DeviceMsg>(&frame).unwrap();
        prop_assert_eq!(back.seq, seq);
        prop_assert_eq!(&back.msg, &DeviceMsg::Packed(p.clone()));
        prop_assert_eq!(p.unpack(), Ok(b));
    }
}

#[test]
fn the_largest_packed_block_fits_a_frame() {
    // Raw fallback of a full five-channel block, worst-case field values.
    let mut x = 0x9E37_79B9u32;
    let counts: Vec<u16> = (0..MAX_BLOCK_COUNTS)
        .map(|_| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x as u16
        })
        .collect();
    let b = SampleBlock {
        run_id: u32::MAX,
        block: u32::MAX,
        first_sample: u32::MAX,
        t_us: u64::MAX,
        channels: ChannelSet::ALL,
        ecr_range: u8::MAX,
        log10_ecr_ohm: f32::NAN,
        temp_c: f32::MAX,
        counts: Counts::from_slice(&counts).unwrap(),
    };
    let p = PackedBlock::pack(&b).unwrap();
    assert_eq!(
        p.data.len(),
        raw_len(BLOCK_LEN, CHANNELS),
        "noise is sent raw"
    );
    let frame = encode_vec(u32::MAX, &DeviceMsg::Packed(p)).unwrap();
    assert!(frame.len() <= MAX_FRAME, "{} bytes", frame.len());
}

#[test]
fn inconsistent_blocks_are_not_packed() {
    let mut b = SampleBlock {
        run_id: 1,
        block: 0,
        first_sample: 0,
        t_us: 0,
        channels: ChannelSet::VIBROMETER,
        ecr_range: 0,
        log10_ecr_ohm: 0.0,
        temp_c: 0.0,
        counts: Counts::from_slice(&[1, 2, 3]).unwrap(),
    };
    assert_eq!(PackedBlock::pack(&b), Err(CodecError::Shape), "1.5 samples");
    b.counts = Counts::from_slice(&[1, 2]).unwrap();
    b.channels = ChannelSet(0b1000_0011);
    assert_eq!(
        PackedBlock::pack(&b),
        Err(CodecError::Shape),
        "unknown channel"
    );
    b.channels = ChannelSet::VIBROMETER;
    let mut p = PackedBlock::pack(&b).unwrap();
    p.samples = 2;
    assert!(p.unpack().is_err(), "a sample count that does not match");
    p.samples = 1;
    p.channels = ChannelSet(0b1000_0011);
    assert_eq!(p.unpack(), Err(CodecError::Shape));
}

/// Random Rice streams must nearly always be refused: the grammar leaves garbage few ways to end
/// exactly on its last byte with zero padding. (A decoder that ignored trailing bytes or padding
/// would accept most of them.)
#[test]
fn random_rice_streams_are_refused() {
    let mut x = 0x2545_F491_4F6C_DD1Du64;
    let mut rnd = move || {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        x
    };
    let (mut tried, mut accepted) = (0, 0);
    for _ in 0..20_000 {
        let n = (rnd() % (BLOCK_LEN as u64 + 1)) as usize;
        let c = 1 + (rnd() % CHANNELS as u64) as usize;
        let len = 1 + (rnd() % 400) as usize;
        let mut data = vec![1u8];
        data.extend((0..len).map(|_| rnd() as u8));
        tried += 1;
        if decoded(&data, n, c).is_ok() {
            accepted += 1;
        }
    }
    assert!(
        accepted * 100 < tried,
        "{accepted} of {tried} random streams decoded"
    );
}

/// The cases the format names: a bad format byte, a raw block of the wrong length, padding bits.
#[test]
fn malformed_headers_are_named() {
    // A constant channel of 4 samples: mode 2 bits + count 16 bits + k 4 bits = 22 bits, so the
    // last of 3 bytes has 2 padding bits.
    let counts = [1000u16; 4];
    let data = encoded(4, 1, &counts);
    assert_eq!(data.len(), 1 + 3);
    assert_eq!(data[0], 1, "Rice");
    let mut padded = data.clone();
    padded[3] |= 1;
    assert_eq!(decoded(&padded, 4, 1), Err(CodecError::Trailing));
    let mut bad = data.clone();
    bad[0] = 2;
    assert_eq!(decoded(&bad, 4, 1), Err(CodecError::UnknownFormat(2)));
    let mut raw = vec![0u8];
    raw.extend(counts.iter().flat_map(|c| c.to_le_bytes()));
    assert_eq!(decoded(&raw, 4, 1), Ok(counts.to_vec()));
    assert_eq!(decoded(&raw[..8], 4, 1), Err(CodecError::RawLength));
    assert_eq!(decoded(&data[..3], 4, 1), Err(CodecError::Truncated));
}

/// A packer step encodes one channel: a five-channel block takes five steps (the firmware packs
/// one per poll), and the steps give the one-call encoding.
#[test]
fn a_packer_step_is_one_channel() {
    use tribo_wire::codec::{encode, raw_len, Packer};
    let counts: Vec<u16> = (0..64 * 5u32)
        .map(|i| 30_000 + ((i * 7919) % 977) as u16)
        .collect();
    let mut whole = vec![0u8; raw_len(64, 5)];
    let n = encode(&counts, 64, 5, &mut whole).unwrap();
    let mut stepped = vec![0u8; raw_len(64, 5)];
    let mut p = Packer::new();
    let mut steps = 0;
    let m = loop {
        steps += 1;
        if let Some(m) = p.step(&counts, 64, 5, &mut stepped).unwrap() {
            break m;
        }
    };
    assert_eq!(steps, 5);
    assert_eq!(&stepped[..m], &whole[..n]);
}

//! The bytes on the wire, pinned: known frames and known COBS/CRC inputs against the exact bytes the
//! protocol has always produced (`tests/pinned_frames.txt`, one `name hex` per line, written by the
//! hand-written CRC-32 and COBS this crate had before it used the `crc` and `cobs` crates).
//!
//! Any change of the framing code that changes a single byte fails here, and a firmware and a host
//! built from different sides of that change could no longer talk.
//!
//! To regenerate the file after a deliberate, protocol-bumping change:
//! `TRIBO_PIN_WRITE=1 cargo test -p tribo-wire --test pinned` (then review the diff).

use tribo_wire::crc32::{crc32, Crc32};
use tribo_wire::frame::{cobs_decode_in_place, cobs_encode, decode_one, encode_vec};
use tribo_wire::*;

const PINNED: &str = include_str!("pinned_frames.txt");

fn sample_block(n_counts: usize, salt: u16) -> SampleBlock {
    // Non-zero counts, so that runs of 254 non-zero bytes (full COBS blocks) occur.
    let counts: Vec<u16> = (0..n_counts as u16)
        .map(|i| i.wrapping_mul(977).wrapping_add(salt) | 0x0101)
        .collect();
    SampleBlock {
        run_id: 0x0101_0101,
        block: 3,
        first_sample: 3 * BLOCK_LEN as u32,
        t_us: 1_234_567,
        channels: ChannelSet::ALL,
        ecr_range: 2,
        log10_ecr_ohm: 3.5,
        temp_c: 25.0,
        counts: Counts::from_slice(&counts).unwrap(),
    }
}

/// The frames pinned: every kind of message the link carries, short and long, and sample blocks of
/// every length class so that the stuffed data ends in each way COBS can end (after a zero, inside
/// a block, exactly on a full 254-byte block).
fn frames() -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = Vec::new();
    let mut host = |name: &str, seq: u32, m: HostMsg| {
        out.push((name.to_string(), encode_vec(seq, &m).unwrap()));
    };
    host("host.hello", 0, HostMsg::Hello { protocol: 2 });
    host("host.heartbeat", 41, HostMsg::Heartbeat);
    host("host.safe", u32::MAX, HostMsg::Safe);
    host(
        "host.pull_blocks",
        7,
        HostMsg::PullBlocks {
            run_id: 12,
            first: 300,
            count: 70_000,
        },
    );
    host(
        "host.set_heater",
        8,
        HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 80.0,
            ramp_c_per_min: 5.0,
        }),
    );
    let mut dev = |name: &str, seq: u32, m: DeviceMsg| {
        out.push((name.to_string(), encode_vec(seq, &m).unwrap()));
    };
    dev("device.ack", 256, DeviceMsg::Ack { seq: 255 });
    dev(
        "device.hello",
        0,
        DeviceMsg::Hello(DeviceInfo {
            protocol: 2,
            firmware: [0, 4, 1],
            serial: 0xDEAD_BEEF,
            max_sample_rate_hz: 20_000,
        }),
    );
    dev(
        "device.gap",
        99,
        DeviceMsg::Gap(Gap {
            run_id: 5,
            first_sample: 1000,
            count: 17,
        }),
    );
    dev(
        "device.fault",
        100,
        DeviceMsg::Fault(FaultReport {
            reason: FaultReason::LeaseExpired,
            uptime_ms: 86_400_000,
            temp_c: f32::NAN,
        }),
    );
    // Protocol v3: the run's analog chain, the last variant.
    dev(
        "device.chain",
        101,
        DeviceMsg::Chain(AnalogChain {
            run_id: 5,
            force_lowpass: LowPass::butterworth(2, 300.0),
        }),
    );
    for n in (0..=MAX_BLOCK_COUNTS).step_by(5) {
        for salt in [0u16, 1] {
            dev(
                &format!("device.samples.{n}.{salt}"),
                n as u32 * 3 + salt as u32,
                DeviceMsg::Samples(sample_block(n, salt)),
            );
        }
    }
    out
}

/// COBS of raw byte strings at the block boundaries (the function is public: the store reads logs
/// with it).
fn cobs_cases() -> Vec<(String, Vec<u8>)> {
    let nonzero = |n: usize| -> Vec<u8> { (0..n).map(|i| (i % 255) as u8 + 1).collect() };
    let mut cases: Vec<(String, Vec<u8>)> = vec![
        ("cobs.one_zero".into(), vec![0]),
        ("cobs.two_zeros".into(), vec![0, 0]),
        ("cobs.trailing_zero".into(), vec![1, 2, 0]),
        ("cobs.leading_zero".into(), vec![0, 1, 2]),
    ];
    for n in [1usize, 253, 254, 255, 508, 509] {
        cases.push((format!("cobs.nonzero.{n}"), nonzero(n)));
        let mut z = nonzero(n);
        z.push(0);
        cases.push((format!("cobs.nonzero_then_zero.{n}"), z));
    }
    cases
        .into_iter()
        .map(|(name, raw)| {
            let mut enc = vec![0u8; raw.len() + raw.len() / 254 + 2];
            let n = cobs_encode(&raw, &mut enc).unwrap();
            enc.truncate(n);
            (name, enc)
        })
        .collect()
}

/// CRC-32 of known inputs, little-endian, as the frames carry it.
fn crc_cases() -> Vec<(String, Vec<u8>)> {
    let long: Vec<u8> = (0..1031u32).map(|i| (i * 7 + 3) as u8).collect();
    let inputs: Vec<(&str, &[u8])> = vec![
        ("crc.empty", b""),
        ("crc.check", b"123456789"),
        ("crc.zero", &[0]),
        ("crc.ones", &[0xFF; 4]),
        ("crc.long", &long),
    ];
    inputs
        .into_iter()
        .map(|(name, data)| (name.to_string(), crc32(data).to_le_bytes().to_vec()))
        .collect()
}

fn everything() -> Vec<(String, Vec<u8>)> {
    let mut all = frames();
    all.extend(cobs_cases());
    all.extend(crc_cases());
    all
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

fn unhex(s: &str) -> Vec<u8> {
    (0..s.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(&s[i..i + 2], 16).unwrap())
        .collect()
}

fn pinned() -> Vec<(String, Vec<u8>)> {
    PINNED
        .lines()
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(|l| {
            let (name, h) = l.split_once(' ').expect("`name hex` per line");
            (name.to_string(), unhex(h))
        })
        .collect()
}

#[test]
fn the_bytes_on_the_wire_are_the_pinned_ones() {
    let now = everything();
    if std::env::var_os("TRIBO_PIN_WRITE").is_some() {
        let mut text = String::from("# tribo-wire pinned bytes: see tests/pinned.rs\n");
        for (name, bytes) in &now {
            text += &format!("{name} {}\n", hex(bytes));
        }
        std::fs::write(
            concat!(env!("CARGO_MANIFEST_DIR"), "/tests/pinned_frames.txt"),
            text,
        )
        .unwrap();
        return;
    }
    let pinned = pinned();
    let names: Vec<&str> = now.iter().map(|(n, _)| n.as_str()).collect();
    let pinned_names: Vec<&str> = pinned.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, pinned_names, "the set of pinned cases changed");
    for ((name, got), (_, want)) in now.iter().zip(&pinned) {
        assert_eq!(
            hex(got),
            hex(want),
            "{name}: the bytes on the wire changed ({} bytes now, {} pinned)",
            got.len(),
            want.len()
        );
    }
}

#[test]
fn the_pinned_cases_cover_every_way_cobs_can_end() {
    // A frame's stuffed bytes end after an implied zero, inside a block, or on a full block
    // (code 0xFF then the 0x01 of an empty last block): the pinned frames must include each, or the
    // pin could miss the one way two encoders differ.
    let frames = frames();
    let full_block_end = frames.iter().any(|(_, f)| {
        let stuffed = &f[..f.len() - 1];
        // walk the codes to the last block
        let mut i = 0;
        let mut last = 0;
        while i < stuffed.len() {
            last = stuffed[i];
            i += last as usize;
        }
        last == 1 && stuffed.len() > 255 && {
            // the block before the last is a full one
            let mut j = 0;
            let mut codes = Vec::new();
            while j < stuffed.len() {
                codes.push(stuffed[j]);
                j += stuffed[j] as usize;
            }
            codes.len() >= 2 && codes[codes.len() - 2] == 0xFF
        }
    });
    assert!(
        full_block_end,
        "no pinned frame ends on a full COBS block: add sample-block lengths"
    );
    // and every pinned frame decodes back to a message
    for (name, f) in &frames {
        let ok = if name.starts_with("host.") {
            decode_one::<HostMsg>(f).is_ok()
        } else {
            decode_one::<DeviceMsg>(f).is_ok()
        };
        assert!(ok, "{name} does not decode");
    }
}

#[test]
fn pinned_cobs_cases_decode_back() {
    for (name, mut enc) in cobs_cases() {
        assert!(!enc.contains(&0), "{name}: a zero in the stuffed bytes");
        let n = cobs_decode_in_place(&mut enc).unwrap_or_else(|| panic!("{name}: no decode"));
        assert!(n <= enc.len(), "{name}");
    }
    // a running CRC equals the one-shot CRC whatever the split
    let data: Vec<u8> = (0..1031u32).map(|i| (i * 7 + 3) as u8).collect();
    for split in [0, 1, 3, 4, 5, 1030, 1031] {
        let mut c = Crc32::new();
        c.update(&data[..split]);
        c.update(&data[split..]);
        assert_eq!(c.finish(), crc32(&data), "split {split}");
    }
}

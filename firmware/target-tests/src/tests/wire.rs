//! The wire protocol on the target: CRC-32 against the standard's vectors, COBS, frames round trip,
//! and the target's frames byte-identical to the host's (same postcard layout, endianness, CRC).

use crate::{check, check_eq, Cx, Outcome};
use tribo_firmware::wire::crc32::{crc32, Crc32};
use tribo_firmware::wire::frame::{cobs_decode_in_place, cobs_encode, decode_one, MAX_FRAME};
use tribo_firmware::wire::{
    BootReport, ChannelSet, Configure, Control, Counts, Decoder, DeviceError, DeviceInfo,
    DeviceMsg, EcrRangeChange, EndReason, EnvelopeShape, ErrorCode, Estimate, FaultReason,
    FaultReport, Field, FrameError, Gap, HeaterFault, HeaterSetpoint, HostMsg, Interlock,
    OnboardResult, PackedBlock, ResetCause, RigState, RunEnd, RunHeader, SampleBlock, SampleClock,
    Status, Verdict, BLOCK_LEN, MAX_BLOCK_COUNTS, PROTOCOL_VERSION,
};
use tribo_firmware::wire::{Encoder, Frame};

/// A message of either direction.
#[derive(Debug, Clone, PartialEq)]
// Like `DeviceMsg` itself: a sample block is the large variant, and there is no heap to box it.
#[allow(clippy::large_enum_variant)]
pub enum Vector {
    Host(HostMsg),
    Device(DeviceMsg),
}

/// Number of [`vector`]s.
pub const VECTORS: usize = 24;

/// Message `i` of the fixed list the host encodes into the bundle and the target encodes again:
/// every variant of both directions that carries data, with edge values (0, maxima, NaN, infinity,
/// a full five-channel block, a non-ASCII boot message).
pub fn vector(i: usize) -> Option<(u32, Vector)> {
    let seq = (i as u32).wrapping_mul(0x9E37_79B9);
    let nan_estimate = Estimate {
        mu0: f32::NAN,
        mu1: f32::INFINITY,
        mu0_se: -0.0,
        mu1_se: f32::MIN_POSITIVE,
    };
    let v = match i {
        0 => Vector::Host(HostMsg::Hello {
            protocol: PROTOCOL_VERSION,
        }),
        1 => Vector::Host(HostMsg::Configure(Configure::real_rig(0.3))),
        2 => Vector::Host(HostMsg::SetHeater(HeaterSetpoint {
            setpoint_c: 80.5,
            ramp_c_per_min: 2.0,
        })),
        3 => Vector::Host(HostMsg::Arm),
        4 => Vector::Host(HostMsg::Release),
        5 => Vector::Host(HostMsg::Pull {
            run_id: 12,
            from_block: u32::MAX,
        }),
        6 => Vector::Host(HostMsg::PullBlocks {
            run_id: 1,
            first: 300,
            count: 65_536,
        }),
        7 => Vector::Host(HostMsg::Heartbeat),
        8 => Vector::Host(HostMsg::Safe),
        9 => Vector::Device(DeviceMsg::Hello(DeviceInfo {
            protocol: PROTOCOL_VERSION,
            firmware: [0, 1, 65_535],
            serial: 0x0123_4567_89AB_CDEF,
            max_sample_rate_hz: 20_000,
        })),
        10 => Vector::Device(DeviceMsg::Ack { seq: u32::MAX }),
        11 => Vector::Device(DeviceMsg::Error(DeviceError {
            code: ErrorCode::Overrun { lost_samples: 1234 },
            about_seq: None,
        })),
        12 => Vector::Device(DeviceMsg::Error(DeviceError {
            code: ErrorCode::Interlock(Interlock::HeaterUnhealthy),
            about_seq: Some(77),
        })),
        13 => Vector::Device(DeviceMsg::Status(Status {
            state: RigState::Running,
            run_id: 3,
            temp_c: 24.75,
            heater_setpoint_c: Some(60.0),
            heater_duty: 0.125,
            heater_fault: Some(HeaterFault::OpenThermocouple),
            magnet_on: true,
            log10_ecr_ohm: f32::NAN,
            ecr_range: 4,
            samples: 1_000_000,
            overruns: 0,
            uptime_ms: u64::MAX,
            last_fault: Some(FaultReport {
                reason: FaultReason::Heater(HeaterFault::Runaway),
                uptime_ms: 1 << 35,
                temp_c: 61.5,
            }),
            faults: 2,
            reset_cause: ResetCause::Watchdog,
            control: Control::StandAlone,
        })),
        14 => Vector::Device(DeviceMsg::RunStarted(RunHeader {
            run_id: 7,
            config: Configure::real_rig(0.05),
            temp_c: 25.5,
            t_us: 1 << 40,
            clock: SampleClock {
                timer_hz: 200_000_000,
                ticks_per_sample: 20_002,
            },
        })),
        15 => Vector::Device(DeviceMsg::Samples(full_block())),
        16 => Vector::Device(DeviceMsg::Result(OnboardResult {
            run_id: 7,
            verdict: Verdict::EstimatorsDisagree,
            cycles: 412,
            frequency_hz: 26.97,
            initial_amplitude_m: 667e-6,
            duration_s: f32::INFINITY,
            best: Estimate {
                mu0: 0.05,
                mu1: 0.0011,
                mu0_se: 1e-5,
                mu1_se: 2e-6,
            },
            averaging: nan_estimate,
            decrement: Estimate::default(),
            shape: EnvelopeShape::Mixed,
            curvature: -1.5e-3,
        })),
        17 => Vector::Device(DeviceMsg::RunEnded(RunEnd {
            run_id: 7,
            blocks: 469,
            samples: 30_000,
            overruns: 2,
            reason: EndReason::Fault(HeaterFault::OverTemperature),
        })),
        18 => Vector::Device(DeviceMsg::Fault(FaultReport {
            reason: FaultReason::LeaseExpired,
            uptime_ms: 123_456_789,
            temp_c: f32::NAN,
        })),
        19 => {
            let mut message = heapless::String::new();
            let _ = message.push_str("panicked at app.rs:42: état inattendu ✓");
            Vector::Device(DeviceMsg::Boot(BootReport {
                cause: ResetCause::Panic,
                message,
            }))
        }
        20 => Vector::Device(DeviceMsg::Gap(Gap {
            run_id: 7,
            first_sample: 4096,
            count: 17,
        })),
        21 => {
            let mut data = heapless::Vec::new();
            for k in 0..40u8 {
                let _ = data.push(k.wrapping_mul(37));
            }
            Vector::Device(DeviceMsg::Packed(PackedBlock {
                run_id: 7,
                block: 2,
                first_sample: 128,
                t_us: 12_800,
                channels: ChannelSet::VIBROMETER,
                samples: 64,
                ecr_range: 3,
                temp_c: 25.0,
                log10_ecr_ohm: 3.5,
                data,
            }))
        }
        22 => Vector::Device(DeviceMsg::EcrRange(EcrRangeChange {
            run_id: 7,
            first_sample: 640,
            range: 2,
            settling: 3,
        })),
        23 => Vector::Device(DeviceMsg::Error(DeviceError {
            code: ErrorCode::OutOfRange(Field::Calibration),
            about_seq: Some(0),
        })),
        _ => return None,
    };
    Some((seq, v))
}

/// A full five-channel block whose counts sweep the 16-bit range (0 and 65535 included).
fn full_block() -> SampleBlock {
    let mut counts = Counts::default();
    for k in 0..MAX_BLOCK_COUNTS as u32 {
        let c = match k {
            0 => 0,
            1 => u16::MAX,
            _ => (k.wrapping_mul(40_503) >> 3) as u16,
        };
        let _ = counts.push(c);
    }
    SampleBlock {
        run_id: 7,
        block: 3,
        first_sample: 3 * BLOCK_LEN as u32,
        t_us: 19_200,
        channels: ChannelSet::ALL,
        ecr_range: 1,
        log10_ecr_ohm: f32::NAN,
        temp_c: 25.0,
        counts,
    }
}

/// Frames `v` with `seq` into `out`; returns the length.
pub fn encode(enc: &mut Encoder, seq: u32, v: &Vector, out: &mut [u8]) -> Option<usize> {
    let r = match v {
        Vector::Host(m) => enc.encode(seq, m, out),
        Vector::Device(m) => enc.encode(seq, m, out),
    };
    r.ok().map(|b| b.len())
}

/// CRC-32/ISO-HDLC check values (the catalogue's check value for "123456789", and values zlib,
/// Ethernet and PNG all give).
pub fn crc_known_vectors(_cx: &mut Cx) -> Outcome {
    let known: [(&[u8], u32); 6] = [
        (b"", 0x0000_0000),
        (b"123456789", 0xCBF4_3926),
        (b"a", 0xE8B7_BE43),
        (b"The quick brown fox jumps over the lazy dog", 0x414F_A339),
        (&[0u8], 0xD202_EF8D),
        (&[0xFFu8; 4], 0xFFFF_FFFF),
    ];
    for (data, want) in known {
        check_eq!(crc32(data), want, "CRC-32 of {:?}", data);
    }
    // A running CRC fed in pieces equals the one-shot CRC.
    let data: [u8; 300] = core::array::from_fn(|i| (i as u32 * 7 + 3) as u8);
    for split in [0, 1, 17, 299, 300] {
        let mut c = Crc32::new();
        c.update(&data[..split]);
        c.update(&data[split..]);
        check_eq!(c.finish(), crc32(&data), "split at {split}");
    }
    Ok(())
}

/// COBS: no zero byte in the output, and it decodes back, for runs of zeros and of 254+ non-zeros.
pub fn cobs_round_trip(_cx: &mut Cx) -> Outcome {
    let mut src = [0u8; 600];
    let mut enc = [0u8; 610];
    for pattern in 0..4u32 {
        for (i, b) in src.iter_mut().enumerate() {
            *b = match pattern {
                0 => 0,
                1 => 1 + (i % 255) as u8,
                2 => (i % 7) as u8,
                _ => (i as u32).wrapping_mul(2_654_435_761).to_le_bytes()[3],
            };
        }
        for len in [0usize, 1, 253, 254, 255, 508, 600] {
            let n = cobs_encode(&src[..len], &mut enc);
            check!(n.is_some(), "pattern {pattern}, length {len}: no room");
            let n = n.unwrap_or(0);
            check!(!enc[..n].contains(&0), "zero in the stuffed bytes");
            let m = cobs_decode_in_place(&mut enc[..n]);
            check_eq!(m, Some(len), "pattern {pattern}");
            check!(enc[..len] == src[..len], "pattern {pattern}, length {len}");
        }
    }
    Ok(())
}

/// Every vector encodes, decodes to the same message (bytes re-encoded equal: `NaN` is not equal to
/// itself), and the frames are byte-identical to the ones the host encoded.
pub fn frames_match_the_host(cx: &mut Cx) -> Outcome {
    let host = cx.bundle()?.header.frames.0;
    let mut enc = Encoder::new();
    let mut out = [0u8; MAX_FRAME];
    let mut again = [0u8; MAX_FRAME];
    let mut rest = host;
    let mut count = 0;
    while let Some((seq, v)) = vector(count) {
        let n = encode(&mut enc, seq, &v, &mut out);
        check!(n.is_some(), "vector {count} does not encode: {v:?}");
        let n = n.unwrap_or(0);
        // the host's frame: up to and including the next zero
        let end = rest.iter().position(|&b| b == 0).map(|p| p + 1);
        check!(end.is_some(), "host frames end before vector {count}");
        let (theirs, tail) = rest.split_at(end.unwrap_or(0));
        rest = tail;
        check!(
            &out[..n] == theirs,
            "vector {count}: target frame ({n} bytes) differs from the host's ({} bytes): {v:?}",
            theirs.len()
        );
        // decode on the target, encode again: same bytes
        let back = match &v {
            Vector::Host(_) => decode_one::<HostMsg>(theirs).map(|f| (f.seq, Vector::Host(f.msg))),
            Vector::Device(_) => {
                decode_one::<DeviceMsg>(theirs).map(|f| (f.seq, Vector::Device(f.msg)))
            }
        };
        check!(back.is_ok(), "vector {count}: {:?}", back.err());
        if let Ok((s, m)) = back {
            check_eq!(s, seq);
            let k = encode(&mut enc, s, &m, &mut again);
            check!(
                k == Some(n) && again[..n] == out[..n],
                "vector {count} re-encoded differs"
            );
        }
        count += 1;
    }
    check_eq!(count, VECTORS);
    check!(rest.is_empty(), "{} host bytes left over", rest.len());
    Ok(())
}

/// The stream decoder: frames split anywhere, garbage between them, a flipped bit, a truncated frame
/// and an overlong one each cost one error, and the next frame decodes.
pub fn decoder_resynchronises(_cx: &mut Cx) -> Outcome {
    let mut enc = Encoder::new();
    let mut good = [0u8; MAX_FRAME];
    // (a NaN would not compare equal to itself once decoded)
    let mut blk = full_block();
    blk.log10_ecr_ohm = 2.5;
    let msg = DeviceMsg::Samples(blk);
    let n = enc.encode(41, &msg, &mut good).map(|b| b.len());
    check!(n.is_ok());
    let n = n.unwrap_or(0);
    let mut dec: Decoder<DeviceMsg> = Decoder::new();
    let mut frames = 0u32;
    let mut errors = heapless::Vec::<FrameError, 8>::new();
    let mut feed = |bytes: &[u8], dec: &mut Decoder<DeviceMsg>| {
        for &b in bytes {
            match dec.push(b) {
                Some(Ok(Frame { seq: 41, msg: m })) if m == msg => frames += 1,
                Some(Ok(_)) => frames += 1000,
                Some(Err(e)) => {
                    let _ = errors.push(e);
                }
                None => {}
            }
        }
    };
    // split in odd pieces
    for piece in good[..n].chunks(7) {
        feed(piece, &mut dec);
    }
    // garbage, then a good frame
    feed(&[1, 2, 3, 0], &mut dec);
    feed(&good[..n], &mut dec);
    // one flipped bit
    let mut bad = good;
    bad[n / 2] ^= 0x10;
    if bad[n / 2] == 0 {
        bad[n / 2] = 0x55;
    }
    feed(&bad[..n], &mut dec);
    // truncated: the frame's tail is lost, the next frame's zero closes it
    feed(&good[..n / 3], &mut dec);
    feed(&[0], &mut dec);
    // overlong: no zero for more than a frame
    let junk = [0x5Au8; 64];
    for _ in 0..(MAX_FRAME / 64 + 2) {
        feed(&junk, &mut dec);
    }
    feed(&[0], &mut dec);
    feed(&good[..n], &mut dec);
    check_eq!(frames, 3, "good frames decoded (errors {:?})", errors);
    check_eq!(errors.len(), 4, "errors {:?}", errors);
    check!(
        matches!(
            errors[0],
            FrameError::Short | FrameError::Cobs | FrameError::Crc
        ),
        "garbage: {:?}",
        errors[0]
    );
    check!(
        matches!(errors[1], FrameError::Crc | FrameError::Cobs),
        "flipped bit: {:?}",
        errors[1]
    );
    check_eq!(errors[3], FrameError::Overflow);
    Ok(())
}

/// What framing costs on the target: a full five-channel block frame encoded, decoded byte by byte,
/// and the CRC and COBS passes alone over the same bytes.
pub fn framing_costs(cx: &mut Cx) -> Outcome {
    let mut enc = Encoder::new();
    let mut out = [0u8; MAX_FRAME];
    let msg = DeviceMsg::Samples(full_block());
    let mut n = 0;
    let encode = cx.count(|| n = enc.encode(7, &msg, &mut out).map_or(0, |b| b.len()));
    check!(n > 0);
    let mut dec: Decoder<DeviceMsg> = Decoder::new();
    let mut decoded = false;
    let decode = cx.count(|| {
        for &b in &out[..n] {
            if let Some(Ok(_)) = dec.push(b) {
                decoded = true;
            }
        }
    });
    check!(decoded);
    let mut crc = 0;
    let crc_cost = cx.count(|| crc = crc32(&out[..n]));
    check!(crc != 0);
    let mut stuffed = [0u8; MAX_FRAME + 8];
    let mut m = None;
    let cobs = cx.count(|| m = cobs_encode(&out[..n - 1], &mut stuffed));
    check!(m.is_some());
    cx.note(format_args!("a full block frame is {n} bytes"));
    let r1 = cx.figure("wire.encode_full_block", encode, "instructions", None);
    let r2 = cx.figure("wire.decode_full_block", decode, "instructions", None);
    let r3 = cx.figure("wire.crc32_of_that_frame", crc_cost, "instructions", None);
    let r4 = cx.figure("wire.cobs_of_that_frame", cobs, "instructions", None);
    r1.and(r2).and(r3).and(r4)
}

//! Round trips of every message, and the decoder against hostile byte streams.

use proptest::prelude::*;
use tribo_wire::frame::{cobs_decode_in_place, cobs_encode, decode_one, encode_vec, MAX_FRAME};
use tribo_wire::*;

// ---------------------------------------------------------------- strategies for every message

fn any_f32() -> impl Strategy<Value = f32> {
    // Finite values only: NaN != NaN would make equality-based round trips meaningless. NaN handling
    // is tested separately (it must survive the wire bit for bit).
    prop_oneof![
        -1e6f32..1e6,
        Just(0.0),
        Just(-0.0),
        Just(f32::MAX),
        Just(f32::MIN_POSITIVE)
    ]
}

fn channel_set() -> impl Strategy<Value = ChannelSet> {
    any::<u8>().prop_map(ChannelSet)
}

fn cal() -> impl Strategy<Value = ChannelCal> {
    (any_f32(), any_f32()).prop_map(|(gain, zero)| ChannelCal { gain, zero })
}

fn configure() -> impl Strategy<Value = Configure> {
    (
        (any_f32(), any_f32(), any_f32()),
        any::<u32>(),
        channel_set(),
        any_f32(),
        any_f32(),
        prop::array::uniform5(cal()),
    )
        .prop_map(
            |((m, k, n), rate, channels, x0, dur, calibration)| Configure {
                rig: RigConstants {
                    mass_kg: m,
                    stiffness_n_per_m: k,
                    load_n: n,
                },
                sample_rate_hz: rate,
                channels,
                initial_amplitude_m: x0,
                max_duration_s: dur,
                calibration,
            },
        )
}

fn field() -> impl Strategy<Value = Field> {
    prop::sample::select(vec![
        Field::Mass,
        Field::Stiffness,
        Field::Load,
        Field::SampleRate,
        Field::Channels,
        Field::InitialAmplitude,
        Field::MaxDuration,
        Field::Calibration,
        Field::HeaterSetpoint,
        Field::HeaterRamp,
        Field::RunId,
    ])
}

fn heater_fault() -> impl Strategy<Value = HeaterFault> {
    prop::sample::select(vec![
        HeaterFault::OverTemperature,
        HeaterFault::OpenThermocouple,
        HeaterFault::ShortedThermocouple,
        HeaterFault::NoReading,
        HeaterFault::BadConverterData,
        HeaterFault::ThermocoupleRange,
        HeaterFault::ColdJunction,
        HeaterFault::HeatingFailed,
        HeaterFault::Runaway,
    ])
}

fn fault_report() -> impl Strategy<Value = FaultReport> {
    (
        prop_oneof![
            heater_fault().prop_map(FaultReason::Heater),
            Just(FaultReason::LeaseExpired),
            Just(FaultReason::MagnetHoldTime),
            Just(FaultReason::StandAloneExpired),
        ],
        any::<u64>(),
        any_f32(),
    )
        .prop_map(|(reason, uptime_ms, temp_c)| FaultReport {
            reason,
            uptime_ms,
            temp_c,
        })
}

fn reset_cause() -> impl Strategy<Value = ResetCause> {
    prop::sample::select(ResetCause::ALL.to_vec())
}

fn error_code() -> impl Strategy<Value = ErrorCode> {
    prop_oneof![
        Just(ErrorCode::Malformed),
        any::<u16>().prop_map(|device| ErrorCode::ProtocolMismatch { device }),
        field().prop_map(ErrorCode::OutOfRange),
        Just(ErrorCode::NotConfigured),
        Just(ErrorCode::Busy),
        prop::sample::select(vec![
            Interlock::NotArmed,
            Interlock::NotSampling,
            Interlock::HeaterUnhealthy,
            Interlock::MagnetOff
        ])
        .prop_map(ErrorCode::Interlock),
        heater_fault().prop_map(ErrorCode::Heater),
        Just(ErrorCode::NoRun),
        any::<u32>().prop_map(|lost_samples| ErrorCode::Overrun { lost_samples }),
        Just(ErrorCode::HoldTimeExceeded),
        any::<u32>().prop_map(|wait_ms| ErrorCode::MagnetCooling { wait_ms }),
    ]
}

fn estimate() -> impl Strategy<Value = Estimate> {
    (any_f32(), any_f32(), any_f32(), any_f32()).prop_map(|(mu0, mu1, mu0_se, mu1_se)| Estimate {
        mu0,
        mu1,
        mu0_se,
        mu1_se,
    })
}

fn host_msg() -> impl Strategy<Value = HostMsg> {
    prop_oneof![
        any::<u16>().prop_map(|protocol| HostMsg::Hello { protocol }),
        configure().prop_map(HostMsg::Configure),
        (any_f32(), any_f32()).prop_map(|(setpoint_c, ramp_c_per_min)| HostMsg::SetHeater(
            HeaterSetpoint {
                setpoint_c,
                ramp_c_per_min
            }
        )),
        Just(HostMsg::HeaterOff),
        Just(HostMsg::Arm),
        Just(HostMsg::Disarm),
        Just(HostMsg::Release),
        Just(HostMsg::Abort),
        Just(HostMsg::Status),
        (any::<u32>(), any::<u32>())
            .prop_map(|(run_id, from_block)| HostMsg::Pull { run_id, from_block }),
        Just(HostMsg::Heartbeat),
        Just(HostMsg::Safe),
    ]
}

fn sample_block() -> impl Strategy<Value = SampleBlock> {
    (
        (any::<u32>(), any::<u32>(), any::<u32>(), any::<u64>()),
        (1u8..32).prop_map(ChannelSet),
        any::<u8>(),
        any_f32(),
        any_f32(),
        prop::collection::vec(any::<u16>(), 0..=MAX_BLOCK_COUNTS),
    )
        .prop_map(
            |((run_id, block, first_sample, t_us), channels, ecr_range, l, t, counts)| {
                SampleBlock {
                    run_id,
                    block,
                    first_sample,
                    t_us,
                    channels,
                    ecr_range,
                    log10_ecr_ohm: l,
                    temp_c: t,
                    counts: Counts::from_slice(&counts).unwrap(),
                }
            },
        )
}

fn device_msg() -> impl Strategy<Value = DeviceMsg> {
    let verdict = prop::sample::select(vec![
        Verdict::Ok,
        Verdict::TooFewCycles,
        Verdict::NoOscillation,
        Verdict::Saturated,
        Verdict::EstimatorsDisagree,
        Verdict::Aborted,
        Verdict::NotAnalysed,
    ]);
    let shape = prop::sample::select(vec![
        EnvelopeShape::Straight,
        EnvelopeShape::Convex,
        EnvelopeShape::Concave,
        EnvelopeShape::Mixed,
    ]);
    let state = prop::sample::select(vec![
        RigState::Idle,
        RigState::Configured,
        RigState::Armed,
        RigState::Running,
        RigState::Finished,
        RigState::Fault,
    ]);
    let reason = prop_oneof![
        Just(EndReason::Stopped),
        Just(EndReason::MaxDuration),
        Just(EndReason::Aborted),
        heater_fault().prop_map(EndReason::Fault),
        Just(EndReason::Overrun),
    ];
    prop_oneof![
        (any::<u16>(), any::<[u16; 3]>(), any::<u64>(), any::<u32>())
            .prop_map(
                |(protocol, firmware, serial, max_sample_rate_hz)| DeviceMsg::Hello(DeviceInfo {
                    protocol,
                    firmware,
                    serial,
                    max_sample_rate_hz
                })
            )
            .boxed(),
        any::<u32>().prop_map(|seq| DeviceMsg::Ack { seq }),
        (error_code(), any::<Option<u32>>())
            .prop_map(|(code, about_seq)| DeviceMsg::Error(DeviceError { code, about_seq })),
        (
            state,
            any::<u32>(),
            any_f32(),
            prop::option::of(any_f32()),
            any_f32(),
            prop::option::of(heater_fault()),
            any::<bool>(),
            any_f32(),
            any::<u8>(),
            (any::<u32>(), any::<u32>(), any::<u64>()),
            (
                prop::option::of(fault_report()),
                any::<u32>(),
                reset_cause(),
                prop::sample::select(vec![Control::None, Control::Host, Control::StandAlone])
            )
        )
            .prop_map(
                |(
                    state,
                    run_id,
                    temp_c,
                    sp,
                    duty,
                    fault,
                    magnet_on,
                    l,
                    r,
                    (s, o, u),
                    (last_fault, faults, reset_cause, control),
                )| {
                    DeviceMsg::Status(Status {
                        state,
                        run_id,
                        temp_c,
                        heater_setpoint_c: sp,
                        heater_duty: duty,
                        heater_fault: fault,
                        magnet_on,
                        log10_ecr_ohm: l,
                        ecr_range: r,
                        samples: s,
                        overruns: o,
                        uptime_ms: u,
                        last_fault,
                        faults,
                        reset_cause,
                        control,
                    })
                }
            )
            .boxed(),
        (
            any::<u32>(),
            configure(),
            any_f32(),
            any::<u64>(),
            (any::<u32>(), any::<u32>())
        )
            .prop_map(
                |(run_id, config, temp_c, t_us, (timer_hz, ticks_per_sample))| {
                    DeviceMsg::RunStarted(RunHeader {
                        run_id,
                        config,
                        temp_c,
                        t_us,
                        clock: SampleClock {
                            timer_hz,
                            ticks_per_sample,
                        },
                    })
                }
            )
            .boxed(),
        (any::<u32>(), any::<u32>(), any::<u32>())
            .prop_map(|(run_id, first_sample, count)| DeviceMsg::Gap(Gap {
                run_id,
                first_sample,
                count
            }))
            .boxed(),
        (any::<u32>(), any::<u32>(), any::<u8>(), any::<u16>())
            .prop_map(|(run_id, first_sample, range, settling)| {
                DeviceMsg::EcrRange(EcrRangeChange {
                    run_id,
                    first_sample,
                    range,
                    settling,
                })
            })
            .boxed(),
        sample_block().prop_map(DeviceMsg::Samples).boxed(),
        (
            (
                any::<u32>(),
                verdict,
                any::<u16>(),
                any_f32(),
                any_f32(),
                any_f32()
            ),
            (estimate(), estimate(), estimate()),
            shape,
            any_f32()
        )
            .prop_map(
                |((run_id, verdict, cycles, f, x0, d), (best, averaging, decrement), shape, c)| {
                    DeviceMsg::Result(OnboardResult {
                        run_id,
                        verdict,
                        cycles,
                        frequency_hz: f,
                        initial_amplitude_m: x0,
                        duration_s: d,
                        best,
                        averaging,
                        decrement,
                        shape,
                        curvature: c,
                    })
                }
            )
            .boxed(),
        (
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            any::<u32>(),
            reason
        )
            .prop_map(
                |(run_id, blocks, samples, overruns, reason)| DeviceMsg::RunEnded(RunEnd {
                    run_id,
                    blocks,
                    samples,
                    overruns,
                    reason
                })
            )
            .boxed(),
        fault_report().prop_map(DeviceMsg::Fault).boxed(),
        (reset_cause(), "[ -~é]{0,40}")
            .prop_map(|(cause, m)| {
                let mut message = heapless::String::new();
                for ch in m.chars() {
                    if message.push(ch).is_err() {
                        break;
                    }
                }
                DeviceMsg::Boot(BootReport { cause, message })
            })
            .boxed(),
    ]
}

// ---------------------------------------------------------------- properties

fn decode_stream<M: serde::de::DeserializeOwned>(bytes: &[u8]) -> (Vec<Frame<M>>, Vec<FrameError>) {
    let mut d = Decoder::<M>::new();
    let (mut ok, mut bad) = (Vec::new(), Vec::new());
    d.feed(bytes, |r| match r {
        Ok(f) => ok.push(f),
        Err(e) => bad.push(e),
    });
    (ok, bad)
}

/// 2000 cases per property by default; `PROPTEST_CASES=1000000 cargo test -p tribo-wire --release`
/// runs the same properties at scale.
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
    fn every_host_message_round_trips(seq in any::<u32>(), msg in host_msg()) {
        let bytes = encode_vec(seq, &msg).unwrap();
        prop_assert!(bytes.len() <= MAX_FRAME);
        prop_assert_eq!(bytes.iter().filter(|&&b| b == 0).count(), 1, "one zero, at the end");
        prop_assert_eq!(decode_one::<HostMsg>(&bytes), Ok(Frame { seq, msg }));
    }

    #[test]
    fn every_device_message_round_trips(seq in any::<u32>(), msg in device_msg()) {
        let bytes = encode_vec(seq, &msg).unwrap();
        prop_assert!(bytes.len() <= MAX_FRAME);
        let (ok, bad) = decode_stream::<DeviceMsg>(&bytes);
        prop_assert!(bad.is_empty());
        prop_assert_eq!(ok, vec![Frame { seq, msg }]);
    }

    #[test]
    fn cobs_round_trips_and_never_emits_zero(data in prop::collection::vec(any::<u8>(), 0..2000)) {
        let mut enc = vec![0u8; data.len() + data.len() / 254 + 2];
        let n = cobs_encode(&data, &mut enc).unwrap();
        prop_assert!(!enc[..n].contains(&0));
        let back = cobs_decode_in_place(&mut enc[..n]).unwrap();
        prop_assert_eq!(&enc[..back], &data[..]);
    }

    /// Arbitrary bytes never panic the decoder, and whatever follows them decodes.
    #[test]
    fn garbage_then_frames_resynchronises(
        garbage in prop::collection::vec(any::<u8>(), 0..3000),
        msgs in prop::collection::vec(device_msg(), 1..5),
    ) {
        let mut stream = garbage.clone();
        stream.push(0); // the end of whatever the garbage was
        for (i, m) in msgs.iter().enumerate() {
            stream.extend(encode_vec(i as u32, m).unwrap());
        }
        let (ok, _) = decode_stream::<DeviceMsg>(&stream);
        // Garbage could by chance form a valid frame (its CRC would have to match): only demand that
        // the real frames all arrive, last and in order.
        let tail: Vec<_> = ok.iter().rev().take(msgs.len()).rev().cloned().collect();
        let want: Vec<_> = msgs.into_iter().enumerate().map(|(i, msg)| Frame { seq: i as u32, msg }).collect();
        prop_assert_eq!(tail, want);
    }

    /// A frame cut short loses itself, never the next one.
    #[test]
    fn truncated_frame_costs_only_itself(
        a in device_msg(), b in device_msg(), cut in any::<prop::sample::Index>(),
    ) {
        let fa = encode_vec(1, &a).unwrap();
        let keep = cut.index(fa.len() - 1); // drop at least the closing zero
        let mut stream = fa[..keep].to_vec();
        stream.push(0); // the line went quiet, then the sender resynchronised
        stream.extend(encode_vec(2, &b).unwrap());
        let (ok, bad) = decode_stream::<DeviceMsg>(&stream);
        prop_assert_eq!(ok, vec![Frame { seq: 2, msg: b }]);
        prop_assert!(keep == 0 || bad.len() == 1, "the truncated frame is reported: {:?}", bad);
    }

    /// Any single flipped bit inside a frame is caught (the CRC or COBS sees it), and the stream
    /// carries on.
    #[test]
    fn flipped_bit_is_detected(msg in device_msg(), next in host_msg(), bit in any::<prop::sample::Index>()) {
        let mut f = encode_vec(7, &msg).unwrap();
        let body = f.len() - 1;
        let i = bit.index(body * 8);
        f[i / 8] ^= 1 << (i % 8);
        let mut stream = f;
        stream.push(0);
        stream.extend(encode_vec(8, &next).unwrap());
        let (ok, bad) = decode_stream::<HostMsg>(&stream);
        prop_assert!(!bad.is_empty(), "corruption went unnoticed");
        prop_assert_eq!(ok.last(), Some(&Frame { seq: 8, msg: next }));
    }

    /// Purely random input: never a panic, and never a "valid" frame whose CRC would not check.
    #[test]
    fn random_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..5000)) {
        let (ok, _) = decode_stream::<HostMsg>(&bytes);
        let (ok2, _) = decode_stream::<DeviceMsg>(&bytes);
        // A 32-bit CRC makes a random valid frame about a 1 in 4e9 event per candidate.
        prop_assert!(ok.len() + ok2.len() <= 1);
    }

    #[test]
    fn counts_reject_odd_or_oversized_byte_strings(len in 0usize..(2 * MAX_BLOCK_COUNTS + 40)) {
        // Hand-build a postcard byte string (varint length, then bytes) and decode it as Counts.
        let mut buf = Vec::new();
        let mut l = len as u32;
        loop {
            let b = (l & 0x7F) as u8;
            l >>= 7;
            if l == 0 { buf.push(b); break } else { buf.push(b | 0x80) }
        }
        buf.extend(std::iter::repeat_n(0xAB, len));
        let r = postcard::from_bytes::<Counts>(&buf);
        prop_assert_eq!(r.is_ok(), len % 2 == 0 && len <= 2 * MAX_BLOCK_COUNTS);
    }
}

// ---------------------------------------------------------------- examples

#[test]
fn full_sample_block_fits_in_a_frame() {
    let counts: Vec<u16> = (0..MAX_BLOCK_COUNTS as u16)
        .map(|i| i.wrapping_mul(977))
        .collect();
    let blk = SampleBlock {
        run_id: u32::MAX,
        block: u32::MAX,
        first_sample: u32::MAX,
        t_us: u64::MAX,
        channels: ChannelSet::ALL,
        ecr_range: 7,
        log10_ecr_ohm: 7.0,
        temp_c: 25.0,
        counts: Counts::from_slice(&counts).unwrap(),
    };
    assert_eq!(blk.samples(), BLOCK_LEN);
    assert!(blk.is_consistent());
    let f = encode_vec(u32::MAX, &DeviceMsg::Samples(blk.clone())).unwrap();
    assert!(f.len() <= MAX_FRAME, "{} bytes", f.len());
    // Interleaving: sample 3, force channel.
    assert_eq!(blk.sample(3).unwrap()[2], counts[3 * 5 + 2]);
    let force: Vec<u16> = blk.channel(Channel::Force).collect();
    assert_eq!(force.len(), BLOCK_LEN);
    assert_eq!(force[10], counts[10 * 5 + 2]);
}

#[test]
fn channel_positions_follow_the_channel_order() {
    let set = ChannelSet(0b10110); // velocity, force, temperature
    assert_eq!(set.position(Channel::Displacement), None);
    assert_eq!(set.position(Channel::Velocity), Some(0));
    assert_eq!(set.position(Channel::Force), Some(1));
    assert_eq!(set.position(Channel::Ecr), None);
    assert_eq!(set.position(Channel::Temperature), Some(2));
    assert_eq!(set.len(), 3);
    // The constant-time position agrees with the iteration order for every set.
    for bits in 0..32u8 {
        let set = ChannelSet(bits);
        for (i, c) in set.iter().enumerate() {
            assert_eq!(set.position(c), Some(i));
        }
        assert_eq!(set.iter().count(), set.len());
    }
}

#[test]
fn nan_survives_the_wire_bit_for_bit() {
    let msg = HostMsg::SetHeater(HeaterSetpoint {
        setpoint_c: f32::NAN,
        ramp_c_per_min: 1.0,
    });
    let f = decode_one::<HostMsg>(&encode_vec(0, &msg).unwrap()).unwrap();
    match f.msg {
        HostMsg::SetHeater(sp) => {
            assert!(sp.setpoint_c.is_nan());
            // …and is refused by the shared range check.
            assert_eq!(sp.validate(), Err(Field::HeaterSetpoint));
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn hello_is_variant_zero_with_protocol_first() {
    // The compatibility rule: a future host must read any firmware's hello. Variant 0, then the
    // protocol number as a varint, whatever else DeviceInfo grows.
    let info = DeviceInfo {
        protocol: 300,
        firmware: [1, 2, 3],
        serial: 9,
        max_sample_rate_hz: 1,
    };
    let mut buf = [0u8; 64];
    let body = postcard::to_slice(&DeviceMsg::Hello(info), &mut buf).unwrap();
    assert_eq!(&body[..3], &[0, 0xAC, 0x02]);
    let body = postcard::to_slice(&HostMsg::Hello { protocol: 1 }, &mut buf).unwrap();
    assert_eq!(body, &[0, 1]);
}

#[test]
fn protocol_mismatch_says_what_to_do() {
    assert!(check_protocol(PROTOCOL_VERSION).is_ok());
    let newer = check_protocol(PROTOCOL_VERSION + 1)
        .unwrap_err()
        .to_string();
    assert!(newer.contains("update tribo"), "{newer}");
    let older = check_protocol(PROTOCOL_VERSION - 1)
        .unwrap_err()
        .to_string();
    assert!(older.contains("reflash"), "{older}");
}

#[test]
fn real_rig_configuration_is_valid_and_each_limit_bites() {
    let ok = Configure::real_rig(0.3);
    assert_eq!(ok.validate(), Ok(()));
    let omega = ok.omega();
    assert!((omega - (1150.0f32 / 0.04).sqrt()).abs() < 1e-3, "{omega}");
    type Edit = fn(&mut Configure);
    let cases: [(Edit, Field); 10] = [
        (|c| c.rig.mass_kg = f32::NAN, Field::Mass),
        (|c| c.rig.stiffness_n_per_m = -1.0, Field::Stiffness),
        (|c| c.rig.load_n = 0.71, Field::Load),
        (|c| c.sample_rate_hz = 50_000, Field::SampleRate),
        (|c| c.channels = ChannelSet(0b1), Field::Channels),
        (|c| c.channels = ChannelSet(0b100011), Field::Channels),
        (|c| c.initial_amplitude_m = 2e-3, Field::InitialAmplitude),
        (|c| c.max_duration_s = f32::INFINITY, Field::MaxDuration),
        (|c| c.calibration[2].gain = 0.0, Field::Calibration),
        (|c| c.calibration[4].zero = 70000.0, Field::Calibration),
    ];
    for (edit, field) in cases {
        let mut c = ok;
        edit(&mut c);
        assert_eq!(c.validate(), Err(field));
    }
}

#[test]
fn calibration_round_trips_within_half_a_count_and_saturates() {
    let cal = ChannelCal::bipolar(2e-3);
    for i in -1000..=1000 {
        let x = i as f32 * 1.9e-6;
        let back = cal.to_si(cal.to_count(x));
        assert!((back - x).abs() <= cal.gain * 0.5 + 1e-9, "{x} -> {back}");
    }
    assert_eq!(cal.to_count(1.0), u16::MAX);
    assert_eq!(cal.to_count(-1.0), 0);
    assert_eq!(cal.to_count(f32::NAN), 32768);
}

#[test]
fn sqrt_matches_std() {
    for i in 0..10_000 {
        let x = (i as f32 * 0.731).powf(2.3) + 1e-30;
        let (a, b) = (sqrt_f32(x), x.sqrt());
        assert!((a - b).abs() <= b * 2.0 * f32::EPSILON, "{x}: {a} vs {b}");
    }
    assert!(sqrt_f32(-1.0).is_nan());
    assert_eq!(sqrt_f32(0.0), 0.0);
}

#[test]
fn overlong_garbage_is_reported_once_and_skipped() {
    let mut stream = vec![0x55u8; 3 * MAX_FRAME];
    stream.push(0);
    stream.extend(encode_vec(5, &HostMsg::Arm).unwrap());
    let (ok, bad) = decode_stream::<HostMsg>(&stream);
    assert_eq!(bad, vec![FrameError::Overflow]);
    assert_eq!(
        ok,
        vec![Frame {
            seq: 5,
            msg: HostMsg::Arm
        }]
    );
}

#[test]
fn a_device_frame_is_not_taken_for_a_host_frame() {
    // Same transport, wrong direction: the CRC is fine, the body is not a HostMsg of this shape.
    let blk = DeviceMsg::Result(OnboardResult {
        run_id: 1,
        verdict: Verdict::Ok,
        cycles: 12,
        frequency_hz: 26.9,
        initial_amplitude_m: 6.67e-4,
        duration_s: 2.0,
        best: Estimate::default(),
        averaging: Estimate::default(),
        decrement: Estimate::default(),
        shape: EnvelopeShape::Convex,
        curvature: 0.0,
    });
    let f = encode_vec(1, &blk).unwrap();
    assert_eq!(decode_one::<HostMsg>(&f), Err(FrameError::Decode));
}

#[test]
fn sample_clock_times_are_exact_rationals_at_any_index() {
    // 200 MHz / 20 002 ticks: the timer's nearest rate to 9 999 S/s, not 9 999 S/s.
    let c = SampleClock {
        timer_hz: 200_000_000,
        ticks_per_sample: 20_002,
    };
    assert!(!c.is_exactly(9_999));
    assert!((c.rate_hz() - 200e6 / 20_002.0).abs() < 1e-9);
    // One hour of samples: the integer and fractional parts apart keep it exact to f64 rounding,
    // where i as f64 / rate would drift by an ulp per operation.
    let i = 36_000_000u64;
    let exact = i as f64 * 20_002.0 / 200e6;
    assert!((c.time_s(i) - exact).abs() <= 1e-12 * exact);
    assert_eq!(c.time_us(10_000), 1_000_100);
    // The clock that started 1 s ago has converted the samples whose period has elapsed.
    assert_eq!(c.samples_in_us(1_000_000), 9_999);
    assert_eq!(c.samples_in_us(1_000_100), 10_000);
    assert_eq!(c.samples_in_us(1_000_099), 9_999);
    let ten_k = SampleClock {
        timer_hz: 200_000_000,
        ticks_per_sample: 20_000,
    };
    assert!(ten_k.is_exactly(10_000));
    assert_eq!(SampleClock::exact(10_000).time_s(5), 5e-4);
    // A damaged clock gives no time rather than a division by zero.
    let bad = SampleClock {
        timer_hz: 0,
        ticks_per_sample: 7,
    };
    assert!(bad.rate_hz().is_nan() && bad.time_s(3).is_nan());
    assert_eq!((bad.time_us(3), bad.samples_in_us(9)), (0, 0));
}

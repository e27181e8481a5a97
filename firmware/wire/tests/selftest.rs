//! The self-test's messages came last: they take the next variant numbers of `HostMsg` and
//! `DeviceMsg`, leave every older message's bytes as they were (`pinned.rs`), and round-trip.

use tribo_wire::frame::{decode_one, encode_vec, MAX_FRAME};
use tribo_wire::*;

/// The message's postcard bytes (no frame).
fn body<T: serde::Serialize>(m: &T) -> Vec<u8> {
    let mut buf = [0u8; 64];
    postcard::to_slice(m, &mut buf).unwrap().to_vec()
}

#[test]
fn the_self_test_messages_are_the_last_variants() {
    let host = body(&HostMsg::SelfTest(SelfTestCheck::Panic));
    let pull_blocks = body(&HostMsg::PullBlocks {
        run_id: 0,
        first: 0,
        count: 0,
    });
    assert_eq!(pull_blocks[0], 12);
    assert_eq!(host, [13, 3], "SelfTest after PullBlocks; Panic is check 3");
    let done = SelfTestReport::FillerDone {
        frames: 1,
        refused: 0,
    };
    let dev = body(&DeviceMsg::SelfTest(done));
    assert_eq!(
        dev,
        [13, 3, 1, 0],
        "SelfTest after EcrRange (12); FillerDone is report 3"
    );
    // The thermocouple check came after the others: check 5, report 4; the older ones' bytes
    // are as above.
    assert_eq!(
        body(&HostMsg::SelfTest(SelfTestCheck::Thermocouple)),
        [13, 5]
    );
    let tc = SelfTestReport::Thermocouple(ThermocoupleReport {
        registers: None,
        age_us: 0,
    });
    assert_eq!(body(&DeviceMsg::SelfTest(tc)), [13, 4, 0, 0]);
    // The outputs check after it: check 6, report 5; the older ones' bytes are as above.
    assert_eq!(body(&HostMsg::SelfTest(SelfTestCheck::Outputs)), [13, 6]);
    let o = SelfTestReport::Outputs(OutputsReport {
        steps: 5,
        outputs: [OutputCheck::default(); SELFTEST_OUTPUTS],
    });
    // Tag 13, report 5, steps 5, then 5 × (sensed, mismatches, driven, read) all zero.
    let mut want = vec![13, 5, 5];
    want.extend([0; 4 * SELFTEST_OUTPUTS]);
    assert_eq!(body(&DeviceMsg::SelfTest(o)), want);
    // The clock check after it: check 7 (intervals 16 as a varint), report 6; the older ones'
    // bytes are as above.
    assert_eq!(
        body(&HostMsg::SelfTest(SelfTestCheck::Clock { intervals: 16 })),
        [13, 7, 16]
    );
    let c = SelfTestReport::Clock(ClockReport::default());
    // Tag 13, report 6, then 10 fields all zero (bools, u8 and varints: one byte each).
    assert_eq!(
        body(&DeviceMsg::SelfTest(c)),
        [13, 6, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]
    );
}

#[test]
fn every_self_test_message_round_trips_and_the_largest_fits_a_frame() {
    let data: heapless::Vec<u8, FILLER_MAX> =
        (0..FILLER_MAX).map(|i| filler_byte(u32::MAX, i)).collect();
    let stats = ChannelStats {
        min: 1,
        max: 65_535,
        mean: 32_000.5,
        sd: 3.25,
        at_rail: 7,
    };
    let msgs = [
        DeviceMsg::SelfTest(SelfTestReport::Filler {
            index: u32::MAX,
            data,
        }),
        DeviceMsg::SelfTest(SelfTestReport::Converter(ConverterReport {
            clock: SampleClock::exact(10_000),
            first_index: u64::MAX - 1,
            last_index: u64::MAX,
            first_us: 1,
            last_us: u64::MAX,
            lost: u32::MAX,
            samples: 20_000,
            channels: [stats; SELFTEST_CHANNELS],
        })),
        DeviceMsg::SelfTest(SelfTestReport::Flash(FlashReport {
            sector: 7,
            bytes: 4096,
            erase_ok: true,
            program_ok: false,
            mismatches: 3,
            erase_us: 1_100_000,
            program_us: 9_000,
            read_us: 2_000,
            erase2_us: 1_100_500,
            flags: Some(0x0401_0000),
        })),
        DeviceMsg::SelfTest(SelfTestReport::Thermocouple(ThermocoupleReport {
            registers: Some([0xFF; 16]),
            age_us: u64::MAX,
        })),
        DeviceMsg::SelfTest(SelfTestReport::Thermocouple(ThermocoupleReport {
            registers: None,
            age_us: 100_000,
        })),
        DeviceMsg::SelfTest(SelfTestReport::Outputs(OutputsReport {
            steps: u8::MAX,
            outputs: [OutputCheck {
                sensed: true,
                mismatches: u8::MAX,
                driven: u16::MAX,
                read: 4095,
            }; SELFTEST_OUTPUTS],
        })),
        DeviceMsg::SelfTest(SelfTestReport::Clock(ClockReport {
            available: true,
            lsi_ready: true,
            timer_hz: u32::MAX,
            periods_per_capture: u8::MAX,
            intervals: u16::MAX,
            overcaptures: u16::MAX,
            timeouts: u16::MAX,
            ticks_sum: u64::MAX,
            ticks_min: u32::MAX,
            ticks_max: u32::MAX,
        })),
    ];
    for (seq, m) in msgs.into_iter().enumerate() {
        let bytes = encode_vec(seq as u32, &m).unwrap();
        assert!(bytes.len() <= MAX_FRAME);
        let f = decode_one::<DeviceMsg>(&bytes).unwrap();
        assert_eq!((f.seq, f.msg), (seq as u32, m));
    }
    for c in [
        SelfTestCheck::Converter {
            rate_hz: 10_000,
            ms: 2000,
        },
        SelfTestCheck::Flash { bytes: 4096 },
        SelfTestCheck::Throughput {
            frames: 2000,
            len: 256,
        },
        SelfTestCheck::Panic,
        SelfTestCheck::Stall,
        SelfTestCheck::Thermocouple,
        SelfTestCheck::Outputs,
        SelfTestCheck::Clock {
            intervals: u16::MAX,
        },
    ] {
        let bytes = encode_vec(1, &HostMsg::SelfTest(c)).unwrap();
        assert_eq!(
            decode_one::<HostMsg>(&bytes).unwrap().msg,
            HostMsg::SelfTest(c)
        );
    }
}

#[test]
fn a_lost_or_shifted_filler_byte_shows() {
    // Neighbouring bytes and neighbouring frames differ: a byte dropped, repeated or taken from
    // the next frame breaks the pattern.
    let f = |k: u32| (0..256).map(|i| filler_byte(k, i)).collect::<Vec<u8>>();
    let a = f(5);
    assert_ne!(a, f(6));
    assert!(a.windows(2).filter(|w| w[0] == w[1]).count() < 8);
    let mut shifted = a[1..].to_vec();
    shifted.push(a[0]);
    assert!(shifted.iter().zip(&a).filter(|(x, y)| x == y).count() < 8);
}

//! Codec tests: layouts, round trips, scaling edges, arbitrary bytes.

use super::*;
use proptest::prelude::*;

fn reference(angle: f32, as_state: AsState, counter: u8) -> Reference {
    Reference {
        angle: SteeringDeg(angle),
        as_state,
        counter: AliveCounter::wrapping(counter),
        clear_faults: false,
    }
}

fn status(angle: f32, current: f32, ecu_state: u8, faults: u16, counter: u8) -> Status {
    Status {
        angle: SteeringDeg(angle),
        current: Amps(current),
        ecu_state,
        faults,
        counter: AliveCounter::wrapping(counter),
    }
}

#[test]
fn reference_frame_layout_is_the_documented_one() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_reference(&reference(-12.34, AsState::Driving, 7));
    assert_eq!(frame.id().raw(), 0x100);
    // counter 7 | Driving (2) << 4; -1234 = 0xFB2E little-endian; reserved zero.
    let crc = crc::crc8_autosar(&[0x00, 0x01, 0x27, 0x2E, 0xFB, 0, 0, 0, 0]);
    assert_eq!(frame.data(), &[crc, 0x27, 0x2E, 0xFB, 0, 0, 0, 0]);
}

#[test]
fn status_frame_layout_is_the_documented_one() {
    let cfg = ProtocolConfig::DEFAULT;
    // -1.5 A = raw -75 = 0xFB5 (12 bit); 45 deg = raw 4500 = 0x1194.
    let frame = cfg.encode_status(&status(45.0, -1.5, 0xA5, 0xBEEF, 3));
    assert_eq!(frame.id().raw(), 0x101);
    let body = [0x53, 0xFB, 0x94, 0x11, 0xA5, 0xEF, 0xBE];
    let mut crc_input = vec![0x01, 0x01];
    crc_input.extend_from_slice(&body);
    let crc = crc::crc8_autosar(&crc_input);
    assert_eq!(
        frame.data(),
        &[crc, 0x53, 0xFB, 0x94, 0x11, 0xA5, 0xEF, 0xBE]
    );
}

#[test]
fn every_raw_angle_round_trips() {
    for raw in i16::MIN..=i16::MAX {
        let angle = angle_from_raw(raw);
        assert_eq!(angle_to_raw(angle), raw, "raw {raw}");
    }
}

#[test]
fn every_raw_current_round_trips() {
    for raw in CURRENT_NOT_AVAILABLE..=CURRENT_RAW_MAX {
        let current = current_from_raw(raw);
        assert_eq!(current_to_raw(current), raw, "raw {raw}");
    }
}

#[test]
fn nan_is_not_available_and_large_values_saturate() {
    assert_eq!(angle_to_raw(SteeringDeg(f32::NAN)), ANGLE_NOT_AVAILABLE);
    assert_eq!(angle_to_raw(SteeringDeg(1e9)), i16::MAX);
    assert_eq!(angle_to_raw(SteeringDeg(f32::NEG_INFINITY)), -i16::MAX);
    assert_eq!(current_to_raw(Amps(f32::NAN)), CURRENT_NOT_AVAILABLE);
    assert_eq!(current_to_raw(Amps(100.0)), 2047);
    assert_eq!(current_to_raw(Amps(-100.0)), -2047);
    assert_eq!(angle_to_raw(SteeringDeg(0.004)), 0);
    assert_eq!(angle_to_raw(SteeringDeg(0.005)), 1);
    assert_eq!(angle_to_raw(SteeringDeg(-0.005)), -1);
}

#[test]
fn reference_round_trips_for_every_state_and_counter() {
    let cfg = ProtocolConfig::DEFAULT;
    let states = [
        AsState::Off,
        AsState::Ready,
        AsState::Driving,
        AsState::Emergency,
        AsState::Finished,
        AsState::Manual,
    ];
    for (i, &as_state) in states.iter().enumerate() {
        for counter in 0..16 {
            let angle = -90.0 + 1.37 * (i as f32 * 16.0 + f32::from(counter));
            let sent = reference(angle, as_state, counter);
            let got = cfg.decode_reference(&cfg.encode_reference(&sent)).unwrap();
            assert_eq!(got.as_state, as_state);
            assert_eq!(got.counter, sent.counter);
            assert!(
                (got.angle.0 - angle).abs() <= 0.005 + 1e-4,
                "{angle} -> {got:?}"
            );
        }
    }
}

#[test]
fn frames_with_another_id_fail_the_crc_because_the_id_is_folded_in() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_status(&status(1.0, 2.0, 3, 4, 5));
    let moved = Frame::new(REFERENCE_ID, frame.data()).unwrap();
    let status_as_reference_cfg = ProtocolConfig {
        status_id: REFERENCE_ID,
        reference_id: STATUS_ID,
        ..cfg
    };
    assert!(matches!(
        status_as_reference_cfg.decode_status(&moved),
        Err(FrameError::Crc { .. })
    ));
    assert!(matches!(
        cfg.decode_reference(&frame),
        Err(FrameError::WrongId { id }) if id == STATUS_ID
    ));
}

#[test]
fn short_long_and_corrupted_frames_are_refused_with_their_reason() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_reference(&reference(10.0, AsState::Ready, 1));
    let short = Frame::new(REFERENCE_ID, &frame.data()[..7]).unwrap();
    assert_eq!(
        cfg.decode_reference(&short),
        Err(FrameError::WrongLength { len: 7 })
    );
    let mut bytes: [u8; 8] = frame.data().try_into().unwrap();
    bytes[3] ^= 0x10;
    let corrupted = Frame::new(REFERENCE_ID, &bytes).unwrap();
    assert_eq!(
        cfg.decode_reference(&corrupted),
        Err(FrameError::Crc {
            expected: frame_crc(REFERENCE_ID, &bytes),
            found: bytes[0]
        })
    );
}

#[test]
fn unknown_as_state_codes_are_refused() {
    let cfg = ProtocolConfig::DEFAULT;
    for code in 6..16u8 {
        let mut bytes = [0, 0x01 | code << 4, 0, 0, 0, 0, 0, 0];
        bytes[0] = frame_crc(REFERENCE_ID, &bytes);
        let frame = Frame::new(REFERENCE_ID, &bytes).unwrap();
        assert_eq!(
            cfg.decode_reference(&frame),
            Err(FrameError::UnknownAsState { code })
        );
    }
}

#[test]
fn crc_detects_every_error_of_up_to_three_bits_in_a_frame() {
    // The CRC is affine, so whether a flip pattern is detected does not depend on the frame:
    // one frame, every pattern of 1, 2 and 3 flipped bits among its 64 (41 664 patterns).
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_reference(&reference(33.33, AsState::Driving, 9));
    let word = u64::from_le_bytes(frame.data().try_into().unwrap());
    let refused = |pattern: u64| {
        let bad = Frame::new(REFERENCE_ID, &(word ^ pattern).to_le_bytes()).unwrap();
        matches!(cfg.decode_reference(&bad), Err(FrameError::Crc { .. }))
    };
    for a in 0..64 {
        assert!(refused(1 << a));
        for b in a + 1..64 {
            assert!(refused(1 << a | 1 << b));
            for c in b + 1..64 {
                assert!(refused(1 << a | 1 << b | 1 << c), "bits {a} {b} {c}");
            }
        }
    }
}

#[test]
fn config_refuses_unusable_limits() {
    let ok = ProtocolConfig::DEFAULT;
    assert_eq!(ok.validate(), Ok(()));
    let bad = [
        (
            ProtocolConfig {
                status_id: ok.reference_id,
                ..ok
            },
            ConfigError::SameIds,
        ),
        (
            ProtocolConfig {
                max_angle: SteeringDeg(f32::NAN),
                ..ok
            },
            ConfigError::MaxAngle,
        ),
        (
            ProtocolConfig {
                max_angle: SteeringDeg(0.0),
                ..ok
            },
            ConfigError::MaxAngle,
        ),
        (
            ProtocolConfig {
                max_angle: SteeringDeg(400.0),
                ..ok
            },
            ConfigError::MaxAngle,
        ),
        (
            ProtocolConfig {
                max_rate_deg_per_s: f32::INFINITY,
                ..ok
            },
            ConfigError::MaxRate,
        ),
        (
            ProtocolConfig {
                max_rate_deg_per_s: -1.0,
                ..ok
            },
            ConfigError::MaxRate,
        ),
        (ProtocolConfig { period_us: 0, ..ok }, ConfigError::Period),
        (
            ProtocolConfig {
                max_invalid_in_row: 0,
                ..ok
            },
            ConfigError::MaxInvalidInRow,
        ),
        (
            ProtocolConfig {
                timeout_us: 0,
                ..ok
            },
            ConfigError::Timeout,
        ),
    ];
    for (config, error) in bad {
        assert_eq!(config.validate(), Err(error));
        assert_eq!(E2eChecker::new(config).err(), Some(error));
    }
}

#[test]
fn default_rate_limit_is_above_what_the_actuator_can_follow() {
    // plant-and-control.md: no-load speed 24 V / ke = 457 rad/s at the motor.
    let ke = 24.0 / 457.0;
    let ratio = crate::gearing::Gearing::PAPER.ratio();
    for supply_v in [24.0f32, 29.4] {
        let wheel_deg_per_s = (supply_v / ke / ratio).to_degrees();
        assert!(wheel_deg_per_s < ProtocolConfig::DEFAULT.max_rate_deg_per_s);
    }
    let at_24v = (457.0 / ratio).to_degrees();
    assert!((at_24v - 306.4).abs() < 0.5, "{at_24v}");
}

#[test]
fn alive_counter_wraps_after_15() {
    assert_eq!(
        AliveCounter::new(15).unwrap().next(),
        AliveCounter::new(0).unwrap()
    );
    assert!(AliveCounter::new(16).is_none());
    assert_eq!(AliveCounter::wrapping(0x1F).raw(), 15);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(20_000))]

    #[test]
    fn status_round_trips_within_half_a_bit(
        angle in -327.67f32..327.67,
        current in -40.94f32..40.94,
        ecu_state: u8,
        faults: u16,
        counter in 0u8..16,
    ) {
        let cfg = ProtocolConfig::DEFAULT;
        let sent = status(angle, current, ecu_state, faults, counter);
        let got = cfg.decode_status(&cfg.encode_status(&sent)).unwrap();
        prop_assert!((got.angle.0 - angle).abs() <= 0.005 + 1e-4);
        prop_assert!((got.current.0 - current).abs() <= 0.01 + 1e-4);
        prop_assert_eq!(got.ecu_state, ecu_state);
        prop_assert_eq!(got.faults, faults);
        prop_assert_eq!(got.counter.raw(), counter);
    }

    #[test]
    fn status_decoder_takes_any_bytes(id in 0u16..=0x7FF, len in 0usize..=8, bytes: [u8; 8]) {
        let cfg = ProtocolConfig::DEFAULT;
        let frame = Frame::new(StandardId::new(id).unwrap(), &bytes[..len]).unwrap();
        if let Ok(status) = cfg.decode_status(&frame) {
            prop_assert_eq!(id, 0x101);
            prop_assert_eq!(len, 8);
            prop_assert_eq!(bytes[0], frame_crc(STATUS_ID, &bytes));
            // Decoding and encoding again gives the same bytes.
            let again = cfg.encode_status(&status);
            prop_assert_eq!(again.data(), &bytes[..]);
        }
    }
}

fn motor(angle: f32, current: f32, counter: u8) -> MotorStatus {
    MotorStatus {
        angle: MotorRad(angle),
        current_mean: Amps(current),
        counter: AliveCounter::wrapping(counter),
        reference_counter: AliveCounter::wrapping(0),
    }
}

#[test]
fn motor_frame_layout_is_the_documented_one() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_motor(&MotorStatus {
        reference_counter: AliveCounter::wrapping(14),
        ..motor(-1.2345, 12.5, 9)
    });
    assert_eq!(frame.id().raw(), 0x102);
    // counter 9, reference counter 14 (0xE); -12345 = 0xFFFFCFC7 LE; 12500 = 0x30D4 LE.
    assert_eq!(
        &frame.data()[1..],
        &[0xE9, 0xC7, 0xCF, 0xFF, 0xFF, 0xD4, 0x30]
    );
    let got = cfg.decode_motor(&frame).unwrap();
    assert!((got.angle.0 + 1.2345).abs() < 1e-6);
    assert_eq!(got.current_mean, Amps(12.5));
    assert_eq!(got.counter.raw(), 9);
    assert_eq!(got.reference_counter.raw(), 14);
}

#[test]
fn motor_frame_marks_nan_and_saturates_out_of_range() {
    let cfg = ProtocolConfig::DEFAULT;
    let got = cfg
        .decode_motor(&cfg.encode_motor(&motor(f32::NAN, f32::NAN, 0)))
        .unwrap();
    assert!(got.angle.0.is_nan() && got.current_mean.0.is_nan());
    let got = cfg
        .decode_motor(&cfg.encode_motor(&motor(-1e9, -100.0, 0)))
        .unwrap();
    assert!((got.angle.0 + 214_748.36).abs() < 0.1, "{:?}", got.angle);
    assert!((got.current_mean.0 + 32.767).abs() < 1e-4);
    let got = cfg
        .decode_motor(&cfg.encode_motor(&motor(f32::INFINITY, f32::INFINITY, 0)))
        .unwrap();
    assert!(got.angle.0 > 214_748.0 && got.current_mean.0 > 32.7);
}

#[test]
fn motor_frames_are_checked_like_status_frames() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_motor(&motor(3.0, 1.0, 2));
    // A status frame's bytes under the motor ID fail the CRC: the ID is folded in.
    let status_frame = cfg.encode_status(&status(1.0, 2.0, 3, 4, 5));
    let moved = Frame::new(MOTOR_ID, status_frame.data()).unwrap();
    assert!(matches!(
        cfg.decode_motor(&moved),
        Err(FrameError::Crc { .. })
    ));
    assert!(matches!(
        cfg.decode_motor(&status_frame),
        Err(FrameError::WrongId { id }) if id == STATUS_ID
    ));
    let short = Frame::new(MOTOR_ID, &frame.data()[..6]).unwrap();
    assert_eq!(
        cfg.decode_motor(&short),
        Err(FrameError::WrongLength { len: 6 })
    );
    for bit in 0..64 {
        let mut bytes = [0u8; 8];
        bytes.copy_from_slice(frame.data());
        bytes[bit / 8] ^= 1 << (bit % 8);
        let flipped = Frame::new(MOTOR_ID, &bytes).unwrap();
        assert!(
            matches!(cfg.decode_motor(&flipped), Err(FrameError::Crc { .. })),
            "bit {bit} flipped went unnoticed"
        );
    }
}

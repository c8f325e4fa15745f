//! The DBC file against the codec: IDs, lengths, and every signal decoded with the DBC's own
//! start bit, length, byte order, sign, factor and offset gives what the Rust decoder gives.

use super::*;
use crate::faults::Fault;
use crate::steering::EcuState;
use can_dbc::{ByteOrder, Dbc, Message, MessageId, Signal, ValueDescription, ValueType};
use proptest::prelude::*;

const DBC: &str = include_str!("steering-ecu.dbc");

fn dbc() -> Dbc {
    Dbc::try_from(DBC).expect("the DBC parses")
}

fn message<'a>(dbc: &'a Dbc, name: &str) -> &'a Message {
    dbc.messages
        .iter()
        .find(|m| m.name == name)
        .unwrap_or_else(|| panic!("message {name} in the DBC"))
}

fn signal<'a>(message: &'a Message, name: &str) -> &'a Signal {
    message
        .signals
        .iter()
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("signal {name} in {}", message.name))
}

/// Raw value of `signal` in `data`, as a generic DBC decoder (SavvyCAN, cantools) reads it.
fn raw(signal: &Signal, data: &[u8]) -> i64 {
    assert_eq!(
        signal.byte_order,
        ByteOrder::LittleEndian,
        "{} is Intel",
        signal.name
    );
    let word = u64::from_le_bytes(data.try_into().unwrap());
    let size = signal.size as u32;
    let bits = (word >> signal.start_bit) & ((1u64 << size) - 1);
    match signal.value_type {
        ValueType::Unsigned => bits as i64,
        ValueType::Signed => ((bits << (64 - size)) as i64) >> (64 - size),
    }
}

fn physical(signal: &Signal, data: &[u8]) -> f64 {
    raw(signal, data) as f64 * signal.factor + signal.offset
}

#[test]
fn ids_lengths_and_signal_sets_agree() {
    let dbc = dbc();
    let cfg = ProtocolConfig::DEFAULT;
    let reference = message(&dbc, "SteeringReference");
    let status = message(&dbc, "SteeringStatus");
    assert_eq!(reference.id, MessageId::Standard(cfg.reference_id.raw()));
    assert_eq!(status.id, MessageId::Standard(cfg.status_id.raw()));
    assert_eq!(reference.size, u64::from(FRAME_LEN));
    assert_eq!(status.size, u64::from(FRAME_LEN));
    let motor = message(&dbc, "EcuMotor");
    assert_eq!(motor.id, MessageId::Standard(MOTOR_ID.raw()));
    assert_eq!(motor.size, u64::from(FRAME_LEN));
    let diagnostics = message(&dbc, "EcuDiagnostics");
    assert_eq!(diagnostics.size, u64::from(FRAME_LEN));
    // The diagnostic frame's multiplexed signals overlap by design: its own test checks them.
    assert_eq!(dbc.messages.len(), 4);

    for m in [reference, status, motor] {
        // Signals inside the frame and not overlapping.
        let mut used = 0u64;
        for s in &m.signals {
            assert!(s.start_bit + s.size <= 64, "{}", s.name);
            let mask = (((1u128 << s.size) - 1) as u64) << s.start_bit;
            assert_eq!(used & mask, 0, "{} overlaps", s.name);
            used |= mask;
        }
    }
    let names = |m: &Message| m.signals.iter().map(|s| s.name.clone()).collect::<Vec<_>>();
    assert_eq!(
        names(reference),
        [
            "REF_Crc",
            "REF_Counter",
            "REF_AsState",
            "REF_SteeringAngle",
            "REF_ClearFaults"
        ]
    );
    assert_eq!(
        names(status),
        [
            "STA_Crc",
            "STA_Counter",
            "STA_MotorCurrent",
            "STA_SteeringAngle",
            "STA_EcuState",
            "STA_Faults"
        ]
    );
    assert_eq!(
        names(motor),
        [
            "MOT_Crc",
            "MOT_Counter",
            "MOT_RefCounter",
            "MOT_MotorAngle",
            "MOT_CurrentMean"
        ]
    );
}

#[test]
fn reference_range_and_as_state_table_agree() {
    let dbc = dbc();
    let reference = message(&dbc, "SteeringReference");
    let angle = signal(reference, "REF_SteeringAngle");
    let max = f64::from(ProtocolConfig::DEFAULT.max_angle.0);
    assert_eq!(angle.max, can_dbc::NumericValue::Uint(max as u64));
    assert_eq!(angle.min, can_dbc::NumericValue::Int(-(max as i64)));

    let table = dbc
        .value_descriptions_for_signal(reference.id, "REF_AsState")
        .expect("a value table for REF_AsState");
    let mut codes = 0;
    for entry in table {
        let code = u8::try_from(entry.id).unwrap();
        let state = AsState::from_code(code).expect("a defined AS state");
        assert_eq!(format!("{state:?}"), entry.description);
        codes += 1;
    }
    assert_eq!(codes, 6, "all six AS states named");
    assert!(
        dbc.value_descriptions
            .iter()
            .all(|v| matches!(v, ValueDescription::Signal { .. }))
    );
}

/// The worked CRC example of `src/FIRMWARE.md` ("The vehicle protocol"), byte for byte, is what the
/// codec sends: reference, counter 1, AS Driving, 12.34 deg. The ID goes into the CRC low byte
/// first (0x00, 0x01); high byte first would give 0x71.
#[test]
fn readme_crc_example_is_what_the_codec_sends() {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = cfg.encode_reference(&Reference {
        angle: SteeringDeg(12.34),
        as_state: AsState::Driving,
        counter: AliveCounter::new(1).unwrap(),
        clear_faults: false,
    });
    assert_eq!(frame.id().raw(), 0x100);
    assert_eq!(frame.data(), [0x3C, 0x21, 0xD2, 0x04, 0, 0, 0, 0]);
    let payload: [u8; 8] = frame.data().try_into().unwrap();
    assert_eq!(frame_crc(frame.id(), &payload), 0x3C);
    let ids_high_first = super::crc::crc8_autosar([0x01u8, 0x00].iter().chain(&payload[1..]));
    assert_eq!(ids_high_first, 0x71);
}

/// cantools and SavvyCAN show these names; every state the firmware can report has one, and
/// every name is the state's own.
#[test]
fn ecu_state_table_names_every_state_code() {
    let dbc = dbc();
    let status = message(&dbc, "SteeringStatus");
    let table = dbc
        .value_descriptions_for_signal(status.id, "STA_EcuState")
        .expect("a value table for STA_EcuState");
    let mut named = std::collections::BTreeSet::new();
    for entry in table {
        let code = u8::try_from(entry.id).unwrap();
        let state = EcuState::from_code(code).expect("a defined ECU state");
        assert_eq!(format!("{state:?}"), entry.description);
        named.insert(code);
    }
    let defined: std::collections::BTreeSet<u8> = (0..=u8::MAX)
        .filter(|&c| EcuState::from_code(c).is_some())
        .collect();
    assert_eq!(named, defined, "every state code named, no other");
}

/// The fault field's table: 0 is "None", each single bit is its fault's name.
#[test]
fn fault_table_names_each_fault_bit() {
    let dbc = dbc();
    let status = message(&dbc, "SteeringStatus");
    let table = dbc
        .value_descriptions_for_signal(status.id, "STA_Faults")
        .expect("a value table for STA_Faults");
    let mut expected: Vec<(u64, String)> = vec![(0, "None".to_string())];
    for fault in Fault::ALL {
        expected.push((1u64 << fault.bit(), format!("{fault:?}")));
    }
    let found: Vec<(u64, String)> = table
        .iter()
        .map(|e| (u64::try_from(e.id).unwrap(), e.description.clone()))
        .collect();
    assert_eq!(found, expected);
}

#[test]
fn diagnostic_pages_decode_as_the_dbc_says() {
    use can_dbc::MultiplexIndicator;
    let dbc = dbc();
    let m = message(&dbc, "EcuDiagnostics");
    assert_eq!(m.id, MessageId::Standard(DIAGNOSTIC_ID.raw()));
    let cfg = ProtocolConfig::DEFAULT;
    let mut pages: Vec<DiagnosticPage> = (0..COUNTER_PAGES)
        .map(|page| DiagnosticPage::Counters {
            page,
            words: [1000 + u16::from(page), 2000 + u16::from(page), 65535],
        })
        .collect();
    for (slot, detail, age_s) in [
        (0, -123_456, 0),
        (7, RECORD_DETAIL_MIN + 1, 1),
        (14, RECORD_DETAIL_MAX - 1, RECORD_AGE_MAX_S),
        (15, 0x1_0002, 61),
    ] {
        pages.push(DiagnosticPage::Record {
            slot,
            record: Some(DiagnosticRecord {
                fault_bit: slot % 10,
                acknowledged: slot % 2 == 1,
                detail,
                age_s,
            }),
        });
    }
    pages.push(DiagnosticPage::Record {
        slot: 3,
        record: None,
    });
    for (i, page) in pages.into_iter().enumerate() {
        let d = Diagnostic {
            counter: AliveCounter::wrapping(i as u8),
            page,
        };
        let frame = cfg.encode_diagnostic(&d);
        assert_eq!(cfg.decode_diagnostic(&frame), Ok(d));
        let data = frame.data();
        assert_eq!(raw(signal(m, "DIA_Page"), data), i64::from(page.code()));
        let on_page: Vec<&Signal> = m
            .signals
            .iter()
            .filter(|s| {
                s.multiplexer_indicator
                    == MultiplexIndicator::MultiplexedSignal(u64::from(page.code()))
            })
            .collect();
        let expected: Vec<i64> = match page {
            DiagnosticPage::Counters { words, .. } => words.map(i64::from).to_vec(),
            DiagnosticPage::Unknown { .. } => unreachable!("only defined pages are sent"),
            DiagnosticPage::Record { slot, record } => match record {
                Some(r) => vec![
                    i64::from(slot),
                    i64::from(r.fault_bit),
                    i64::from(r.acknowledged),
                    i64::from(r.detail),
                    i64::from(r.age_s),
                ],
                None => vec![i64::from(slot), i64::from(NO_RECORD), 0, 0, 0],
            },
        };
        let found: Vec<i64> = on_page.iter().map(|s| raw(s, data)).collect();
        assert_eq!(found, expected, "page {page:?}");
    }
    // A page code the layout does not define is refused, not read as some page.
    for code in (COUNTER_PAGES..16).filter(|c| *c != RECORD_PAGE) {
        let word = u64::from(code) << 12;
        let frame = frame_with_crc(DIAGNOSTIC_ID, word);
        assert_eq!(
            cfg.decode_diagnostic(&frame).map(|d| d.page),
            Ok(DiagnosticPage::Unknown { code, payload: 0 })
        );
    }
}

/// A record's detail beyond 28 bits saturates, and the saturated ends read back as the
/// `i32` ends, so a current that was not a number (`i32::MIN`) still says so.
#[test]
fn a_record_detail_saturates_to_the_i32_ends() {
    let cfg = ProtocolConfig::DEFAULT;
    for (sent, read) in [
        (i32::MIN, i32::MIN),
        (RECORD_DETAIL_MIN - 5, i32::MIN),
        (i32::MAX, i32::MAX),
        (RECORD_DETAIL_MAX, i32::MAX),
        (-1, -1),
        (0xFF05, 0xFF05),
    ] {
        let d = Diagnostic {
            counter: AliveCounter::wrapping(0),
            page: DiagnosticPage::Record {
                slot: 1,
                record: Some(DiagnosticRecord {
                    fault_bit: 5,
                    acknowledged: false,
                    detail: sent,
                    age_s: u16::MAX,
                }),
            },
        };
        let back = cfg.decode_diagnostic(&cfg.encode_diagnostic(&d)).unwrap();
        let DiagnosticPage::Record {
            record: Some(r), ..
        } = back.page
        else {
            panic!("{back:?}")
        };
        assert_eq!((r.detail, r.age_s), (read, RECORD_AGE_MAX_S), "{sent}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    #[test]
    fn dbc_decodes_reference_frames_as_the_codec_does(
        raw_angle: i16,
        code in 0u8..6,
        counter in 0u8..16,
        clear_faults: bool,
    ) {
        let dbc = dbc_cached();
        let cfg = ProtocolConfig::DEFAULT;
        let m = message(dbc, "SteeringReference");
        let sent = Reference {
            angle: angle_from_raw(raw_angle),
            as_state: AsState::from_code(code).unwrap(),
            counter: AliveCounter::new(counter).unwrap(),
            clear_faults,
        };
        let f = cfg.encode_reference(&sent);
        let data = f.data();
        let got = cfg.decode_reference(&f).unwrap();

        prop_assert_eq!(raw(signal(m, "REF_Crc"), data), i64::from(data[0]));
        prop_assert_eq!(data[0], frame_crc(cfg.reference_id, data.try_into().unwrap()));
        prop_assert_eq!(raw(signal(m, "REF_Counter"), data), i64::from(got.counter.raw()));
        prop_assert_eq!(raw(signal(m, "REF_AsState"), data), i64::from(got.as_state.code()));
        prop_assert_eq!(raw(signal(m, "REF_ClearFaults"), data), i64::from(clear_faults));
        prop_assert_eq!(got.clear_faults, clear_faults);
        let angle = physical(signal(m, "REF_SteeringAngle"), data);
        if raw_angle == ANGLE_NOT_AVAILABLE {
            prop_assert!(got.angle.0.is_nan());
            prop_assert_eq!(raw(signal(m, "REF_SteeringAngle"), data), i64::from(i16::MIN));
        } else {
            // f32 against f64: agree to 1 % of a bit.
            prop_assert!((angle - f64::from(got.angle.0)).abs() < 1e-4, "{} {:?}", angle, got.angle);
        }
    }

    #[test]
    fn dbc_decodes_status_frames_as_the_codec_does(
        raw_angle: i16,
        raw_current in -2048i16..=2047,
        ecu_state: u8,
        faults: u16,
        counter in 0u8..16,
    ) {
        let dbc = dbc_cached();
        let cfg = ProtocolConfig::DEFAULT;
        let m = message(dbc, "SteeringStatus");
        let sent = Status {
            angle: angle_from_raw(raw_angle),
            current: current_from_raw(raw_current),
            ecu_state,
            faults,
            counter: AliveCounter::new(counter).unwrap(),
        };
        let f = cfg.encode_status(&sent);
        let data = f.data();
        let got = cfg.decode_status(&f).unwrap();

        prop_assert_eq!(raw(signal(m, "STA_Crc"), data), i64::from(data[0]));
        prop_assert_eq!(raw(signal(m, "STA_Counter"), data), i64::from(counter));
        prop_assert_eq!(raw(signal(m, "STA_EcuState"), data), i64::from(ecu_state));
        prop_assert_eq!(raw(signal(m, "STA_Faults"), data), i64::from(faults));
        prop_assert_eq!(raw(signal(m, "STA_SteeringAngle"), data), i64::from(raw_angle));
        prop_assert_eq!(raw(signal(m, "STA_MotorCurrent"), data), i64::from(raw_current));
        if raw_angle != ANGLE_NOT_AVAILABLE {
            let angle = physical(signal(m, "STA_SteeringAngle"), data);
            prop_assert!((angle - f64::from(got.angle.0)).abs() < 1e-4);
        }
        if raw_current != CURRENT_NOT_AVAILABLE {
            let current = physical(signal(m, "STA_MotorCurrent"), data);
            prop_assert!((current - f64::from(got.current.0)).abs() < 2e-4);
        }
        prop_assert_eq!(got.ecu_state, ecu_state);
        prop_assert_eq!(got.faults, faults);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(5_000))]

    #[test]
    fn dbc_decodes_motor_frames_as_the_codec_does(
        raw_angle: i32,
        raw_current: i16,
        counter in 0u8..16,
        reference_counter in 0u8..16,
    ) {
        let dbc = dbc_cached();
        let cfg = ProtocolConfig::DEFAULT;
        let m = message(dbc, "EcuMotor");
        // The raw values through the codec's own scale, as the ECU would send them.
        let angle = if raw_angle == MOTOR_ANGLE_NOT_AVAILABLE {
            f32::NAN
        } else {
            (f64::from(raw_angle) * MOTOR_RAD_PER_BIT) as f32
        };
        let current = if raw_current == MOTOR_CURRENT_NOT_AVAILABLE {
            f32::NAN
        } else {
            f32::from(raw_current) * MOTOR_CURRENT_A_PER_BIT
        };
        let sent = MotorStatus {
            angle: MotorRad(angle),
            current_mean: Amps(current),
            counter: AliveCounter::new(counter).unwrap(),
            reference_counter: AliveCounter::new(reference_counter).unwrap(),
        };
        let f = cfg.encode_motor(&sent);
        let data = f.data();
        let got = cfg.decode_motor(&f).unwrap();

        prop_assert_eq!(f.id(), MOTOR_ID);
        prop_assert_eq!(data[0], frame_crc(MOTOR_ID, data.try_into().unwrap()));
        prop_assert_eq!(raw(signal(m, "MOT_Crc"), data), i64::from(data[0]));
        prop_assert_eq!(raw(signal(m, "MOT_Counter"), data), i64::from(counter));
        prop_assert_eq!(got.counter.raw(), counter);
        prop_assert_eq!(
            raw(signal(m, "MOT_RefCounter"), data),
            i64::from(reference_counter)
        );
        prop_assert_eq!(got.reference_counter.raw(), reference_counter);
        prop_assert_eq!(raw(signal(m, "MOT_CurrentMean"), data), i64::from(raw_current));
        if raw_angle == MOTOR_ANGLE_NOT_AVAILABLE {
            prop_assert!(got.angle.0.is_nan());
            prop_assert_eq!(raw(signal(m, "MOT_MotorAngle"), data), i64::from(i32::MIN));
        } else {
            // f32 carries 24 bits: the raw value survives to within one part in 2^23.
            let dbc_angle = physical(signal(m, "MOT_MotorAngle"), data);
            let tol = 1e-4_f64.max(dbc_angle.abs() * 2e-7);
            prop_assert!((dbc_angle - f64::from(got.angle.0)).abs() <= tol, "{} {:?}", dbc_angle, got.angle);
        }
        if raw_current == MOTOR_CURRENT_NOT_AVAILABLE {
            prop_assert!(got.current_mean.0.is_nan());
        } else {
            let dbc_current = physical(signal(m, "MOT_CurrentMean"), data);
            prop_assert!((dbc_current - f64::from(got.current_mean.0)).abs() < 1e-5);
        }
    }
}

/// The DBC parsed once for the property tests (parsing per case would dominate their runtime).
fn dbc_cached() -> &'static Dbc {
    static DBC_PARSED: std::sync::OnceLock<Dbc> = std::sync::OnceLock::new();
    DBC_PARSED.get_or_init(dbc)
}

//! What the configuration script and the enable walk write into the drive, word by word, as a
//! drive that confirms every write and reads back what it holds sees it; and the scaling and
//! the paper's limits those words are made from. The expected words are worked out by hand
//! from the EPOS4 firmware specification and the paper's tables, not taken from the code.

use super::super::sdo::{self, ServerRequest};
use super::*;
use crate::canopen::NodeId;

fn node() -> NodeId {
    NodeId::new(1).unwrap()
}

/// A drive's object dictionary as far as the link writes it: every download stored and
/// confirmed, every upload answered with the stored word (0 if never written). Of CiA 402
/// only the last step is modelled: "enable operation" turns the statusword to Operation
/// enabled.
#[derive(Default)]
struct Dictionary {
    /// Every download in order: object, value, size in bytes.
    writes: Vec<(ObjectAddress, u32, Option<u8>)>,
}

impl Dictionary {
    fn value(&self, object: ObjectAddress) -> Option<u32> {
        self.writes
            .iter()
            .rev()
            .find(|(o, _, _)| *o == object)
            .map(|(_, v, _)| *v)
    }

    /// The drive's answer to the SDO request in `out`, if there is one.
    fn answer(&mut self, out: &Outbox) -> Option<Frame> {
        match out.iter().find_map(|f| sdo::parse_request(f, node()))? {
            ServerRequest::Download {
                object,
                value,
                bytes,
            } => {
                self.writes.push((object, value, bytes));
                if object == od::CONTROLWORD
                    && value == u32::from(Command::EnableOperation.controlword())
                {
                    let enabled = State::OperationEnabled.statusword_bits();
                    self.writes.push((od::STATUSWORD, u32::from(enabled), None));
                }
                sdo::download_response_frame(node(), object)
            }
            ServerRequest::Upload { object } => {
                let value = self.value(object).unwrap_or(0);
                let width = if object == od::STATUSWORD {
                    Width::U16
                } else {
                    Width::U32
                };
                sdo::upload_response_frame(node(), object, value, width)
            }
            ServerRequest::Unsupported { .. } => None,
        }
    }
}

/// Runs the link's SDO transfers against `drive` until the link asks for nothing more.
fn serve(link: &mut Epos4Link, drive: &mut Dictionary, mut out: Outbox, now_us: &mut u64) {
    for _ in 0..200 {
        let Some(answer) = drive.answer(&out) else {
            return;
        };
        *now_us += 1_000;
        out = link.on_frame(&answer, *now_us);
        assert_eq!(link.error(), None);
    }
    panic!("the link kept asking after 200 transfers");
}

/// The whole paper configuration, in the order the drive receives it. The words that are not
/// gains (the gains' words have their own test above) are the manual's encodings: a
/// controlword 0x0000 first, 20 A as 20 000 mA, 25 deg at the wheel as 498 inc (25 deg x
/// 85.45 motor per wheel, Table 2, / 360 deg x 84 inc/rev = 498.5), 5 400 rpm, mode 8 (CSP),
/// a 10 ms interpolation period with index -3 (0xFD: ms), a 20 ms heartbeat, and the
/// consumer entry for node 127 at 50 ms (0x007F_0032: node in bits 16-23, ms in 0-15).
#[test]
fn the_paper_configuration_writes_these_words_in_this_order() {
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let mut drive = Dictionary::default();
    let mut t = 0;
    let out = link.start(t);
    serve(&mut link, &mut drive, out, &mut t);
    assert_eq!(link.phase(), Phase::Starting);

    let not_gains: Vec<(ObjectAddress, u32, Option<u8>)> = drive
        .writes
        .iter()
        .copied()
        .filter(|(o, _, _)| o.index != 0x30A0 && o.index != 0x30A1)
        .take(9)
        .collect();
    let a = ObjectAddress::new;
    assert_eq!(
        not_gains,
        vec![
            (a(0x6040, 0), 0x0000, Some(2)),
            (a(0x3001, 2), 20_000, Some(4)),
            (a(0x6065, 0), 498, Some(4)),
            (a(0x607F, 0), 5_400, Some(4)),
            (a(0x6060, 0), 8, Some(1)),
            (a(0x60C2, 1), 10, Some(1)),
            (a(0x60C2, 2), 0xFD, Some(1)),
            (a(0x1017, 0), 20, Some(2)),
            (a(0x1016, 1), 0x007F_0032, Some(4)),
        ]
    );
    // The PDOs end valid with the link's COB-IDs and mappings: RPDO1 0x201 <- 0x607A (32
    // bit); TPDO1 0x181 (no RTR, bit 30) -> 0x6041 (16), 0x6064 (32); TPDO2 0x281 -> 0x30D1
    // sub 2 (32).
    for (object, value) in [
        (a(0x1400, 1), 0x201),
        (a(0x1600, 1), 0x607A_0020),
        (a(0x1800, 1), 0x4000_0181),
        (a(0x1A00, 1), 0x6041_0010),
        (a(0x1A00, 2), 0x6064_0020),
        (a(0x1801, 1), 0x4000_0281),
        (a(0x1A01, 1), 0x30D1_0220),
    ] {
        assert_eq!(drive.value(object), Some(value), "{object}");
    }
}

/// The software position limits of an enable walk are the ECU's origin +- 110 deg at the
/// wheel (2 193 inc: 110 x 85.45 / 360 x 84 = 2 193.3), written to 0x607D sub 1 and 2 and
/// read back before "enable operation"; at the ends of the `i32` range they saturate.
#[test]
fn the_enable_walk_writes_limits_around_the_origin() {
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let _ = link.set_power(true, 0);
    assert_eq!(link.position_limits(), None);
    link.set_position_origin(Some(1_000));
    assert_eq!(link.position_limits(), Some((1_000 - 2_193, 1_000 + 2_193)));
    assert_eq!(link.verified_position_limits(), None);

    let mut drive = Dictionary::default();
    // The drive stands in Switched on at 1 200 inc.
    let switched_on = State::SwitchedOn.statusword_bits();
    drive
        .writes
        .push((od::STATUSWORD, u32::from(switched_on), None));
    drive.writes.push((od::POSITION_ACTUAL, 1_200, None));
    let mut out = Outbox::new();
    link.enter_enabling(false, 0, &mut out);
    let mut t = 0;
    serve(&mut link, &mut drive, out, &mut t);
    assert_eq!(link.phase(), Phase::Cyclic);
    assert_eq!(
        drive.value(od::MIN_POSITION_LIMIT),
        Some((-1_193i32) as u32)
    );
    assert_eq!(drive.value(od::MAX_POSITION_LIMIT), Some(3_193));
    assert_eq!(drive.value(od::TARGET_POSITION), Some(1_200));
    assert_eq!(
        drive.value(od::CONTROLWORD),
        Some(u32::from(Command::EnableOperation.controlword()))
    );
    assert_eq!(link.verified_position_limits(), Some((-1_193, 3_193)));

    link.set_position_origin(Some(i32::MAX - 5));
    assert_eq!(link.position_limits(), Some((i32::MAX - 2_198, i32::MAX)));
    link.set_position_origin(Some(i32::MIN + 5));
    assert_eq!(link.position_limits(), Some((i32::MIN, i32::MIN + 2_198)));
}

/// The paper's limits in the drive's units (84 Hall increments per motor turn, 85.45 motor
/// turns per wheel turn): 20 000 mA, 498 inc for 25 deg, 2 193 inc for 110 deg.
#[test]
fn the_paper_limits_in_drive_units() {
    let limits = DriveLimits::paper(84);
    assert_eq!(
        limits,
        DriveLimits {
            current_ma: 20_000,
            following_error_inc: 498,
            max_velocity_rpm: 5_400,
            position_limit_inc: 2_193,
        }
    );
    assert_eq!(Epos4Config::paper(node()).limits, limits);
    assert_eq!(POSITION_LIMIT_DEG, 110.0);
}

/// Increments round to the nearest (halves away from zero) on both sides of zero, and the
/// scale reports the increments per turn it was made with.
#[test]
fn position_scale_rounds_to_the_nearest_increment() {
    let s = PositionScale::new(84).unwrap();
    assert_eq!(s.counts_per_rev(), 84);
    assert_eq!(PositionScale::new(4096).unwrap().counts_per_rev(), 4096);
    let turn = core::f32::consts::TAU;
    for (motor_turns, inc) in [
        (0.4 / 84.0, 0),
        (0.6 / 84.0, 1),
        (10.4 / 84.0, 10),
        (10.6 / 84.0, 11),
        (-0.6 / 84.0, -1),
        (-10.4 / 84.0, -10),
        (-10.6 / 84.0, -11),
        (1.0, 84),
    ] {
        assert_eq!(
            s.inc_from_motor(MotorRad(motor_turns * turn)),
            Some(inc),
            "{motor_turns} turns"
        );
    }
}

/// The drive's position comes back as a motor angle (84 inc per turn), and the target goes
/// out in the next RPDO1 as the increments nearest the angle asked for; an angle that is not
/// a number is refused and the previous target kept.
#[test]
fn positions_in_and_targets_out_are_scaled_by_the_increments_per_turn() {
    let turn = core::f32::consts::TAU;
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    link.phase = Phase::Cyclic;
    assert!(!link.position_known());
    let [lo, hi] = State::OperationEnabled.statusword_bits().to_le_bytes();
    let [p0, p1, p2, p3] = (-168i32).to_le_bytes();
    let tpdo1 = Frame::new(StandardId::new(0x181).unwrap(), &[lo, hi, p0, p1, p2, p3]).unwrap();
    let _ = link.on_frame(&tpdo1, 1_000);
    assert!(link.position_known());
    assert!(
        (link.motor_position().0 + 2.0 * turn).abs() < 1e-5,
        "{:?}",
        link.motor_position()
    );

    assert_eq!(link.set_target(MotorRad(1.5 * turn)), Ok(()));
    assert_eq!(link.target_inc(), 126);
    assert!(link.set_target(MotorRad(f32::NAN)).is_err());
    assert_eq!(link.target_inc(), 126);
    let rpdo1 = |out: &Outbox| {
        out.iter()
            .find(|f| f.id().raw() == 0x201)
            .and_then(|f| pdo::decode_i32(f.data()))
    };
    assert_eq!(rpdo1(&link.poll(2_000)), Some(126));
    link.set_target_inc(-7);
    assert_eq!(link.target_inc(), -7);
    assert_eq!(rpdo1(&link.poll(12_000)), Some(-7));
}

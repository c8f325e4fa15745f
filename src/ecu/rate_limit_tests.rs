//! The reference's rate limit, end to end: what the controller is handed, whatever the
//! frames do.

use super::tests::Vehicle;
use super::*;
use crate::sensors::hall_from_motor;
use proptest::prelude::*;

const MS: u64 = 1000;
/// The position tick, us (2 kHz).
const TICK_US: u64 = 500;

/// What the vehicle does next, after `gap_us` of silence.
#[derive(Debug, Clone)]
enum Send {
    /// One frame stepping `frac` of the E2E budget for the gap (beyond 1: refused).
    Step { frac: f32 },
    /// `n` frames 200 us apart, each stepping `frac` of a period's budget.
    Burst { n: u8, frac: f32 },
    /// `n` frames with a broken CRC (the counter still advances), 200 us apart.
    Junk { n: u8 },
}

fn send() -> impl Strategy<Value = (u64, Send)> {
    let gap = prop_oneof![
        4 => Just(10 * MS),
        3 => 0u64..=125 * MS,
        1 => prop_oneof![Just(40 * MS), Just(80 * MS), Just(120 * MS), Just(125 * MS)],
    ];
    let what = prop_oneof![
        6 => (-1.2f32..1.2).prop_map(|frac| Send::Step { frac }),
        2 => (2u8..6, -1.0f32..1.0).prop_map(|(n, frac)| Send::Burst { n, frac }),
        1 => (1u8..5).prop_map(|n| Send::Junk { n }),
    ];
    (gap, what)
}

fn setpoint_deg(ecu: &Ecu) -> f32 {
    let Drive::Direct(cascade) = ecu.drive() else {
        panic!("direct mode")
    };
    let cascade = cascade.controller();
    SteeringDeg::from(Gearing::PAPER.steering_from_motor(cascade.setpoint().position)).0
}

fn hall_at(deg: f32) -> i32 {
    let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
    hall_from_motor(f64::from(motor.0))
}

/// The direct-drive car as the firmware runs it: position ticks at 2 kHz, column samples
/// at 500 Hz, a motor and column that follow the set-point exactly. The vehicle's frames
/// come as `script` says. Every set-point step (wheel deg) taken while the drive stayed
/// on, with the time it was taken, and the faults latched at the end.
fn run(script: &[(u64, Send)]) -> (Vec<(u64, f32)>, crate::faults::FaultSet) {
    let mut ecu = Ecu::paper().expect("paper ECU");
    let rate = ecu.protocol.max_rate_deg_per_s;
    let mut vehicle = Vehicle::new();
    // Frames due: (time, angle, junk).
    let mut due: Vec<(u64, f32, bool)> = (0..5).map(|k| (k * 10 * MS, 0.0, false)).collect();
    let mut t_frame = 40 * MS;
    let mut angle = 0.0f32;
    for (gap, what) in script {
        t_frame += gap;
        match *what {
            Send::Step { frac } => {
                let budget = rate * (*gap).max(10 * MS) as f32 * 1e-6;
                angle = (angle + frac * budget).clamp(-85.0, 85.0);
                due.push((t_frame, angle, false));
            }
            Send::Burst { n, frac } => {
                for k in 0..u64::from(n) {
                    angle = (angle + frac * rate * 0.01).clamp(-85.0, 85.0);
                    due.push((t_frame + k * 200, angle, false));
                }
                t_frame += u64::from(n) * 200;
            }
            Send::Junk { n } => {
                for k in 0..u64::from(n) {
                    due.push((t_frame + k * 200, angle, true));
                }
                t_frame += u64::from(n) * 200;
            }
        }
    }
    // Then on time again, at the last angle, for 200 ms.
    for k in 1..=20 {
        due.push((t_frame + k * 10 * MS, angle, false));
    }
    let end = t_frame + 200 * MS;
    let mut steps = Vec::new();
    let mut next = due.iter().peekable();
    let mut position = 0.0f32;
    let mut on_before = false;
    let mut t = 0;
    while t <= end {
        if t.is_multiple_of(2 * MS) {
            let _ = ecu.on_encoder(t, SteeringDeg(position));
        }
        while let Some(&&(at, deg, junk)) = next.peek() {
            if at > t {
                break;
            }
            let mut f = vehicle.frame(AsState::Driving, deg, false);
            if junk {
                let mut bytes: [u8; 8] = f.data().try_into().expect("8 bytes");
                bytes[0] ^= 0x5A;
                f = Frame::new(f.id(), &bytes).expect("a frame");
            }
            let _ = ecu.on_reference_frame(at, &f);
            next.next();
        }
        if t.is_multiple_of(2 * MS) {
            let _ = ecu.tick(t);
        }
        let on = ecu.output().demand != DriveDemand::Disabled;
        let _ = ecu.position_tick(hall_at(position));
        let setpoint = setpoint_deg(&ecu);
        if on && on_before {
            steps.push((t, setpoint - position));
        }
        if on {
            // The motor and the column are where the set-point was.
            position = setpoint;
        }
        on_before = on;
        t += TICK_US;
    }
    (steps, ecu.output().faults)
}

fn assert_within_rate(steps: &[(u64, f32)]) -> Result<(), TestCaseError> {
    let limit = ProtocolConfig::default().max_rate_deg_per_s * TICK_US as f32 * 1e-6;
    for &(t, step) in steps {
        prop_assert!(
            step.abs() <= limit + 1e-3,
            "the set-point moved {step} deg in one {TICK_US} us tick at {t} us (limit {limit})"
        );
    }
    Ok(())
}

/// The cases the audit measured: 40/80/120/125 ms without frames, then a step of the whole
/// budget; four junk frames, then a 20 deg step.
#[test]
fn after_a_gap_the_set_point_ramps_at_the_rate_limit() {
    for gap in [40, 80, 120, 125] {
        let (steps, faults) = run(&[(gap * MS, Send::Step { frac: 1.0 })]);
        assert_within_rate(&steps).unwrap();
        assert!(faults.is_empty(), "after {gap} ms: {faults:?}");
    }
    let (steps, _) = run(&[
        (10 * MS, Send::Junk { n: 4 }),
        (10 * MS, Send::Step { frac: 0.5 }),
        (0, Send::Step { frac: 0.0 }),
    ]);
    assert_within_rate(&steps).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever the frame timing (gaps of 0 to 125 ms, bursts, junk frames, Hold and back
    /// to Track), the set-point the cascade is handed never moves more than 400 deg/s
    /// times its tick.
    #[test]
    fn the_set_point_never_moves_faster_than_the_rate_limit(
        script in prop::collection::vec(send(), 1..40)
    ) {
        assert_within_rate(&run(&script).0)?;
    }
}

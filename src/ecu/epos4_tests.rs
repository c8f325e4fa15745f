//! EPOS4 mode against the EPOS4 model (`canopen::epos4_model`, the drive host-sim's simulated
//! car runs too, here with a motor that stands unless a test moves it): the bring-up, the
//! power stage following the demand, the link's faults and their recovery, the current and
//! the target the drive is given. The library's other tests reach this mode only through
//! host-sim.

use super::tests::Vehicle;
use super::*;
use crate::canopen::NodeId;
use crate::canopen::cia402::State;
use crate::canopen::epos4::Phase;
use crate::canopen::epos4::{Epos4Config, od};
use crate::canopen::epos4_model::{Epos4Model, Motor};
use crate::controller::SteeringController;
use crate::faults::Fault;
use crate::sensors::{HALL_COUNTS_PER_REV, hall_from_motor, motor_from_hall};

const MS: u64 = 1000;

fn node() -> NodeId {
    NodeId::new(1).unwrap()
}

/// The motor behind the EPOS4 model: it stands at `position_inc` (the drive's own count from
/// its power-up) unless the test moves it, and the drive reports `current_ma`.
#[derive(Debug)]
struct StillMotor {
    position_inc: i32,
    current_ma: i32,
    /// The targets the drive took in Operation enabled (the ones it follows).
    targets: Vec<i32>,
    /// The motor goes to each target at once.
    follows: bool,
}

impl Motor for StillMotor {
    fn tick(&mut self, _running: bool) {}

    fn enable(&mut self, _gains: &EposGains) {}

    fn target(&mut self, inc: i32) {
        self.targets.push(inc);
        if self.follows {
            self.position_inc = inc;
        }
    }

    fn position_inc(&self) -> i32 {
        self.position_inc
    }

    fn current_averaged_ma(&self) -> i32 {
        self.current_ma
    }

    fn current_actual_ma(&self) -> i32 {
        self.current_ma
    }
}

/// The ECU in EPOS4 mode, the EPOS4 model on the other end of its link (its motor standing
/// unless a test moves it) and the vehicle computer: the set-up every test of this file
/// starts from.
struct Bench {
    ecu: Ecu,
    drive: Epos4Model,
    motor: StillMotor,
    /// Frames for the ECU, delivered at its next drive call.
    answers: Vec<Frame>,
    vehicle: Vehicle,
    /// What the link sent when it started (at 0).
    started: Vec<Frame>,
}

impl Bench {
    /// The ECU started at 0, its drive powered up at `position_inc`.
    fn new(position_inc: i32) -> Bench {
        Bench::with(
            ControllerKind::Paper,
            Epos4Config::paper(node()),
            position_inc,
        )
    }

    /// [`Bench::new`] with `controller` and the link's `config`.
    fn with(controller: ControllerKind, config: Epos4Config, position_inc: i32) -> Bench {
        let ecu = Ecu::build(EcuBuild::new(controller, DriveChoice::Epos4(config)), 0).unwrap();
        let mut b = Bench {
            ecu,
            drive: Epos4Model::new(node()),
            motor: StillMotor {
                position_inc,
                current_ma: 0,
                targets: Vec::new(),
                follows: false,
            },
            answers: Vec::new(),
            vehicle: Vehicle::new(),
            started: Vec::new(),
        };
        // The drive boots first (its boot-up goes to the ECU's first drive call).
        b.advance(0);
        b.started = b.ecu.drive_start(0).to_vec();
        for f in b.started.clone() {
            b.send_to_drive(&f);
        }
        b
    }

    /// Tracking 0 deg in AS Driving at the returned time (400 ms), the drive at 500.
    fn tracking() -> (Bench, u64) {
        let mut b = Bench::new(500);
        let t = 400 * MS;
        let _ = b.run(0, t, AsState::Driving, 0.0, 0.0);
        let log: Vec<_> = b.ecu.machine().fault_log().iter().copied().collect();
        assert_eq!(b.ecu.output().state, EcuState::Tracking, "{log:?}");
        (b, t)
    }

    /// The drive runs to `t`; what it sends (heartbeats) waits for the ECU's next drive call.
    fn advance(&mut self, t: u64) {
        let answers = &mut self.answers;
        self.drive.advance(t, &mut self.motor, |f| answers.push(f));
    }

    /// `f` to the drive; its answers wait for the ECU's next drive call.
    fn send_to_drive(&mut self, f: &Frame) {
        let answers = self.drive.on_frame(f, &mut self.motor);
        self.answers.extend(answers);
    }

    /// One millisecond of the drive task: the drive runs to `t`, its answers to what the ECU
    /// sent in the previous one (a bus round trip later) go to the ECU, then the ECU polls;
    /// everything the ECU sends goes to the drive. The frames the ECU sent, in order.
    fn step(&mut self, t: u64) -> Vec<Frame> {
        self.advance(t);
        let answers = std::mem::take(&mut self.answers);
        let mut sent = Vec::new();
        for answer in &answers {
            sent.extend(self.ecu.on_drive_frame(t, answer));
        }
        sent.extend(self.ecu.drive_poll(t));
        for f in &sent {
            self.send_to_drive(f);
        }
        sent
    }

    /// Runs the car from `from` to `to` as the firmware's tasks do: the drive task every 1 ms,
    /// the encoder (column at `column`) and the vehicle's frame (`as_state`, `deg`; none for
    /// a NaN `deg`) every 10 ms. Every frame the ECU sent.
    fn run(&mut self, from: u64, to: u64, as_state: AsState, deg: f32, column: f32) -> Vec<Frame> {
        let mut sent = Vec::new();
        let mut t = from;
        while t < to {
            if (t - from).is_multiple_of(10 * MS) {
                let _ = self.ecu.on_encoder(t, SteeringDeg(column));
                if !deg.is_nan() {
                    let _ = self.vehicle.send(&mut self.ecu, t, as_state, deg);
                }
            }
            sent.extend(self.step(t));
            t += MS;
        }
        sent
    }
}

fn is_disable(f: &Frame) -> bool {
    Some(*f) == crate::canopen::epos4::disable_voltage_frame(node())
}

/// The link brings the drive up through the ECU's drive calls, and in AS Driving the
/// drive reaches Operation enabled and is given the reference as the CSP target: the
/// column-derived angle plus the origin (the drive counted from 500 at power-up, the
/// column stood at 0).
#[test]
fn the_ecu_brings_the_epos4_up_and_steers_it() {
    let mut b = Bench::new(500);
    let sent = b.started.clone();
    assert!(!sent.is_empty(), "no configuration frame at the start");
    let _ = b.run(0, 200 * MS, AsState::Off, 0.0, 0.0);
    assert_eq!(b.ecu.link().map(|l| l.phase()), Some(Phase::Standby));
    assert_eq!(b.ecu.output().state, EcuState::Idle);
    assert_eq!(b.ecu.motor_origin_counts(), Some(500));
    let _ = b.run(200 * MS, 400 * MS, AsState::Driving, 0.0, 0.0);
    assert_eq!(b.drive.cia402_state(), State::OperationEnabled);
    assert_eq!(b.ecu.output().state, EcuState::Tracking);
    assert!(
        b.ecu.output().faults.is_empty(),
        "{:?}",
        b.ecu.output().faults
    );
    assert_eq!(b.motor.targets.last(), Some(&500));
    // 10 deg at the wheel, reached through the enable ramp.
    let _ = b.run(400 * MS, 600 * MS, AsState::Driving, 10.0, 0.0);
    let scale = b.ecu.link().unwrap().scale();
    let want = scale
        .inc_from_motor(Gearing::PAPER.motor_from_steering(SteeringDeg(10.0).into()))
        .unwrap();
    assert_eq!(b.motor.targets.last(), Some(&(500 + want)));
    assert_eq!(b.ecu.pending_overflow(), 0);
}

/// The CSP target for `deg` at the wheel, in the drive's increments from the origin.
fn inc_at(ecu: &Ecu, deg: f32) -> i32 {
    let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
    ecu.link().unwrap().scale().inc_from_motor(motor).unwrap()
}

/// A demand change found outside the drive calls (here the reference timeout, seen by
/// the supervisor's tick) leaves its disable for the next drive poll: on the bus within
/// 1 ms, before anything else.
#[test]
fn a_disable_decided_by_a_tick_goes_out_first_at_the_next_drive_poll() {
    let (mut b, t0) = Bench::tracking();
    // The vehicle falls silent; the encoder and the supervisor keep running.
    let mut t = t0;
    let disabled_at = loop {
        t += MS;
        if (t - t0).is_multiple_of(2 * MS) {
            let _ = b.ecu.on_encoder(t, SteeringDeg(0.0));
        }
        if b.ecu.tick(t).demand == DriveDemand::Disabled {
            break t;
        }
        let _ = b.step(t);
        assert!(t < t0 + 200 * MS, "never disabled");
    };
    let sent = b.step(disabled_at);
    assert!(sent.first().is_some_and(is_disable), "{sent:?}");
    assert_eq!(b.drive.cia402_state(), State::SwitchOnDisabled);
    assert!(b.ecu.output().faults.contains(Fault::ReferenceTimeout));
}

/// The drive's current (TPDO2) feeds the over-current check: 30 A in the drive's 10 ms
/// samples latches within 20 ms and disables the drive; the status and motor frames carry
/// the drive's current.
#[test]
fn the_drives_current_feeds_the_over_current_check_and_the_frames() {
    let (mut b, t0) = Bench::tracking();
    b.motor.current_ma = 5_000;
    let _ = b.run(t0, t0 + 20 * MS, AsState::Driving, 0.0, 0.0);
    let protocol = ProtocolConfig::default();
    let status = protocol.decode_status(&b.ecu.status_frame()).unwrap();
    assert!((status.current.0 - 5.0).abs() < 0.1, "{:?}", status.current);
    let motor = protocol.decode_motor(&b.ecu.motor_frame()).unwrap();
    assert!(
        (motor.current_mean.0 - 5.0).abs() < 0.1,
        "{:?}",
        motor.current_mean
    );
    b.motor.current_ma = 30_000;
    let t1 = t0 + 20 * MS;
    let mut latched_at = None;
    for k in 0..40 {
        let t = t1 + k * MS;
        let _ = b.step(t);
        if latched_at.is_none() && b.ecu.output().faults.contains(Fault::OverCurrent) {
            latched_at = Some(t - t1);
        }
    }
    assert!(latched_at.is_some_and(|at| at <= 20 * MS), "{latched_at:?}");
    assert_eq!(b.drive.cia402_state(), State::SwitchOnDisabled);
}

/// An EMCY from the drive latches `EposFault` with its code. The failed link is not
/// reset while the AS state is Driving; in AS Off it is reset at once and then at most
/// once a second; back in Standby the cause is gone and a clear request clears.
#[test]
fn a_failed_link_is_reset_only_in_as_off_and_at_most_once_a_second() {
    let (mut b, t0) = Bench::tracking();
    let emcy = crate::canopen::emcy::Emcy {
        error_code: 0x3210,
        error_register: 0x04,
        vendor: [0; 5],
    }
    .to_frame(node())
    .unwrap();
    let _ = b.ecu.on_drive_frame(t0, &emcy);
    let out = b.ecu.output();
    assert!(out.faults.contains(Fault::EposFault), "{out:?}");
    let record = b.ecu.machine().fault_log().iter().last().copied();
    assert_eq!(
        record.map(|r| (r.fault, r.detail)),
        Some((Fault::EposFault, 0x3210))
    );
    let t1 = t0 + 2000 * MS;
    let _ = b.run(t0, t1, AsState::Driving, 0.0, 0.0);
    assert!(
        b.ecu.link().unwrap().error().is_some(),
        "reset while AS Driving"
    );
    // A clear asked for in AS Driving is refused, and counted.
    assert_eq!(b.ecu.clear_refusals(), 0);
    let f = b.vehicle.frame(AsState::Driving, 0.0, true);
    let _ = b.ecu.on_reference_frame(t1, &f);
    assert_eq!(b.ecu.clear_refusals(), 1);
    // AS Off: reset at once, the link is back in Standby within 100 ms.
    let t2 = t1 + 100 * MS;
    let _ = b.run(t1, t2, AsState::Off, 0.0, 0.0);
    assert_eq!(b.ecu.link().unwrap().phase(), Phase::Standby);
    // A second failure 100 ms later waits for the second's end (t1 + 1 s).
    let _ = b.ecu.on_drive_frame(t2, &emcy);
    let _ = b.run(t2, t1 + 990 * MS, AsState::Off, 0.0, 0.0);
    assert!(
        b.ecu.link().unwrap().error().is_some(),
        "reset within the second"
    );
    let t3 = t1 + 1100 * MS;
    let _ = b.run(t1 + 990 * MS, t3, AsState::Off, 0.0, 0.0);
    assert_eq!(b.ecu.link().unwrap().phase(), Phase::Standby);
    // The cause is gone: the clear bit's rising edge clears.
    let f = b.vehicle.frame(AsState::Off, 0.0, true);
    let out = b.ecu.on_reference_frame(t3, &f);
    assert!(out.faults.is_empty(), "{:?}", out.faults);
    assert_eq!(b.ecu.clear_refusals(), 1);
}

/// EPOS4 mode: the enable ramp starts where the column is once the drive is in Operation
/// enabled, and the CSP target then moves at most the ramp's speed toward a far reference.
#[test]
fn an_epos4_enable_ramps_the_target_from_the_column() {
    let mut b = Bench::new(500);
    // The link comes up with no vehicle frame yet ...
    let _ = b.run(0, 200 * MS, AsState::Off, f32::NAN, 0.0);
    // ... which asks for 30 deg from its first frame, in AS Driving, on. The motor follows
    // each target and the column the motor (a stiff belt).
    b.motor.follows = true;
    let mut t = 200 * MS;
    while t < 900 * MS {
        if t.is_multiple_of(10 * MS) {
            let motor = b.ecu.motor_angle();
            let column = SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor));
            let _ = b.ecu.on_encoder(t, column);
            let _ = b.vehicle.send(&mut b.ecu, t, AsState::Driving, 30.0);
        }
        let _ = b.step(t);
        t += MS;
    }
    assert!(
        b.ecu.output().faults.is_empty(),
        "{:?}",
        b.ecu.output().faults
    );
    // The ramp's speed for a 10 ms cycle, one increment of rounding.
    let per_cycle = inc_at(&b.ecu, ENABLE_RAMP_DPS * 0.01) + 1;
    let steps: Vec<i32> = b.motor.targets.windows(2).map(|w| w[1] - w[0]).collect();
    assert!(
        b.motor.targets.first() == Some(&500),
        "{:?}",
        b.motor.targets
    );
    assert!(steps.iter().all(|s| s.abs() <= per_cycle), "{steps:?}");
    // 30 deg at the ramp's speed and acceleration: there after 0.5 s of the 0.7 s.
    assert_eq!(b.motor.targets.last(), Some(&(500 + inc_at(&b.ecu, 30.0))));
}

/// The origin comes from the column: a drive that powered up at 500 increments with the
/// column at 5 deg has its column 0 at 500 less 5 deg's increments, and the ECU's motor
/// angle reads 5 deg at the wheel.
#[test]
fn the_epos4_origin_is_taken_from_the_column() {
    let mut b = Bench::new(500);
    let _ = b.run(0, 200 * MS, AsState::Off, 0.0, 5.0);
    let origin = 500 - inc_at(&b.ecu, 5.0);
    assert_eq!(b.ecu.motor_origin_counts(), Some(origin));
    let wheel = SteeringDeg::from(Gearing::PAPER.steering_from_motor(b.ecu.motor_angle()));
    let resolution = 360.0 / inc_at(&b.ecu, 360.0) as f32;
    assert!((wheel.0 - 5.0).abs() <= resolution, "{wheel:?}");
    let _ = b.run(200 * MS, 400 * MS, AsState::Driving, 5.0, 5.0);
    assert_eq!(b.ecu.output().state, EcuState::Tracking);
    assert_eq!(b.motor.targets.last(), Some(&500));
}

/// Direct mode: the origin is the Hall count nearest to the column's angle through the
/// gearing, so the motor angle the ECU believes is within half a count of the column's.
#[test]
fn the_direct_origin_rounds_to_the_nearest_hall_count() {
    let half_count = std::f32::consts::PI / HALL_COUNTS_PER_REV as f32;
    for deg in [0.3f32, 1.0, 2.3, 5.55, -7.2, 13.1, -0.4] {
        let mut ecu = Ecu::paper().unwrap();
        let _ = ecu.position_tick(0);
        let _ = ecu.on_encoder(0, SteeringDeg(deg));
        let want = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
        let got = ecu.motor_angle();
        assert!(
            (got.0 - want.0).abs() <= half_count + 1e-5,
            "{deg} deg: motor {} rad, column says {} rad",
            got.0,
            want.0
        );
    }
}

/// Direct mode: the motor frame carries the mean of the current samples since the last
/// motor frame, and NaN when none came.
#[test]
fn the_motor_frame_carries_the_mean_current_since_the_last_one() {
    let mut ecu = Ecu::paper().unwrap();
    let protocol = ProtocolConfig::default();
    for k in 0..20u64 {
        let amps = if k < 10 { 2.0 } else { 4.0 };
        let _ = ecu.current_tick(k * 50, Amps(amps));
    }
    let motor = protocol.decode_motor(&ecu.motor_frame()).unwrap();
    assert!(
        (motor.current_mean.0 - 3.0).abs() < 0.01,
        "{:?}",
        motor.current_mean
    );
    let motor = protocol.decode_motor(&ecu.motor_frame()).unwrap();
    assert!(motor.current_mean.0.is_nan(), "{:?}", motor.current_mean);
}

/// Direct mode: the origin is taken from the column once (and at each enable), not on
/// every sample: a motor that turns 20 deg (at the wheel) while the column stands (a
/// broken belt) is a disagreement, latched 20 ms after it exceeds the window.
#[test]
fn a_motor_turning_without_the_column_is_a_disagreement() {
    let mut ecu = Ecu::paper().unwrap();
    let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(20.0).into());
    let hall = hall_from_motor(f64::from(motor.0));
    let _ = ecu.position_tick(0);
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = ecu.position_tick(hall);
    let mut latched_at = None;
    for k in 1..=30u64 {
        let out = ecu.on_encoder(k * MS, SteeringDeg(0.0));
        if latched_at.is_none() && out.faults.contains(Fault::EncoderMotorDisagreement) {
            latched_at = Some(k * MS);
        }
    }
    assert_eq!(latched_at, Some(21 * MS));
}

/// EPOS4 mode: a drive that does not follow its target (the motor stands while the
/// reference is 30 deg away) latches `TrackingError` through the ECU's encoder path.
#[test]
fn an_epos4_that_does_not_follow_latches_a_tracking_error() {
    let mut b = Bench::new(500);
    let _ = b.run(0, 200 * MS, AsState::Off, f32::NAN, 0.0);
    let _ = b.run(200 * MS, 1200 * MS, AsState::Driving, 30.0, 0.0);
    assert!(
        b.ecu.output().faults.contains(Fault::TrackingError),
        "{:?}",
        b.ecu.output()
    );
}

/// The ECU-mode constructors: the direct one runs the ECU-mode cascade; over an EPOS4 the
/// drive gets Table 3's gains with the model's feedforward in mA (A x 1000), and the ECU
/// brings it up and steers it.
#[test]
fn ecu_mode_runs_its_cascade_direct_and_its_feedforward_on_the_epos4() {
    let ecu = Ecu::build(EcuBuild::new(ControllerKind::Ecu, DriveChoice::Direct), 0).unwrap();
    assert!(matches!(
        ecu.drive(),
        Drive::Direct(d) if matches!(d.controller(), SteeringController::Ecu(_))
    ));
    let gains = Ecu::ecu_mode_epos4_gains();
    assert!((gains.ff_velocity_ma_s_per_rad / 1000.0 - EcuTuning::PAPER.ff_velocity).abs() < 1e-6);
    assert!(
        (gains.ff_acceleration_ma_s2_per_rad / 1000.0 - EcuTuning::PAPER.ff_acceleration).abs()
            < 1e-9
    );
    assert!(gains.ff_velocity_ma_s_per_rad > 0.0 && gains.ff_acceleration_ma_s2_per_rad > 0.0);
    let feedback_only = |g: EposGains| EposGains {
        ff_velocity_ma_s_per_rad: 0.0,
        ff_acceleration_ma_s2_per_rad: 0.0,
        ..g
    };
    assert_eq!(feedback_only(gains), feedback_only(EposGains::PAPER));

    let mut config = Epos4Config::paper(node());
    config.gains = gains;
    let mut b = Bench::with(ControllerKind::Ecu, config, 500);
    let _ = b.run(0, 400 * MS, AsState::Driving, 0.0, 0.0);
    assert_eq!(b.ecu.output().state, EcuState::Tracking);
    let written = b.drive.object(od::POSITION_FF_VELOCITY);
    assert_eq!(
        written,
        Some((gains.ff_velocity_ma_s_per_rad * 1000.0).round() as u32)
    );
    assert_eq!(b.motor.targets.last(), Some(&500));
}

/// A frame whose angle breaks the rate rule is dropped; its AS state counts only when it
/// does not allow power. AS Driving from such a frame after AS Off powers nothing.
#[test]
fn a_dropped_driving_frame_powers_nothing() {
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    for k in 0..5u64 {
        let _ = ecu.on_encoder(k * 10 * MS, SteeringDeg(0.0));
        let _ = vehicle.send(&mut ecu, k * 10 * MS, AsState::Off, 0.0);
    }
    // 60 deg 10 ms after 0 deg: authentic and in sequence, but dropped by the rate rule.
    let _ = ecu.on_encoder(50 * MS, SteeringDeg(0.0));
    let out = vehicle.send(&mut ecu, 50 * MS, AsState::Driving, 60.0);
    assert_eq!(out.demand, DriveDemand::Disabled);
    assert_eq!(out.state, EcuState::Idle);
    assert_eq!(ecu.machine().as_state(), Some(AsState::Off));
}

/// Direct mode, through the 20 kHz current tick: 20 consecutive samples above 22 A latch
/// `OverCurrent` and switch the bridge off; samples alternating above and within never do
/// (a sample within ends the run, fast path or not).
#[test]
fn the_current_tick_latches_only_a_run_of_over_current_samples() {
    let mut ecu = Ecu::paper().unwrap();
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = Vehicle::new().send(&mut ecu, 0, AsState::Driving, 0.0);
    let _ = ecu.position_tick(0);
    // Over on odd samples, within on even ones, the last (the 200th) within.
    for k in 1..=200u64 {
        let amps = if k % 2 == 1 { 25.0 } else { 10.0 };
        let _ = ecu.current_tick(k * 50, Amps(amps));
    }
    assert!(ecu.output().faults.is_empty(), "{:?}", ecu.output().faults);
    let mut latched_at = None;
    for k in 1..=40u64 {
        let voltage = ecu.current_tick(10 * MS + k * 50, Amps(-25.0));
        if latched_at.is_none() && ecu.output().faults.contains(Fault::OverCurrent) {
            latched_at = Some(k);
            assert_eq!(voltage, None, "bridge off in the latching call");
        } else if latched_at.is_none() {
            assert!(voltage.is_some(), "bridge on before the latch");
        }
    }
    assert_eq!(latched_at, Some(20), "samples to latch");
}

/// The watchdog's progress counts: one per supervisor call (tick, reference frame,
/// encoder sample or error) and one per fast-loop period (`fast_loop_ran`, and each
/// EPOS4-mode drive poll); the supervisor's last call time never goes back.
#[test]
fn the_progress_counts_and_the_supervisors_time_follow_the_calls() {
    let mut ecu = Ecu::paper().unwrap();
    assert_eq!(ecu.supervisor_seen_us(), None);
    assert_eq!((ecu.progress().supervisor, ecu.progress().fast), (0, 0));
    let _ = ecu.tick(5 * MS);
    let _ = ecu.on_encoder(3 * MS, SteeringDeg(0.0));
    let _ = Vehicle::new().send(&mut ecu, 7 * MS, AsState::Off, 0.0);
    let _ = ecu.on_encoder_error(6 * MS, 1);
    assert_eq!(ecu.supervisor_seen_us(), Some(7 * MS));
    ecu.fast_loop_ran();
    ecu.fast_loop_ran();
    assert_eq!((ecu.progress().supervisor, ecu.progress().fast), (4, 2));
    let mut b = Bench::new(0);
    let _ = b.step(MS);
    let _ = b.step(2 * MS);
    assert_eq!(b.ecu.progress().fast, 2);
}

/// Direct mode: after a stall (bridge off, cascade not stepped) the fast loop restarts
/// the cascade where the motor is now, in the column-aligned frame: the next position
/// tick's set-point is the motor's angle and it asks for no current.
#[test]
fn a_resync_restarts_the_cascade_at_the_motor() {
    let mut ecu = Ecu::paper().unwrap();
    let _ = ecu.position_tick(0);
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = Vehicle::new().send(&mut ecu, 0, AsState::Driving, 0.0);
    // The wheels were turned to 10 deg while the loop stood.
    let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(10.0).into());
    let hall = hall_from_motor(f64::from(motor.0));
    let _ = ecu.position_tick(hall);
    ecu.resync_cascade();
    let current = ecu.position_tick(hall);
    assert!(current.0.abs() < 1.0, "{} A at the set-point", current.0);
    let Drive::Direct(cascade) = ecu.drive() else {
        panic!("direct mode")
    };
    let cascade = cascade.controller();
    let at = cascade.setpoint().position;
    assert!(
        (at.0 - motor_from_hall(hall).0).abs() < 1e-4,
        "set-point {} rad, motor {} rad",
        at.0,
        motor_from_hall(hall).0
    );
}

/// The drive's fault cause is gone exactly when the link is back up (Standby, Disabling
/// or Cyclic after the reset), not while it is still failed: a clear asked for before the reset is refused,
/// one asked for right after the call that brought the link up is granted.
#[test]
fn a_drive_fault_clears_only_once_the_link_is_back_up() {
    let (mut b, t0) = Bench::tracking();
    let emcy = crate::canopen::emcy::Emcy {
        error_code: 0x3210,
        error_register: 0x04,
        vendor: [0; 5],
    }
    .to_frame(node())
    .unwrap();
    let _ = b.ecu.on_drive_frame(t0, &emcy);
    // Still in AS Driving (no reset): the link stays failed for 20 ms of drive polls.
    let t1 = t0 + 20 * MS;
    let _ = b.run(t0, t1, AsState::Driving, 0.0, 0.0);
    assert!(b.ecu.link().unwrap().error().is_some());
    // AS Off and a clear at once, before the next drive poll resets the link: refused.
    let _ = b.vehicle.send(&mut b.ecu, t1, AsState::Off, 0.0);
    let f = b.vehicle.frame(AsState::Off, 0.0, true);
    let out = b.ecu.on_reference_frame(t1, &f);
    assert!(
        out.faults.contains(Fault::EposFault),
        "cleared while failed"
    );
    // The bit low again, so the next request is a rising edge.
    let _ = b.vehicle.send(&mut b.ecu, t1, AsState::Off, 0.0);
    // Run the drive task until the call that brings the link up; clear right after it.
    let up = |ecu: &Ecu| {
        matches!(
            ecu.link().unwrap().phase(),
            Phase::Standby | Phase::Disabling | Phase::Cyclic
        )
    };
    let mut t = t1;
    'up: loop {
        t += MS;
        assert!(t < t1 + 500 * MS, "the link never came back");
        if (t - t1).is_multiple_of(10 * MS) {
            let _ = b.ecu.on_encoder(t, SteeringDeg(0.0));
            let _ = b.vehicle.send(&mut b.ecu, t, AsState::Off, 0.0);
        }
        b.advance(t);
        let mut sent = Vec::new();
        for answer in std::mem::take(&mut b.answers) {
            sent.extend(b.ecu.on_drive_frame(t, &answer));
            if up(&b.ecu) {
                break 'up;
            }
        }
        sent.extend(b.ecu.drive_poll(t));
        if up(&b.ecu) {
            break;
        }
        for f in &sent {
            b.send_to_drive(f);
        }
    }
    let f = b.vehicle.frame(AsState::Off, 0.0, true);
    let out = b.ecu.on_reference_frame(t, &f);
    assert!(out.faults.is_empty(), "{:?}", out.faults);
}

/// EPOS4 mode: after 120 ms without frames the vehicle's next frame is 48 deg away (the
/// E2E budget allows it); the drive's target moves at most the 400 deg/s rate times the
/// 10 ms SYNC cycle, however the frames fall between SYNCs.
#[test]
fn after_a_gap_the_epos4_target_moves_at_the_rate_limit() {
    let (mut b, t) = Bench::tracking();
    b.motor.follows = true;
    let before = b.motor.targets.len();
    // Silence, then 48 deg, on time again.
    let _ = b.run(t, t + 120 * MS, AsState::Driving, f32::NAN, 0.0);
    let start = t + 120 * MS;
    let mut t = start;
    while t < start + 200 * MS {
        if t.is_multiple_of(10 * MS) {
            let motor = b.ecu.motor_angle();
            let column = SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor));
            let _ = b.ecu.on_encoder(t, column);
            let _ = b.vehicle.send(&mut b.ecu, t, AsState::Driving, 48.0);
        }
        let _ = b.step(t);
        t += MS;
    }
    assert!(
        b.ecu.output().faults.is_empty(),
        "{:?}",
        b.ecu.output().faults
    );
    let per_cycle = inc_at(&b.ecu, 4.0) + 1;
    let steps: Vec<i32> = b.motor.targets[before..]
        .windows(2)
        .map(|w| w[1] - w[0])
        .collect();
    assert!(steps.iter().all(|s| s.abs() <= per_cycle), "{steps:?}");
    assert_eq!(b.motor.targets.last(), Some(&(500 + inc_at(&b.ecu, 48.0))));
}

//! The ECU driven directly: enables, origins, the AS rules, the diagnostic pages.

use super::*;
use crate::protocol::Reference;
use crate::sensors::hall_from_motor;

const MS: u64 = 1000;

/// Sends reference frames with consecutive counters, as the vehicle computer does.
pub(super) struct Vehicle {
    protocol: ProtocolConfig,
    counter: AliveCounter,
}

impl Vehicle {
    pub(super) fn new() -> Self {
        Vehicle {
            protocol: ProtocolConfig::default(),
            counter: AliveCounter::wrapping(0),
        }
    }

    pub(super) fn frame(&mut self, as_state: AsState, deg: f32, clear_faults: bool) -> Frame {
        self.counter = self.counter.next();
        self.protocol.encode_reference(&Reference {
            angle: SteeringDeg(deg),
            as_state,
            counter: self.counter,
            clear_faults,
        })
    }

    pub(super) fn send(
        &mut self,
        ecu: &mut Ecu,
        now_us: u64,
        as_state: AsState,
        deg: f32,
    ) -> Output {
        let f = self.frame(as_state, deg, false);
        ecu.on_reference_frame(now_us, &f)
    }
}

/// The Hall count of a motor standing at `deg` at the wheel (power-up at column 0).
fn hall_at(deg: f32) -> i32 {
    let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
    hall_from_motor(f64::from(motor.0))
}

/// One 0.5 ms step of the tasks at their rates around an enable at 100 ms: the column sample
/// (`column`, deg) every 2 ms, the vehicle's frame every 10 ms (AS Off before 100 ms, then AS
/// Driving, at 10 deg), then the position tick with the motor at `hall`.
fn enabled_at_100_ms(ecu: &mut Ecu, vehicle: &mut Vehicle, t: u64, column: f32, hall: i32) {
    if t.is_multiple_of(2 * MS) {
        let _ = ecu.on_encoder(t, SteeringDeg(column));
    }
    if t.is_multiple_of(10 * MS) {
        let s = if t < 100 * MS {
            AsState::Off
        } else {
            AsState::Driving
        };
        let _ = vehicle.send(ecu, t, s, 10.0);
    }
    let _ = ecu.position_tick(hall);
}

#[test]
fn an_enable_by_an_encoder_sample_resets_the_cascade() {
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    // Tracking 0 deg for 100 ms.
    let mut t = 0;
    while t < 100 * MS {
        let _ = ecu.on_encoder(t, SteeringDeg(0.0));
        let _ = vehicle.send(&mut ecu, t, AsState::Driving, 0.0);
        for _ in 0..20 {
            let _ = ecu.position_tick(0);
        }
        t += 10 * MS;
    }
    assert_eq!(ecu.output().demand, DriveDemand::Track);
    // AS Finished: disabled. The driver turns the wheel to 30 deg; the encoder task is
    // late (no sample for 40 ms, allowed while the drive may not be powered).
    let _ = vehicle.send(&mut ecu, t, AsState::Finished, 0.0);
    for k in 1..=50u16 {
        let deg = 0.6 * f32::from(k);
        let _ = ecu.position_tick(hall_at(deg));
        let _ = ecu.on_encoder(t + u64::from(k) * 2 * MS, SteeringDeg(deg));
    }
    let hall = hall_at(30.0);
    t += 140 * MS;
    // AS Driving with the vehicle already asking for 30 deg: no fresh encoder sample yet.
    let out = vehicle.send(&mut ecu, t, AsState::Driving, 30.0);
    assert_eq!(out.demand, DriveDemand::Disabled, "encoder not fresh yet");
    // The encoder sample is the event that enables the drive.
    let out = ecu.on_encoder(t + MS, SteeringDeg(30.0));
    assert_eq!(out.demand, DriveDemand::Track);
    // The motor is where the vehicle wants it: the loop must not push it anywhere.
    for k in 0..20 {
        let current = ecu.position_tick(hall);
        assert!(
            current.0.abs() < 1.0,
            "position tick {k}: {} A with the motor at the reference",
            current.0
        );
    }
}

/// A glitch of 0.5, 1.5 or 2.9 deg in the column sample just before the enabling frame
/// (each within the jump check's 2 deg between 2 ms samples): either the origin is still
/// right to 0.1 deg, or a fault is latched. Never a silent offset.
#[test]
fn a_glitch_in_the_sample_before_the_enable_leaves_no_silent_origin_offset() {
    for glitch in [0.0f32, 0.5, 1.5, 2.9] {
        let mut ecu = Ecu::paper().unwrap();
        let mut vehicle = Vehicle::new();
        let hall = hall_at(10.0);
        let truth = Gearing::PAPER.motor_from_steering(SteeringDeg(10.0).into());
        let mut t = 0u64;
        // AS Off, the column and the motor resting at 10 deg, the tasks at their rates.
        while t <= 300 * MS {
            // The sample at 100 ms is the last before the first AS Driving frame.
            let column = if t == 100 * MS { 10.0 + glitch } else { 10.0 };
            enabled_at_100_ms(&mut ecu, &mut vehicle, t, column, hall);
            t += 500;
        }
        let offset = SteeringDeg::from(
            Gearing::PAPER.steering_from_motor(MotorRad(ecu.motor_angle().0 - truth.0)),
        );
        let faults = ecu.output().faults;
        assert!(
            faults.contains(crate::faults::Fault::Origin)
                || (offset.0.abs() <= 0.1 && faults.is_empty()),
            "glitch {glitch} deg: origin off by {} deg, faults {faults:?}",
            offset.0
        );
        if glitch == 0.0 {
            assert_eq!(ecu.output().demand, DriveDemand::Track, "a clean enable");
        } else {
            assert_eq!(ecu.output().demand, DriveDemand::Disabled, "{glitch} deg");
            // The cause is judged at each enable: AS Off clears it, and the next enable
            // on clean samples takes the right origin.
            let _ = ecu.on_encoder(t, SteeringDeg(10.0));
            let f = vehicle.frame(AsState::Off, 10.0, true);
            let out = ecu.on_reference_frame(t, &f);
            assert!(out.faults.is_empty(), "cleared in AS Off: {:?}", out.faults);
            let mut t = t;
            for _ in 0..10 {
                t += 2 * MS;
                let _ = ecu.on_encoder(t, SteeringDeg(10.0));
            }
            let out = vehicle.send(&mut ecu, t, AsState::Ready, 10.0);
            assert_eq!(out.demand, DriveDemand::Track, "{glitch} deg, re-enabled");
            let offset = SteeringDeg::from(
                Gearing::PAPER.steering_from_motor(MotorRad(ecu.motor_angle().0 - truth.0)),
            );
            assert!(offset.0.abs() <= 0.1, "re-enabled {} deg off", offset.0);
        }
    }
}

/// An origin 2.9 deg off (every sample of the enable's window glitched alike, so they
/// agree) is found while the drive rests on: the loop holds the motor where its wrong
/// origin says the reference is, the column reads 2.9 deg apart, little current flows.
/// With the right origin nothing latches.
#[test]
fn a_wrong_origin_latches_once_the_drive_rests() {
    for offset in [0.0f32, 2.9, -2.9] {
        let mut ecu = Ecu::paper().unwrap();
        let mut vehicle = Vehicle::new();
        // The motor's true angle, wheel deg; the column reads it (plus the glitch while
        // the window before the enable is sampled).
        let mut motor = 10.0f32;
        let mut t = 0u64;
        let mut latched_at = None;
        while t <= 1_000 * MS {
            let glitched = (84 * MS..=100 * MS).contains(&t);
            let column = if glitched { motor + offset } else { motor };
            enabled_at_100_ms(&mut ecu, &mut vehicle, t, column, hall_at(motor));
            if ecu.output().demand != DriveDemand::Disabled {
                // A stiff drive: the motor is where the set-point is, in truth.
                let aligned = setpoint_deg(&ecu);
                let origin_error = ecu.motor_angle().0
                    - Gearing::PAPER
                        .motor_from_steering(SteeringDeg(motor).into())
                        .0;
                let error =
                    SteeringDeg::from(Gearing::PAPER.steering_from_motor(MotorRad(origin_error)));
                motor = aligned - error.0;
            }
            if latched_at.is_none() && ecu.output().faults.contains(crate::faults::Fault::Origin) {
                latched_at = Some(t);
            }
            t += 500;
        }
        if offset == 0.0 {
            assert_eq!(latched_at, None, "the right origin");
            assert_eq!(ecu.output().demand, DriveDemand::Track);
        } else {
            let at = latched_at.expect("a wrong origin latches");
            // The enable at 100 ms, the ramp over the 2.9 deg the wrong column reads
            // (0.11 s, accelerating and slowing down), then ORIGIN_REST_US at rest.
            assert!(at <= 350 * MS, "{offset} deg: latched at {at} us");
            let detail = ecu.machine().fault_log().iter().last().map(|r| r.detail);
            assert!(
                detail.is_some_and(|d| d.abs() > crate::steering::ORIGIN_RESTING_DETAIL),
                "{detail:?}"
            );
        }
    }
}

/// With the column beyond +-90 deg at the enable (the drive's limits allow 110), the ramp
/// starts there: its samples beyond the vehicle's +-90 deg are the ECU's own and are taken,
/// so the set-point moves at most at the ramp's speed from the first tick to the reference, in
/// paper mode and ECU mode.
#[test]
fn an_enable_beyond_90_deg_ramps_from_the_column() {
    for (column, target) in [(105.0f32, 80.0f32), (-108.0, -60.0), (100.0, 95.0)] {
        for mut ecu in [
            Ecu::paper().unwrap(),
            Ecu::build(EcuBuild::new(ControllerKind::Ecu, DriveChoice::Direct), 0).unwrap(),
        ] {
            let mut vehicle = Vehicle::new();
            let mut position = column;
            let mut previous = None;
            let mut t = 0u64;
            let target = target.clamp(-90.0, 90.0);
            while t < 900 * MS {
                // The position tick first (the fast loop runs from power-up), and its
                // set-point read only when the tick ran with the drive on.
                let on = ecu.output().demand != DriveDemand::Disabled;
                let _ = ecu.position_tick(hall_at(position));
                if t.is_multiple_of(2 * MS) {
                    let _ = ecu.on_encoder(t, SteeringDeg(position));
                }
                if t.is_multiple_of(10 * MS) {
                    let _ = vehicle.send(&mut ecu, t, AsState::Driving, target);
                }
                if on {
                    let Drive::Direct(cascade) = ecu.drive() else {
                        panic!("direct")
                    };
                    let cascade = cascade.controller();
                    let motor = cascade.setpoint().position;
                    let setpoint = SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor)).0;
                    if let Some(p) = previous {
                        let step: f32 = setpoint - p;
                        assert!(
                            step.abs() <= ENABLE_RAMP_DPS * 0.5e-3 + 0.01,
                            "{column} -> {target}: {step} deg in one tick at {t} us"
                        );
                    }
                    previous = Some(setpoint);
                    position = setpoint;
                }
                t += 500;
            }
            let log: Vec<_> = ecu.machine().fault_log().iter().copied().collect();
            assert!(
                ecu.output().faults.is_empty(),
                "{column} -> {target}: {log:?}"
            );
            assert!(
                (position - target).abs() < 0.5,
                "{column} -> {target}: at {position}"
            );
        }
    }
}

/// The set-point the direct cascade holds, wheel deg.
fn setpoint_deg(ecu: &Ecu) -> f32 {
    let Drive::Direct(cascade) = ecu.drive() else {
        panic!("direct mode")
    };
    let cascade = cascade.controller();
    let motor = cascade.setpoint().position;
    SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor)).0
}

#[test]
fn an_enable_ramps_from_the_measured_column_to_a_far_reference() {
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    // The vehicle asks for 60 deg in the very first AS Driving frame.
    let mut t = MS;
    let out = vehicle.send(&mut ecu, t, AsState::Driving, 60.0);
    assert!(out.drive_just_enabled);
    let mut previous = 0.0f32;
    let mut first_current = None;
    // The motor and the column follow the set-point of the previous period (a drive that
    // keeps up; the tracking check would otherwise see a jammed actuator).
    let mut column = 0.0f32;
    for _period in 0..100 {
        for _ in 0..20 {
            let current = ecu.position_tick(hall_at(column));
            first_current.get_or_insert(current.0);
            let setpoint = setpoint_deg(&ecu);
            // One position tick is 0.5 ms: the ramp allows 0.05 deg per tick.
            let step = setpoint - previous;
            assert!(
                step.abs() <= ENABLE_RAMP_DPS * 0.5e-3 + 1e-3,
                "set-point moved {step} deg in one tick at {t} us"
            );
            previous = setpoint;
        }
        t += 10 * MS;
        column = previous;
        let _ = ecu.on_encoder(t, SteeringDeg(column));
        let _ = vehicle.send(&mut ecu, t, AsState::Driving, 60.0);
    }
    assert!(ecu.output().faults.is_empty(), "{:?}", ecu.output());
    let first = first_current.unwrap_or(f32::NAN);
    assert!(
        first.abs() < 2.0,
        "{first} A on the first tick after the enable"
    );
    // 60 deg at the ramp's speed and acceleration take 0.93 s: there within 1 s.
    assert!((previous - 60.0).abs() < 0.1, "set-point at {previous} deg");
}

#[test]
fn only_the_rising_edge_of_the_clear_bit_clears() {
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = vehicle.send(&mut ecu, 0, AsState::Off, 0.0);
    // A fault latches while the vehicle holds the clear bit; a valid frame then proves
    // the bus is back (the cause is gone).
    let f = vehicle.frame(AsState::Off, 0.0, true);
    let _ = ecu.on_reference_frame(10 * MS, &f);
    let _ = ecu.on_bus_off(15 * MS, 255);
    for k in 2..10 {
        let _ = ecu.on_encoder(k * 10 * MS, SteeringDeg(0.0));
        let f = vehicle.frame(AsState::Off, 0.0, true);
        let out = ecu.on_reference_frame(k * 10 * MS, &f);
        assert!(
            out.faults.contains(crate::faults::Fault::BusOff),
            "cleared by a held bit at {k}0 ms"
        );
    }
    // Released, then set again: that is a request.
    let _ = ecu.on_encoder(100 * MS, SteeringDeg(0.0));
    let _ = vehicle.send(&mut ecu, 100 * MS, AsState::Off, 0.0);
    let f = vehicle.frame(AsState::Off, 0.0, true);
    let out = ecu.on_reference_frame(110 * MS, &f);
    assert!(out.faults.is_empty(), "{:?}", out.faults);
}

#[test]
fn an_emergency_frame_disables_at_once_whatever_its_angle() {
    // 60 deg fails the rate rule after 0 deg, 95 deg the range rule: the frame is still
    // authentic and in sequence, so its AS Emergency holds.
    for deg in [60.0, 95.0, -95.0] {
        let mut ecu = Ecu::paper().unwrap();
        let mut vehicle = Vehicle::new();
        let mut t = 0;
        for _ in 0..5 {
            let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            let _ = vehicle.send(&mut ecu, t, AsState::Driving, 0.0);
            t += 10 * MS;
        }
        assert_eq!(ecu.output().demand, DriveDemand::Track);
        let out = vehicle.send(&mut ecu, t, AsState::Emergency, deg);
        assert_eq!(out.demand, DriveDemand::Disabled, "{deg} deg");
        assert_eq!(out.state, crate::steering::EcuState::Emergency, "{deg} deg");
    }
}

/// After one lost frame the next frame (CRC good) fails the counter
/// check, but a frame that asks for less authority is honoured whatever its counter:
/// AS Emergency, Finished, Off and Manual (and Ready under the DrivingOnly rule) disable in
/// that very frame, 10 ms after the last one, not a period later.
#[test]
fn a_disabling_as_state_is_honoured_in_a_frame_that_fails_only_its_counter() {
    use crate::as_state::Actuation;
    let cases = [
        (Actuation::ReadyOrDriving, AsState::Emergency),
        (Actuation::ReadyOrDriving, AsState::Finished),
        (Actuation::ReadyOrDriving, AsState::Off),
        (Actuation::ReadyOrDriving, AsState::Manual),
        (Actuation::DrivingOnly, AsState::Ready),
    ];
    for (actuation, as_state) in cases {
        for repeat in [false, true] {
            let config = Config::DEFAULT.with_actuation(actuation);
            let mut ecu = Ecu::build(
                EcuBuild {
                    config,
                    ..EcuBuild::new(ControllerKind::Paper, DriveChoice::Direct)
                },
                0,
            )
            .unwrap();
            let mut vehicle = Vehicle::new();
            let mut t = 0;
            for _ in 0..5 {
                let _ = ecu.on_encoder(t, SteeringDeg(0.0));
                let _ = vehicle.send(&mut ecu, t, AsState::Driving, 0.0);
                t += 10 * MS;
            }
            assert_eq!(ecu.output().demand, DriveDemand::Track);
            let f = if repeat {
                // The counter of the last frame again (a repeat, but new content).
                vehicle.counter = AliveCounter::wrapping(vehicle.counter.raw().wrapping_sub(1));
                vehicle.frame(as_state, 0.0, false)
            } else {
                // One frame lost on the bus: the next one jumps the counter.
                let _lost = vehicle.frame(AsState::Driving, 0.0, false);
                vehicle.frame(as_state, 0.0, false)
            };
            let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            let drops = *ecu.e2e().drops();
            let out = ecu.on_reference_frame(t, &f);
            let after = *ecu.e2e().drops();
            assert_eq!(
                (
                    after.stale - drops.stale,
                    after.counter_jump - drops.counter_jump
                ),
                if repeat { (1, 0) } else { (0, 1) },
                "the frame fails its counter"
            );
            assert_eq!(
                out.demand,
                DriveDemand::Disabled,
                "{as_state:?} ({actuation:?}, repeat {repeat})"
            );
        }
    }
    // A frame asking for more authority (AS Driving) with a bad counter is not taken.
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = vehicle.send(&mut ecu, 0, AsState::Off, 0.0);
    let _lost = vehicle.frame(AsState::Ready, 0.0, false);
    let _ = ecu.on_encoder(10 * MS, SteeringDeg(0.0));
    let out = vehicle.send(&mut ecu, 10 * MS, AsState::Ready, 0.0);
    assert_eq!(
        out.demand,
        DriveDemand::Disabled,
        "Ready with a jumped counter"
    );
}

/// AS Emergency is released only by an AS Off frame that passes every rule: an Off in a
/// frame that fails its counter disables (the drive is off already) but leaves the
/// emergency standing, so a Ready after it does not power the drive.
#[test]
fn only_an_accepted_as_off_frame_releases_an_emergency() {
    for lost_before_off in [true, false] {
        let mut ecu = Ecu::paper().unwrap();
        let mut vehicle = Vehicle::new();
        let mut t = 0;
        for _ in 0..5 {
            let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            let _ = vehicle.send(&mut ecu, t, AsState::Driving, 0.0);
            t += 10 * MS;
        }
        let out = vehicle.send(&mut ecu, t, AsState::Emergency, 0.0);
        assert_eq!(out.state, EcuState::Emergency);
        if lost_before_off {
            let _lost = vehicle.frame(AsState::Off, 0.0, false);
        }
        for s in [AsState::Off, AsState::Off, AsState::Ready, AsState::Ready] {
            t += 10 * MS;
            let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            let _ = vehicle.send(&mut ecu, t, s, 0.0);
        }
        // The second Off frame was in sequence again: it releases the emergency, and the
        // Ready frames power the drive. With only the first Off (bad counter) it would not.
        assert_eq!(ecu.output().demand, DriveDemand::Track, "{lost_before_off}");
    }
    // Only the counter-failing Off: the emergency stands.
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let _ = ecu.on_encoder(0, SteeringDeg(0.0));
    let _ = vehicle.send(&mut ecu, 0, AsState::Driving, 0.0);
    let _ = vehicle.send(&mut ecu, 10 * MS, AsState::Emergency, 0.0);
    let _lost = vehicle.frame(AsState::Off, 0.0, false);
    let out = vehicle.send(&mut ecu, 20 * MS, AsState::Off, 0.0);
    assert_eq!(out.state, EcuState::Emergency, "Off with a jumped counter");
    assert_eq!(ecu.machine().as_state(), Some(AsState::Emergency));
}

#[test]
fn tracking_is_not_reported_before_the_epos4_is_enabled() {
    use crate::canopen::NodeId;
    use crate::canopen::epos4::Epos4Config;
    let config = Epos4Config::paper(NodeId::new(1).unwrap());
    let mut ecu = Ecu::build(
        EcuBuild::new(ControllerKind::Paper, DriveChoice::Epos4(config)),
        0,
    )
    .unwrap();
    let _ = ecu.drive_start(0);
    let mut vehicle = Vehicle::new();
    // The drive never answers: the link stays in its bring-up.
    for k in 0..10u64 {
        let t = k * 10 * MS;
        let _ = ecu.on_encoder(t, SteeringDeg(0.0));
        let _ = ecu.drive_poll(t);
        let out = vehicle.send(&mut ecu, t, AsState::Driving, 0.0);
        assert_ne!(out.state, EcuState::Tracking, "at {k}0 ms");
        assert_ne!(ecu.output().state, EcuState::Tracking, "at {k}0 ms");
        // Until the link gives up on the silent drive (an SDO time-out, EposFault).
        if out.faults.is_empty() {
            assert_eq!(out.state, EcuState::Arming, "at {k}0 ms");
        }
    }
}

#[test]
fn the_enable_ramp_ends_when_a_fast_reference_crosses_it() {
    // A 4 Hz, 15 deg sine (377 deg/s at its zero crossings, faster than the ramp) from the
    // enable on: the ramp must hand over to the reference, not chase it for ever.
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let mut t = 0u64;
    let mut handed_over_at = None;
    for k in 0..200u64 {
        let s = k as f32 * 0.01;
        let deg = 15.0 * (core::f32::consts::TAU * 4.0 * s).sin() + 20.0;
        let _ = ecu.on_encoder(t, SteeringDeg(0.0));
        let _ = vehicle.send(&mut ecu, t, AsState::Driving, deg);
        // The position ticks of the period, as the fast loop takes them.
        for _ in 0..20 {
            let _ = ecu.position_tick(0);
        }
        if handed_over_at.is_none() && k > 0 && ecu.ramp.is_none() {
            handed_over_at = Some(k);
            let given = ecu.reference.map_or(f32::NAN, |r| r.0);
            assert!((given - deg).abs() < 0.01, "{given} vs {deg}");
        }
        t += 10 * MS;
    }
    let k = handed_over_at.expect("the ramp handed over to the reference");
    // 20 deg at the ramp's speed to the sine's centre, then within one of its periods.
    assert!(k <= 50, "handed over after {k}0 ms");
}

#[test]
fn every_link_failure_code_has_its_own_name_and_drive_codes_have_none() {
    let names: Vec<_> = (0xFF01..=0xFF09).map(link_fault_name).collect();
    assert!(names.iter().all(Option::is_some), "{names:?}");
    let mut distinct = names.clone();
    distinct.sort();
    distinct.dedup();
    assert_eq!(distinct.len(), names.len(), "{names:?}");
    for drive_code in [0, 0x8611, 0x3210, 0xFF00, 0xFF0A] {
        assert_eq!(link_fault_name(drive_code), None, "0x{drive_code:04X}");
    }
}

#[test]
fn the_diagnostic_pages_carry_the_counters_and_the_newest_faults() {
    use crate::protocol::{COUNTER_PAGES, DIAGNOSTIC_ROUND, DiagnosticPage};
    let mut ecu = Ecu::paper().unwrap();
    let mut vehicle = Vehicle::new();
    let _ = vehicle.send(&mut ecu, 0, AsState::Off, 0.0);
    let mut bad = vehicle.frame(AsState::Off, 0.0, false);
    let mut bytes = [0u8; 8];
    bytes.copy_from_slice(bad.data());
    bytes[0] ^= 1;
    bad = Frame::new(bad.id(), &bytes).unwrap();
    let _ = ecu.on_reference_frame(10 * MS, &bad);
    let _ = ecu.on_bus_off(20 * MS, 200);
    let _ = ecu.machine_mut().on_epos_fault(30 * MS, 0x3210);
    let protocol = ProtocolConfig::default();
    let pages: Vec<_> = (0..DIAGNOSTIC_ROUND)
        .map(|_| {
            protocol
                .decode_diagnostic(&ecu.diagnostic_frame(40 * MS))
                .unwrap()
                .page
        })
        .collect();
    let counters = |i: usize| match pages[i] {
        DiagnosticPage::Counters { page, words } if usize::from(page) == i => words,
        p => panic!("page {i}: {p:?}"),
    };
    assert_eq!(counters(0), [0, 1, 0], "one CRC drop");
    assert_eq!(counters(2)[2], 1, "one bus-off");
    assert_eq!(
        counters(4),
        [2, 2, 0],
        "two records held, none acknowledged"
    );
    assert_eq!(counters(5), [0, 0, 0], "the stack not measured");
    use crate::faults::Fault;
    let record = |slot: u8| match pages[usize::from(COUNTER_PAGES + slot)] {
        DiagnosticPage::Record { slot: s, record } if s == slot => {
            record.map(|r| (r.fault_bit, r.detail, r.acknowledged))
        }
        p => panic!("slot {slot}: {p:?}"),
    };
    // Oldest first: the bus-off that came first is the first record.
    assert_eq!(record(0), Some((Fault::BusOff.bit(), 200, false)));
    assert_eq!(record(1), Some((Fault::EposFault.bit(), 0x3210, false)));
    assert!((2..16).all(|slot| record(slot).is_none()));
}

/// The stack's high-water mark goes out on counter page 5, in 4-byte words.
#[test]
fn the_stack_high_water_mark_goes_out_on_page_5() {
    use crate::protocol::{DIAGNOSTIC_ROUND, DiagnosticPage};
    use crate::stack::{PAINT, StackUsage};
    let mut ecu = Ecu::paper().unwrap();
    // A 1 KiB region of which the top 300 bytes were used.
    let region: Vec<u32> = (0..256).map(|i| if i < 181 { PAINT } else { 7 }).collect();
    ecu.set_stack_usage(StackUsage::measure(region.len(), |i| region[i]));
    let protocol = ProtocolConfig::default();
    let page5 = (0..DIAGNOSTIC_ROUND)
        .map(|_| {
            protocol
                .decode_diagnostic(&ecu.diagnostic_frame(0))
                .unwrap()
                .page
        })
        .find(|p| matches!(p, DiagnosticPage::Counters { page: 5, .. }));
    assert_eq!(
        page5,
        Some(DiagnosticPage::Counters {
            page: 5,
            words: [75, 256, 0]
        })
    );
}

/// The root cause reaches the bus: with five faults latched (the first, a bus-off, the
/// cause), one round of the diagnostic frame carries all five in the order they came,
/// each with its age, and a clear acknowledges them without removing them.
#[test]
fn every_record_and_its_age_reach_the_bus_in_one_round_oldest_first() {
    use crate::faults::{FAULT_LOG_CAPACITY, Fault};
    use crate::protocol::{DIAGNOSTIC_ROUND, DiagnosticPage, DiagnosticRecord};
    const S: u64 = 1_000_000;
    let mut ecu = Ecu::paper().unwrap();
    let _ = ecu.on_bus_off(S, 200);
    let _ = ecu.machine_mut().on_epos_fault(2 * S, 0x3210);
    let _ = ecu.machine_mut().on_heartbeat_lost(3 * S);
    let _ = ecu.on_encoder_error(4 * S, 1);
    let _ = ecu.machine_mut().on_invalid_frames_fault(5 * S, 5);
    let protocol = ProtocolConfig::default();
    let round = |ecu: &mut Ecu, now_us: u64| -> Vec<Option<DiagnosticRecord>> {
        (0..DIAGNOSTIC_ROUND)
            .filter_map(|_| {
                match protocol
                    .decode_diagnostic(&ecu.diagnostic_frame(now_us))
                    .unwrap()
                    .page
                {
                    DiagnosticPage::Record { record, .. } => Some(record),
                    p => {
                        assert!(matches!(p, DiagnosticPage::Counters { .. }), "{p:?}");
                        None
                    }
                }
            })
            .collect()
    };
    let records = round(&mut ecu, 65 * S);
    assert_eq!(records.len(), FAULT_LOG_CAPACITY);
    let held: Vec<_> = records.iter().flatten().collect();
    let bits: Vec<u8> = held.iter().map(|r| r.fault_bit).collect();
    assert_eq!(
        bits,
        [
            Fault::BusOff,
            Fault::EposFault,
            Fault::HeartbeatLost,
            Fault::Encoder,
            Fault::InvalidFrames
        ]
        .map(Fault::bit)
    );
    let ages: Vec<u16> = held.iter().map(|r| r.age_s).collect();
    assert_eq!(ages, [64, 63, 62, 61, 60]);
    assert!(held.iter().all(|r| !r.acknowledged));
    // Acknowledged by an accepted clear (AS Off, every cause gone), still on the bus.
    let mut vehicle = Vehicle::new();
    let _ = ecu.machine_mut().on_epos_fault_gone(66 * S);
    let _ = ecu.machine_mut().on_heartbeat(66 * S);
    let _ = ecu.on_encoder(66 * S, SteeringDeg(0.0));
    let _ = vehicle.send(&mut ecu, 66 * S, AsState::Off, 0.0);
    let clear = vehicle.frame(AsState::Off, 0.0, true);
    let out = ecu.on_reference_frame(66 * S + 10_000, &clear);
    assert!(out.faults.is_empty(), "cleared: {:?}", out.faults);
    let _ = ecu.on_bus_off(67 * S, 100);
    let records = round(&mut ecu, 70 * S);
    let held: Vec<_> = records.iter().flatten().collect();
    assert_eq!(held.len(), 6);
    assert!(held[..5].iter().all(|r| r.acknowledged));
    assert!(!held[5].acknowledged && held[5].age_s == 3);
}

/// The origin checks on their own (direct drive, Hall counts, origin at count 0): the
/// window's median and its agreement bound at an enable, and the running check's rest, its
/// mean effort, its time and its bound.
mod origin_checks {
    use super::*;
    use crate::faults::Fault;

    /// One column-encoder count is two Hall counts through the paper's gears: the candidates
    /// may stray from their median by that plus one (the Hall count's own quantisation).
    const BOUND: i32 = 3;

    /// An ECU with these origin candidates, 2 ms apart, judged 2 ms after the last (all in
    /// the 16 ms window).
    fn judged(origins: &[i32]) -> (Option<i32>, bool) {
        let mut ecu = Ecu::paper().unwrap();
        for (k, &o) in (0u64..).zip(origins) {
            let _ = ecu.origin_candidates.push_back((k * 2 * MS, o));
        }
        let refused = ecu
            .origin_from_window(origins.len() as u64 * 2 * MS)
            .is_err();
        (ecu.motor_origin_counts(), refused)
    }

    #[test]
    fn the_origin_is_the_median_of_the_window() {
        assert_eq!(judged(&[5, 6, 5, 6, 6, 5, 6, 6]), (Some(6), false));
        assert_eq!(judged(&[9, 8, 8]), (Some(8), false));
    }

    /// A candidate exactly the bound from the median, on either side, agrees; one more
    /// count refuses the enable.
    #[test]
    fn candidates_within_the_bound_of_the_median_agree_on_either_side() {
        assert_eq!(judged(&[10 - BOUND, 10, 10, 10]), (Some(10), false));
        assert_eq!(judged(&[10 - BOUND - 1, 10, 10, 10]), (None, true));
        assert_eq!(judged(&[10, 10, 10 + BOUND]), (Some(10), false));
        assert_eq!(judged(&[10, 10, 10 + BOUND + 1]), (None, true));
    }

    /// Whether the running check latched `Origin` with the motor at `hall` (wheel deg 0 at
    /// count 0) and the column at `column` deg.
    fn rest(ecu: &mut Ecu, t: u64, column: f32, hall: i32, effort: f32) -> bool {
        ecu.hall_count = hall;
        ecu.check_origin_at_rest(t, SteeringDeg(column), Amps(effort))
            .is_some_and(|o| o.faults.contains(Fault::Origin))
    }

    fn at_origin_0() -> Ecu {
        let mut ecu = Ecu::paper().unwrap();
        ecu.set_origin(Some(0));
        ecu
    }

    /// The first sample at which the check latches, samples every 2 ms up to 300 ms.
    fn latched_at(
        column: impl Fn(u64) -> f32,
        hall: impl Fn(u64) -> i32,
        effort: f32,
    ) -> Option<u64> {
        let mut ecu = at_origin_0();
        (0..=150u64)
            .map(|k| k * 2 * MS)
            .find(|&t| rest(&mut ecu, t, column(t), hall(t), effort))
    }

    /// At rest with 1.9 A (within the 2 A mean) and the column 2.6 deg from the motor, the
    /// fault latches 100 ms after the rest began, not before; 2.5 deg apart is within.
    #[test]
    fn a_rest_latches_after_100_ms_only_beyond_2_5_deg() {
        assert_eq!(latched_at(|_| 2.6, |_| 0, 1.9), Some(100 * MS));
        assert_eq!(latched_at(|_| -2.6, |_| 0, -1.9), Some(100 * MS));
        assert_eq!(latched_at(|_| 2.5, |_| 0, 1.9), None);
        assert_eq!(latched_at(|_| 2.6, |_| 0, 2.1), None, "not quiet");
    }

    /// A rest needs both angles still: a motor dithering 0.3 deg (6 Hall counts) under a
    /// still column, or the reverse, is no rest.
    #[test]
    fn a_rest_needs_both_the_column_and_the_motor_still() {
        let dither = |t: u64| (t / (2 * MS)) % 2 == 1;
        let hall = |t: u64| if dither(t) { 6 } else { 0 };
        assert_eq!(latched_at(|_| 4.0, hall, 0.0), None);
        let column = |t: u64| if dither(t) { 4.3 } else { 4.0 };
        assert_eq!(latched_at(column, |_| 0, 0.0), None);
        assert_eq!(
            latched_at(|_| 4.0, |_| 6, 0.0),
            Some(100 * MS),
            "the motor still"
        );
    }

    /// The mean effort is over every sample of the rest, the one that began it included: a
    /// 100 A sample that began the rest and 50 of -1.9 A after it average 0.1 A.
    #[test]
    fn the_rests_mean_effort_counts_the_sample_that_began_it() {
        let mut ecu = at_origin_0();
        assert!(!rest(&mut ecu, 0, 4.0, 0, 0.0));
        // The column moved 0.5 deg: the rest begins again here.
        assert!(!rest(&mut ecu, 2 * MS, 4.5, 0, 100.0));
        let latched = (2..=51u64)
            .map(|k| k * 2 * MS)
            .find(|&t| rest(&mut ecu, t, 4.5, 0, -1.9));
        assert_eq!(latched, Some(102 * MS));
    }
}

/// In EPOS4 mode the rate limit spans the last SYNC interval, but at most one reference
/// period: 400 deg/s over 10 ms after a 30 ms gap between SYNCs.
#[test]
fn the_epos4_rate_limit_spans_at_most_one_reference_period() {
    let link = Epos4Config::paper(crate::canopen::NodeId::new(1).unwrap());
    let build = EcuBuild::new(ControllerKind::Paper, DriveChoice::Epos4(link));
    let mut ecu = Ecu::build(build, 0).unwrap();
    let d = ecu.drive.epos4_mut().unwrap();
    d.synced(0, Some(SteeringDeg(1.0)));
    d.synced(30 * MS, Some(SteeringDeg(1.0)));
    for (target, limited) in [(20.0, 5.0), (-20.0, -3.0), (3.0, 3.0)] {
        let got = ecu.rate_limited(SteeringDeg(target)).0;
        assert!((got - limited).abs() < 1e-4, "{target} deg -> {got} deg");
    }
}

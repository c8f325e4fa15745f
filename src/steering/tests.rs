//! The state machine driven as the ECU drives it: events and ticks at the firmware's rates,
//! each module one behaviour of the module documentation.
use super::*;

mod random_events;

const MS: u64 = 1000;

/// The motor angle that reads as `deg` at the column through the paper's gears.
fn motor_at(deg: f32) -> MotorRad {
    Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into())
}

/// A machine in AS Driving, tracking at `t = 10 ms`, column and motor agreeing at 0 deg.
fn tracking() -> (SteeringStateMachine, u64) {
    let mut sm = SteeringStateMachine::default();
    let _ = sm.on_encoder(0, SteeringDeg(0.0), motor_at(0.0));
    let _ = sm.on_reference(0, AsState::Ready);
    let _ = sm.on_encoder(10 * MS, SteeringDeg(0.0), motor_at(0.0));
    let out = sm.on_reference(10 * MS, AsState::Driving);
    assert_eq!(out.demand, DriveDemand::Track);
    assert_eq!(out.state, EcuState::Tracking);
    (sm, 10 * MS)
}

/// A machine tracking in AS Driving at `t = 10 ms`, column and motor at `deg`.
fn tracking_at(deg: f32) -> (SteeringStateMachine, u64) {
    let mut sm = SteeringStateMachine::default();
    let _ = sm.on_encoder(0, SteeringDeg(deg), motor_at(deg));
    let _ = sm.on_reference(0, AsState::Driving);
    let _ = sm.on_encoder(10 * MS, SteeringDeg(deg), motor_at(deg));
    let out = sm.on_reference(10 * MS, AsState::Driving);
    assert_eq!(out.demand, DriveDemand::Track);
    (sm, 10 * MS)
}

/// Feeds encoder samples at 2 kHz (agreeing, at 0 deg) and ticks from `from` to `to`.
fn run_encoder(sm: &mut SteeringStateMachine, from: u64, to: u64) -> Output {
    let mut t = from;
    let mut out = sm.tick(from);
    while t < to {
        t = (t + 500).min(to);
        let _ = sm.on_encoder(t, SteeringDeg(0.0), motor_at(0.0));
        out = sm.tick(t);
    }
    out
}

/// In AS Off, with fresh frames, no cause left: clear the faults.
fn clear_in_off(sm: &mut SteeringStateMachine, t: u64) -> Result<(), ClearRefused> {
    let _ = sm.on_reference(t, AsState::Off);
    sm.request_clear_faults(t)
}

/// The column as a 12-bit absolute encoder reports it (AMT20: 4096 counts a turn).
fn quantised(deg: f32) -> f32 {
    let count = 360.0 / 4096.0;
    (deg / count).round() * count
}

/// Drives the runaway check as the ECU does (references at 100 Hz, encoder samples every
/// `sample_us`, each followed by the effort check) for 200 ms with the column at
/// `column(s)` (s since the start) and the effort `current(s)`; the time since the start
/// at which `TrackingError` latched.
fn runaway_latch(
    reference: f32,
    sample_us: u64,
    column: impl Fn(f32) -> f32,
    current: impl Fn(f32) -> f32,
) -> Option<u64> {
    let (mut sm, t0) = tracking_at(column(0.0));
    let mut t = t0;
    while t < t0 + 200 * MS {
        t += sample_us;
        let s = (t - t0) as f32 * 1e-6;
        let c = column(s);
        if (t - t0).is_multiple_of(10 * MS) {
            let _ = sm.on_reference(t, AsState::Driving);
        }
        let _ = sm.on_encoder(t, SteeringDeg(c), motor_at(c));
        let out = sm.on_drive_effort(t, SteeringDeg(reference), SteeringDeg(c), Amps(current(s)));
        if out.faults.contains(Fault::TrackingError) {
            return Some(t - t0);
        }
    }
    None
}

/// Which AS states power the drive, and AS Emergency's latch.
mod as_state_and_power {
    use super::*;

    #[test]
    fn only_ready_and_driving_power_the_drive() {
        for s in [
            AsState::Manual,
            AsState::Off,
            AsState::Ready,
            AsState::Driving,
            AsState::Emergency,
            AsState::Finished,
        ] {
            let mut sm = SteeringStateMachine::default();
            let _ = sm.on_encoder(0, SteeringDeg(0.0), motor_at(0.0));
            let out = sm.on_reference(MS, s);
            if s.actuator_may_be_powered() {
                assert_eq!(out.demand, DriveDemand::Track, "{s:?}");
                assert!(out.drive_just_enabled);
            } else {
                assert_eq!(out.demand, DriveDemand::Disabled, "{s:?}");
                let expected = if s == AsState::Emergency {
                    EcuState::Emergency
                } else {
                    EcuState::Idle
                };
                assert_eq!(out.state, expected, "{s:?}");
            }
            assert!(out.faults.is_empty());
        }
        // Driving, then Finished: disabled in the same call, no fault.
        let (mut sm, t) = tracking();
        let out = sm.on_reference(t + 5 * MS, AsState::Finished);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Idle);
        assert!(out.faults.is_empty());
    }

    #[test]
    fn nothing_powers_the_drive_before_the_first_frame() {
        let mut sm = SteeringStateMachine::default();
        let out = run_encoder(&mut sm, 0, 500 * MS);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Idle);
        assert!(
            out.faults.is_empty(),
            "no reference expected outside AS Ready/Driving"
        );
    }

    #[test]
    fn emergency_disables_at_once() {
        let (mut sm, t) = tracking();
        let out = sm.on_reference(t + 1, AsState::Emergency);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Emergency);

        // From an AS-state frame without a reference, and from Hold.
        let (mut sm, t) = tracking();
        let out = run_encoder(&mut sm, t, t + 50 * MS);
        assert_eq!(out.demand, DriveDemand::Hold);
        let out = sm.on_as_state(t + 50 * MS + 1, AsState::Emergency);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Emergency);
        // Emergency is the AS's verdict, not an ECU fault.
        assert!(out.faults.is_empty());
    }

    /// AS Emergency latches until AS Off, as the driverless rules' AS state machine says
    /// (Emergency is left only when the ASMS is switched off): Emergency followed by Ready,
    /// Driving, Finished or Manual stays Emergency, drive off, however long the frames come;
    /// Off releases it, and from Off the usual Ready -> Driving powers the drive again.
    #[test]
    fn emergency_latches_until_as_off() {
        for next in [
            AsState::Driving,
            AsState::Ready,
            AsState::Finished,
            AsState::Manual,
        ] {
            let (mut sm, t) = tracking();
            let out = sm.on_reference(t + 10 * MS, AsState::Emergency);
            assert_eq!(out.state, EcuState::Emergency);
            let mut t = t + 10 * MS;
            for _ in 0..20 {
                t += 10 * MS;
                let _ = sm.on_encoder(t, SteeringDeg(0.0), motor_at(0.0));
                let out = sm.on_reference(t, next);
                assert_eq!(out.demand, DriveDemand::Disabled, "Emergency -> {next:?}");
                assert_eq!(out.state, EcuState::Emergency, "Emergency -> {next:?}");
                assert!(out.faults.is_empty(), "{:?}", out.faults);
                let out = sm.on_as_state(t + MS, next);
                assert_eq!(out.state, EcuState::Emergency, "AS-only {next:?}");
            }
            assert_eq!(sm.as_state(), Some(AsState::Emergency), "{next:?}");
            // AS Off releases the latch.
            t += 10 * MS;
            let out = sm.on_reference(t, AsState::Off);
            assert_eq!(out.state, EcuState::Idle, "{next:?}");
            for s in [AsState::Ready, AsState::Driving] {
                t += 10 * MS;
                let _ = sm.on_encoder(t, SteeringDeg(0.0), motor_at(0.0));
                let out = sm.on_reference(t, s);
                assert_eq!(out.demand, DriveDemand::Track, "{s:?} after Off");
            }
        }
    }

    #[test]
    fn the_driving_only_rule_keeps_the_drive_off_in_as_ready() {
        let config = Config::DEFAULT.with_actuation(Actuation::DrivingOnly);
        let mut sm = SteeringStateMachine::new(config);
        let _ = sm.on_encoder(0, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_reference(MS, AsState::Ready);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Idle);
        // No reference timeout counts in AS Ready either: nothing is powered.
        let out = run_encoder(&mut sm, MS, 500 * MS);
        assert!(out.faults.is_empty(), "{:?}", out.faults);
        let _ = sm.on_encoder(500 * MS, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_reference(500 * MS, AsState::Driving);
        assert_eq!(out.demand, DriveDemand::Track);
        // The FS default powers the drive in AS Ready.
        assert_eq!(Config::DEFAULT.actuation(), Actuation::ReadyOrDriving);
    }
}

/// Track, Hold, then Disabled with `ReferenceTimeout` as the reference goes stale.
mod reference_timeout {
    use super::*;

    #[test]
    fn stale_reference_holds_then_disables_and_latches() {
        let (mut sm, t0) = tracking();
        // 0..30 ms after the last valid frame: still tracking.
        let out = run_encoder(&mut sm, t0, t0 + 30 * MS);
        assert_eq!(out.demand, DriveDemand::Track);
        // Just past 30 ms: hold.
        let out = run_encoder(&mut sm, t0 + 30 * MS, t0 + 30 * MS + 500);
        assert_eq!(out.demand, DriveDemand::Hold);
        assert_eq!(out.state, EcuState::Holding);
        assert!(!out.drive_just_enabled, "the drive was on already");
        // Up to 130 ms: still hold, no fault yet.
        let out = run_encoder(&mut sm, t0 + 30 * MS + 500, t0 + 130 * MS);
        assert_eq!(out.demand, DriveDemand::Hold);
        assert!(out.faults.is_empty());
        // Past 130 ms: disabled, latched, recorded with the age.
        let out = run_encoder(&mut sm, t0 + 130 * MS, t0 + 130 * MS + 500);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Faulted);
        assert!(out.faults.contains(Fault::ReferenceTimeout));
        let record = sm.fault_log().iter().last().copied();
        assert_eq!(record.map(|r| r.fault), Some(Fault::ReferenceTimeout));
        assert_eq!(record.map(|r| r.detail), Some(130));
        // A frame coming back does not re-enable the drive.
        let out = sm.on_reference(t0 + 140 * MS, AsState::Driving);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(sm.hold_entries(), 1);
    }

    #[test]
    fn a_short_reference_gap_is_ridden_through_in_hold() {
        let (mut sm, t0) = tracking();
        let out = run_encoder(&mut sm, t0, t0 + 80 * MS);
        assert_eq!(out.demand, DriveDemand::Hold);
        let out = sm.on_reference(t0 + 80 * MS, AsState::Driving);
        assert_eq!(out.demand, DriveDemand::Track);
        assert!(out.faults.is_empty());
        assert!(!out.drive_just_enabled, "hold kept the loop running");
        assert_eq!(sm.hold_entries(), 1);
    }

    #[test]
    fn a_late_call_latches_the_timeout_before_the_frame_counts() {
        let (mut sm, t0) = tracking();
        // Nobody ticked for 200 ms; the next frame cannot undo the timeout that happened.
        let _ = sm.on_encoder(t0 + 200 * MS, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_reference(t0 + 200 * MS, AsState::Driving);
        assert!(out.faults.contains(Fault::ReferenceTimeout));
        assert_eq!(out.demand, DriveDemand::Disabled);
    }

    /// The hold never outlasts 130 ms after the last valid reference, even when the AS state
    /// allowed power later than that reference (here from an AS-state-only frame 10 ms
    /// after it): at 135 ms the drive is off (Standby, the timeout not latched yet).
    #[test]
    fn the_hold_ends_130_ms_after_the_last_reference() {
        let mut sm = SteeringStateMachine::default();
        let _ = sm.on_encoder(0, SteeringDeg(0.0), motor_at(0.0));
        let _ = sm.on_reference(0, AsState::Off);
        let _ = sm.on_encoder(10 * MS, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_as_state(10 * MS, AsState::Driving);
        assert_eq!(out.demand, DriveDemand::Track);
        let mut demands = Vec::new();
        for t in (12 * MS..=135 * MS).step_by(1_000) {
            let _ = sm.on_encoder(t, SteeringDeg(0.0), motor_at(0.0));
            demands.push((t / MS, sm.tick(t).demand));
        }
        assert!(demands.contains(&(130, DriveDemand::Hold)), "{demands:?}");
        assert_eq!(demands.last(), Some(&(135, DriveDemand::Disabled)));
    }

    #[test]
    fn time_going_back_neither_panics_nor_refreshes() {
        let (mut sm, t) = tracking();
        let _ = run_encoder(&mut sm, t, t + 50 * MS);
        // An event stamped earlier is taken as happening now; it cannot move time back.
        let out = sm.on_reference(0, AsState::Driving);
        assert_eq!(out.demand, DriveDemand::Track, "the frame did arrive");
        let out = run_encoder(&mut sm, t + 50 * MS, t + 81 * MS);
        assert_eq!(out.demand, DriveDemand::Hold);
        let _ = sm.tick(u64::MAX);
        let _ = sm.on_reference(u64::MAX, AsState::Driving);
        let _ = sm.tick(0);
    }
}

/// A latch goes only on request, in AS Off, with every cause gone.
mod clearing_faults {
    use super::*;

    #[test]
    fn faults_clear_only_on_request_in_as_off() {
        let (mut sm, t) = tracking();
        let out = sm.on_heartbeat_lost(t + MS);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Faulted);
        let _ = sm.on_heartbeat(t + 2 * MS);
        // Cause gone and AS Off, but nobody asked: still latched, still disabled.
        let _ = sm.on_reference(t + 3 * MS, AsState::Off);
        let out = run_encoder(&mut sm, t + 3 * MS, t + 10 * MS);
        assert!(out.faults.contains(Fault::HeartbeatLost));
        assert_eq!(out.state, EcuState::Faulted);
        // The request in AS Off clears.
        assert_eq!(clear_in_off(&mut sm, t + 10 * MS), Ok(()));
        let out = sm.tick(t + 10 * MS);
        assert!(out.faults.is_empty());
        assert_eq!(out.state, EcuState::Idle);
        // The record stays in the log.
        assert_eq!(sm.fault_log().len(), 1);
        // And the car can steer again.
        let _ = sm.on_encoder(t + 20 * MS, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_reference(t + 20 * MS, AsState::Ready);
        assert_eq!(out.demand, DriveDemand::Track);
        assert!(out.drive_just_enabled);
    }

    #[test]
    fn clear_refused_while_driving() {
        let (mut sm, t) = tracking();
        let _ = sm.on_bus_off(t + MS, 255);
        let _ = sm.on_bus_recovered(t + 2 * MS);
        let _ = sm.on_encoder(t + 3 * MS, SteeringDeg(0.0), motor_at(0.0));
        let _ = sm.on_reference(t + 3 * MS, AsState::Driving);
        assert_eq!(
            sm.request_clear_faults(t + 3 * MS),
            Err(ClearRefused::NotInAsOff {
                as_state: Some(AsState::Driving),
                stale: false
            })
        );
        for s in [
            AsState::Ready,
            AsState::Manual,
            AsState::Finished,
            AsState::Emergency,
        ] {
            let _ = sm.on_reference(t + 4 * MS, s);
            assert!(
                matches!(
                    sm.request_clear_faults(t + 4 * MS),
                    Err(ClearRefused::NotInAsOff { .. })
                ),
                "{s:?}"
            );
        }
        assert!(sm.faults().contains(Fault::BusOff));
        // AS Off, but known only from a frame that is too old.
        let _ = sm.on_reference(t + 5 * MS, AsState::Off);
        assert_eq!(
            sm.request_clear_faults(t + 100 * MS),
            Err(ClearRefused::NotInAsOff {
                as_state: Some(AsState::Off),
                stale: true
            })
        );
    }

    #[test]
    fn clear_refused_while_the_cause_is_present() {
        let (mut sm, t) = tracking();
        let _ = sm.on_epos_fault(t + MS, 0x3210);
        let _ = sm.on_heartbeat_lost(t + MS);
        assert_eq!(
            clear_in_off(&mut sm, t + 2 * MS),
            Err(ClearRefused::CauseActive {
                faults: FaultSet::from(Fault::EposFault).union(Fault::HeartbeatLost.into())
            })
        );
        let _ = sm.on_epos_fault_gone(t + 3 * MS);
        let _ = sm.on_heartbeat(t + 3 * MS);
        assert_eq!(clear_in_off(&mut sm, t + 3 * MS), Ok(()));
        assert!(sm.faults().is_empty());
    }

    #[test]
    fn a_clear_request_never_resets_a_detector() {
        // AS Off, the vehicle asks to clear every 10 ms (the reference period) while the column
        // and the motor disagree by 20 deg and the current reads 30 A: both must latch.
        let mut sm = SteeringStateMachine::default();
        let mut t = 0;
        for _ in 0..400 {
            let _ = sm.on_reference(t, AsState::Off);
            for j in 0..5 {
                let _ = sm.on_encoder(t + j * 2 * MS, SteeringDeg(20.0), motor_at(0.0));
            }
            let _ = sm.on_current(t, Amps(30.0));
            let _ = sm.request_clear_faults(t);
            t += 10 * MS;
        }
        let faults = sm.faults();
        assert!(
            faults.contains(Fault::EncoderMotorDisagreement),
            "{faults:?}"
        );
        assert!(faults.contains(Fault::OverCurrent), "{faults:?}");
    }

    /// Faults clear with an AS Off frame up to one reference timeout old, the timeout itself
    /// included; 1 µs later it is stale.
    #[test]
    fn a_clear_accepts_an_as_off_frame_exactly_one_timeout_old() {
        let (mut sm, t0) = tracking_at(0.0);
        let _ = sm.on_bus_off(t0 + MS, 255);
        let _ = sm.on_bus_recovered(t0 + 2 * MS);
        let _ = sm.on_reference(t0 + 3 * MS, AsState::Off);
        assert_eq!(
            sm.clone().request_clear_faults(t0 + 33 * MS + 1),
            Err(ClearRefused::NotInAsOff {
                as_state: Some(AsState::Off),
                stale: true
            })
        );
        assert_eq!(sm.request_clear_faults(t0 + 33 * MS), Ok(()));
    }
}

/// The column encoder's checks: errors, silence, jumps and the motor cross-check.
mod column_encoder {
    use super::*;
    use crate::gearing::{TAU_BS_M_PER_RAD, TAU_P_M_PER_RAD};

    #[test]
    fn encoder_faults_latch_and_a_good_sample_removes_the_cause() {
        let (mut sm, t) = tracking();
        let out = sm.on_encoder(t + 1, SteeringDeg(f32::NAN), motor_at(0.0));
        assert_eq!(out.faults, FaultSet::from(Fault::Encoder));
        assert_eq!(
            sm.fault_log().get(0).map(|r| r.detail),
            Some(EncoderFaultDetail::ColumnNotFinite as i32)
        );
        let _ = sm.on_encoder_fault(t + 2, 7);
        assert!(matches!(
            clear_in_off(&mut sm, t + 3),
            Err(ClearRefused::CauseActive { .. })
        ));
        let _ = sm.on_encoder(t + 4, SteeringDeg(0.0), MotorRad(0.0));
        assert_eq!(clear_in_off(&mut sm, t + 4), Ok(()));

        let (mut sm, t) = tracking();
        let out = sm.on_encoder(t + 1, SteeringDeg(0.0), MotorRad(f32::INFINITY));
        assert_eq!(out.faults, FaultSet::from(Fault::Encoder));
    }

    /// A sensor-reported encoder error is recorded as `0x1_0000 + code`.
    #[test]
    fn a_reported_encoder_error_records_its_code_above_the_base() {
        let mut sm = SteeringStateMachine::default();
        let _ = sm.on_encoder_fault(MS, 7);
        assert_eq!(
            sm.fault_log().get(0).map(|r| (r.fault, r.detail)),
            Some((Fault::Encoder, 0x1_0007))
        );
    }

    #[test]
    fn encoder_silence_in_ready_latches_and_never_tracks() {
        let mut sm = SteeringStateMachine::default();
        // References in AS Ready but the encoder never speaks.
        let mut out = sm.on_reference(0, AsState::Ready);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(out.state, EcuState::Standby);
        for k in 1..=4 {
            out = sm.on_reference(k * 10 * MS, AsState::Ready);
            assert_ne!(out.demand, DriveDemand::Track);
        }
        assert!(out.faults.contains(Fault::Encoder));
        let detail = sm.fault_log().get(0).map(|r| r.detail);
        assert_eq!(detail, Some(EncoderFaultDetail::Stale as i32));
    }

    /// The encoder timeout's boundary: a sample exactly 30 ms old is still fresh (Track, no
    /// fault); 1 µs later the encoder is stale and latches.
    #[test]
    fn an_encoder_sample_exactly_one_timeout_old_is_still_fresh() {
        let (mut sm, t0) = tracking_at(0.0);
        let _ = sm.on_reference(t0 + 20 * MS, AsState::Driving);
        let out = sm.tick(t0 + 30 * MS);
        assert_eq!(out.demand, DriveDemand::Track);
        assert!(out.faults.is_empty(), "{:?}", out.faults);
        let out = sm.tick(t0 + 30 * MS + 1);
        assert_eq!(out.faults, FaultSet::from(Fault::Encoder));
        assert_eq!(
            sm.fault_log().get(0).map(|r| r.detail),
            Some(EncoderFaultDetail::Stale as i32)
        );
    }

    #[test]
    fn encoder_jump_latches() {
        let mut sm = SteeringStateMachine::default();
        // 300 deg/s at 2 kHz (0.15 deg a sample): plausible.
        let mut t = 0;
        let mut deg = 0.0f32;
        for _ in 0..200 {
            t += 500;
            deg += 0.15;
            let out = sm.on_encoder(t, SteeringDeg(deg), motor_at(deg));
            assert!(out.faults.is_empty(), "at {deg}");
        }
        // A flipped bit 6: 64 counts = 5.6 deg in 0.5 ms.
        t += 500;
        let jumped = deg + 5.625;
        let out = sm.on_encoder(t, SteeringDeg(jumped), motor_at(jumped));
        assert!(out.faults.contains(Fault::EncoderJump));
        let record = sm.fault_log().iter().last().copied();
        assert_eq!(record.map(|r| r.detail), Some(562));

        // The same step between 100 Hz samples is within 1 + 1000 x 0.01 = 11 deg.
        let mut sm = SteeringStateMachine::default();
        let _ = sm.on_encoder(0, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_encoder(10 * MS, SteeringDeg(10.0), motor_at(10.0));
        assert!(out.faults.is_empty());
        let out = sm.on_encoder(20 * MS, SteeringDeg(22.0), motor_at(22.0));
        assert!(out.faults.contains(Fault::EncoderJump));
    }

    /// The jump limit is `floor + rate x dt`, the limit itself allowed: a late sample (dt 0)
    /// may move by exactly the 1 deg floor, a 100 Hz sample by 10.5 deg (limit 11 deg).
    #[test]
    fn a_jump_up_to_the_floor_plus_the_rate_allowance_is_plausible() {
        let mut sm = SteeringStateMachine::default();
        let _ = sm.on_encoder(10 * MS, SteeringDeg(0.0), motor_at(0.0));
        let out = sm.on_encoder(10 * MS, SteeringDeg(1.0), motor_at(1.0));
        assert!(out.faults.is_empty(), "1 deg at dt 0: {:?}", out.faults);
        let out = sm.on_encoder(20 * MS, SteeringDeg(11.5), motor_at(11.5));
        assert!(out.faults.is_empty(), "10.5 deg in 10 ms: {:?}", out.faults);
        let out = sm.on_encoder(20 * MS, SteeringDeg(12.6), motor_at(12.6));
        assert!(out.faults.contains(Fault::EncoderJump), "1.1 deg at dt 0");
    }

    #[test]
    fn encoder_motor_disagreement_latches() {
        let (mut sm, t0) = tracking();
        // 14 deg apart (belt deflection under 20 A plus dead band): normal.
        let mut t = t0;
        for _ in 0..100 {
            t += 500;
            let _ = sm.on_reference(t, AsState::Driving);
            let out = sm.on_encoder(t, SteeringDeg(0.0), motor_at(-14.0));
            assert!(out.faults.is_empty());
        }
        // A 10 ms excursion beyond 15 deg: not long enough.
        for _ in 0..20 {
            t += 500;
            let _ = sm.on_reference(t, AsState::Driving);
            let out = sm.on_encoder(t, SteeringDeg(0.0), motor_at(16.0));
            assert!(out.faults.is_empty());
        }
        let _ = sm.on_encoder(t + 500, SteeringDeg(0.0), motor_at(0.0));
        t += 500;
        // A broken belt: the motor runs away from the column.
        let start = t;
        let out = loop {
            t += 500;
            let _ = sm.on_reference(t, AsState::Driving);
            let out = sm.on_encoder(t, SteeringDeg(0.0), motor_at(-20.0));
            if !out.faults.is_empty() || t > start + 100 * MS {
                break out;
            }
        };
        assert!(out.faults.contains(Fault::EncoderMotorDisagreement));
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(
            t - start,
            20 * MS + 500,
            "20 ms after the first sample beyond"
        );
        let detail = sm.fault_log().iter().last().map(|r| r.detail);
        assert!(
            detail.is_some_and(|d| (1999..=2001).contains(&d)),
            "{detail:?}"
        );
    }

    #[test]
    fn disagreement_window_exceeds_belt_deflection_at_20_a() {
        // 20 A x kt (Table 1) x belt 2:1 = torque at the nut; kB = 0.29 Nm/rad (Table 4).
        let nut_torque_nm = 20.0 * 52.5e-3 * 2.0;
        let nut_deflection_rad = nut_torque_nm / 0.29;
        let at_wheel_deg = (nut_deflection_rad * TAU_BS_M_PER_RAD / TAU_P_M_PER_RAD).to_degrees();
        assert!((at_wheel_deg - 9.7).abs() < 0.1, "{at_wheel_deg}");
        assert!(DEFAULT_DISAGREEMENT_DEG > at_wheel_deg + 4.0);
    }
}

/// Over-current runs at 20 kHz and at the EPOS4's 10 ms samples.
mod over_current {
    use super::*;

    #[test]
    fn overcurrent_latches() {
        let (mut sm, t) = tracking();
        // 19 samples above 22 A, then one below: a spike, no fault.
        for k in 0..19 {
            let out = sm.on_current(t + k, Amps(-25.0));
            assert!(out.faults.is_empty());
        }
        let _ = sm.on_current(t + 19, Amps(19.9));
        // 20 in a row: latched, disabled in the same call.
        let mut out = sm.tick(t + 20);
        for k in 0..20 {
            out = sm.on_current(t + 20 + k, Amps(25.0));
        }
        assert!(out.faults.contains(Fault::OverCurrent));
        assert_eq!(out.demand, DriveDemand::Disabled);
        let record = sm.fault_log().iter().last().copied();
        assert_eq!(record.map(|r| r.detail), Some(25_000));

        // A current nobody can read counts as above.
        let mut sm = SteeringStateMachine::default();
        let mut out = sm.tick(0);
        for k in 0..20 {
            out = sm.on_current(k, Amps(f32::NAN));
        }
        assert!(out.faults.contains(Fault::OverCurrent));
        assert_eq!(sm.fault_log().get(0).map(|r| r.detail), Some(i32::MIN));
    }

    #[test]
    fn an_over_current_sampled_every_10_ms_latches_within_20_ms() {
        // EPOS4 mode: the drive's current comes with each SYNC (TPDO2, every 10 ms).
        let (mut sm, t0) = tracking();
        let mut latched_at = None;
        for k in 1..=30u64 {
            let t = t0 + k * 10 * MS;
            let _ = sm.on_reference(t, AsState::Driving);
            let _ = sm.on_encoder(t, SteeringDeg(0.0), motor_at(0.0));
            let out = sm.on_current(t, Amps(30.0));
            if latched_at.is_none() && out.faults.contains(Fault::OverCurrent) {
                latched_at = Some(k * 10 * MS);
            }
        }
        let at = latched_at.expect("latched");
        // The first sample above is at 10 ms: latched by the third at the latest.
        assert!(at <= 30 * MS, "latched {at} us after the first sample");
    }

    /// `overcurrent_pending` says whether a run of over-current samples is open: the ECU's
    /// 20 kHz fast path skips the machine only while it is false.
    #[test]
    fn an_over_current_run_is_pending_until_a_sample_within() {
        let mut sm = SteeringStateMachine::default();
        assert!(!sm.overcurrent_pending(), "fresh");
        let _ = sm.on_current(0, Amps(10.0));
        assert!(!sm.overcurrent_pending(), "within");
        let _ = sm.on_current(50, Amps(-25.0));
        assert!(sm.overcurrent_pending(), "one sample beyond");
        let _ = sm.on_current(100, Amps(21.9));
        assert!(!sm.overcurrent_pending(), "a sample within ends the run");
    }
}

/// A column that does not close the gap to its reference.
mod tracking_error {
    use super::*;

    #[test]
    fn tracking_error_latches_when_the_column_stands_still_or_runs_away() {
        for (name, column_dps) in [("jammed", 0.0f32), ("running away", -50.0)] {
            let (mut sm, t0) = tracking();
            let mut t = t0;
            let mut out = sm.tick(t);
            let mut latched_at = None;
            while t < t0 + 500 * MS {
                t += 2 * MS;
                let column = column_dps * (t - t0) as f32 * 1e-6;
                if (t - t0).is_multiple_of(10 * MS) {
                    let _ = sm.on_reference(t, AsState::Driving);
                }
                let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
                out = sm.on_tracking(t, SteeringDeg(30.0), SteeringDeg(column));
                if latched_at.is_none() && out.faults.contains(Fault::TrackingError) {
                    latched_at = Some(t - t0);
                }
            }
            let at = latched_at.unwrap_or_else(|| panic!("{name}: never latched"));
            assert!((200 * MS..=210 * MS).contains(&at), "{name}: at {at} us");
            assert_eq!(out.demand, DriveDemand::Disabled, "{name}");
        }
    }

    #[test]
    fn a_gap_the_actuator_is_closing_is_no_tracking_error() {
        // The reference ramps at the protocol's 400 deg/s to 90 deg, the column follows at the
        // motor's 306 deg/s: the error grows to 21 deg and beyond, but the column makes progress.
        let (mut sm, t0) = tracking();
        let mut t = t0;
        while t < t0 + 600 * MS {
            t += 2 * MS;
            let s = (t - t0) as f32 * 1e-6;
            let reference = (400.0 * s).min(90.0);
            let column = (306.0 * s).min(90.0);
            if (t - t0).is_multiple_of(10 * MS) {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
            let out = sm.on_tracking(t, SteeringDeg(reference), SteeringDeg(column));
            assert!(
                out.faults.is_empty(),
                "at {} ms: {:?}",
                (t - t0) / MS,
                out.faults
            );
        }
        // And the drive being switched off clears the cause.
        let _ = sm.on_tracking(t, SteeringDeg(90.0), SteeringDeg(0.0));
        let _ = sm.on_not_tracking(t + MS);
        assert!(sm.active.is_empty());
    }

    /// A gap the column closes from above (negative error) at 35 deg/s, a little more than
    /// the 30 deg/s of progress the check asks for, is no tracking error: the progress is
    /// the motion toward the reference whichever side it is on, measured from where the
    /// interval began.
    #[test]
    fn a_gap_closed_from_above_just_faster_than_the_progress_rule_is_no_fault() {
        let (mut sm, t0) = tracking_at(40.0);
        let mut t = t0;
        // Reference 10 deg: 30 deg below; the column comes down to 30 deg (within the 20 deg
        // window) after 286 ms, so at least one full 200 ms interval is judged.
        while t < t0 + 280 * MS {
            t += 2 * MS;
            let column = 40.0 - 35.0 * (t - t0) as f32 * 1e-6;
            if (t - t0).is_multiple_of(10 * MS) {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
            let out = sm.on_tracking(t, SteeringDeg(10.0), SteeringDeg(column));
            assert!(
                out.faults.is_empty(),
                "at {} ms: {:?}",
                (t - t0) / MS,
                out.faults
            );
        }
        // ... and the same column standing still 30 deg above the reference latches.
        let (mut sm, t0) = tracking_at(40.0);
        let mut latched = false;
        for k in 1..=110u64 {
            let t = t0 + k * 2 * MS;
            if k % 5 == 0 {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(40.0), motor_at(40.0));
            latched |= sm
                .on_tracking(t, SteeringDeg(10.0), SteeringDeg(40.0))
                .faults
                .contains(Fault::TrackingError);
        }
        assert!(latched, "a jammed column above the reference");
    }
}

/// A saturated push toward the reference while the column runs away from it.
mod runaway {
    use super::*;

    #[test]
    fn a_runaway_under_a_saturated_push_latches_in_50_ms_and_a_coast_does_not() {
        // Runaway: 20 A toward +10 deg while the column runs away at 100 deg/s.
        let (mut sm, t0) = tracking();
        let mut latched_at = None;
        let mut t = t0;
        while t < t0 + 200 * MS && latched_at.is_none() {
            t += 2 * MS;
            let column = -100.0 * (t - t0) as f32 * 1e-6;
            if (t - t0).is_multiple_of(10 * MS) {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
            let out = sm.on_drive_effort(t, SteeringDeg(10.0), SteeringDeg(column), Amps(20.0));
            if out.faults.contains(Fault::TrackingError) {
                latched_at = Some(t - t0);
            }
        }
        let at = latched_at.expect("the runaway latched");
        assert!((50 * MS..=52 * MS).contains(&at), "at {at} us");

        // A coast: the reference reversed, the column keeps going away for 40 ms while the
        // loop brakes at 20 A, then comes back.
        let (mut sm, t0) = tracking();
        let mut t = t0;
        while t < t0 + 200 * MS {
            t += 2 * MS;
            let s = (t - t0) as f32 * 1e-6;
            // 300 deg/s decelerating to 0 at 40 ms, then back at the same rate.
            let column = 300.0 * s - 3750.0 * s * s;
            if (t - t0).is_multiple_of(10 * MS) {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
            let out = sm.on_drive_effort(t, SteeringDeg(-5.0), SteeringDeg(column), Amps(-20.0));
            assert!(out.faults.is_empty(), "at {} ms", (t - t0) / MS);
        }
    }

    #[test]
    fn a_saturated_loop_lagging_a_10_hz_reference_is_no_runaway() {
        // The paper's sweep ends at 10 Hz, where a saturated loop lags by most of a half
        // period: the current flips with the error every 50 ms and the column, behind the soft
        // belt, is still moving away when each push begins. Reference 9 deg, column 3 deg
        // lagging 150 deg, current at the limit toward the reference.
        let (mut sm, t0) = tracking();
        let w = std::f32::consts::TAU * 10.0;
        let mut t = t0;
        while t < t0 + 2000 * MS {
            t += 2 * MS;
            let s = (t - t0) as f32 * 1e-6;
            let reference = 9.0 * (w * s).sin();
            let column = 3.0 * (w * s - 2.6).sin();
            if (t - t0).is_multiple_of(10 * MS) {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            let _ = sm.on_encoder(t, SteeringDeg(column), motor_at(column));
            let push = Amps(20.0 * (reference - column).signum());
            let out = sm.on_drive_effort(t, SteeringDeg(reference), SteeringDeg(column), push);
            assert!(out.faults.is_empty(), "latched at {} ms", (t - t0) / MS);
        }
    }

    /// The runaway rule is symmetric and its current threshold is 18 A toward the
    /// reference: 18.5 A pushing down while the column runs up latches in 50 ms, 17.5 A
    /// pushing up while the column runs down does not; a column running away from a
    /// reference at the centre latches too.
    #[test]
    fn a_runaway_needs_18_a_toward_the_reference_in_either_direction() {
        let at = runaway_latch(-10.0, 2 * MS, |s| 100.0 * s, |_| -18.5);
        assert!(
            at.is_some_and(|at| (50 * MS..=52 * MS).contains(&at)),
            "downward push: {at:?}"
        );
        let at = runaway_latch(10.0, 2 * MS, |s| -100.0 * s, |_| 17.5);
        assert_eq!(at, None, "17.5 A is below the saturated push");
        // Away from a centred reference: the error is the reference less the column.
        let at = runaway_latch(0.0, 2 * MS, |s| 100.0 * s, |_| -20.0);
        assert!(
            at.is_some_and(|at| (50 * MS..=52 * MS).contains(&at)),
            "from the centre: {at:?}"
        );
    }

    /// A push that stops for one sample and resumes is a new push: the runaway latches 50 ms
    /// after it resumed, not never.
    #[test]
    fn a_runaway_latches_50_ms_after_an_interrupted_push_resumes() {
        // 20 A toward +10 deg, except 10 A at 30 ms; the column runs away at 100 deg/s.
        let current = |s: f32| {
            if (0.029..0.031).contains(&s) {
                10.0
            } else {
                20.0
            }
        };
        let at = runaway_latch(10.0, 2 * MS, |s| -100.0 * s, current);
        assert!(
            at.is_some_and(|at| (80 * MS..=82 * MS).contains(&at)),
            "{at:?}"
        );
    }

    /// The speed away is measured over 10 ms, not sample to sample: through a 12-bit encoder
    /// sampled at 2 kHz, a column creeping away at 5 deg/s (below the 20 deg/s of a runaway)
    /// shows as 0 or 176 deg/s between samples, and that must not latch; a real runaway at
    /// 40 deg/s seen the same way does.
    #[test]
    fn a_creep_seen_through_the_encoders_counts_is_no_runaway() {
        let creep = runaway_latch(10.0, 500, |s| quantised(-5.0 * s), |_| 20.0);
        assert_eq!(creep, None, "5 deg/s away latched at {creep:?} us");
        let runaway = runaway_latch(10.0, 500, |s| quantised(-40.0 * s), |_| 20.0);
        assert!(
            runaway.is_some_and(|at| (50 * MS..=55 * MS).contains(&at)),
            "{runaway:?}"
        );
    }

    /// "Not slowing" is judged against the speed away when the push began, less one count
    /// per window of slack: a column already running away at 100 deg/s when the push begins
    /// and keeping that speed latches 50 ms later; one the push slows to 50 deg/s (still away,
    /// but braked) does not.
    #[test]
    fn a_runaway_is_judged_against_its_speed_when_the_push_began() {
        let current = |s: f32| if s < 0.03 { 10.0 } else { 20.0 };
        let at = runaway_latch(10.0, 2 * MS, |s| -100.0 * s, current);
        assert!(
            at.is_some_and(|at| (80 * MS..=82 * MS).contains(&at)),
            "kept its speed: {at:?}"
        );
        let braked = |s: f32| {
            if s < 0.03 {
                -100.0 * s
            } else {
                -3.0 - 50.0 * (s - 0.03)
            }
        };
        let at = runaway_latch(10.0, 2 * MS, braked, current);
        assert_eq!(at, None, "braked to half its speed away");
    }

    /// The not-slowing rule's slack is one encoder count per speed window: a runaway at
    /// 40 deg/s seen through the 12-bit encoder reads 4 or 5 counts per 10 ms (35 or
    /// 44 deg/s). Pushed from 60.5 ms, after a 5-count window, it latches 50 ms later even
    /// though the window then read one count less.
    #[test]
    fn a_runaway_one_encoder_count_slower_than_at_the_push_still_latches_in_50_ms() {
        let current = |s: f32| if s < 0.0603 { 10.0 } else { 20.0 };
        let at = runaway_latch(10.0, 500, |s| quantised(-40.0 * s), current);
        assert_eq!(at, Some(110_500), "push at 60.5 ms");
    }
}

/// Faults reported by the EPOS4, the CAN controller and the frame checks.
mod drive_and_bus_faults {
    use super::*;

    #[test]
    fn heartbeat_loss_latches() {
        let (mut sm, t) = tracking();
        let out = sm.on_heartbeat_lost(t + 1);
        assert_eq!(out.faults, FaultSet::from(Fault::HeartbeatLost));
        assert_eq!(out.demand, DriveDemand::Disabled);
    }

    #[test]
    fn bus_off_latches() {
        let (mut sm, t) = tracking();
        let out = sm.on_bus_off(t + 1, 255);
        assert_eq!(out.faults, FaultSet::from(Fault::BusOff));
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(sm.fault_log().get(0).map(|r| r.detail), Some(255));
        // A valid frame proves the bus is back: the cause is gone.
        assert_eq!(clear_in_off(&mut sm, t + 2), Ok(()));
    }

    #[test]
    fn epos_fault_latches_with_its_code() {
        let (mut sm, t) = tracking();
        let out = sm.on_epos_fault(t + 1, 0x8611);
        assert_eq!(out.faults, FaultSet::from(Fault::EposFault));
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert_eq!(sm.fault_log().get(0).map(|r| r.detail), Some(0x8611));
    }

    #[test]
    fn invalid_frames_latch_until_a_valid_frame_and_a_clear() {
        let (mut sm, t) = tracking();
        let out = sm.on_invalid_frames_fault(t + 1, 5);
        assert_eq!(out.faults, FaultSet::from(Fault::InvalidFrames));
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert!(sm.request_clear_faults(t + 2).is_err(), "not in AS Off");
        assert_eq!(clear_in_off(&mut sm, t + 3), Ok(()));
    }
}

/// The two ways `Origin` latches, and the detail each records: the two ranges never overlap,
/// so a read-out tells a refused enable from a wrong origin found at rest.
mod origin_faults {
    use super::*;

    /// The detail of the first record after `event` on a fresh machine, and whether the
    /// cause was left active (it never is: each enable judges the origin afresh).
    fn first_detail(event: impl FnOnce(&mut SteeringStateMachine) -> Output) -> (i32, bool) {
        let mut sm = SteeringStateMachine::default();
        let out = event(&mut sm);
        assert_eq!(out.faults, FaultSet::from(Fault::Origin));
        assert_eq!(out.demand, DriveDemand::Disabled);
        let record = sm.fault_log().get(0).copied();
        assert_eq!(record.map(|r| r.fault), Some(Fault::Origin));
        let cause_gone = clear_in_off(&mut sm, 2 * MS).is_ok();
        (record.map_or(i32::MIN, |r| r.detail), cause_gone)
    }

    /// A refused enable records the samples' spread in centi-degrees, from 0 up to one below
    /// `ORIGIN_RESTING_DETAIL` however wide the spread.
    #[test]
    fn a_refused_enable_records_its_spread_below_the_resting_range() {
        let spread = |deg: f32| first_detail(|sm| sm.on_origin_disagreement(MS, SteeringDeg(deg)));
        assert_eq!(spread(0.5), (50, true));
        assert_eq!(spread(12.25), (1_225, true));
        assert_eq!(spread(20_000.0), (ORIGIN_RESTING_DETAIL - 1, true));
        assert_eq!(spread(f32::INFINITY), (999_999, true));
        assert_eq!(spread(-3.0), (0, true));
    }

    /// A wrong origin found at rest records its difference in centi-degrees moved
    /// `ORIGIN_RESTING_DETAIL` away from 0 with its sign (a difference of 0 on the positive
    /// side), saturating at twice that.
    #[test]
    fn a_wrong_origin_at_rest_records_its_signed_difference_beyond_the_resting_detail() {
        let off = |deg: f32| first_detail(|sm| sm.on_origin_off(MS, SteeringDeg(deg)));
        assert_eq!(off(4.25), (1_000_425, true));
        assert_eq!(off(-3.5), (-1_000_350, true));
        assert_eq!(off(0.0), (1_000_000, true));
        assert_eq!(off(1.0e6), (2_000_000, true));
        assert_eq!(off(-1.0e6), (-2_000_000, true));
    }
}

/// Checked configuration values, state codes and the machine's accessors.
mod configuration_and_read_out {
    use super::*;

    #[test]
    fn config_refuses_invalid_values() {
        let c = Config::DEFAULT;
        assert!(c.with_reference_timeout_us(0).is_err());
        assert!(c.with_encoder_timeout_us(0).is_err());
        assert!(c.with_encoder_jump(f32::NAN, 1000.0).is_err());
        assert!(c.with_encoder_jump(1.0, -1.0).is_err());
        assert!(c.with_disagreement(SteeringDeg(0.0), 0).is_err());
        assert!(c.with_disagreement(SteeringDeg(f32::INFINITY), 0).is_err());
        assert!(c.with_overcurrent(Amps(22.0), 0).is_err());
        assert!(c.with_overcurrent(Amps(f32::NAN), 5).is_err());
        let ok = c
            .with_disagreement(SteeringDeg(5.0), 0)
            .and_then(|c| c.with_overcurrent(Amps(10.0), 1));
        assert_eq!(
            ok.map(|c| (c.disagreement(), c.overcurrent())),
            Ok(((SteeringDeg(5.0), 0), (Amps(10.0), 1)))
        );
    }

    /// Every setter sets its value and keeps the others; every accessor reads its own (values
    /// unlike the defaults and unlike 0 and 1).
    #[test]
    fn a_configuration_keeps_every_value_it_was_given() {
        let gearing = Gearing::new(2.0, 0.01, 0.03).unwrap();
        let config = Config::DEFAULT
            .with_reference_timeout_us(50_000)
            .unwrap()
            .with_hold_us(70_000)
            .with_encoder_timeout_us(40_000)
            .unwrap()
            .with_encoder_jump(2.5, 800.0)
            .unwrap()
            .with_tracking(SteeringDeg(12.0), 90_000, 7.0)
            .unwrap()
            .with_actuation(Actuation::DrivingOnly)
            .with_gearing(gearing);
        assert_eq!(config.reference_timeout_us(), 50_000);
        assert_eq!(config.hold_us(), 70_000);
        assert_eq!(config.encoder_timeout_us(), 40_000);
        assert_eq!(config.encoder_jump(), (2.5, 800.0));
        assert_eq!(
            (
                config.tracking_deg,
                config.tracking_persist_us,
                config.tracking_progress_dps
            ),
            (12.0, 90_000, 7.0)
        );
        assert_eq!(config.actuation(), Actuation::DrivingOnly);
        assert_eq!(config.gearing().ratio(), gearing.ratio());
        assert_eq!(
            Config::DEFAULT.with_hold_us(0).hold_us(),
            0,
            "0: disable at once"
        );
        let sm = SteeringStateMachine::new(config);
        assert_eq!(sm.config().hold_us(), 70_000);
    }

    #[test]
    fn state_codes_round_trip() {
        for code in 0..=255u8 {
            match EcuState::from_code(code) {
                Some(s) => assert_eq!(s.code(), code),
                None => assert!(code > 6),
            }
        }
    }

    /// The accessors of the machine read its state: the AS state last received, the log it
    /// keeps (a read-out through `fault_log_mut` empties the one `fault_log` shows), and how
    /// often it went from Track to Hold.
    #[test]
    fn the_machine_reports_its_as_state_log_and_hold_count() {
        const MS: u64 = 1_000;
        let mut sm = SteeringStateMachine::default();
        assert_eq!(sm.as_state(), None);
        // References every 10 ms except in 50..100 ms and 150..200 ms (two gaps beyond the
        // 30 ms timeout but within the hold), the column sampled every 2 ms.
        let mut demands = Vec::new();
        for t in (0..=250 * MS).step_by(2_000) {
            let _ = sm.on_column(t, SteeringDeg(0.0));
            let gap = (51 * MS..100 * MS).contains(&t) || (151 * MS..200 * MS).contains(&t);
            if t % (10 * MS) == 0 && !gap {
                let _ = sm.on_reference(t, AsState::Driving);
            }
            demands.push(sm.tick(t).demand);
        }
        assert_eq!(sm.as_state(), Some(AsState::Driving));
        assert!(demands.contains(&DriveDemand::Hold), "{demands:?}");
        assert_eq!(sm.hold_entries(), 2);
        let _ = sm.on_bus_off(300 * MS, 7);
        assert!(!sm.fault_log().is_empty());
        sm.fault_log_mut().clear();
        assert!(sm.fault_log().is_empty());
    }
}

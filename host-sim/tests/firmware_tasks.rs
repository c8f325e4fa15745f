//! The firmware's own tasks (reference receiver, status sender, encoder reader) and its
//! direct-drive fast loop (`steering_ecu::direct::FastLoop`: Hall commutation, current sense,
//! the cascade), running against the simulated actuator in virtual time: the
//! steering rules, end to end. Own test binary: the mock clock and task pools are global.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/task_scenarios.rs"]
mod task_scenarios;
use task_scenarios::{
    append_resting_steps, assert_settled, controller, in_both_modes, on_plant, plant_effects,
    with_controller,
};

use canlink::Stamped;
use host_sim::effect_plant::PlantEffects;
use host_sim::firmware_fixture::{
    CarPlant, EncoderFault, FirmwareFixture, FixtureBuild, SenseFault, hold_clock,
};
use host_sim::sim_ecu::{CarEffects, STEP_US, SimCar, SimDrive, SimEcu};
use std::cell::RefCell;
use steering_ecu::as_state::AsState;
use steering_ecu::can::Frame;
use steering_ecu::controller::ControllerKind;
use steering_ecu::ecu::{Drive, Ecu};
use steering_ecu::faults::Fault;
use steering_ecu::protocol::{AliveCounter, ProtocolConfig, Reference};
use steering_ecu::steering::{DriveDemand, EcuState};
use steering_ecu::tasks::{self, FrameQueue, SharedEcu};
use steering_ecu::units::SteeringDeg;

/// A sensor fault the scenario injects, from a period on (`at_period` sets it).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Inject {
    None,
    /// The column encoder does not answer.
    EncoderSilent,
    /// The column encoder reads this much more than the column, deg (a slipping coupling).
    EncoderOffsetDeg(f64),
    /// The current sense reads this much more than the winding carries, A (an amplifier
    /// offset).
    CurrentBiasA(f32),
    /// The current sense reads the winding's current with the wrong sign (swapped shunt
    /// wires).
    CurrentSignFlipped,
    /// The fast-loop interrupt stops (the ADC trigger lost, the interrupt masked).
    FastLoopStopped,
}

impl Inject {
    /// Puts the injection into the fixture's sensors and fast loop.
    fn apply(self, fixture: &mut FirmwareFixture) {
        fixture.set_encoder_fault(match self {
            Inject::EncoderSilent => EncoderFault::Silent,
            Inject::EncoderOffsetDeg(d) => EncoderFault::OffsetDeg(d),
            _ => EncoderFault::None,
        });
        fixture.set_sense_fault(match self {
            Inject::CurrentBiasA(a) => SenseFault::BiasA(f64::from(a)),
            Inject::CurrentSignFlipped => SenseFault::SignFlipped,
            _ => SenseFault::None,
        });
        fixture.set_fast_loop_running(self != Inject::FastLoopStopped);
    }
}

/// What the vehicle computer sends in each 10 ms period of the scenario.
#[derive(Clone, Copy, Debug)]
enum Send {
    Ref(AsState, f32),
    /// A reference frame with the clear-faults request bit set.
    Clear(AsState, f32),
    Nothing,
    CorruptCrc(AsState, f32),
}

/// One sample of the run, taken every 10 ms just before the vehicle's frame.
#[derive(Clone, Copy, Debug)]
struct Sample {
    t_ms: u64,
    demand: DriveDemand,
    state: EcuState,
    column_deg: f64,
    current_a: f64,
    faults: u16,
}

/// Runs the tasks for `script.len()` periods of 10 ms; `at_period` may act on the ECU (the
/// clear request, which has no frame yet) and set the injection.
fn run(script: &[Send], at_period: impl Fn(usize, &mut Ecu, &mut Inject)) -> Vec<Sample> {
    run_from(0.0, script, at_period)
}

/// [`run`] with the actuator at rest at `column_deg` at power-up (the Hall count starts at 0
/// wherever the motor stands, as the real decoder's does).
fn run_from(
    column_deg: f64,
    script: &[Send],
    at_period: impl Fn(usize, &mut Ecu, &mut Inject),
) -> Vec<Sample> {
    run_logged(column_deg, script, at_period).samples
}

/// A run's samples, every frame the ECU's tasks put on the bus (stamped with the period
/// boundary at which the harness took it off the transmit queue) and when the watchdog was
/// fed, us.
struct Logged {
    samples: Vec<Sample>,
    sent: Vec<Stamped>,
    feeds_us: Vec<u64>,
}

/// [`run_from`], logged. The fixture's phases in this test's order: the tasks polled first,
/// then, at each period boundary, the sample, the vehicle's frame straight into the ECU's
/// reference queue and the transmit queue taken off; then the fast loop.
fn run_logged(
    column_deg: f64,
    script: &[Send],
    at_period: impl Fn(usize, &mut Ecu, &mut Inject),
) -> Logged {
    let kind = controller();
    let effects = plant_effects(kind);
    let mut fixture = FirmwareFixture::new(FixtureBuild {
        controller: kind,
        drive: SimDrive::Direct,
        column_rad: column_deg.to_radians(),
        epos4_effects: PlantEffects::NONE,
        direct_plant: CarPlant::with_effects(effects, 50e-6),
        bus_faults: Default::default(),
        bus_seed: 1,
        watchdog: true,
        reference_delay_us: 0,
    });
    let protocol = ProtocolConfig::default();
    let mut counter = AliveCounter::wrapping(0);
    let mut inject = Inject::None;
    let mut samples = Vec::new();
    let mut sent = Vec::new();
    let period_steps = 10_000 / STEP_US;
    for tick in 0..script.len() as u64 * period_steps {
        fixture.poll_tasks();
        let now_us = fixture.now_us();
        if tick.is_multiple_of(period_steps) {
            let period = (tick / period_steps) as usize;
            let (demand, state, faults) = fixture.with_ecu(|e| {
                at_period(period, e, &mut inject);
                let o = e.output();
                (o.demand, o.state, o.faults.bits())
            });
            inject.apply(&mut fixture);
            samples.push(Sample {
                t_ms: now_us / 1000,
                demand,
                state,
                column_deg: fixture.column_rad().to_degrees(),
                current_a: fixture.current_a(),
                faults,
            });
            let frame = match script.get(period) {
                Some(Send::Ref(as_state, deg)) => Some((*as_state, *deg, false, false)),
                Some(Send::Clear(as_state, deg)) => Some((*as_state, *deg, false, true)),
                Some(Send::CorruptCrc(as_state, deg)) => Some((*as_state, *deg, true, false)),
                _ => None,
            };
            if let Some((as_state, deg, corrupt, clear_faults)) = frame {
                counter = counter.next();
                let f = protocol.encode_reference(&Reference {
                    angle: SteeringDeg(deg),
                    as_state,
                    counter,
                    clear_faults,
                });
                let f = if corrupt {
                    let mut bytes = [0u8; 8];
                    bytes.copy_from_slice(f.data());
                    bytes[0] ^= 0x5A;
                    Frame::new(f.id(), &bytes).unwrap()
                } else {
                    f
                };
                fixture.to_ecu(f);
            }
            sent.extend(fixture.take_tx().into_iter().map(|frame| Stamped {
                t_us: now_us,
                frame,
            }));
        }
        // The fast loop, as the firmware's ADC interrupt runs it.
        fixture.fast_loop();
        fixture.end_step();
    }
    Logged {
        samples,
        sent,
        feeds_us: fixture.feeds_us(),
    }
}

#[test]
fn steering_rules_end_to_end_on_the_firmware_tasks() {
    in_both_modes(|_| steering_rules_end_to_end());
}

fn steering_rules_end_to_end() {
    // Timeline, 10 ms per entry:
    //   0-9    AS Off, 0 deg          -> drive disabled
    //   10-79  AS Ready/Driving 10 deg -> tracking, the column reaches 10 deg
    //   80-99  nothing                -> hold after 30 ms, disabled + timeout fault after 130 ms
    //   100-109 AS Driving again      -> still disabled: the fault is latched
    //   100     clear request while driving -> refused
    //   110-119 AS Off                -> clear request (frame bit) at 115 accepted
    //   120-159 AS Driving 0 deg      -> tracking again (the enable ramp back from 10 deg)
    //   160-165 corrupted CRC         -> invalid-frame fault latched, disabled
    //   166-169 AS Emergency          -> disabled
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Ready, 10.0); 10]);
    script.extend(vec![Send::Ref(AsState::Driving, 10.0); 60]);
    script.extend(vec![Send::Nothing; 20]);
    script.push(Send::Clear(AsState::Driving, 10.0));
    script.extend(vec![Send::Ref(AsState::Driving, 10.0); 9]);
    script.extend(vec![Send::Ref(AsState::Off, 10.0); 5]);
    script.push(Send::Clear(AsState::Off, 10.0));
    script.extend(vec![Send::Ref(AsState::Off, 10.0); 4]);
    script.extend(vec![Send::Ref(AsState::Driving, 0.0); 40]);
    script.extend(vec![Send::CorruptCrc(AsState::Driving, 0.0); 6]);
    script.extend(vec![Send::Ref(AsState::Emergency, 0.0); 4]);
    let s = run(&script, |period, ecu, _| {
        if period == 105 {
            assert_eq!(
                ecu.clear_refusals(),
                1,
                "the request while driving was refused"
            );
        }
    });
    let at = |p: usize| {
        assert_eq!(s[p].t_ms, p as u64 * 10, "one sample per period");
        s[p]
    };
    assert_eq!(at(5).demand, DriveDemand::Disabled);
    assert_eq!(at(5).state, EcuState::Idle);
    assert_eq!(at(30).demand, DriveDemand::Track);
    assert!(
        (at(79).column_deg - 10.0).abs() < 0.5,
        "column {}",
        at(79).column_deg
    );
    // Reference stops after period 79's frame: hold from 30 ms, then disabled and latched.
    assert_eq!(
        at(82).demand,
        DriveDemand::Track,
        "20 ms without a frame: still tracking"
    );
    assert_eq!(at(84).demand, DriveDemand::Hold);
    assert!((at(90).column_deg - 10.0).abs() < 0.5, "holds the position");
    assert_eq!(at(95).demand, DriveDemand::Disabled);
    assert!(at(95).faults & (1 << Fault::ReferenceTimeout.bit()) != 0);
    assert!(at(99).current_a.abs() < 0.5, "current taken to zero");
    assert_eq!(
        at(105).demand,
        DriveDemand::Disabled,
        "latched while driving"
    );
    assert_eq!(at(105).state, EcuState::Faulted);
    assert_eq!(at(117).faults, 0, "cleared in AS Off on request");
    assert_eq!(at(140).demand, DriveDemand::Track);
    assert!(
        at(159).column_deg.abs() < 0.5,
        "column {}",
        at(159).column_deg
    );
    assert_eq!(
        at(166).demand,
        DriveDemand::Disabled,
        "five bad CRCs in a row"
    );
    assert!(at(166).faults & (1 << Fault::InvalidFrames.bit()) != 0);
    assert_eq!(at(169).demand, DriveDemand::Disabled);
    assert!(s.iter().all(|x| x.current_a.abs() <= 20.0));
}

#[test]
fn sensor_faults_latch_through_the_tasks_and_switch_the_bridge_off() {
    in_both_modes(sensor_faults_latch);
}

fn sensor_faults_latch(kind: ControllerKind) {
    // 0-9 AS Off, 10-99 AS Driving 5 deg; the fault is injected from period 30 on.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 5.0); 90]);
    /// (what breaks, the injection for a period, the fault that must latch)
    type Case = (&'static str, fn(usize) -> Inject, Fault);
    let cases: [Case; 4] = [
        ("encoder silent", |_| Inject::EncoderSilent, Fault::Encoder),
        (
            "encoder jumps 40 deg",
            |_| Inject::EncoderOffsetDeg(40.0),
            Fault::EncoderJump,
        ),
        (
            // 0.4 deg per 10 ms = 40 deg/s: slower than the jump check; past the 15 deg
            // window (on top of the belt's own lag) after about 0.4 s.
            "coupling slips slowly",
            |p| Inject::EncoderOffsetDeg(0.4 * (p - 29) as f64),
            Fault::EncoderMotorDisagreement,
        ),
        (
            // The current loop regulates the measured current within 20 A, so the winding
            // carries -10 A and the column runs away: only the tracking check sees it (and
            // then, with the bridge off, the over-current check sees the 30 A offset).
            "current sense reads 30 A high",
            |_| Inject::CurrentBiasA(30.0),
            Fault::TrackingError,
        ),
    ];
    for (name, injection, fault) in cases {
        let s = run(&script, |period, _, inject| {
            if period >= 30 {
                *inject = injection(period);
            }
        });
        assert_eq!(s[29].demand, DriveDemand::Track, "{name}: tracking before");
        assert_eq!(s[29].faults, 0, "{name}: no fault before");
        let at = (30..s.len())
            .find(|&p| s[p].faults != 0)
            .unwrap_or_else(|| panic!("{name}: nothing latched: {:?}", s[99]));
        assert!(
            s[at].faults & (1 << fault.bit()) != 0,
            "{name}: {fault:?} is among the first faults latched: {:#x}",
            s[at].faults
        );
        eprintln!(
            "{kind:?} mode, {name}: {fault:?} latched {} ms after the injection, column at {:.1} deg",
            (at - 30) * 10,
            s[at].column_deg
        );
        assert_eq!(s[at].demand, DriveDemand::Disabled, "{name}");
        assert_eq!(s[99].state, EcuState::Faulted, "{name}: stays latched");
        assert!(s[99].current_a.abs() < 0.5, "{name}: current taken to zero");
    }
}

/// A drive that runs away from the reference while the loop pushes toward
/// it with all it has is a fault within 50 ms of the push, not after the tracking check's
/// 20 deg for 200 ms.
#[test]
fn a_runaway_latches_within_50_ms_of_the_saturated_push() {
    in_both_modes(|_| a_runaway_latches_within_50_ms_of_the_saturated_push_in());
}

fn a_runaway_latches_within_50_ms_of_the_saturated_push_in() {
    // 0-9 AS Off, 10-69 AS Driving 5 deg; the current sense breaks at period 30.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 5.0); 60]);
    for (name, injection) in [
        ("sense reads 30 A high", Inject::CurrentBiasA(30.0)),
        ("sense sign flipped", Inject::CurrentSignFlipped),
    ] {
        let s = run(&script, |period, _, inject| {
            if period >= 30 {
                *inject = injection;
            }
        });
        assert_eq!(s[29].faults, 0, "{name}");
        let at = (30..s.len())
            .find(|&p| s[p].faults != 0)
            .unwrap_or_else(|| panic!("{name}: nothing latched"));
        let latched_ms = (at - 30) * 10;
        eprintln!(
            "{name}: latched {latched_ms} ms after the injection (column {:.1} deg, faults {:#x})",
            s[at].column_deg, s[at].faults
        );
        // The offset is the runaway check's; the flipped sign makes the current loop a
        // positive feedback, which the over-current check sees first.
        let expected = (1 << Fault::TrackingError.bit()) | (1 << Fault::OverCurrent.bit());
        assert!(s[at].faults & expected != 0, "{name}: {:#x}", s[at].faults);
        assert!(
            latched_ms <= 100,
            "{name}: latched {latched_ms} ms after the injection"
        );
        assert!(
            (s[at].column_deg - 5.0).abs() < 20.0,
            "{name}: the column ran {:.1} deg away",
            s[at].column_deg - 5.0
        );
        assert_eq!(s[at].demand, DriveDemand::Disabled, "{name}");
    }
}

/// The Hall count starts at 0 wherever the motor stands at power-up, so the
/// motor's origin must be taken from the column encoder, or the ECU steers to the wrong angle
/// (or latches the disagreement for good).
#[test]
fn the_motor_origin_is_aligned_to_the_column_wherever_the_car_powers_up() {
    in_both_modes(|_| the_motor_origin_is_aligned_to_the_column_wherever_the_car_powers_up_in());
}

fn the_motor_origin_is_aligned_to_the_column_wherever_the_car_powers_up_in() {
    // 0-9 AS Off, then 1 s of AS Driving at 0 deg.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 0.0); 101]);
    for column_deg in [-30.0, -12.0, 5.0, 15.0, 30.0] {
        let s = run_from(column_deg, &script, |_, _, _| {});
        assert!(
            (s[5].column_deg - column_deg).abs() < 0.1,
            "{column_deg}: the car stands where it was powered up"
        );
        assert!(
            s.iter().all(|x| x.faults == 0),
            "{column_deg}: a fault latched: {:?}",
            s.iter().find(|x| x.faults != 0)
        );
        let end = s[110];
        assert_eq!(end.state, EcuState::Tracking, "{column_deg}");
        assert!(
            end.column_deg.abs() < 1.0,
            "power-up at {column_deg} deg: column at {:.2} deg 1 s after AS Driving at 0 deg",
            end.column_deg
        );
    }
}

/// The receive side of the bus: bus-off ends routing and latches the fault.
#[test]
fn bus_off_ends_reception_and_latches_the_fault() {
    in_both_modes(|_| bus_off_ends_reception_and_latches_the_fault_in());
}

fn bus_off_ends_reception_and_latches_the_fault_in() {
    use steering_ecu::can::StandardId;
    use steering_ecu::ports::{BusError, CanRx};
    use steering_ecu::tasks::{Route, RouterCounters};

    struct Script(std::vec::IntoIter<Result<Frame, BusError>>);
    impl CanRx for Script {
        async fn receive(&mut self) -> Result<Frame, BusError> {
            self.0.next().unwrap_or(Err(BusError::BusOff))
        }
    }
    struct AllToReference;
    impl Route for AllToReference {
        fn route(&self, _: &Frame) -> Option<usize> {
            Some(0)
        }
    }

    let _clock = hold_clock();
    let ecu = SharedEcu::new(RefCell::new(Ecu::paper().unwrap()));
    let queue = FrameQueue::new();
    let frame = Frame::new(StandardId::new(0x100).unwrap(), &[0; 8]).unwrap();
    let mut rx = Script(vec![Ok(frame), Err(BusError::Overrun)].into_iter());
    let mut counters = RouterCounters::default();
    let end = embassy_futures::block_on(tasks::receive_task(
        &mut rx,
        &AllToReference,
        &[queue.sender()],
        &mut counters,
        &ecu,
        || 248,
    ));
    assert_eq!(end, BusError::BusOff);
    assert_eq!((counters.routed, counters.bus_errors), (1, 1));
    let out = ecu.lock(|e| e.borrow().output());
    assert!(out.faults.contains(Fault::BusOff), "{:?}", out.faults);
    assert_eq!(out.demand, DriveDemand::Disabled);
    let record = ecu.lock(|e| e.borrow().machine().fault_log().iter().next().copied());
    assert_eq!(
        record.map(|r| (r.fault, r.detail)),
        Some((Fault::BusOff, 248))
    );
}

/// Every motor frame carries the counter of the last reference frame that passed the CRC, so a
/// sender that starts while the ECU runs can continue it: frames with a corrupted CRC do not
/// move it, and it stays while no reference comes.
#[test]
fn the_motor_frame_carries_the_last_authentic_reference_counter() {
    let _paper = task_scenarios::with_controller(ControllerKind::Paper);
    // Counters 1..=5 good, 6..=8 with a corrupted CRC, then silence.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 5];
    script.extend(vec![Send::CorruptCrc(AsState::Off, 0.0); 3]);
    script.extend(vec![Send::Nothing; 5]);
    let sent = run_logged(0.0, &script, |_, _, _| {}).sent;
    let protocol = ProtocolConfig::default();
    let counters: Vec<u8> = sent
        .iter()
        .filter_map(|s| protocol.decode_motor(&s.frame).ok())
        .map(|m| m.reference_counter.raw())
        .collect();
    assert!(counters.len() >= 12, "{counters:?}");
    assert!(
        counters[0] <= 1,
        "at most the first reference before the first: {counters:?}"
    );
    // Nondecreasing through the good frames, then held at 5.
    assert!(counters.windows(2).all(|w| w[0] <= w[1]), "{counters:?}");
    assert!(counters.contains(&3), "{counters:?}");
    assert_eq!(counters.last(), Some(&5), "{counters:?}");
}

/// The counters and the fault ring leave the ECU on 0x103, one page per
/// status period, and `steer-can monitor`'s decoding shows them by name.
#[test]
fn the_diagnostic_frame_brings_drop_counters_and_fault_records_to_the_monitor() {
    use steer_can::decode::Decoder;
    use steer_can::monitor::Monitor;
    use steering_ecu::canopen::NodeId;
    use steering_ecu::canopen::epos4::PositionScale;

    let _serial = with_controller(ControllerKind::Paper);
    // 0-9 AS Off; 10-29 AS Driving 0 deg; 30-44 nothing (hold, then the timeout latches);
    // 45-49 AS Off, a clear at 50, AS Off to 59; 60-69 Driving; 70-75 six corrupted CRCs (the
    // fifth latches the invalid-frame fault); 76-99 AS Off, long enough for every page.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 0.0); 20]);
    script.extend(vec![Send::Nothing; 15]);
    script.extend(vec![Send::Ref(AsState::Off, 0.0); 5]);
    script.push(Send::Clear(AsState::Off, 0.0));
    script.extend(vec![Send::Ref(AsState::Off, 0.0); 9]);
    script.extend(vec![Send::Ref(AsState::Driving, 0.0); 10]);
    script.extend(vec![Send::CorruptCrc(AsState::Driving, 0.0); 6]);
    script.extend(vec![Send::Ref(AsState::Off, 0.0); 24]);
    let Logged {
        samples: s, sent, ..
    } = run_logged(0.0, &script, |_, _, _| {});
    assert!(s[44].faults & (1 << Fault::ReferenceTimeout.bit()) != 0);
    assert_eq!(s[59].faults, 0, "cleared in AS Off");
    assert!(s[76].faults & (1 << Fault::InvalidFrames.bit()) != 0);

    let node = NodeId::new(1).unwrap();
    let scale = PositionScale::new(4096).unwrap();
    let mut monitor = Monitor::new(Decoder::new(node, scale));
    for frame in &sent {
        let _ = monitor.on_frame(frame);
    }
    let pages = monitor
        .counts
        .get("diagnostics 0x103")
        .copied()
        .unwrap_or(0);
    // One page per 10 ms status period, as the status and motor frames.
    let status = monitor.counts.get("status 0x101").copied().unwrap_or(0);
    assert!(
        pages + 1 >= status && status >= 90,
        "{pages} pages, {status} status frames"
    );
    assert_eq!(monitor.diagnostic_counter.lost, 0, "no page skipped");
    assert!(monitor.crc_errors.is_empty() && monitor.other_errors.is_empty());
    let d = &monitor.diagnostics;
    assert_eq!(d.counter("dropped: CRC"), Some(6), "six corrupted frames");
    // The first good frame after them: its counter is seven past the last CRC-good one.
    assert_eq!(d.counter("dropped: counter jump"), Some(1));
    assert_eq!(d.counter("bus-off events"), Some(0));
    // The silence and the corrupted run each held the position 30 ms after the last good frame.
    assert_eq!(d.counter("hold entries"), Some(2));
    use steer_can::monitor::RecordPage;
    // Every slot of the fault log came, oldest first.
    let records = d.records();
    assert!(
        records.iter().all(|r| *r != RecordPage::NotSeen),
        "{records:?}"
    );
    let RecordPage::Fault {
        fault: older,
        detail: age_ms,
        acknowledged: true,
        ..
    } = records[0]
    else {
        panic!("the timeout, acknowledged by the clear at 50: {records:?}")
    };
    assert_eq!(older, Ok(Fault::ReferenceTimeout));
    assert!((130..=140).contains(&age_ms), "{age_ms} ms");
    // The score that latched it, after the clear: not acknowledged.
    assert!(matches!(
        records[1],
        RecordPage::Fault {
            fault: Ok(Fault::InvalidFrames),
            detail: 5,
            acknowledged: false,
            age_s: 0,
        }
    ));
    assert!(
        records[2..].iter().all(|r| *r == RecordPage::Empty),
        "two faults, two records"
    );
    assert_eq!(d.counter("fault records held"), Some(2));
    assert_eq!(d.counter("unacknowledged records"), Some(1));
    let text = monitor.summary();
    eprintln!("{text}");
    for words in [
        "dropped: CRC 6",
        "hold entries 2",
        "bus-off events 0",
        "fault record 2 (unacknowledged, 0 s ago): invalid reference frames: invalid-frame score 5",
        "fault record 1 (acknowledged, 0 s ago): reference timeout: no valid reference for 1",
    ] {
        assert!(
            text.contains(words),
            "monitor summary lacks {words:?}:\n{text}"
        );
    }
    assert!(
        text.find("fault record 2 (unacknowledged") < text.find("fault record 1 (acknowledged"),
        "the unacknowledged fault first:\n{text}"
    );
}

/// ECU mode in direct drive settles a resting step within 0.3 deg, on the plant with 1.5 deg of
/// belt play and 200 N of rack friction and on the paper's linear plant: the steps of `STEPS_DEG`
/// at the protocol's rate, each held 2.5 s.
#[test]
fn ecu_mode_settles_a_resting_step_within_0_3_deg_on_either_plant() {
    let _serial = with_controller(ControllerKind::Ecu);
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 0.0); 40]);
    let holds = append_resting_steps(&mut script, |deg| Send::Ref(AsState::Driving, deg));
    for (name, effects) in [
        ("play and friction", PlantEffects::PLAY_AND_FRICTION),
        ("paper plant", PlantEffects::NONE),
    ] {
        let s = on_plant(effects, || run(&script, |_, _, _| {}));
        assert!(s.iter().all(|x| x.faults == 0), "{name}: a fault");
        let column: Vec<f64> = s.iter().map(|x| x.column_deg).collect();
        assert_settled("direct, ECU mode", name, &column, &holds);
    }
}

/// The watchdog is fed every feed period while the tasks and the fast loop
/// run, and not once while the fast loop is stopped, so the IWDG resets the MCU.
#[test]
fn the_watchdog_is_fed_only_while_the_fast_loop_and_the_tasks_run() {
    in_both_modes(|_| the_watchdog_is_fed_only_while_both_run());
}

fn the_watchdog_is_fed_only_while_both_run() {
    use steering_ecu::watchdog::{FEED_PERIOD_US, WATCHDOG_TIMEOUT_US};
    // 0-9 AS Off, 10-59 AS Driving 5 deg; the fast loop stops for periods 20-34.
    let mut script = vec![Send::Ref(AsState::Off, 0.0); 10];
    script.extend(vec![Send::Ref(AsState::Driving, 5.0); 50]);
    let feeds = run_logged(0.0, &script, |period, _, inject| {
        *inject = if (20..35).contains(&period) {
            Inject::FastLoopStopped
        } else {
            Inject::None
        };
    })
    .feeds_us;
    let ms = |p: u64| p * 10_000;
    let running = |from: u64, to: u64| {
        feeds
            .iter()
            .filter(|&&t| t > ms(from) && t <= ms(to))
            .count()
    };
    // Every feed period while both run (the first check sees both halves already moving).
    assert!(running(0, 20) >= 19, "{feeds:?}");
    assert_eq!(
        running(21, 35),
        0,
        "fed with the fast loop stopped: {feeds:?}"
    );
    let gap = feeds
        .windows(2)
        .map(|w| w[1] - w[0])
        .max()
        .unwrap_or(u64::MAX);
    assert!(
        gap > u64::from(WATCHDOG_TIMEOUT_US),
        "the stop ({gap} us without a feed) outlasts the IWDG's timeout"
    );
    assert!(running(36, 60) >= 23, "fed again once it runs: {feeds:?}");
    assert!(
        feeds
            .windows(2)
            .all(|w| w[1] - w[0] >= u64::from(FEED_PERIOD_US)),
        "at most one feed per period"
    );
}

/// What an enable asked of the motor, A: the largest mean of the winding current over one
/// 10 ms reference period (what the ECU reports on the bus: the motor frame's mean current in
/// direct drive, the drive's averaged current over the EPOS4), and, for the record, the largest
/// instantaneous winding current and (direct drive) current set-point.
#[derive(Debug, Clone, Copy, Default)]
struct EnableCurrent {
    period_mean_a: f64,
    instantaneous_a: f64,
    setpoint_a: f64,
}

/// A vehicle computer scripted on a car that already saw references (the simulated car's
/// vehicle while `steer-can record` listens, after a `send`) continues the ECU's reference
/// counter, as a real one listening for the motor frame would: the ECU drops no frame as a
/// counter jump.
#[test]
fn a_scripted_vehicle_continues_the_counter_the_ecu_last_saw() {
    let mut car = SimEcu::new(SimCar {
        column_deg: 0.0,
        controller: ControllerKind::Paper,
        drive: SimDrive::Direct,
        effects: CarEffects::NONE,
    });
    for round in 1..=2u64 {
        car.script_vehicle(vec![(AsState::Off, 0.0); 5]);
        car.run_until(round * 100_000);
    }
    let drops = car.with_ecu(|e| *e.e2e().drops());
    assert_eq!(drops.counter_jump, 0, "{drops:?}");
    assert_eq!(drops.invalid_total(), 0, "{drops:?}");
}

/// [`EnableCurrent`] while a resting car at 0 deg is enabled toward `target_deg`, in the
/// simulated car (the firmware's tasks, its EPOS4 link and its fast loop at their own rates,
/// the simulated EPOS4 and the plant): AS Off for 1 s (the EPOS4's bring-up), then AS Driving
/// at `target_deg` for 1.5 s (the 0.7 s ramp of 60 deg and its settling), sampled every
/// 50 us.
fn enable_current(drive: SimDrive, controller: ControllerKind, target_deg: f64) -> EnableCurrent {
    let mut car = SimEcu::new(SimCar {
        column_deg: 0.0,
        controller,
        drive,
        effects: CarEffects::NONE,
    });
    let mut script = vec![(AsState::Off, target_deg); 100];
    script.extend(vec![(AsState::Driving, target_deg); 150]);
    car.script_vehicle(script);
    let period_steps = u64::from(steering_ecu::protocol::PERIOD_US) / STEP_US;
    let mut peak = EnableCurrent::default();
    let (mut sum, mut n) = (0.0, 0);
    let mut t_us = 0;
    while t_us < 2_500_000 {
        t_us += STEP_US;
        car.run_until(t_us);
        let setpoint = car.with_ecu(|e| match e.drive() {
            Drive::Direct(d) => f64::from(d.controller().current_setpoint().0),
            Drive::Epos4(_) => 0.0,
        });
        let winding = car.current_a();
        peak.setpoint_a = peak.setpoint_a.max(setpoint.abs());
        peak.instantaneous_a = peak.instantaneous_a.max(winding.abs());
        sum += winding;
        n += 1;
        if n == period_steps {
            peak.period_mean_a = peak.period_mean_a.max((sum / n as f64).abs());
            (sum, n) = (0.0, 0);
        }
    }
    let o = car.output();
    assert_eq!(o.demand, DriveDemand::Track, "{drive:?} {controller:?}");
    assert_eq!(o.faults.bits(), 0, "{drive:?} {controller:?}");
    assert!(
        (car.column_deg() - target_deg).abs() < 1.0,
        "{drive:?} {controller:?}: the column reached {:.2} deg of {target_deg}",
        car.column_deg()
    );
    peak
}

/// Enabling a resting car asks at most half the 20 A current limit over any reference period,
/// in either drive and with either controller, for a small and a far target: the enable ramp
/// starts (and ends) with limited acceleration, not with a step in speed that the position
/// loop answers with the full current for a period. (Instantaneous peaks of one position tick
/// remain in direct drive: the paper's D term differences the Hall angle and kicks the
/// set-point at every Hall edge, at rest as well; they are printed, not bounded here.)
#[test]
fn the_enable_of_a_resting_car_asks_at_most_half_the_current_limit() {
    let half = f64::from(steering_ecu::paper_mode::CURRENT_LIMIT.0) / 2.0;
    let mut worst: f64 = 0.0;
    for drive in [SimDrive::Direct, SimDrive::Epos4] {
        for controller in [ControllerKind::Paper, ControllerKind::Ecu] {
            for target_deg in [5.0, 60.0] {
                let c = enable_current(drive, controller, target_deg);
                eprintln!(
                    "enable to {target_deg} deg, {drive:?} drive, {controller:?} mode: \
                     {:.2} A over a period at most, {:.2} A instantaneous, set-point {:.2} A",
                    c.period_mean_a, c.instantaneous_a, c.setpoint_a
                );
                worst = worst.max(c.period_mean_a);
            }
        }
    }
    assert!(
        worst <= half,
        "an enable asked {worst:.2} A over a period, more than half the {:.0} A limit",
        2.0 * half
    );
}

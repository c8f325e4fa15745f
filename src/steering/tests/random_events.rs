//! Random event sequences against the invariants of the module documentation.
use super::*;
use proptest::prelude::*;

const AS_STATES: [AsState; 6] = [
    AsState::Manual,
    AsState::Off,
    AsState::Ready,
    AsState::Driving,
    AsState::Emergency,
    AsState::Finished,
];

#[derive(Debug, Clone)]
enum Event {
    Tick,
    Reference(usize),
    AsOnly(usize),
    InvalidFrames,
    Encoder(f32, f32),
    EncoderFault,
    Current(f32),
    EposFault,
    EposGone,
    HeartbeatLost,
    Heartbeat,
    BusOff,
    BusRecovered,
    Clear,
}

fn angle() -> impl Strategy<Value = f32> {
    prop_oneof![
        8 => -100.0f32..100.0,
        1 => Just(f32::NAN),
        1 => any::<f32>(),
    ]
}

fn event() -> impl Strategy<Value = Event> {
    prop_oneof![
        6 => Just(Event::Tick),
        8 => (0..6usize).prop_map(Event::Reference),
        1 => (0..6usize).prop_map(Event::AsOnly),
        1 => Just(Event::InvalidFrames),
        // Mostly agreeing, sometimes apart, sometimes garbage.
        8 => (-90.0f32..90.0, prop_oneof![8 => Just(0.0f32), 2 => -30.0f32..30.0])
            .prop_map(|(c, d)| Event::Encoder(c, c + d)),
        1 => (angle(), angle()).prop_map(|(c, m)| Event::Encoder(c, m)),
        1 => Just(Event::EncoderFault),
        4 => prop_oneof![8 => -21.0f32..21.0, 1 => -40.0f32..40.0, 1 => any::<f32>()]
            .prop_map(Event::Current),
        1 => Just(Event::EposFault),
        1 => Just(Event::EposGone),
        1 => Just(Event::HeartbeatLost),
        1 => Just(Event::Heartbeat),
        1 => Just(Event::BusOff),
        1 => Just(Event::BusRecovered),
        2 => Just(Event::Clear),
    ]
}

/// The AS state the machine must believe: Emergency stands until Off.
fn next_as_state(believed: Option<AsState>, sent: AsState) -> Option<AsState> {
    if believed == Some(AsState::Emergency) && sent != AsState::Off {
        believed
    } else {
        Some(sent)
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn random_events_never_break_the_invariants(
        steps in prop::collection::vec((0u64..40_000, event()), 1..400)
    ) {
        let mut sm = SteeringStateMachine::default();
        let gearing = Gearing::PAPER;
        let mut now = 0u64;
        let mut last_reference: Option<u64> = None;
        let mut last_encoder: Option<u64> = None;
        let mut as_state: Option<AsState> = None;
        let mut faults = FaultSet::EMPTY;
        for (dt, ev) in steps {
            now += dt;
            let out = match ev {
                Event::Tick => sm.tick(now),
                Event::Reference(i) => {
                    as_state = next_as_state(as_state, AS_STATES[i]);
                    last_reference = Some(now);
                    sm.on_reference(now, AS_STATES[i])
                }
                Event::AsOnly(i) => {
                    as_state = next_as_state(as_state, AS_STATES[i]);
                    sm.on_as_state(now, AS_STATES[i])
                }
                Event::InvalidFrames => sm.on_invalid_frames_fault(now, 10),
                Event::Encoder(c, m) => {
                    let motor = gearing.motor_from_steering(SteeringDeg(m).into());
                    if c.is_finite() && motor.is_finite() {
                        last_encoder = Some(now);
                    }
                    sm.on_encoder(now, SteeringDeg(c), motor)
                }
                Event::EncoderFault => sm.on_encoder_fault(now, 1),
                Event::Current(a) => sm.on_current(now, Amps(a)),
                Event::EposFault => sm.on_epos_fault(now, 0x1000),
                Event::EposGone => sm.on_epos_fault_gone(now),
                Event::HeartbeatLost => sm.on_heartbeat_lost(now),
                Event::Heartbeat => sm.on_heartbeat(now),
                Event::BusOff => sm.on_bus_off(now, 255),
                Event::BusRecovered => sm.on_bus_recovered(now),
                Event::Clear => {
                    let result = sm.request_clear_faults(now);
                    if result.is_ok() {
                        prop_assert_eq!(as_state, Some(AsState::Off));
                        faults = FaultSet::EMPTY;
                    }
                    sm.tick(now)
                }
            };
            let age = |t: Option<u64>| t.map(|t| now - t);
            let powered = as_state.is_some_and(AsState::actuator_may_be_powered);
            match out.demand {
                DriveDemand::Track => {
                    prop_assert!(out.faults.is_empty());
                    prop_assert!(powered);
                    prop_assert!(age(last_reference).is_some_and(|a| a <= 30_000));
                    prop_assert!(age(last_encoder).is_some_and(|a| a <= 30_000));
                    prop_assert_eq!(out.state, EcuState::Tracking);
                }
                DriveDemand::Hold => {
                    prop_assert!(out.faults.is_empty());
                    prop_assert!(powered);
                    prop_assert!(age(last_reference).is_some_and(|a| a <= 130_000));
                    prop_assert_eq!(out.state, EcuState::Holding);
                }
                DriveDemand::Disabled => {}
            }
            if !out.faults.is_empty() {
                prop_assert_eq!(out.demand, DriveDemand::Disabled);
            }
            if as_state == Some(AsState::Emergency) {
                prop_assert_eq!(out.demand, DriveDemand::Disabled);
                prop_assert_eq!(out.state, EcuState::Emergency);
            }
            // Faults only go away through a granted clear.
            prop_assert_eq!(out.faults.intersection(faults), faults);
            faults = out.faults;
            prop_assert_eq!(out.faults, sm.faults());
            prop_assert_eq!(sm.as_state(), as_state);
            prop_assert_eq!(EcuState::from_code(out.state.code()), Some(out.state));
        }
    }
}

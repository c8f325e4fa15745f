//! The ECU in one piece of pure logic: the reference frames through the E2E check into the
//! steering state machine, whose demand gates the cascade, and the status frame back. The
//! firmware's tasks and interrupts call these methods (under a critical-section mutex);
//! host-sim calls the same ones from its tasks in virtual time.
//!
//! This is the "direct" drive mode, where the ECU runs the cascade itself. The demand decides
//! what the fast loops may do:
//!
//! ```text
//! demand    | position tick              | current tick
//! ----------+----------------------------+------------------------------
//! Disabled  | 0 A, cascade not stepped   | bridge off (None)
//! Hold      | cascade on the last sample | PI current loop
//! Track     | cascade, new samples pushed| PI current loop
//! ```
//!
//! When the demand leaves `Disabled`, the cascade is reset to the measured motor angle first,
//! so it starts where the motor is, with empty integrators.

use crate::can::Frame;
use crate::paper_mode::Cascade;
use crate::protocol::{AliveCounter, E2eChecker, E2eVerdict, MotorStatus, ProtocolConfig, Status};
use crate::sensors::motor_from_hall;
use crate::steering::{Config, DriveDemand, Output, SteeringStateMachine};
use crate::units::{Amps, SteeringDeg, Volts};

#[derive(Debug, Clone)]
pub struct Ecu {
    protocol: ProtocolConfig,
    e2e: E2eChecker,
    machine: SteeringStateMachine,
    cascade: Cascade,
    last: Output,
    status_counter: AliveCounter,
    hall_count: i32,
    column: SteeringDeg,
    current: Amps,
    clear_refusals: u16,
    motor_counter: AliveCounter,
    /// Measured current summed since the last motor frame, A, and the number of samples.
    current_sum: f32,
    current_samples: u32,
}

impl Ecu {
    /// An ECU with these settings; `None` if the protocol configuration is refused.
    pub fn new(protocol: ProtocolConfig, config: Config, cascade: Cascade) -> Option<Self> {
        let e2e = E2eChecker::new(protocol).ok()?;
        let mut machine = SteeringStateMachine::new(config);
        let last = machine.tick(0);
        Some(Ecu {
            protocol,
            e2e,
            machine,
            cascade,
            last,
            status_counter: AliveCounter::wrapping(0),
            hall_count: 0,
            column: SteeringDeg(f32::NAN),
            current: Amps(f32::NAN),
            clear_refusals: 0,
            motor_counter: AliveCounter::wrapping(0),
            current_sum: 0.0,
            current_samples: 0,
        })
    }

    /// The paper's actuator, the default protocol and state-machine settings.
    pub fn paper() -> Option<Self> {
        Self::new(ProtocolConfig::default(), Config::DEFAULT, Cascade::paper())
    }

    pub fn output(&self) -> Output {
        self.last
    }

    pub fn machine(&self) -> &SteeringStateMachine {
        &self.machine
    }

    pub fn machine_mut(&mut self) -> &mut SteeringStateMachine {
        &mut self.machine
    }

    pub fn e2e(&self) -> &E2eChecker {
        &self.e2e
    }

    /// Clear requests (reference frame bit) the state machine refused, saturating.
    pub fn clear_refusals(&self) -> u16 {
        self.clear_refusals
    }

    fn apply(&mut self, out: Output) -> Output {
        if out.drive_just_enabled {
            self.cascade.reset(self.hall_count);
        }
        self.last = out;
        out
    }

    /// A frame routed to the reference consumer: checked end to end, then handed on.
    pub fn on_reference_frame(&mut self, now_us: u64, frame: &Frame) -> Output {
        let out = match self.e2e.check(frame, now_us) {
            E2eVerdict::Valid(reference) => {
                let mut out = self.machine.on_reference(now_us, reference.as_state);
                if reference.clear_faults {
                    // Refused unless AS Off with every cause gone; the faults stay then.
                    if self.machine.request_clear_faults(now_us).is_err() {
                        self.clear_refusals = self.clear_refusals.saturating_add(1);
                    }
                    out = self.machine.tick(now_us);
                }
                let out = self.apply(out);
                if out.demand == DriveDemand::Track {
                    // The E2E check already bounds the angle to the cascade's range; a refusal
                    // here keeps the ramp in progress, which is the documented outcome.
                    let _ = self.cascade.push_reference(reference.angle);
                }
                return out;
            }
            E2eVerdict::Dropped { .. } => self.machine.tick(now_us),
            E2eVerdict::Fault { invalid_in_row, .. } => self
                .machine
                .on_invalid_frames_fault(now_us, u16::from(invalid_in_row)),
        };
        self.apply(out)
    }

    /// Time passes (call at least every reference period): timeouts are found here.
    pub fn tick(&mut self, now_us: u64) -> Output {
        let out = self.machine.tick(now_us);
        self.apply(out)
    }

    /// A column-encoder sample, checked against the motor angle of the last position tick.
    pub fn on_encoder(&mut self, now_us: u64, column: SteeringDeg) -> Output {
        self.column = column;
        let out = self
            .machine
            .on_encoder(now_us, column, motor_from_hall(self.hall_count));
        self.apply(out)
    }

    /// The encoder did not answer or flagged its reading.
    pub fn on_encoder_error(&mut self, now_us: u64, code: u16) -> Output {
        self.column = SteeringDeg(f32::NAN);
        let out = self.machine.on_encoder_fault(now_us, code);
        self.apply(out)
    }

    pub fn on_bus_off(&mut self, now_us: u64, tec: u8) -> Output {
        let out = self.machine.on_bus_off(now_us, tec);
        self.apply(out)
    }

    /// Position-loop tick (2 kHz): the current set-point, 0 A unless the drive is enabled.
    pub fn position_tick(&mut self, hall_count: i32) -> Amps {
        self.hall_count = hall_count;
        match self.last.demand {
            DriveDemand::Disabled => Amps::ZERO,
            DriveDemand::Hold | DriveDemand::Track => {
                self.cascade.position_step(hall_count).current
            }
        }
    }

    /// Current-loop tick (20 kHz): the voltage to apply, or `None` for bridge off. The
    /// measured current also feeds the over-current check.
    pub fn current_tick(&mut self, now_us: u64, measured: Amps) -> Option<Volts> {
        self.current = measured;
        self.current_sum += measured.0;
        self.current_samples = self.current_samples.saturating_add(1);
        let out = self.machine.on_current(now_us, measured);
        let out = self.apply(out);
        match out.demand {
            DriveDemand::Disabled => None,
            DriveDemand::Hold | DriveDemand::Track => {
                Some(self.cascade.current_step(measured).voltage)
            }
        }
    }

    /// The next status frame (call once per status period).
    pub fn status_frame(&mut self) -> Frame {
        self.status_counter = self.status_counter.next();
        self.protocol.encode_status(&Status {
            angle: self.column,
            current: self.current,
            ecu_state: self.last.state.code(),
            faults: self.last.faults.bits(),
            counter: self.status_counter,
        })
    }

    /// The next motor frame (call once per status period, after [`Ecu::status_frame`]): the
    /// motor angle of the last position tick and the mean measured current since the last
    /// motor frame (NaN when no current sample came, or one was not a number).
    pub fn motor_frame(&mut self) -> Frame {
        self.motor_counter = self.motor_counter.next();
        let current_mean = if self.current_samples == 0 {
            Amps(f32::NAN)
        } else {
            Amps(self.current_sum / self.current_samples as f32)
        };
        self.current_sum = 0.0;
        self.current_samples = 0;
        self.protocol.encode_motor(&MotorStatus {
            angle: motor_from_hall(self.hall_count),
            current_mean,
            counter: self.motor_counter,
        })
    }
}

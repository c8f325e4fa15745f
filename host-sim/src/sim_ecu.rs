//! The simulated car on the bus: the firmware's own tasks (`steering_ecu::tasks`: reference
//! receiver, status sender, encoder reader and, in EPOS4 mode, the EPOS4 link) and its `Ecu`,
//! the simulated EPOS4 at its node and the paper's plant, all on one in-memory CAN bus in
//! virtual time. A host tool attaches as a further node through [`canlink::Transport`],
//! so every `steer-can` command runs against it exactly as against the car.
//!
//! Two builds of the car, as the firmware has two drive modes ([`SimDrive`]):
//! - EPOS4 mode (the firmware's default build): the ECU's link brings the EPOS4 up (SDO
//!   configuration, CSP mode 8, SYNC every 10 ms, heartbeats, PDOs) and the simulated EPOS4
//!   (`crate::epos4_sim`) runs the paper's cascade on its own copy of the paper plant.
//! - direct drive: the ECU's own fast loop (`steering_ecu::direct::FastLoop`: Hall
//!   commutation, current sense, bridge; position 2 kHz, current 20 kHz) runs as the
//!   firmware's ADC interrupt runs it, as in `tests/firmware_tasks.rs`, on the plant here. The
//!   simulated EPOS4 stays on the bus, unconfigured, as a drive a direct-drive car does not use.
//!
//! How the tasks run: on [`crate::firmware_fixture`] (the firmware's tasks polled once per
//! 50 µs step, embassy-time's mock driver advanced by the step), in the order below. The
//! host code calls in and out (`recv_until`) between steps. The ECU's received frames go
//! through the firmware's own routing ([`steering_ecu::tasks::FirmwareRoutes`],
//! [`route_to_ecu`]).
//!
//! The mock clock is global to the process, so one `SimEcu` lives at a time: `new` waits for
//! the previous one to be dropped.
//!
//! ```text
//!  step (50 µs):  bus delivers due frames -> ECU port: routed to the reference / drive queue
//!                                          -> EPOS4 port: Epos4Sim::on_frame, answers sent
//!                                          -> host port: inbox
//!                 vehicle computer (if scripted): its reference frame every 10 ms
//!                 poll the tasks; the ECU's frames from the TX queue onto the bus
//!                 EPOS4 advance (heartbeat, PDOs, its own loops on its plant)
//!                 direct drive only: fast loop (Hall code, phase currents -> bridge command;
//!                 position tick every 10th step), plant step
//!                 encoder value; mock clock += 50 µs
//! ```

use crate::effect_plant::PlantEffects;
use crate::epos4_sim::Epos4Sim;
use crate::firmware_fixture::{CarPlant, EncoderFault, FirmwareFixture, FixtureBuild, SenseFault};
use canlink::canbus::{CanBus, Port, RandomFaults};
use canlink::reference::ReferenceSender;
use canlink::{Clock, LinkError, Stamped, Transport};
use std::collections::VecDeque;
use steering_ecu::as_state::AsState;
use steering_ecu::can::Frame;
use steering_ecu::controller::ControllerKind;
use steering_ecu::ecu::Ecu;
use steering_ecu::protocol::{AliveCounter, PERIOD_US, ProtocolConfig};
use steering_ecu::steering::Output;

// The fixture's names, as the simulated car's users have always named them.
pub use crate::firmware_fixture::{
    BUS_LATENCY_US, EPOS_NODE, STEP_US, SUPPLY_V, SimDrive, direct_drive_period,
    direct_drive_period_sensed, epos4_ecu, route_to_ecu,
};

/// Wall-clock time of the simulation's t = 0 in its recordings, s since the Unix epoch: a fixed,
/// recognisable origin, so recordings of the simulation repeat byte for byte.
pub const EPOCH_S: f64 = 1_700_000_000.0;
/// How the simulated car is built and powered up.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SimCar {
    /// Steering angle at power-up, deg at the wheel (a non-finite one is taken as 0).
    pub column_deg: f64,
    pub controller: ControllerKind,
    pub drive: SimDrive,
    /// What the car has that Table 4 leaves out (none: the paper's plant exactly).
    pub effects: CarEffects,
}

impl SimCar {
    /// The default firmware (EPOS4 mode, the paper's controller), powered up straight.
    pub const DEFAULT: SimCar = SimCar {
        column_deg: 0.0,
        controller: ControllerKind::Paper,
        drive: SimDrive::Epos4,
        effects: CarEffects::NONE,
    };
}

/// A simulated car's hidden effects, `--plant-effects KEY=VALUE,...`: the plant's (host-sim's
/// `--plant-effects` keys: `backlash_deg`, `coulomb_n`, `coulomb_creep_mm_s`, `tire_n`, ...)
/// and `reference_delay_ms`, a delay between the reference frame reaching the ECU and the ECU
/// acting on it. For rehearsing the gap diagnosis on a car whose gap is known.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct CarEffects {
    pub plant: PlantEffects,
    /// 0..=200 ms.
    pub reference_delay_s: f64,
}

impl CarEffects {
    pub const NONE: CarEffects = CarEffects {
        plant: PlantEffects::NONE,
        reference_delay_s: 0.0,
    };

    pub fn is_none(&self) -> bool {
        self.plant.is_none() && self.reference_delay_s == 0.0
    }
}

impl std::str::FromStr for CarEffects {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let mut delay = 0.0;
        let mut rest = Vec::new();
        for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
            match item.split_once('=') {
                Some((k, v)) if k.trim() == "reference_delay_ms" => {
                    // The caller quotes the whole list: the key and the value apart, once.
                    let ms: f64 = v
                        .trim()
                        .parse()
                        .ok()
                        .filter(|ms| (0.0..=200.0).contains(ms))
                        .ok_or_else(|| {
                            format!(
                                "reference_delay_ms takes a number of ms within 0..=200, not \
                                 `{}`",
                                v.trim()
                            )
                        })?;
                    delay = ms * 1e-3;
                }
                _ => rest.push(item),
            }
        }
        let plant = PlantEffects::parse(&rest.join(",")).map_err(|e| e.to_string())?;
        Ok(CarEffects {
            plant,
            reference_delay_s: delay,
        })
    }
}

impl std::fmt::Display for CarEffects {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.plant.is_none(), self.reference_delay_s > 0.0) {
            (true, false) => write!(f, "none"),
            (false, false) => write!(f, "{}", self.plant),
            (true, true) => write!(f, "reference_delay_ms={}", self.reference_delay_s * 1e3),
            (false, true) => write!(
                f,
                "{},reference_delay_ms={}",
                self.plant,
                self.reference_delay_s * 1e3
            ),
        }
    }
}

/// A fault put into the simulation on purpose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Injection {
    /// The column encoder stops answering (SPI timeout).
    EncoderNoResponse,
    /// The current sensor reads this many amps more than flows (a broken sensor or a short):
    /// the over-current check sees it. Direct drive only (the EPOS4 measures its own
    /// current): see [`SimEcu::can_inject`].
    CurrentOffset(f64),
    /// The EPOS4 reports a drive error with this CANopen error code (EMCY + Fault state).
    EposFault(u16),
}

impl Injection {
    /// `encoder`, `overcurrent` (a 30 A offset), `epos` (0x3210, DC link over-voltage).
    pub fn parse(s: &str) -> Option<Injection> {
        match s {
            "encoder" => Some(Injection::EncoderNoResponse),
            "overcurrent" => Some(Injection::CurrentOffset(30.0)),
            "epos" => Some(Injection::EposFault(0x3210)),
            _ => None,
        }
    }
}

/// A scripted vehicle computer ([`SimEcu::script_vehicle`]).
struct Vehicle {
    port: Port,
    script: VecDeque<(AsState, f64)>,
    sender: ReferenceSender,
    next_us: u64,
}

/// The simulated ECU, its actuator, the EPOS4 and the bus.
pub struct SimEcu {
    fixture: FirmwareFixture,
    host_port: Port,
    vehicle: Option<Vehicle>,
    /// The reference counter of the ECU's last motor frame on the bus (`MOT_RefCounter`): a
    /// scripted vehicle continues after it, as a vehicle computer that listens before its
    /// first frame does.
    ecu_reference_counter: AliveCounter,
    inbox: VecDeque<Stamped>,
    scheduled: Vec<(u64, Injection)>,
}

impl std::fmt::Debug for SimEcu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimEcu")
            .field("now_us", &self.fixture.now_us())
            .field("output", &self.output())
            .finish_non_exhaustive()
    }
}

impl SimEcu {
    /// The paper's ECU and actuator at rest at 0 deg, the EPOS4 at node 1 (booting), t = 0.
    /// Waits while another `SimEcu` of this process is alive.
    pub fn paper() -> SimEcu {
        Self::paper_at(0.0)
    }

    /// [`SimEcu::paper`] with the car powered up at `column_deg` at the wheel (the actuator
    /// and the EPOS4's plant at rest there). The Hall count and the EPOS4's position start at
    /// 0 wherever the motor stands, so this rehearses the ECU's motor-origin alignment.
    /// A non-finite angle is taken as 0.
    pub fn paper_at(column_deg: f64) -> SimEcu {
        Self::at(column_deg, ControllerKind::Paper)
    }

    /// [`SimEcu::paper_at`] with the ECU running `controller` (direct drive).
    pub fn at(column_deg: f64, controller: ControllerKind) -> SimEcu {
        Self::new(SimCar {
            column_deg,
            controller,
            drive: SimDrive::Direct,
            effects: CarEffects::NONE,
        })
    }

    /// The car `car` describes, at t = 0; the EPOS4 sends its boot-up message first, as it
    /// boots before the ECU's link starts. Waits while another `SimEcu` of this process is
    /// alive.
    pub fn new(car: SimCar) -> SimEcu {
        let column_rad = if car.column_deg.is_finite() {
            car.column_deg.to_radians()
        } else {
            0.0
        };
        let mut fixture = FirmwareFixture::new(FixtureBuild {
            controller: car.controller,
            drive: car.drive,
            column_rad,
            epos4_effects: car.effects.plant,
            direct_plant: CarPlant::new(car.effects.plant, STEP_US as f64 * 1e-6),
            bus_faults: RandomFaults::default(),
            bus_seed: 1,
            watchdog: false,
            reference_delay_us: (car.effects.reference_delay_s * 1e6).round() as u64,
        });
        let host_port = fixture.bus_mut().attach();
        SimEcu {
            fixture,
            host_port,
            vehicle: None,
            ecu_reference_counter: AliveCounter::default(),
            inbox: VecDeque::new(),
            scheduled: Vec::new(),
        }
    }

    /// Which drive the car runs.
    pub fn drive(&self) -> SimDrive {
        self.fixture.drive()
    }

    /// A vehicle computer on its own node that sends `script` as its reference frames (AS
    /// state, angle at the wheel in deg), one every 10 ms from the next whole period, and then
    /// falls silent (end the script in AS Off, or the ECU sees a reference timeout). For
    /// `steer-can record`, which on the car records while someone else steers. Replaces an
    /// earlier script.
    pub fn script_vehicle(&mut self, script: Vec<(AsState, f64)>) {
        let port = match &self.vehicle {
            Some(v) => v.port,
            None => self.fixture.bus_mut().attach(),
        };
        let period = u64::from(PERIOD_US);
        let mut sender = ReferenceSender::default();
        sender.continue_after(self.ecu_reference_counter);
        self.vehicle = Some(Vehicle {
            port,
            script: script.into(),
            sender,
            next_us: self.fixture.now_us().div_ceil(period) * period,
        });
    }

    /// The ECU's last output (demand, state, faults).
    pub fn output(&self) -> Output {
        self.fixture.output()
    }

    /// Read or change the ECU directly (tests).
    pub fn with_ecu<R>(&self, f: impl FnOnce(&mut Ecu) -> R) -> R {
        self.fixture.with_ecu(f)
    }

    pub fn epos(&self) -> &Epos4Sim {
        self.fixture.epos()
    }

    pub fn epos_mut(&mut self) -> &mut Epos4Sim {
        self.fixture.epos_mut()
    }

    pub fn bus_mut(&mut self) -> &mut CanBus {
        self.fixture.bus_mut()
    }

    /// Column angle of the simulated actuator, deg at the wheel.
    pub fn column_deg(&self) -> f64 {
        self.fixture.column_rad().to_degrees()
    }

    /// Motor current of the simulated actuator, A.
    pub fn current_a(&self) -> f64 {
        self.fixture.current_a()
    }

    /// Whether `injection` has an effect on this car: a current-sense offset needs the ECU's
    /// own current sensing (direct drive).
    pub fn can_inject(&self, injection: Injection) -> bool {
        !matches!(
            (injection, self.drive()),
            (Injection::CurrentOffset(_), SimDrive::Epos4)
        )
    }

    /// Apply `injection` now (one [`SimEcu::can_inject`] refuses has no effect).
    pub fn inject(&mut self, injection: Injection) {
        match injection {
            Injection::EncoderNoResponse => self.fixture.set_encoder_fault(EncoderFault::Silent),
            Injection::CurrentOffset(a) => self.fixture.set_sense_fault(SenseFault::BiasA(a)),
            Injection::EposFault(code) => self.fixture.epos_mut().inject_fault(code),
        }
    }

    /// Apply `injection` when the virtual clock reaches `at_us`.
    pub fn inject_at(&mut self, at_us: u64, injection: Injection) {
        self.scheduled.push((at_us, injection));
    }

    /// Run until `t_us` (frames for the host go to its inbox).
    pub fn run_until(&mut self, t_us: u64) {
        while self.fixture.now_us() < t_us {
            self.step();
        }
    }

    /// One 50 µs step: the bus before the tasks, so a frame due now is seen now.
    fn step(&mut self) {
        let now = self.fixture.now_us();
        let due: Vec<Injection> = self
            .scheduled
            .iter()
            .filter(|(at, _)| *at <= now)
            .map(|(_, i)| *i)
            .collect();
        self.scheduled.retain(|(at, _)| *at > now);
        for i in due {
            self.inject(i);
        }
        for (port, frame) in self.fixture.deliver() {
            if port == self.host_port {
                self.inbox.push_back(Stamped { t_us: now, frame });
            }
        }
        if let Some(v) = &mut self.vehicle
            && now >= v.next_us
            && let Some((as_state, deg)) = v.script.pop_front()
        {
            let frame = v.sender.frame(deg, as_state, false);
            self.fixture.bus_mut().send(v.port, frame, now);
            v.next_us += u64::from(PERIOD_US);
        }
        self.fixture.poll_tasks();
        let ecu_port = self.fixture.ecu_port();
        for frame in self.fixture.take_tx() {
            if let Ok(motor) = ProtocolConfig::DEFAULT.decode_motor(&frame) {
                self.ecu_reference_counter = motor.reference_counter;
            }
            self.fixture.bus_mut().send(ecu_port, frame, now);
        }
        self.fixture.advance_epos();
        self.fixture.fast_loop();
        self.fixture.end_step();
    }
}

impl Clock for SimEcu {
    fn now_us(&self) -> u64 {
        self.fixture.now_us()
    }
}

impl Transport for SimEcu {
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError> {
        let now = self.fixture.now_us();
        self.fixture.bus_mut().send(self.host_port, *frame, now);
        Ok(())
    }

    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
        loop {
            if let Some(rx) = self.inbox.pop_front() {
                return Ok(Some(rx));
            }
            if self.fixture.now_us() >= deadline_us {
                return Ok(None);
            }
            self.step();
        }
    }

    fn name(&self) -> &str {
        "sim"
    }

    fn epoch_s(&self) -> f64 {
        EPOCH_S
    }
}

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
//! How the tasks run: the same task functions the STM32 runs, polled once per 50 µs step by a
//! small single-threaded executor here (a no-op waker, every task polled every step), with
//! embassy-time's mock driver advanced by the step. Polling every step costs nothing at this
//! rate and lets the host code call in and out (`recv_until`) instead of handing control to
//! embassy's `Executor::run_until`. The ECU's received frames go through the firmware's own
//! routing ([`steering_ecu::tasks::FirmwareRoutes`], [`route_to_ecu`]).
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

use crate::effect_plant::{EffectPlant, PlantEffects};
use crate::epos4_sim::Epos4Sim;
use crate::plant::{Actuator, LinearPlant, PlantParams};
use canlink::canbus::{CanBus, Port};
use canlink::reference::ReferenceSender;
use canlink::{Clock, LinkError, Stamped, Transport};
use embassy_time::{Duration, MockDriver};
use std::cell::Cell;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::sync::{Mutex, MutexGuard};
use std::task::{Context, Waker};
use steering_ecu::as_state::AsState;
use steering_ecu::can::Frame;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::epos4::{Epos4Config, PositionScale};
use steering_ecu::commutation::{BRIDGE_OFF, BridgeCommand, HallDecoder, code_of};
use steering_ecu::controller::ControllerKind;
use steering_ecu::direct::FastLoop;
use steering_ecu::ecu::{DriveChoice, Ecu, EcuBuild};
use steering_ecu::ports::{Bridge, ColumnEncoderPort, CurrentSense, EncoderError, HallInputs};
use steering_ecu::protocol::{AliveCounter, PERIOD_US, ProtocolConfig};
use steering_ecu::sensors::{ColumnEncoder, hall_from_motor};
use steering_ecu::steering::Output;
use steering_ecu::tasks::{self, FirmwareRoutes, FrameQueue, Route, SharedEcu};
use steering_ecu::units::{Amps, Volts};

/// Simulation step, µs (the current loop's 20 kHz).
pub const STEP_US: u64 = 50;
/// The bridge's DC supply, V (Table 2: 24 V).
pub const SUPPLY_V: f64 = 24.0;
/// Frame time on the bus, µs (8 bytes at 1 Mbit/s, about 130 bit times).
pub const BUS_LATENCY_US: u64 = 130;
/// Wall-clock time of the simulation's t = 0 in its recordings, s since the Unix epoch: a fixed,
/// recognisable origin, so recordings of the simulation repeat byte for byte.
pub const EPOCH_S: f64 = 1_700_000_000.0;
/// The EPOS4's node on the simulated bus (the firmware's default).
pub const EPOS_NODE: u8 = 1;

/// One simulated ECU per process at a time (the mock clock is global).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Which firmware build the simulated car runs (the firmware's `drive-epos4` / `drive-direct`
/// features).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SimDrive {
    /// The default build: the ECU commands the EPOS4 over CANopen (CSP, SYNC, PDOs).
    #[default]
    Epos4,
    /// The ECU's own three-phase bridge.
    Direct,
}

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

/// The direct-drive car's plant: the linear one of eqs. 1-8, or with effects the effect plant.
#[derive(Debug)]
enum CarPlant {
    Linear(Box<LinearPlant>),
    Effects(Box<EffectPlant>),
}

impl CarPlant {
    fn new(effects: PlantEffects, dt: f64) -> CarPlant {
        if effects.is_none() {
            CarPlant::Linear(Box::new(
                LinearPlant::new(PlantParams::PAPER, dt).expect("the paper plant discretises"),
            ))
        } else {
            CarPlant::Effects(Box::new(
                EffectPlant::new(PlantParams::PAPER, effects, dt)
                    .expect("the paper plant discretises"),
            ))
        }
    }

    fn get(&mut self) -> &mut dyn Actuator {
        match self {
            CarPlant::Linear(p) => p.as_mut(),
            CarPlant::Effects(p) => p.as_mut(),
        }
    }
}

impl Actuator for CarPlant {
    fn step(&mut self, voltage_v: f64) {
        self.get().step(voltage_v)
    }
    fn current_a(&self) -> f64 {
        match self {
            CarPlant::Linear(p) => p.current_a(),
            CarPlant::Effects(p) => p.current_a(),
        }
    }
    fn motor_rad(&self) -> f64 {
        match self {
            CarPlant::Linear(p) => p.motor_rad(),
            CarPlant::Effects(p) => p.motor_rad(),
        }
    }
    fn motor_speed_rad_s(&self) -> f64 {
        match self {
            CarPlant::Linear(p) => p.motor_speed_rad_s(),
            CarPlant::Effects(p) => p.motor_speed_rad_s(),
        }
    }
    fn column_rad(&self) -> f64 {
        match self {
            CarPlant::Linear(p) => p.column_rad(),
            CarPlant::Effects(p) => p.column_rad(),
        }
    }
    fn set_at_rest(&mut self, column_rad: f64) {
        self.get().set_at_rest(column_rad)
    }
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
                    let ms: f64 = v
                        .trim()
                        .parse()
                        .map_err(|_| format!("reference_delay_ms={v}: not a number"))?;
                    if !(0.0..=200.0).contains(&ms) {
                        return Err(format!("reference_delay_ms={v}: must be within 0..=200"));
                    }
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

/// The ECU as the firmware's EPOS4 build makes it at start-up (`main.rs`, [`Ecu::build`]),
/// with the EPOS4 at [`EPOS_NODE`]: the link with the paper's settings (ECU mode writes its
/// own feedforward gains over them). Also those settings, for the simulated drive's scale.
pub fn epos4_ecu(controller: ControllerKind, now_us: u64) -> Option<(Ecu, Epos4Config)> {
    let config = Epos4Config::paper(NodeId::new(EPOS_NODE)?);
    let ecu = Ecu::build(
        EcuBuild::new(controller, DriveChoice::Epos4(config)),
        now_us,
    )?;
    Some((ecu, config))
}

/// Hands a frame the ECU received to the task that consumes it, as the firmware's receive
/// task does ([`FirmwareRoutes`]: consumer 0 the reference task, 1 the EPOS4 link); a full
/// queue drops the frame, as on the chip. Frames for no consumer are dropped.
pub fn route_to_ecu(frame: Frame, reference: &FrameQueue, drive: &FrameQueue) {
    let queue = match FirmwareRoutes.route(&frame) {
        Some(0) => reference,
        Some(_) => drive,
        None => return,
    };
    let _ = queue.try_send(frame);
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

#[derive(Debug)]
struct EncoderState {
    column_rad: Cell<f64>,
    broken: Cell<bool>,
}

struct SimEncoder(Rc<EncoderState>);

impl ColumnEncoderPort for SimEncoder {
    async fn read(&mut self) -> Result<u16, EncoderError> {
        if self.0.broken.get() {
            return Err(EncoderError::NoResponse);
        }
        Ok(ColumnEncoder { zero_raw: 0 }.raw_from_angle(self.0.column_rad.get()))
    }
}

/// The Hall sensors as the fast loop reads them: the code of the motor's true sector.
struct SimHall(u8);
impl HallInputs for SimHall {
    fn read(&mut self) -> u8 {
        self.0
    }
}

/// The phase currents as the ADC reads them.
struct SimSense([Amps; 3]);
impl CurrentSense for SimSense {
    fn phase_currents(&mut self) -> [Amps; 3] {
        self.0
    }
}

/// The bridge: keeps the command for the plant's terminal voltage.
struct SimBridge(BridgeCommand);
impl Bridge for SimBridge {
    fn apply(&mut self, command: &BridgeCommand) {
        self.0 = *command;
    }
}

/// One 50 us PWM period of the direct drive on the paper's actuator, as the firmware's ADC
/// interrupt runs it (`steering_ecu::direct::FastLoop::run`): the Hall code of the motor's
/// sector and the phase currents (the winding current in the pair the sector drives, plus
/// `current_offset_a` of sense error) from the plant, then the bridge command back to a
/// terminal voltage for one plant step. With the bridge off the winding is left to its
/// back-EMF and the current dies out.
pub fn direct_drive_period(
    plant: &mut impl Actuator,
    fast: &mut FastLoop,
    ecu: &SharedEcu,
    now_us: u64,
    current_offset_a: f64,
) {
    direct_drive_period_sensed(plant, fast, ecu, now_us, |i| i + current_offset_a);
}

/// [`direct_drive_period`] with any current-sense error: `sense` maps the winding's true
/// current to what the phase-current ADC reads (an offset, a flipped sign, a wrong gain).
pub fn direct_drive_period_sensed(
    plant: &mut impl Actuator,
    fast: &mut FastLoop,
    ecu: &SharedEcu,
    now_us: u64,
    sense: impl Fn(f64) -> f64,
) {
    let sector = hall_from_motor(plant.motor_rad()).rem_euclid(6) as u8;
    let mut truth = HallDecoder::new(0);
    let _ = truth.update(code_of(sector));
    let mut phases = [Amps::ZERO; 3];
    if let Some((high, low)) = truth.driven_legs() {
        let measured = sense(plant.current_a()) as f32;
        phases[high] = Amps(measured);
        phases[low] = Amps(-measured);
    }
    let mut bridge = SimBridge(BRIDGE_OFF);
    ecu.lock(|e| {
        fast.run(
            &mut e.borrow_mut(),
            now_us,
            &mut SimHall(code_of(sector)),
            &mut SimSense(phases),
            &mut bridge,
        )
    });
    let v = match truth.terminal_voltage(&bridge.0, SUPPLY_V as f32) {
        Some(v) => f64::from(v),
        None => PlantParams::PAPER.ke * plant.motor_speed_rad_s(),
    };
    plant.step(v);
}

type Task = Pin<Box<dyn Future<Output = ()>>>;

/// A scripted vehicle computer ([`SimEcu::script_vehicle`]).
struct Vehicle {
    port: Port,
    script: VecDeque<(AsState, f64)>,
    sender: ReferenceSender,
    next_us: u64,
}

/// The simulated ECU, its actuator, the EPOS4 and the bus.
pub struct SimEcu {
    ecu: &'static SharedEcu,
    reference_frames: &'static FrameQueue,
    drive_frames: &'static FrameQueue,
    tx_frames: &'static FrameQueue,
    tasks: Vec<Task>,
    drive: SimDrive,
    encoder: Rc<EncoderState>,
    bus: CanBus,
    ecu_port: Port,
    epos_port: Port,
    host_port: Port,
    vehicle: Option<Vehicle>,
    /// The reference counter of the ECU's last motor frame on the bus (`MOT_RefCounter`): a
    /// scripted vehicle continues after it, as a vehicle computer that listens before its
    /// first frame does.
    ecu_reference_counter: AliveCounter,
    plant: CarPlant,
    /// Reference frames held back from the ECU (`reference_delay_ms`), with when they are due.
    delayed_references: VecDeque<(u64, Frame)>,
    reference_delay_us: u64,
    fast: FastLoop,
    epos: Epos4Sim,
    now_us: u64,
    inbox: VecDeque<Stamped>,
    current_offset: f64,
    scheduled: Vec<(u64, Injection)>,
    _one_at_a_time: MutexGuard<'static, ()>,
}

impl std::fmt::Debug for SimEcu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SimEcu")
            .field("now_us", &self.now_us)
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
        let guard = ONE_AT_A_TIME
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        MockDriver::get().reset();
        let node = NodeId::new(EPOS_NODE).expect("node 1 is valid");
        let (ecu, config) = match car.drive {
            SimDrive::Direct => Ecu::build(EcuBuild::new(car.controller, DriveChoice::Direct), 0)
                .map(|e| (e, Epos4Config::paper(node))),
            SimDrive::Epos4 => epos4_ecu(car.controller, 0),
        }
        .expect("the paper configuration is valid");
        // Leaked: the task futures borrow them for 'static, like the firmware's statics.
        let ecu: &'static SharedEcu =
            Box::leak(Box::new(SharedEcu::new(std::cell::RefCell::new(ecu))));
        let reference_frames: &'static FrameQueue = Box::leak(Box::new(FrameQueue::new()));
        let drive_frames: &'static FrameQueue = Box::leak(Box::new(FrameQueue::new()));
        let tx_frames: &'static FrameQueue = Box::leak(Box::new(FrameQueue::new()));
        let encoder = Rc::new(EncoderState {
            column_rad: Cell::new(column_rad),
            broken: Cell::new(false),
        });
        let port: &'static mut SimEncoder = Box::leak(Box::new(SimEncoder(encoder.clone())));
        let mut tasks: Vec<Task> = vec![
            Box::pin(async move {
                tasks::reference_task(reference_frames.receiver(), ecu).await;
            }),
            Box::pin(async move {
                tasks::status_task(tx_frames.sender(), ecu).await;
            }),
            Box::pin(async move {
                tasks::encoder_task(port, ColumnEncoder { zero_raw: 0 }, ecu).await;
            }),
        ];
        if car.drive == SimDrive::Epos4 {
            tasks.push(Box::pin(async move {
                tasks::drive_task(drive_frames.receiver(), tx_frames.sender(), ecu).await;
            }));
        }
        let mut bus = CanBus::new(1, BUS_LATENCY_US);
        let ecu_port = bus.attach();
        let epos_port = bus.attach();
        let host_port = bus.attach();
        let scale = PositionScale::new(config.counts_per_rev).expect("84 inc/rev");
        let mut epos = Epos4Sim::new_at_with(node, scale, column_rad, car.effects.plant)
            .expect("the paper plant discretises");
        for frame in epos.advance(0) {
            bus.send(epos_port, frame, 0);
        }
        let mut plant = CarPlant::new(car.effects.plant, STEP_US as f64 * 1e-6);
        plant.set_at_rest(column_rad);
        SimEcu {
            ecu,
            reference_frames,
            drive_frames,
            tx_frames,
            tasks,
            drive: car.drive,
            encoder,
            bus,
            ecu_port,
            epos_port,
            host_port,
            vehicle: None,
            ecu_reference_counter: AliveCounter::default(),
            plant,
            delayed_references: VecDeque::new(),
            reference_delay_us: (car.effects.reference_delay_s * 1e6).round() as u64,
            fast: FastLoop::new(0, Volts(SUPPLY_V as f32)),
            epos,
            now_us: 0,
            inbox: VecDeque::new(),
            current_offset: 0.0,
            scheduled: Vec::new(),
            _one_at_a_time: guard,
        }
    }

    /// Which drive the car runs.
    pub fn drive(&self) -> SimDrive {
        self.drive
    }

    /// A vehicle computer on its own node that sends `script` as its reference frames (AS
    /// state, angle at the wheel in deg), one every 10 ms from the next whole period, and then
    /// falls silent (end the script in AS Off, or the ECU sees a reference timeout). For
    /// `steer-can record`, which on the car records while someone else steers. Replaces an
    /// earlier script.
    pub fn script_vehicle(&mut self, script: Vec<(AsState, f64)>) {
        let port = match &self.vehicle {
            Some(v) => v.port,
            None => self.bus.attach(),
        };
        let period = u64::from(PERIOD_US);
        let mut sender = ReferenceSender::default();
        sender.continue_after(self.ecu_reference_counter);
        self.vehicle = Some(Vehicle {
            port,
            script: script.into(),
            sender,
            next_us: self.now_us.div_ceil(period) * period,
        });
    }

    /// The ECU's last output (demand, state, faults).
    pub fn output(&self) -> Output {
        self.ecu.lock(|e| e.borrow().output())
    }

    /// Read or change the ECU directly (tests).
    pub fn with_ecu<R>(&self, f: impl FnOnce(&mut Ecu) -> R) -> R {
        self.ecu.lock(|e| f(&mut e.borrow_mut()))
    }

    pub fn epos(&self) -> &Epos4Sim {
        &self.epos
    }

    pub fn epos_mut(&mut self) -> &mut Epos4Sim {
        &mut self.epos
    }

    pub fn bus_mut(&mut self) -> &mut CanBus {
        &mut self.bus
    }

    /// Column angle of the simulated actuator, deg at the wheel.
    pub fn column_deg(&self) -> f64 {
        self.column_rad().to_degrees()
    }

    fn column_rad(&self) -> f64 {
        match self.drive {
            SimDrive::Epos4 => self.epos.column_rad(),
            SimDrive::Direct => self.plant.column_rad(),
        }
    }

    /// Motor current of the simulated actuator, A.
    pub fn current_a(&self) -> f64 {
        match self.drive {
            SimDrive::Epos4 => self.epos.current_a(),
            SimDrive::Direct => self.plant.current_a(),
        }
    }

    /// Whether `injection` has an effect on this car: a current-sense offset needs the ECU's
    /// own current sensing (direct drive).
    pub fn can_inject(&self, injection: Injection) -> bool {
        !matches!(
            (injection, self.drive),
            (Injection::CurrentOffset(_), SimDrive::Epos4)
        )
    }

    /// Apply `injection` now (one [`SimEcu::can_inject`] refuses has no effect).
    pub fn inject(&mut self, injection: Injection) {
        match injection {
            Injection::EncoderNoResponse => self.encoder.broken.set(true),
            Injection::CurrentOffset(a) => self.current_offset = a,
            Injection::EposFault(code) => self.epos.inject_fault(code),
        }
    }

    /// Apply `injection` when the virtual clock reaches `at_us`.
    pub fn inject_at(&mut self, at_us: u64, injection: Injection) {
        self.scheduled.push((at_us, injection));
    }

    /// Run until `t_us` (frames for the host go to its inbox).
    pub fn run_until(&mut self, t_us: u64) {
        while self.now_us < t_us {
            self.step();
        }
    }

    fn step(&mut self) {
        let now = self.now_us;
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
        // A hidden reference delay: the vehicle's frames reach the ECU's reference task late.
        while self
            .delayed_references
            .front()
            .is_some_and(|(due, _)| *due <= now)
        {
            if let Some((_, frame)) = self.delayed_references.pop_front() {
                route_to_ecu(frame, self.reference_frames, self.drive_frames);
            }
        }
        for (port, frame) in self.bus.deliver(now) {
            if port == self.ecu_port {
                if self.reference_delay_us > 0 && FirmwareRoutes.route(&frame) == Some(0) {
                    self.delayed_references
                        .push_back((now + self.reference_delay_us, frame));
                    continue;
                }
                // Direct drive has no EPOS4 link task: its queue stays empty-handed, as the
                // firmware built for direct drive routes to a link it does not run.
                route_to_ecu(frame, self.reference_frames, self.drive_frames);
                if self.drive == SimDrive::Direct {
                    while self.drive_frames.try_receive().is_ok() {}
                }
            } else if port == self.epos_port {
                for answer in self.epos.on_frame(&frame) {
                    self.bus.send(self.epos_port, answer, now);
                }
            } else if port == self.host_port {
                self.inbox.push_back(Stamped { t_us: now, frame });
            }
        }
        if let Some(v) = &mut self.vehicle
            && now >= v.next_us
            && let Some((as_state, deg)) = v.script.pop_front()
        {
            let frame = v.sender.frame(deg, as_state, false);
            self.bus.send(v.port, frame, now);
            v.next_us += u64::from(PERIOD_US);
        }
        let mut cx = Context::from_waker(Waker::noop());
        for task in &mut self.tasks {
            let _ = task.as_mut().poll(&mut cx);
        }
        while let Ok(frame) = self.tx_frames.try_receive() {
            if let Ok(motor) = ProtocolConfig::DEFAULT.decode_motor(&frame) {
                self.ecu_reference_counter = motor.reference_counter;
            }
            self.bus.send(self.ecu_port, frame, now);
        }
        for frame in self.epos.advance(now) {
            self.bus.send(self.epos_port, frame, now);
        }
        if self.drive == SimDrive::Direct {
            direct_drive_period(
                &mut self.plant,
                &mut self.fast,
                self.ecu,
                now,
                self.current_offset,
            );
        }
        self.encoder.column_rad.set(self.column_rad());
        MockDriver::get().advance(Duration::from_micros(STEP_US));
        self.now_us += STEP_US;
    }
}

impl Clock for SimEcu {
    fn now_us(&self) -> u64 {
        self.now_us
    }
}

impl Transport for SimEcu {
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError> {
        self.bus.send(self.host_port, *frame, self.now_us);
        Ok(())
    }

    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
        loop {
            if let Some(rx) = self.inbox.pop_front() {
                return Ok(Some(rx));
            }
            if self.now_us >= deadline_us {
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

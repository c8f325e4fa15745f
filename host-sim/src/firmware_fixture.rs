//! The firmware's tasks in virtual time: one fixture for the simulated car (`crate::sim_ecu`)
//! and for the host tests that drive the tasks (`tests/firmware_tasks.rs`,
//! `tests/epos4_tasks.rs`). It builds the ECU as `main.rs` does ([`Ecu::build`]), runs the
//! same task functions the STM32 runs (`steering_ecu::tasks`: reference receiver, status
//! sender, encoder reader, in EPOS4 mode the EPOS4 link, optionally the watchdog), holds the
//! drive (the simulated EPOS4 on its own plant, or the direct drive's fast loop on the
//! fixture's plant), the in-memory CAN bus and the mock clock, and offers one 50 µs step's
//! phases as methods:
//!
//! ```text
//!  deliver      the bus's due frames: ECU port -> routed to the reference / drive queue
//!               (`FirmwareRoutes`), EPOS4 port -> Epos4Sim::on_frame, answers sent;
//!               frames for other ports handed back
//!  poll_tasks   every task polled once (a no-op waker: polling costs nothing at this rate,
//!               and the caller keeps control between steps instead of embassy's run_until)
//!  tx_to_bus    the ECU's transmit queue onto the bus (or `take_tx` for a test's own log)
//!  advance_epos the EPOS4's own period: heartbeat, PDOs, its loops on its plant
//!  fast_loop    direct drive: one PWM period (Hall code, phase currents -> bridge -> plant)
//!  end_step     the encoder reads the column; the mock clock += 50 µs
//! ```
//!
//! The caller strings the phases together. The simulated car delivers the bus before the
//! tasks run; the task tests poll first and deliver after the drive's period. Those orders
//! are each test's own timing (when a frame is seen, the order of the lossy bus's random
//! draws), and the tests' figures were measured on them, so the fixture keeps both rather
//! than choosing one.
//!
//! The mock clock is global to the process, so one fixture lives at a time: `new` waits for
//! the previous one to be dropped.

use crate::effect_plant::{EffectPlant, PlantEffects};
use crate::epos4_sim::Epos4Sim;
use crate::plant::{Actuator, LinearPlant, PlantParams};
use canlink::canbus::{CanBus, Port, RandomFaults};
use embassy_time::{Duration, Instant, MockDriver};
use std::cell::{Cell, RefCell};
use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;
use std::rc::Rc;
use std::sync::{Mutex, MutexGuard};
use std::task::{Context, Waker};
use steering_ecu::can::Frame;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::epos4::{Epos4Config, PositionScale};
use steering_ecu::commutation::{BRIDGE_OFF, BridgeCommand, HallDecoder, code_of};
use steering_ecu::controller::ControllerKind;
use steering_ecu::direct::FastLoop;
use steering_ecu::ecu::{DriveChoice, Ecu, EcuBuild};
use steering_ecu::ports::{Bridge, ColumnEncoderPort, CurrentSense, EncoderError, HallInputs};
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
/// The EPOS4's node on the simulated bus (the firmware's default).
pub const EPOS_NODE: u8 = 1;

/// One fixture per process at a time (the mock clock is global).
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Holds the process's mock clock without a fixture, for a test that reads the clock (a task
/// run with `block_on`) while fixtures may run in other threads.
pub fn hold_clock() -> MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(|poisoned| poisoned.into_inner())
}

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

/// The ECU the firmware builds for `drive` at `now_us`.
fn build_ecu(controller: ControllerKind, drive: SimDrive, now_us: u64) -> Option<Ecu> {
    match drive {
        SimDrive::Direct => Ecu::build(EcuBuild::new(controller, DriveChoice::Direct), now_us),
        SimDrive::Epos4 => epos4_ecu(controller, now_us).map(|(ecu, _)| ecu),
    }
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

/// The direct drive's plant: the linear one of eqs. 1-8, or the effect plant.
#[derive(Debug)]
pub enum CarPlant {
    Linear(Box<LinearPlant>),
    Effects(Box<EffectPlant>),
}

impl CarPlant {
    /// The simulated car's plant: the linear one without effects, else the effect plant.
    pub fn new(effects: PlantEffects, dt: f64) -> CarPlant {
        if effects.is_none() {
            CarPlant::Linear(Box::new(
                LinearPlant::new(PlantParams::PAPER, dt).expect("the paper plant discretises"),
            ))
        } else {
            CarPlant::with_effects(effects, dt)
        }
    }

    /// The effect plant, also with no effects (the task tests' plant).
    pub fn with_effects(effects: PlantEffects, dt: f64) -> CarPlant {
        CarPlant::Effects(Box::new(
            EffectPlant::new(PlantParams::PAPER, effects, dt).expect("the paper plant discretises"),
        ))
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

/// What the column encoder answers besides the column's angle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum EncoderFault {
    #[default]
    None,
    /// It does not answer (SPI timeout).
    Silent,
    /// It reads this much more than the column, deg (a slipping coupling).
    OffsetDeg(f64),
}

/// What the phase-current ADC reads of the winding's current (direct drive).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub enum SenseFault {
    #[default]
    None,
    /// This many amps more than flows (an amplifier offset, a short).
    BiasA(f64),
    /// The wrong sign (swapped shunt wires).
    SignFlipped,
}

impl SenseFault {
    fn read(self, winding_a: f64) -> f64 {
        match self {
            SenseFault::None => winding_a,
            SenseFault::BiasA(a) => winding_a + a,
            SenseFault::SignFlipped => -winding_a,
        }
    }
}

#[derive(Debug)]
struct EncoderState {
    column_rad: Cell<f64>,
    fault: Cell<EncoderFault>,
}

struct SimEncoder(Rc<EncoderState>);

impl ColumnEncoderPort for SimEncoder {
    async fn read(&mut self) -> Result<u16, EncoderError> {
        let rad = self.0.column_rad.get();
        match self.0.fault.get() {
            EncoderFault::Silent => Err(EncoderError::NoResponse),
            EncoderFault::OffsetDeg(d) => {
                Ok(ColumnEncoder { zero_raw: 0 }.raw_from_angle(rad + d.to_radians()))
            }
            EncoderFault::None => Ok(ColumnEncoder { zero_raw: 0 }.raw_from_angle(rad)),
        }
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

/// How a fixture is built.
#[derive(Debug)]
pub struct FixtureBuild {
    pub controller: ControllerKind,
    pub drive: SimDrive,
    /// The column at power-up, rad (the actuator and the EPOS4's plant at rest there; the Hall
    /// count and the EPOS4's position start at 0 wherever the motor stands).
    pub column_rad: f64,
    /// The simulated EPOS4's plant's effects.
    pub epos4_effects: PlantEffects,
    /// The direct drive's plant (set at rest at `column_rad` by the fixture).
    pub direct_plant: CarPlant,
    /// The bus's random faults (from its first frame, the EPOS4's boot-up) and their seed.
    pub bus_faults: RandomFaults,
    pub bus_seed: u64,
    /// Whether the watchdog task runs (its feeds are logged: [`FirmwareFixture::feeds_us`]).
    pub watchdog: bool,
    /// A delay between a reference frame reaching the ECU and the reference task getting it,
    /// µs (a hidden effect of the simulated car).
    pub reference_delay_us: u64,
}

/// The firmware's ECU and tasks, the drive, the bus and the clock of one simulation.
pub struct FirmwareFixture {
    ecu: &'static SharedEcu,
    reference_frames: &'static FrameQueue,
    drive_frames: &'static FrameQueue,
    tx_frames: &'static FrameQueue,
    tasks: Vec<Task>,
    controller: ControllerKind,
    drive: SimDrive,
    watchdog: bool,
    encoder: Rc<EncoderState>,
    feeds_us: Rc<RefCell<Vec<u64>>>,
    bus: CanBus,
    ecu_port: Port,
    epos_port: Port,
    plant: CarPlant,
    fast: FastLoop,
    sense: SenseFault,
    fast_loop_running: bool,
    epos: Epos4Sim,
    /// Reference frames held back from the ECU (`reference_delay_us`), with when they are due.
    delayed_references: VecDeque<(u64, Frame)>,
    reference_delay_us: u64,
    now_us: u64,
    _one_at_a_time: MutexGuard<'static, ()>,
}

impl std::fmt::Debug for FirmwareFixture {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("FirmwareFixture")
            .field("now_us", &self.now_us)
            .field("drive", &self.drive)
            .finish_non_exhaustive()
    }
}

impl FirmwareFixture {
    /// The fixture `build` describes, at t = 0, the mock clock reset; the EPOS4's boot-up
    /// message is on the bus first, as it boots before the ECU's link starts. Waits while
    /// another fixture of this process is alive.
    pub fn new(build: FixtureBuild) -> FirmwareFixture {
        let guard = hold_clock();
        MockDriver::get().reset();
        let node = NodeId::new(EPOS_NODE).expect("node 1 is valid");
        let config = Epos4Config::paper(node);
        let mut bus = CanBus::new(build.bus_seed, BUS_LATENCY_US);
        let ecu_port = bus.attach();
        let epos_port = bus.attach();
        bus.set_random_faults(build.bus_faults);
        let scale = PositionScale::new(config.counts_per_rev).expect("84 inc/rev");
        let mut epos = Epos4Sim::new_at_with(node, scale, build.column_rad, build.epos4_effects)
            .expect("the paper plant discretises");
        for frame in epos.advance(0) {
            bus.send(epos_port, frame, 0);
        }
        let mut plant = build.direct_plant;
        plant.set_at_rest(build.column_rad);
        let encoder = Rc::new(EncoderState {
            column_rad: Cell::new(0.0),
            fault: Cell::new(EncoderFault::None),
        });
        // Leaked: the task futures borrow it for 'static, like the firmware's statics.
        let ecu: &'static SharedEcu = Box::leak(Box::new(SharedEcu::new(RefCell::new(
            build_ecu(build.controller, build.drive, 0).expect("the paper configuration is valid"),
        ))));
        let mut fixture = FirmwareFixture {
            ecu,
            reference_frames: Box::leak(Box::new(FrameQueue::new())),
            drive_frames: Box::leak(Box::new(FrameQueue::new())),
            tx_frames: Box::leak(Box::new(FrameQueue::new())),
            tasks: Vec::new(),
            controller: build.controller,
            drive: build.drive,
            watchdog: build.watchdog,
            encoder,
            feeds_us: Rc::new(RefCell::new(Vec::new())),
            bus,
            ecu_port,
            epos_port,
            plant,
            fast: FastLoop::new(0, Volts(SUPPLY_V as f32)),
            sense: SenseFault::None,
            fast_loop_running: true,
            epos,
            delayed_references: VecDeque::new(),
            reference_delay_us: build.reference_delay_us,
            now_us: 0,
            _one_at_a_time: guard,
        };
        fixture.spawn_tasks();
        fixture.encoder.column_rad.set(fixture.column_rad());
        fixture
    }

    /// The firmware's tasks on the current ECU (the order they are polled in each step).
    fn spawn_tasks(&mut self) {
        let (ecu, reference_frames, drive_frames, tx_frames) = (
            self.ecu,
            self.reference_frames,
            self.drive_frames,
            self.tx_frames,
        );
        // Leaked: the task futures borrow it for 'static, like the firmware's statics.
        let port: &'static mut SimEncoder = Box::leak(Box::new(SimEncoder(self.encoder.clone())));
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
        if self.drive == SimDrive::Epos4 {
            tasks.push(Box::pin(async move {
                tasks::drive_task(drive_frames.receiver(), tx_frames.sender(), ecu).await;
            }));
        }
        if self.watchdog {
            let feeds = self.feeds_us.clone();
            tasks.push(Box::pin(async move {
                tasks::watchdog_task(ecu, || {
                    feeds.borrow_mut().push(Instant::now().as_micros());
                })
                .await;
            }));
        }
        self.tasks = tasks;
    }

    /// The ECU resets without a panic (an IWDG reset, a brown-out) at this instant: its tasks
    /// stop where they are, what it had queued is lost, and a fresh ECU starts with fresh
    /// tasks; the drive and the bus run on.
    pub fn reset_ecu(&mut self) {
        while self.tx_frames.try_receive().is_ok() {}
        while self.reference_frames.try_receive().is_ok() {}
        while self.drive_frames.try_receive().is_ok() {}
        let ecu = build_ecu(self.controller, self.drive, self.now_us)
            .expect("the paper configuration is valid");
        self.ecu = Box::leak(Box::new(SharedEcu::new(RefCell::new(ecu))));
        self.spawn_tasks();
    }

    pub fn now_us(&self) -> u64 {
        self.now_us
    }

    pub fn drive(&self) -> SimDrive {
        self.drive
    }

    pub fn controller(&self) -> ControllerKind {
        self.controller
    }

    /// The ECU the tasks share (for a direct call such as the fast loop's).
    pub fn shared_ecu(&self) -> &'static SharedEcu {
        self.ecu
    }

    /// The ECU's last output (demand, state, faults).
    pub fn output(&self) -> Output {
        self.ecu.lock(|e| e.borrow().output())
    }

    /// Read or change the ECU directly.
    pub fn with_ecu<R>(&self, f: impl FnOnce(&mut Ecu) -> R) -> R {
        self.ecu.lock(|e| f(&mut e.borrow_mut()))
    }

    pub fn epos(&self) -> &Epos4Sim {
        &self.epos
    }

    pub fn epos_mut(&mut self) -> &mut Epos4Sim {
        &mut self.epos
    }

    pub fn bus(&self) -> &CanBus {
        &self.bus
    }

    pub fn bus_mut(&mut self) -> &mut CanBus {
        &mut self.bus
    }

    /// The simulated EPOS4's port on the bus.
    pub fn epos_port(&self) -> Port {
        self.epos_port
    }

    /// The ECU's port on the bus.
    pub fn ecu_port(&self) -> Port {
        self.ecu_port
    }

    /// Column angle of the simulated actuator, rad at the wheel.
    pub fn column_rad(&self) -> f64 {
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

    pub fn set_encoder_fault(&mut self, fault: EncoderFault) {
        self.encoder.fault.set(fault);
    }

    pub fn set_sense_fault(&mut self, fault: SenseFault) {
        self.sense = fault;
    }

    /// Stops or restarts the direct drive's fast-loop interrupt (the ADC trigger lost).
    pub fn set_fast_loop_running(&mut self, running: bool) {
        self.fast_loop_running = running;
    }

    /// When the watchdog task fed the watchdog, µs (with [`FixtureBuild::watchdog`]).
    pub fn feeds_us(&self) -> Vec<u64> {
        self.feeds_us.borrow().clone()
    }

    /// A frame for the ECU, straight into its receive routing (no bus).
    pub fn to_ecu(&mut self, frame: Frame) {
        route_to_ecu(frame, self.reference_frames, self.drive_frames);
    }

    /// Phase: the bus's frames due now. Frames for the ECU go to its tasks' queues (late by
    /// the reference delay if there is one; in direct drive the EPOS4 link's queue is emptied,
    /// as the direct-drive firmware routes to a link it does not run), frames for the EPOS4
    /// to it, its answers onto the bus; frames for other ports are returned.
    pub fn deliver(&mut self) -> Vec<(Port, Frame)> {
        let now = self.now_us;
        while self
            .delayed_references
            .front()
            .is_some_and(|(due, _)| *due <= now)
        {
            if let Some((_, frame)) = self.delayed_references.pop_front() {
                route_to_ecu(frame, self.reference_frames, self.drive_frames);
            }
        }
        let mut others = Vec::new();
        for (port, frame) in self.bus.deliver(now) {
            if port == self.ecu_port {
                if self.reference_delay_us > 0 && FirmwareRoutes.route(&frame) == Some(0) {
                    self.delayed_references
                        .push_back((now + self.reference_delay_us, frame));
                    continue;
                }
                route_to_ecu(frame, self.reference_frames, self.drive_frames);
                if self.drive == SimDrive::Direct {
                    while self.drive_frames.try_receive().is_ok() {}
                }
            } else if port == self.epos_port {
                for answer in self.epos.on_frame(&frame) {
                    self.bus.send(self.epos_port, answer, now);
                }
            } else {
                others.push((port, frame));
            }
        }
        others
    }

    /// Phase: every task polled once.
    pub fn poll_tasks(&mut self) {
        let mut cx = Context::from_waker(Waker::noop());
        for task in &mut self.tasks {
            let _ = task.as_mut().poll(&mut cx);
        }
    }

    /// Phase: the ECU's transmit queue onto the bus; how many frames it sent.
    pub fn tx_to_bus(&mut self) -> usize {
        let mut n = 0;
        while let Ok(frame) = self.tx_frames.try_receive() {
            self.bus.send(self.ecu_port, frame, self.now_us);
            n += 1;
        }
        n
    }

    /// Phase (instead of [`FirmwareFixture::tx_to_bus`]): the ECU's transmit queue, taken off.
    pub fn take_tx(&mut self) -> Vec<Frame> {
        let mut frames = Vec::new();
        while let Ok(frame) = self.tx_frames.try_receive() {
            frames.push(frame);
        }
        frames
    }

    /// Phase: the EPOS4's own period (heartbeat, PDOs, its loops on its plant), its frames
    /// onto the bus.
    pub fn advance_epos(&mut self) {
        for frame in self.epos.advance(self.now_us) {
            self.bus.send(self.epos_port, frame, self.now_us);
        }
    }

    /// Phase, direct drive only: one period of the fast loop on the plant (unless stopped).
    pub fn fast_loop(&mut self) {
        if self.drive == SimDrive::Direct && self.fast_loop_running {
            let sense = self.sense;
            direct_drive_period_sensed(
                &mut self.plant,
                &mut self.fast,
                self.ecu,
                self.now_us,
                |i| sense.read(i),
            );
        }
    }

    /// Phase, last of a step: the encoder reads the column; the mock clock += 50 µs.
    pub fn end_step(&mut self) {
        self.encoder.column_rad.set(self.column_rad());
        MockDriver::get().advance(Duration::from_micros(STEP_US));
        self.now_us += STEP_US;
    }
}

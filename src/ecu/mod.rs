//! The ECU in one piece of pure logic: the reference frames through the E2E check into the
//! steering state machine, whose demand gates the cascade, and the status frame back. The
//! firmware's tasks and interrupts call these methods (under a critical-section mutex);
//! host-sim calls the same ones from its tasks in virtual time.
//!
//! Two drive modes ([`Drive`]):
//!
//! **Direct**: the ECU runs the cascade itself. The demand decides what the fast loops may do:
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
//!
//! **EPOS4** (the paper's car): the drive runs the loops in cyclic synchronous position mode;
//! the ECU's [`Epos4Link`] brings it up and sends the target every SYNC. The demand maps onto
//! the drive's power stage:
//!
//! ```text
//! demand    | EPOS4
//! ----------+---------------------------------------------------------------
//! Disabled  | power stage off ("disable voltage"), the target follows the motor
//! Hold      | Operation enabled, target = the last reference sample
//! Track     | Operation enabled, target = each new reference sample (motor inc)
//! ```
//!
//! The link's frames come back from [`Ecu::drive_poll`] and [`Ecu::on_drive_frame`], and a
//! demand change made anywhere else (a timeout seen by [`Ecu::tick`], an encoder fault) leaves
//! its frame in a small queue that the next of those two calls returns; the drive task calls
//! `drive_poll` every millisecond, so a disable is on the bus within 1 ms. Link failures latch
//! faults: heartbeat lost or TPDOs missing -> `HeartbeatLost`, anything else (EMCY, statusword
//! fault, SDO abort or time-out, gain read-back mismatch) -> `EposFault` with the code of
//! [`link_fault_code`]. A failed link is reset automatically once a second while the vehicle
//! reports AS Off (the driver steers, nothing is powered); when it is back in Standby the
//! cause is gone and the clear request in AS Off clears the latched fault.

mod drive;

use drive::PENDING_DEPTH;
pub use drive::{DirectDrive, Drive, Epos4Drive};

use crate::as_state::AsState;
use crate::can::Frame;
use crate::canopen::epos4::{Epos4Config, Epos4Link, LinkError, Outbox};
use crate::controller::ControllerKind;
use crate::ecu_mode::{ColumnCascade, ColumnShaper, EcuTuning};
use crate::enable_ramp::EnableRamp;
use crate::gains::EposGains;
use crate::gearing::Gearing;
use crate::paper_mode::Cascade;
use crate::protocol::{AliveCounter, E2eChecker, E2eVerdict, MotorStatus, ProtocolConfig, Status};
use crate::steering::{Config, DriveDemand, EcuState, Output, SteeringStateMachine};
use crate::units::{Amps, MotorRad, SteeringDeg, SteeringRad, Volts};

/// What one drive call puts on the bus: the pending demand-change frames and the link's.
pub type DriveFrames = heapless::Vec<Frame, { PENDING_DEPTH + 4 }>;

/// After every enable the reference given to the drive starts at the measured column, at
/// rest, and moves toward the vehicle's reference with limited acceleration at most this
/// fast until it meets it ([`crate::enable_ramp`]).
pub use crate::enable_ramp::ENABLE_RAMP_DPS;

/// The motor origin is taken at every enable from the column samples of this window, us
/// (the encoder task's 500 Hz gives 8), and only if each is within [`ORIGIN_AGREEMENT_COUNTS`]
/// column-encoder counts (plus one motor count) of their median: one glitched sample before
/// the enabling frame (1.5 deg passes the jump check) must not become an offset of the
/// wheels for the whole run.
pub const ORIGIN_WINDOW_US: u64 = 16_000;
/// See [`ORIGIN_WINDOW_US`]: one count of the 12-bit column encoder, its quantisation.
pub const ORIGIN_AGREEMENT_COUNTS: f32 = 1.0;
/// Origin candidates kept: the window's samples at 500 Hz.
const ORIGIN_SAMPLES: usize = 8;

/// The running cross-check of the origin: while the drive is on and rests (column and motor
/// each within [`ORIGIN_REST_MOTION_DEG`] of where the rest began, |effort| at most
/// [`ORIGIN_REST_CURRENT`]) for this long, us ...
pub const ORIGIN_REST_US: u64 = 100_000;
/// ... column and motor angle / gear ratio must agree within this, deg at the wheel: the
/// backlash (about 1 deg), the belt's stretch at 2 A (0.49 deg/A: 9.7 deg at 20 A, see the
/// disagreement window in `src/steering/mod.rs`, about 1 deg) and the quantisation (0.1 deg). An
/// origin wrong by more latches `Origin`; the agreement at the enable bounds it far tighter.
pub const ORIGIN_REST_BOUND_DEG: f32 = 2.5;
/// See [`ORIGIN_REST_US`], deg at the wheel.
pub const ORIGIN_REST_MOTION_DEG: f32 = 0.2;
/// See [`ORIGIN_REST_US`].
pub const ORIGIN_REST_CURRENT: Amps = Amps(2.0);

/// Time between automatic resets of a failed EPOS4 link in AS Off, us.
pub const LINK_RESET_INTERVAL_US: u64 = 1_000_000;

/// The code a link failure is latched with (the fault log's detail): the EMCY error code or
/// the statusword where the drive gave one, else 0xFF00 + the kind.
pub fn link_fault_code(error: LinkError) -> u16 {
    match error {
        LinkError::Emcy { error_code, .. } => error_code,
        LinkError::DriveFault { statusword } | LinkError::LeftOperationEnabled { statusword } => {
            statusword
        }
        LinkError::Cia402Stuck { .. } => 0xFF01,
        LinkError::SdoTimeout { .. } => 0xFF02,
        LinkError::SdoAborted { .. } => 0xFF03,
        LinkError::SdoUnexpected { .. } => 0xFF04,
        LinkError::ReadBackMismatch { .. } => 0xFF05,
        LinkError::NodeDidNotStart { .. } => 0xFF06,
        LinkError::NodeLeftOperational { .. } => 0xFF07,
        LinkError::HeartbeatLost { .. } => 0xFF08,
        LinkError::PdoTimeout { .. } => 0xFF09,
    }
}

/// The name of a link failure's own code ([`link_fault_code`]'s 0xFF01..=0xFF09), for tools
/// that show the diagnostic frame's fault records; `None` for a code the drive gave (an EMCY
/// error code or a statusword).
pub fn link_fault_name(code: u16) -> Option<&'static str> {
    Some(match code {
        0xFF01 => "CiA 402 state machine stuck",
        0xFF02 => "SDO timeout",
        0xFF03 => "SDO aborted",
        0xFF04 => "unexpected SDO response",
        0xFF05 => "a limit or gain read back differs from the one written",
        0xFF06 => "node did not start",
        0xFF07 => "node left operational",
        0xFF08 => "heartbeat lost",
        0xFF09 => "PDO timeout",
        _ => return None,
    })
}

#[derive(Debug, Clone)]
pub struct Ecu {
    protocol: ProtocolConfig,
    e2e: E2eChecker,
    machine: SteeringStateMachine,
    drive: Drive,
    gearing: Gearing,
    last: Output,
    status_counter: AliveCounter,
    hall_count: i32,
    column: SteeringDeg,
    current: Amps,
    clear_refusals: u16,
    /// The clear bit of the last valid reference frame: a request is its rising edge.
    clear_bit: bool,
    /// When a task (the supervisor) last called in: see [`Ecu::supervisor_seen_us`].
    supervisor_us: Option<u64>,
    /// Progress counts for the watchdog's feed gate ([`crate::watchdog`]).
    progress: crate::watchdog::Progress,
    /// Bus-off events (saturating).
    bus_offs: u16,
    diagnostic_counter: AliveCounter,
    diagnostic_page: u8,
    /// Pending frames that did not fit (saturating); the link's supervision covers a lost one.
    pending_overflow: u16,
    /// The firmware's stack high-water mark, as it last measured it (`None` off the chip).
    stack: Option<crate::stack::StackUsage>,
    /// The last reference sample the drive was given (wheel deg), for the tracking check.
    reference: Option<SteeringDeg>,
    /// The motor sensor's count (Hall count in direct mode, EPOS4 increments) that reads as
    /// column 0, from the column encoder through the gearing ([`Ecu::motor_angle`]). `None`
    /// until the first column sample with a known motor position; the disagreement check
    /// waits for it.
    origin_counts: Option<i32>,
    /// The origin each recent column sample implies (the motor count less the column's angle
    /// in counts), with its time: [`ORIGIN_WINDOW_US`].
    origin_candidates: heapless::Deque<(u64, i32), ORIGIN_SAMPLES>,
    /// The running origin check: when the current rest began, with column and motor (wheel
    /// deg) then, and the effort summed since (A) over that many samples.
    rest: Option<(u64, f32, f32, f32, u32)>,
    /// The enable ramp ([`ENABLE_RAMP_DPS`]); `None` once it has met the vehicle's
    /// reference.
    ramp: Option<EnableRamp>,
    /// The state machine's over-current threshold (its configuration never changes).
    overcurrent_threshold: Amps,
    motor_counter: AliveCounter,
    /// Measured current summed since the last motor frame, A, and the number of samples.
    current_sum: f32,
    current_samples: u32,
}

/// Which drive an ECU commands, as the firmware's build chooses it (its `drive-epos4` and
/// `drive-direct` features).
#[derive(Debug, Clone, Copy)]
pub enum DriveChoice {
    /// The ECU's own bridge: it runs the controller's cascade itself.
    Direct,
    /// An EPOS4 in cyclic synchronous position mode, brought up with these link settings
    /// (ECU mode writes its own feedforward gains over theirs, [`Ecu::ecu_mode_epos4_gains`]).
    Epos4(Epos4Config),
}

/// What [`Ecu::build`] makes: the controller, the drive and the settings.
#[derive(Debug, Clone, Copy)]
pub struct EcuBuild {
    pub controller: ControllerKind,
    pub drive: DriveChoice,
    pub protocol: ProtocolConfig,
    pub config: Config,
}

impl EcuBuild {
    /// `controller` on `drive`, the default protocol and state-machine settings.
    pub const fn new(controller: ControllerKind, drive: DriveChoice) -> Self {
        EcuBuild {
            controller,
            drive,
            protocol: ProtocolConfig::DEFAULT,
            config: Config::DEFAULT,
        }
    }
}

impl Ecu {
    /// The one way to make an ECU (the firmware, host-sim's simulated car, the golden vectors
    /// and the tests all come through here): `None` if a setting is refused.
    ///
    /// - Paper mode, direct: the paper's cascade ([`Cascade::paper`]) on the ECU's bridge.
    /// - ECU mode, direct: [`ColumnCascade`] with Table 3's gains and [`EcuTuning::PAPER`].
    /// - Paper mode over an EPOS4: the link alone; the drive runs the paper's loops.
    /// - ECU mode over an EPOS4: the ECU runs the column side ([`ColumnShaper`]: inverse belt
    ///   model and column feedback) once per reference period and sends the result as the CSP
    ///   target; the drive runs its own loops with the feedforward of
    ///   [`Ecu::ecu_mode_epos4_gains`], written at bring-up.
    ///
    /// `now_us` starts the EPOS4 link's clock.
    pub fn build(build: EcuBuild, now_us: u64) -> Option<Self> {
        let EcuBuild {
            controller,
            drive,
            protocol,
            config,
        } = build;
        let gearing = config.gearing();
        let drive = match (drive, controller) {
            (DriveChoice::Direct, ControllerKind::Paper) => {
                Drive::Direct(DirectDrive::new(Cascade::paper().into()))
            }
            (DriveChoice::Direct, ControllerKind::Ecu) => {
                let gains = EposGains::PAPER.to_si().ok()?;
                let cascade = ColumnCascade::new(&gains, gearing, EcuTuning::PAPER);
                Drive::Direct(DirectDrive::new(cascade.into()))
            }
            (DriveChoice::Epos4(link), ControllerKind::Paper) => {
                let link = Epos4Link::new(link, now_us).ok()?;
                Drive::Epos4(Epos4Drive::new(link, None, protocol.period_us))
            }
            (DriveChoice::Epos4(mut link), ControllerKind::Ecu) => {
                link.gains = Self::ecu_mode_epos4_gains();
                let link = Epos4Link::new(link, now_us).ok()?;
                let shaper = ColumnShaper::new(gearing, EcuTuning::PAPER, 1);
                Drive::Epos4(Epos4Drive::new(link, Some(shaper), protocol.period_us))
            }
        };
        Self::assemble(protocol, config, drive)
    }

    /// Shorthand for the paper's controller on the ECU's bridge with the default settings
    /// ([`Ecu::build`]).
    pub fn paper() -> Option<Self> {
        Self::build(EcuBuild::new(ControllerKind::Paper, DriveChoice::Direct), 0)
    }

    fn assemble(protocol: ProtocolConfig, config: Config, drive: Drive) -> Option<Self> {
        let e2e = E2eChecker::new(protocol).ok()?;
        let gearing = config.gearing();
        let overcurrent_threshold = config.overcurrent().0;
        let mut machine = SteeringStateMachine::new(config);
        let last = machine.tick(0);
        Some(Ecu {
            protocol,
            e2e,
            machine,
            drive,
            gearing,
            last,
            status_counter: AliveCounter::wrapping(0),
            hall_count: 0,
            column: SteeringDeg(f32::NAN),
            current: Amps(f32::NAN),
            clear_refusals: 0,
            clear_bit: false,
            supervisor_us: None,
            progress: crate::watchdog::Progress {
                supervisor: 0,
                fast: 0,
            },
            bus_offs: 0,
            diagnostic_counter: AliveCounter::wrapping(0),
            diagnostic_page: 0,
            pending_overflow: 0,
            stack: None,
            reference: None,
            origin_counts: None,
            origin_candidates: heapless::Deque::new(),
            rest: None,
            ramp: None,
            overcurrent_threshold,
            motor_counter: AliveCounter::wrapping(0),
            current_sum: 0.0,
            current_samples: 0,
        })
    }

    /// The EPOS4's gains in ECU mode: Table 3's PID with the model's feedforward
    /// ([`EcuTuning::PAPER`], converted to the drive's mA s/rad and mA s^2/rad).
    pub fn ecu_mode_epos4_gains() -> EposGains {
        EposGains {
            ff_velocity_ma_s_per_rad: EcuTuning::PAPER.ff_velocity * 1000.0,
            ff_acceleration_ma_s2_per_rad: EcuTuning::PAPER.ff_acceleration * 1000.0,
            ..EposGains::PAPER
        }
    }

    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The EPOS4 link, in EPOS4 mode.
    pub fn link(&self) -> Option<&Epos4Link> {
        self.drive.link()
    }

    /// The motor angle the ECU believes, aligned to the column (0 = column 0 through the
    /// gearing): the Hall count of the last position tick (direct) or the EPOS4's last
    /// position actual, less the origin. NaN while the origin is not known (no column sample
    /// yet, or the EPOS4 has not reported its position).
    pub fn motor_angle(&self) -> MotorRad {
        self.aligned_motor().unwrap_or(MotorRad(f32::NAN))
    }

    /// The motor origin in the drive's own counts (Hall counts or EPOS4 increments), see
    /// [`Ecu::motor_angle`].
    pub fn motor_origin_counts(&self) -> Option<i32> {
        self.origin_counts
    }

    /// The motor sensor's raw count: the Hall count (it starts at 0 wherever the motor stands
    /// at power-up), or the EPOS4's position actual once the drive has reported one.
    fn motor_counts(&self) -> Option<i32> {
        self.drive.motor_counts(self.hall_count)
    }

    /// The nearest count of a motor angle, in the drive's unit; `None` if not finite.
    fn counts_from_motor(&self, motor: MotorRad) -> Option<i32> {
        self.drive.counts_from_motor(motor)
    }

    fn motor_from_counts(&self, counts: i32) -> MotorRad {
        self.drive.motor_from_counts(counts)
    }

    /// The motor's count relative to the origin: what the cascade and the disagreement check
    /// see.
    fn aligned_counts(&self) -> Option<i32> {
        Some(self.motor_counts()?.saturating_sub(self.origin_counts?))
    }

    fn aligned_motor(&self) -> Option<MotorRad> {
        self.aligned_counts().map(|c| self.motor_from_counts(c))
    }

    /// The motor origin, also to the EPOS4 link: the drive's software position limits are
    /// written around it at each enable.
    fn set_origin(&mut self, origin: Option<i32>) {
        self.origin_counts = origin;
        self.drive.set_origin(origin);
    }

    /// Takes the motor origin from the last column sample: the motor count now, less the
    /// count the column's angle reads as through the gearing. Nothing changes while the
    /// column or the motor position is unknown.
    fn align_origin(&mut self) {
        let motor_at_column = self
            .gearing
            .motor_from_steering(SteeringRad::from(self.column));
        if let (Some(counts), Some(column_counts)) =
            (self.motor_counts(), self.counts_from_motor(motor_at_column))
        {
            self.set_origin(Some(counts.saturating_sub(column_counts)));
        }
    }

    /// The last column sample's angle in motor counts, through the gearing.
    fn column_counts(&self) -> Option<i32> {
        self.counts_from_motor(
            self.gearing
                .motor_from_steering(SteeringRad::from(self.column)),
        )
    }

    /// Sets the origin to the median of the window's candidates ([`ORIGIN_WINDOW_US`]) if
    /// they agree; their spread (deg at the wheel) if not. With no candidate in the window
    /// (the column is not known), the last sample's origin as before.
    fn origin_from_window(&mut self, now_us: u64) -> Result<(), SteeringDeg> {
        let mut window: heapless::Vec<i32, ORIGIN_SAMPLES> = self
            .origin_candidates
            .iter()
            .filter(|(t, _)| now_us.saturating_sub(*t) <= ORIGIN_WINDOW_US)
            .map(|&(_, o)| o)
            .collect();
        window.sort_unstable();
        let (Some(&median), Some(&low), Some(&high)) =
            (window.get(window.len() / 2), window.first(), window.last())
        else {
            self.align_origin();
            return Ok(());
        };
        let count_deg = 360.0 / crate::sensors::COLUMN_ENCODER_COUNTS as f32;
        let one_count =
            self.counts_from_motor(self.gearing.motor_from_steering(SteeringRad::from(
                SteeringDeg(ORIGIN_AGREEMENT_COUNTS * count_deg),
            )))
            .and_then(|c| c.checked_sub(self.counts_from_motor(MotorRad(0.0))?))
            .unwrap_or(0)
            .saturating_abs();
        // Plus one motor count: the motor sensor's own quantisation.
        let bound = one_count.saturating_add(1);
        if median.saturating_sub(low) > bound || high.saturating_sub(median) > bound {
            let spread_motor = self.motor_from_counts(high.saturating_sub(low));
            return Err(SteeringDeg::from(
                self.gearing.steering_from_motor(spread_motor),
            ));
        }
        self.set_origin(Some(median));
        Ok(())
    }

    /// The running cross-check of the origin ([`ORIGIN_REST_US`]); the machine's output if it
    /// latched the fault.
    fn check_origin_at_rest(
        &mut self,
        now_us: u64,
        column: SteeringDeg,
        effort: Amps,
    ) -> Option<Output> {
        let motor = self
            .aligned_motor()
            .map(|m| SteeringDeg::from(self.gearing.steering_from_motor(m)).0)
            .filter(|m| m.is_finite() && column.is_finite());
        let Some(motor) = motor else {
            self.rest = None;
            return None;
        };
        if !effort.is_finite() {
            // An effort nobody can read is no rest.
            self.rest = None;
            return None;
        }
        let (since, column_then, motor_then, sum, n) =
            *self.rest.get_or_insert((now_us, column.0, motor, 0.0, 0));
        let still = (column.0 - column_then).abs() <= ORIGIN_REST_MOTION_DEG
            && (motor - motor_then).abs() <= ORIGIN_REST_MOTION_DEG;
        if !still {
            self.rest = Some((now_us, column.0, motor, effort.0, 1));
            return None;
        }
        let (sum, n) = (sum + effort.0, n.saturating_add(1));
        self.rest = Some((since, column_then, motor_then, sum, n));
        // The mean: the loop dithers a count either side at rest (its current with it), the
        // belt's load is what stays.
        let quiet = (sum / n as f32).abs() <= ORIGIN_REST_CURRENT.0;
        let difference = column.0 - motor;
        if now_us.saturating_sub(since) >= ORIGIN_REST_US
            && quiet
            && difference.abs() > ORIGIN_REST_BOUND_DEG
        {
            self.rest = None;
            return Some(self.machine.on_origin_off(now_us, SteeringDeg(difference)));
        }
        None
    }

    /// Frames from demand changes that did not fit the pending queue (saturating).
    pub fn pending_overflow(&self) -> u16 {
        self.pending_overflow
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

    /// The stack's high-water mark for the diagnostic frame; the firmware measures it now and
    /// then ([`crate::stack`]), host builds never do.
    pub fn set_stack_usage(&mut self, usage: crate::stack::StackUsage) {
        self.stack = Some(usage);
    }

    /// Clear requests (rising edges of the reference frame's bit) the state machine refused,
    /// saturating.
    pub fn clear_refusals(&self) -> u16 {
        self.clear_refusals
    }

    fn apply(&mut self, now_us: u64, out: Output) -> Output {
        // The enable is judged here, against the demand the drive last got, not only from the
        // machine's flag: one ECU event may call the machine twice (an encoder sample, then
        // the tracking check), and the flag is true in the first call only.
        let mut out = out;
        out.drive_just_enabled =
            self.last.demand == DriveDemand::Disabled && out.demand != DriveDemand::Disabled;
        if out.drive_just_enabled {
            // The first reference sample after enabling is the one to track (the enable ramp
            // bounds its motion, not the rate limit: there is no previous sample).
            self.reference = None;
            // Every enable takes the motor origin from the column encoder afresh: the motor
            // may have been turned (driver, tyres) while the drive was off, and the Hall
            // count or the drive's position only ever counted relative steps. From the
            // window's samples, which must agree; otherwise the enable is refused.
            if let Err(spread) = self.origin_from_window(now_us) {
                let refused = self.machine.on_origin_disagreement(now_us, spread);
                return self.apply(now_us, refused);
            }
            // ... and the reference starts where the column is. The demand is Track or Hold
            // only with a fresh, finite column sample; should it not be finite, the ramp
            // starts at the first reference sample instead (see `push_reference`).
            self.ramp = Some(EnableRamp::at_rest(self.column, now_us));
        }
        let aligned = self.aligned_counts();
        let column_motor = self
            .gearing
            .motor_from_steering(SteeringRad::from(self.column));
        let lost = self.drive.on_demand(
            now_us,
            out.demand != DriveDemand::Disabled,
            out.drive_just_enabled,
            aligned.unwrap_or(self.hall_count),
            column_motor,
        );
        self.pending_overflow = self.pending_overflow.saturating_add(lost);
        // Power demanded is not power delivered: until the EPOS4 is in Operation enabled the
        // status says Arming, so the vehicle computer does not drive off on wheels nobody
        // steers.
        if self.drive.arming() && matches!(out.state, EcuState::Tracking | EcuState::Holding) {
            out.state = EcuState::Arming;
        }
        self.last = out;
        out
    }

    /// The angle the drive is given for the vehicle's `target`: the enable ramp while it
    /// runs, then the target itself.
    fn ramped(&mut self, now_us: u64, target: SteeringDeg) -> SteeringDeg {
        let Some(ramp) = &mut self.ramp else {
            return target;
        };
        if self.drive.arming() {
            // The EPOS4 is not in Operation enabled yet (the link walks CiA 402 for a few
            // SDO round trips): the ramp waits at the measured column, at rest.
            self.ramp =
                Some(EnableRamp::at_rest(self.column, now_us)).filter(|_| self.column.is_finite());
            return self.column;
        }
        match ramp.step(now_us, target, u64::from(self.protocol.period_us)) {
            Some(angle) => angle,
            None => {
                self.ramp = None;
                target
            }
        }
    }

    /// The angle the drive is given for `angle`: at most the protocol's rate (400 deg/s) times
    /// the time the controller takes to get there from the previous sample, whatever the
    /// frame timing. The E2E budget grows with the time since the last accepted frame (a
    /// 48 deg step is plausible after 120 ms of silence), and the controller ramps each sample
    /// in one period: unlimited, that step would be 4 800 deg/s. So after a gap, a burst, junk
    /// frames or a hold the drive ramps to the vehicle's angle at the rate limit instead.
    ///
    /// Direct drive: the interpolator ramps a sample from the set-point due next to the sample
    /// over one reference period; the step from the previous sample may be the rate times
    /// the position ticks taken since it (at most one period), and the set-point then moves
    /// at most the rate times each tick (the rest of the previous segment plus the new step
    /// is at most one period's worth). EPOS4: the drive takes its target once per SYNC, so
    /// the step from the sample of the last SYNC may be the rate times the SYNC interval.
    fn rate_limited(&self, angle: SteeringDeg) -> SteeringDeg {
        let rate = self.protocol.max_rate_deg_per_s;
        let period_s = self.protocol.period_us as f32 * 1e-6;
        let (anchor, span_s) = self.drive.rate_anchor(self.reference, period_s);
        let Some(anchor) = anchor.filter(|a| a.is_finite()) else {
            return angle;
        };
        let max_step = rate * span_s;
        let step = angle.0 - anchor.0;
        // NaN compares false: a non-finite angle goes on to be refused by the controller.
        if step.abs() <= max_step {
            angle
        } else if step.is_finite() {
            SteeringDeg(anchor.0 + max_step * step.signum())
        } else {
            angle
        }
    }

    fn push_reference(&mut self, now_us: u64, target: SteeringDeg) {
        // The enable ramp is the ECU's own motion, its last step included: ECU mode does not
        // shape it.
        let ramping = self.ramp.is_some();
        let angle = self.ramped(now_us, target);
        let angle = self.rate_limited(angle);
        self.reference = Some(angle);
        self.drive.push(
            self.gearing,
            angle,
            ramping,
            self.column,
            self.origin_counts,
        );
    }

    /// When the supervisor (the tasks: [`Ecu::tick`], [`Ecu::on_reference_frame`],
    /// [`Ecu::on_encoder`], [`Ecu::on_encoder_error`]) last called, us; `None` before the first
    /// call. The direct drive's fast loop turns the bridge off by itself when this is too old
    /// ([`crate::direct::SUPERVISOR_TIMEOUT_US`]): a hung task must not leave the bridge
    /// driven on a decision nobody revisits.
    pub fn supervisor_seen_us(&self) -> Option<u64> {
        self.supervisor_us
    }

    /// Direct mode: restart the cascade at the motor's measured angle with empty integrators
    /// (the fast loop does this after the supervisor came back from a stall, during which the
    /// bridge was off and the loop not stepped). Nothing in EPOS4 mode.
    pub fn resync_cascade(&mut self) {
        let aligned = self.aligned_counts().unwrap_or(self.hall_count);
        self.drive.resync(aligned);
    }

    /// How far the supervisor tasks and the fast loop have come (wrapping counts): the
    /// watchdog feeds only when both moved ([`crate::watchdog::FeedGate`]).
    pub fn progress(&self) -> crate::watchdog::Progress {
        self.progress
    }

    /// The fast loop ran one period (direct drive: [`crate::direct::FastLoop::step`] calls
    /// this first, whatever the period then does; EPOS4: each [`Ecu::drive_poll`]).
    pub fn fast_loop_ran(&mut self) {
        self.progress.fast = self.progress.fast.wrapping_add(1);
    }

    fn supervisor_called(&mut self, now_us: u64) {
        self.progress.supervisor = self.progress.supervisor.wrapping_add(1);
        self.supervisor_us = Some(self.supervisor_us.map_or(now_us, |t| t.max(now_us)));
    }

    /// A frame routed to the reference consumer: checked end to end, then handed on.
    pub fn on_reference_frame(&mut self, now_us: u64, frame: &Frame) -> Output {
        self.supervisor_called(now_us);
        let out = match self.e2e.check(frame, now_us) {
            E2eVerdict::Valid(reference) => {
                let mut out = self.machine.on_reference(now_us, reference.as_state);
                // A request is the bit's rising edge: a bit held (a stuck button, a vehicle
                // computer that sets it every period) clears once, not every period.
                let request = reference.clear_faults && !self.clear_bit;
                self.clear_bit = reference.clear_faults;
                if request {
                    // Refused unless AS Off with every cause gone; the faults stay then.
                    if self.machine.request_clear_faults(now_us).is_err() {
                        self.clear_refusals = self.clear_refusals.saturating_add(1);
                    }
                    out = self.machine.tick(now_us);
                }
                let out = self.apply(now_us, out);
                if out.demand == DriveDemand::Track {
                    self.push_reference(now_us, reference.angle);
                }
                return out;
            }
            E2eVerdict::Dropped { .. } => self.machine.tick(now_us),
            E2eVerdict::Fault { invalid_in_row, .. } => self
                .machine
                .on_invalid_frames_fault(now_us, u16::from(invalid_in_row)),
        };
        // A dropped frame whose ID, length and CRC were good carries the AS state the vehicle
        // did send: any state that does not allow power disables at once, whatever the
        // counter (a frame lost before it) and the angle. Only more authority needs a frame
        // that passed every rule: Ready/Driving from it refresh nothing, and neither does an
        // AS Off that would release a standing emergency (the drive is off already).
        let in_emergency = self.machine.as_state() == Some(AsState::Emergency);
        let out = match self.e2e.authentic_as_state() {
            Some(AsState::Off) if in_emergency => out,
            Some(as_state) if !self.machine.config().actuation().allows(as_state) => {
                self.machine.on_as_state(now_us, as_state)
            }
            _ => out,
        };
        self.apply(now_us, out)
    }

    /// Time passes (call at least every reference period): timeouts are found here.
    pub fn tick(&mut self, now_us: u64) -> Output {
        self.supervisor_called(now_us);
        let out = self.machine.tick(now_us);
        self.apply(now_us, out)
    }

    /// A column-encoder sample, checked against the motor angle of the last position tick.
    pub fn on_encoder(&mut self, now_us: u64, column: SteeringDeg) -> Output {
        self.supervisor_called(now_us);
        self.column = column;
        if self.motor_counts().is_none() {
            // The EPOS4 restarted (a new origin of its own) or has not reported yet.
            self.set_origin(None);
        }
        if self.origin_counts.is_none() && column.is_finite() {
            self.align_origin();
        }
        match (self.motor_counts(), self.column_counts()) {
            (Some(counts), Some(column_counts)) => {
                if self.origin_candidates.is_full() {
                    let _ = self.origin_candidates.pop_front();
                }
                let _ = self
                    .origin_candidates
                    .push_back((now_us, counts.saturating_sub(column_counts)));
            }
            // No motor position, or no column: nothing agrees with anything.
            _ => self.origin_candidates.clear(),
        }
        let out = match self.aligned_motor() {
            Some(motor) => self.machine.on_encoder(now_us, column, motor),
            None => self.machine.on_column(now_us, column),
        };
        let out = match (out.demand, self.reference) {
            (DriveDemand::Track | DriveDemand::Hold, Some(reference)) => {
                let _ = self.machine.on_tracking(now_us, reference, column);
                // What pushes the motor: the position loop's current set-point (direct), the
                // drive's measured current (EPOS4: its set-point is not on the bus).
                let effort = self.drive.effort(self.current);
                let out = self
                    .machine
                    .on_drive_effort(now_us, reference, column, effort);
                self.check_origin_at_rest(now_us, column, effort)
                    .unwrap_or(out)
            }
            _ => {
                self.rest = None;
                self.machine.on_not_tracking(now_us)
            }
        };
        self.apply(now_us, out)
    }

    /// The encoder did not answer or flagged its reading.
    pub fn on_encoder_error(&mut self, now_us: u64, code: u16) -> Output {
        self.supervisor_called(now_us);
        self.column = SteeringDeg(f32::NAN);
        let out = self.machine.on_encoder_fault(now_us, code);
        self.apply(now_us, out)
    }

    /// The motor's Hall sensors gave bad samples in a row (direct mode; see
    /// [`crate::direct`] for the codes).
    pub fn on_hall_fault(&mut self, now_us: u64, code: u16) -> Output {
        let out = self.machine.on_encoder_fault(now_us, code);
        self.apply(now_us, out)
    }

    pub fn on_bus_off(&mut self, now_us: u64, tec: u8) -> Output {
        self.bus_offs = self.bus_offs.saturating_add(1);
        let out = self.machine.on_bus_off(now_us, tec);
        self.apply(now_us, out)
    }

    /// Position-loop tick (2 kHz, direct mode): the current set-point, 0 A unless the drive
    /// is enabled. In EPOS4 mode nothing runs here: 0 A.
    pub fn position_tick(&mut self, hall_count: i32) -> Amps {
        self.hall_count = hall_count;
        let Some(d) = self.drive.direct_mut() else {
            return Amps::ZERO;
        };
        d.ticked();
        let cascade = d.controller_mut();
        match self.last.demand {
            DriveDemand::Disabled => Amps::ZERO,
            // The cascade runs in the column-aligned frame; the origin is set on the enable
            // that switched the drive on, so it is known here.
            DriveDemand::Hold | DriveDemand::Track => {
                let aligned = hall_count.saturating_sub(self.origin_counts.unwrap_or(0));
                // ECU mode closes its column terms on the newest encoder sample (the aligned
                // frame puts column 0 at motor 0); paper mode ignores it.
                let column = Some(SteeringRad::from(self.column)).filter(|c| c.is_finite());
                cascade.position_step(aligned, column).current
            }
        }
    }

    /// Current-loop tick (20 kHz, direct mode): the voltage to apply, or `None` for bridge off.
    /// The measured current also feeds the over-current check. In EPOS4 mode: `None`.
    pub fn current_tick(&mut self, now_us: u64, measured: Amps) -> Option<Volts> {
        if self.drive.link().is_some() {
            return None;
        }
        self.current = measured;
        self.current_sum += measured.0;
        self.current_samples = self.current_samples.saturating_add(1);
        // Fast path (the 20 kHz budget, measured by the emulated suite): a sample within the
        // over-current threshold while no over-current run is open changes nothing in the
        // state machine, so the last output stands; time-based rules are applied by `tick`
        // every 2 ms. Any other sample goes through the full check.
        let out = if measured.0.abs() <= self.overcurrent_threshold.0
            && !self.machine.overcurrent_pending()
        {
            self.last
        } else {
            let out = self.machine.on_current(now_us, measured);
            self.apply(now_us, out)
        };
        let d = self.drive.direct_mut()?;
        let cascade = d.controller_mut();
        match out.demand {
            DriveDemand::Disabled => None,
            DriveDemand::Hold | DriveDemand::Track => Some(cascade.current_step(measured).voltage),
        }
    }

    /// EPOS4 mode, once at start: the link's first configuration frame. Empty in direct mode.
    pub fn drive_start(&mut self, now_us: u64) -> DriveFrames {
        let out = match self.drive.epos4_mut() {
            Some(d) => d.link_mut().start(now_us),
            None => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// EPOS4 mode, often (every 1 ms): SYNC and RPDO on their period, SDO time-outs, the
    /// heartbeat and TPDO supervision, the automatic reset of a failed link in AS Off. Returns
    /// the frames to send, the pending demand-change frames first. Empty in direct mode.
    pub fn drive_poll(&mut self, now_us: u64) -> DriveFrames {
        self.fast_loop_ran();
        let as_off = self.machine.as_state() == Some(AsState::Off);
        let out = match self.drive.epos4_mut() {
            Some(d) => {
                if d.link().error().is_some()
                    && as_off
                    && d.take_reset_due(now_us, LINK_RESET_INTERVAL_US)
                {
                    d.link_mut().request_fault_reset(now_us)
                } else {
                    d.link_mut().poll(now_us)
                }
            }
            None => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// EPOS4 mode: a frame routed to the drive (PDO, SDO answer, heartbeat, EMCY). Returns the
    /// frames to send. Ignored in direct mode.
    pub fn on_drive_frame(&mut self, now_us: u64, frame: &Frame) -> DriveFrames {
        let out = match self.drive.epos4_mut() {
            Some(d) => d.link_mut().on_frame(frame, now_us),
            None => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// The link's news into the state machine, then the frames to send: pending ones first.
    fn after_link(&mut self, now_us: u64, link_out: Outbox) -> DriveFrames {
        let Some(d) = self.drive.epos4_mut() else {
            // Direct mode has no link: nothing came out of it.
            return DriveFrames::new();
        };
        let mut out = self.last;
        if let Some(current) = d.new_current() {
            self.current = current;
            out = self.machine.on_current(now_us, current);
        }
        if let Some(error) = d.error_change() {
            out = match error {
                Some(LinkError::HeartbeatLost { .. } | LinkError::PdoTimeout { .. }) => {
                    self.machine.on_heartbeat_lost(now_us)
                }
                Some(e) => self.machine.on_epos_fault(now_us, link_fault_code(e)),
                None => out,
            };
        }
        if d.came_up() {
            // Back in Standby (or further) after a start or a reset: the causes are gone.
            let _ = self.machine.on_heartbeat(now_us);
            out = self.machine.on_epos_fault_gone(now_us);
        }
        if link_out.iter().any(crate::canopen::nmt::is_sync) {
            // The target went out with this SYNC: the rate limit's next anchor.
            d.synced(now_us, self.reference);
        }
        let _ = self.apply(now_us, out);
        let pending = self.drive.take_pending();
        let mut frames = DriveFrames::new();
        for f in pending.iter().chain(link_out.iter()) {
            if frames.push(*f).is_err() {
                self.pending_overflow = self.pending_overflow.saturating_add(1);
            }
        }
        frames
    }

    /// The next status frame (call once per status period).
    pub fn status_frame(&mut self) -> Frame {
        // In EPOS4 mode the current is the drive's last TPDO2 (see `after_link`).
        self.status_counter = self.status_counter.next();
        self.protocol.encode_status(&Status {
            angle: self.column,
            current: self.current,
            ecu_state: self.last.state.code(),
            faults: self.last.faults.bits(),
            counter: self.status_counter,
        })
    }

    /// The next page of the diagnostic frame ([`crate::protocol::DiagnosticPage`]): the E2E
    /// drop counters per reason, early frames, bus-off events, refused clears, hold entries,
    /// lost demand-change frames, the fault log's counts, the stack's high-water mark, then
    /// every slot of the fault log,
    /// oldest first, with each record's age at `now_us`; one page per call, round robin, so a
    /// reader sees everything within [`crate::protocol::DIAGNOSTIC_ROUND`] calls.
    pub fn diagnostic_frame(&mut self, now_us: u64) -> Frame {
        use crate::protocol::{
            COUNTER_PAGES, DIAGNOSTIC_ROUND, Diagnostic, DiagnosticPage, DiagnosticRecord,
        };
        let position = self.diagnostic_page;
        self.diagnostic_page = position.saturating_add(1) % DIAGNOSTIC_ROUND;
        self.diagnostic_counter = self.diagnostic_counter.next();
        let d = *self.e2e.drops();
        let log = self.machine.fault_log();
        let saturated = |n: usize| u16::try_from(n).unwrap_or(u16::MAX);
        let counters = |page: u8, words: [u16; 3]| DiagnosticPage::Counters { page, words };
        let page = match position {
            0 => counters(0, [d.wrong_length, d.crc, d.stale]),
            1 => counters(
                1,
                [d.counter_jump, d.unknown_as_state, d.angle_out_of_range],
            ),
            2 => counters(2, [d.rate_too_high, self.e2e.early_frames(), self.bus_offs]),
            3 => counters(
                3,
                [
                    self.clear_refusals,
                    self.machine.hold_entries(),
                    self.pending_overflow,
                ],
            ),
            4 => counters(
                4,
                [
                    saturated(log.len()),
                    saturated(log.unacknowledged()),
                    u16::try_from(log.dropped()).unwrap_or(u16::MAX),
                ],
            ),
            5 => {
                // Not measured (a host build, or before the first measurement): all zero.
                let [peak, size] = self.stack.map_or([0, 0], |u| u.words_u16());
                counters(5, [peak, size, 0])
            }
            _ => {
                // Positions from COUNTER_PAGES on (the arms above take the others).
                let slot = position.saturating_sub(COUNTER_PAGES);
                let index = usize::from(slot);
                let record = log.get(index).map(|r| DiagnosticRecord {
                    fault_bit: r.fault.bit(),
                    acknowledged: log.is_acknowledged(index),
                    detail: r.detail,
                    age_s: u16::try_from(now_us.saturating_sub(r.at_us) / 1_000_000)
                        .unwrap_or(u16::MAX),
                });
                DiagnosticPage::Record { slot, record }
            }
        };
        self.protocol.encode_diagnostic(&Diagnostic {
            counter: self.diagnostic_counter,
            page,
        })
    }

    /// The next motor frame (call once per status period, after [`Ecu::status_frame`]): the
    /// motor angle the ECU believes ([`Ecu::motor_angle`]) and the mean measured current since
    /// the last motor frame. In EPOS4 mode no current tick runs here, so the current is the
    /// drive's last TPDO2; NaN when no sample came (or one was not a number). It also carries
    /// the reference counter the E2E check last saw, for a sender that starts while the ECU
    /// runs to continue from (0 before the first reference: any counter is accepted then).
    pub fn motor_frame(&mut self) -> Frame {
        self.motor_counter = self.motor_counter.next();
        let current_mean = if self.current_samples > 0 {
            Amps(self.current_sum / self.current_samples as f32)
        } else if self.drive.link().is_some() {
            self.current
        } else {
            Amps(f32::NAN)
        };
        self.current_sum = 0.0;
        self.current_samples = 0;
        self.protocol.encode_motor(&MotorStatus {
            angle: self.motor_angle(),
            current_mean,
            counter: self.motor_counter,
            reference_counter: self.e2e.last_counter().unwrap_or_default(),
        })
    }
}

#[cfg(test)]
mod tests;

#[cfg(test)]
mod epos4_tests;

#[cfg(test)]
mod rate_limit_tests;

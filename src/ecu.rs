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

use crate::as_state::AsState;
use crate::can::Frame;
use crate::canopen::epos4::{Epos4Link, LinkError, Outbox, Phase};
use crate::controller::SteeringController;
use crate::ecu_mode::{ColumnCascade, ColumnShaper, EcuTuning};
use crate::enable_ramp::EnableRamp;
use crate::gains::EposGains;
use crate::gearing::Gearing;
use crate::paper_mode::Cascade;
use crate::protocol::{AliveCounter, E2eChecker, E2eVerdict, MotorStatus, ProtocolConfig, Status};
use crate::sensors::{HALL_COUNTS_PER_REV, hall_from_motor, motor_from_hall};
use crate::steering::{Config, DriveDemand, EcuState, Output, SteeringStateMachine};
use crate::units::{Amps, MotorRad, SteeringDeg, SteeringRad, Volts};

/// How the motor is driven; see the module docs.
#[derive(Debug, Clone)]
// One per ECU, made once: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
pub enum Drive {
    /// The ECU runs the cascade on its own bridge: paper mode or ECU mode.
    Direct(SteeringController),
    /// An EPOS4 in cyclic synchronous position mode runs the loops.
    Epos4(Epos4Link),
}

/// Frames a demand change left for the drive task; a disable is one frame, so 4 is room for
/// several changes within one drive-task period.
const PENDING_DEPTH: usize = 4;

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
/// disagreement window in `src/steering.rs`, about 1 deg) and the quantisation (0.1 deg). An
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
    /// EPOS4 mode: frames from demand changes, for the next drive call.
    pending: heapless::Vec<Frame, PENDING_DEPTH>,
    /// Pending frames that did not fit (saturating); the link's supervision covers a lost one.
    pending_overflow: u16,
    /// The firmware's stack high-water mark, as it last measured it (`None` off the chip).
    stack: Option<crate::stack::StackUsage>,
    /// EPOS4 mode: the link was up (Standby, Disabling or Cyclic) at the last supervision.
    link_up: bool,
    link_error: Option<LinkError>,
    last_link_reset_us: Option<u64>,
    current_seen_us: u64,
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
    /// Position ticks since the last reference sample was pushed (direct drive), saturating:
    /// the rate limit's time base ([`Ecu::rate_limited`]).
    ticks_since_push: u32,
    /// EPOS4 mode: the reference sample the drive's target came from at the last SYNC, and
    /// when that SYNC and the one before it went out: the rate limit's anchor and time base.
    synced_reference: Option<SteeringDeg>,
    last_sync_us: Option<u64>,
    sync_interval_us: u64,
    /// The state machine's over-current threshold (its configuration never changes).
    overcurrent_threshold: Amps,
    motor_counter: AliveCounter,
    /// Measured current summed since the last motor frame, A, and the number of samples.
    current_sum: f32,
    current_samples: u32,
    /// ECU mode over an EPOS4: the column side of the controller, which makes the CSP target.
    /// `None` in paper mode and in direct drive (where the controller holds its own).
    shaper: Option<ColumnShaper>,
}

impl Ecu {
    /// A direct-drive ECU with these settings; `None` if the protocol configuration is refused.
    pub fn new(
        protocol: ProtocolConfig,
        config: Config,
        cascade: impl Into<SteeringController>,
    ) -> Option<Self> {
        Self::with_drive(protocol, config, Drive::Direct(cascade.into()))
    }

    /// An ECU driving the motor as `drive` says; `None` if the protocol configuration is
    /// refused.
    pub fn with_drive(protocol: ProtocolConfig, config: Config, drive: Drive) -> Option<Self> {
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
            pending: heapless::Vec::new(),
            pending_overflow: 0,
            stack: None,
            link_up: false,
            link_error: None,
            last_link_reset_us: None,
            current_seen_us: 0,
            reference: None,
            origin_counts: None,
            origin_candidates: heapless::Deque::new(),
            rest: None,
            ramp: None,
            ticks_since_push: u32::MAX,
            synced_reference: None,
            last_sync_us: None,
            sync_interval_us: u64::from(protocol.period_us),
            overcurrent_threshold,
            motor_counter: AliveCounter::wrapping(0),
            current_sum: 0.0,
            current_samples: 0,
            shaper: None,
        })
    }

    /// The paper's actuator driven directly, the default protocol and state-machine settings.
    pub fn paper() -> Option<Self> {
        Self::new(ProtocolConfig::default(), Config::DEFAULT, Cascade::paper())
    }

    /// ECU mode ([`crate::ecu_mode`]) on the paper's actuator, driven directly.
    pub fn ecu_direct() -> Option<Self> {
        let gains = EposGains::PAPER.to_si().ok()?;
        let config = Config::DEFAULT;
        let cascade = ColumnCascade::new(&gains, config.gearing(), EcuTuning::PAPER);
        Self::new(ProtocolConfig::default(), config, cascade)
    }

    /// ECU mode over an EPOS4: the ECU runs the column side ([`ColumnShaper`]: inverse belt
    /// model and column feedback) once per reference period and sends the result as the CSP
    /// target; the drive runs its own loops, with the feedforward of
    /// [`Ecu::ecu_mode_epos4_gains`] written at bring-up.
    pub fn ecu_epos4(link: Epos4Link) -> Option<Self> {
        let config = Config::DEFAULT;
        let mut ecu = Self::with_drive(ProtocolConfig::default(), config, Drive::Epos4(link))?;
        ecu.shaper = Some(ColumnShaper::new(config.gearing(), EcuTuning::PAPER, 1));
        Some(ecu)
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

    /// The paper's car: an EPOS4 with the link's settings, the default protocol and
    /// state-machine settings.
    pub fn paper_epos4(link: Epos4Link) -> Option<Self> {
        Self::with_drive(
            ProtocolConfig::default(),
            Config::DEFAULT,
            Drive::Epos4(link),
        )
    }

    pub fn drive(&self) -> &Drive {
        &self.drive
    }

    /// The EPOS4 link, in EPOS4 mode.
    pub fn link(&self) -> Option<&Epos4Link> {
        match &self.drive {
            Drive::Epos4(link) => Some(link),
            Drive::Direct(_) => None,
        }
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
        match &self.drive {
            Drive::Direct(_) => Some(self.hall_count),
            Drive::Epos4(link) => link
                .position_known()
                .then_some(link.feedback().position_inc),
        }
    }

    /// The nearest count of a motor angle, in the drive's unit; `None` if not finite.
    fn counts_from_motor(&self, motor: MotorRad) -> Option<i32> {
        match &self.drive {
            Drive::Direct(_) => motor.is_finite().then(|| {
                // `hall_from_motor` floors: half a count more rounds to the nearest.
                let half_count = core::f64::consts::PI / f64::from(HALL_COUNTS_PER_REV);
                hall_from_motor(f64::from(motor.0) + half_count)
            }),
            Drive::Epos4(link) => link.scale().inc_from_motor(motor),
        }
    }

    fn motor_from_counts(&self, counts: i32) -> MotorRad {
        match &self.drive {
            Drive::Direct(_) => motor_from_hall(counts),
            Drive::Epos4(link) => link.scale().motor_from_inc(counts),
        }
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
        if let Drive::Epos4(link) = &mut self.drive {
            link.set_position_origin(origin);
        }
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

    /// Clear requests (rising edges of the reference frame's bit) the state machine refused,
    /// saturating.
    /// The stack's high-water mark for the diagnostic frame; the firmware measures it now and
    /// then ([`crate::stack`]), host builds never do.
    pub fn set_stack_usage(&mut self, usage: crate::stack::StackUsage) {
        self.stack = Some(usage);
    }

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
            self.synced_reference = None;
            self.ticks_since_push = u32::MAX;
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
        if out.drive_just_enabled
            && let Some(shaper) = &mut self.shaper
        {
            // ECU mode over the EPOS4 starts from rest where the column is.
            shaper.reset(
                self.gearing
                    .motor_from_steering(SteeringRad::from(self.column)),
            );
        }
        match &mut self.drive {
            Drive::Direct(cascade) => {
                if out.drive_just_enabled {
                    cascade.reset(aligned.unwrap_or(self.hall_count));
                }
            }
            Drive::Epos4(link) => {
                let frames = link.set_power(out.demand != DriveDemand::Disabled, now_us);
                for f in frames {
                    if self.pending.push(f).is_err() {
                        self.pending_overflow = self.pending_overflow.saturating_add(1);
                    }
                }
            }
        }
        // Power demanded is not power delivered: until the EPOS4 is in Operation enabled the
        // status says Arming, so the vehicle computer does not drive off on wheels nobody
        // steers.
        if let Drive::Epos4(link) = &self.drive
            && matches!(out.state, EcuState::Tracking | EcuState::Holding)
            && link.phase() != Phase::Cyclic
        {
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
        if let Drive::Epos4(link) = &self.drive
            && link.phase() != Phase::Cyclic
        {
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
        let (anchor, span_s) = match &self.drive {
            Drive::Direct(_) => {
                let ticks = self
                    .ticks_since_push
                    .min(crate::paper_mode::POSITION_TICKS_PER_REFERENCE);
                (
                    self.reference,
                    ticks as f32 / crate::paper_mode::POSITION_LOOP_HZ as f32,
                )
            }
            Drive::Epos4(_) => (
                self.synced_reference,
                (self.sync_interval_us as f32 * 1e-6).min(period_s),
            ),
        };
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
        self.ticks_since_push = 0;
        match &mut self.drive {
            // The E2E check already bounds the angle to the cascade's range; a refusal here
            // keeps the ramp in progress, which is the documented outcome.
            Drive::Direct(cascade) => {
                let _ = if ramping {
                    cascade.push_unshaped(angle)
                } else {
                    cascade.push_reference(angle)
                };
            }
            Drive::Epos4(link) => {
                let mut motor = self.gearing.motor_from_steering(SteeringRad::from(angle));
                if let Some(shaper) = &mut self.shaper {
                    // ECU mode: the shaped target with the column terms. A refused sample
                    // keeps the shaper's last target.
                    let _ = if ramping {
                        shaper.push_unshaped(angle)
                    } else {
                        shaper.push_reference(angle)
                    };
                    let column = Some(SteeringRad::from(self.column)).filter(|c| c.is_finite());
                    motor = shaper.next_target(column);
                }
                // The drive counts from where it powered up: its target is the column-derived
                // angle plus the origin. Not finite, or no origin yet: the target stays (the
                // link keeps it at the drive's actual position until it is enabled).
                if let (Some(inc), Some(origin)) =
                    (link.scale().inc_from_motor(motor), self.origin_counts)
                {
                    link.set_target_inc(inc.saturating_add(origin));
                }
            }
        }
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
        if let Drive::Direct(cascade) = &mut self.drive {
            cascade.reset(aligned);
        }
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
                let effort = match &self.drive {
                    Drive::Direct(cascade) => cascade.current_setpoint(),
                    Drive::Epos4(_) => self.current,
                };
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
        self.ticks_since_push = self.ticks_since_push.saturating_add(1);
        let Drive::Direct(cascade) = &mut self.drive else {
            return Amps::ZERO;
        };
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
        if let Drive::Epos4(_) = self.drive {
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
        let Drive::Direct(cascade) = &mut self.drive else {
            return None;
        };
        match out.demand {
            DriveDemand::Disabled => None,
            DriveDemand::Hold | DriveDemand::Track => Some(cascade.current_step(measured).voltage),
        }
    }

    /// EPOS4 mode, once at start: the link's first configuration frame. Empty in direct mode.
    pub fn drive_start(&mut self, now_us: u64) -> DriveFrames {
        let out = match &mut self.drive {
            Drive::Epos4(link) => link.start(now_us),
            Drive::Direct(_) => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// EPOS4 mode, often (every 1 ms): SYNC and RPDO on their period, SDO time-outs, the
    /// heartbeat and TPDO supervision, the automatic reset of a failed link in AS Off. Returns
    /// the frames to send, the pending demand-change frames first. Empty in direct mode.
    pub fn drive_poll(&mut self, now_us: u64) -> DriveFrames {
        self.fast_loop_ran();
        let as_off = self.machine.as_state() == Some(AsState::Off);
        let reset_due = self
            .last_link_reset_us
            .is_none_or(|t| now_us.saturating_sub(t) >= LINK_RESET_INTERVAL_US);
        let out = match &mut self.drive {
            Drive::Epos4(link) if link.error().is_some() && as_off && reset_due => {
                self.last_link_reset_us = Some(now_us);
                link.request_fault_reset(now_us)
            }
            Drive::Epos4(link) => link.poll(now_us),
            Drive::Direct(_) => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// EPOS4 mode: a frame routed to the drive (PDO, SDO answer, heartbeat, EMCY). Returns the
    /// frames to send. Ignored in direct mode.
    pub fn on_drive_frame(&mut self, now_us: u64, frame: &Frame) -> DriveFrames {
        let out = match &mut self.drive {
            Drive::Epos4(link) => link.on_frame(frame, now_us),
            Drive::Direct(_) => Outbox::new(),
        };
        self.after_link(now_us, out)
    }

    /// The link's news into the state machine, then the frames to send: pending ones first.
    fn after_link(&mut self, now_us: u64, link_out: Outbox) -> DriveFrames {
        let Drive::Epos4(link) = &self.drive else {
            // Direct mode has no link: nothing came out of it.
            return DriveFrames::new();
        };
        let error = link.error();
        let up = matches!(
            link.phase(),
            Phase::Standby | Phase::Disabling | Phase::Cyclic
        );
        let feedback = link.feedback();
        let current = link.motor_current();
        let mut out = self.last;
        if feedback.current_updated_us != self.current_seen_us {
            self.current_seen_us = feedback.current_updated_us;
            self.current = current;
            out = self.machine.on_current(now_us, current);
        }
        if error != self.link_error {
            self.link_error = error;
            out = match error {
                Some(LinkError::HeartbeatLost { .. } | LinkError::PdoTimeout { .. }) => {
                    self.machine.on_heartbeat_lost(now_us)
                }
                Some(e) => self.machine.on_epos_fault(now_us, link_fault_code(e)),
                None => out,
            };
        }
        if up && !self.link_up {
            // Back in Standby (or further) after a start or a reset: the causes are gone.
            let _ = self.machine.on_heartbeat(now_us);
            out = self.machine.on_epos_fault_gone(now_us);
        }
        self.link_up = up;
        if link_out.iter().any(crate::canopen::nmt::is_sync) {
            // The target went out with this SYNC: the rate limit's next anchor.
            self.synced_reference = self.reference;
            if let Some(t) = self.last_sync_us.replace(now_us) {
                self.sync_interval_us = now_us.saturating_sub(t);
            }
        }
        let _ = self.apply(now_us, out);
        let mut frames = DriveFrames::new();
        for f in self.pending.iter().chain(link_out.iter()) {
            if frames.push(*f).is_err() {
                self.pending_overflow = self.pending_overflow.saturating_add(1);
            }
        }
        self.pending.clear();
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
    /// drive's last TPDO2; NaN when no sample came (or one was not a number).
    pub fn motor_frame(&mut self) -> Frame {
        self.motor_counter = self.motor_counter.next();
        let current_mean = if self.current_samples > 0 {
            Amps(self.current_sum / self.current_samples as f32)
        } else if let Drive::Epos4(_) = self.drive {
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
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::Reference;

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
                if t.is_multiple_of(2 * MS) {
                    // The sample at 100 ms is the last before the first AS Driving frame.
                    let column = if t == 100 * MS { 10.0 + glitch } else { 10.0 };
                    let _ = ecu.on_encoder(t, SteeringDeg(column));
                }
                if t.is_multiple_of(10 * MS) {
                    let s = if t < 100 * MS {
                        AsState::Off
                    } else {
                        AsState::Driving
                    };
                    let _ = vehicle.send(&mut ecu, t, s, 10.0);
                }
                let _ = ecu.position_tick(hall);
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
                if t.is_multiple_of(2 * MS) {
                    let glitched = (84 * MS..=100 * MS).contains(&t);
                    let column = if glitched { motor + offset } else { motor };
                    let _ = ecu.on_encoder(t, SteeringDeg(column));
                }
                if t.is_multiple_of(10 * MS) {
                    let s = if t < 100 * MS {
                        AsState::Off
                    } else {
                        AsState::Driving
                    };
                    let _ = vehicle.send(&mut ecu, t, s, 10.0);
                }
                let _ = ecu.position_tick(hall_at(motor));
                if ecu.output().demand != DriveDemand::Disabled {
                    // A stiff drive: the motor is where the set-point is, in truth.
                    let aligned = setpoint_deg(&ecu);
                    let origin_error = ecu.motor_angle().0
                        - Gearing::PAPER
                            .motor_from_steering(SteeringDeg(motor).into())
                            .0;
                    let error = SteeringDeg::from(
                        Gearing::PAPER.steering_from_motor(MotorRad(origin_error)),
                    );
                    motor = aligned - error.0;
                }
                if latched_at.is_none()
                    && ecu.output().faults.contains(crate::faults::Fault::Origin)
                {
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
            for mut ecu in [Ecu::paper().unwrap(), Ecu::ecu_direct().unwrap()] {
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
                        let motor = cascade.setpoint().position;
                        let setpoint =
                            SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor)).0;
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
                let mut ecu =
                    Ecu::new(ProtocolConfig::default(), config, Cascade::paper()).unwrap();
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
        let mut ecu = Ecu::paper_epos4(Epos4Link::new(config, 0).unwrap()).unwrap();
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
}

// Tests for what `.ci/mutation.sh` found missed in this file (issue 12): mostly the EPOS4
// mode, which the library's other tests reach only through host-sim.
#[cfg(test)]
mod mutation_tests {
    use super::tests::Vehicle;
    use super::*;
    use crate::canopen::cia402::{self, State};
    use crate::canopen::epos4::{Epos4Config, od};
    use crate::canopen::nmt::{self, NmtCommand, NmtState};
    use crate::canopen::sdo::{self, ServerRequest, Width};
    use crate::canopen::{NodeId, ObjectAddress, cob_id, function};
    use crate::faults::Fault;
    use std::collections::HashMap;

    const MS: u64 = 1000;

    fn node() -> NodeId {
        NodeId::new(1).unwrap()
    }

    /// A minimal EPOS4 on the other end of the link: an object dictionary that reads back
    /// what was written, the CiA 402 state driven by the controlword, NMT start, a heartbeat
    /// and TPDO1 (statusword, position) and TPDO2 (current, mA) on each SYNC. The motor stands
    /// at `position_inc` (the drive's own count from its power-up) unless the test moves it.
    struct FakeEpos4 {
        od: HashMap<ObjectAddress, u32>,
        state: State,
        operational: bool,
        position_inc: i32,
        current_ma: i32,
        /// The targets RPDO1 brought in Operation enabled (the ones the drive follows).
        targets: Vec<i32>,
        /// Frames for the ECU, delivered at its next drive call.
        answers: Vec<Frame>,
        /// The motor goes to each target at once.
        follows: bool,
    }

    impl FakeEpos4 {
        fn new(position_inc: i32) -> Self {
            FakeEpos4 {
                od: HashMap::new(),
                state: State::SwitchOnDisabled,
                operational: false,
                position_inc,
                current_ma: 0,
                targets: Vec::new(),
                answers: Vec::new(),
                follows: false,
            }
        }

        fn statusword(&self) -> u16 {
            match self.state {
                State::SwitchOnDisabled => 0x0040,
                State::ReadyToSwitchOn => 0x0021,
                State::SwitchedOn => 0x0023,
                State::OperationEnabled => 0x0027,
                _ => 0x0008,
            }
        }

        fn on_controlword(&mut self, cw: u16) {
            use cia402::Command;
            self.state = match (self.state, cw) {
                (_, cw) if cw == Command::DisableVoltage.controlword() => State::SwitchOnDisabled,
                (_, cw) if cw == Command::FaultReset.controlword() => State::SwitchOnDisabled,
                (_, cw) if cw == Command::Shutdown.controlword() => State::ReadyToSwitchOn,
                (State::ReadyToSwitchOn | State::OperationEnabled, 0x0007) => State::SwitchedOn,
                (State::SwitchedOn, 0x000F) => State::OperationEnabled,
                (state, _) => state,
            };
        }

        fn on_frame(&mut self, f: &Frame) -> Vec<Frame> {
            let n = node();
            let mut out = Vec::new();
            if let Some((NmtCommand::Start, target)) = nmt::parse_command(f)
                && target.includes(n)
            {
                self.operational = true;
                out.extend(nmt::heartbeat_frame(n, NmtState::Operational));
            } else if nmt::is_sync(f) && self.operational {
                let mut d = [0u8; 6];
                d[..2].copy_from_slice(&self.statusword().to_le_bytes());
                d[2..].copy_from_slice(&self.position_inc.to_le_bytes());
                out.extend(Frame::new(cob_id(function::TPDO1, n), &d));
                out.extend(Frame::new(
                    cob_id(function::TPDO2, n),
                    &self.current_ma.to_le_bytes(),
                ));
                out.extend(nmt::heartbeat_frame(n, NmtState::Operational));
            } else if f.id() == cob_id(function::RPDO1, n) {
                if let Ok(bytes) = <[u8; 4]>::try_from(f.data())
                    && self.state == State::OperationEnabled
                {
                    let target = i32::from_le_bytes(bytes);
                    self.targets.push(target);
                    if self.follows {
                        self.position_inc = target;
                    }
                }
            } else if let Some(request) = sdo::parse_request(f, n) {
                match request {
                    ServerRequest::Download { object, value, .. } => {
                        if object == od::CONTROLWORD {
                            self.on_controlword(value as u16);
                        }
                        self.od.insert(object, value);
                        out.extend(sdo::download_response_frame(n, object));
                    }
                    ServerRequest::Upload { object } => {
                        let value = match object {
                            o if o == od::STATUSWORD => u32::from(self.statusword()),
                            o if o == od::POSITION_ACTUAL => self.position_inc as u32,
                            o => self.od.get(&o).copied().unwrap_or(0),
                        };
                        out.extend(sdo::upload_response_frame(n, object, value, Width::U32));
                    }
                    ServerRequest::Unsupported { .. } => {}
                }
            }
            out
        }
    }

    /// One millisecond of the drive task: the drive's answers to what the ECU sent in the
    /// previous one (a bus round trip later) go to the ECU, then the ECU polls; everything the
    /// ECU sends goes to the drive. The frames the ECU sent, in order.
    fn step(ecu: &mut Ecu, drive: &mut FakeEpos4, t: u64) -> Vec<Frame> {
        let answers = std::mem::take(&mut drive.answers);
        let mut sent = Vec::new();
        for answer in &answers {
            sent.extend(ecu.on_drive_frame(t, answer));
        }
        sent.extend(ecu.drive_poll(t));
        for f in &sent {
            let answers = drive.on_frame(f);
            drive.answers.extend(answers);
        }
        sent
    }

    /// An EPOS4-mode ECU (paper mode) whose drive powered up at `position_inc`, started at 0.
    fn epos4_ecu(position_inc: i32) -> (Ecu, FakeEpos4, Vec<Frame>) {
        let config = Epos4Config::paper(node());
        let mut ecu = Ecu::paper_epos4(Epos4Link::new(config, 0).unwrap()).unwrap();
        let mut drive = FakeEpos4::new(position_inc);
        let sent = ecu.drive_start(0).to_vec();
        for f in &sent {
            let answers = drive.on_frame(f);
            drive.answers.extend(answers);
        }
        (ecu, drive, sent)
    }

    /// Runs the car from `from` to `to` as the firmware's tasks do: the drive task every 1 ms,
    /// the encoder (column at `column`) and the vehicle's frame (`as_state`, `deg`; none for
    /// a NaN `deg`) every 10 ms. Every frame the ECU sent.
    #[allow(clippy::too_many_arguments)]
    fn run(
        ecu: &mut Ecu,
        drive: &mut FakeEpos4,
        vehicle: &mut Vehicle,
        from: u64,
        to: u64,
        as_state: AsState,
        deg: f32,
        column: f32,
    ) -> Vec<Frame> {
        let mut sent = Vec::new();
        let mut t = from;
        while t < to {
            if (t - from).is_multiple_of(10 * MS) {
                let _ = ecu.on_encoder(t, SteeringDeg(column));
                if !deg.is_nan() {
                    let _ = vehicle.send(ecu, t, as_state, deg);
                }
            }
            sent.extend(step(ecu, drive, t));
            t += MS;
        }
        sent
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
        let (mut ecu, mut drive, sent) = epos4_ecu(500);
        assert!(!sent.is_empty(), "no configuration frame at the start");
        let mut vehicle = Vehicle::new();
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            200 * MS,
            AsState::Off,
            0.0,
            0.0,
        );
        assert_eq!(ecu.link().map(|l| l.phase()), Some(Phase::Standby));
        assert_eq!(ecu.output().state, EcuState::Idle);
        assert_eq!(ecu.motor_origin_counts(), Some(500));
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            200 * MS,
            400 * MS,
            AsState::Driving,
            0.0,
            0.0,
        );
        assert_eq!(drive.state, State::OperationEnabled);
        assert_eq!(ecu.output().state, EcuState::Tracking);
        assert!(ecu.output().faults.is_empty(), "{:?}", ecu.output().faults);
        assert_eq!(drive.targets.last(), Some(&500));
        // 10 deg at the wheel, reached through the enable ramp.
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            400 * MS,
            600 * MS,
            AsState::Driving,
            10.0,
            0.0,
        );
        let scale = ecu.link().unwrap().scale();
        let want = scale
            .inc_from_motor(Gearing::PAPER.motor_from_steering(SteeringDeg(10.0).into()))
            .unwrap();
        assert_eq!(drive.targets.last(), Some(&(500 + want)));
        assert_eq!(ecu.pending_overflow(), 0);
    }

    /// The CSP target for `deg` at the wheel, in the drive's increments from the origin.
    fn inc_at(ecu: &Ecu, deg: f32) -> i32 {
        let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
        ecu.link().unwrap().scale().inc_from_motor(motor).unwrap()
    }

    /// An EPOS4-mode ECU tracking 0 deg in AS Driving at 400 ms, the drive at 500.
    fn tracking_epos4() -> (Ecu, FakeEpos4, Vehicle, u64) {
        let (mut ecu, mut drive, _) = epos4_ecu(500);
        let mut vehicle = Vehicle::new();
        let t = 400 * MS;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            t,
            AsState::Driving,
            0.0,
            0.0,
        );
        let log: Vec<_> = ecu.machine().fault_log().iter().copied().collect();
        assert_eq!(ecu.output().state, EcuState::Tracking, "{log:?}");
        (ecu, drive, vehicle, t)
    }

    /// A demand change found outside the drive calls (here the reference timeout, seen by
    /// the supervisor's tick) leaves its disable for the next drive poll: on the bus within
    /// 1 ms, before anything else.
    #[test]
    fn a_disable_decided_by_a_tick_goes_out_first_at_the_next_drive_poll() {
        let (mut ecu, mut drive, _, t0) = tracking_epos4();
        // The vehicle falls silent; the encoder and the supervisor keep running.
        let mut t = t0;
        let disabled_at = loop {
            t += MS;
            if (t - t0).is_multiple_of(2 * MS) {
                let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            }
            if ecu.tick(t).demand == DriveDemand::Disabled {
                break t;
            }
            let _ = step(&mut ecu, &mut drive, t);
            assert!(t < t0 + 200 * MS, "never disabled");
        };
        let sent = step(&mut ecu, &mut drive, disabled_at);
        assert!(sent.first().is_some_and(is_disable), "{sent:?}");
        assert_eq!(drive.state, State::SwitchOnDisabled);
        assert!(ecu.output().faults.contains(Fault::ReferenceTimeout));
    }

    /// The drive's current (TPDO2) feeds the over-current check: 30 A in the drive's 10 ms
    /// samples latches within 20 ms and disables the drive; the status and motor frames carry
    /// the drive's current.
    #[test]
    fn the_drives_current_feeds_the_over_current_check_and_the_frames() {
        let (mut ecu, mut drive, mut vehicle, t0) = tracking_epos4();
        drive.current_ma = 5_000;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t0,
            t0 + 20 * MS,
            AsState::Driving,
            0.0,
            0.0,
        );
        let protocol = ProtocolConfig::default();
        let status = protocol.decode_status(&ecu.status_frame()).unwrap();
        assert!((status.current.0 - 5.0).abs() < 0.1, "{:?}", status.current);
        let motor = protocol.decode_motor(&ecu.motor_frame()).unwrap();
        assert!(
            (motor.current_mean.0 - 5.0).abs() < 0.1,
            "{:?}",
            motor.current_mean
        );
        drive.current_ma = 30_000;
        let t1 = t0 + 20 * MS;
        let mut latched_at = None;
        for k in 0..40 {
            let t = t1 + k * MS;
            let _ = step(&mut ecu, &mut drive, t);
            if latched_at.is_none() && ecu.output().faults.contains(Fault::OverCurrent) {
                latched_at = Some(t - t1);
            }
        }
        assert!(latched_at.is_some_and(|at| at <= 20 * MS), "{latched_at:?}");
        assert_eq!(drive.state, State::SwitchOnDisabled);
    }

    /// An EMCY from the drive latches `EposFault` with its code. The failed link is not
    /// reset while the AS state is Driving; in AS Off it is reset at once and then at most
    /// once a second; back in Standby the cause is gone and a clear request clears.
    #[test]
    fn a_failed_link_is_reset_only_in_as_off_and_at_most_once_a_second() {
        let (mut ecu, mut drive, mut vehicle, t0) = tracking_epos4();
        let emcy = crate::canopen::emcy::Emcy {
            error_code: 0x3210,
            error_register: 0x04,
            vendor: [0; 5],
        }
        .to_frame(node())
        .unwrap();
        let _ = ecu.on_drive_frame(t0, &emcy);
        let out = ecu.output();
        assert!(out.faults.contains(Fault::EposFault), "{out:?}");
        let record = ecu.machine().fault_log().iter().last().copied();
        assert_eq!(
            record.map(|r| (r.fault, r.detail)),
            Some((Fault::EposFault, 0x3210))
        );
        let t1 = t0 + 2000 * MS;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t0,
            t1,
            AsState::Driving,
            0.0,
            0.0,
        );
        assert!(
            ecu.link().unwrap().error().is_some(),
            "reset while AS Driving"
        );
        // A clear asked for in AS Driving is refused, and counted.
        assert_eq!(ecu.clear_refusals(), 0);
        let f = vehicle.frame(AsState::Driving, 0.0, true);
        let _ = ecu.on_reference_frame(t1, &f);
        assert_eq!(ecu.clear_refusals(), 1);
        // AS Off: reset at once, the link is back in Standby within 100 ms.
        let t2 = t1 + 100 * MS;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t1,
            t2,
            AsState::Off,
            0.0,
            0.0,
        );
        assert_eq!(ecu.link().unwrap().phase(), Phase::Standby);
        // A second failure 100 ms later waits for the second's end (t1 + 1 s).
        let _ = ecu.on_drive_frame(t2, &emcy);
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t2,
            t1 + 990 * MS,
            AsState::Off,
            0.0,
            0.0,
        );
        assert!(
            ecu.link().unwrap().error().is_some(),
            "reset within the second"
        );
        let t3 = t1 + 1100 * MS;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t1 + 990 * MS,
            t3,
            AsState::Off,
            0.0,
            0.0,
        );
        assert_eq!(ecu.link().unwrap().phase(), Phase::Standby);
        // The cause is gone: the clear bit's rising edge clears.
        let f = vehicle.frame(AsState::Off, 0.0, true);
        let out = ecu.on_reference_frame(t3, &f);
        assert!(out.faults.is_empty(), "{:?}", out.faults);
        assert_eq!(ecu.clear_refusals(), 1);
    }

    /// EPOS4 mode: the enable ramp starts where the column is once the drive is in Operation
    /// enabled, and the CSP target then moves at most the ramp's speed toward a far reference.
    #[test]
    fn an_epos4_enable_ramps_the_target_from_the_column() {
        let (mut ecu, mut drive, _) = epos4_ecu(500);
        let mut vehicle = Vehicle::new();
        // The link comes up with no vehicle frame yet ...
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            200 * MS,
            AsState::Off,
            f32::NAN,
            0.0,
        );
        // ... which asks for 30 deg from its first frame, in AS Driving, on. The motor follows
        // each target and the column the motor (a stiff belt).
        drive.follows = true;
        let mut t = 200 * MS;
        while t < 900 * MS {
            if t.is_multiple_of(10 * MS) {
                let motor = ecu.motor_angle();
                let column = SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor));
                let _ = ecu.on_encoder(t, column);
                let _ = vehicle.send(&mut ecu, t, AsState::Driving, 30.0);
            }
            let _ = step(&mut ecu, &mut drive, t);
            t += MS;
        }
        assert!(ecu.output().faults.is_empty(), "{:?}", ecu.output().faults);
        // The ramp's speed for a 10 ms cycle, one increment of rounding.
        let per_cycle = inc_at(&ecu, ENABLE_RAMP_DPS * 0.01) + 1;
        let steps: Vec<i32> = drive.targets.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(drive.targets.first() == Some(&500), "{:?}", drive.targets);
        assert!(steps.iter().all(|s| s.abs() <= per_cycle), "{steps:?}");
        // 30 deg at the ramp's speed and acceleration: there after 0.5 s of the 0.7 s.
        assert_eq!(drive.targets.last(), Some(&(500 + inc_at(&ecu, 30.0))));
    }

    /// The origin comes from the column: a drive that powered up at 500 increments with the
    /// column at 5 deg has its column 0 at 500 less 5 deg's increments, and the ECU's motor
    /// angle reads 5 deg at the wheel.
    #[test]
    fn the_epos4_origin_is_taken_from_the_column() {
        let (mut ecu, mut drive, _) = epos4_ecu(500);
        let mut vehicle = Vehicle::new();
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            200 * MS,
            AsState::Off,
            0.0,
            5.0,
        );
        let origin = 500 - inc_at(&ecu, 5.0);
        assert_eq!(ecu.motor_origin_counts(), Some(origin));
        let wheel = SteeringDeg::from(Gearing::PAPER.steering_from_motor(ecu.motor_angle()));
        let resolution = 360.0 / inc_at(&ecu, 360.0) as f32;
        assert!((wheel.0 - 5.0).abs() <= resolution, "{wheel:?}");
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            200 * MS,
            400 * MS,
            AsState::Driving,
            5.0,
            5.0,
        );
        assert_eq!(ecu.output().state, EcuState::Tracking);
        assert_eq!(drive.targets.last(), Some(&500));
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
        let (mut ecu, mut drive, _) = epos4_ecu(500);
        let mut vehicle = Vehicle::new();
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            200 * MS,
            AsState::Off,
            f32::NAN,
            0.0,
        );
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            200 * MS,
            1200 * MS,
            AsState::Driving,
            30.0,
            0.0,
        );
        assert!(
            ecu.output().faults.contains(Fault::TrackingError),
            "{:?}",
            ecu.output()
        );
    }

    /// The ECU-mode constructors: the direct one runs the ECU-mode cascade; over an EPOS4 the
    /// drive gets Table 3's gains with the model's feedforward in mA (A x 1000), and the ECU
    /// brings it up and steers it.
    #[test]
    fn ecu_mode_runs_its_cascade_direct_and_its_feedforward_on_the_epos4() {
        let ecu = Ecu::ecu_direct().unwrap();
        assert!(matches!(
            ecu.drive(),
            Drive::Direct(SteeringController::Ecu(_))
        ));
        let gains = Ecu::ecu_mode_epos4_gains();
        assert!(
            (gains.ff_velocity_ma_s_per_rad / 1000.0 - EcuTuning::PAPER.ff_velocity).abs() < 1e-6
        );
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
        let mut ecu = Ecu::ecu_epos4(Epos4Link::new(config, 0).unwrap()).unwrap();
        let mut drive = FakeEpos4::new(500);
        for f in ecu.drive_start(0) {
            let answers = drive.on_frame(&f);
            drive.answers.extend(answers);
        }
        let mut vehicle = Vehicle::new();
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            0,
            400 * MS,
            AsState::Driving,
            0.0,
            0.0,
        );
        assert_eq!(ecu.output().state, EcuState::Tracking);
        let written = drive.od.get(&od::POSITION_FF_VELOCITY).copied();
        assert_eq!(
            written,
            Some((gains.ff_velocity_ma_s_per_rad * 1000.0).round() as u32)
        );
        assert_eq!(drive.targets.last(), Some(&500));
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
        let (mut ecu, mut drive, _) = epos4_ecu(0);
        let _ = step(&mut ecu, &mut drive, MS);
        let _ = step(&mut ecu, &mut drive, 2 * MS);
        assert_eq!(ecu.progress().fast, 2);
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
        let (mut ecu, mut drive, mut vehicle, t0) = tracking_epos4();
        let emcy = crate::canopen::emcy::Emcy {
            error_code: 0x3210,
            error_register: 0x04,
            vendor: [0; 5],
        }
        .to_frame(node())
        .unwrap();
        let _ = ecu.on_drive_frame(t0, &emcy);
        // Still in AS Driving (no reset): the link stays failed for 20 ms of drive polls.
        let t1 = t0 + 20 * MS;
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t0,
            t1,
            AsState::Driving,
            0.0,
            0.0,
        );
        assert!(ecu.link().unwrap().error().is_some());
        // AS Off and a clear at once, before the next drive poll resets the link: refused.
        let _ = vehicle.send(&mut ecu, t1, AsState::Off, 0.0);
        let f = vehicle.frame(AsState::Off, 0.0, true);
        let out = ecu.on_reference_frame(t1, &f);
        assert!(
            out.faults.contains(Fault::EposFault),
            "cleared while failed"
        );
        // The bit low again, so the next request is a rising edge.
        let _ = vehicle.send(&mut ecu, t1, AsState::Off, 0.0);
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
                let _ = ecu.on_encoder(t, SteeringDeg(0.0));
                let _ = vehicle.send(&mut ecu, t, AsState::Off, 0.0);
            }
            let mut sent = Vec::new();
            for answer in std::mem::take(&mut drive.answers) {
                sent.extend(ecu.on_drive_frame(t, &answer));
                if up(&ecu) {
                    break 'up;
                }
            }
            sent.extend(ecu.drive_poll(t));
            if up(&ecu) {
                break;
            }
            for f in &sent {
                let answers = drive.on_frame(f);
                drive.answers.extend(answers);
            }
        }
        let f = vehicle.frame(AsState::Off, 0.0, true);
        let out = ecu.on_reference_frame(t, &f);
        assert!(out.faults.is_empty(), "{:?}", out.faults);
    }

    /// EPOS4 mode: after 120 ms without frames the vehicle's next frame is 48 deg away (the
    /// E2E budget allows it); the drive's target moves at most the 400 deg/s rate times the
    /// 10 ms SYNC cycle, however the frames fall between SYNCs.
    #[test]
    fn after_a_gap_the_epos4_target_moves_at_the_rate_limit() {
        let (mut ecu, mut drive, mut vehicle, t) = tracking_epos4();
        drive.follows = true;
        let before = drive.targets.len();
        // Silence, then 48 deg, on time again.
        let _ = run(
            &mut ecu,
            &mut drive,
            &mut vehicle,
            t,
            t + 120 * MS,
            AsState::Driving,
            f32::NAN,
            0.0,
        );
        let start = t + 120 * MS;
        let mut t = start;
        while t < start + 200 * MS {
            if t.is_multiple_of(10 * MS) {
                let motor = ecu.motor_angle();
                let column = SteeringDeg::from(Gearing::PAPER.steering_from_motor(motor));
                let _ = ecu.on_encoder(t, column);
                let _ = vehicle.send(&mut ecu, t, AsState::Driving, 48.0);
            }
            let _ = step(&mut ecu, &mut drive, t);
            t += MS;
        }
        assert!(ecu.output().faults.is_empty(), "{:?}", ecu.output().faults);
        let per_cycle = inc_at(&ecu, 4.0) + 1;
        let steps: Vec<i32> = drive.targets[before..]
            .windows(2)
            .map(|w| w[1] - w[0])
            .collect();
        assert!(steps.iter().all(|s| s.abs() <= per_cycle), "{steps:?}");
        assert_eq!(drive.targets.last(), Some(&(500 + inc_at(&ecu, 48.0))));
    }
}

// The reference's rate limit, end to end: what the controller is handed, whatever the frames do.
#[cfg(test)]
mod rate_limit_tests {
    use super::tests::Vehicle;
    use super::*;
    use proptest::prelude::*;

    const MS: u64 = 1000;
    /// The position tick, us (2 kHz).
    const TICK_US: u64 = 500;

    /// What the vehicle does next, after `gap_us` of silence.
    #[derive(Debug, Clone)]
    enum Send {
        /// One frame stepping `frac` of the E2E budget for the gap (beyond 1: refused).
        Step { frac: f32 },
        /// `n` frames 200 us apart, each stepping `frac` of a period's budget.
        Burst { n: u8, frac: f32 },
        /// `n` frames with a broken CRC (the counter still advances), 200 us apart.
        Junk { n: u8 },
    }

    fn send() -> impl Strategy<Value = (u64, Send)> {
        let gap = prop_oneof![
            4 => Just(10 * MS),
            3 => 0u64..=125 * MS,
            1 => prop_oneof![Just(40 * MS), Just(80 * MS), Just(120 * MS), Just(125 * MS)],
        ];
        let what = prop_oneof![
            6 => (-1.2f32..1.2).prop_map(|frac| Send::Step { frac }),
            2 => (2u8..6, -1.0f32..1.0).prop_map(|(n, frac)| Send::Burst { n, frac }),
            1 => (1u8..5).prop_map(|n| Send::Junk { n }),
        ];
        (gap, what)
    }

    fn setpoint_deg(ecu: &Ecu) -> f32 {
        let Drive::Direct(cascade) = ecu.drive() else {
            panic!("direct mode")
        };
        SteeringDeg::from(Gearing::PAPER.steering_from_motor(cascade.setpoint().position)).0
    }

    fn hall_at(deg: f32) -> i32 {
        let motor = Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into());
        hall_from_motor(f64::from(motor.0))
    }

    /// The direct-drive car as the firmware runs it: position ticks at 2 kHz, column samples
    /// at 500 Hz, a motor and column that follow the set-point exactly. The vehicle's frames
    /// come as `script` says. Every set-point step (wheel deg) taken while the drive stayed
    /// on, with the time it was taken, and the faults latched at the end.
    fn run(script: &[(u64, Send)]) -> (Vec<(u64, f32)>, crate::faults::FaultSet) {
        let mut ecu = Ecu::paper().expect("paper ECU");
        let rate = ecu.protocol.max_rate_deg_per_s;
        let mut vehicle = Vehicle::new();
        // Frames due: (time, angle, junk).
        let mut due: Vec<(u64, f32, bool)> = (0..5).map(|k| (k * 10 * MS, 0.0, false)).collect();
        let mut t_frame = 40 * MS;
        let mut angle = 0.0f32;
        for (gap, what) in script {
            t_frame += gap;
            match *what {
                Send::Step { frac } => {
                    let budget = rate * (*gap).max(10 * MS) as f32 * 1e-6;
                    angle = (angle + frac * budget).clamp(-85.0, 85.0);
                    due.push((t_frame, angle, false));
                }
                Send::Burst { n, frac } => {
                    for k in 0..u64::from(n) {
                        angle = (angle + frac * rate * 0.01).clamp(-85.0, 85.0);
                        due.push((t_frame + k * 200, angle, false));
                    }
                    t_frame += u64::from(n) * 200;
                }
                Send::Junk { n } => {
                    for k in 0..u64::from(n) {
                        due.push((t_frame + k * 200, angle, true));
                    }
                    t_frame += u64::from(n) * 200;
                }
            }
        }
        // Then on time again, at the last angle, for 200 ms.
        for k in 1..=20 {
            due.push((t_frame + k * 10 * MS, angle, false));
        }
        let end = t_frame + 200 * MS;
        let mut steps = Vec::new();
        let mut next = due.iter().peekable();
        let mut position = 0.0f32;
        let mut on_before = false;
        let mut t = 0;
        while t <= end {
            if t.is_multiple_of(2 * MS) {
                let _ = ecu.on_encoder(t, SteeringDeg(position));
            }
            while let Some(&&(at, deg, junk)) = next.peek() {
                if at > t {
                    break;
                }
                let mut f = vehicle.frame(AsState::Driving, deg, false);
                if junk {
                    let mut bytes: [u8; 8] = f.data().try_into().expect("8 bytes");
                    bytes[0] ^= 0x5A;
                    f = Frame::new(f.id(), &bytes).expect("a frame");
                }
                let _ = ecu.on_reference_frame(at, &f);
                next.next();
            }
            if t.is_multiple_of(2 * MS) {
                let _ = ecu.tick(t);
            }
            let on = ecu.output().demand != DriveDemand::Disabled;
            let _ = ecu.position_tick(hall_at(position));
            let setpoint = setpoint_deg(&ecu);
            if on && on_before {
                steps.push((t, setpoint - position));
            }
            if on {
                // The motor and the column are where the set-point was.
                position = setpoint;
            }
            on_before = on;
            t += TICK_US;
        }
        (steps, ecu.output().faults)
    }

    fn assert_within_rate(steps: &[(u64, f32)]) -> Result<(), TestCaseError> {
        let limit = ProtocolConfig::default().max_rate_deg_per_s * TICK_US as f32 * 1e-6;
        for &(t, step) in steps {
            prop_assert!(
                step.abs() <= limit + 1e-3,
                "the set-point moved {step} deg in one {TICK_US} us tick at {t} us (limit {limit})"
            );
        }
        Ok(())
    }

    /// The cases the audit measured: 40/80/120/125 ms without frames, then a step of the whole
    /// budget; four junk frames, then a 20 deg step.
    #[test]
    fn after_a_gap_the_set_point_ramps_at_the_rate_limit() {
        for gap in [40, 80, 120, 125] {
            let (steps, faults) = run(&[(gap * MS, Send::Step { frac: 1.0 })]);
            assert_within_rate(&steps).unwrap();
            assert!(faults.is_empty(), "after {gap} ms: {faults:?}");
        }
        let (steps, _) = run(&[
            (10 * MS, Send::Junk { n: 4 }),
            (10 * MS, Send::Step { frac: 0.5 }),
            (0, Send::Step { frac: 0.0 }),
        ]);
        assert_within_rate(&steps).unwrap();
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Whatever the frame timing (gaps of 0 to 125 ms, bursts, junk frames, Hold and back
        /// to Track), the set-point the cascade is handed never moves more than 400 deg/s
        /// times its tick.
        #[test]
        fn the_set_point_never_moves_faster_than_the_rate_limit(
            script in prop::collection::vec(send(), 1..40)
        ) {
            assert_within_rate(&run(&script).0)?;
        }
    }
}

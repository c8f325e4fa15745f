//! The steering state machine: from the AS state, the reference's freshness and the fault
//! detectors to what the drive must do ([`DriveDemand`]). Pure logic; time enters as an
//! argument (`now_us`, µs on any monotonic clock), so the firmware's tasks and host-sim's
//! tests drive the same code.
//!
//! # Theory of operation
//!
//! Every entry point (an event such as [`SteeringStateMachine::on_reference`], or the periodic
//! [`SteeringStateMachine::tick`]) first applies the time-based rules up to `now_us`, then the
//! event, and returns the [`Output`] that holds from then on. The demand is recomputed from
//! scratch on every call by one function, so there is no path to [`DriveDemand::Track`] other
//! than: no latched fault, an AS state that allows power (Ready or Driving under the FS rules,
//! the default; Driving only under the FSAE DV supplement: [`Config::with_actuation`]), a valid reference
//! frame within the reference timeout, and a column-encoder sample within the encoder timeout.
//!
//! ```text
//!                      AS Ready/Driving, valid frame <= 30 ms ago,
//!   +---------+        encoder fresh, no fault                 +----------+
//!   |  Idle   | --------------------------------------------> | Tracking |<-----+
//!   |Disabled | <-------------------------------------------- |  Track   |      |
//!   +---------+        AS Off / Manual / Finished             +----------+      |
//!     ^   |  AS Ready/Driving but no fresh        no valid frame |              | valid frame
//!     |   v  reference or encoder yet             for > 30 ms    v              | again
//!   +---------+                                               +----------+      |
//!   | Standby |                                               | Holding  |------+
//!   |Disabled |                                               |   Hold   |
//!   +---------+                                               +----------+
//!     ^                                     no valid frame for > 130 ms |
//!     |  request_clear_faults():              (ReferenceTimeout)        v
//!     |  AS Off and every cause gone                              +----------+
//!     +---------------------------------------------------------- | Faulted  |
//!                                      any fault, from any state: | Disabled |
//!                                      same call                  +----------+
//!
//!   AS Emergency, from any state, in the same call ----> Emergency (Disabled), latched:
//!   every AS state but Off after it still reads Emergency; AS Off ----> Idle
//! ```
//!
//! What the drive does ([`DriveDemand`]): `Disabled` = bridge off / EPOS4 "disable voltage",
//! zero current, the reversible ball screw lets the driver (or the tyres' self-aligning torque)
//! turn the wheels; `Hold` = position loop on, on the last reference sample, no new samples;
//! `Track` = position loop on, following the reference.
//!
//! Status code of each state ([`EcuState::code`], the status frame): Idle 0, Standby 1,
//! Tracking 2, Holding 3, Emergency 4, Faulted 5, Arming 6 (EPOS4 mode: power demanded, the
//! drive not in Operation enabled yet; the ECU reports it, this machine never does). With AS Emergency and a latched fault at once
//! the state reads Emergency; the fault bits still carry the faults.
//!
//! ## Reference timeout timeline
//!
//! ```text
//!   t = 0 ms       last valid reference frame                          Track
//!   0 < t <= 30    3 reference periods: the set-point ramps to the      Track
//!                  last sample and stays there (reference.rs)
//!   30 < t <= 130  hold: position loop on the last sample; a valid      Hold
//!                  frame in this window returns to Track, no fault
//!   t > 130        drive disabled, ReferenceTimeout latched             Disabled
//! ```
//!
//! Decisions are taken when the machine is called, so their resolution is the calling period:
//! the firmware calls [`SteeringStateMachine::tick`] at the position-loop rate (2 kHz), and at
//! no less than 100 Hz in any case.
//!
//! Why hold 100 ms (default, [`DEFAULT_HOLD_US`]): long enough to ride through a short gap (ten
//! reference periods: an overrun of the vehicle computer's task, an error burst on the bus)
//! without dropping the steering in a corner; short enough that the car does not drive on a
//! frozen angle for long (at 15 m/s it covers 2 m in the 130 ms). After that the drive is
//! disabled: the wheels are free and the tyres' self-aligning torque centres them while the
//! vehicle computer, which sees the fault bit, brings the car to AS Emergency (EBS).
//! Holding only follows tracking: a drive that was not steering is not switched on to hold.
//!
//! ## Faults
//!
//! A fault latches (the drive is disabled in the same call, a [`FaultRecord`] goes into the
//! [`FaultLog`]) and stays latched until [`SteeringStateMachine::request_clear_faults`]
//! succeeds, which it does only in AS Off (known from a frame within the reference timeout)
//! and once the cause of every latched fault is gone.
//!
//! | fault | detection | cause gone when |
//! |---|---|---|
//! | `ReferenceTimeout` | AS Ready/Driving and no valid frame for 130 ms (30 + hold), counted from the later of the last frame and the moment the AS state allowed power | a valid frame is fresh |
//! | `InvalidFrames` | the protocol layer's invalid-frame score (+1 invalid, -1 valid) reaches its limit | a valid frame arrives |
//! | `Encoder` | the sensor reports an error, a reading is not finite, or no sample for 30 ms while AS Ready/Driving | a finite sample arrives |
//! | `EncoderJump` | column moved more than `1 deg + 1000 deg/s x dt` since the previous sample | the next sample is plausible |
//! | `EncoderMotorDisagreement` | \|column - motor / gear ratio\| > 15 deg for 20 ms | a sample within the window |
//! | `OverCurrent` | \|I\| > 22 A (or not a number) in 20 consecutive samples, or in a run of consecutive samples lasting 10 ms (the EPOS4's 10 ms current samples) | a sample within the threshold |
//! | `EposFault` | statusword fault bit or an EMCY from the EPOS4 | the firmware reports the EPOS4 fault reset done |
//! | `HeartbeatLost` | the CANopen consumer-heartbeat time of the EPOS4 elapsed | a heartbeat arrives |
//! | `BusOff` | the CAN controller reports bus-off | bus recovered, or a valid frame arrives |
//! | `Origin` | at an enable, the column samples of the last 16 ms disagree on the motor origin by more than one encoder count (plus one motor count) from their median ([`crate::ecu::ORIGIN_WINDOW_US`]): the enable is refused; or, drive on and resting (column and motor each within 0.2 deg, \|effort\| <= 2 A for 100 ms), \|column - motor / gear ratio\| > 2.5 deg ([`crate::ecu::ORIGIN_REST_BOUND_DEG`]) | judged afresh at each enable |
//! | `TrackingError` | drive on, \|column - reference\| > 20 deg for 200 ms and the column not closing the gap at 30 deg/s; or (runaway) the current pushing toward the reference at 18 A or more for 50 ms while the column still moves away at 20 deg/s or more, no slower than when the push began | a sample within the window, or the drive off |
//!
//! The plausibility checks (jump, disagreement, current) run in every AS state: a broken
//! sensor is found in AS Off, before the car is handed to the autonomous system.
//!
//! A panic is not a fault here: the firmware's panic handler turns the bridge off (EPOS4
//! disabled, PWM outputs low) and resets the MCU, so nothing of this machine runs after it.
//! After the reset the machine starts in Idle with no fault and no reference, so the drive
//! stays disabled until the vehicle computer sends fresh frames in AS Ready or Driving.
//!
//! ## Defaults and why
//!
//! - Reference timeout 30 ms ([`DEFAULT_REFERENCE_TIMEOUT_US`]): three periods of the 100 Hz
//!   reference (issue).
//! - Encoder timeout 30 ms ([`DEFAULT_ENCODER_TIMEOUT_US`]): the same rule as the reference; at
//!   2 kHz that is 60 missed samples, at 100 Hz three.
//! - Encoder jump ([`DEFAULT_JUMP_FLOOR_DEG`], [`DEFAULT_MAX_COLUMN_RATE_DPS`]): the motor
//!   turns at most 24 V / ke = 457 rad/s, 5.35 rad/s = 306 deg/s at the wheel (375 deg/s on a
//!   full 29.4 V pack); a driver back-driving the reversible screw, or a kerb strike, may be
//!   faster, so 1000 deg/s. The 1 deg floor is 11 counts of the 12-bit encoder (quantisation and
//!   a noisy LSB). The limit is 1.5 deg between 2 kHz samples, 11 deg between 100 Hz samples.
//! - Disagreement window 15 deg at the wheel ([`DEFAULT_DISAGREEMENT_DEG`]): the window must
//!   exceed what the plant's compliance lets the two angles differ by in normal operation.
//!   20 A is 1.05 Nm at the motor, 2.1 Nm at the nut through the 2:1 belt; the identified belt
//!   stiffness kB = 0.29 Nm/rad (Table 4, at the nut) lets the nut lag the motor by 7.2 rad,
//!   which is 7.2 x tauBS / tauP = 0.17 rad = 9.7 deg at the wheel (Table 2). Add the dead band
//!   (backlash, about 1 deg), the twist of the column's torsion bar under the steering wheel's
//!   damping when the wheel moves fast (about 3 deg at 5 Hz, 10 deg), and the quantisation
//!   (0.05 deg Hall, 0.09 deg encoder): 14 deg. host-sim's plant (Table 4, no backlash)
//!   agrees: the column and motor / gear ratio differ by up to 10.3 deg on the 80 deg step at
//!   20 A, 9.5 deg in the sweep and 9.1 deg on the track run, so a 5 deg window would trip
//!   in normal driving. 15 deg leaves a little margin; the persistence
//!   of 20 ms ([`DEFAULT_DISAGREEMENT_PERSIST_US`]) rides out single bad samples. What it
//!   catches: a broken or badly skipping belt, lost Hall counts, a slipped encoder magnet.
//!   Tighten it once a bench log shows the real difference.
//! - Over-current 22 A for 20 samples ([`DEFAULT_OVERCURRENT`],
//!   [`DEFAULT_OVERCURRENT_SAMPLES`]): the current loop keeps |I| below the 20 A limit
//!   (measured peak 19.95 A in host-sim), so 10 % above it means the loop has lost control of
//!   the current (bridge fault, sensor, EPOS4). 20 samples are 1 ms at 20 kHz or 10 ms at
//!   2 kHz: long enough to ignore a single spike, short against the winding's thermal time.
//! - Tracking error 20 deg for 200 ms without 30 deg/s of progress ([`DEFAULT_TRACKING_DEG`],
//!   [`DEFAULT_TRACKING_PERSIST_US`], [`DEFAULT_TRACKING_PROGRESS_DPS`]): the other checks
//!   compare sensors with each other; this one compares the actuator with its order. host-sim
//!   found the case: a current-sense amplifier reading 30 A high makes the current loop drive
//!   -10 A for ever, the column runs to the end stop, and neither the over-current check (the
//!   measured current is within 20 A) nor the disagreement check (column and motor agree) sees
//!   it. Normal errors stay below it: 10.7 deg at most on the track run, and in the 10 deg
//!   sweep the error changes sign faster than 200 ms. An error the actuator is closing (a
//!   large reference step, a ramp at the 400 deg/s the protocol allows against the motor's
//!   306 deg/s) is not a fault: the column must move toward the reference by less than
//!   30 deg/s over the 200 ms, i.e. stand still (jammed) or run away (lost control).

use crate::as_state::{Actuation, AsState};
use crate::faults::{EncoderFaultDetail, Fault, FaultLog, FaultRecord, FaultSet};
use crate::gearing::Gearing;
use crate::units::{Amps, MotorRad, SteeringDeg};

/// No valid reference for this long leaves active steering (3 periods of 100 Hz).
pub const DEFAULT_REFERENCE_TIMEOUT_US: u32 = 30_000;
/// After the reference timeout, hold the last position this long, then disable and latch.
pub const DEFAULT_HOLD_US: u32 = 100_000;
/// No column-encoder sample for this long while the AS state allows power latches a fault.
pub const DEFAULT_ENCODER_TIMEOUT_US: u32 = 30_000;
/// Column-encoder jump allowed between two samples however close they are, deg at the wheel.
pub const DEFAULT_JUMP_FLOOR_DEG: f32 = 1.0;
/// Fastest plausible column speed, deg/s at the wheel.
pub const DEFAULT_MAX_COLUMN_RATE_DPS: f32 = 1000.0;
/// Column encoder vs motor angle / gear ratio, deg at the wheel.
pub const DEFAULT_DISAGREEMENT_DEG: f32 = 15.0;
/// The disagreement must last this long to latch.
pub const DEFAULT_DISAGREEMENT_PERSIST_US: u32 = 20_000;
/// Measured |I| above this is an over-current sample.
pub const DEFAULT_OVERCURRENT: Amps = Amps(22.0);
/// Consecutive over-current samples that latch the fault.
pub const DEFAULT_OVERCURRENT_SAMPLES: u16 = 20;
/// ... or a run of over-current samples (at least two) lasting this long, µs, whatever the
/// sample rate: the EPOS4's current comes once per 10 ms SYNC, where 20 samples would be
/// 200 ms; two samples 10 ms apart latch within 20 ms of the first (issue 12). At 20 kHz the
/// 20 samples (1 ms) come first.
pub const OVERCURRENT_PERSIST_US: u64 = 10_000;
/// |column - reference| beyond this is a tracking error candidate, deg at the wheel.
pub const DEFAULT_TRACKING_DEG: f32 = 20.0;
/// ... for this long, µs ...
pub const DEFAULT_TRACKING_PERSIST_US: u32 = 200_000;
/// ... while the column closes the gap slower than this, deg/s.
pub const DEFAULT_TRACKING_PROGRESS_DPS: f32 = 30.0;
/// Runaway: the current toward the reference at least this (90 % of the 20 A loop limit: the
/// loop is saturated, pushing with all it has) ...
pub const RUNAWAY_CURRENT: Amps = Amps(18.0);
/// ... for this long, µs (issue 12: within 50 ms) ...
pub const RUNAWAY_PERSIST_US: u32 = 50_000;
/// ... while the column still moves away from the reference at least this fast, deg/s, over
/// the last [`RUNAWAY_SPEED_WINDOW_US`]. A column that only coasts on (the motor decelerating
/// after a reversal of the reference: at most about 44 ms from full speed at 20 A) is moving
/// toward the reference again after 50 ms; 20 deg/s is 2.3 encoder counts per 10 ms, above
/// the quantisation.
pub const RUNAWAY_AWAY_DPS: f32 = 20.0;
/// The speed of [`RUNAWAY_AWAY_DPS`] is measured over at least this, µs (5 encoder samples).
pub const RUNAWAY_SPEED_WINDOW_US: u32 = 10_000;
/// A runaway's motion away does not slow under the push; this much slower than when the push
/// began still counts as not slowing, deg/s: one 12-bit encoder count (0.088 deg) per
/// [`RUNAWAY_SPEED_WINDOW_US`], the speed measurement's resolution.
pub const RUNAWAY_SLOWING_SLACK_DPS: f32 = 360.0 / 4096.0 / (RUNAWAY_SPEED_WINDOW_US as f32 * 1e-6);

/// The detail of a [`Fault::Origin`] found by the resting cross-check is its difference in
/// centi-degrees moved this far from 0 (with its sign), so it reads apart from the spread of
/// the samples at an enable (always below it).
pub const ORIGIN_RESTING_DETAIL: i32 = 1_000_000;

/// What the drive must do from this call on.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum DriveDemand {
    /// Bridge off (EPOS4 "disable voltage"), zero current: the driver can steer.
    Disabled,
    /// Position loop on, holding the last reference sample; no new samples are pushed.
    Hold,
    /// Position loop on, following the reference.
    Track,
}

/// The ECU's state as reported in the status frame ([`EcuState::code`]).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum EcuState {
    /// AS Off, Manual, Finished or not yet known; no fault. Drive disabled.
    Idle = 0,
    /// AS Ready or Driving, no fault, but no fresh reference or encoder sample. Disabled.
    Standby = 1,
    /// Following the reference.
    Tracking = 2,
    /// Reference stale: holding the last sample.
    Holding = 3,
    /// AS Emergency. Disabled.
    Emergency = 4,
    /// A fault is latched. Disabled.
    Faulted = 5,
    /// EPOS4 mode: the machine demands power (it would read Tracking or Holding) but the
    /// drive is not in Operation enabled yet (the link is still bringing it up or walking
    /// CiA 402); the wheels are not steered. Set by [`crate::ecu::Ecu`], which knows the link.
    Arming = 6,
}

impl EcuState {
    /// The status-frame code; stable.
    pub const fn code(self) -> u8 {
        self as u8
    }

    /// `None` for codes no state has.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(EcuState::Idle),
            1 => Some(EcuState::Standby),
            2 => Some(EcuState::Tracking),
            3 => Some(EcuState::Holding),
            4 => Some(EcuState::Emergency),
            5 => Some(EcuState::Faulted),
            6 => Some(EcuState::Arming),
            _ => None,
        }
    }
}

/// The result of every call: apply `demand` at once.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[must_use = "the demand must reach the drive; a latched fault disables it in this very call"]
pub struct Output {
    pub demand: DriveDemand,
    pub state: EcuState,
    /// Latched faults (the status frame's fault bits).
    pub faults: FaultSet,
    /// True on the call where the demand leaves `Disabled`: reset the cascade to the measured
    /// motor angle ([`crate::paper_mode::Cascade::reset`]) before its next position step, so
    /// the loop starts where the motor is, with empty integrators.
    pub drive_just_enabled: bool,
}

/// A configuration value that was refused; the field names it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// A time that must be at least 1 µs was zero.
    ZeroTime { field: &'static str },
    /// A count that must be at least 1 was zero.
    ZeroCount { field: &'static str },
    /// A value that must be finite and positive (or non-negative, see the setter) was not.
    NotPositive { field: &'static str },
}

/// Thresholds and times of the state machine. Built from [`Config::DEFAULT`] through the
/// checked `with_*` setters, so an invalid value cannot get in.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Config {
    reference_timeout_us: u32,
    hold_us: u32,
    encoder_timeout_us: u32,
    jump_floor_deg: f32,
    max_column_rate_dps: f32,
    disagreement_deg: f32,
    disagreement_persist_us: u32,
    overcurrent: Amps,
    overcurrent_samples: u16,
    tracking_deg: f32,
    tracking_persist_us: u32,
    tracking_progress_dps: f32,
    gearing: Gearing,
    actuation: Actuation,
}

impl Default for Config {
    fn default() -> Self {
        Self::DEFAULT
    }
}

fn positive(x: f32, field: &'static str) -> Result<f32, ConfigError> {
    if x.is_finite() && x > 0.0 {
        Ok(x)
    } else {
        Err(ConfigError::NotPositive { field })
    }
}

impl Config {
    /// The defaults of the module documentation, with the paper's gear chain.
    pub const DEFAULT: Config = Config {
        reference_timeout_us: DEFAULT_REFERENCE_TIMEOUT_US,
        hold_us: DEFAULT_HOLD_US,
        encoder_timeout_us: DEFAULT_ENCODER_TIMEOUT_US,
        jump_floor_deg: DEFAULT_JUMP_FLOOR_DEG,
        max_column_rate_dps: DEFAULT_MAX_COLUMN_RATE_DPS,
        disagreement_deg: DEFAULT_DISAGREEMENT_DEG,
        disagreement_persist_us: DEFAULT_DISAGREEMENT_PERSIST_US,
        overcurrent: DEFAULT_OVERCURRENT,
        overcurrent_samples: DEFAULT_OVERCURRENT_SAMPLES,
        tracking_deg: DEFAULT_TRACKING_DEG,
        tracking_persist_us: DEFAULT_TRACKING_PERSIST_US,
        tracking_progress_dps: DEFAULT_TRACKING_PROGRESS_DPS,
        gearing: Gearing::PAPER,
        actuation: Actuation::ReadyOrDriving,
    };

    /// Reference timeout, µs (at least 1).
    pub fn with_reference_timeout_us(mut self, us: u32) -> Result<Self, ConfigError> {
        if us == 0 {
            return Err(ConfigError::ZeroTime {
                field: "reference_timeout_us",
            });
        }
        self.reference_timeout_us = us;
        Ok(self)
    }

    /// Hold time after the reference timeout, µs; 0 disables at the timeout.
    pub fn with_hold_us(mut self, us: u32) -> Self {
        self.hold_us = us;
        self
    }

    /// Encoder timeout, µs (at least 1).
    pub fn with_encoder_timeout_us(mut self, us: u32) -> Result<Self, ConfigError> {
        if us == 0 {
            return Err(ConfigError::ZeroTime {
                field: "encoder_timeout_us",
            });
        }
        self.encoder_timeout_us = us;
        Ok(self)
    }

    /// Encoder-jump limit `floor_deg + max_rate_dps x dt`; both finite and positive.
    pub fn with_encoder_jump(
        mut self,
        floor_deg: f32,
        max_rate_dps: f32,
    ) -> Result<Self, ConfigError> {
        self.jump_floor_deg = positive(floor_deg, "jump_floor_deg")?;
        self.max_column_rate_dps = positive(max_rate_dps, "max_column_rate_dps")?;
        Ok(self)
    }

    /// Disagreement window (finite, positive, deg at the wheel) and how long it must be
    /// exceeded to latch (0 = on the first sample beyond it).
    pub fn with_disagreement(
        mut self,
        window: SteeringDeg,
        persist_us: u32,
    ) -> Result<Self, ConfigError> {
        self.disagreement_deg = positive(window.0, "disagreement_deg")?;
        self.disagreement_persist_us = persist_us;
        Ok(self)
    }

    /// Tracking-error window (finite, positive, deg at the wheel), persistence (µs) and the
    /// progress toward the reference below which the error is a fault (finite, positive,
    /// deg/s).
    pub fn with_tracking(
        mut self,
        window: SteeringDeg,
        persist_us: u32,
        progress_dps: f32,
    ) -> Result<Self, ConfigError> {
        self.tracking_deg = positive(window.0, "tracking_deg")?;
        self.tracking_progress_dps = positive(progress_dps, "tracking_progress_dps")?;
        self.tracking_persist_us = persist_us;
        Ok(self)
    }

    /// Over-current threshold (finite, positive) and consecutive samples to latch (>= 1).
    pub fn with_overcurrent(mut self, threshold: Amps, samples: u16) -> Result<Self, ConfigError> {
        self.overcurrent = Amps(positive(threshold.0, "overcurrent")?);
        if samples == 0 {
            return Err(ConfigError::ZeroCount {
                field: "overcurrent_samples",
            });
        }
        self.overcurrent_samples = samples;
        Ok(self)
    }

    /// Which AS states may power the drive ([`Actuation`]; default FS: Ready or Driving).
    pub fn with_actuation(mut self, actuation: Actuation) -> Self {
        self.actuation = actuation;
        self
    }

    pub fn actuation(&self) -> Actuation {
        self.actuation
    }

    /// The gear chain for the disagreement check (already validated by [`Gearing::new`]).
    pub fn with_gearing(mut self, gearing: Gearing) -> Self {
        self.gearing = gearing;
        self
    }

    pub fn reference_timeout_us(&self) -> u32 {
        self.reference_timeout_us
    }
    pub fn hold_us(&self) -> u32 {
        self.hold_us
    }
    pub fn encoder_timeout_us(&self) -> u32 {
        self.encoder_timeout_us
    }
    /// (floor deg, max rate deg/s)
    pub fn encoder_jump(&self) -> (f32, f32) {
        (self.jump_floor_deg, self.max_column_rate_dps)
    }
    /// (window, persistence µs)
    pub fn disagreement(&self) -> (SteeringDeg, u32) {
        (
            SteeringDeg(self.disagreement_deg),
            self.disagreement_persist_us,
        )
    }
    /// (threshold, consecutive samples)
    pub fn overcurrent(&self) -> (Amps, u16) {
        (self.overcurrent, self.overcurrent_samples)
    }
    pub fn gearing(&self) -> Gearing {
        self.gearing
    }
}

/// Why [`SteeringStateMachine::request_clear_faults`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ClearRefused {
    /// Faults clear only in AS Off, known from a frame within the reference timeout. `as_state`
    /// is the last one received (`None`: none yet); `stale` is true if it is too old.
    NotInAsOff {
        as_state: Option<AsState>,
        stale: bool,
    },
    /// The cause of these latched faults is still there.
    CauseActive { faults: FaultSet },
}

/// The steering state machine. See the module documentation.
#[derive(Debug, Clone)]
pub struct SteeringStateMachine {
    config: Config,
    /// Latest time seen; earlier stamps (an event processed late) are taken as this.
    now_us: u64,
    as_state: Option<AsState>,
    last_as_us: Option<u64>,
    /// When the AS state last became one that allows power; `None` while it does not.
    powered_since_us: Option<u64>,
    last_reference_us: Option<u64>,
    last_encoder_us: Option<u64>,
    /// Previous plausible-or-not column sample, for the jump check: (time, deg).
    previous_column: Option<(u64, f32)>,
    disagreement_since_us: Option<u64>,
    /// Start of the current tracking-error interval: (time, column deg).
    tracking_since: Option<(u64, f32)>,
    /// Since when the current has pushed toward the reference at [`RUNAWAY_CURRENT`].
    runaway_since: Option<u64>,
    /// A column sample for the speed away: (time, deg), and the last speed away, deg/s.
    runaway_probe: Option<(u64, f32)>,
    away_dps: f32,
    /// The column's speed away from the reference when the saturated push began, deg/s.
    away_at_push_dps: f32,
    /// The sign of the error the push began on (+1 toward positive angles).
    push_direction: f32,
    overcurrent_count: u16,
    /// When the current over-current run began.
    overcurrent_since_us: Option<u64>,
    latched: FaultSet,
    /// Faults whose cause is present now (latched or not yet).
    active: FaultSet,
    log: FaultLog,
    last_demand: DriveDemand,
    hold_entries: u16,
}

impl Default for SteeringStateMachine {
    fn default() -> Self {
        Self::new(Config::DEFAULT)
    }
}

/// µs to ms for a record's detail, saturated.
fn ms_detail(us: u64) -> i32 {
    (us / 1000).min(i32::MAX as u64) as i32
}

/// Degrees to centi-degrees for a record's detail; `as` saturates and maps NaN to 0.
fn centideg_detail(deg: f32) -> i32 {
    (deg * 100.0) as i32
}

impl SteeringStateMachine {
    /// Starts in Idle: no AS state, no reference, no fault, drive disabled.
    pub fn new(config: Config) -> Self {
        SteeringStateMachine {
            config,
            now_us: 0,
            as_state: None,
            last_as_us: None,
            powered_since_us: None,
            last_reference_us: None,
            last_encoder_us: None,
            previous_column: None,
            disagreement_since_us: None,
            tracking_since: None,
            runaway_since: None,
            runaway_probe: None,
            away_dps: 0.0,
            away_at_push_dps: 0.0,
            push_direction: 0.0,
            overcurrent_count: 0,
            overcurrent_since_us: None,
            latched: FaultSet::EMPTY,
            active: FaultSet::EMPTY,
            log: FaultLog::new(),
            last_demand: DriveDemand::Disabled,
            hold_entries: 0,
        }
    }

    pub fn config(&self) -> &Config {
        &self.config
    }

    /// The latched faults.
    pub fn faults(&self) -> FaultSet {
        self.latched
    }

    /// The last AS state received, if any.
    pub fn as_state(&self) -> Option<AsState> {
        self.as_state
    }

    pub fn fault_log(&self) -> &FaultLog {
        &self.log
    }

    /// For a read-out that consumes the log ([`FaultLog::pop_oldest`], [`FaultLog::clear`]).
    pub fn fault_log_mut(&mut self) -> &mut FaultLog {
        &mut self.log
    }

    /// How often the drive went from Track to Hold (saturating): reference gaps that were
    /// ridden through or ended in a timeout.
    pub fn hold_entries(&self) -> u16 {
        self.hold_entries
    }

    /// Periodic call (at least 100 Hz; the firmware uses the 2 kHz position tick): applies the
    /// timeouts.
    pub fn tick(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.output()
    }

    /// A valid reference frame arrived (the protocol layer checked it), carrying `as_state`.
    /// The caller pushes the angle into the cascade when the returned demand is `Track`.
    pub fn on_reference(&mut self, now_us: u64, as_state: AsState) -> Output {
        let now = self.advance(now_us);
        self.set_as_state(now, as_state);
        self.last_reference_us = Some(now);
        // A valid frame proves the bus and the frame checks work again.
        self.active.remove(Fault::ReferenceTimeout);
        self.active.remove(Fault::InvalidFrames);
        self.active.remove(Fault::BusOff);
        self.output()
    }

    /// The AS state from a frame that carries no reference (it does not refresh the reference).
    pub fn on_as_state(&mut self, now_us: u64, as_state: AsState) -> Output {
        let now = self.advance(now_us);
        self.set_as_state(now, as_state);
        self.output()
    }

    /// The protocol layer's invalid-frame score reached its limit (`count`, see
    /// [`crate::protocol::e2e`]).
    pub fn on_invalid_frames_fault(&mut self, now_us: u64, count: u16) -> Output {
        let now = self.advance(now_us);
        self.raise(now, Fault::InvalidFrames, i32::from(count));
        self.output()
    }

    /// A column-encoder sample with the motor angle taken at the same time. `motor` is aligned
    /// to the column (0 = column 0 through the gearing; the ECU takes the origin from the
    /// column encoder, [`crate::ecu::Ecu::motor_angle`]). Call only with readings the sensor
    /// vouches for; report its errors with [`SteeringStateMachine::on_encoder_fault`].
    pub fn on_encoder(&mut self, now_us: u64, column: SteeringDeg, motor: MotorRad) -> Output {
        self.encoder_sample(now_us, column, Some(motor))
    }

    /// A column-encoder sample while the motor angle is not known (no motor origin yet: the
    /// EPOS4 has not reported its position). Every check of [`SteeringStateMachine::on_encoder`]
    /// but the disagreement, which has nothing to compare; a disagreement in progress is
    /// forgotten (its cause is not shown any more).
    pub fn on_column(&mut self, now_us: u64, column: SteeringDeg) -> Output {
        self.encoder_sample(now_us, column, None)
    }

    fn encoder_sample(
        &mut self,
        now_us: u64,
        column: SteeringDeg,
        motor: Option<MotorRad>,
    ) -> Output {
        let now = self.advance(now_us);
        if !column.is_finite() {
            self.previous_column = None;
            self.raise(
                now,
                Fault::Encoder,
                EncoderFaultDetail::ColumnNotFinite as i32,
            );
            return self.output();
        }
        if motor.is_some_and(|m| !m.is_finite()) {
            self.raise(
                now,
                Fault::Encoder,
                EncoderFaultDetail::MotorNotFinite as i32,
            );
            return self.output();
        }
        self.active.remove(Fault::Encoder);
        self.last_encoder_us = Some(now);
        self.check_jump(now, column.0);
        match motor {
            Some(motor) => {
                let motor_as_column =
                    SteeringDeg::from(self.config.gearing.steering_from_motor(motor));
                self.check_disagreement(now, column.0 - motor_as_column.0);
            }
            None => {
                self.disagreement_since_us = None;
                self.active.remove(Fault::EncoderMotorDisagreement);
            }
        }
        self.output()
    }

    /// A column sample against the reference the drive is following (call while the drive is
    /// on; see the tracking-error row of the module docs). Non-finite values count as beyond
    /// the window with no progress.
    pub fn on_tracking(
        &mut self,
        now_us: u64,
        reference: SteeringDeg,
        column: SteeringDeg,
    ) -> Output {
        let now = self.advance(now_us);
        let error = reference.0 - column.0;
        if error.abs() <= self.config.tracking_deg {
            self.tracking_since = None;
            self.active.remove(Fault::TrackingError);
            return self.output();
        }
        self.active.insert(Fault::TrackingError);
        let (since, column_then) = *self.tracking_since.get_or_insert((now, column.0));
        let elapsed_us = now.saturating_sub(since);
        if elapsed_us >= u64::from(self.config.tracking_persist_us) {
            let toward = (column.0 - column_then) * error.signum();
            let progress_dps = toward / (elapsed_us as f32 * 1e-6);
            // NaN compares false: no progress anyone can vouch for.
            if progress_dps >= self.config.tracking_progress_dps {
                // Closing the gap: start a new interval from here.
                self.tracking_since = Some((now, column.0));
            } else {
                self.raise(now, Fault::TrackingError, centideg_detail(error));
            }
        }
        self.output()
    }

    /// The runaway check (call with each column sample while the drive is on): `current` is
    /// what pushes the motor (direct: the position loop's set-point; EPOS4: the drive's
    /// measured current), positive toward positive angles. When it pushes toward the reference
    /// at [`RUNAWAY_CURRENT`] or more for [`RUNAWAY_PERSIST_US`] and the column still moves away
    /// at [`RUNAWAY_AWAY_DPS`] or more, no slower than when the push began (a push the right
    /// way slows it), the drive has lost control of the current's direction
    /// (a sign-flipped current sense, an offset the loop regulates against, swapped motor
    /// phases): `TrackingError` latches, the detail the error in centi-degrees. Non-finite
    /// values push nothing and move nothing: the check rests (the encoder and over-current
    /// checks own them).
    pub fn on_drive_effort(
        &mut self,
        now_us: u64,
        reference: SteeringDeg,
        column: SteeringDeg,
        current: Amps,
    ) -> Output {
        let now = self.advance(now_us);
        let error = reference.0 - column.0;
        match self.runaway_probe {
            Some((t, c)) if now.saturating_sub(t) >= u64::from(RUNAWAY_SPEED_WINDOW_US) => {
                let dt_s = now.saturating_sub(t) as f32 * 1e-6;
                // Away = moving against the sign of the error.
                self.away_dps = -(column.0 - c) * error.signum() / dt_s;
                self.runaway_probe = Some((now, column.0));
            }
            Some(_) => {}
            None => self.runaway_probe = Some((now, column.0)),
        }
        // NaN compares false: no push anyone can vouch for.
        let pushing = current.0 * error.signum() >= RUNAWAY_CURRENT.0;
        if !pushing {
            self.runaway_since = None;
            return self.output();
        }
        // One push is one direction: a saturated loop on a fast reference flips its current
        // with the error, and each flip starts a new push.
        if self.runaway_since.is_none() || error.signum() != self.push_direction {
            self.runaway_since = Some(now);
            self.away_at_push_dps = self.away_dps;
            self.push_direction = error.signum();
        }
        let since = self.runaway_since.unwrap_or(now);
        // A loop that lags a fast reference (a 10 Hz sweep: the error's sign holds for 50 ms,
        // and the soft belt delays the column by as much) also sees the column move away
        // under a saturated push, but the push slows it. A drive pushing the wrong way does
        // not: the motion away is at least as fast as when the push began (one encoder count
        // per speed window of slack for the quantisation).
        let not_slowing = self.away_dps >= self.away_at_push_dps - RUNAWAY_SLOWING_SLACK_DPS;
        if now.saturating_sub(since) >= u64::from(RUNAWAY_PERSIST_US)
            && self.away_dps >= RUNAWAY_AWAY_DPS
            && not_slowing
        {
            self.raise(now, Fault::TrackingError, centideg_detail(error));
        }
        self.output()
    }

    /// An over-current run is open: the last current sample was beyond the threshold (or not
    /// a number), so the next sample must go through [`SteeringStateMachine::on_current`]
    /// even if it is within.
    pub fn overcurrent_pending(&self) -> bool {
        self.overcurrent_count > 0 || self.active.contains(Fault::OverCurrent)
    }

    /// The drive is off (or has no reference): no tracking error can be present.
    pub fn on_not_tracking(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.tracking_since = None;
        self.runaway_since = None;
        self.runaway_probe = None;
        self.away_dps = 0.0;
        self.active.remove(Fault::TrackingError);
        self.output()
    }

    /// The column encoder reported an error (`code` is the firmware's, e.g. a status bit).
    pub fn on_encoder_fault(&mut self, now_us: u64, code: u16) -> Output {
        let now = self.advance(now_us);
        let detail = (EncoderFaultDetail::SensorReported as i32).saturating_add(i32::from(code));
        self.raise(now, Fault::Encoder, detail);
        self.output()
    }

    /// A measured motor current sample (at the rate of the current or the position loop).
    pub fn on_current(&mut self, now_us: u64, measured: Amps) -> Output {
        let now = self.advance(now_us);
        // NaN compares false: a current nobody can read is not vouched to be within the limit.
        let within = measured.0.abs() <= self.config.overcurrent.0;
        if within {
            self.overcurrent_count = 0;
            self.overcurrent_since_us = None;
            self.active.remove(Fault::OverCurrent);
        } else {
            self.overcurrent_count = self.overcurrent_count.saturating_add(1);
            let since = *self.overcurrent_since_us.get_or_insert(now);
            self.active.insert(Fault::OverCurrent);
            let lasted =
                self.overcurrent_count >= 2 && now.saturating_sub(since) >= OVERCURRENT_PERSIST_US;
            if self.overcurrent_count >= self.config.overcurrent_samples || lasted {
                let detail = if measured.0.is_nan() {
                    i32::MIN
                } else {
                    (measured.0 * 1000.0) as i32
                };
                self.raise(now, Fault::OverCurrent, detail);
            }
        }
        self.output()
    }

    /// The column samples the motor origin is taken from at this enable disagree by `spread`
    /// (deg at the wheel): the enable is refused and [`Fault::Origin`] latches. The cause is
    /// judged afresh at every enable, so it is gone once reported.
    pub fn on_origin_disagreement(&mut self, now_us: u64, spread: SteeringDeg) -> Output {
        let now = self.advance(now_us);
        let detail = centideg_detail(spread.0).clamp(0, ORIGIN_RESTING_DETAIL - 1);
        self.raise(now, Fault::Origin, detail);
        self.active.remove(Fault::Origin);
        self.output()
    }

    /// The drive rested on (see [`crate::ecu::ORIGIN_REST_US`]) with column and motor angle /
    /// gear ratio `difference` apart (deg at the wheel), more than compliance and backlash
    /// allow at that effort: the origin is wrong, [`Fault::Origin`] latches. The cause goes
    /// with the next enable, which takes the origin afresh.
    pub fn on_origin_off(&mut self, now_us: u64, difference: SteeringDeg) -> Output {
        let now = self.advance(now_us);
        let centideg =
            centideg_detail(difference.0).clamp(-ORIGIN_RESTING_DETAIL, ORIGIN_RESTING_DETAIL);
        let detail = if centideg < 0 {
            centideg.saturating_sub(ORIGIN_RESTING_DETAIL)
        } else {
            centideg.saturating_add(ORIGIN_RESTING_DETAIL)
        };
        self.raise(now, Fault::Origin, detail);
        self.active.remove(Fault::Origin);
        self.output()
    }

    /// The EPOS4 reported a fault (statusword bit 3 or an EMCY); `code` is its error code.
    pub fn on_epos_fault(&mut self, now_us: u64, code: u16) -> Output {
        let now = self.advance(now_us);
        self.raise(now, Fault::EposFault, i32::from(code));
        self.output()
    }

    /// The EPOS4's fault is gone (fault reset done, statusword fault bit clear).
    pub fn on_epos_fault_gone(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.active.remove(Fault::EposFault);
        self.output()
    }

    /// The EPOS4's heartbeat did not come within the consumer-heartbeat time.
    pub fn on_heartbeat_lost(&mut self, now_us: u64) -> Output {
        let now = self.advance(now_us);
        self.raise(now, Fault::HeartbeatLost, 0);
        self.output()
    }

    /// An EPOS4 heartbeat arrived.
    pub fn on_heartbeat(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.active.remove(Fault::HeartbeatLost);
        self.output()
    }

    /// The CAN controller went bus-off; `tec` is its transmit error counter if known.
    pub fn on_bus_off(&mut self, now_us: u64, tec: u8) -> Output {
        let now = self.advance(now_us);
        self.raise(now, Fault::BusOff, i32::from(tec));
        self.output()
    }

    /// The CAN controller is back on the bus.
    pub fn on_bus_recovered(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.active.remove(Fault::BusOff);
        self.output()
    }

    /// Clears every latched fault, if the AS state is Off (from a frame within the reference
    /// timeout) and the cause of each is gone; otherwise nothing changes. The fault log is
    /// kept, and no detector's timer or count is reset. The next call's [`Output`] shows the
    /// result. The ECU calls it on the rising edge of the frame's clear bit only.
    pub fn request_clear_faults(&mut self, now_us: u64) -> Result<(), ClearRefused> {
        let now = self.advance(now_us);
        let stale = self
            .last_as_us
            .is_none_or(|t| now.saturating_sub(t) > u64::from(self.config.reference_timeout_us));
        if self.as_state != Some(AsState::Off) || stale {
            return Err(ClearRefused::NotInAsOff {
                as_state: self.as_state,
                stale,
            });
        }
        let still = self.active.intersection(self.latched);
        if !still.is_empty() {
            return Err(ClearRefused::CauseActive { faults: still });
        }
        // Only the latch goes: the detectors' timers and counts are left alone. A cause that
        // is gone has already reset them; one that is building up (not latched yet) must keep
        // building, or a vehicle asking to clear every period would mask it for ever.
        self.latched = FaultSet::EMPTY;
        self.log.acknowledge_all();
        Ok(())
    }

    /// Moves time on to `now_us` (never back) and applies the time-based rules.
    fn advance(&mut self, now_us: u64) -> u64 {
        self.now_us = self.now_us.max(now_us);
        let now = self.now_us;
        if let Some(powered_since) = self.powered_since_us {
            let age_from = |last: Option<u64>| {
                let since = last.map_or(powered_since, |t| t.max(powered_since));
                now.saturating_sub(since)
            };
            let reference_age = age_from(self.last_reference_us);
            let limit = u64::from(self.config.reference_timeout_us)
                .saturating_add(u64::from(self.config.hold_us));
            if reference_age > limit {
                self.raise(now, Fault::ReferenceTimeout, ms_detail(reference_age));
            }
            let encoder_age = age_from(self.last_encoder_us);
            if encoder_age > u64::from(self.config.encoder_timeout_us) {
                self.raise(now, Fault::Encoder, EncoderFaultDetail::Stale as i32);
            }
        }
        now
    }

    fn set_as_state(&mut self, now: u64, as_state: AsState) {
        // The rules' AS state machine leaves AS Emergency only for AS Off (the ASMS switched
        // off): any other state after it is a vehicle computer out of order, and the
        // emergency stands.
        let as_state = if self.as_state == Some(AsState::Emergency) && as_state != AsState::Off {
            AsState::Emergency
        } else {
            as_state
        };
        if self.config.actuation.allows(as_state) {
            if self.powered_since_us.is_none() {
                self.powered_since_us = Some(now);
            }
        } else {
            self.powered_since_us = None;
        }
        self.as_state = Some(as_state);
        self.last_as_us = Some(now);
    }

    /// The cause is present: mark it and latch it (recording it if newly latched).
    fn raise(&mut self, now: u64, fault: Fault, detail: i32) {
        self.active.insert(fault);
        if self.latched.insert(fault) {
            self.log.push(FaultRecord {
                fault,
                at_us: now,
                detail,
            });
        }
    }

    fn check_jump(&mut self, now: u64, column_deg: f32) {
        if let Some((t, previous)) = self.previous_column {
            let dt_us = now.saturating_sub(t);
            // After a gap the previous sample says nothing about this one; the encoder
            // timeout covers the gap itself.
            if dt_us <= u64::from(self.config.encoder_timeout_us) {
                let limit = self.config.jump_floor_deg
                    + self.config.max_column_rate_dps * (dt_us as f32 * 1e-6);
                let jump = (column_deg - previous).abs();
                if jump > limit {
                    self.raise(now, Fault::EncoderJump, centideg_detail(jump));
                } else {
                    self.active.remove(Fault::EncoderJump);
                }
            }
        }
        self.previous_column = Some((now, column_deg));
    }

    fn check_disagreement(&mut self, now: u64, difference_deg: f32) {
        // Not finite (two huge angles) counts as beyond the window.
        if difference_deg.abs() <= self.config.disagreement_deg {
            self.disagreement_since_us = None;
            self.active.remove(Fault::EncoderMotorDisagreement);
            return;
        }
        self.active.insert(Fault::EncoderMotorDisagreement);
        let since = *self.disagreement_since_us.get_or_insert(now);
        if now.saturating_sub(since) >= u64::from(self.config.disagreement_persist_us) {
            self.raise(
                now,
                Fault::EncoderMotorDisagreement,
                centideg_detail(difference_deg),
            );
        }
    }

    /// The demand, from the stored facts alone: the single place that can say `Track`.
    fn output(&mut self) -> Output {
        let now = self.now_us;
        let age = |t: Option<u64>| t.map(|t| now.saturating_sub(t));
        let reference_age = age(self.last_reference_us);
        let encoder_age = age(self.last_encoder_us);
        let timeout = u64::from(self.config.reference_timeout_us);
        let reference_fresh = reference_age.is_some_and(|a| a <= timeout);
        let encoder_fresh =
            encoder_age.is_some_and(|a| a <= u64::from(self.config.encoder_timeout_us));
        let within_hold = reference_age
            .is_some_and(|a| a <= timeout.saturating_add(u64::from(self.config.hold_us)));
        let actuation = self.config.actuation;
        let may_power = self.as_state.is_some_and(|s| actuation.allows(s));
        let engaged = self.last_demand != DriveDemand::Disabled;

        let demand = if !may_power || !self.latched.is_empty() {
            DriveDemand::Disabled
        } else if reference_fresh && encoder_fresh {
            DriveDemand::Track
        } else if engaged && within_hold {
            DriveDemand::Hold
        } else {
            DriveDemand::Disabled
        };

        let state = if self.as_state == Some(AsState::Emergency) {
            EcuState::Emergency
        } else if !self.latched.is_empty() {
            EcuState::Faulted
        } else {
            match demand {
                DriveDemand::Track => EcuState::Tracking,
                DriveDemand::Hold => EcuState::Holding,
                DriveDemand::Disabled if may_power => EcuState::Standby,
                DriveDemand::Disabled => EcuState::Idle,
            }
        };

        if self.last_demand == DriveDemand::Track && demand == DriveDemand::Hold {
            self.hold_entries = self.hold_entries.saturating_add(1);
        }
        let drive_just_enabled = !engaged && demand != DriveDemand::Disabled;
        self.last_demand = demand;
        Output {
            demand,
            state,
            faults: self.latched,
            drive_just_enabled,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gearing::{TAU_BS_M_PER_RAD, TAU_P_M_PER_RAD};

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

    #[test]
    fn state_codes_round_trip() {
        for code in 0..=255u8 {
            match EcuState::from_code(code) {
                Some(s) => assert_eq!(s.code(), code),
                None => assert!(code > 6),
            }
        }
    }
}

#[cfg(test)]
mod property_tests {
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
}

// Tests for what `.ci/mutation.sh` found missed in this file (issue 12).
#[cfg(test)]
mod mutation_tests {
    use super::*;

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

    const MS: u64 = 1_000;

    /// The motor angle that reads as `deg` at the column through the paper's gears.
    fn motor_at(deg: f32) -> MotorRad {
        Gearing::PAPER.motor_from_steering(SteeringDeg(deg).into())
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
            let out =
                sm.on_drive_effort(t, SteeringDeg(reference), SteeringDeg(c), Amps(current(s)));
            if out.faults.contains(Fault::TrackingError) {
                return Some(t - t0);
            }
        }
        None
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

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
//! ## Detectors
//!
//! Each check that remembers something between calls is a small pure struct in its own file:
//! one detector, its inputs (the sample, the time, its limits from [`Config`]) and its
//! [`Verdict`] on them. The machine owns one of each, feeds them from its entry points and
//! applies each verdict to the fault's cause and latch in one place (`apply`); the faults that
//! arrive as events (EPOS4, heartbeat, bus-off, invalid frames, origin) need no detector.
//!
//! ```text
//!   on_reference / on_as_state --> Timeouts (timeouts.rs)          --> ReferenceTimeout, Encoder
//!   on_encoder / on_column     --> JumpCheck (jump.rs)             --> EncoderJump
//!                              --> DisagreementCheck (disagreement.rs) --> EncoderMotorDisagreement
//!   on_current                 --> OverCurrentCheck (overcurrent.rs)   --> OverCurrent
//!   on_tracking                --> TrackingCheck (tracking.rs)     --> TrackingError
//!   on_drive_effort            --> RunawayCheck (runaway.rs)       --> TrackingError
//!                                      |
//!                                      v  Verdict: Within / Building / Latch / Unjudged
//!                   active causes + latched faults + fault log --> output(): the demand
//! ```
//!
//! A panic is not a fault here: the firmware's panic handler turns the bridge off (EPOS4
//! disabled, PWM outputs low) and resets the MCU, so nothing of this machine runs after it.
//! After the reset the machine starts in Idle with no fault and no reference, so the drive
//! stays disabled until the vehicle computer sends fresh frames in AS Ready or Driving.
//!
//! ## Defaults and why
//!
//! - Reference timeout 30 ms ([`DEFAULT_REFERENCE_TIMEOUT_US`]): three periods of the 100 Hz
//!   reference: two frames lost in a row keep the drive tracking, a third puts it in Hold.
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

mod disagreement;
mod jump;
mod overcurrent;
mod runaway;
mod timeouts;
mod tracking;
mod verdict;

pub use disagreement::{DisagreementCheck, DisagreementLimits};
pub use jump::{JumpCheck, JumpLimits};
pub use overcurrent::{OVERCURRENT_PERSIST_US, OverCurrentCheck, OverCurrentLimits};
pub use runaway::{
    RUNAWAY_AWAY_DPS, RUNAWAY_CURRENT, RUNAWAY_PERSIST_US, RUNAWAY_SLOWING_SLACK_DPS,
    RUNAWAY_SPEED_WINDOW_US, RunawayCheck,
};
pub use timeouts::{TimeoutLimits, Timeouts};
pub use tracking::{TrackingCheck, TrackingLimits};
pub use verdict::Verdict;

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
/// |column - reference| beyond this is a tracking error candidate, deg at the wheel.
pub const DEFAULT_TRACKING_DEG: f32 = 20.0;
/// ... for this long, µs ...
pub const DEFAULT_TRACKING_PERSIST_US: u32 = 200_000;
/// ... while the column closes the gap slower than this, deg/s.
pub const DEFAULT_TRACKING_PROGRESS_DPS: f32 = 30.0;
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

    /// The limits of each detector, as it takes them.
    pub fn timeout_limits(&self) -> TimeoutLimits {
        TimeoutLimits {
            reference_timeout_us: self.reference_timeout_us,
            hold_us: self.hold_us,
            encoder_timeout_us: self.encoder_timeout_us,
        }
    }
    /// The jump check compares samples at most one encoder timeout apart.
    pub fn jump_limits(&self) -> JumpLimits {
        JumpLimits {
            floor_deg: self.jump_floor_deg,
            max_rate_dps: self.max_column_rate_dps,
            max_gap_us: self.encoder_timeout_us,
        }
    }
    pub fn disagreement_limits(&self) -> DisagreementLimits {
        DisagreementLimits {
            window_deg: self.disagreement_deg,
            persist_us: self.disagreement_persist_us,
        }
    }
    pub fn overcurrent_limits(&self) -> OverCurrentLimits {
        OverCurrentLimits {
            threshold: self.overcurrent,
            samples: self.overcurrent_samples,
        }
    }
    pub fn tracking_limits(&self) -> TrackingLimits {
        TrackingLimits {
            window_deg: self.tracking_deg,
            persist_us: self.tracking_persist_us,
            progress_dps: self.tracking_progress_dps,
        }
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
    /// The reference timeout and the encoder timeout.
    timeouts: Timeouts,
    jump: JumpCheck,
    disagreement: DisagreementCheck,
    tracking: TrackingCheck,
    runaway: RunawayCheck,
    overcurrent: OverCurrentCheck,
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

/// A current as mA for a record's detail, saturated; a current that is not a number is
/// recorded as `i32::MIN`, apart from every reading.
fn milliamps_detail(current: Amps) -> i32 {
    if current.0.is_nan() {
        i32::MIN
    } else {
        (current.0 * 1000.0) as i32
    }
}

impl SteeringStateMachine {
    /// Starts in Idle: no AS state, no reference, no fault, drive disabled.
    pub fn new(config: Config) -> Self {
        SteeringStateMachine {
            config,
            now_us: 0,
            as_state: None,
            last_as_us: None,
            timeouts: Timeouts::new(),
            jump: JumpCheck::new(),
            disagreement: DisagreementCheck::new(),
            tracking: TrackingCheck::new(),
            runaway: RunawayCheck::new(),
            overcurrent: OverCurrentCheck::new(),
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
        self.timeouts.on_reference(now);
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
            self.jump.forget();
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
        self.timeouts.on_encoder(now);
        let jump = self.jump.check(now, column.0, &self.config.jump_limits());
        self.apply(now, Fault::EncoderJump, jump, centideg_detail);
        let disagreement = match motor {
            Some(motor) => {
                let motor_as_column =
                    SteeringDeg::from(self.config.gearing.steering_from_motor(motor));
                let difference_deg = column.0 - motor_as_column.0;
                self.disagreement
                    .check(now, difference_deg, &self.config.disagreement_limits())
            }
            None => {
                self.disagreement.forget();
                Verdict::Within
            }
        };
        self.apply(
            now,
            Fault::EncoderMotorDisagreement,
            disagreement,
            centideg_detail,
        );
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
        let verdict = self
            .tracking
            .check(now, reference, column, &self.config.tracking_limits());
        self.apply(now, Fault::TrackingError, verdict, centideg_detail);
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
        let verdict = self.runaway.check(now, reference, column, current);
        self.apply(now, Fault::TrackingError, verdict, centideg_detail);
        self.output()
    }

    /// An over-current run is open: the last current sample was beyond the threshold (or not
    /// a number), so the next sample must go through [`SteeringStateMachine::on_current`]
    /// even if it is within.
    pub fn overcurrent_pending(&self) -> bool {
        self.overcurrent.run_open() || self.active.contains(Fault::OverCurrent)
    }

    /// The drive is off (or has no reference): no tracking error can be present.
    pub fn on_not_tracking(&mut self, now_us: u64) -> Output {
        self.advance(now_us);
        self.tracking.reset();
        self.runaway.reset();
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
        let verdict = self
            .overcurrent
            .check(now, measured, &self.config.overcurrent_limits());
        self.apply(now, Fault::OverCurrent, verdict, milliamps_detail);
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
        let limits = self.config.timeout_limits();
        let reference = self.timeouts.reference(now, &limits);
        self.apply(now, Fault::ReferenceTimeout, reference, ms_detail);
        let encoder = self.timeouts.encoder(now, &limits);
        self.apply(now, Fault::Encoder, encoder, |_| {
            EncoderFaultDetail::Stale as i32
        });
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
        self.timeouts
            .on_power_allowed(now, self.config.actuation.allows(as_state));
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

    /// A detector's verdict on the state of `fault`; `detail` makes the record's detail from
    /// the figure a latch carries.
    fn apply<T>(&mut self, now: u64, fault: Fault, verdict: Verdict<T>, detail: fn(T) -> i32) {
        match verdict {
            Verdict::Unjudged => {}
            Verdict::Within => self.active.remove(fault),
            Verdict::Building => {
                self.active.insert(fault);
            }
            Verdict::Latch(figure) => self.raise(now, fault, detail(figure)),
        }
    }

    /// The demand, from the stored facts alone: the single place that can say `Track`.
    fn output(&mut self) -> Output {
        let now = self.now_us;
        let reference_age = self.timeouts.reference_age(now);
        let encoder_age = self.timeouts.encoder_age(now);
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
mod tests;

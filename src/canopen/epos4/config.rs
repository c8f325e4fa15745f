//! The EPOS4's configuration: the object dictionary entries the link writes, the position
//! scale, the gain words, the drive's limits and the heartbeat, and why a configuration is
//! refused. The link that writes them is the parent module.

use super::super::cia402::Command;
use super::super::sdo::{SdoRequest, SdoWrite, Width};
use super::super::{NodeId, ObjectAddress};
use crate::can::Frame;
use crate::gains::{EposGains, GainError};
use crate::units::{Amps, MotorRad};

/// Object dictionary entries (EDS section names in brackets; see the module docs for the file).
pub mod od {
    use super::ObjectAddress;

    /// \[1017\] Producer heartbeat time, UNSIGNED16, rw, ms.
    pub const PRODUCER_HEARTBEAT: ObjectAddress = ObjectAddress::new(0x1017, 0);
    /// \[Consumer 1 heartbeat time\] UNSIGNED32 rw: node << 16 | ms.
    pub const CONSUMER_HEARTBEAT: ObjectAddress = ObjectAddress::new(0x1016, 1);
    /// \[1400\] Receive PDO 1 parameter / \[1600\] mapping.
    pub const RPDO1_COMMUNICATION: u16 = 0x1400;
    /// \[1800\] / \[1801\] Transmit PDO 1 / 2 parameter (subs 0..=3).
    pub const TPDO1_COMMUNICATION: u16 = 0x1800;
    /// \[30A0sub1\] Current controller P gain, UNSIGNED32, rww, µV/A.
    pub const CURRENT_P: ObjectAddress = ObjectAddress::new(0x30A0, 1);
    /// \[30A0sub2\] Current controller I gain, UNSIGNED32, rww, µV/(A·ms).
    pub const CURRENT_I: ObjectAddress = ObjectAddress::new(0x30A0, 2);
    /// \[30A1sub1\] Position controller P gain, UNSIGNED32, rww, µA/rad.
    pub const POSITION_P: ObjectAddress = ObjectAddress::new(0x30A1, 1);
    /// \[30A1sub2\] Position controller I gain, UNSIGNED32, rww, µA/(rad·s).
    pub const POSITION_I: ObjectAddress = ObjectAddress::new(0x30A1, 2);
    /// \[30A1sub3\] Position controller D gain, UNSIGNED32, rww, µA·s/rad.
    pub const POSITION_D: ObjectAddress = ObjectAddress::new(0x30A1, 3);
    /// \[30A1sub4\] Position controller FF velocity gain, UNSIGNED32, rww, µA·s/rad.
    pub const POSITION_FF_VELOCITY: ObjectAddress = ObjectAddress::new(0x30A1, 4);
    /// \[30A1sub5\] Position controller FF acceleration gain, UNSIGNED32, rww, µA·s²/rad.
    pub const POSITION_FF_ACCELERATION: ObjectAddress = ObjectAddress::new(0x30A1, 5);
    /// \[30D1sub1\] Current actual value averaged, INTEGER32, ro, mappable, mA.
    pub const CURRENT_ACTUAL_AVERAGED: ObjectAddress = ObjectAddress::new(0x30D1, 1);
    /// \[30D1sub2\] Current actual value, INTEGER32, ro, mappable, mA.
    pub const CURRENT_ACTUAL: ObjectAddress = ObjectAddress::new(0x30D1, 2);
    /// \[6040\] Controlword, UNSIGNED16, rww, mappable.
    pub const CONTROLWORD: ObjectAddress = ObjectAddress::new(0x6040, 0);
    /// \[6041\] Statusword, UNSIGNED16, ro, mappable.
    pub const STATUSWORD: ObjectAddress = ObjectAddress::new(0x6041, 0);
    /// \[6060\] Modes of operation, INTEGER8, rww.
    pub const MODES_OF_OPERATION: ObjectAddress = ObjectAddress::new(0x6060, 0);
    /// \[6061\] Modes of operation display, INTEGER8, ro.
    pub const MODES_OF_OPERATION_DISPLAY: ObjectAddress = ObjectAddress::new(0x6061, 0);
    /// \[6064\] Position actual value, INTEGER32, ro, mappable, inc.
    pub const POSITION_ACTUAL: ObjectAddress = ObjectAddress::new(0x6064, 0);
    /// \[607A\] Target position, INTEGER32, rww, mappable, inc.
    pub const TARGET_POSITION: ObjectAddress = ObjectAddress::new(0x607A, 0);
    /// \[60C2sub1\] Interpolation time period value, UNSIGNED8, rww, 0..=100.
    pub const INTERPOLATION_PERIOD: ObjectAddress = ObjectAddress::new(0x60C2, 1);
    /// \[60C2sub2\] Interpolation time index, INTEGER8, rww (10^index s; default -3).
    pub const INTERPOLATION_INDEX: ObjectAddress = ObjectAddress::new(0x60C2, 2);

    /// Motor data: output current limit, UNSIGNED32, mA (EPOS4 firmware specification; not
    /// checked against the EDS in this repository).
    pub const OUTPUT_CURRENT_LIMIT: ObjectAddress = ObjectAddress::new(0x3001, 2);
    /// \[6065\] Following error window, UNSIGNED32, inc (CiA 402).
    pub const FOLLOWING_ERROR_WINDOW: ObjectAddress = ObjectAddress::new(0x6065, 0);
    /// \[607F\] Max profile velocity, UNSIGNED32, rpm (CiA 402; the EPOS4's default velocity
    /// unit).
    pub const MAX_PROFILE_VELOCITY: ObjectAddress = ObjectAddress::new(0x607F, 0);
    /// \[607Dsub1\] Software position limit: min position limit, INTEGER32, inc (CiA 402).
    pub const MIN_POSITION_LIMIT: ObjectAddress = ObjectAddress::new(0x607D, 1);
    /// \[607Dsub2\] Software position limit: max position limit, INTEGER32, inc (CiA 402).
    pub const MAX_POSITION_LIMIT: ObjectAddress = ObjectAddress::new(0x607D, 2);

    /// 0x6060 value of cyclic synchronous position mode (CiA 402).
    pub const MODE_CSP: i8 = 8;
    /// \[60C2sub1\] HighLimit.
    pub const INTERPOLATION_PERIOD_MAX: u8 = 100;
    /// Interpolation time index -3: the period is in ms.
    pub const INTERPOLATION_INDEX_MS: i8 = -3;
}

/// Position increments <-> motor angle, for a configured increments-per-revolution.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionScale {
    counts_per_rev: u32,
}

impl PositionScale {
    /// `None` for 0 increments per revolution.
    pub const fn new(counts_per_rev: u32) -> Option<Self> {
        if counts_per_rev == 0 {
            None
        } else {
            Some(PositionScale { counts_per_rev })
        }
    }

    pub fn counts_per_rev(&self) -> u32 {
        self.counts_per_rev
    }

    pub fn motor_from_inc(&self, inc: i32) -> MotorRad {
        MotorRad((inc as f64 * (core::f64::consts::TAU / self.counts_per_rev as f64)) as f32)
    }

    /// Nearest increment; `None` for NaN or infinity, saturated at the `i32` range (about
    /// 25 million motor turns at 84 inc/rev: a saturated target is already far beyond the
    /// rack's travel, and the drive's software limits apply first).
    pub fn inc_from_motor(&self, angle: MotorRad) -> Option<i32> {
        if !angle.is_finite() {
            return None;
        }
        let x = angle.0 as f64 * (self.counts_per_rev as f64 / core::f64::consts::TAU);
        let rounded = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
        // `as` truncates toward zero and saturates at the i32 range.
        Some(rounded as i32)
    }
}

/// Motor current from the EPOS4's mA.
pub fn amps_from_ma(ma: i32) -> Amps {
    Amps(ma as f32 * 1e-3)
}

/// Why gains cannot be written as EPOS4 words.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum GainWordError {
    Invalid(GainError),
    /// 1000 x the gain does not fit UNSIGNED32.
    TooLarge {
        object: ObjectAddress,
    },
}

/// The seven Table 3 gains as the UNSIGNED32 words of 0x30A0 / 0x30A1: 1000 x the Table 3
/// number (mV -> µV, mA -> µA), rounded to the nearest unit.
pub fn gain_words(gains: &EposGains) -> Result<[(ObjectAddress, u32); 7], GainWordError> {
    gains.to_si().map_err(GainWordError::Invalid)?;
    let word = |object: ObjectAddress, value: f32| -> Result<(ObjectAddress, u32), GainWordError> {
        let micro = value as f64 * 1000.0 + 0.5;
        if micro > u32::MAX as f64 {
            return Err(GainWordError::TooLarge { object });
        }
        // Finite and >= 0 after `to_si`; in range after the check above.
        Ok((object, micro as u32))
    };
    Ok([
        word(od::CURRENT_P, gains.current_kp_mv_per_a)?,
        word(od::CURRENT_I, gains.current_ki_mv_per_a_ms)?,
        word(od::POSITION_P, gains.position_kp_ma_per_rad)?,
        word(od::POSITION_I, gains.position_ki_ma_per_rad_s)?,
        word(od::POSITION_D, gains.position_kd_ma_s_per_rad)?,
        word(od::POSITION_FF_VELOCITY, gains.ff_velocity_ma_s_per_rad)?,
        word(
            od::POSITION_FF_ACCELERATION,
            gains.ff_acceleration_ma_s2_per_rad,
        )?,
    ])
}

/// The SDO request that writes controlword "disable voltage" (0x0000) to `node`: the power
/// stage off from any state. Sent without waiting for an answer by the link after a failure and
/// by the firmware's panic handler.
pub fn disable_voltage_frame(node: NodeId) -> Option<Frame> {
    super::super::sdo::request_frame(
        node,
        &SdoRequest::Download(SdoWrite {
            object: od::CONTROLWORD,
            value: Command::DisableVoltage.controlword() as u32,
            width: Width::U16,
        }),
    )
}

/// Everything [`Epos4Link`](super::Epos4Link) needs to know.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Epos4Config {
    pub node: NodeId,
    pub gains: EposGains,
    /// Position increments per motor revolution (see the module docs).
    pub counts_per_rev: u32,
    /// SYNC and interpolation period, ms (1..=100: the 0x60C2 sub 1 range). Paper: 10 ms.
    pub cycle_ms: u8,
    /// Heartbeat period the drive is told to produce (0x1017), ms; 1.. .
    pub heartbeat_ms: u16,
    /// Silence after which the drive counts as lost; must exceed `heartbeat_ms`.
    pub heartbeat_timeout_us: u64,
    pub sdo_timeout_us: u64,
    /// Attempts per SDO transfer before the link gives up (>= 1).
    pub sdo_attempts: u8,
    /// Consecutive SYNC periods without TPDO1 before the link fails.
    pub max_missed_tpdos: u8,
    /// Which 0x30D1 sub-index TPDO2 carries.
    pub current_object: ObjectAddress,
    /// The ECU's own heartbeat, which the drive is told to watch (0x1016): if the ECU dies
    /// (a hang, a reset, a cut wire), the drive faults and switches its power stage off.
    pub ecu_heartbeat: Option<EcuHeartbeat>,
    /// The drive's own limits, written and read back at bring-up.
    pub limits: DriveLimits,
}

/// Limits the drive enforces by itself, so a wrong target or a confused ECU cannot ask for more.
/// The three above are written once in the configuration script; the software position limits
/// (0x607D) are written by every enable walk, around the origin the ECU last took from the
/// column ([`Epos4Link::set_position_origin`](super::Epos4Link::set_position_origin)), because the drive counts from its power-up
/// position: see [`Epos4Link::position_limits`](super::Epos4Link::position_limits).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DriveLimits {
    /// Output current limit, mA (0x3001 sub 2).
    pub current_ma: u32,
    /// Following error window, inc (0x6065): beyond it the drive faults.
    pub following_error_inc: u32,
    /// Max profile velocity, rpm (0x607F).
    pub max_velocity_rpm: u32,
    /// Software position limits (0x607D), inc either side of the column-derived origin.
    pub position_limit_inc: u32,
}

/// The steering's travel the drive allows either side of straight ahead, deg at the wheel:
/// the reference's +-90 deg (the E2E rule) plus [`POSITION_LIMIT_MARGIN_DEG`].
pub const POSITION_LIMIT_DEG: f32 = 90.0 + POSITION_LIMIT_MARGIN_DEG;
/// Margin of the drive's software position limits beyond +-90 deg, deg at the wheel. The
/// drive limits the motor's position, which under load runs ahead of the column by the belt's
/// stretch: up to 9.7 deg at the 20 A limit (Tables 1 and 4, `ecu_mode::EcuTuning::max_lead_rad`),
/// and ECU mode's target leads by as much. 10 deg more covers a position step's overshoot, so
/// the limits never take travel the ECU asks for at full lock.
pub const POSITION_LIMIT_MARGIN_DEG: f32 = 20.0;

/// Following error window at the wheel, deg: above the 20 deg the ECU's tracking check allows
/// (a 400 deg/s reference slew against the motor's 306 deg/s lags up to about 21 deg over the
/// full range), so the drive's own fault only fires where the ECU's would.
pub const FOLLOWING_ERROR_DEG: f32 = 25.0;
/// Max profile velocity, rpm: the motor's no-load speed on a full 29.4 V pack (29.4 V / ke
/// 52.5 mV s/rad = 560 rad/s = 5350 rpm), rounded up: a faster command is not the motor's own.
pub const MAX_VELOCITY_RPM: u32 = 5_400;

impl DriveLimits {
    /// The paper's car: the 20 A loop limit (section 3.3), [`FOLLOWING_ERROR_DEG`] through the
    /// paper's gears at `counts_per_rev`, [`MAX_VELOCITY_RPM`].
    /// [`POSITION_LIMIT_DEG`] likewise.
    pub fn paper(counts_per_rev: u32) -> Self {
        let inc_at_wheel = |deg: f32| {
            let motor = crate::gearing::Gearing::PAPER
                .motor_from_steering(crate::units::SteeringDeg(deg).into());
            PositionScale::new(counts_per_rev)
                .and_then(|s| s.inc_from_motor(motor))
                .map_or(0, |i| i.unsigned_abs())
        };
        DriveLimits {
            current_ma: (crate::paper_mode::CURRENT_LIMIT.0 * 1000.0) as u32,
            following_error_inc: inc_at_wheel(FOLLOWING_ERROR_DEG),
            max_velocity_rpm: MAX_VELOCITY_RPM,
            position_limit_inc: inc_at_wheel(POSITION_LIMIT_DEG),
        }
    }
}

/// The heartbeat the link produces for the ECU and the time the drive allows between two.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EcuHeartbeat {
    /// The ECU's node ID on the bus (not used by any drive).
    pub node: NodeId,
    /// Producer period, ms (>= 1).
    pub period_ms: u16,
    /// Consumer time given to the drive, ms; must exceed `period_ms`.
    pub consumer_ms: u16,
}

impl EcuHeartbeat {
    /// Node 127, every 10 ms, 50 ms allowed: five periods, so one lost frame is no fault.
    pub const DEFAULT: EcuHeartbeat = EcuHeartbeat {
        node: match NodeId::new(127) {
            Some(n) => n,
            None => panic!("127 is a node ID"), // evaluated at compile time
        },
        period_ms: 10,
        consumer_ms: 50,
    };
}

impl Epos4Config {
    /// The paper's car: Table 3 gains, 84 Hall increments per revolution, 10 ms cycle.
    pub fn paper(node: NodeId) -> Self {
        Epos4Config {
            node,
            gains: EposGains::PAPER,
            counts_per_rev: crate::sensors::HALL_COUNTS_PER_REV,
            cycle_ms: (1000 / crate::paper_mode::REFERENCE_HZ) as u8,
            heartbeat_ms: 20,
            heartbeat_timeout_us: 100_000,
            sdo_timeout_us: 20_000,
            sdo_attempts: 3,
            max_missed_tpdos: 5,
            current_object: od::CURRENT_ACTUAL,
            ecu_heartbeat: Some(EcuHeartbeat::DEFAULT),
            limits: DriveLimits::paper(crate::sensors::HALL_COUNTS_PER_REV),
        }
    }
}

/// Why a configuration is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    Gains(GainWordError),
    CountsPerRev,
    CycleMs { ms: u8 },
    Heartbeat,
    SdoAttempts,
    CurrentObject { object: ObjectAddress },
}

//! The vehicle-facing CAN protocol: the 100 Hz steering reference from the vehicle computer,
//! the 100 Hz status frame back, their codec, and the end-to-end (E2E) check every reference
//! passes before the control core sees it ([`e2e`]).
//!
//! IDs, layouts and scaling are also in `src/protocol/steering-ecu.dbc`, for SavvyCAN and
//! cantools; a host test decodes this codec's frames with that file and compares.
//!
//! # Frames
//!
//! Classic CAN, 11-bit IDs, 8 data bytes, all signals Intel (little-endian), bit numbers as in
//! the DBC (bit 0 = LSB of byte 0). IDs are the defaults of [`ProtocolConfig`].
//!
//! Reference, `0x100`, vehicle computer -> steering ECU, every 10 ms:
//!
//! ```text
//! byte | bits   | signal             | raw type | scale        | range
//! -----+--------+--------------------+----------+--------------+--------------------------
//!  0   |  0..7  | REF_Crc            | u8       | -            | CRC-8/AUTOSAR, see below
//!  1   |  8..11 | REF_Counter        | u4       | 1            | 0..15, +1 per frame, wraps
//!  1   | 12..15 | REF_AsState        | u4       | AsState code | 0..5 (Off, Ready, Driving,
//!      |        |                    |          |              | Emergency, Finished, Manual)
//!  2-3 | 16..31 | REF_SteeringAngle  | i16      | 0.01 deg/bit | +-327.67 deg; valid +-90 deg
//!  4   | 32     | REF_ClearFaults    | u1       | 1 = request  | clear latched faults (only
//!      |        |                    |          |              | honoured in AS Off)
//!  4-7 | 33..63 | reserved           | -        | -            | sent 0, covered by the CRC,
//!      |        |                    |          |              | otherwise ignored
//! ```
//!
//! Status, `0x101`, steering ECU -> vehicle computer, every 10 ms:
//!
//! ```text
//! byte | bits   | signal             | raw type | scale        | range
//! -----+--------+--------------------+----------+--------------+--------------------------
//!  0   |  0..7  | STA_Crc            | u8       | -            | CRC-8/AUTOSAR, see below
//!  1   |  8..11 | STA_Counter        | u4       | 1            | 0..15, +1 per frame, wraps
//!  1-2 | 12..23 | STA_MotorCurrent   | i12      | 0.02 A/bit   | +-40.94 A
//!  3-4 | 24..39 | STA_SteeringAngle  | i16      | 0.01 deg/bit | +-327.67 deg (column encoder)
//!  5   | 40..47 | STA_EcuState       | u8       | 1            | the state machine's code
//!  6-7 | 48..63 | STA_Faults         | u16      | bit field    | the fault register's bits
//! ```
//!
//! Motor, `0x102`, steering ECU -> vehicle computer, every 10 ms right after the status frame
//! (the status frame is full; a log needs the motor angle too):
//!
//! ```text
//! byte | bits   | signal             | raw type | scale        | range
//! -----+--------+--------------------+----------+--------------+--------------------------
//!  0   |  0..7  | MOT_Crc            | u8       | -            | CRC-8/AUTOSAR, see below
//!  1   |  8..11 | MOT_Counter        | u4       | 1            | 0..15, +1 per frame, wraps
//!  1   | 12..15 | MOT_RefCounter     | u4       | 1            | 0..15, the reference counter
//!      |        |                    |          |              | the E2E check last saw
//!  2-5 | 16..47 | MOT_MotorAngle     | i32      | 1e-4 rad/bit | +-214748 rad at the motor
//!  6-7 | 48..63 | MOT_CurrentMean    | i16      | 0.001 A/bit  | +-32.767 A
//! ```
//!
//! The motor angle is the one the position loop last used (Hall counts in direct drive), at
//! the motor shaft: +-90 deg at the wheel is +-134 rad there, 0.1 mrad per bit keeps a Hall
//! step (75 mrad) exact. The current is the mean of the measured current over the status
//! period, the figure the paper plots and the sim-to-real diagnosis compares: a single sample
//! of a current that chatters by 20 A between position ticks says little. The most negative
//! raw value of each field means "not available", as in the status frame.
//!
//! The reference counter is the alive counter of the last reference frame that passed the
//! CRC, accepted or not: the one the E2E check judges the next frame's counter against (0
//! before the first, when any counter is accepted). A sender that starts while the ECU runs
//! (a second bench tool after a first, the vehicle computer after a restart) continues from it
//! +1, so its first frame is not dropped as a counter jump. It rides in the motor frame, every
//! period, so a sender waits one period for it, not a diagnostic round.
//!
//! The status frame has 68 bits of wish list for 64 bits of frame: the motor current gets 12
//! bits at 0.02 A/bit (twice the 20 A current limit, 20 mA resolution) so that the ECU state
//! and the fault bits go out whole. Each angle and current field has one raw value reserved for
//! "not available": the most negative one (angle `-32768`, current `-2048`). NaN encodes to it
//! and decodes from it; finite values beyond the range saturate to the largest representable
//! magnitude, because a saturated reading is still the right sign and the vehicle computer
//! must see that the wheel is far out.
//!
//! # CRC
//!
//! CRC-8/AUTOSAR ([`crc`]): poly 0x2F, init 0xFF, not reflected, xorout 0xFF, check value
//! 0xDF over `"123456789"`. Byte 0 of each frame is the CRC over
//!
//! ```text
//! [ID & 0xFF, ID >> 8, byte 1, byte 2, ..., byte 7]
//! ```
//!
//! i.e. the 11-bit CAN ID as two little-endian bytes (the "data ID", not transmitted), then
//! payload bytes 1 to 7. Folding the ID in means a frame copied to another ID (a status frame
//! looped back, a gateway mix-up) fails the CRC even where the ID filter would not catch it.
//!
//! # E2E rules for the reference (see [`e2e`])
//!
//! In this order; the first rule a frame breaks is the reason it is dropped:
//!
//! ```text
//! rule                                  | on failure (FrameError)         | counts toward fault
//! --------------------------------------+---------------------------------+--------------------
//! ID == reference ID                    | WrongId { id }                  | no (other traffic)
//! DLC == 8 bytes                        | WrongLength { len }             | yes
//! byte 0 == CRC                         | Crc { expected, found }         | yes
//! counter != last counter               | Stale { counter }               | yes
//! counter == last counter + 1 (mod 16)  | Counter { expected, found }     | yes
//! AS state code in 0..=5                | UnknownAsState { code }         | yes
//! |angle| <= 90 deg                     | AngleOutOfRange { angle, .. }   | yes
//! |angle - last accepted| <= budget     | RateTooHigh { step, allowed }   | yes
//! ```
//!
//! "Last counter" is the counter of the last frame that passed the CRC, accepted or not, so
//! one lost frame costs the next frame too (it is dropped as a jump, and re-synchronises the
//! counter), and the one after is accepted again. A dropped frame whose CRC is good still
//! carries the sender's AS state, whatever its counter: AS Emergency, Finished or Off in it
//! disables at once ([`e2e::E2eChecker::authentic_as_state`]). The rate budget is 400 deg/s times the time
//! since the last accepted reference, at least one 10 ms period: 4.00 deg per sample.
//! An invalid-frame score of five (configurable; +1 per invalid frame, -1 per valid one) makes
//! [`e2e::E2eVerdict::Fault`].

pub mod crc;
pub mod e2e;

#[cfg(test)]
mod dbc_tests;

use crate::as_state::AsState;
use crate::can::{Frame, StandardId};
use crate::units::{Amps, MotorRad, SteeringDeg};

pub use e2e::{DropCounters, E2eChecker, E2eVerdict};

/// Length of both frames, bytes.
pub const FRAME_LEN: u8 = 8;
/// Reference and status period, us (100 Hz, paper section 4.1).
pub const PERIOD_US: u32 = 10_000;
/// Steering-angle scale of both frames, deg per bit.
pub const ANGLE_DEG_PER_BIT: f32 = 0.01;
/// Motor-current scale of the status frame, A per bit.
pub const CURRENT_A_PER_BIT: f32 = 0.02;
/// The inverses, exact in f32 (0.01 and 0.02 are not), so whole degrees give whole raw values.
const ANGLE_BITS_PER_DEG: f32 = 100.0;
const CURRENT_BITS_PER_A: f32 = 50.0;
/// Raw angle meaning "not available" (NaN).
pub const ANGLE_NOT_AVAILABLE: i16 = i16::MIN;
/// Raw 12-bit current meaning "not available" (NaN).
pub const CURRENT_NOT_AVAILABLE: i16 = -2048;
const CURRENT_RAW_MAX: i16 = 2047;

/// Default reference ID.
pub const REFERENCE_ID: StandardId = match StandardId::new(0x100) {
    Some(id) => id,
    None => panic!("0x100 is an 11-bit ID"), // evaluated at compile time
};
/// Default status ID.
pub const STATUS_ID: StandardId = match StandardId::new(0x101) {
    Some(id) => id,
    None => panic!("0x101 is an 11-bit ID"), // evaluated at compile time
};

/// Default motor-frame ID (not configurable yet: one ECU per bus).
pub const MOTOR_ID: StandardId = match StandardId::new(0x102) {
    Some(id) => id,
    None => panic!("0x102 is an 11-bit ID"), // evaluated at compile time
};
/// Diagnostic-frame ID: the fault ring and the counters, one page per frame, sent
/// every status period by [`crate::tasks::status_task`].
pub const DIAGNOSTIC_ID: StandardId = match StandardId::new(0x103) {
    Some(id) => id,
    None => panic!("0x103 is an 11-bit ID"), // evaluated at compile time
};
/// Counter pages of the diagnostic frame, pages 0..COUNTER_PAGES; see [`DiagnosticPage`].
pub const COUNTER_PAGES: u8 = 6;
/// Page code of a fault record; which record is in the page's payload.
pub const RECORD_PAGE: u8 = 8;
/// Frames in one round of the diagnostic frame: each counter page, then one per slot of the
/// fault log, oldest first, so every record and counter comes within this many periods.
pub const DIAGNOSTIC_ROUND: u8 = COUNTER_PAGES + crate::faults::FAULT_LOG_CAPACITY as u8;
/// Fault code of an empty record slot.
pub const NO_RECORD: u8 = 0x0F;
/// Bits of a record's detail on the bus (two's complement): the detail saturates at
/// [`RECORD_DETAIL_MIN`] / [`RECORD_DETAIL_MAX`], which read back as `i32::MIN` / `i32::MAX`
/// (the saturated values the fault docs name, such as a current that was not a number).
pub const RECORD_DETAIL_BITS: u32 = 28;
pub const RECORD_DETAIL_MIN: i32 = -(1 << (RECORD_DETAIL_BITS - 1));
pub const RECORD_DETAIL_MAX: i32 = (1 << (RECORD_DETAIL_BITS - 1)) - 1;
/// A record's age on the bus, s, saturating (11 bits: 34 min).
pub const RECORD_AGE_MAX_S: u16 = 2047;

/// One record slot of the diagnostic frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DiagnosticRecord {
    /// The fault's bit (as in the status frame), 0..=14.
    pub fault_bit: u8,
    /// A clear request was accepted since the fault latched.
    pub acknowledged: bool,
    /// The record's detail, saturated as [`RECORD_DETAIL_BITS`] says.
    pub detail: i32,
    /// Seconds since the fault latched when the page was sent, saturated at
    /// [`RECORD_AGE_MAX_S`].
    pub age_s: u16,
}

/// What one diagnostic page carries.
///
/// Counter pages (page code 0..=5) carry three saturating u16 counters at bits 16, 32 and 48:
/// 0 = E2E drops for wrong length, CRC, stale counter; 1 = counter jump, unknown AS state,
/// angle out of range; 2 = rate too high, early frames, bus-off events; 3 = refused clear
/// requests, hold entries, lost demand-change frames; 4 = fault records held, of them not
/// acknowledged, records dropped from the full ring; 5 = the stack's high-water mark and the
/// stack's size, 4-byte words (both 0: not measured, as on the host), a reserved 0. A record page (page code
/// [`RECORD_PAGE`]) carries one slot of the fault log: bits 16..19 the slot (0 = the oldest
/// held), 20..23 the fault's bit ([`NO_RECORD`] = an empty slot), 24 acknowledged, 25..52
/// the detail (signed), 53..63 the age, s.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DiagnosticPage {
    Counters {
        page: u8,
        words: [u16; 3],
    },
    Record {
        slot: u8,
        record: Option<DiagnosticRecord>,
    },
    /// A page code this layout does not define (a newer ECU, a corrupted sender): its
    /// payload, bits 16..63, untouched.
    Unknown {
        code: u8,
        payload: u64,
    },
}

impl DiagnosticPage {
    /// The page code on the bus (bits 12..15).
    pub fn code(&self) -> u8 {
        match self {
            DiagnosticPage::Counters { page, .. } => *page,
            DiagnosticPage::Record { .. } => RECORD_PAGE,
            DiagnosticPage::Unknown { code, .. } => *code,
        }
    }
}

/// One page of the diagnostic frame (0x103): byte 0 CRC, bits 8..11 counter, 12..15 page code.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Diagnostic {
    pub counter: AliveCounter,
    pub page: DiagnosticPage,
}

/// Motor-angle scale of the motor frame, rad per bit.
pub const MOTOR_RAD_PER_BIT: f64 = 1e-4;
/// Mean-current scale of the motor frame, A per bit.
pub const MOTOR_CURRENT_A_PER_BIT: f32 = 0.001;
/// Raw motor angle meaning "not available" (NaN).
pub const MOTOR_ANGLE_NOT_AVAILABLE: i32 = i32::MIN;
/// Raw mean current meaning "not available" (NaN).
pub const MOTOR_CURRENT_NOT_AVAILABLE: i16 = i16::MIN;
const MOTOR_BITS_PER_RAD: f64 = 1e4;
const MOTOR_CURRENT_BITS_PER_A: f32 = 1000.0;

/// The 4-bit alive counter of both frames: 0..=15, +1 per frame, 15 is followed by 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AliveCounter(u8);

impl AliveCounter {
    /// Number of counter values; the counter runs modulo this.
    pub const MODULUS: u8 = 16;

    /// `None` above 15.
    pub const fn new(raw: u8) -> Option<Self> {
        if raw < Self::MODULUS {
            Some(AliveCounter(raw))
        } else {
            None
        }
    }

    /// The low four bits of `raw`, as a sender that counts in a wider integer means it.
    pub const fn wrapping(raw: u8) -> Self {
        AliveCounter(raw % Self::MODULUS)
    }

    pub const fn raw(self) -> u8 {
        self.0
    }

    /// The counter of the next frame.
    pub const fn next(self) -> Self {
        Self::wrapping(self.0.wrapping_add(1))
    }
}

/// A steering reference as the vehicle computer sends it.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Reference {
    /// Steering-wheel angle asked for, deg at the wheel.
    pub angle: SteeringDeg,
    pub as_state: AsState,
    pub counter: AliveCounter,
    /// Request to clear the latched faults. Honoured only in AS Off and once every fault's
    /// cause is gone (the state machine's rule); otherwise the request is refused and counted.
    pub clear_faults: bool,
}

/// What the steering ECU reports back.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Status {
    /// Measured steering-column angle (column encoder), deg at the wheel; NaN = not available.
    pub angle: SteeringDeg,
    /// Measured motor current, A; NaN = not available.
    pub current: Amps,
    /// The state machine's state code; carried as is.
    pub ecu_state: u8,
    /// The fault bits; carried as is.
    pub faults: u16,
    pub counter: AliveCounter,
}

/// The motor frame's content: what a log needs beside the status frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MotorStatus {
    /// Motor shaft angle the position loop last used, rad; NaN = not available.
    pub angle: MotorRad,
    /// Mean measured motor current over the last status period, A; NaN = not available.
    pub current_mean: Amps,
    pub counter: AliveCounter,
    /// The counter of the last reference frame that passed the CRC (0 before the first): a
    /// new sender's first frame carries the next one.
    pub reference_counter: AliveCounter,
}

/// Why a received frame was dropped. The decoders return `WrongId`, `WrongLength`, `Crc` and
/// `UnknownAsState`; the E2E checker adds the ones that need history or limits.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FrameError {
    /// Not the ID asked for (`id` is the one received).
    WrongId { id: StandardId },
    /// DLC other than 8 bytes.
    WrongLength { len: u8 },
    /// Byte 0 is not the CRC of the frame: `expected` computed here, `found` in byte 0.
    Crc { expected: u8, found: u8 },
    /// The counter did not advance: the sender repeated a frame or stopped updating it.
    Stale { counter: u8 },
    /// The counter jumped: `found - expected` frames (mod 16) were lost in between.
    Counter { expected: u8, found: u8 },
    /// An AS state code the rules do not define.
    UnknownAsState { code: u8 },
    /// Reference beyond the configured steering range (NaN-coded angles included).
    AngleOutOfRange {
        angle: SteeringDeg,
        limit: SteeringDeg,
    },
    /// The reference moved `step` since the last accepted one, more than the `allowed` budget.
    RateTooHigh {
        step: SteeringDeg,
        allowed: SteeringDeg,
    },
}

/// Why a [`ProtocolConfig`] was refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ConfigError {
    /// Reference and status must have different IDs (the CRC folds the ID in, but a receiver
    /// filtering by ID could not tell them apart).
    SameIds,
    /// Steering range not finite, not positive, or beyond the i16 range (327.67 deg).
    MaxAngle,
    /// Rate limit not finite, or not positive.
    MaxRate,
    /// Zero reference period.
    Period,
    /// Zero invalid frames in a row would be a fault before the first frame.
    MaxInvalidInRow,
    /// Zero timeout.
    Timeout,
}

/// IDs and E2E limits. [`ProtocolConfig::DEFAULT`] is what the DBC describes.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ProtocolConfig {
    pub reference_id: StandardId,
    pub status_id: StandardId,
    /// Largest accepted |reference|, deg at the wheel.
    pub max_angle: SteeringDeg,
    /// Largest accepted reference rate, deg/s at the wheel.
    pub max_rate_deg_per_s: f32,
    /// Nominal reference period, us; the smallest time the rate budget is computed for.
    pub period_us: u32,
    /// An invalid-frame score this high is a fault (+1 per invalid frame, -1 per valid one).
    pub max_invalid_in_row: u8,
    /// No accepted reference for longer than this, us, is a timeout ([`E2eChecker::timed_out`]).
    pub timeout_us: u32,
}

impl ProtocolConfig {
    /// 0x100 / 0x101, +-90 deg, 400 deg/s, 10 ms, 5 in a row, 50 ms.
    ///
    /// - +-90 deg: the paper's steering range (section 2, [`crate::paper_mode::STEERING_RANGE_DEG`]).
    /// - 400 deg/s: the actuator's no-load speed is 24 V / ke = 457 rad/s at the motor, / 85.45
    ///   (gear chain, Table 2) = 5.35 rad/s = 306 deg/s at the wheel; with a full 7S pack
    ///   (29.4 V) 375 deg/s. A reference faster than 400 deg/s is one no supply lets the
    ///   actuator follow, so it is implausible; everything the actuator could follow passes.
    ///   Per 10 ms sample that is 4.00 deg.
    /// - 5 in a row, 50 ms: five reference periods, the same tolerance for lost and for bad
    ///   frames; the interpolator holds the last sample meanwhile.
    pub const DEFAULT: ProtocolConfig = ProtocolConfig {
        reference_id: REFERENCE_ID,
        status_id: STATUS_ID,
        max_angle: SteeringDeg(crate::paper_mode::STEERING_RANGE_DEG),
        max_rate_deg_per_s: 400.0,
        period_us: PERIOD_US,
        max_invalid_in_row: 5,
        timeout_us: 5 * PERIOD_US,
    };

    /// `Ok` when every field is usable; see [`ConfigError`].
    pub fn validate(&self) -> Result<(), ConfigError> {
        let max_angle_raw = f32::from(i16::MAX) * ANGLE_DEG_PER_BIT;
        if self.reference_id == self.status_id {
            Err(ConfigError::SameIds)
        } else if !(self.max_angle.0 > 0.0 && self.max_angle.0 <= max_angle_raw) {
            Err(ConfigError::MaxAngle)
        } else if !(self.max_rate_deg_per_s.is_finite() && self.max_rate_deg_per_s > 0.0) {
            Err(ConfigError::MaxRate)
        } else if self.period_us == 0 {
            Err(ConfigError::Period)
        } else if self.max_invalid_in_row == 0 {
            Err(ConfigError::MaxInvalidInRow)
        } else if self.timeout_us == 0 {
            Err(ConfigError::Timeout)
        } else {
            Ok(())
        }
    }

    /// The reference frame for `reference` (vehicle-computer side: host-sim, bench tools).
    pub fn encode_reference(&self, reference: &Reference) -> Frame {
        let word = u64::from(reference.counter.raw()) << 8
            | u64::from(reference.as_state.code() & 0x0F) << 12
            | u64::from(angle_to_raw(reference.angle) as u16) << 16
            | u64::from(reference.clear_faults) << 32;
        frame_with_crc(self.reference_id, word)
    }

    /// Decodes a reference frame on its own: ID, length, CRC and AS state code. Counter, range
    /// and rate need history and limits: that is [`E2eChecker::check`], which the control
    /// core's input must come through.
    pub fn decode_reference(&self, frame: &Frame) -> Result<Reference, FrameError> {
        let word = checked_word(self.reference_id, frame)?;
        let code = field(word, 12, 4) as u8;
        let as_state = AsState::from_code(code).ok_or(FrameError::UnknownAsState { code })?;
        Ok(Reference {
            angle: angle_from_raw(field(word, 16, 16) as u16 as i16),
            as_state,
            counter: AliveCounter::wrapping(field(word, 8, 4) as u8),
            clear_faults: field(word, 32, 1) == 1,
        })
    }

    /// The status frame for `status`.
    pub fn encode_status(&self, status: &Status) -> Frame {
        let word = u64::from(status.counter.raw()) << 8
            | u64::from(current_to_raw(status.current) as u16 & 0x0FFF) << 12
            | u64::from(angle_to_raw(status.angle) as u16) << 24
            | u64::from(status.ecu_state) << 40
            | u64::from(status.faults) << 48;
        frame_with_crc(self.status_id, word)
    }

    /// Decodes a status frame (vehicle-computer side, host-sim): ID, length, CRC.
    pub fn decode_status(&self, frame: &Frame) -> Result<Status, FrameError> {
        let word = checked_word(self.status_id, frame)?;
        Ok(Status {
            angle: angle_from_raw(field(word, 24, 16) as u16 as i16),
            current: current_from_raw(sign_extend_12(field(word, 12, 12) as u16)),
            ecu_state: field(word, 40, 8) as u8,
            faults: field(word, 48, 16) as u16,
            counter: AliveCounter::wrapping(field(word, 8, 4) as u8),
        })
    }
}

impl ProtocolConfig {
    /// The motor frame (ID [`MOTOR_ID`]) for `motor`.
    pub fn encode_motor(&self, motor: &MotorStatus) -> Frame {
        let word = u64::from(motor.counter.raw()) << 8
            | u64::from(motor.reference_counter.raw()) << 12
            | u64::from(motor_angle_to_raw(motor.angle) as u32) << 16
            | u64::from(motor_current_to_raw(motor.current_mean) as u16) << 48;
        frame_with_crc(MOTOR_ID, word)
    }

    /// Decodes a motor frame (vehicle-computer side, host tools): ID, length, CRC.
    pub fn decode_motor(&self, frame: &Frame) -> Result<MotorStatus, FrameError> {
        let word = checked_word(MOTOR_ID, frame)?;
        let angle_raw = field(word, 16, 32) as u32 as i32;
        let current_raw = field(word, 48, 16) as u16 as i16;
        Ok(MotorStatus {
            angle: if angle_raw == MOTOR_ANGLE_NOT_AVAILABLE {
                MotorRad(f32::NAN)
            } else {
                MotorRad((f64::from(angle_raw) * MOTOR_RAD_PER_BIT) as f32)
            },
            current_mean: if current_raw == MOTOR_CURRENT_NOT_AVAILABLE {
                Amps(f32::NAN)
            } else {
                Amps(f32::from(current_raw) / MOTOR_CURRENT_BITS_PER_A)
            },
            counter: AliveCounter::wrapping(field(word, 8, 4) as u8),
            reference_counter: AliveCounter::wrapping(field(word, 12, 4) as u8),
        })
    }
}

impl ProtocolConfig {
    /// The diagnostic frame (ID [`DIAGNOSTIC_ID`]) as [`DiagnosticPage`] lays it out. A
    /// counter page's code is taken modulo 16 (4 bits), a slot modulo 16, a record's fault bit
    /// keeps its low 4 bits, its detail and age saturate.
    pub fn encode_diagnostic(&self, d: &Diagnostic) -> Frame {
        let payload = match d.page {
            DiagnosticPage::Counters { words, .. } => {
                u64::from(words[0]) << 16 | u64::from(words[1]) << 32 | u64::from(words[2]) << 48
            }
            DiagnosticPage::Record { slot, record } => {
                let slot = u64::from(slot & 0x0F) << 16;
                match record {
                    None => slot | u64::from(NO_RECORD) << 20,
                    Some(r) => {
                        let detail = r.detail.clamp(RECORD_DETAIL_MIN, RECORD_DETAIL_MAX) as u32
                            & ((1 << RECORD_DETAIL_BITS) - 1);
                        slot | u64::from(r.fault_bit & 0x0F) << 20
                            | u64::from(r.acknowledged) << 24
                            | u64::from(detail) << 25
                            | u64::from(r.age_s.min(RECORD_AGE_MAX_S)) << 53
                    }
                }
            }
            DiagnosticPage::Unknown { payload, .. } => payload << 16,
        };
        let word =
            u64::from(d.counter.raw()) << 8 | u64::from(d.page.code() & 0x0F) << 12 | payload;
        frame_with_crc(DIAGNOSTIC_ID, word)
    }

    /// Decodes a diagnostic frame: ID, length, CRC; a page code the layout does not define
    /// comes back as [`DiagnosticPage::Unknown`], never as some other page.
    pub fn decode_diagnostic(&self, frame: &Frame) -> Result<Diagnostic, FrameError> {
        let word = checked_word(DIAGNOSTIC_ID, frame)?;
        let code = field(word, 12, 4) as u8;
        let page = if code < COUNTER_PAGES {
            DiagnosticPage::Counters {
                page: code,
                words: [
                    field(word, 16, 16) as u16,
                    field(word, 32, 16) as u16,
                    field(word, 48, 16) as u16,
                ],
            }
        } else if code == RECORD_PAGE {
            let fault_bit = field(word, 20, 4) as u8;
            let record = (fault_bit != NO_RECORD).then(|| {
                let raw = field(word, 25, RECORD_DETAIL_BITS) as u32;
                // Sign-extend the 28 bits; the saturated ends stand for beyond them.
                let detail = match ((raw << (32 - RECORD_DETAIL_BITS)) as i32)
                    >> (32 - RECORD_DETAIL_BITS)
                {
                    RECORD_DETAIL_MIN => i32::MIN,
                    RECORD_DETAIL_MAX => i32::MAX,
                    d => d,
                };
                DiagnosticRecord {
                    fault_bit,
                    acknowledged: field(word, 24, 1) != 0,
                    detail,
                    age_s: field(word, 53, 11) as u16,
                }
            });
            DiagnosticPage::Record {
                slot: field(word, 16, 4) as u8,
                record,
            }
        } else {
            DiagnosticPage::Unknown {
                code,
                payload: word >> 16,
            }
        };
        Ok(Diagnostic {
            counter: AliveCounter::wrapping(field(word, 8, 4) as u8),
            page,
        })
    }
}

impl Default for ProtocolConfig {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// The CRC byte 0 must carry: CRC-8/AUTOSAR over the ID (2 bytes, little-endian) and payload
/// bytes 1..=7.
pub fn frame_crc(id: StandardId, payload: &[u8; 8]) -> u8 {
    let data_id = id.raw().to_le_bytes();
    crc::crc8_autosar(data_id.iter().chain(payload.iter().skip(1)))
}

/// `len` bits of the little-endian frame word from bit `start` (DBC Intel numbering).
#[expect(
    clippy::arithmetic_side_effects,
    reason = "every caller names a literal field of 1 to 32 bits: the mask does not underflow"
)]
const fn field(word: u64, start: u32, len: u32) -> u64 {
    (word >> start) & ((1 << len) - 1)
}

/// The payload as a little-endian word, after the ID, length and CRC checks.
fn checked_word(id: StandardId, frame: &Frame) -> Result<u64, FrameError> {
    if frame.id() != id {
        return Err(FrameError::WrongId { id: frame.id() });
    }
    let payload: [u8; 8] = frame
        .data()
        .try_into()
        .map_err(|_| FrameError::WrongLength {
            // A frame holds at most 8 bytes, so the length fits a u8.
            len: frame.data().len() as u8,
        })?;
    let expected = frame_crc(id, &payload);
    let [found, ..] = payload;
    if expected != found {
        return Err(FrameError::Crc { expected, found });
    }
    Ok(u64::from_le_bytes(payload))
}

fn frame_with_crc(id: StandardId, word_without_crc: u64) -> Frame {
    let mut payload = (word_without_crc & !0xFF).to_le_bytes();
    let crc = frame_crc(id, &payload);
    payload[0] = crc;
    Frame::from_bytes(id, payload)
}

/// Rounds half away from zero; `as` saturates, so any finite value lands in range.
fn round_to_i32(x: f32) -> i32 {
    (if x >= 0.0 { x + 0.5 } else { x - 0.5 }) as i32
}

/// NaN -> "not available"; beyond +-327.67 deg -> +-327.67 deg (the reserved raw value stays
/// reserved).
fn angle_to_raw(angle: SteeringDeg) -> i16 {
    if angle.0.is_nan() {
        return ANGLE_NOT_AVAILABLE;
    }
    let raw =
        round_to_i32(angle.0 * ANGLE_BITS_PER_DEG).clamp(i32::from(-i16::MAX), i32::from(i16::MAX));
    raw as i16
}

fn angle_from_raw(raw: i16) -> SteeringDeg {
    if raw == ANGLE_NOT_AVAILABLE {
        SteeringDeg(f32::NAN)
    } else {
        SteeringDeg(f32::from(raw) * ANGLE_DEG_PER_BIT)
    }
}

/// NaN -> "not available"; beyond +-40.94 A -> +-40.94 A.
fn current_to_raw(current: Amps) -> i16 {
    if current.0.is_nan() {
        return CURRENT_NOT_AVAILABLE;
    }
    round_to_i32(current.0 * CURRENT_BITS_PER_A)
        .clamp(i32::from(-CURRENT_RAW_MAX), i32::from(CURRENT_RAW_MAX)) as i16
}

fn current_from_raw(raw: i16) -> Amps {
    if raw == CURRENT_NOT_AVAILABLE {
        Amps(f32::NAN)
    } else {
        Amps(f32::from(raw) * CURRENT_A_PER_BIT)
    }
}

/// NaN -> "not available"; beyond the i32 range -> saturated (the reserved value stays
/// reserved).
fn motor_angle_to_raw(angle: MotorRad) -> i32 {
    if angle.0.is_nan() {
        return MOTOR_ANGLE_NOT_AVAILABLE;
    }
    let x = f64::from(angle.0) * MOTOR_BITS_PER_RAD;
    let rounded = if x >= 0.0 { x + 0.5 } else { x - 0.5 };
    // `as` saturates; the clamp keeps i32::MIN for "not available".
    (rounded as i64).clamp(i64::from(-i32::MAX), i64::from(i32::MAX)) as i32
}

/// NaN -> "not available"; beyond +-32.767 A -> +-32.767 A.
fn motor_current_to_raw(current: Amps) -> i16 {
    if current.0.is_nan() {
        return MOTOR_CURRENT_NOT_AVAILABLE;
    }
    round_to_i32(current.0 * MOTOR_CURRENT_BITS_PER_A)
        .clamp(i32::from(-i16::MAX), i32::from(i16::MAX)) as i16
}

/// A 12-bit two's-complement field as an i16.
const fn sign_extend_12(raw: u16) -> i16 {
    ((raw << 4) as i16) >> 4
}

#[cfg(test)]
mod tests;

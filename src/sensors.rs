//! The two position sensors as angles: the motor's Hall sensors (position feedback of the
//! loop, as on the paper's EPOS4) and the absolute encoder on the steering column.

use crate::units::{MotorRad, SteeringRad};
use core::f32::consts::TAU;

/// Hall states per electrical revolution (three sensors, six edges).
pub const HALL_STEPS_PER_ELECTRICAL_REV: u32 = 6;
/// Pole pairs of the Maxon EC 60 flat (datasheet; paper section 2).
pub const POLE_PAIRS: u32 = 14;
/// Hall counts per mechanical revolution: 6 x 14 = 84, i.e. 4.29 deg of motor per count.
pub const HALL_COUNTS_PER_REV: u32 = HALL_STEPS_PER_ELECTRICAL_REV * POLE_PAIRS;
/// Column encoder resolution: 12 bit per revolution, 0.088 deg per count.
pub const COLUMN_ENCODER_BITS: u32 = 12;
pub const COLUMN_ENCODER_COUNTS: u32 = 1 << COLUMN_ENCODER_BITS;

/// Motor angle of a Hall count (multi-turn count kept by the commutation logic).
///
/// `i32` counts cover +-25.5 million motor turns, far beyond any steering travel, so the
/// conversion is exact to f32 rounding.
pub fn motor_from_hall(count: i32) -> MotorRad {
    MotorRad(count as f32 * (TAU / HALL_COUNTS_PER_REV as f32))
}

/// The Hall count a motor angle reads as (floor: the count changes on the sensor edge).
/// Used by host-sim to quantise the simulated angle exactly as the sensors would; saturates at
/// the `i32` range and maps NaN to 0.
pub fn hall_from_motor(angle_rad: f64) -> i32 {
    let counts =
        floor_saturating(angle_rad * (HALL_COUNTS_PER_REV as f64 / core::f64::consts::TAU));
    counts.clamp(i32::MIN as i64, i32::MAX as i64) as i32
}

/// `floor` without libm: `as` truncates toward zero, saturates at the i64 range and maps NaN
/// to 0, so every input has a defined result.
fn floor_saturating(x: f64) -> i64 {
    let t = x as i64;
    if (t as f64) > x {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Column-encoder reading: the raw single-turn word and the zero set at bring-up.
///
/// The column turns +-90 deg (less than half a turn) so a single-turn absolute encoder suffices;
/// the reading is the offset-corrected word wrapped into [-2048, 2047] counts.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ColumnEncoder {
    /// Raw word that reads as straight ahead.
    pub zero_raw: u16,
}

impl ColumnEncoder {
    /// Steering angle from a raw word. Bits above the 12 used are ignored (masked), so any
    /// `u16` has a defined angle.
    pub fn angle(&self, raw: u16) -> SteeringRad {
        // Modulo 4096, which divides 2^16: the wrapping difference of the words is exact.
        let mask = (COLUMN_ENCODER_COUNTS - 1) as u16;
        let diff = i32::from(raw.wrapping_sub(self.zero_raw) & mask);
        let signed = if diff >= (COLUMN_ENCODER_COUNTS / 2) as i32 {
            // 2048..=4095 minus 4096: nothing wraps.
            diff.wrapping_sub(COLUMN_ENCODER_COUNTS as i32)
        } else {
            diff
        };
        SteeringRad(signed as f32 * (TAU / COLUMN_ENCODER_COUNTS as f32))
    }

    /// The raw word an angle reads as (what host-sim feeds the encoder port). Non-finite
    /// angles read as the zero position.
    pub fn raw_from_angle(&self, angle_rad: f64) -> u16 {
        let counts = if angle_rad.is_finite() {
            floor_saturating(angle_rad * (COLUMN_ENCODER_COUNTS as f64 / core::f64::consts::TAU))
        } else {
            0
        };
        // Modulo 4096, which divides 2^64: wrapping is exact even for a count saturated at
        // the i64 range.
        let mask = (COLUMN_ENCODER_COUNTS - 1) as i64;
        (counts.wrapping_add(i64::from(self.zero_raw)) & mask) as u16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hall_has_84_counts_per_revolution() {
        assert_eq!(HALL_COUNTS_PER_REV, 84);
        assert!((motor_from_hall(84).0 - TAU).abs() < 1e-5);
        assert_eq!(hall_from_motor(core::f64::consts::TAU - 1e-9), 83);
        assert_eq!(hall_from_motor(-1e-9), -1);
    }

    #[test]
    fn hall_quantisation_of_garbage_is_defined() {
        assert_eq!(hall_from_motor(f64::NAN), 0);
        assert_eq!(hall_from_motor(f64::INFINITY), i32::MAX);
        assert_eq!(hall_from_motor(f64::NEG_INFINITY), i32::MIN);
    }

    #[test]
    fn column_encoder_wraps_around_its_zero() {
        let enc = ColumnEncoder { zero_raw: 4000 };
        assert_eq!(enc.angle(4000).0, 0.0);
        // 100 counts past the zero, across the 4095 -> 0 wrap.
        let a = enc.angle(4);
        assert!((a.0 - 100.0 * TAU / 4096.0).abs() < 1e-6);
        let b = enc.angle(3900);
        assert!((b.0 + 100.0 * TAU / 4096.0).abs() < 1e-6);
        // Upper bits are ignored.
        assert_eq!(enc.angle(4000 | 0xF000), enc.angle(4000));
    }

    #[test]
    fn column_encoder_round_trips_within_one_count() {
        let enc = ColumnEncoder { zero_raw: 123 };
        for deg in [-90.0f64, -45.3, 0.0, 12.7, 89.9] {
            let rad = deg.to_radians();
            let back = enc.angle(enc.raw_from_angle(rad)).0 as f64;
            assert!((back - rad).abs() <= TAU as f64 / 4096.0, "{deg} -> {back}");
        }
    }

    #[test]
    fn column_encoder_raw_of_any_angle_is_defined() {
        // Angles whose count saturates at the i64 range, from a non-zero zero: the offset is
        // added modulo the 12-bit word (the count here was once added unchecked and
        // overflowed). i64::MAX and i64::MIN are -1 and 0 modulo 4096.
        let enc = ColumnEncoder { zero_raw: 123 };
        assert_eq!(enc.raw_from_angle(1e300), 122);
        assert_eq!(enc.raw_from_angle(f64::MAX), 122);
        assert_eq!(enc.raw_from_angle(-1e300), 123);
        assert_eq!(enc.raw_from_angle(f64::INFINITY), 123);
    }
}

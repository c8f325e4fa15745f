//! Typed units where a mix-up is possible: an angle at the steering wheel and an angle at the
//! motor differ by a factor of about 85, and a gain in EPOS units differs from SI by 1000.
//!
//! The newtypes are thin (`f32` inside, public) so arithmetic stays readable; what they buy is
//! that a function asking for a [`MotorRad`] cannot be handed a [`SteeringRad`].

use core::f32::consts::PI;

macro_rules! unit {
    ($(#[$doc:meta])* $name:ident, $unit:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, Copy, PartialEq, PartialOrd, Default)]
        #[cfg_attr(feature = "defmt", derive(defmt::Format))]
        pub struct $name(pub f32);

        impl $name {
            /// The unit's symbol, for logs and tables.
            pub const UNIT: &'static str = $unit;
            pub const ZERO: Self = Self(0.0);

            /// True when the value is neither NaN nor infinite.
            pub fn is_finite(self) -> bool {
                self.0.is_finite()
            }
        }

        impl core::ops::Add for $name {
            type Output = Self;
            fn add(self, rhs: Self) -> Self {
                Self(self.0 + rhs.0)
            }
        }

        impl core::ops::Sub for $name {
            type Output = Self;
            fn sub(self, rhs: Self) -> Self {
                Self(self.0 - rhs.0)
            }
        }

        impl core::ops::Neg for $name {
            type Output = Self;
            fn neg(self) -> Self {
                Self(-self.0)
            }
        }
    };
}

unit!(
    /// Angle of the motor shaft, rad (what the Hall sensors and the position loop see).
    MotorRad,
    "rad"
);
unit!(
    /// Angle at the steering wheel / column, rad. Positive = the same sign as the motor angle.
    SteeringRad,
    "rad"
);
unit!(
    /// Angle at the steering wheel / column, degrees: the unit of the CAN reference and the logs.
    SteeringDeg,
    "deg"
);
unit!(
    /// Motor phase current (torque-producing), A.
    Amps,
    "A"
);
unit!(
    /// Motor terminal voltage, V.
    Volts,
    "V"
);

impl From<SteeringDeg> for SteeringRad {
    fn from(d: SteeringDeg) -> Self {
        SteeringRad(d.0 * (PI / 180.0))
    }
}

impl From<SteeringRad> for SteeringDeg {
    fn from(r: SteeringRad) -> Self {
        SteeringDeg(r.0 * (180.0 / PI))
    }
}

/// Clamp `x` to `[-limit, limit]`; NaN maps to 0 so a saturated output is never NaN.
/// Returns the clamped value and whether it was limited.
pub fn saturate(x: f32, limit: f32) -> (f32, bool) {
    if x.is_nan() {
        (0.0, true)
    } else if x > limit {
        (limit, true)
    } else if x < -limit {
        (-limit, true)
    } else {
        (x, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn degrees_and_radians_round_trip() {
        let d = SteeringDeg(90.0);
        let r: SteeringRad = d.into();
        assert!((r.0 - PI / 2.0).abs() < 1e-6);
        let back: SteeringDeg = r.into();
        assert!((back.0 - 90.0).abs() < 1e-4);
    }

    #[test]
    fn saturate_limits_both_signs_and_maps_nan_to_zero() {
        assert_eq!(saturate(30.0, 20.0), (20.0, true));
        assert_eq!(saturate(-30.0, 20.0), (-20.0, true));
        assert_eq!(saturate(5.0, 20.0), (5.0, false));
        assert_eq!(saturate(f32::NAN, 20.0), (0.0, true));
        assert_eq!(saturate(f32::INFINITY, 20.0), (20.0, true));
    }
}

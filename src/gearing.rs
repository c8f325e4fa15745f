//! The gear chain from the steering wheel to the motor, from the paper's Table 2 ratios.
//!
//! wheel/column --pinion (C-factor)--> rack <--ball screw (lead)-- nut <--belt 2:1-- motor
//!
//! With the drive at rest the belt carries no torque, so the rigid ratio holds:
//! `theta_rot = belt * delta_SW * tau_P / tau_BS`, about 85.5 rad of motor per rad at the wheel.

use crate::units::{MotorRad, SteeringRad};

/// Belt reduction, motor turns per nut turn. Table 2 prints tauB = 2 "belt to ball screw
/// ratio"; the nut turns at half the motor speed (plant-and-control.md, printing error 1).
pub const BELT_REDUCTION: f32 = 2.0;
/// Ball-screw lead / 2 pi, m/rad (Table 2: tauBS = 3.183e-4 m/rad, a 2 mm lead).
pub const TAU_BS_M_PER_RAD: f32 = 3.183e-4;
/// Pinion C-factor / 2 pi, m/rad (Table 2: tauP = 1.36e-2 m/rad, 85.5 mm/rev).
pub const TAU_P_M_PER_RAD: f32 = 1.36e-2;

/// The rigid gear chain between the steering column and the motor shaft.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Gearing {
    /// Motor radians per steering-column radian.
    motor_per_steering: f32,
}

impl Gearing {
    /// The paper's actuator (Table 2).
    pub const PAPER: Gearing = Gearing {
        motor_per_steering: BELT_REDUCTION * TAU_P_M_PER_RAD / TAU_BS_M_PER_RAD,
    };

    /// A chain from its three ratios; `None` unless all are finite and positive.
    pub fn new(belt_reduction: f32, tau_bs_m_per_rad: f32, tau_p_m_per_rad: f32) -> Option<Self> {
        let ratio = belt_reduction * tau_p_m_per_rad / tau_bs_m_per_rad;
        let all_positive = [belt_reduction, tau_bs_m_per_rad, tau_p_m_per_rad]
            .iter()
            .all(|v| v.is_finite() && *v > 0.0);
        (all_positive && ratio.is_finite() && ratio > 0.0).then_some(Gearing {
            motor_per_steering: ratio,
        })
    }

    /// Motor radians per steering-column radian (about 85.5 for the paper's actuator).
    pub fn ratio(&self) -> f32 {
        self.motor_per_steering
    }

    pub fn motor_from_steering(&self, a: SteeringRad) -> MotorRad {
        MotorRad(a.0 * self.motor_per_steering)
    }

    pub fn steering_from_motor(&self, a: MotorRad) -> SteeringRad {
        SteeringRad(a.0 / self.motor_per_steering)
    }

    /// Rack displacement, m, for a steering-column angle (C-factor).
    pub fn rack_m(a: SteeringRad) -> f32 {
        a.0 * TAU_P_M_PER_RAD
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::units::SteeringDeg;

    #[test]
    fn paper_ratio_is_about_85_motor_rad_per_wheel_rad() {
        let r = Gearing::PAPER.ratio();
        assert!((r - 85.45).abs() < 0.05, "ratio {r}");
    }

    #[test]
    fn full_lock_is_about_45_mm_of_rack() {
        // plant-and-control.md: 45 mm travel for -90..+90 deg at the wheel.
        let travel = Gearing::rack_m(SteeringDeg(180.0).into());
        assert!((travel - 0.0427).abs() < 1e-3, "travel {travel} m");
    }

    #[test]
    fn motor_and_steering_round_trip() {
        let g = Gearing::PAPER;
        let s = SteeringRad(0.3);
        let back = g.steering_from_motor(g.motor_from_steering(s));
        assert!((back.0 - 0.3).abs() < 1e-6);
    }

    #[test]
    fn refuses_non_positive_or_non_finite_ratios() {
        assert!(Gearing::new(0.0, 1.0, 1.0).is_none());
        assert!(Gearing::new(2.0, -1.0, 1.0).is_none());
        assert!(Gearing::new(2.0, 1.0, f32::NAN).is_none());
        assert!(Gearing::new(2.0, 1e-45, 1e38).is_none());
        assert!(Gearing::new(2.0, 3.183e-4, 1.36e-2).is_some());
    }
}

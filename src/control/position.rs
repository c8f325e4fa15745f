//! Position loop: PID on the motor angle plus velocity and acceleration feedforward,
//! giving the current set-point, limited to 20 A.
//!
//! `i* = Kp e + Ki sum(e dt) + Kd (e[k] - e[k-1]) / dt + Kv w_ref + Ka a_ref`, clamped to
//! +-limit. The derivative acts on the error by backward difference (paper mode, as the EPOS4).
//!
//! Bad input: a non-finite set-point or measurement gives 0 A and leaves the loop state as it
//! was ([`PositionStatus::InputNotFinite`]); a finite input that overflows the arithmetic
//! saturates at the limit; the output is never NaN.

use super::AntiWindup;
use crate::gains::SiGains;
use crate::reference::Setpoint;
use crate::units::{Amps, MotorRad, saturate};

/// What the position loop did this tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PositionStatus {
    Linear,
    /// The current set-point hit the limit; the integrator was held.
    Saturated,
    /// An input was NaN or infinite: 0 A commanded, state untouched.
    InputNotFinite,
}

#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct PositionOutput {
    pub current: Amps,
    pub status: PositionStatus,
}

#[derive(Debug, Clone)]
pub struct PositionLoop {
    kp: f32,
    ki: f32,
    kd: f32,
    kv: f32,
    ka: f32,
    dt_s: f32,
    limit_a: f32,
    anti_windup: AntiWindup,
    /// Integral term, A. Also clamped to +-limit: it can never ask for more than the limit.
    integral_a: f32,
    previous_error: Option<f32>,
}

impl PositionLoop {
    /// `dt_s` is the loop period; a non-positive or non-finite period is replaced by 0.5 ms
    /// (the paper-mode period), and a non-finite or negative limit by 0 A (no torque).
    pub fn new(gains: &SiGains, dt_s: f32, limit: Amps) -> Self {
        let mut loop_ = PositionLoop {
            kp: 0.0,
            ki: 0.0,
            kd: 0.0,
            kv: 0.0,
            ka: 0.0,
            dt_s: if dt_s.is_finite() && dt_s > 0.0 {
                dt_s
            } else {
                5e-4
            },
            limit_a: if limit.0.is_finite() && limit.0 >= 0.0 {
                limit.0
            } else {
                0.0
            },
            anti_windup: AntiWindup::default(),
            integral_a: 0.0,
            previous_error: None,
        };
        loop_.set_gains(gains);
        loop_
    }

    /// Gains arrive validated ([`SiGains`] cannot hold NaN or negative values).
    pub fn set_gains(&mut self, gains: &SiGains) {
        self.kp = gains.position_kp();
        self.ki = gains.position_ki();
        self.kd = gains.position_kd();
        self.kv = gains.ff_velocity();
        self.ka = gains.ff_acceleration();
    }

    pub fn set_anti_windup(&mut self, mode: AntiWindup) {
        self.anti_windup = mode;
    }

    pub fn limit(&self) -> Amps {
        Amps(self.limit_a)
    }

    pub fn integral(&self) -> Amps {
        Amps(self.integral_a)
    }

    /// Forget the integrator and the derivative history (drive disabled or re-enabled).
    pub fn reset(&mut self) {
        self.integral_a = 0.0;
        self.previous_error = None;
    }

    pub fn step(&mut self, setpoint: Setpoint, measured: MotorRad) -> PositionOutput {
        self.step_with(setpoint, measured, Amps::ZERO)
    }

    /// [`PositionLoop::step`] with `extra` added to the output before the limit (ECU mode's
    /// D term on the measured speed), so that the limit and the anti-windup see the whole
    /// demand. A non-finite `extra` is an input like the others: 0 A, state untouched.
    pub fn step_with(
        &mut self,
        setpoint: Setpoint,
        measured: MotorRad,
        extra: Amps,
    ) -> PositionOutput {
        let inputs_finite = setpoint.position.is_finite()
            && setpoint.velocity.is_finite()
            && setpoint.acceleration.is_finite()
            && measured.is_finite()
            && extra.is_finite();
        if !inputs_finite {
            return PositionOutput {
                current: Amps::ZERO,
                status: PositionStatus::InputNotFinite,
            };
        }
        let error = setpoint.position.0 - measured.0;
        let derivative = match self.previous_error {
            Some(previous) => (error - previous) / self.dt_s,
            None => 0.0,
        };
        // The integrator includes this tick's error only if that does not push the output
        // past the limit (conditional integration).
        let candidate_integral = self.integral_a + self.ki * error * self.dt_s;
        let unsaturated = self.kp * error
            + candidate_integral
            + self.kd * derivative
            + self.kv * setpoint.velocity
            + self.ka * setpoint.acceleration
            + extra.0;
        let (current, saturated) = saturate(unsaturated, self.limit_a);
        let integrate = match self.anti_windup {
            AntiWindup::ConditionalIntegration => !saturated,
            AntiWindup::IntegratorClamp | AntiWindup::Disabled => true,
        };
        if integrate && candidate_integral.is_finite() {
            let bound = match self.anti_windup {
                AntiWindup::Disabled => f32::MAX,
                AntiWindup::ConditionalIntegration | AntiWindup::IntegratorClamp => self.limit_a,
            };
            self.integral_a = saturate(candidate_integral, bound).0;
        }
        self.previous_error = error.is_finite().then_some(error);
        PositionOutput {
            current: Amps(current),
            status: if saturated {
                PositionStatus::Saturated
            } else {
                PositionStatus::Linear
            },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains::EposGains;

    fn paper_loop() -> PositionLoop {
        PositionLoop::new(&EposGains::PAPER.to_si().unwrap(), 5e-4, Amps(20.0))
    }

    fn hold(position: f32) -> Setpoint {
        Setpoint {
            position: MotorRad(position),
            velocity: 0.0,
            acceleration: 0.0,
        }
    }

    #[test]
    fn proportional_action_on_a_small_error() {
        let mut pl = paper_loop();
        let out = pl.step(hold(0.1), MotorRad(0.0));
        // Kp e + Ki e dt = 4.39 * 0.1 + 7.352 * 0.1 * 5e-4
        assert!((out.current.0 - (0.439 + 7.352 * 0.1 * 5e-4)).abs() < 1e-5);
        assert_eq!(out.status, PositionStatus::Linear);
    }

    #[test]
    fn derivative_acts_on_the_error_by_backward_difference() {
        let mut pl = paper_loop();
        pl.step(hold(0.0), MotorRad(0.0));
        let out = pl.step(hold(0.0), MotorRad(-0.001));
        // e = 0.001, de/dt = 2 rad/s, Kd = 0.15987 -> 0.31974 A, plus Kp e and the integral.
        let expected = 4.39e-3 + 0.15987 * 2.0 + 7.352 * 0.001 * 5e-4;
        assert!((out.current.0 - expected).abs() < 1e-5, "{}", out.current.0);
    }

    #[test]
    fn feedforward_adds_velocity_and_acceleration_terms() {
        let mut pl = paper_loop();
        let sp = Setpoint {
            position: MotorRad(0.0),
            velocity: 100.0,
            acceleration: 1000.0,
        };
        let out = pl.step(sp, MotorRad(0.0));
        assert!((out.current.0 - (0.01259 * 100.0 + 0.001783 * 1000.0)).abs() < 1e-4);
    }

    #[test]
    fn current_setpoint_never_exceeds_20_a() {
        let mut pl = paper_loop();
        for e in [1.0e3f32, -1.0e3, 3.0e38, -3.0e38] {
            let out = pl.step(hold(e), MotorRad(0.0));
            assert!(out.current.0.abs() <= 20.0);
            assert_eq!(out.status, PositionStatus::Saturated);
        }
    }

    #[test]
    fn integrator_is_frozen_while_saturated() {
        let mut pl = paper_loop();
        for _ in 0..1000 {
            pl.step(hold(100.0), MotorRad(0.0));
        }
        assert_eq!(pl.integral().0, 0.0);
        pl.set_anti_windup(AntiWindup::Disabled);
        for _ in 0..1000 {
            pl.step(hold(100.0), MotorRad(0.0));
        }
        assert!(pl.integral().0 > 300.0, "windup when disabled");
    }

    #[test]
    fn non_finite_input_commands_zero_current_and_keeps_state() {
        let mut pl = paper_loop();
        pl.step(hold(0.01), MotorRad(0.0));
        let integral = pl.integral();
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            let out = pl.step(hold(0.0), MotorRad(bad));
            assert_eq!(out.current, Amps::ZERO);
            assert_eq!(out.status, PositionStatus::InputNotFinite);
            let out = pl.step(hold(bad), MotorRad(0.0));
            assert_eq!(out.current, Amps::ZERO);
            let mut sp = hold(0.0);
            sp.velocity = bad;
            assert_eq!(pl.step(sp, MotorRad(0.0)).current, Amps::ZERO);
        }
        assert_eq!(pl.integral(), integral);
    }

    #[test]
    fn degenerate_period_and_limit_are_replaced() {
        let g = EposGains::PAPER.to_si().unwrap();
        let mut pl = PositionLoop::new(&g, f32::NAN, Amps(f32::NAN));
        let out = pl.step(hold(1.0), MotorRad(0.0));
        assert_eq!(out.current, Amps::ZERO, "NaN limit means no torque");
    }
}

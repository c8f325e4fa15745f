//! "Paper mode": the cascade at the rates and with the sensors of the paper's car, shared by the
//! firmware and host-sim so that a log from the car and a log from the simulation mean the
//! same thing.
//!
//! | what                    | paper mode                                   | source            |
//! |-------------------------|----------------------------------------------|-------------------|
//! | current loop            | PI, 20 kHz, +-24 V, conditional integration  | sec. 3.3, Table 3 |
//! | position loop           | PID + vel/acc feedforward, 2 kHz, +-20 A     | sec. 3.3, Table 3 |
//! | reference               | 100 Hz, interpolated, one sample of lag      | sec. 4.1          |
//! | derivative              | on the error, backward difference            | EPOS4             |
//! | position feedback       | Hall sensors, 84 counts/rev                  | EC 60 flat        |
//! | column encoder          | 12 bit/rev                                   | sec. 2            |
//!
//! The EPOS4 itself runs 25 kHz / 2.5 kHz; 20 kHz / 2 kHz are round divisors of a 100 Hz
//! reference that an STM32 timer hits exactly (10 current ticks per position tick, 20 position
//! ticks per reference period).
//!
//! Call order per position tick, as the firmware's interrupts and host-sim both do:
//! [`Cascade::push_reference`] when a sample arrives (every 20th tick), then
//! [`Cascade::position_step`], then ten [`Cascade::current_step`] with the current set-point it
//! produced.

use crate::control::AntiWindup;
use crate::control::current::{CurrentLoop, CurrentOutput, Winding};
use crate::control::position::{PositionLoop, PositionOutput};
use crate::gains::{EposGains, GainError, SiGains};
use crate::gearing::Gearing;
use crate::reference::{Interpolator, ReferenceError, Setpoint};
use crate::sensors::motor_from_hall;
use crate::units::{Amps, MotorRad, SteeringDeg, SteeringRad, Volts};

pub const CURRENT_LOOP_HZ: u32 = 20_000;
pub const POSITION_LOOP_HZ: u32 = 2_000;
pub const REFERENCE_HZ: u32 = 100;
pub const CURRENT_TICKS_PER_POSITION_TICK: u32 = CURRENT_LOOP_HZ / POSITION_LOOP_HZ;
pub const POSITION_TICKS_PER_REFERENCE: u32 = POSITION_LOOP_HZ / REFERENCE_HZ;
/// Motor current limit, A (section 3.3: "set to 20 A according to the motor capabilities").
pub const CURRENT_LIMIT: Amps = Amps(20.0);
/// Voltage limit, V (section 3.3 and 4.1: the 24 V LV battery).
pub const VOLTAGE_LIMIT: Volts = Volts(24.0);
/// Motor terminal resistance, ohm (Table 1), for the current guard's winding model.
pub const MOTOR_RA_OHM: f32 = 0.293;
/// Motor terminal inductance, H (Table 1).
pub const MOTOR_LA_H: f32 = 0.279e-3;
/// Steering range accepted as a reference, deg at the wheel (section 2: -90..+90 deg).
pub const STEERING_RANGE_DEG: f32 = 90.0;

/// The range of the ECU's own samples (the enable ramp), deg at the wheel: the drive's position
/// limits ([`crate::canopen::epos4::POSITION_LIMIT_DEG`], 110 deg). A column beyond the
/// vehicle's +-90 deg at an enable is where the ramp must start, not a sample to refuse.
pub const RAMP_RANGE_DEG: f32 = crate::canopen::epos4::POSITION_LIMIT_DEG;

/// A reference sample at the wheel as a motor angle; refused if it is not finite or beyond
/// +-[`STEERING_RANGE_DEG`]. Every controller takes its samples through this.
pub fn reference_at_motor(
    gearing: Gearing,
    angle: SteeringDeg,
) -> Result<MotorRad, ReferenceError> {
    within_at_motor(gearing, angle, STEERING_RANGE_DEG)
}

/// The ECU's own sample (the enable ramp) as a motor angle; refused if it is not finite or
/// beyond +-[`RAMP_RANGE_DEG`].
pub fn ramp_at_motor(gearing: Gearing, angle: SteeringDeg) -> Result<MotorRad, ReferenceError> {
    within_at_motor(gearing, angle, RAMP_RANGE_DEG)
}

fn within_at_motor(
    gearing: Gearing,
    angle: SteeringDeg,
    range_deg: f32,
) -> Result<MotorRad, ReferenceError> {
    if !angle.is_finite() {
        return Err(ReferenceError::NotFinite);
    }
    if angle.0.abs() > range_deg {
        return Err(ReferenceError::OutOfRange);
    }
    Ok(gearing.motor_from_steering(SteeringRad::from(angle)))
}

/// The whole cascade: reference interpolator, position loop, current loop.
#[derive(Debug, Clone)]
pub struct Cascade {
    gearing: Gearing,
    interpolator: Interpolator,
    position: PositionLoop,
    current: CurrentLoop,
    current_setpoint: Amps,
    last_setpoint: Setpoint,
}

impl Cascade {
    /// The cascade with the current guard modelling the Table 1 winding; see
    /// [`Cascade::set_winding`] for another motor.
    pub fn new(gains: &SiGains, gearing: Gearing) -> Self {
        let mut cascade = Cascade {
            gearing,
            interpolator: Interpolator::new(
                POSITION_TICKS_PER_REFERENCE as u16,
                1.0 / REFERENCE_HZ as f32,
            ),
            position: PositionLoop::new(gains, 1.0 / POSITION_LOOP_HZ as f32, CURRENT_LIMIT),
            current: CurrentLoop::new(
                gains,
                1.0 / CURRENT_LOOP_HZ as f32,
                CURRENT_LIMIT,
                VOLTAGE_LIMIT,
            ),
            current_setpoint: Amps::ZERO,
            last_setpoint: Setpoint::default(),
        };
        cascade.set_winding(MOTOR_RA_OHM, MOTOR_LA_H);
        cascade
    }

    /// The winding the current guard models (ohm, H); invalid values turn the guard off.
    pub fn set_winding(&mut self, ra_ohm: f32, la_h: f32) {
        self.current
            .set_winding(Winding::new(ra_ohm, la_h, 1.0 / CURRENT_LOOP_HZ as f32));
    }

    /// The paper's actuator with the Table 3 gains.
    pub fn paper() -> Self {
        match EposGains::PAPER.to_si() {
            Ok(gains) => Self::new(&gains, Gearing::PAPER),
            // Table 3 is finite and non-negative; the unit test `paper_gains_convert_to_si`
            // pins it. Zero gains would be the safe fallback.
            Err(_) => Self::new(&SiGains::ZERO, Gearing::PAPER),
        }
    }

    /// New gains for both loops; refused as a whole (old gains kept) if any is invalid.
    pub fn set_gains(&mut self, gains: &EposGains) -> Result<(), GainError> {
        let si = gains.to_si()?;
        self.position.set_gains(&si);
        self.current.set_gains(&si);
        Ok(())
    }

    pub fn set_anti_windup(&mut self, mode: AntiWindup) {
        self.position.set_anti_windup(mode);
        self.current.set_anti_windup(mode);
    }

    /// Voltage limit of the current loop, e.g. the measured battery voltage (default 24 V).
    /// Non-finite or negative values are ignored.
    pub fn set_voltage_limit(&mut self, limit: Volts) {
        self.current.set_voltage_limit(limit);
    }

    /// Anti-windup of the current loop alone (the position loop keeps its own).
    pub fn set_current_anti_windup(&mut self, mode: AntiWindup) {
        self.current.set_anti_windup(mode);
    }

    pub fn gearing(&self) -> Gearing {
        self.gearing
    }

    /// A new reference sample at the wheel. Refused (and the ramp in progress continues) if
    /// it is not finite or beyond +-[`STEERING_RANGE_DEG`].
    pub fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        let motor = reference_at_motor(self.gearing, angle)?;
        self.interpolator.push(motor)
    }

    /// A sample the ECU made itself (the enable ramp), taken within +-[`RAMP_RANGE_DEG`].
    pub fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        let motor = ramp_at_motor(self.gearing, angle)?;
        self.interpolator.push(motor)
    }

    /// One position-loop tick (2 kHz) with the multi-turn Hall count as feedback.
    pub fn position_step(&mut self, hall_count: i32) -> PositionOutput {
        self.position_step_at(motor_from_hall(hall_count))
    }

    /// One position-loop tick with the motor angle from another sensor (an encoder, or the
    /// exact angle in simulation).
    pub fn position_step_at(&mut self, motor: MotorRad) -> PositionOutput {
        let setpoint = self.interpolator.next_setpoint();
        self.last_setpoint = setpoint;
        let out = self.position.step(setpoint, motor);
        self.current_setpoint = out.current;
        out
    }

    /// One current-loop tick (20 kHz) with the measured motor current.
    pub fn current_step(&mut self, measured: Amps) -> CurrentOutput {
        self.current.step(self.current_setpoint, measured)
    }

    /// The set-point of the last position tick (motor side), for logs.
    pub fn setpoint(&self) -> Setpoint {
        self.last_setpoint
    }

    pub fn current_setpoint(&self) -> Amps {
        self.current_setpoint
    }

    /// Drive disabled: integrators and derivative history cleared, current set-point 0, and
    /// the reference held at `hall_count` until new samples come.
    pub fn reset(&mut self, hall_count: i32) {
        self.position.reset();
        self.current.reset();
        self.current_setpoint = Amps::ZERO;
        self.interpolator.reset_to(motor_from_hall(hall_count));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rates_divide_evenly() {
        assert_eq!(
            CURRENT_TICKS_PER_POSITION_TICK * POSITION_LOOP_HZ,
            CURRENT_LOOP_HZ
        );
        assert_eq!(
            POSITION_TICKS_PER_REFERENCE * REFERENCE_HZ,
            POSITION_LOOP_HZ
        );
    }

    #[test]
    fn refuses_out_of_range_and_non_finite_references() {
        let mut c = Cascade::paper();
        assert_eq!(c.push_reference(SteeringDeg(0.0)), Ok(()));
        assert_eq!(
            c.push_reference(SteeringDeg(90.5)),
            Err(ReferenceError::OutOfRange)
        );
        assert_eq!(
            c.push_reference(SteeringDeg(f32::NAN)),
            Err(ReferenceError::NotFinite)
        );
        assert_eq!(c.push_reference(SteeringDeg(-90.0)), Ok(()));
    }

    #[test]
    fn reference_step_drives_current_towards_it_within_limits() {
        let mut c = Cascade::paper();
        c.push_reference(SteeringDeg(0.0)).unwrap();
        c.push_reference(SteeringDeg(10.0)).unwrap();
        let pos = c.position_step(0);
        assert!(pos.current.0 > 0.0 && pos.current.0 <= 20.0);
        let v = c.current_step(Amps(0.0));
        assert!(v.voltage.0 > 0.0 && v.voltage.0 <= 24.0);
    }

    #[test]
    fn invalid_gains_are_refused_as_a_whole() {
        let mut c = Cascade::paper();
        let mut g = EposGains::PAPER;
        g.position_kp_ma_per_rad = -1.0;
        assert!(c.set_gains(&g).is_err());
        // Old gains still in force: a 1-count error gives the paper's Kp response.
        c.push_reference(SteeringDeg(0.0)).unwrap();
        let out = c.position_step(-1);
        assert!(out.current.0 > 0.3, "{}", out.current.0);
    }
}

#[cfg(test)]
mod garbage_tests {
    //! Whatever arrives, the outputs stay finite and within 20 A / 24 V, and nothing panics.
    use super::*;

    use det_rng::XorShift64Star as Rng;

    #[test]
    fn arbitrary_inputs_give_bounded_finite_outputs() {
        let mut rng = Rng::from_state(0x9E37_79B9_7F4A_7C15);
        let mut c = Cascade::paper();
        for k in 0..200_000u32 {
            match rng.next_u64() % 8 {
                0 => {
                    let _ = c.push_reference(SteeringDeg(rng.any_f32(120.0)));
                }
                1 => {
                    let out = c.position_step(rng.next_u64() as i32);
                    assert!(
                        out.current.0.is_finite() && out.current.0.abs() <= 20.0,
                        "{k}"
                    );
                }
                2 => {
                    let out = c.position_step_at(MotorRad(rng.any_f32(200.0)));
                    assert!(
                        out.current.0.is_finite() && out.current.0.abs() <= 20.0,
                        "{k}"
                    );
                }
                3 if k % 1000 == 3 => c.reset(rng.next_u64() as i32),
                4 if k % 5000 == 4 => {
                    let mut g = EposGains::PAPER;
                    g.position_kd_ma_s_per_rad = rng.any_f32(1000.0);
                    let _ = c.set_gains(&g);
                }
                5 if k % 5000 == 5 => c.set_winding(rng.any_f32(1.0), rng.any_f32(1e-3)),
                _ => {
                    let out = c.current_step(Amps(rng.any_f32(40.0)));
                    assert!(
                        out.voltage.0.is_finite() && out.voltage.0.abs() <= 24.0,
                        "{k}"
                    );
                }
            }
        }
    }
}

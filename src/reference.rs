//! The 100 Hz steering reference, turned into a position set-point for every position-loop
//! tick, the way the EPOS4 does in cyclic synchronous position mode.
//!
//! When sample `r[n]` arrives, the set-point runs linearly from `r[n-1]` to `r[n]` over the
//! next reference period: one sample of lag, no extrapolation. The velocity feedforward is the
//! slope of that segment and the acceleration feedforward the change of slope per period.
//!
//! ```text
//!  r[n-1]        r[n]          samples arrive at nT
//!    *-------------*
//!     \____ setpoint during [nT, (n+1)T) ____/
//! ```
//!
//! Outcomes for bad input (documented, tested): a non-finite sample is refused and the segment
//! in progress continues; when no new sample arrives the set-point stops at the last sample
//! and the feedforward drops to zero (hold). Watching for that timeout is the job of the layer
//! above.

use crate::units::MotorRad;

/// Position, velocity and acceleration the position loop is asked to follow (motor side).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Setpoint {
    pub position: MotorRad,
    /// rad/s at the motor
    pub velocity: f32,
    /// rad/s^2 at the motor
    pub acceleration: f32,
}

/// Why a reference sample was not taken.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ReferenceError {
    /// NaN or infinite: refused, the set-point carries on as if the sample had not come.
    NotFinite,
    /// Beyond the configured steering range: refused likewise.
    OutOfRange,
}

/// Linear interpolation of a periodic reference with one sample of lag.
#[derive(Debug, Clone)]
pub struct Interpolator {
    ticks_per_period: u16,
    period_s: f32,
    start: f32,
    end: f32,
    slope: f32,
    accel: f32,
    tick: u16,
    primed: bool,
}

impl Interpolator {
    /// `ticks_per_period` position-loop ticks per reference period of `period_s` seconds.
    /// Zero ticks is treated as one, and a non-positive or non-finite period as 10 ms, so any
    /// configuration has a defined behaviour.
    pub fn new(ticks_per_period: u16, period_s: f32) -> Self {
        let period_s = if period_s.is_finite() && period_s > 0.0 {
            period_s
        } else {
            0.01
        };
        Interpolator {
            ticks_per_period: ticks_per_period.max(1),
            period_s,
            start: 0.0,
            end: 0.0,
            slope: 0.0,
            accel: 0.0,
            tick: 0,
            primed: false,
        }
    }

    /// Hold `position` with no feedforward until the next sample; the next sample then ramps
    /// from here. Used when the drive is enabled, so it starts where the motor is.
    pub fn reset_to(&mut self, position: MotorRad) {
        let p = if position.is_finite() {
            position.0
        } else {
            0.0
        };
        self.start = p;
        self.end = p;
        self.slope = 0.0;
        self.accel = 0.0;
        self.tick = self.ticks_per_period;
        self.primed = true;
    }

    /// Take a new sample (motor side). The first sample ever is held, not ramped to.
    pub fn push(&mut self, sample: MotorRad) -> Result<(), ReferenceError> {
        if !sample.is_finite() {
            return Err(ReferenceError::NotFinite);
        }
        if !self.primed {
            self.reset_to(sample);
            return Ok(());
        }
        let slope = (sample.0 - self.end) / self.period_s;
        // A segment that had already ended (late sample) was held at zero velocity.
        let previous_slope = if self.tick >= self.ticks_per_period {
            0.0
        } else {
            self.slope
        };
        self.accel = (slope - previous_slope) / self.period_s;
        self.start = self.end;
        self.end = sample.0;
        self.slope = slope;
        self.tick = 0;
        Ok(())
    }

    /// The set-point for this position-loop tick; advances by one tick.
    pub fn next_setpoint(&mut self) -> Setpoint {
        if self.tick >= self.ticks_per_period {
            return Setpoint {
                position: MotorRad(self.end),
                velocity: 0.0,
                acceleration: 0.0,
            };
        }
        let frac = self.tick as f32 / self.ticks_per_period as f32;
        self.tick += 1;
        Setpoint {
            position: MotorRad(self.start + (self.end - self.start) * frac),
            velocity: self.slope,
            acceleration: self.accel,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ramps_between_the_last_two_samples_with_one_sample_of_lag() {
        let mut it = Interpolator::new(20, 0.01);
        it.push(MotorRad(0.0)).unwrap();
        it.push(MotorRad(1.0)).unwrap();
        let first = it.next_setpoint();
        assert_eq!(first.position.0, 0.0, "starts at the previous sample");
        assert!((first.velocity - 100.0).abs() < 1e-3, "slope 1 rad / 10 ms");
        for _ in 0..9 {
            it.next_setpoint();
        }
        let mid = it.next_setpoint();
        assert!((mid.position.0 - 0.5).abs() < 1e-6);
    }

    #[test]
    fn acceleration_feedforward_is_the_change_of_slope_per_period() {
        let mut it = Interpolator::new(20, 0.01);
        for r in [0.0, 0.0, 1.0, 3.0] {
            it.push(MotorRad(r)).unwrap();
        }
        let sp = it.next_setpoint();
        // slopes 100 then 200 rad/s, 10 ms apart.
        assert!((sp.velocity - 200.0).abs() < 1e-3);
        assert!((sp.acceleration - 10_000.0).abs() < 1e-1);
    }

    #[test]
    fn holds_the_last_sample_when_the_reference_stops() {
        let mut it = Interpolator::new(20, 0.01);
        it.push(MotorRad(0.0)).unwrap();
        it.push(MotorRad(2.0)).unwrap();
        let mut last = Setpoint::default();
        for _ in 0..100 {
            last = it.next_setpoint();
        }
        assert_eq!(last.position.0, 2.0);
        assert_eq!(last.velocity, 0.0);
        assert_eq!(last.acceleration, 0.0);
    }

    #[test]
    fn refuses_non_finite_samples_and_carries_on() {
        let mut it = Interpolator::new(20, 0.01);
        it.push(MotorRad(0.0)).unwrap();
        it.push(MotorRad(1.0)).unwrap();
        assert_eq!(it.push(MotorRad(f32::NAN)), Err(ReferenceError::NotFinite));
        assert_eq!(
            it.push(MotorRad(f32::NEG_INFINITY)),
            Err(ReferenceError::NotFinite)
        );
        let sp = it.next_setpoint();
        assert_eq!(sp.position.0, 0.0);
        assert!((sp.velocity - 100.0).abs() < 1e-3);
    }

    #[test]
    fn degenerate_configuration_still_behaves() {
        let mut it = Interpolator::new(0, f32::NAN);
        it.push(MotorRad(0.0)).unwrap();
        it.push(MotorRad(1.0)).unwrap();
        let sp = it.next_setpoint();
        assert!(sp.position.is_finite() && sp.velocity.is_finite());
    }
}

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
//! When a sample arrives, relative to the segment in progress (`N` = position ticks per
//! reference period, the position loop calls [`Interpolator::next_setpoint`] once per tick):
//!
//! | arrival  | definition                                                  | new segment starts at  | previous slope |
//! |----------|-------------------------------------------------------------|------------------------|----------------|
//! | on time  | exactly `N` set-points taken since the last sample          | the last sample        | the segment's  |
//! | late     | the set-point was already held at the segment end >= 1 tick | the last sample        | 0 (it was held)|
//! | early    | fewer than `N` set-points taken since the last sample       | the set-point due next | the segment's  |
//!
//! The firmware's and host-sim's call pattern (a sample, then `N` set-points, then the next
//! sample) is "on time" for every sample, so the acceleration feedforward is the change of
//! slope per period and a constant-velocity ramp gets none. An early sample continues from
//! where the set-point is, so the set-point never jumps.
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
    /// Set-points taken in the current segment (saturates at `ticks_per_period`).
    tick: u16,
    /// The set-point has been held at `end` for at least one tick (reference late or stopped).
    held: bool,
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
            held: false,
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
        self.held = true;
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
        let (start, previous_slope) = if self.held {
            // Late: the set-point stood still at the segment end, so it starts from rest there.
            (self.end, 0.0)
        } else if self.tick < self.ticks_per_period {
            // Early: continue from the set-point the next tick would have had.
            (self.position_at(self.tick), self.slope)
        } else {
            // On time: the segment just ended at `end` with its own slope.
            (self.end, self.slope)
        };
        let slope = (sample.0 - start) / self.period_s;
        self.accel = (slope - previous_slope) / self.period_s;
        self.start = start;
        self.end = sample.0;
        self.slope = slope;
        self.tick = 0;
        self.held = false;
        Ok(())
    }

    /// The set-point for this position-loop tick; advances by one tick.
    pub fn next_setpoint(&mut self) -> Setpoint {
        if self.tick >= self.ticks_per_period {
            self.held = true;
            return Setpoint {
                position: MotorRad(self.end),
                velocity: 0.0,
                acceleration: 0.0,
            };
        }
        let position = self.position_at(self.tick);
        // Below `ticks_per_period` (checked above): no overflow.
        self.tick = self.tick.saturating_add(1);
        Setpoint {
            position: MotorRad(position),
            velocity: self.slope,
            acceleration: self.accel,
        }
    }

    /// Where the current segment ends: the newest sample (motor side).
    pub fn segment_end(&self) -> MotorRad {
        MotorRad(self.end)
    }

    /// The set-point `tick` ticks into the current segment.
    fn position_at(&self, tick: u16) -> f32 {
        let frac = tick as f32 / self.ticks_per_period as f32;
        self.start + (self.end - self.start) * frac
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

    /// The real call pattern: a sample, then `ticks` set-points, as the position loop takes them.
    fn push_then_run(it: &mut Interpolator, sample: f32, ticks: usize) -> Vec<Setpoint> {
        it.push(MotorRad(sample)).unwrap();
        (0..ticks).map(|_| it.next_setpoint()).collect()
    }

    #[test]
    fn acceleration_feedforward_is_the_change_of_slope_per_period() {
        let mut it = Interpolator::new(20, 0.01);
        push_then_run(&mut it, 0.0, 20);
        push_then_run(&mut it, 0.0, 20);
        let first = push_then_run(&mut it, 1.0, 20);
        let second = push_then_run(&mut it, 3.0, 20);
        // Slopes 0, 100, then 200 rad/s, 10 ms apart.
        assert!((first[0].velocity - 100.0).abs() < 1e-3);
        assert!((first[0].acceleration - 10_000.0).abs() < 1e-1);
        assert!((second[0].velocity - 200.0).abs() < 1e-3);
        assert!(
            (second[0].acceleration - 10_000.0).abs() < 1e-1,
            "{}",
            second[0].acceleration
        );
        assert_eq!(
            second[0].position.0, 1.0,
            "on time: starts at the last sample"
        );
    }

    #[test]
    fn constant_velocity_ramp_has_no_acceleration_feedforward_after_its_first_period() {
        let mut it = Interpolator::new(20, 0.01);
        push_then_run(&mut it, 0.0, 20);
        for n in 1..50 {
            let period = push_then_run(&mut it, 0.5 * n as f32, 20);
            for sp in &period {
                assert!((sp.velocity - 50.0).abs() < 1e-2, "period {n}: {sp:?}");
                if n == 1 {
                    assert!((sp.acceleration - 5_000.0).abs() < 1.0, "{sp:?}");
                } else {
                    assert_eq!(sp.acceleration, 0.0, "period {n}: {sp:?}");
                }
            }
            // The set-point moves by one tick's share of the slope each tick: no jumps.
            for w in period.windows(2) {
                assert!((w[1].position.0 - w[0].position.0 - 0.025).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn late_sample_starts_from_rest_at_the_held_end() {
        let mut it = Interpolator::new(20, 0.01);
        push_then_run(&mut it, 0.0, 20);
        push_then_run(&mut it, 1.0, 20);
        // The next sample is one tick late: the set-point is held at 1.0 for one tick.
        let held = it.next_setpoint();
        assert_eq!(
            (held.position.0, held.velocity, held.acceleration),
            (1.0, 0.0, 0.0)
        );
        let period = push_then_run(&mut it, 2.0, 20);
        assert_eq!(period[0].position.0, 1.0);
        assert!((period[0].velocity - 100.0).abs() < 1e-3);
        // From standstill to 100 rad/s in one period.
        assert!((period[0].acceleration - 10_000.0).abs() < 1e-1);
    }

    #[test]
    fn early_sample_continues_from_the_current_set_point() {
        let mut it = Interpolator::new(20, 0.01);
        push_then_run(&mut it, 0.0, 20);
        push_then_run(&mut it, 1.0, 20);
        // 18 of 20 ticks taken, then the next sample arrives two ticks early.
        let partial = push_then_run(&mut it, 2.0, 18);
        assert!((partial[17].position.0 - (1.0 + 17.0 / 20.0)).abs() < 1e-6);
        let period = push_then_run(&mut it, 3.0, 20);
        let continued = 1.0 + 18.0 / 20.0;
        assert!(
            (period[0].position.0 - continued).abs() < 1e-6,
            "no jump: {:?}",
            period[0]
        );
        let slope = (3.0 - continued) / 0.01;
        assert!((period[0].velocity - slope).abs() < 1e-2);
        // The segment in progress still had its slope of 100 rad/s.
        assert!((period[0].acceleration - (slope - 100.0) / 0.01).abs() < 5.0);
    }

    #[test]
    fn stop_holds_with_no_feedforward_then_restarts_from_rest() {
        let mut it = Interpolator::new(20, 0.01);
        push_then_run(&mut it, 0.0, 20);
        push_then_run(&mut it, 1.0, 20);
        push_then_run(&mut it, 2.0, 20);
        // The reference stops for 5 periods.
        for _ in 0..100 {
            let sp = it.next_setpoint();
            assert_eq!(
                (sp.position.0, sp.velocity, sp.acceleration),
                (2.0, 0.0, 0.0)
            );
        }
        let period = push_then_run(&mut it, 2.0, 20);
        assert!(
            period
                .iter()
                .all(|sp| sp.position.0 == 2.0 && sp.velocity == 0.0 && sp.acceleration == 0.0)
        );
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

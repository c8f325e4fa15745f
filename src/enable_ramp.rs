//! The enable ramp: after every enable the angle given to the drive starts at the measured
//! column, at rest, and moves toward the vehicle's reference with limited acceleration, at
//! most [`ENABLE_RAMP_DPS`], slowing down again so that it meets a resting reference at rest.
//!
//! Why the acceleration is limited: the drive follows its set-point with a position loop whose
//! velocity feedforward and D term answer a step in the set-point's speed with a step in
//! current. A ramp that starts at full speed from rest is such a step: the paper's loop asks
//! the full 20 A for the first ~10 ms of it, a jolt in the driver's hands on the wheel. Started
//! at [`ENABLE_RAMP_ACCEL_DPS2`] the set-point's speed grows by 10 deg/s per reference period,
//! and the loop asks a few amps.
//!
//! ```text
//!  speed
//!   70 deg/s |      ___________________
//!            |     /                   \
//!            |    /                     \      accelerate at ENABLE_RAMP_ACCEL_DPS2,
//!            |   /                       \     cruise at ENABLE_RAMP_DPS, and slow
//!          0 +--/-------------------------\--  down to meet the reference at rest
//!            enable                      met
//! ```

use crate::units::SteeringDeg;

/// The ramp's cruising speed, deg/s at the wheel. Why 70 deg/s: moving the paper's actuator
/// at a steady 100 deg/s already takes 10-11 A (the nut's and the motor's damping), more than
/// half the 20 A limit, before any acceleration; at 70 deg/s it takes about 7.5 A, and a
/// driver's hands on the wheel are not struck. 60 deg take 0.93 s with the acceleration and
/// the slowing down: within the 1 s the vehicle computer gives the steering in AS Ready.
pub const ENABLE_RAMP_DPS: f32 = 70.0;

/// The ramp's acceleration (and deceleration), deg/s^2 at the wheel: full speed after 0.07 s
/// and 2.5 deg. The ramp's speed steps by 10 deg/s per 10 ms reference period, a tenth of the
/// 100 deg/s step that asked the full 20 A for the first 10 ms when the ramp started at full
/// speed.
pub const ENABLE_RAMP_ACCEL_DPS2: f32 = 1000.0;

/// Where the ramp is: the last angle it gave, when, and how fast it was moving then.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EnableRamp {
    at: SteeringDeg,
    since_us: u64,
    /// deg/s at the wheel, never negative: the ramp moves toward the reference.
    speed_dps: f32,
    /// The sign of the ramp's last step (0 at rest): a reference on the other side of the
    /// ramp's angle has crossed it.
    direction: f32,
}

impl EnableRamp {
    /// A ramp at rest at `at` (the measured column) at `now_us`. A non-finite `at` is kept:
    /// the first [`EnableRamp::step`] then hands over to the reference at once.
    pub fn at_rest(at: SteeringDeg, now_us: u64) -> Self {
        EnableRamp {
            at,
            since_us: now_us,
            speed_dps: 0.0,
            direction: 0.0,
        }
    }

    /// The last angle the ramp gave, deg at the wheel.
    pub fn angle(&self) -> SteeringDeg {
        self.at
    }

    /// The ramp's next angle toward `target` at `now_us`, or `None` once it has met the
    /// target (the caller gives the target itself from then on). The time since the last step
    /// counts for at most `max_dt_us` (one reference period): a late frame moves the angle no
    /// further than an on-time one. A non-finite target moves nothing and ends nothing; a
    /// non-finite angle (the column was not known at the enable) ends the ramp.
    pub fn step(
        &mut self,
        now_us: u64,
        target: SteeringDeg,
        max_dt_us: u64,
    ) -> Option<SteeringDeg> {
        if !self.at.is_finite() {
            return None;
        }
        let dt_s = now_us.saturating_sub(self.since_us).min(max_dt_us) as f32 * 1e-6;
        self.since_us = now_us;
        let gap = target.0 - self.at.0;
        if !gap.is_finite() {
            // The set-point waits where it is: at rest there.
            self.speed_dps = 0.0;
            self.direction = 0.0;
            return Some(self.at);
        }
        if self.direction != 0.0 && gap * self.direction < 0.0 {
            // A moving reference crossed the ramp: from here the reference leads.
            return None;
        }
        let speed_step = ENABLE_RAMP_ACCEL_DPS2 * dt_s;
        // The fastest speed, in whole steps of `speed_step`, from which steps of
        // `speed_step` less each period still stop at the target: from k steps' speed, k
        // periods of slowing down cover speed_step * dt * k (k + 1) / 2. At least one step:
        // a gap shorter than the slowest step is met by it.
        let stopping = if speed_step > 0.0 {
            let k = (sqrt(1.0 + 8.0 * gap.abs() / (speed_step * dt_s)) - 1.0) / 2.0;
            // Whole steps, rounded down (k >= 0, and the cast saturates), a thousandth of a
            // step over: the root of an exact square may round below it.
            speed_step * ((k + 1e-3) as u32 as f32).max(1.0)
        } else {
            0.0
        };
        let speed = (self.speed_dps + speed_step)
            .min(ENABLE_RAMP_DPS)
            .min(stopping);
        let max_step = speed * dt_s;
        if gap.abs() <= max_step {
            return None;
        }
        self.speed_dps = speed;
        self.direction = if max_step > 0.0 { gap.signum() } else { 0.0 };
        self.at = SteeringDeg(self.at.0 + max_step * gap.signum());
        Some(self.at)
    }
}

/// The square root of `x >= 1` (no libm on the target): Newton's method from the exponent's
/// halving, which is within 4 % of the root; four steps take that below f32's resolution.
/// Deterministic, so the host and the target compute the same bits.
fn sqrt(x: f32) -> f32 {
    let mut y = f32::from_bits((x.to_bits() >> 1).saturating_add(0x1fbd_1df5));
    for _ in 0..4 {
        y = 0.5 * (y + x / y);
    }
    y
}

#[cfg(test)]
mod tests {
    use super::*;

    const PERIOD_US: u64 = 10_000;

    /// The ramp's angles, one per period, from 0 deg at rest toward `target` until it meets
    /// it; and the period at which it did.
    fn ramp_to(target: f32) -> (Vec<f32>, usize) {
        let mut ramp = EnableRamp::at_rest(SteeringDeg(0.0), 0);
        let mut angles = vec![0.0];
        for k in 1..1000u64 {
            match ramp.step(k * PERIOD_US, SteeringDeg(target), PERIOD_US) {
                Some(a) => angles.push(a.0),
                None => {
                    angles.push(target);
                    return (angles, k as usize);
                }
            }
        }
        panic!("the ramp to {target} deg never met it");
    }

    #[test]
    fn the_ramp_starts_and_ends_at_rest_and_cruises_at_its_speed() {
        for target in [0.3f32, 5.0, 60.0, -60.0, -110.0] {
            let (angles, met) = ramp_to(target);
            let dt = PERIOD_US as f32 * 1e-6;
            let speeds: Vec<f32> = angles.windows(2).map(|w| (w[1] - w[0]) / dt).collect();
            let mut previous = 0.0f32;
            for (k, &v) in speeds.iter().chain([0.0].iter()).enumerate() {
                assert!(
                    v.abs() <= ENABLE_RAMP_DPS + 1e-3,
                    "{target}: {v} deg/s at period {k}"
                );
                // Speed steps of one period's acceleration, and a float's rounding.
                assert!(
                    (v - previous).abs() <= ENABLE_RAMP_ACCEL_DPS2 * dt + 0.05,
                    "{target}: speed {previous} -> {v} deg/s at period {k}"
                );
                assert!(v * target >= 0.0, "{target}: moved away at period {k}");
                previous = v;
            }
            // Distance over the cruising speed plus the time to reach it, and a period.
            let bound = target.abs() / ENABLE_RAMP_DPS + ENABLE_RAMP_DPS / ENABLE_RAMP_ACCEL_DPS2;
            assert!(
                (met as f32) * dt <= bound + 2.0 * dt,
                "{target}: met after {met} periods"
            );
        }
        let (angles, _) = ramp_to(60.0);
        assert!(
            angles
                .windows(2)
                .any(|w| ((w[1] - w[0]) / 0.01 - ENABLE_RAMP_DPS).abs() < 1e-2),
            "a far target is reached at the cruising speed"
        );
    }

    /// The ramp is as fast as its acceleration allows: a target of k^2 speed steps (one
    /// period's acceleration times a period: 0.1 deg) is met in 2k - 1 periods, k - 1 of them
    /// accelerating, one at k steps' speed and k - 1 slowing down, the last of which reaches
    /// the target. These gaps are where the stopping speed's root is a whole number, the
    /// rounding the thousandth of a step guards.
    #[test]
    fn a_target_of_k_squared_speed_steps_is_met_in_2k_minus_1_periods() {
        let speed_step_deg = ENABLE_RAMP_ACCEL_DPS2 * 1e-4;
        for k in 2..=6u32 {
            for sign in [1.0f32, -1.0] {
                let target = sign * (k * k) as f32 * speed_step_deg;
                let (angles, _) = ramp_to(target);
                // The period the angle reaches the target (the ramp may say so one period
                // later, when a float's rounding leaves a sliver of the gap).
                let there = angles.iter().position(|a| (a - target).abs() < 1e-4);
                assert_eq!(
                    there,
                    Some((2 * k - 1) as usize),
                    "{target} deg: {angles:?}"
                );
            }
        }
    }

    /// A step that moved nothing (two frames at the same instant) leaves the ramp at rest
    /// with no direction: a reference that then lies on the other side has not crossed a
    /// moving ramp, and the ramp turns to it.
    #[test]
    fn a_ramp_that_has_not_moved_turns_to_a_reference_on_the_other_side() {
        let mut fresh = EnableRamp::at_rest(SteeringDeg(0.0), 0);
        let mut stepped = fresh;
        let _ = stepped.step(0, SteeringDeg(10.0), PERIOD_US);
        assert_eq!(stepped.angle(), SteeringDeg(0.0));
        let expected = fresh.step(PERIOD_US, SteeringDeg(-10.0), PERIOD_US);
        assert!(expected.is_some_and(|a| a.0 < 0.0), "{expected:?}");
        assert_eq!(
            stepped.step(PERIOD_US, SteeringDeg(-10.0), PERIOD_US),
            expected
        );
    }

    #[test]
    fn the_square_root_is_exact_to_f32() {
        for x in [1.0f32, 2.0, 9.0, 25.0, 17_601.0, 1.0e6, 3.3e7] {
            let y = sqrt(x);
            assert!(
                ((y as f64) - (x as f64).sqrt()).abs() <= 2e-7 * (x as f64).sqrt(),
                "{x}: {y}"
            );
        }
    }

    #[test]
    fn a_late_frame_moves_no_further_than_an_on_time_one() {
        let mut on_time = EnableRamp::at_rest(SteeringDeg(0.0), 0);
        let mut late = on_time;
        let _ = on_time.step(PERIOD_US, SteeringDeg(60.0), PERIOD_US);
        let _ = late.step(5 * PERIOD_US, SteeringDeg(60.0), PERIOD_US);
        assert_eq!(on_time.angle(), late.angle());
    }

    #[test]
    fn bad_values_move_nothing_and_a_crossing_reference_takes_over() {
        let mut ramp = EnableRamp::at_rest(SteeringDeg(0.0), 0);
        assert_eq!(
            ramp.step(0, SteeringDeg(10.0), PERIOD_US),
            Some(SteeringDeg(0.0))
        );
        for k in 1..5u64 {
            let _ = ramp.step(k * PERIOD_US, SteeringDeg(10.0), PERIOD_US);
        }
        let here = ramp.angle();
        assert!(here.0 > 0.0);
        assert_eq!(
            ramp.step(5 * PERIOD_US, SteeringDeg(f32::NAN), PERIOD_US),
            Some(here)
        );
        assert_eq!(
            ramp.step(6 * PERIOD_US, SteeringDeg(f32::INFINITY), PERIOD_US),
            Some(here)
        );
        // At rest again after the bad samples: the next step is one period's acceleration.
        let next = ramp.step(7 * PERIOD_US, SteeringDeg(10.0), PERIOD_US);
        let expected = here.0 + ENABLE_RAMP_ACCEL_DPS2 * 1e-4;
        assert!(
            next.is_some_and(|a| (a.0 - expected).abs() < 1e-4),
            "{next:?}"
        );
        // A reference behind the ramp's angle has crossed it: the reference leads.
        assert_eq!(ramp.step(8 * PERIOD_US, SteeringDeg(-1.0), PERIOD_US), None);
        let mut unknown = EnableRamp::at_rest(SteeringDeg(f32::NAN), 0);
        assert_eq!(unknown.step(PERIOD_US, SteeringDeg(10.0), PERIOD_US), None);
    }
}

//! The runaway check: the drive pushing toward the reference with all it has while the column
//! keeps moving away from it, no slower than when the push began. The drive has lost control
//! of the current's direction (a sign-flipped current sense, an offset the loop regulates
//! against, swapped motor phases) and the tracking check's 200 ms would be too late.

use super::verdict::Verdict;
use crate::units::{Amps, SteeringDeg};

/// Runaway: the current toward the reference at least this (90 % of the 20 A loop limit: the
/// loop is saturated, pushing with all it has) ...
pub const RUNAWAY_CURRENT: Amps = Amps(18.0);
/// ... for this long, µs (a runaway must be found within 50 ms) ...
pub const RUNAWAY_PERSIST_US: u32 = 50_000;
/// ... while the column still moves away from the reference at least this fast, deg/s, over
/// the last [`RUNAWAY_SPEED_WINDOW_US`]. A column that only coasts on (the motor decelerating
/// after a reversal of the reference: at most about 44 ms from full speed at 20 A) is moving
/// toward the reference again after 50 ms; 20 deg/s is 2.3 encoder counts per 10 ms, above
/// the quantisation.
pub const RUNAWAY_AWAY_DPS: f32 = 20.0;
/// The speed of [`RUNAWAY_AWAY_DPS`] is measured over at least this, µs (5 encoder samples).
pub const RUNAWAY_SPEED_WINDOW_US: u32 = 10_000;
/// A runaway's motion away does not slow under the push; this much slower than when the push
/// began still counts as not slowing, deg/s: one 12-bit encoder count (0.088 deg) per
/// [`RUNAWAY_SPEED_WINDOW_US`], the speed measurement's resolution.
pub const RUNAWAY_SLOWING_SLACK_DPS: f32 = 360.0 / 4096.0 / (RUNAWAY_SPEED_WINDOW_US as f32 * 1e-6);

/// The column's speed away from the reference and the saturated push in progress; see
/// [`RunawayCheck::check`].
#[derive(Debug, Clone, Default)]
pub struct RunawayCheck {
    /// Since when the current has pushed toward the reference at [`RUNAWAY_CURRENT`].
    since_us: Option<u64>,
    /// A column sample for the speed away: (time µs, deg) ...
    probe: Option<(u64, f32)>,
    /// ... and the last speed away measured from it, deg/s.
    away_dps: f32,
    /// The column's speed away from the reference when the push began, deg/s.
    away_at_push_dps: f32,
    /// The sign of the error the push began on (+1 toward positive angles).
    push_direction: f32,
}

impl RunawayCheck {
    pub const fn new() -> Self {
        RunawayCheck {
            since_us: None,
            probe: None,
            away_dps: 0.0,
            away_at_push_dps: 0.0,
            push_direction: 0.0,
        }
    }

    /// One column sample with what pushes the motor (`current`, positive toward positive
    /// angles). It latches when the push toward the reference has lasted
    /// [`RUNAWAY_PERSIST_US`] and the column still moves away at [`RUNAWAY_AWAY_DPS`] or
    /// more, no slower than when the push began (a push the right way slows it); `Latch`
    /// carries the error (reference - column), deg. It never clears the tracking fault's
    /// cause, which the tracking check owns: `Unjudged` otherwise. Non-finite values push
    /// nothing and move nothing (the encoder and over-current checks own them).
    pub fn check(
        &mut self,
        now_us: u64,
        reference: SteeringDeg,
        column: SteeringDeg,
        current: Amps,
    ) -> Verdict<f32> {
        let error = reference.0 - column.0;
        match self.probe {
            Some((t, c)) if now_us.saturating_sub(t) >= u64::from(RUNAWAY_SPEED_WINDOW_US) => {
                let dt_s = now_us.saturating_sub(t) as f32 * 1e-6;
                // Away = moving against the sign of the error.
                self.away_dps = -(column.0 - c) * error.signum() / dt_s;
                self.probe = Some((now_us, column.0));
            }
            Some(_) => {}
            None => self.probe = Some((now_us, column.0)),
        }
        // NaN compares false: no push anyone can vouch for.
        let pushing = current.0 * error.signum() >= RUNAWAY_CURRENT.0;
        if !pushing {
            self.since_us = None;
            return Verdict::Unjudged;
        }
        // One push is one direction: a saturated loop on a fast reference flips its current
        // with the error, and each flip starts a new push.
        if self.since_us.is_none() || error.signum() != self.push_direction {
            self.since_us = Some(now_us);
            self.away_at_push_dps = self.away_dps;
            self.push_direction = error.signum();
        }
        let since = self.since_us.unwrap_or(now_us);
        // A loop that lags a fast reference (a 10 Hz sweep: the error's sign holds for 50 ms,
        // and the soft belt delays the column by as much) also sees the column move away
        // under a saturated push, but the push slows it. A drive pushing the wrong way does
        // not: the motion away is at least as fast as when the push began (one encoder count
        // per speed window of slack for the quantisation).
        let not_slowing = self.away_dps >= self.away_at_push_dps - RUNAWAY_SLOWING_SLACK_DPS;
        if now_us.saturating_sub(since) >= u64::from(RUNAWAY_PERSIST_US)
            && self.away_dps >= RUNAWAY_AWAY_DPS
            && not_slowing
        {
            Verdict::Latch(error)
        } else {
            Verdict::Unjudged
        }
    }

    /// The drive is off or has no reference: the push and the speed measurement start again.
    /// The speed at the last push and its direction are kept: the next push sets them anew.
    pub fn reset(&mut self) {
        self.since_us = None;
        self.probe = None;
        self.away_dps = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Samples every 2 ms for 200 ms, the column at `column(s)` against `reference`, pushed
    /// by `current`: the time of the first `Latch`, µs.
    fn first_latch(
        check: &mut RunawayCheck,
        reference: f32,
        column: impl Fn(f32) -> f32,
        current: f32,
    ) -> Option<u64> {
        (0..=100u64).map(|k| k * 2_000).find(|&t| {
            let c = column(t as f32 * 1e-6);
            matches!(
                check.check(t, SteeringDeg(reference), SteeringDeg(c), Amps(current)),
                Verdict::Latch(_)
            )
        })
    }

    /// 20 A toward +10 deg while the column runs away from it at 100 deg/s: latched 50 ms
    /// after the push began, with the error.
    #[test]
    fn a_saturated_push_with_the_column_running_away_latches_in_50_ms() {
        let mut check = RunawayCheck::new();
        assert_eq!(
            first_latch(&mut check, 10.0, |s| -100.0 * s, 20.0),
            Some(50_000)
        );
        let mut check = RunawayCheck::new();
        let _ = first_latch(&mut check, 10.0, |s| -100.0 * s, 20.0);
        let verdict = check.check(52_000, SteeringDeg(10.0), SteeringDeg(-5.2), Amps(20.0));
        assert!(
            matches!(verdict, Verdict::Latch(e) if (e - 15.2).abs() < 1e-4),
            "{verdict:?}"
        );
    }

    /// The push must be toward the reference and at 18 A: 17.5 A is not saturated, and a
    /// push away from the reference is the loop braking an overshoot.
    #[test]
    fn only_a_saturated_push_toward_the_reference_counts() {
        let mut check = RunawayCheck::new();
        assert_eq!(first_latch(&mut check, 10.0, |s| -100.0 * s, 17.5), None);
        let mut check = RunawayCheck::new();
        assert_eq!(first_latch(&mut check, 10.0, |s| -100.0 * s, -20.0), None);
        let mut check = RunawayCheck::new();
        assert_eq!(
            first_latch(&mut check, 10.0, |s| -100.0 * s, 18.0),
            Some(50_000)
        );
    }

    /// A column moving away slower than 20 deg/s, or toward the reference, is no runaway.
    #[test]
    fn a_slow_or_closing_column_is_no_runaway() {
        let mut check = RunawayCheck::new();
        assert_eq!(first_latch(&mut check, 10.0, |s| -15.0 * s, 20.0), None);
        let mut check = RunawayCheck::new();
        assert_eq!(
            first_latch(&mut check, 10.0, |s| 40.0 * s - 30.0, 20.0),
            None
        );
    }

    #[test]
    fn values_that_are_not_numbers_push_nothing() {
        let mut check = RunawayCheck::new();
        assert_eq!(
            first_latch(&mut check, 10.0, |s| -100.0 * s, f32::NAN),
            None
        );
        let mut check = RunawayCheck::new();
        assert_eq!(
            first_latch(&mut check, f32::NAN, |s| -100.0 * s, 20.0),
            None
        );
    }

    /// After a reset the speed is measured afresh: the push that follows starts from a speed
    /// of 0, so a column that keeps running away latches 50 ms after the push resumed.
    #[test]
    fn a_reset_starts_the_push_and_the_speed_again() {
        let mut check = RunawayCheck::new();
        for k in 0..20u64 {
            let t = k * 2_000;
            let c = -100.0 * t as f32 * 1e-6;
            let _ = check.check(t, SteeringDeg(10.0), SteeringDeg(c), Amps(20.0));
        }
        check.reset();
        let latched = (20..=100u64).map(|k| k * 2_000).find(|&t| {
            let c = -100.0 * t as f32 * 1e-6;
            matches!(
                check.check(t, SteeringDeg(10.0), SteeringDeg(c), Amps(20.0)),
                Verdict::Latch(_)
            )
        });
        assert_eq!(latched, Some(90_000));
    }
}

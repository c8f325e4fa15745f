//! The tracking-error check: the actuator against its order. A column far from the reference
//! for long that does not close the gap is jammed or has run away, whatever the sensors say
//! of each other (a current-sense amplifier reading 30 A high drives the column to the end
//! stop with the measured current within the limit and column and motor agreeing).

use super::verdict::Verdict;
use crate::units::SteeringDeg;

/// The window, how long beyond it is judged, and the progress that excuses it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TrackingLimits {
    /// |reference - column| beyond this is a candidate, deg at the wheel.
    pub window_deg: f32,
    /// ... judged over intervals of this length, µs ...
    pub persist_us: u32,
    /// ... and a fault unless the column moved toward the reference at least this fast over
    /// the interval, deg/s.
    pub progress_dps: f32,
}

/// Remembers where the current interval beyond the window began; see
/// [`TrackingCheck::check`].
#[derive(Debug, Clone, Default)]
pub struct TrackingCheck {
    /// Start of the current interval: (time µs, column deg).
    since: Option<(u64, f32)>,
}

impl TrackingCheck {
    pub const fn new() -> Self {
        TrackingCheck { since: None }
    }

    /// Judges the column against the reference the drive follows, at `now_us`. Each interval
    /// beyond the window that has lasted `limits.persist_us` is judged by the column's
    /// progress toward the reference since the interval began: enough progress starts a new
    /// interval from here, too little latches. Non-finite values count as beyond the window
    /// with no progress. `Latch` carries the error (reference - column), deg.
    pub fn check(
        &mut self,
        now_us: u64,
        reference: SteeringDeg,
        column: SteeringDeg,
        limits: &TrackingLimits,
    ) -> Verdict<f32> {
        let error = reference.0 - column.0;
        if error.abs() <= limits.window_deg {
            self.since = None;
            return Verdict::Within;
        }
        let (since, column_then) = *self.since.get_or_insert((now_us, column.0));
        let elapsed_us = now_us.saturating_sub(since);
        if elapsed_us < u64::from(limits.persist_us) {
            return Verdict::Building;
        }
        let toward = (column.0 - column_then) * error.signum();
        let progress_dps = toward / (elapsed_us as f32 * 1e-6);
        // NaN compares false: no progress anyone can vouch for.
        if progress_dps >= limits.progress_dps {
            // Closing the gap: start a new interval from here.
            self.since = Some((now_us, column.0));
            Verdict::Building
        } else {
            Verdict::Latch(error)
        }
    }

    /// The drive is off or has no reference: no interval is open.
    pub fn reset(&mut self) {
        self.since = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: TrackingLimits = TrackingLimits {
        window_deg: 20.0,
        persist_us: 200_000,
        progress_dps: 30.0,
    };

    /// A column standing 30 deg off its reference builds for 200 ms, then latches.
    #[test]
    fn a_jammed_column_latches_after_the_interval() {
        let mut check = TrackingCheck::new();
        let (reference, column) = (SteeringDeg(30.0), SteeringDeg(0.0));
        assert_eq!(
            check.check(0, reference, SteeringDeg(10.0), &LIMITS),
            Verdict::Within
        );
        assert_eq!(
            check.check(1_000, reference, column, &LIMITS),
            Verdict::Building
        );
        assert_eq!(
            check.check(200_999, reference, column, &LIMITS),
            Verdict::Building
        );
        assert_eq!(
            check.check(201_000, reference, column, &LIMITS),
            Verdict::Latch(30.0)
        );
    }

    /// Progress counts toward the reference on either side: 8 deg in 200 ms (40 deg/s) is
    /// enough from below and from above and starts a new interval; the same 8 deg away from
    /// the reference is not.
    #[test]
    fn progress_toward_the_reference_from_either_side_excuses_the_error() {
        for (reference, start, toward) in [(50.0f32, 0.0f32, 8.0f32), (-50.0, 0.0, -8.0)] {
            let mut check = TrackingCheck::new();
            let _ = check.check(0, SteeringDeg(reference), SteeringDeg(start), &LIMITS);
            let closer = SteeringDeg(start + toward);
            assert_eq!(
                check.check(200_000, SteeringDeg(reference), closer, &LIMITS),
                Verdict::Building,
                "{reference}"
            );
            // The new interval began at 200 ms: standing still to 399 ms is not judged yet.
            assert_eq!(
                check.check(399_999, SteeringDeg(reference), closer, &LIMITS),
                Verdict::Building
            );
            let away = SteeringDeg(start - toward);
            let mut check = TrackingCheck::new();
            let _ = check.check(0, SteeringDeg(reference), SteeringDeg(start), &LIMITS);
            assert_eq!(
                check.check(200_000, SteeringDeg(reference), away, &LIMITS),
                Verdict::Latch(reference - away.0)
            );
        }
    }

    #[test]
    fn values_that_are_not_numbers_are_beyond_with_no_progress() {
        let mut check = TrackingCheck::new();
        let nan = SteeringDeg(f32::NAN);
        assert_eq!(
            check.check(0, SteeringDeg(0.0), nan, &LIMITS),
            Verdict::Building
        );
        assert!(matches!(
            check.check(200_000, SteeringDeg(0.0), nan, &LIMITS),
            Verdict::Latch(e) if e.is_nan()
        ));
    }

    #[test]
    fn a_reset_closes_the_interval() {
        let mut check = TrackingCheck::new();
        let _ = check.check(0, SteeringDeg(30.0), SteeringDeg(0.0), &LIMITS);
        check.reset();
        assert_eq!(
            check.check(250_000, SteeringDeg(30.0), SteeringDeg(0.0), &LIMITS),
            Verdict::Building
        );
    }
}

//! The column encoder against the motor: the column angle and the motor angle through the
//! gear chain may differ by the belt's and the column's compliance, not more for long (a
//! broken or skipping belt, lost Hall counts, a slipped encoder magnet).

use super::verdict::Verdict;

/// The window and how long the difference must stay beyond it to latch.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DisagreementLimits {
    /// |column - motor / gear ratio| allowed, deg at the wheel.
    pub window_deg: f32,
    /// µs beyond the window before it latches (0 = the first sample beyond).
    pub persist_us: u32,
}

/// Remembers since when the difference has been beyond the window; see
/// [`DisagreementCheck::check`].
#[derive(Debug, Clone, Default)]
pub struct DisagreementCheck {
    since_us: Option<u64>,
}

impl DisagreementCheck {
    pub const fn new() -> Self {
        DisagreementCheck { since_us: None }
    }

    /// Judges `difference_deg` (column less the motor as a column angle, deg at the wheel) at
    /// `now_us`. A difference that is not a number (two huge angles) counts as beyond the
    /// window. `Latch` carries the difference.
    pub fn check(
        &mut self,
        now_us: u64,
        difference_deg: f32,
        limits: &DisagreementLimits,
    ) -> Verdict<f32> {
        if difference_deg.abs() <= limits.window_deg {
            self.since_us = None;
            return Verdict::Within;
        }
        let since = *self.since_us.get_or_insert(now_us);
        if now_us.saturating_sub(since) >= u64::from(limits.persist_us) {
            Verdict::Latch(difference_deg)
        } else {
            Verdict::Building
        }
    }

    /// Nothing to compare (no motor angle yet): a disagreement in progress is forgotten.
    pub fn forget(&mut self) {
        self.since_us = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: DisagreementLimits = DisagreementLimits {
        window_deg: 15.0,
        persist_us: 20_000,
    };

    /// Beyond the window it builds, and latches once it has lasted the persistence, counted
    /// from the first sample beyond, the persistence itself included.
    #[test]
    fn a_difference_beyond_the_window_latches_after_the_persistence() {
        let mut check = DisagreementCheck::new();
        assert_eq!(check.check(0, 15.0, &LIMITS), Verdict::Within);
        assert_eq!(check.check(500, -15.5, &LIMITS), Verdict::Building);
        assert_eq!(check.check(20_499, 30.0, &LIMITS), Verdict::Building);
        assert_eq!(check.check(20_500, -16.0, &LIMITS), Verdict::Latch(-16.0));
    }

    /// One sample within starts the count again.
    #[test]
    fn a_sample_within_restarts_the_persistence() {
        let mut check = DisagreementCheck::new();
        let _ = check.check(0, 20.0, &LIMITS);
        assert_eq!(check.check(19_000, 1.0, &LIMITS), Verdict::Within);
        assert_eq!(check.check(20_000, 20.0, &LIMITS), Verdict::Building);
        assert_eq!(check.check(39_999, 20.0, &LIMITS), Verdict::Building);
        assert_eq!(check.check(40_000, 20.0, &LIMITS), Verdict::Latch(20.0));
    }

    #[test]
    fn a_difference_that_is_not_a_number_is_beyond_the_window() {
        let mut check = DisagreementCheck::new();
        let at_once = DisagreementLimits {
            persist_us: 0,
            ..LIMITS
        };
        assert!(matches!(check.check(0, f32::NAN, &at_once), Verdict::Latch(d) if d.is_nan()));
    }

    #[test]
    fn a_forgotten_disagreement_starts_again() {
        let mut check = DisagreementCheck::new();
        let _ = check.check(0, 20.0, &LIMITS);
        check.forget();
        assert_eq!(check.check(25_000, 20.0, &LIMITS), Verdict::Building);
        assert_eq!(check.check(45_000, 20.0, &LIMITS), Verdict::Latch(20.0));
    }
}

//! The over-current check: a measured current beyond the threshold for a run of samples means
//! the current loop has lost control of it (a bridge fault, a current sensor, the EPOS4).

use super::verdict::Verdict;
use crate::units::Amps;

/// ... or a run of over-current samples (at least two) lasting this long, µs, whatever the
/// sample rate: the EPOS4's current comes once per 10 ms SYNC, where 20 samples would be
/// 200 ms; two samples 10 ms apart latch within 20 ms of the first. At 20 kHz the 20 samples
/// (1 ms) come first.
pub const OVERCURRENT_PERSIST_US: u64 = 10_000;

/// The threshold and the run of samples beyond it that latches.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct OverCurrentLimits {
    /// Measured |I| above this is an over-current sample.
    pub threshold: Amps,
    /// Consecutive over-current samples that latch (at least 1).
    pub samples: u16,
}

/// Counts the current run of samples beyond the threshold; see [`OverCurrentCheck::check`].
#[derive(Debug, Clone, Default)]
pub struct OverCurrentCheck {
    count: u16,
    /// When the current run began.
    since_us: Option<u64>,
}

impl OverCurrentCheck {
    pub const fn new() -> Self {
        OverCurrentCheck {
            count: 0,
            since_us: None,
        }
    }

    /// Judges one measured sample at `now_us`. A current that is not a number is not vouched
    /// to be within the threshold: it counts as beyond. The run latches after
    /// `limits.samples` samples in a row, or once it has lasted [`OVERCURRENT_PERSIST_US`]
    /// over at least two; `Latch` carries the sample.
    pub fn check(
        &mut self,
        now_us: u64,
        measured: Amps,
        limits: &OverCurrentLimits,
    ) -> Verdict<Amps> {
        // NaN compares false.
        let within = measured.0.abs() <= limits.threshold.0;
        if within {
            self.count = 0;
            self.since_us = None;
            return Verdict::Within;
        }
        self.count = self.count.saturating_add(1);
        let since = *self.since_us.get_or_insert(now_us);
        let lasted = self.count >= 2 && now_us.saturating_sub(since) >= OVERCURRENT_PERSIST_US;
        if self.count >= limits.samples || lasted {
            Verdict::Latch(measured)
        } else {
            Verdict::Building
        }
    }

    /// A run is open: the last sample was beyond the threshold, so the next must be judged
    /// even if it is within.
    pub fn run_open(&self) -> bool {
        self.count > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: OverCurrentLimits = OverCurrentLimits {
        threshold: Amps(22.0),
        samples: 20,
    };

    /// At 20 kHz (50 µs apart): 19 samples beyond and one within is a spike; 20 in a row
    /// latch on the 20th, whatever their sign.
    #[test]
    fn twenty_samples_in_a_row_latch_and_one_within_ends_the_run() {
        let mut check = OverCurrentCheck::new();
        for k in 0..19 {
            assert_eq!(check.check(k * 50, Amps(-25.0), &LIMITS), Verdict::Building);
        }
        assert!(check.run_open());
        assert_eq!(check.check(950, Amps(22.0), &LIMITS), Verdict::Within);
        assert!(!check.run_open());
        for k in 0..19 {
            let sign = if k % 2 == 0 { 1.0 } else { -1.0 };
            assert_eq!(
                check.check(1_000 + k * 50, Amps(sign * 23.0), &LIMITS),
                Verdict::Building
            );
        }
        assert_eq!(
            check.check(1_950, Amps(30.0), &LIMITS),
            Verdict::Latch(Amps(30.0))
        );
    }

    /// At the EPOS4's 10 ms samples the run latches on the second one, 10 ms after the
    /// first; a single sample never does, however long ago the run began.
    #[test]
    fn a_run_lasting_10_ms_latches_on_its_second_sample() {
        let mut check = OverCurrentCheck::new();
        assert_eq!(check.check(0, Amps(30.0), &LIMITS), Verdict::Building);
        assert_eq!(check.check(9_999, Amps(30.0), &LIMITS), Verdict::Building);
        assert_eq!(
            check.check(10_000, Amps(31.0), &LIMITS),
            Verdict::Latch(Amps(31.0))
        );

        let mut check = OverCurrentCheck::new();
        assert_eq!(check.check(0, Amps(30.0), &LIMITS), Verdict::Building);
        assert_eq!(check.check(5_000, Amps(1.0), &LIMITS), Verdict::Within);
        assert_eq!(check.check(20_000, Amps(30.0), &LIMITS), Verdict::Building);
    }

    #[test]
    fn a_current_that_is_not_a_number_counts_as_beyond() {
        let mut check = OverCurrentCheck::new();
        let at_once = OverCurrentLimits {
            samples: 1,
            ..LIMITS
        };
        assert!(
            matches!(check.check(0, Amps(f32::NAN), &at_once), Verdict::Latch(a) if a.0.is_nan())
        );
        assert!(check.run_open());
    }
}

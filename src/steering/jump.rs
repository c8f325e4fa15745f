//! The column-encoder jump check: two consecutive samples farther apart than the column can
//! turn in the time between them (a flipped bit, a glitch on the SPI lines).

use super::verdict::Verdict;

/// How far the column may move between two samples: `floor_deg + max_rate_dps x dt`, judged
/// only for samples at most `max_gap_us` apart (the encoder timeout: after a longer gap the
/// previous sample says nothing about this one, and the timeout covers the gap itself).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JumpLimits {
    /// Deg at the wheel allowed however close the samples are (quantisation, a noisy LSB).
    pub floor_deg: f32,
    /// Fastest plausible column speed, deg/s at the wheel.
    pub max_rate_dps: f32,
    /// Samples farther apart than this, µs, are not compared.
    pub max_gap_us: u32,
}

/// Remembers the previous column sample; see [`JumpCheck::check`].
#[derive(Debug, Clone, Default)]
pub struct JumpCheck {
    /// The previous sample, plausible or not: (time µs, deg).
    previous: Option<(u64, f32)>,
}

impl JumpCheck {
    pub const fn new() -> Self {
        JumpCheck { previous: None }
    }

    /// Judges the sample `column_deg` (finite) taken at `now_us` against the previous one,
    /// then keeps it as the previous. `Latch` carries the jump, deg at the wheel; the check
    /// never says `Building` (one sample beyond the limit is the fault).
    pub fn check(&mut self, now_us: u64, column_deg: f32, limits: &JumpLimits) -> Verdict<f32> {
        let mut verdict = Verdict::Unjudged;
        if let Some((t, previous)) = self.previous {
            let dt_us = now_us.saturating_sub(t);
            if dt_us <= u64::from(limits.max_gap_us) {
                let limit = limits.floor_deg + limits.max_rate_dps * (dt_us as f32 * 1e-6);
                let jump = (column_deg - previous).abs();
                verdict = if jump > limit {
                    Verdict::Latch(jump)
                } else {
                    Verdict::Within
                };
            }
        }
        self.previous = Some((now_us, column_deg));
        verdict
    }

    /// The sample was not a number: the next one has nothing to be compared with.
    pub fn forget(&mut self) {
        self.previous = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: JumpLimits = JumpLimits {
        floor_deg: 1.0,
        max_rate_dps: 1000.0,
        max_gap_us: 30_000,
    };

    #[test]
    fn the_first_sample_has_nothing_to_be_compared_with() {
        let mut jump = JumpCheck::new();
        assert_eq!(jump.check(0, 90.0, &LIMITS), Verdict::Unjudged);
    }

    /// The floor itself is allowed at dt 0; after 10 ms the limit is 1 + 1000 x 0.01 = 11 deg.
    #[test]
    fn a_move_up_to_the_floor_plus_the_rate_allowance_is_within() {
        let mut jump = JumpCheck::new();
        let _ = jump.check(1_000, 0.0, &LIMITS);
        assert_eq!(jump.check(1_000, -1.0, &LIMITS), Verdict::Within);
        assert_eq!(jump.check(11_000, 9.5, &LIMITS), Verdict::Within);
        assert_eq!(jump.check(11_000, 11.0, &LIMITS), Verdict::Latch(1.5));
        assert_eq!(jump.check(21_000, -0.5, &LIMITS), Verdict::Latch(11.5));
    }

    /// Each sample is compared with the one before it, plausible or not: after a glitch the
    /// way back is a jump too, and then the column reads steady again.
    #[test]
    fn a_glitch_is_a_jump_out_and_a_jump_back() {
        let mut jump = JumpCheck::new();
        let _ = jump.check(0, 10.0, &LIMITS);
        assert_eq!(jump.check(500, 15.625, &LIMITS), Verdict::Latch(5.625));
        assert_eq!(jump.check(1_000, 10.0, &LIMITS), Verdict::Latch(5.625));
        assert_eq!(jump.check(1_500, 10.1, &LIMITS), Verdict::Within);
    }

    /// Samples more than the encoder timeout apart are not compared (the timeout owns the
    /// gap); the sample after the gap starts a new comparison.
    #[test]
    fn samples_farther_apart_than_the_gap_are_not_compared() {
        let mut jump = JumpCheck::new();
        let _ = jump.check(0, 0.0, &LIMITS);
        assert_eq!(jump.check(30_001, 90.0, &LIMITS), Verdict::Unjudged);
        assert_eq!(jump.check(30_501, 95.0, &LIMITS), Verdict::Latch(5.0));
        let _ = jump.check(40_000, 0.0, &LIMITS);
        // Exactly at the gap it is judged: 1 + 30 deg.
        assert_eq!(jump.check(70_000, 31.5, &LIMITS), Verdict::Latch(31.5));
    }

    #[test]
    fn a_forgotten_sample_is_not_compared() {
        let mut jump = JumpCheck::new();
        let _ = jump.check(0, 0.0, &LIMITS);
        jump.forget();
        assert_eq!(jump.check(500, 45.0, &LIMITS), Verdict::Unjudged);
    }

    /// Time going back (an event processed late) counts as dt 0, not as a huge allowance.
    #[test]
    fn time_going_back_allows_only_the_floor() {
        let mut jump = JumpCheck::new();
        let _ = jump.check(10_000, 0.0, &LIMITS);
        assert_eq!(jump.check(0, 2.0, &LIMITS), Verdict::Latch(2.0));
    }
}

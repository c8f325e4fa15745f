//! The two freshness rules: a reference frame and a column-encoder sample must keep coming
//! while the AS state allows power. Each age counts from the later of the last arrival and the
//! moment power became allowed, so a drive that was just allowed power gets a full timeout.

use super::verdict::Verdict;

/// The times of the freshness rules, µs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TimeoutLimits {
    /// No valid reference for this long leaves active steering ...
    pub reference_timeout_us: u32,
    /// ... and this much longer (the hold) latches the reference timeout.
    pub hold_us: u32,
    /// No encoder sample for this long latches the encoder fault.
    pub encoder_timeout_us: u32,
}

/// When the reference and the encoder last came, and since when power is allowed.
#[derive(Debug, Clone, Default)]
pub struct Timeouts {
    /// When the AS state last became one that allows power; `None` while it does not.
    powered_since_us: Option<u64>,
    last_reference_us: Option<u64>,
    last_encoder_us: Option<u64>,
}

impl Timeouts {
    pub const fn new() -> Self {
        Timeouts {
            powered_since_us: None,
            last_reference_us: None,
            last_encoder_us: None,
        }
    }

    /// The AS state at `now_us` allows power (`true`) or not. Power allowed again after a
    /// state that did not starts the ages afresh; staying allowed keeps them.
    pub fn on_power_allowed(&mut self, now_us: u64, allowed: bool) {
        if !allowed {
            self.powered_since_us = None;
        } else if self.powered_since_us.is_none() {
            self.powered_since_us = Some(now_us);
        }
    }

    /// A valid reference frame arrived.
    pub fn on_reference(&mut self, now_us: u64) {
        self.last_reference_us = Some(now_us);
    }

    /// A finite column-encoder sample arrived.
    pub fn on_encoder(&mut self, now_us: u64) {
        self.last_encoder_us = Some(now_us);
    }

    /// µs since the last valid reference frame, `None` before the first.
    pub fn reference_age(&self, now_us: u64) -> Option<u64> {
        self.last_reference_us.map(|t| now_us.saturating_sub(t))
    }

    /// µs since the last encoder sample, `None` before the first.
    pub fn encoder_age(&self, now_us: u64) -> Option<u64> {
        self.last_encoder_us.map(|t| now_us.saturating_sub(t))
    }

    /// The reference timeout: `Latch` with the age (µs, counted from the later of the last
    /// frame and the moment power became allowed) once it exceeds the timeout plus the hold,
    /// while power is allowed; `Unjudged` otherwise (a frame is what removes the cause).
    pub fn reference(&self, now_us: u64, limits: &TimeoutLimits) -> Verdict<u64> {
        let limit =
            u64::from(limits.reference_timeout_us).saturating_add(u64::from(limits.hold_us));
        self.judge(now_us, self.last_reference_us, limit)
    }

    /// The encoder timeout, as [`Timeouts::reference`] with the encoder timeout alone.
    pub fn encoder(&self, now_us: u64, limits: &TimeoutLimits) -> Verdict<u64> {
        self.judge(
            now_us,
            self.last_encoder_us,
            u64::from(limits.encoder_timeout_us),
        )
    }

    fn judge(&self, now_us: u64, last: Option<u64>, limit: u64) -> Verdict<u64> {
        let Some(powered_since) = self.powered_since_us else {
            return Verdict::Unjudged;
        };
        let since = last.map_or(powered_since, |t| t.max(powered_since));
        let age = now_us.saturating_sub(since);
        if age > limit {
            Verdict::Latch(age)
        } else {
            Verdict::Unjudged
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const LIMITS: TimeoutLimits = TimeoutLimits {
        reference_timeout_us: 30_000,
        hold_us: 100_000,
        encoder_timeout_us: 30_000,
    };

    #[test]
    fn nothing_times_out_while_power_is_not_allowed() {
        let mut timeouts = Timeouts::new();
        timeouts.on_reference(0);
        assert_eq!(timeouts.reference(1_000_000, &LIMITS), Verdict::Unjudged);
        assert_eq!(timeouts.encoder(1_000_000, &LIMITS), Verdict::Unjudged);
        timeouts.on_power_allowed(0, true);
        timeouts.on_power_allowed(10, false);
        assert_eq!(timeouts.reference(1_000_000, &LIMITS), Verdict::Unjudged);
    }

    /// The limits themselves are allowed: 130 ms for the reference, 30 ms for the encoder.
    #[test]
    fn each_rule_latches_past_its_limit_with_the_age() {
        let mut timeouts = Timeouts::new();
        timeouts.on_power_allowed(0, true);
        timeouts.on_reference(1_000);
        timeouts.on_encoder(2_000);
        assert_eq!(timeouts.reference(131_000, &LIMITS), Verdict::Unjudged);
        assert_eq!(
            timeouts.reference(131_001, &LIMITS),
            Verdict::Latch(130_001)
        );
        assert_eq!(timeouts.encoder(32_000, &LIMITS), Verdict::Unjudged);
        assert_eq!(timeouts.encoder(32_001, &LIMITS), Verdict::Latch(30_001));
    }

    /// Ages count from when power became allowed if that is later than the last arrival, or
    /// if nothing ever arrived; staying allowed does not move that moment.
    #[test]
    fn ages_count_from_when_power_became_allowed() {
        let mut timeouts = Timeouts::new();
        timeouts.on_reference(0);
        timeouts.on_power_allowed(50_000, true);
        timeouts.on_power_allowed(60_000, true);
        assert_eq!(timeouts.reference(180_000, &LIMITS), Verdict::Unjudged);
        assert_eq!(
            timeouts.reference(180_001, &LIMITS),
            Verdict::Latch(130_001)
        );
        assert_eq!(timeouts.encoder(80_001, &LIMITS), Verdict::Latch(30_001));
        // The plain ages, for the demand, count from the arrival.
        assert_eq!(timeouts.reference_age(180_000), Some(180_000));
        assert_eq!(timeouts.encoder_age(180_000), None);
    }
}

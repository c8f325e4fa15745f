//! The gate in front of the chip's independent watchdog (IWDG): it says
//! "feed" only when both halves of the firmware have shown progress since the last feed, so a
//! hung or starved half stops the feeding and the IWDG resets the MCU.
//!
//! - The supervisor: the tasks that tick the state machine (reference receiver, encoder
//!   reader); each call counts ([`crate::ecu::Ecu::progress`]).
//! - The fast loop: direct drive's 20 kHz interrupt ([`crate::direct::FastLoop::step`]), or in
//!   EPOS4 mode the drive task's 1 ms link poll ([`crate::ecu::Ecu::drive_poll`]).
//!
//! The feeder itself ([`crate::tasks::watchdog_task`]) is a task of the same executor as the
//! supervisor, so a stalled executor stops it as well. Direct drive also has a faster, local
//! guard: the fast loop switches the bridge off after 5 ms without the supervisor
//! ([`crate::direct::SUPERVISOR_TIMEOUT_US`]); the IWDG is the last resort when the fast loop
//! itself (or everything) stops.
//!
//! The timeout is derived from the feed period and the IWDG's clock: embassy sets the IWDG up
//! for a 32 kHz LSI, but the STM32F446's LSI runs anywhere between 17 and 47 kHz (DS10693,
//! "LSI oscillator characteristics"), so [`WATCHDOG_TIMEOUT_US`] = 100 ms is really 68 to
//! 188 ms: at least six feed periods of slack for a late executor, and a reset within 188 ms of
//! a stall (the reference timeout plus hold is 130 ms). After a reset the firmware starts with
//! the drive off, as at power-up.

/// How often the feeder asks the gate, us (one status period).
pub const FEED_PERIOD_US: u32 = 10_000;
/// Feed periods in the nominal IWDG timeout (see the module doc for the LSI's spread).
pub const FEED_PERIODS_PER_TIMEOUT: u32 = 10;
/// Nominal IWDG timeout, us (at the LSI's 32 kHz).
pub const WATCHDOG_TIMEOUT_US: u32 = FEED_PERIOD_US * FEED_PERIODS_PER_TIMEOUT;

/// Progress counts of the two halves (each wraps; only a change matters).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Progress {
    /// Calls of the supervisor tasks into the ECU.
    pub supervisor: u32,
    /// Fast-loop periods (direct) or link polls (EPOS4).
    pub fast: u32,
}

/// Decides each feed. Starts from zero counts, so the first feed needs both halves to have run.
#[derive(Debug, Clone, Copy, Default)]
pub struct FeedGate {
    at_last_feed: Progress,
    refused: u32,
}

impl FeedGate {
    pub const fn new() -> Self {
        FeedGate {
            at_last_feed: Progress {
                supervisor: 0,
                fast: 0,
            },
            refused: 0,
        }
    }

    /// `true`: feed the watchdog now. Only when both counts moved since the last feed; a
    /// refusal keeps the old counts, so a half that stalled must run again before any feed.
    pub fn check(&mut self, now: Progress) -> bool {
        let feed =
            now.supervisor != self.at_last_feed.supervisor && now.fast != self.at_last_feed.fast;
        if feed {
            self.at_last_feed = now;
        } else {
            self.refused = self.refused.saturating_add(1);
        }
        feed
    }

    /// Checks that did not feed (saturating), for the log.
    pub fn refused(&self) -> u32 {
        self.refused
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(supervisor: u32, fast: u32) -> Progress {
        Progress { supervisor, fast }
    }

    #[test]
    fn feeds_only_when_both_halves_ran_since_the_last_feed() {
        let mut gate = FeedGate::new();
        assert!(!gate.check(p(0, 0)), "nothing ran yet");
        assert!(!gate.check(p(3, 0)), "the fast loop has not run");
        assert!(!gate.check(p(0, 40)), "the supervisor has not run");
        assert!(gate.check(p(3, 40)));
        assert!(!gate.check(p(3, 40)), "no progress since that feed");
        assert!(gate.check(p(4, 41)));
        assert_eq!(gate.refused(), 4);
    }

    #[test]
    fn a_stalled_supervisor_stops_the_feeding_until_it_runs_again() {
        let mut gate = FeedGate::new();
        assert!(gate.check(p(1, 200)));
        for fast in (400..4000).step_by(200) {
            assert!(!gate.check(p(1, fast)), "supervisor stalled at 1");
        }
        assert!(gate.check(p(2, 4000)));
    }

    #[test]
    fn a_stalled_fast_loop_stops_the_feeding_until_it_runs_again() {
        let mut gate = FeedGate::new();
        assert!(gate.check(p(5, 7)));
        for supervisor in 6..30 {
            assert!(!gate.check(p(supervisor, 7)), "fast loop stalled at 7");
        }
        assert!(gate.check(p(30, 8)));
    }

    #[test]
    fn counts_that_wrap_are_progress() {
        let mut gate = FeedGate::new();
        assert!(gate.check(p(u32::MAX, u32::MAX)));
        assert!(gate.check(p(0, 0)));
    }

    #[test]
    fn the_timeout_is_the_documented_multiple_of_the_feed_period() {
        assert_eq!(WATCHDOG_TIMEOUT_US, 100_000);
        // Shortest real timeout (LSI at 47 kHz instead of 32) still spans six feed periods.
        assert!(u64::from(WATCHDOG_TIMEOUT_US) * 32 / 47 >= 6 * u64::from(FEED_PERIOD_US));
    }
}

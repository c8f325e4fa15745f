//! The end-to-end check of the steering reference: the one gate between the CAN bus and the
//! control core. Pure: the caller passes the receive time, nothing here reads a clock.
//!
//! # Theory of operation
//!
//! ```text
//!  frame, now_us
//!       |
//!  ID? --no--> Dropped(WrongId)        (not counted toward a fault: other traffic)
//!       |
//!  8 bytes? CRC? --no--> invalid        (the counter byte is not trusted)
//!       |
//!  counter = last seen + 1? -------> last seen := this counter, whatever follows
//!       |  no: Stale / Counter -> invalid
//!  AS code? |angle| <= max? step <= budget? --no--> invalid
//!       |
//!  Valid(Reference): last accepted := (angle, now_us), invalid score -= 1 (not below 0)
//!
//!  invalid: counted per reason (saturating u16), invalid score += 1 (at most the limit);
//!           score >= max_invalid_in_row -> Fault, else Dropped.
//! ```
//!
//! The first frame after [`E2eChecker::new`] or [`E2eChecker::reset`] may carry any counter,
//! and the first accepted one any in-range angle. The rate budget is
//! `max_rate * max(now - last accepted, period)`: the time since the last accepted sample, so
//! a reference dropped for its rate is compared against a budget that grows until the
//! reference is plausible again, and a burst of late frames still gets one period each.
//! A receive time earlier than the last accepted one counts as one period.
//!
//! The step rule alone gives every frame a period's budget, so a sender running faster than
//! the period could move the angle faster than the rate. The real-time window (panda's
//! `rt_rate_limit`) closes that: measured from an anchor (an accepted value, restarted every
//! [`RT_WINDOW_US`]), the angle may move at most `max_rate * (time since the anchor + one
//! period)`, however many frames come. Frames that come less than half a period after the
//! previous authentic one are counted ([`E2eChecker::early_frames`]).
//!
//! A frame that passes the CRC but fails the counter (one frame lost before it, a repeat) or
//! the angle rules (range, rate) still carries an AS state the sender did send:
//! [`E2eChecker::authentic_as_state`] gives it, so AS Emergency (or Finished, Off) in such a
//! frame still disables the drive at once. Only power needs a frame that passes every rule.
//!
//! The checker does not latch the fault: a valid frame lowers the invalid score (as panda's
//! wrong-counter count: a good frame decrements, it does not zero, so 4 bad frames in every
//! 5 still reach the limit). Latching, and
//! what the drive does meanwhile, is the state machine's decision.

use super::{
    AliveCounter, ConfigError, FrameError, ProtocolConfig, Reference, checked_word, field,
};
use crate::as_state::AsState;
use crate::can::Frame;
use crate::units::SteeringDeg;

/// Dropped reference frames per reason. Saturating: a counter at `u16::MAX` means "at least".
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DropCounters {
    pub wrong_id: u16,
    pub wrong_length: u16,
    pub crc: u16,
    pub stale: u16,
    pub counter_jump: u16,
    pub unknown_as_state: u16,
    pub angle_out_of_range: u16,
    pub rate_too_high: u16,
}

impl DropCounters {
    /// All drops except foreign IDs.
    pub fn invalid_total(&self) -> u32 {
        [
            self.wrong_length,
            self.crc,
            self.stale,
            self.counter_jump,
            self.unknown_as_state,
            self.angle_out_of_range,
            self.rate_too_high,
        ]
        .iter()
        .map(|&n| u32::from(n))
        .sum()
    }

    fn count(&mut self, error: &FrameError) {
        let n = match error {
            FrameError::WrongId { .. } => &mut self.wrong_id,
            FrameError::WrongLength { .. } => &mut self.wrong_length,
            FrameError::Crc { .. } => &mut self.crc,
            FrameError::Stale { .. } => &mut self.stale,
            FrameError::Counter { .. } => &mut self.counter_jump,
            FrameError::UnknownAsState { .. } => &mut self.unknown_as_state,
            FrameError::AngleOutOfRange { .. } => &mut self.angle_out_of_range,
            FrameError::RateTooHigh { .. } => &mut self.rate_too_high,
        };
        *n = n.saturating_add(1);
    }
}

/// The outcome of one received frame.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum E2eVerdict {
    /// Passed every rule: the control core may use it.
    Valid(Reference),
    /// Dropped; `invalid_in_row` frames in a row have now been invalid (below the limit).
    Dropped {
        error: FrameError,
        invalid_in_row: u8,
    },
    /// Dropped, and `invalid_in_row` reached the configured limit: the reference link is
    /// faulty. Every further invalid frame reports it again, until a valid one.
    Fault {
        error: FrameError,
        invalid_in_row: u8,
    },
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Accepted {
    angle_raw: i16,
    at_us: u64,
}

/// The E2E checker of the reference frame; see the module doc.
#[derive(Debug, Clone)]
pub struct E2eChecker {
    config: ProtocolConfig,
    /// |angle| limit, raw 0.01 deg units (floor of the configured limit).
    max_angle_raw: i32,
    /// Rate limit, raw 0.01 deg units per second (floor of the configured limit).
    max_rate_raw_per_s: u64,
    last_counter: Option<AliveCounter>,
    last_accepted: Option<Accepted>,
    invalid_in_row: u8,
    drops: DropCounters,
    /// See [`E2eChecker::authentic_as_state`].
    authentic_as_state: Option<AsState>,
    /// The real-time window's anchor: an accepted value, at most [`RT_WINDOW_US`] old when
    /// the window was (re)started.
    window: Option<Accepted>,
    /// Receive time of the last frame that passed ID, length and CRC.
    last_authentic_us: Option<u64>,
    early_frames: u16,
}

/// Length of the real-time rate window, us (panda's `rt_rate_limit` uses the same 250 ms):
/// 25 reference periods, long enough that a burst of early frames cannot add a period's step
/// each, short enough that the anchor stays a recent accepted value.
pub const RT_WINDOW_US: u64 = 250_000;

impl E2eChecker {
    /// A checker for `config`, or why the configuration is refused.
    pub fn new(config: ProtocolConfig) -> Result<Self, ConfigError> {
        config.validate()?;
        // Floor, so the integer limits are never looser than the configured ones; the float
        // limits are validated finite and positive, and `as` saturates.
        let max_angle_raw = (config.max_angle.0 * super::ANGLE_BITS_PER_DEG) as i32;
        let max_rate_raw_per_s = (config.max_rate_deg_per_s * super::ANGLE_BITS_PER_DEG) as u64;
        Ok(E2eChecker {
            config,
            max_angle_raw,
            max_rate_raw_per_s,
            last_counter: None,
            last_accepted: None,
            invalid_in_row: 0,
            drops: DropCounters::default(),
            authentic_as_state: None,
            window: None,
            last_authentic_us: None,
            early_frames: 0,
        })
    }

    pub fn config(&self) -> &ProtocolConfig {
        &self.config
    }

    /// Checks one received frame, `now_us` its receive time (any monotonic microsecond clock).
    pub fn check(&mut self, frame: &Frame, now_us: u64) -> E2eVerdict {
        self.authentic_as_state = None;
        match self.rules(frame, now_us) {
            Ok(reference) => {
                // A good frame takes one off, it does not wipe the score (panda's wrong-counter
                // count): a link that loses or repeats most frames reaches the limit even with
                // good frames in between.
                self.invalid_in_row = self.invalid_in_row.saturating_sub(1);
                E2eVerdict::Valid(reference)
            }
            Err(error) => {
                self.drops.count(&error);
                if !matches!(error, FrameError::WrongId { .. }) {
                    // Saturate at the limit: the score only needs to say "at least the limit",
                    // and one good frame after a long burst then leaves the fault verdict
                    // (the state machine keeps the latch).
                    self.invalid_in_row = self
                        .invalid_in_row
                        .saturating_add(1)
                        .min(self.config.max_invalid_in_row);
                }
                let invalid_in_row = self.invalid_in_row;
                if self.in_fault() {
                    E2eVerdict::Fault {
                        error,
                        invalid_in_row,
                    }
                } else {
                    E2eVerdict::Dropped {
                        error,
                        invalid_in_row,
                    }
                }
            }
        }
    }

    fn rules(&mut self, frame: &Frame, now_us: u64) -> Result<Reference, FrameError> {
        let word = checked_word(self.config.reference_id, frame)?;
        if let Some(last) = self.last_authentic_us.replace(now_us)
            && now_us.saturating_sub(last) < u64::from(self.config.period_us / 2)
        {
            self.early_frames = self.early_frames.saturating_add(1);
        }

        // The frame passed the CRC, so the sender did send this AS state, whatever its counter
        // (a frame lost before it, a repeat) or its angle: see `authentic_as_state`.
        let code = field(word, 12, 4) as u8;
        let as_state = AsState::from_code(code);
        self.authentic_as_state = as_state;

        let counter = AliveCounter::wrapping(field(word, 8, 4) as u8);
        // ... and this counter: the next frame is judged against it whether or not this one is
        // accepted.
        let last = self.last_counter.replace(counter);
        if let Some(last) = last {
            if counter == last {
                return Err(FrameError::Stale {
                    counter: counter.raw(),
                });
            }
            let expected = last.next();
            if counter != expected {
                return Err(FrameError::Counter {
                    expected: expected.raw(),
                    found: counter.raw(),
                });
            }
        }

        let as_state = as_state.ok_or(FrameError::UnknownAsState { code })?;

        let angle_raw = field(word, 16, 16) as u16 as i16;
        let clear_faults = field(word, 32, 1) == 1;
        if i32::from(angle_raw).abs() > self.max_angle_raw {
            return Err(FrameError::AngleOutOfRange {
                angle: super::angle_from_raw(angle_raw),
                limit: self.config.max_angle,
            });
        }

        if let Some(prev) = self.last_accepted {
            let step = angle_raw.abs_diff(prev.angle_raw);
            let allowed = self.step_budget_raw(now_us.saturating_sub(prev.at_us));
            if u64::from(step) > allowed {
                return Err(FrameError::RateTooHigh {
                    step: raw_deg(u64::from(step)),
                    allowed: raw_deg(allowed),
                });
            }
            // The real-time window: against the anchor, the angle may have moved the rate
            // times the real time since it, plus one period (the jitter allowance the step
            // rule gives), however many frames came in between. A window older than
            // RT_WINDOW_US restarts at the last accepted value.
            let anchor = match self.window {
                Some(a) if now_us.saturating_sub(a.at_us) < RT_WINDOW_US => a,
                _ => prev,
            };
            self.window = Some(anchor);
            let moved = angle_raw.abs_diff(anchor.angle_raw);
            let elapsed_us = now_us.saturating_sub(anchor.at_us);
            let allowed = self
                .max_rate_raw_per_s
                .saturating_mul(elapsed_us.saturating_add(u64::from(self.config.period_us)))
                / 1_000_000;
            if u64::from(moved) > allowed {
                return Err(FrameError::RateTooHigh {
                    step: raw_deg(u64::from(moved)),
                    allowed: raw_deg(allowed),
                });
            }
        }

        let accepted = Accepted {
            angle_raw,
            at_us: now_us,
        };
        self.last_accepted = Some(accepted);
        if self.window.is_none() {
            self.window = Some(accepted);
        }
        Ok(Reference {
            angle: super::angle_from_raw(angle_raw),
            as_state,
            counter,
            clear_faults,
        })
    }

    /// Largest accepted step, raw 0.01 deg, `elapsed_us` after the last accepted sample.
    fn step_budget_raw(&self, elapsed_us: u64) -> u64 {
        let dt_us = elapsed_us.max(u64::from(self.config.period_us));
        // Saturate: past a few seconds the budget exceeds any possible step anyway.
        self.max_rate_raw_per_s.saturating_mul(dt_us) / 1_000_000
    }

    /// The AS state of the frame just checked, if that frame was authentic (ID, length and CRC
    /// good, a known AS code), whether or not its counter, angle and rate passed; `None`
    /// otherwise. Such a frame is not accepted, but its AS state is the vehicle's word: one
    /// that asks for less authority (AS Emergency, Finished, Off, Manual) must disable the drive
    /// at once, a lost frame before it or not. Only a frame that asks for more
    /// authority (power) needs every rule, the counter included: act on this only to disable.
    pub fn authentic_as_state(&self) -> Option<AsState> {
        self.authentic_as_state
    }

    /// Authentic frames (ID, length, CRC good) that came less than half a period after the
    /// previous one (saturating): a sender running faster than the protocol's period. Half a
    /// period is far beyond the bus and scheduling jitter (a few 100 us), so the count is
    /// not noise.
    pub fn early_frames(&self) -> u16 {
        self.early_frames
    }

    /// The counter of the last frame that passed ID, length and CRC, accepted or not: the one
    /// the next frame's counter must follow. `None` before the first, and after
    /// [`E2eChecker::reset`] (then any counter is accepted).
    pub fn last_counter(&self) -> Option<AliveCounter> {
        self.last_counter
    }

    /// Frames dropped so far, per reason.
    pub fn drops(&self) -> &DropCounters {
        &self.drops
    }

    /// The invalid-frame score: +1 per invalid frame, -1 per valid one, between 0 and the
    /// configured limit (in a clean run of invalid frames, their number).
    pub fn invalid_in_row(&self) -> u8 {
        self.invalid_in_row
    }

    /// The invalid run has reached the configured limit.
    pub fn in_fault(&self) -> bool {
        self.invalid_in_row >= self.config.max_invalid_in_row
    }

    /// Time since the last accepted reference, us; `None` before the first.
    pub fn since_accepted_us(&self, now_us: u64) -> Option<u64> {
        self.last_accepted
            .map(|accepted| now_us.saturating_sub(accepted.at_us))
    }

    /// No accepted reference for longer than the configured timeout, or none yet.
    pub fn timed_out(&self, now_us: u64) -> bool {
        self.since_accepted_us(now_us)
            .is_none_or(|age| age > u64::from(self.config.timeout_us))
    }

    /// Forget the counter and the last reference (e.g. when the drive is re-enabled), keep
    /// the drop counters: they are diagnostics for the whole power cycle.
    pub fn reset(&mut self) {
        self.last_counter = None;
        self.last_accepted = None;
        self.window = None;
        self.invalid_in_row = 0;
    }
}

fn raw_deg(raw: u64) -> SteeringDeg {
    SteeringDeg(raw as f32 * super::ANGLE_DEG_PER_BIT)
}

#[cfg(test)]
mod tests;

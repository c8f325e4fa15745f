//! What a detector says about one input, in the terms the state machine acts on.

/// One detector's judgement of one input. The machine turns it into the state of the fault
/// the detector watches: [`Verdict::Within`] removes the cause, [`Verdict::Building`] marks it
/// present, [`Verdict::Latch`] marks it present and latches it, [`Verdict::Unjudged`] leaves
/// it as it was.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Verdict<T> {
    /// Nothing to judge (a first sample, a sample after a gap, no saturated push): the cause
    /// stays as it was.
    Unjudged,
    /// Within the rule: the cause is gone.
    Within,
    /// Beyond the rule, not for long enough to latch: the cause is present.
    Building,
    /// Beyond the rule for long enough: latch, recording this figure (deg, A, µs: each
    /// detector says which).
    Latch(T),
}

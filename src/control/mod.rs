//! The two loops of the cascade: position PID with feedforward ([`position`]) producing a
//! current set-point, and the PI current loop ([`current`]) producing the motor voltage.
//!
//! Both saturate on purpose (20 A, 24 V) and both use conditional integration as anti-windup:
//! the integrator does not move while the output it feeds is saturated. It is the EPOS4's
//! choice, it needs no extra tuning parameter (a back-calculation gain would), and on a
//! saturated step it leaves the integrator where it was before the saturation, so the
//! recovery has no windup overshoot (host-sim's `large_step_recovers_without_windup_overshoot`).

pub mod current;
pub mod position;

/// How an integrator is kept from winding up while the output is saturated.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AntiWindup {
    /// Freeze the integrator while the output is saturated (the paper's and the EPOS4's way).
    #[default]
    ConditionalIntegration,
    /// Integrate always, but clamp the integral term to the output limit.
    IntegratorClamp,
    /// Integrate regardless. Only for showing what windup does (tests, host-sim comparisons).
    Disabled,
}

//! Current loop: PI on the motor current, giving the terminal voltage, limited to the supply
//! (24 V, the LV battery).
//!
//! `v = Kp e + Ki sum(e dt)`, clamped to +-limit, conditional integration as anti-windup.
//! The paper places the PI zero Ki/Kp = 1050 rad/s on the winding pole Ra/La (Table 3,
//! Table 1), so the closed current loop is first order with a bandwidth of Kp/La.
//!
//! Current guard: the position loop's set-point is limited to 20 A, but a PI following a
//! set-point that jumps by 20 A every 0.5 ms (the D term on 84-count Hall feedback does that at
//! speed) overshoots it, by 1.3 A in the paper's sweep. With a [`Winding`] model the loop
//! therefore clamps each voltage so that the *predicted* current at the end of the period stays
//! within the limit: `i[k+1] = a i[k] + (v - e) (1 - a) / Ra`, `a = exp(-Ra dt / La)`, with
//! the back-EMF `e` recovered from the last period's voltage and currents (a dead-beat
//! observer: no speed sensor needed). The integrator is frozen while the guard acts.
//!
//! Bad input: a non-finite set-point or measurement gives 0 V and leaves the state as it was
//! ([`CurrentStatus::InputNotFinite`]); a set-point beyond the current limit is clamped to it.

use super::AntiWindup;
use crate::gains::SiGains;
use crate::units::{Amps, Volts, saturate};

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum CurrentStatus {
    Linear,
    /// The voltage hit the limit; the integrator was held.
    Saturated,
    /// The current guard cut the voltage to keep the current within its limit; integrator held.
    CurrentLimited,
    /// An input was NaN or infinite: 0 V commanded, state untouched.
    InputNotFinite,
}

#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct CurrentOutput {
    pub voltage: Volts,
    pub status: CurrentStatus,
}

/// How far inside the current limit the guard aims, A. The back-EMF estimate is one period
/// old; at the motor's full acceleration (about 13 000 rad/s^2 at 20 A) the back-EMF moves
/// 0.03 V per period, which the 5.7 V/A winding gain turns into 6 mA of overshoot; 50 mA
/// covers it with room for f32 rounding. Measured without margin: 20.0005 A on an 80 deg step.
pub const GUARD_MARGIN_A: f32 = 0.05;

/// The motor winding as the current guard models it over one loop period.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Winding {
    /// exp(-Ra dt / La): how much of the current survives one period at zero net voltage.
    decay: f32,
    /// Ra / (1 - decay), V/A: the net voltage that changes the current by 1 A in one period.
    gain: f32,
}

impl Winding {
    /// `None` unless resistance, inductance and period are finite and positive.
    pub fn new(ra_ohm: f32, la_h: f32, dt_s: f32) -> Option<Self> {
        let valid = |x: f32| x.is_finite() && x > 0.0;
        if !(valid(ra_ohm) && valid(la_h) && valid(dt_s)) {
            return None;
        }
        let decay = exp_neg(ra_ohm * dt_s / la_h);
        let gain = ra_ohm / (1.0 - decay);
        (decay.is_finite() && gain.is_finite() && decay < 1.0).then_some(Winding { decay, gain })
    }
}

/// exp(-x) for x >= 0 without libm: halve until small, 4-term Taylor, square back.
fn exp_neg(x: f32) -> f32 {
    if !(x.is_finite() && x >= 0.0) {
        return 0.0;
    }
    let mut y = x;
    let mut halvings = 0_u32;
    while y > 1e-3 && halvings < 64 {
        y *= 0.5;
        halvings = halvings.saturating_add(1);
    }
    let mut r = 1.0 - y + y * y / 2.0 - y * y * y / 6.0;
    for _ in 0..halvings {
        r *= r;
    }
    r
}

#[derive(Debug, Clone)]
pub struct CurrentLoop {
    kp: f32,
    ki: f32,
    dt_s: f32,
    current_limit_a: f32,
    voltage_limit_v: f32,
    anti_windup: AntiWindup,
    /// Integral term, V; clamped to +-voltage limit.
    integral_v: f32,
    winding: Option<Winding>,
    /// Voltage applied and current measured last period, for the back-EMF observer.
    last: Option<(f32, f32)>,
}

impl CurrentLoop {
    /// A non-positive or non-finite period becomes 50 us (paper mode); a non-finite or
    /// negative limit becomes 0 (no current, no voltage).
    pub fn new(gains: &SiGains, dt_s: f32, current_limit: Amps, voltage_limit: Volts) -> Self {
        let non_negative = |x: f32| if x.is_finite() && x >= 0.0 { x } else { 0.0 };
        CurrentLoop {
            kp: gains.current_kp(),
            ki: gains.current_ki(),
            dt_s: if dt_s.is_finite() && dt_s > 0.0 {
                dt_s
            } else {
                5e-5
            },
            current_limit_a: non_negative(current_limit.0),
            voltage_limit_v: non_negative(voltage_limit.0),
            anti_windup: AntiWindup::default(),
            integral_v: 0.0,
            winding: None,
            last: None,
        }
    }

    /// Turn the current guard on with this winding model (or off with `None`).
    pub fn set_winding(&mut self, winding: Option<Winding>) {
        self.winding = winding;
        self.last = None;
    }

    pub fn set_gains(&mut self, gains: &SiGains) {
        self.kp = gains.current_kp();
        self.ki = gains.current_ki();
    }

    pub fn set_anti_windup(&mut self, mode: AntiWindup) {
        self.anti_windup = mode;
    }

    /// Set the voltage limit, e.g. to min(24 V, measured supply) when the battery sags.
    /// Non-finite or negative values are ignored: the previous limit stays.
    pub fn set_voltage_limit(&mut self, limit: Volts) {
        if limit.0.is_finite() && limit.0 >= 0.0 {
            self.voltage_limit_v = limit.0;
        }
    }

    pub fn voltage_limit(&self) -> Volts {
        Volts(self.voltage_limit_v)
    }

    pub fn integral(&self) -> Volts {
        Volts(self.integral_v)
    }

    pub fn reset(&mut self) {
        self.integral_v = 0.0;
        self.last = None;
    }

    pub fn step(&mut self, setpoint: Amps, measured: Amps) -> CurrentOutput {
        if !(setpoint.is_finite() && measured.is_finite()) {
            return CurrentOutput {
                voltage: Volts::ZERO,
                status: CurrentStatus::InputNotFinite,
            };
        }
        let (target, _) = saturate(setpoint.0, self.current_limit_a);
        let error = target - measured.0;
        let candidate_integral = self.integral_v + self.ki * error * self.dt_s;
        let (mut voltage, saturated) =
            saturate(self.kp * error + candidate_integral, self.voltage_limit_v);
        let guarded = match self.guard_band(measured.0) {
            Some((_, high)) if voltage > high => {
                voltage = saturate(high, self.voltage_limit_v).0;
                true
            }
            Some((low, _)) if voltage < low => {
                voltage = saturate(low, self.voltage_limit_v).0;
                true
            }
            _ => false,
        };
        self.last = Some((voltage, measured.0));
        let integrate = match self.anti_windup {
            AntiWindup::ConditionalIntegration => !(saturated || guarded),
            AntiWindup::IntegratorClamp | AntiWindup::Disabled => true,
        };
        if integrate && candidate_integral.is_finite() {
            let bound = match self.anti_windup {
                AntiWindup::Disabled => f32::MAX,
                AntiWindup::ConditionalIntegration | AntiWindup::IntegratorClamp => {
                    self.voltage_limit_v
                }
            };
            self.integral_v = saturate(candidate_integral, bound).0;
        }
        CurrentOutput {
            voltage: Volts(voltage),
            status: if guarded {
                CurrentStatus::CurrentLimited
            } else if saturated {
                CurrentStatus::Saturated
            } else {
                CurrentStatus::Linear
            },
        }
    }

    /// The voltages that keep the next current sample within +-limit, if the guard is on and
    /// has a previous period to estimate the back-EMF from.
    fn guard_band(&self, current: f32) -> Option<(f32, f32)> {
        let w = self.winding?;
        let (v0, i0) = self.last?;
        let back_emf = v0 - w.gain * (current - w.decay * i0);
        let bound = (self.current_limit_a - GUARD_MARGIN_A).max(0.0);
        let high = back_emf + w.gain * (bound - w.decay * current);
        let low = back_emf + w.gain * (-bound - w.decay * current);
        (high.is_finite() && low.is_finite() && low <= high).then_some((low, high))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains::EposGains;

    fn paper_loop() -> CurrentLoop {
        CurrentLoop::new(
            &EposGains::PAPER.to_si().unwrap(),
            5e-5,
            Amps(20.0),
            Volts(24.0),
        )
    }

    #[test]
    fn pi_action_on_a_small_error() {
        let mut cl = paper_loop();
        let out = cl.step(Amps(1.0), Amps(0.0));
        // Kp e + Ki e dt = 2 * 1 + 2100 * 1 * 5e-5
        assert!((out.voltage.0 - 2.105).abs() < 1e-5);
        let out = cl.step(Amps(1.0), Amps(0.0));
        assert!((out.voltage.0 - 2.21).abs() < 1e-5);
    }

    #[test]
    fn voltage_never_exceeds_24_v_and_integrator_holds() {
        let mut cl = paper_loop();
        for _ in 0..10_000 {
            let out = cl.step(Amps(20.0), Amps(0.0));
            assert!(out.voltage.0 <= 24.0);
        }
        assert!(cl.integral().0.abs() <= 24.0);
        assert_eq!(cl.integral().0, 0.0, "saturated from the first tick");
    }

    #[test]
    fn setpoint_beyond_the_current_limit_is_clamped() {
        let mut cl = paper_loop();
        let a = cl.step(Amps(1.0e6), Amps(19.0)).voltage;
        let mut cl = paper_loop();
        let b = cl.step(Amps(20.0), Amps(19.0)).voltage;
        assert_eq!(a, b);
    }

    #[test]
    fn guard_keeps_a_simulated_winding_within_the_limit_against_back_emf() {
        // The winding of Table 1 at a constant speed whose back-EMF (20 V) the PI has not
        // learnt: asked for -20 A, a bare PI starting from a stale integrator overshoots.
        let (ra, la, dt) = (0.293f32, 0.279e-3f32, 5e-5f32);
        let a = exp_neg(ra * dt / la);
        let run = |guard: bool| {
            let mut cl = paper_loop();
            if guard {
                cl.set_winding(Winding::new(ra, la, dt));
            }
            let mut i = 0.0f32;
            let mut peak = 0.0f32;
            for k in 0..400 {
                let target = if (k / 10) % 2 == 0 { -20.0 } else { 3.0 };
                let v = cl.step(Amps(target), Amps(i)).voltage.0;
                i = a * i + (1.0 - a) * (v - 20.0) / ra;
                peak = peak.max(i.abs());
            }
            peak
        };
        assert!(run(false) > 20.2, "the bare PI overshoots: {}", run(false));
        assert!(run(true) <= 20.0 + 1e-3, "guarded peak {}", run(true));
    }

    #[test]
    fn exp_neg_matches_std() {
        for x in [0.0f32, 1e-4, 0.0525, 1.0, 7.5] {
            assert!((exp_neg(x) - (-x).exp()).abs() < 1e-5, "{x}");
        }
        assert_eq!(exp_neg(f32::NAN), 0.0);
        assert!(Winding::new(0.293, 0.0, 5e-5).is_none());
        assert!(Winding::new(f32::NAN, 1e-3, 5e-5).is_none());
    }

    #[test]
    fn non_finite_input_gives_zero_volts() {
        let mut cl = paper_loop();
        cl.step(Amps(1.0), Amps(0.0));
        let before = cl.integral();
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            assert_eq!(cl.step(Amps(bad), Amps(0.0)).voltage, Volts::ZERO);
            let out = cl.step(Amps(0.0), Amps(bad));
            assert_eq!(out.voltage, Volts::ZERO);
            assert_eq!(out.status, CurrentStatus::InputNotFinite);
        }
        assert_eq!(cl.integral(), before);
    }

    #[test]
    fn voltage_limit_follows_supply_but_ignores_garbage() {
        let mut cl = paper_loop();
        cl.set_voltage_limit(Volts(12.0));
        assert_eq!(cl.voltage_limit(), Volts(12.0));
        cl.set_voltage_limit(Volts(f32::NAN));
        cl.set_voltage_limit(Volts(-3.0));
        assert_eq!(cl.voltage_limit(), Volts(12.0));
        assert!(cl.step(Amps(20.0), Amps(0.0)).voltage.0 <= 12.0);
    }
}

//! "ECU mode": the ECU's own steering controller, for the column rather than the motor.
//!
//! Paper mode (see [`crate::paper_mode`]) closes its loops on the motor and leaves the column to
//! follow through the belt. On the paper's plant that belt is soft (k_B = 0.29 Nm/rad, Table 4)
//! and the nut side is dominated by damping (beta_BS = 1.34e-2 Nm s/rad, Table 4), so with the
//! motor held on its set-point the pinion lags it like a low-pass of about 50 ms: 0.86 of the
//! amplitude at 2 Hz, 0.64 at 4 Hz (eqs. 5-8). Paper mode's -3 dB point therefore sits near
//! 2.3 Hz whatever its motor loop does. ECU mode keeps the paper's structure (PID on the motor
//! angle, PI on the current, the same limits and anti-windup) and adds what the model says is
//! missing:
//!
//! ```text
//!  r (100 Hz) --> [inverse belt model] --> motor target --> interpolator --> PID + model ff --> i*
//!       |                                                          ^              ^
//!       +--> interpolator --> (r - column) --> slow integral ------+   speed from Hall edge timing
//! ```
//!
//! 1. **Inverse belt model on the reference.** With the motor position imposed the nut obeys
//!    `J* th'' + c th' + k_B th = k_B th_m / 2 + beta_B th_m' / 2` (eqs. 5-7, the column taken as
//!    rigid with the pinion), so the motor target that makes the pinion follow `r` is
//!    `G (r + tau1 r' + tau2 r'')` with `tau1 = (c - beta_B) / k_B`, `tau2 = J* / k_B`, `G` the
//!    motor-per-pinion ratio. `r'` and `r''` are backward differences of the 100 Hz samples.
//! 2. **Model feedforward.** The drivetrain reflected to the motor: inertia `J_rot + J*/4`,
//!    damping `r + c/4` (eq. 8 for `J*`), in A per rad/s and A per rad/s^2 through k_t. Table
//!    3's velocity feedforward (12.59 mA s/rad) covers the motor alone; the nut's damping needs
//!    about six times that.
//! 3. **Speed from Hall edge timing** for the D term instead of differencing the 84-count Hall
//!    angle: a Hall step over one 0.5 ms tick reads as 150 rad/s, so paper mode's D term kicks
//!    the current set-point by about 24 A at every edge, even holding still. Here the speed is
//!    the last edge-to-edge step over its time, bounded by one step over the time since the
//!    last edge (so it decays to zero at rest), and the D term acts on `w_ref - w_est`.
//! 4. **Column feedback**, which moves the motor target so that the column (not the motor)
//!    settles on the reference: a proportional term (gain [`EcuTuning::column_gain`], acting
//!    only beyond one encoder count so the 12-bit quantisation does not chatter the target at
//!    rest) that keeps the column on the reference when the plant is not the model (a belt half
//!    as stiff: 2.38 Hz instead of 1.64 Hz without it; gain 0.5, as 1 overshot a 20 deg step by
//!    13 %), and a slow integral (time constant
//!    [`EcuTuning::column_time_constant_s`], clamped to [`EcuTuning::column_authority_rad`] at
//!    the column) for backlash, friction and gearing offsets, also acting only beyond one
//!    count, so that which of two counts a resting column reads does not wind it.
//!
//! Bad input: as paper mode. A non-finite or out-of-range reference is refused; a missing or
//! non-finite column sample freezes the column integral (the inner loops carry on).

use crate::control::AntiWindup;
use crate::control::current::{CurrentLoop, CurrentOutput, Winding};
use crate::control::position::{PositionLoop, PositionOutput};
use crate::gains::SiGains;
use crate::gearing::Gearing;
use crate::paper_mode::{
    CURRENT_LIMIT, CURRENT_LOOP_HZ, MOTOR_LA_H, MOTOR_RA_OHM, POSITION_LOOP_HZ,
    POSITION_TICKS_PER_REFERENCE, REFERENCE_HZ, VOLTAGE_LIMIT, reference_at_motor,
};
use crate::reference::{Interpolator, ReferenceError, Setpoint};
use crate::sensors::{COLUMN_ENCODER_COUNTS, HALL_COUNTS_PER_REV, motor_from_hall};
use crate::units::{Amps, MotorRad, SteeringDeg, SteeringRad, Volts, saturate};
use core::f32::consts::TAU;

/// Below this reference speed at the column (1.5 deg/s) the reference counts as resting and the
/// column integral runs, rad/s. The reference comes in bits of 0.01 deg at 100 Hz
/// ([`crate::protocol::ANGLE_DEG_PER_BIT`], [`REFERENCE_HZ`]), so its speed between two samples
/// is a whole number of bits per period, 1 deg/s each: one bit per period (an AS computer's
/// rounding dithering the last bit) rests, two do not, and the threshold lies halfway between
/// two speeds the reference can have, where the f32 rounding of a difference cannot decide it
/// (at exactly one bit per period it would, and the integral would run at some steering angles
/// and not at others).
const RESTING_RAD_PER_S: f32 =
    1.5 * crate::protocol::ANGLE_DEG_PER_BIT * REFERENCE_HZ as f32 * (TAU / 360.0);

/// The column integral acts only within this error at the column (1 deg, rad): it is for
/// static offsets (backlash of 1.5 deg leaves at most 0.75 deg), not for the catch-up after a
/// step.
const INTEGRAL_ZONE_RAD: f32 = 0.017_453;

/// A column that has moved no more than one encoder count (it is "moving" from 1.5 counts, so
/// that a column dithering between two counts has stopped wherever it is, and the rounding of
/// two f32 angles one count apart never decides) for this long has stopped, s: with
/// the reference resting, what error is left then is a static offset (play, friction) that the
/// proportional term alone cannot take back, however large, and the integral takes it on.
/// Longer than a stick-slip pause of the catch-up after a step on the plant with play and
/// friction; short against the integral's own time constant.
const COLUMN_STILL_S: f32 = 0.1;

/// Fastest change of the proportional column term, rad/s at the column (100 deg/s).
const COLUMN_SLEW_RAD_PER_S: f32 = 1.745_33;

/// After the enable ramp hands over, the proportional column term's gain grows from 0 to
/// [`EcuTuning::column_gain`] over this long, s: the column lags the ramp's end by up to a
/// degree, and the term taking that back at once (at its 100 deg/s slew) would be a step in
/// the target's speed, which the drive answers with its full current.
const COLUMN_GAIN_FADE_IN_S: f32 = 0.05;

/// One count of the 12-bit column encoder, rad.
const COLUMN_COUNT_RAD: f32 = TAU / COLUMN_ENCODER_COUNTS as f32;

/// The model-derived constants of ECU mode. [`EcuTuning::PAPER`] is the paper's plant, and the
/// only tuning there is: host-sim runs it unchanged on other plants (`--plant FILE`) to measure
/// its robustness, and the unit test `paper_tuning_matches_the_tables` recomputes it from
/// Tables 1, 2 and 4.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct EcuTuning {
    /// First-order term of the inverse belt model, s: (c - beta_B) / k_B.
    pub lag1_s: f32,
    /// Second-order term of the inverse belt model, s^2: J* / k_B.
    pub lag2_s2: f32,
    /// Largest lead the inverse belt model may add, rad at the column: the belt stretch the
    /// current limit can make, k_t I_max (belt reduction)^2 / (k_B G) (Tables 1, 4: 0.17 rad,
    /// 9.7 deg at 20 A).
    pub max_lead_rad: f32,
    /// Velocity feedforward at the motor, A per rad/s: (r + c / 4) / k_t.
    pub ff_velocity: f32,
    /// Acceleration feedforward at the motor, A per rad/s^2: (J_rot + J* / 4) / k_t.
    pub ff_acceleration: f32,
    /// Proportional column feedback: motor target moved per unit of column error (both at the
    /// motor through the gearing), dimensionless.
    pub column_gain: f32,
    /// Time constant of the column integral, s.
    pub column_time_constant_s: f32,
    /// Largest correction the column integral may make, rad at the column.
    pub column_authority_rad: f32,
}

impl EcuTuning {
    /// The paper's plant (Tables 1, 2, 4; belt factor 1/2 and eq. 6 corrected as in host-sim):
    /// c = beta_BS + beta_B + beta_SW g^2 = 1.597e-2 Nm s/rad at the nut (g = tauBS / tauP),
    /// J* = 1.076e-4 kg m^2 (eq. 8), k_B = 0.29 Nm/rad, k_t = 52.5 mNm/A, J_rot = 0.81e-4 kg m^2,
    /// r = 5.78e-5 Nm s/rad. The unit test `paper_tuning_matches_the_tables` recomputes them.
    pub const PAPER: EcuTuning = EcuTuning {
        lag1_s: 0.049_203,
        lag2_s2: 3.709_3e-4,
        max_lead_rad: 0.169_5,
        ff_velocity: 0.077_132,
        ff_acceleration: 2.055_1e-3,
        column_gain: 0.5,
        column_time_constant_s: 0.3,
        column_authority_rad: 0.087_266,
    };

    fn is_valid(&self) -> bool {
        let ok = |x: f32| x.is_finite() && x >= 0.0;
        ok(self.lag1_s)
            && ok(self.lag2_s2)
            && ok(self.ff_velocity)
            && ok(self.ff_acceleration)
            && self.column_time_constant_s.is_finite()
            && self.column_time_constant_s > 0.0
            && ok(self.column_authority_rad)
            && ok(self.column_gain)
            && ok(self.max_lead_rad)
    }
}

/// Motor speed from Hall edge timing, rad/s.
#[derive(Debug, Clone, Default)]
struct HallSpeed {
    last_count: Option<i32>,
    /// Ticks since the last edge.
    since_edge: u32,
    speed: f32,
    /// Sign of the last edge (0 before the first).
    direction: f32,
}

impl HallSpeed {
    fn step(&mut self, count: i32, dt_s: f32) -> f32 {
        let step_rad = TAU / HALL_COUNTS_PER_REV as f32;
        self.since_edge = self.since_edge.saturating_add(1);
        match self.last_count {
            Some(last) if last != count => {
                let steps = count.wrapping_sub(last) as f32;
                let speed = steps * step_rad / (self.since_edge as f32 * dt_s);
                // An edge against the last one's direction: the motor turned round in between,
                // so its speed is near zero, not a full step over one tick (chatter on an edge).
                // The first edge after a reset has no start time either.
                let unknown = speed * self.direction <= 0.0;
                self.direction = speed.signum();
                self.speed = if unknown { 0.0 } else { speed };
                self.since_edge = 0;
            }
            Some(_) => {
                // No edge: the speed cannot exceed one step over the time since the last one.
                let bound = step_rad / (self.since_edge as f32 * dt_s);
                self.speed = saturate(self.speed, bound).0;
            }
            None => {
                self.speed = 0.0;
                self.since_edge = 0;
            }
        }
        self.last_count = Some(count);
        self.speed
    }
}

/// The column side of ECU mode: the inverse belt model on the reference and the column
/// feedback, giving the motor target. Direct drive runs it inside [`ColumnCascade`] at 2 kHz;
/// EPOS4 mode runs it alone, once per SYNC, and sends the target as the CSP position.
#[derive(Debug, Clone)]
pub struct ColumnShaper {
    gearing: Gearing,
    tuning: EcuTuning,
    /// Motor targets (after the inverse belt model).
    target: Interpolator,
    /// The plain reference at the motor, for the column error.
    plain: Interpolator,
    /// Seconds per tick.
    dt_s: f32,
    /// The last two accepted reference samples at the motor, newest first.
    history: [Option<f32>; 2],
    /// Column integral, rad at the motor.
    column_correction: f32,
    /// The last column error, rad at the motor (0 without a column sample).
    column_error: f32,
    /// The newest sample was shaped (a vehicle reference), not the enable ramp's.
    shaping: bool,
    /// The share of the proportional column term's gain in force, 0..=1: 0 during the enable
    /// ramp, then growing over [`COLUMN_GAIN_FADE_IN_S`].
    gain_share: f32,
    /// The proportional column term as applied (slew-limited), rad at the motor.
    proportional: f32,
    /// Where the column was when it last moved by two counts or more, rad at the motor.
    column_anchor: Option<f32>,
    /// Time since then, s (saturating at [`COLUMN_STILL_S`]).
    column_still_s: f32,
}

impl ColumnShaper {
    /// `ticks_per_period` calls of [`ColumnShaper::next`] per 10 ms reference period (20 in
    /// direct drive at 2 kHz; the SYNCs per period in EPOS4 mode). An invalid tuning is
    /// replaced by [`EcuTuning::PAPER`].
    pub fn new(gearing: Gearing, tuning: EcuTuning, ticks_per_period: u16) -> Self {
        let tuning = if tuning.is_valid() {
            tuning
        } else {
            EcuTuning::PAPER
        };
        let ticks = ticks_per_period.max(1);
        let period = 1.0 / REFERENCE_HZ as f32;
        ColumnShaper {
            gearing,
            tuning,
            target: Interpolator::new(ticks, period),
            plain: Interpolator::new(ticks, period),
            dt_s: period / ticks as f32,
            history: [None; 2],
            column_correction: 0.0,
            column_error: 0.0,
            shaping: true,
            gain_share: 1.0,
            proportional: 0.0,
            column_anchor: None,
            column_still_s: 0.0,
        }
    }

    pub fn tuning(&self) -> EcuTuning {
        self.tuning
    }

    /// A new reference sample at the wheel; refused as paper mode refuses it.
    pub fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        let r = reference_at_motor(self.gearing, angle)?.0;
        let t = 1.0 / REFERENCE_HZ as f32;
        let r1 = self.history[0].unwrap_or(r);
        let r2 = self.history[1].unwrap_or(r1);
        let slope = (r - r1) / t;
        let curvature = (r - 2.0 * r1 + r2) / (t * t);
        // The lead is the belt's stretch and the nut's lag; no more can exist than the current
        // limit can stretch the belt to, so a step in the reference (which would ask for
        // hundreds of degrees of lead for one period) is shaped no further than that.
        let lead_limit = self.gearing.ratio() * self.tuning.max_lead_rad;
        let lead = saturate(
            self.tuning.lag1_s * slope + self.tuning.lag2_s2 * curvature,
            lead_limit,
        )
        .0;
        let target = r + lead;
        self.history = [Some(r), Some(r1)];
        self.plain.push(MotorRad(r))?;
        self.shaping = true;
        self.target.push(MotorRad(target))
    }

    /// A sample taken as it is, without the inverse belt model, and with the derivative history
    /// restarted there: the ECU's enable ramp (a velocity step it makes itself) would otherwise
    /// become a position step of `lag1_s` times the ramp rate (4.9 deg at 100 deg/s) at the
    /// start of every enable, and again at its end.
    pub fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        let r = crate::paper_mode::ramp_at_motor(self.gearing, angle)?.0;
        self.history = [Some(r), Some(r)];
        self.plain.push(MotorRad(r))?;
        self.shaping = false;
        self.gain_share = 0.0;
        self.target.push(MotorRad(r))
    }

    /// The motor target for this tick, given the column angle when a fresh sample exists.
    pub fn next(&mut self, column: Option<SteeringRad>) -> Setpoint {
        let mut setpoint = self.target.next_setpoint();
        let correction = self.column_terms(column);
        setpoint.position = MotorRad(setpoint.position.0 + correction);
        setpoint
    }

    /// EPOS4 mode, once per SYNC: the newest shaped sample plus the column terms, as the CSP
    /// target. The drive interpolates from its last target to this one over the next period,
    /// which is the one sample of lag direct drive's interpolator has too.
    pub fn next_target(&mut self, column: Option<SteeringRad>) -> MotorRad {
        let _ = self.target.next_setpoint();
        let correction = self.column_terms(column);
        MotorRad(self.target.segment_end().0 + correction)
    }

    /// Advance the plain reference one tick, take the column sample into the column terms and
    /// return their correction of the motor target, rad at the motor.
    fn column_terms(&mut self, column: Option<SteeringRad>) -> f32 {
        let plain = self.plain.next_setpoint();
        // Stillness counts from when the reference came to rest: before, the column standing
        // still says nothing (the motor may still be crossing the play).
        let reference_resting = plain.velocity.abs() <= self.gearing.ratio() * RESTING_RAD_PER_S;
        self.column_still_s = if reference_resting {
            (self.column_still_s + self.dt_s).min(COLUMN_STILL_S)
        } else {
            0.0
        };
        // One column-encoder count at the motor: the step of what the column terms read.
        let count = self.gearing.ratio() * COLUMN_COUNT_RAD;
        if let Some(column) = column.filter(|c| c.is_finite()) {
            let column_motor = self.gearing.motor_from_steering(column).0;
            if self
                .column_anchor
                .is_none_or(|anchor| (column_motor - anchor).abs() > 1.5 * count)
            {
                self.column_anchor = Some(column_motor);
                self.column_still_s = 0.0;
            }
            let error = plain.position.0 - column_motor;
            self.column_error = if error.is_finite() { error } else { 0.0 };
            let authority = self.gearing.ratio() * self.tuning.column_authority_rad;
            // Like the proportional term, the integral takes only the error beyond the
            // encoder's last count: within it the column's reading is quantisation, not an
            // offset, and integrating which of two counts each sample fell on would make a car
            // whose run no model repeats (gap/NOTES.md, "The ECU controller on the EPOS4 car").
            // What it leaves is under a count at the column, 0.088 deg.
            let next = self.column_correction
                + beyond(error, count) * self.dt_s / self.tuning.column_time_constant_s;
            // The integral is for static offsets (backlash, friction, gearing): while the
            // reference moves, the column's lag is the feedforward's business, and integrating
            // it would wind up and overshoot when the reference stops (0.7 deg after a 10 deg
            // ramp at 100 deg/s, seen through the firmware's tasks).
            // And only near the reference or once the column has stopped: a large error while
            // the column still moves is the catch-up after a step, the proportional term's, and
            // integrating it would overshoot by as much again; a column stopped short (friction
            // and play against the proportional term's pull: 1.1 deg on the plant with 1.5 deg
            // of play and 200 N at the rack over the EPOS4) is an offset, the integral's.
            let stopped = self.column_still_s >= COLUMN_STILL_S;
            let resting = reference_resting
                && (stopped || error.abs() <= self.gearing.ratio() * INTEGRAL_ZONE_RAD);
            if resting && next.is_finite() {
                self.column_correction = saturate(next, authority).0;
            }
        }
        // The column encoder's 0.088 deg count is 1.75 Hall counts at the motor: proportional
        // action on the last count would chatter the target between two counts at rest, so it
        // acts only on the error beyond one count, as the integral does.
        let beyond_count = beyond(self.column_error, count);
        // Not during the enable ramp: the column lags the ECU's own ramp, and pushing on that
        // lag would make the ramp faster than its documented rate.
        let gain = if self.shaping {
            self.gain_share = (self.gain_share + self.dt_s / COLUMN_GAIN_FADE_IN_S).min(1.0);
            self.tuning.column_gain * self.gain_share
        } else {
            0.0
        };
        // The proportional term moves the target no faster than 100 deg/s
        // at the column: when a ramp hands over, or an encoder sample jumps, the drive sees a
        // ramp, not a step.
        let slew = self.gearing.ratio() * COLUMN_SLEW_RAD_PER_S * self.dt_s;
        let wanted = gain * beyond_count;
        if wanted.is_finite() {
            self.proportional += saturate(wanted - self.proportional, slew).0;
        }
        self.column_correction + self.proportional
    }

    /// Start again from rest at the motor angle `here`: histories and column terms cleared.
    pub fn reset(&mut self, here: MotorRad) {
        self.column_correction = 0.0;
        self.column_error = 0.0;
        self.proportional = 0.0;
        self.column_anchor = None;
        self.column_still_s = 0.0;
        self.history = [None; 2];
        self.target.reset_to(here);
        self.plain.reset_to(here);
    }
}

/// What of `error` lies beyond `band` either side of zero (0 within it).
fn beyond(error: f32, band: f32) -> f32 {
    error - saturate(error, band).0
}

/// The ECU-mode cascade for direct drive: the same call pattern as
/// [`crate::paper_mode::Cascade`] (a reference sample, then 20 position steps each followed by
/// 10 current steps), with the column angle given to each position step.
#[derive(Debug, Clone)]
pub struct ColumnCascade {
    shaper: ColumnShaper,
    position: PositionLoop,
    current: CurrentLoop,
    speed: HallSpeed,
    kd: f32,
    current_setpoint: Amps,
    last_setpoint: Setpoint,
}

impl ColumnCascade {
    /// `gains` are the paper's loops (Table 3) whose feedforward ECU mode replaces by the model's.
    pub fn new(gains: &SiGains, gearing: Gearing, tuning: EcuTuning) -> Self {
        let mut cascade = ColumnCascade {
            shaper: ColumnShaper::new(gearing, tuning, POSITION_TICKS_PER_REFERENCE as u16),
            position: PositionLoop::new(
                &SiGains::ZERO,
                1.0 / POSITION_LOOP_HZ as f32,
                CURRENT_LIMIT,
            ),
            current: CurrentLoop::new(
                gains,
                1.0 / CURRENT_LOOP_HZ as f32,
                CURRENT_LIMIT,
                VOLTAGE_LIMIT,
            ),
            speed: HallSpeed::default(),
            kd: 0.0,
            current_setpoint: Amps::ZERO,
            last_setpoint: Setpoint::default(),
        };
        cascade.set_gains(gains);
        cascade.set_winding(MOTOR_RA_OHM, MOTOR_LA_H);
        cascade
    }

    fn set_gains(&mut self, gains: &SiGains) {
        // The PID without its D term and with the model's feedforward: the D term acts on the
        // Hall-timed speed below, outside the loop's own backward difference.
        let tuning = self.shaper.tuning();
        let pid = gains
            .with_position_loop(
                gains.position_kp(),
                gains.position_ki(),
                0.0,
                tuning.ff_velocity,
                tuning.ff_acceleration,
            )
            .unwrap_or(SiGains::ZERO);
        self.position.set_gains(&pid);
        self.kd = gains.position_kd();
        self.current.set_gains(gains);
    }

    pub fn set_winding(&mut self, ra_ohm: f32, la_h: f32) {
        self.current
            .set_winding(Winding::new(ra_ohm, la_h, 1.0 / CURRENT_LOOP_HZ as f32));
    }

    pub fn set_anti_windup(&mut self, mode: AntiWindup) {
        self.position.set_anti_windup(mode);
        self.current.set_anti_windup(mode);
    }

    pub fn set_voltage_limit(&mut self, limit: Volts) {
        self.current.set_voltage_limit(limit);
    }

    /// A new reference sample at the wheel; refused as paper mode refuses it.
    pub fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        self.shaper.push_reference(angle)
    }

    /// [`ColumnShaper::push_unshaped`]: the ECU's own enable ramp.
    pub fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        self.shaper.push_unshaped(angle)
    }

    /// One position-loop tick (2 kHz): the Hall count and, when a fresh sample exists, the
    /// column angle.
    pub fn position_step(
        &mut self,
        hall_count: i32,
        column: Option<SteeringRad>,
    ) -> PositionOutput {
        let speed = self.speed.step(hall_count, 1.0 / POSITION_LOOP_HZ as f32);
        let setpoint = self.shaper.next(column);
        self.last_setpoint = setpoint;
        // The D term on the motor speed alone, inside the limit (the position loop saturates
        // the whole sum and holds its integrator accordingly).
        let damping = Amps(self.kd * (setpoint.velocity - speed));
        let out = self
            .position
            .step_with(setpoint, motor_from_hall(hall_count), damping);
        self.current_setpoint = out.current;
        out
    }

    pub fn current_step(&mut self, measured: Amps) -> CurrentOutput {
        self.current.step(self.current_setpoint, measured)
    }

    pub fn setpoint(&self) -> Setpoint {
        self.last_setpoint
    }

    pub fn current_setpoint(&self) -> Amps {
        self.current_setpoint
    }

    /// Drive disabled: every integrator and history cleared, the target held at the motor.
    pub fn reset(&mut self, hall_count: i32) {
        self.position.reset();
        self.current.reset();
        self.speed = HallSpeed::default();
        self.current_setpoint = Amps::ZERO;
        self.shaper.reset(motor_from_hall(hall_count));
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gains::EposGains;

    #[test]
    fn paper_tuning_matches_the_tables() {
        // Tables 1, 2, 4 (SI).
        let (r, j_rot, kt) = (5.78e-5f64, 0.81e-4, 52.5e-3);
        let (m_bs, m_r, tau_bs, tau_p, tau_r) = (0.171, 6.5e-2, 3.183e-4, 1.36e-2, 19.4);
        let (j_bs, j_w, k_b, beta_b, beta_bs, beta_sw) =
            (6.5e-6, 2.65, 0.29, 1.7e-3, 1.34e-2, 1.59);
        let g: f64 = tau_bs / tau_p;
        let j_star = j_bs + (m_r + m_bs) * tau_bs * tau_bs + j_w * (tau_bs * tau_r).powi(2);
        let c = beta_bs + beta_b + beta_sw * g * g;
        let p = EcuTuning::PAPER;
        let close = |a: f32, b: f64| ((a as f64 - b) / b).abs() < 1e-3;
        assert!(
            close(p.lag1_s, (c - beta_b) / k_b),
            "{}",
            (c - beta_b) / k_b
        );
        assert!(close(p.lag2_s2, j_star / k_b), "{}", j_star / k_b);
        assert!(
            close(p.ff_velocity, (r + c / 4.0) / kt),
            "{}",
            (r + c / 4.0) / kt
        );
        assert!(
            close(p.ff_acceleration, (j_rot + j_star / 4.0) / kt),
            "{}",
            (j_rot + j_star / 4.0) / kt
        );
    }

    fn cascade() -> ColumnCascade {
        ColumnCascade::new(
            &EposGains::PAPER.to_si().unwrap(),
            Gearing::PAPER,
            EcuTuning::PAPER,
        )
    }

    #[test]
    fn holding_still_on_a_hall_edge_does_not_kick_the_current() {
        let mut c = cascade();
        c.reset(0);
        c.push_reference(SteeringDeg(0.0)).unwrap();
        let mut worst = 0.0f32;
        // The motor sits on an edge and chatters between two counts every other tick.
        for k in 0..2000 {
            let out = c.position_step(k % 2, Some(SteeringRad(0.0)));
            worst = worst.max(out.current.0.abs());
        }
        assert!(worst < 10.0, "{worst} A");
    }

    #[test]
    fn hall_speed_reads_edge_timing_and_decays_at_rest() {
        let mut s = HallSpeed::default();
        let dt = 5e-4;
        let step = TAU / 84.0;
        s.step(0, dt);
        // The first edge only starts the clock.
        assert_eq!(s.step(1, dt), 0.0);
        for _ in 0..3 {
            s.step(1, dt);
        }
        // The next edge four ticks later: one step over 2 ms.
        let w = s.step(2, dt);
        assert!((w - step / 2e-3).abs() < 1e-3, "{w}");
        let mut last = w;
        for _ in 0..100 {
            last = s.step(2, dt);
        }
        // Chatter back across the edge reads as a turn-round, not a full step per tick.
        assert_eq!(s.step(1, dt), 0.0);
        assert!(last > 0.0 && last <= step / (100.0 * dt) + 1e-6, "{last}");
    }

    #[test]
    fn the_column_integral_moves_the_motor_target_towards_the_column_reference() {
        let mut c = cascade();
        c.reset(0);
        c.push_reference(SteeringDeg(0.0)).unwrap();
        // The column reads 1 deg short of the reference, the motor sits on its target.
        for _ in 0..2000 {
            c.position_step(0, Some(SteeringRad::from(SteeringDeg(-1.0))));
        }
        assert!(c.setpoint().position.0 > 0.0);
    }

    /// EPOS4 mode's shaper (one call per SYNC, a SYNC per reference period) after `periods`
    /// reference samples from `reference(k)` with the column at `column(k)`: the column
    /// integral's correction, rad at the motor.
    fn column_integral_after(
        periods: usize,
        reference: impl Fn(usize) -> SteeringDeg,
        column: impl Fn(usize) -> SteeringRad,
    ) -> f32 {
        let mut s = ColumnShaper::new(Gearing::PAPER, EcuTuning::PAPER, 1);
        let start = reference(0);
        s.reset(Gearing::PAPER.motor_from_steering(SteeringRad::from(start)));
        for k in 0..periods {
            s.push_reference(reference(k)).unwrap();
            s.next_target(Some(column(k)));
        }
        s.column_correction
    }

    /// The reference comes in bits of 0.01 deg at 100 Hz (the protocol's REF_SteeringAngle),
    /// so a slow one moves a whole bit per period: whether that is resting must not depend on
    /// where the wheel is. The old threshold (1 deg/s) was exactly one bit per period, and the
    /// f32 rounding of each difference decided, so the column integral ran at some angles and
    /// not at others, and a model of the car could not repeat its own run.
    #[test]
    fn a_reference_moving_one_bit_per_period_rests_alike_at_every_angle() {
        let bit = crate::protocol::ANGLE_DEG_PER_BIT;
        let corrections: heapless::Vec<f32, 16> = [-41.23f32, -7.5, 0.37, 3.0, 12.81, 25.02, 58.6]
            .iter()
            .map(|&from| {
                // 1 s of a reference creeping up one bit per period, the column 0.5 deg short.
                let raw = (from / bit) as i32;
                let at = move |k: usize| SteeringDeg((raw + k as i32) as f32 * bit);
                let column = move |k: usize| SteeringRad::from(SteeringDeg(at(k).0 - 0.5));
                column_integral_after(100, at, column)
            })
            .collect();
        let first = corrections[0];
        assert!(first > 0.0, "{corrections:?}");
        for c in &corrections {
            assert!((c - first).abs() < 1e-3 * first, "{corrections:?}");
        }
    }

    /// A column dithering between two neighbouring counts has not moved (the column encoder's
    /// last count is noise), wherever it is: with the reference resting and the column more
    /// than the integral's zone short, the integral runs once it has stood still that long. The
    /// old test ("more than one count" between two f32 angles a count apart) let the rounding
    /// decide, so the integral ran at some counts and never at others.
    #[test]
    fn a_column_dithering_by_one_count_has_stopped_at_every_count() {
        let count = COLUMN_COUNT_RAD;
        let corrections: heapless::Vec<f32, 16> = [-950i32, -523, -3, 0, 41, 777, 990]
            .iter()
            .map(|&at| {
                let resting = (at as f32 * count).to_degrees() + 2.0;
                let column = move |k: usize| SteeringRad((at + (k % 2) as i32) as f32 * count);
                column_integral_after(100, move |_| SteeringDeg(resting), column)
            })
            .collect();
        for c in &corrections {
            assert!(*c > 0.0, "{corrections:?}");
        }
    }

    /// A column resting on the reference's count, dithering to the next one, has no offset
    /// the integral could take back: the integral stays where it is, whichever count each
    /// sample falls on. It took the count's noise in before, and a car under the ECU
    /// controller then repeated its own run only to 93 %.
    #[test]
    fn a_column_dithering_within_a_count_of_the_reference_leaves_the_integral_alone() {
        let count = COLUMN_COUNT_RAD;
        for at in [-523i32, 0, 41, 777] {
            let resting = (at as f32 * count).to_degrees();
            let column =
                move |k: usize| SteeringRad((at + k.is_multiple_of(3) as i32) as f32 * count);
            let c = column_integral_after(200, move |_| SteeringDeg(resting), column);
            // Within the f32 rounding of a count's edge (the old integral: a third of a count
            // for 2 s against its 0.3 s, 2.2 counts).
            let count_at_motor = Gearing::PAPER.ratio() * count;
            assert!(c.abs() < 1e-3 * count_at_motor, "at count {at}: {c}");
        }
    }

    #[test]
    fn refuses_bad_references_and_missing_columns_keep_it_running() {
        let mut c = cascade();
        c.reset(0);
        assert_eq!(
            c.push_reference(SteeringDeg(f32::NAN)),
            Err(ReferenceError::NotFinite)
        );
        assert_eq!(
            c.push_reference(SteeringDeg(91.0)),
            Err(ReferenceError::OutOfRange)
        );
        let out = c.position_step(0, Some(SteeringRad(f32::NAN)));
        assert!(out.current.0.is_finite());
        let out = c.position_step(i32::MAX, None);
        assert!(out.current.0.is_finite() && out.current.0.abs() <= 20.0);
    }
}

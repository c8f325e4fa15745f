//! The paper's actuator with the effects the linear model leaves out, placed where they arise:
//! play in the belt/nut and between the pinion and the column encoder, Coulomb (+Stribeck)
//! friction at the motor and at the rack, and the tyre's scrub as an elasto-plastic bristle at
//! the rack. It is an [`Actuator`], so `sim::run` closes the firmware's loop around it exactly
//! as around the linear plant (`host-sim --plant-effects`, and the gap diagnosis's candidates).
//!
//! The linear part is the plant of eqs. 1-8 discretised exactly for the current-loop step with
//! two torque inputs (motor shaft, ball screw); each effect is a torque computed from the state
//! at the start of the step and held over it. At 20 kHz the fastest mechanical pole (334 rad/s)
//! moves 1.7 % of a radian per step, so holding the effects' torques is accurate; the friction
//! law's slope is bounded so that one step cannot reverse the speed it opposes.

use crate::plant::{Actuator, PlantError, PlantParams, state};
use nalgebra::SMatrix;

/// The effects and their sizes; zero means absent ([`PlantEffects::NONE`]).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct PlantEffects {
    /// Play in the belt/nut (between the motor pulley and the ball screw), full width, referred
    /// to the column: deg at the wheel. The motor turns that far without moving the rack.
    pub belt_play_deg: f64,
    /// Play between the pinion and the column encoder, full width, deg at the wheel: the
    /// encoder lags the rack by up to this much when the direction changes.
    pub column_play_deg: f64,
    /// Coulomb friction at the motor shaft, Nm.
    pub motor_coulomb_nm: f64,
    /// Static friction above `motor_coulomb_nm` at standstill (Stribeck), Nm.
    pub motor_stribeck_nm: f64,
    /// Stribeck velocity at the motor, rad/s (0 = 1 rad/s).
    pub stribeck_velocity_rad_s: f64,
    /// Coulomb friction at the rack, N.
    pub rack_coulomb_n: f64,
    /// Rack speed over which the rack friction builds up, mm/s: the force is
    /// `rack_coulomb_n tanh(v / rack_creep_mm_s)`, so below it the rack creeps under a force
    /// short of the friction (grease, seals). 0 = sharp: the friction holds the rack still.
    pub rack_creep_mm_s: f64,
    /// Tyre scrub: the largest force of the bristle at the rack, N.
    pub tire_force_n: f64,
    /// Tyre scrub: the bristle's stiffness at the rack, N/mm.
    pub tire_stiffness_n_per_mm: f64,
    /// The tyre's law: an elasto-plastic bristle (linear up to its largest force, then
    /// sliding), or Dahl's (the force approaches its largest value smoothly,
    /// dF/dx = k (1 - F/F_max sgn v)).
    pub tire_dahl: bool,
}

/// Why a `--plant-effects` list was refused.
#[derive(Debug, Clone, PartialEq)]
pub enum EffectsError {
    /// An item without `=`.
    Syntax(String),
    UnknownKey(String),
    /// Not a finite number, or negative.
    BadValue {
        key: String,
        value: String,
    },
    /// A tyre bristle needs both its force and its stiffness.
    TireIncomplete,
}

impl std::fmt::Display for EffectsError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            EffectsError::Syntax(item) => {
                write!(f, "`{item}`: expected KEY=VALUE (e.g. backlash_deg=1.5)")
            }
            EffectsError::UnknownKey(key) => write!(
                f,
                "unknown effect `{key}`; known: {}",
                PlantEffects::KEYS
                    .iter()
                    .map(|(k, _)| *k)
                    .collect::<Vec<_>>()
                    .join(", ")
            ),
            // The caller's message quotes the whole list (clap does): name the key and the
            // value apart, once each, with what the key takes.
            EffectsError::BadValue { key, value } => {
                let what = PlantEffects::KEYS
                    .iter()
                    .find(|(k, _)| k == key)
                    .map_or(String::new(), |(_, what)| format!(" ({what})"));
                write!(f, "{key} takes a finite number >= 0{what}, not `{value}`")
            }
            EffectsError::TireIncomplete => write!(
                f,
                "tire_n and tire_n_per_mm go together (a bristle needs its force and its stiffness)"
            ),
        }
    }
}

impl std::error::Error for EffectsError {}

impl PlantEffects {
    pub const NONE: PlantEffects = PlantEffects {
        belt_play_deg: 0.0,
        column_play_deg: 0.0,
        motor_coulomb_nm: 0.0,
        motor_stribeck_nm: 0.0,
        stribeck_velocity_rad_s: 0.0,
        rack_coulomb_n: 0.0,
        rack_creep_mm_s: 0.0,
        tire_force_n: 0.0,
        tire_stiffness_n_per_mm: 0.0,
        tire_dahl: false,
    };

    /// The plant with effects that ECU mode's targets name (`backlash_deg=1.5,coulomb_n=200`):
    /// 1.5 deg of play in
    /// the belt/nut at the wheel and 200 N of Coulomb friction at the rack. ECU mode's track
    /// target is measured on it, and the firmware's task tests run ECU mode against it.
    pub const PLAY_AND_FRICTION: PlantEffects = PlantEffects {
        belt_play_deg: 1.5,
        rack_coulomb_n: 200.0,
        ..PlantEffects::NONE
    };

    /// The keys of `--plant-effects`, with what each sets.
    pub const KEYS: [(&'static str, &'static str); 10] = [
        (
            "backlash_deg",
            "play in the belt/nut, full width, deg at the wheel",
        ),
        (
            "column_play_deg",
            "play between pinion and column encoder, deg at the wheel",
        ),
        ("coulomb_n", "Coulomb friction at the rack, N"),
        (
            "coulomb_creep_mm_s",
            "rack speed over which the rack friction builds up (tanh), mm/s; 0 = sharp",
        ),
        ("motor_coulomb_nm", "Coulomb friction at the motor, Nm"),
        (
            "motor_stribeck_nm",
            "static friction above Coulomb at the motor, Nm",
        ),
        ("stribeck_rad_s", "Stribeck velocity at the motor, rad/s"),
        (
            "tire_n",
            "tyre scrub: bristle's largest force at the rack, N",
        ),
        (
            "tire_n_per_mm",
            "tyre scrub: bristle's stiffness at the rack, N/mm",
        ),
        (
            "tire_dahl",
            "1: the tyre follows Dahl's law, not the elasto-plastic one",
        ),
    ];

    /// True when no effect is present: the plant is the linear one.
    pub fn is_none(&self) -> bool {
        let t = self;
        [
            t.belt_play_deg,
            t.column_play_deg,
            t.motor_coulomb_nm,
            t.motor_stribeck_nm,
            t.rack_coulomb_n,
            t.tire_force_n,
        ]
        .iter()
        .all(|v| *v == 0.0)
    }

    /// Parse `key=value[,key=value...]` (the `--plant-effects` syntax, keys in
    /// [`PlantEffects::KEYS`]). An empty string is no effect.
    pub fn parse(list: &str) -> Result<PlantEffects, EffectsError> {
        let mut fx = PlantEffects::NONE;
        for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
            let (key, value) = item
                .split_once('=')
                .ok_or_else(|| EffectsError::Syntax(item.to_string()))?;
            let (key, value) = (key.trim(), value.trim());
            if !PlantEffects::KEYS.iter().any(|(k, _)| *k == key) {
                return Err(EffectsError::UnknownKey(key.to_string()));
            }
            let v: f64 = value
                .parse()
                .ok()
                .filter(|v: &f64| v.is_finite() && *v >= 0.0)
                .ok_or_else(|| EffectsError::BadValue {
                    key: key.to_string(),
                    value: value.to_string(),
                })?;
            let slot = match key {
                "backlash_deg" => &mut fx.belt_play_deg,
                "column_play_deg" => &mut fx.column_play_deg,
                "coulomb_n" => &mut fx.rack_coulomb_n,
                "coulomb_creep_mm_s" => &mut fx.rack_creep_mm_s,
                "motor_coulomb_nm" => &mut fx.motor_coulomb_nm,
                "motor_stribeck_nm" => &mut fx.motor_stribeck_nm,
                "stribeck_rad_s" => &mut fx.stribeck_velocity_rad_s,
                "tire_n" => &mut fx.tire_force_n,
                "tire_n_per_mm" => &mut fx.tire_stiffness_n_per_mm,
                "tire_dahl" => {
                    fx.tire_dahl = v != 0.0;
                    continue;
                }
                other => return Err(EffectsError::UnknownKey(other.to_string())),
            };
            *slot = v;
        }
        if (fx.tire_force_n > 0.0) != (fx.tire_stiffness_n_per_mm > 0.0) {
            return Err(EffectsError::TireIncomplete);
        }
        Ok(fx)
    }
}

impl std::str::FromStr for PlantEffects {
    type Err = EffectsError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        PlantEffects::parse(s)
    }
}

impl std::fmt::Display for PlantEffects {
    /// The `--plant-effects` form of the effects present ("none" without any).
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let items = [
            ("backlash_deg", self.belt_play_deg),
            ("column_play_deg", self.column_play_deg),
            ("coulomb_n", self.rack_coulomb_n),
            ("coulomb_creep_mm_s", self.rack_creep_mm_s),
            ("motor_coulomb_nm", self.motor_coulomb_nm),
            ("motor_stribeck_nm", self.motor_stribeck_nm),
            ("stribeck_rad_s", self.stribeck_velocity_rad_s),
            ("tire_n", self.tire_force_n),
            ("tire_n_per_mm", self.tire_stiffness_n_per_mm),
        ];
        let mut present: Vec<String> = items
            .iter()
            .filter(|(_, v)| *v != 0.0)
            .map(|(k, v)| format!("{k}={v}"))
            .collect();
        if self.tire_dahl {
            present.push("tire_dahl=1".into());
        }
        if present.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&present.join(","))
        }
    }
}

/// Play (backlash) operator: the output follows the input only once the gap is taken up.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Play {
    half: f64,
    y: f64,
}

impl Play {
    pub(crate) fn new(width: f64, y0: f64) -> Self {
        Play {
            half: 0.5 * width.max(0.0),
            y: y0,
        }
    }
    pub(crate) fn step(&mut self, x: f64) -> f64 {
        self.y = self.y.clamp(x - self.half, x + self.half);
        self.y
    }
}

/// Tyre bristle at the rack: elasto-plastic (deflection follows the motion, clamped at
/// `f_max / k`) or Dahl's law (`dF = k dx (1 - F/f_max sgn dx)`, stepped per motion increment).
#[derive(Debug, Clone, Copy)]
pub(crate) struct Bristle {
    k: f64,
    z_max: f64,
    z: f64,
    x_last: f64,
    dahl: bool,
}

impl Bristle {
    pub(crate) fn new(f_max: f64, k_n_per_m: f64, x0: f64) -> Self {
        let on = f_max > 0.0 && k_n_per_m > 0.0;
        Bristle {
            k: if on { k_n_per_m } else { 0.0 },
            z_max: if on { f_max / k_n_per_m } else { 0.0 },
            z: 0.0,
            x_last: x0,
            dahl: false,
        }
    }

    /// The same bristle under Dahl's law.
    pub(crate) fn dahl(mut self) -> Self {
        self.dahl = true;
        self
    }
    /// Force opposing the motion, N.
    pub(crate) fn force(&mut self, x: f64) -> f64 {
        if self.k == 0.0 {
            return 0.0;
        }
        let dx = x - self.x_last;
        self.x_last = x;
        if self.dahl {
            // z = F / k: dz = dx (1 - z/z_max sgn dx); exact for the step's dx when the
            // motion does not reverse within it.
            let s = dx.signum();
            let target = s * self.z_max;
            self.z = target + (self.z - target) * (-dx.abs() / self.z_max).exp();
        } else {
            self.z = (self.z + dx).clamp(-self.z_max, self.z_max);
        }
        self.k * self.z
    }
}

/// Coulomb(+Stribeck) torque opposing `w`: saturated-linear around zero with a slope that one
/// explicit step of inertia `j` at step `dt` cannot overshoot (c dt / j <= 1/4). With a creep
/// speed `w_creep` above that slope's width it builds up smoothly instead, `tanh(w / w_creep)`
/// (0 = sharp).
fn friction(fc: f64, fs: f64, vs: f64, w_creep: f64, w: f64, j: f64, dt: f64) -> f64 {
    // Absent friction costs nothing: the simulation runs this twice per 50 us step.
    if fc == 0.0 && fs == 0.0 {
        return 0.0;
    }
    let level = if fs == 0.0 {
        fc
    } else {
        fc + fs * (-(w / vs).powi(2)).exp()
    };
    if level <= 0.0 {
        return 0.0;
    }
    let w_eps = 4.0 * level * dt / j;
    if w_creep > w_eps {
        -level * tanh_by_exp(w / w_creep)
    } else {
        -level * (w / w_eps).clamp(-1.0, 1.0)
    }
}

/// `tanh(x)` by one `exp`: the library's `tanh` goes through `expm1`, and the two took 15 % of
/// a diagnosis of a log with rack friction (`perf record` on `host-sim gap`; the friction runs
/// twice per 50 us step). Within 2.3e-16 of `f64::tanh` for every `x` (absolute: the force's
/// error is below a femtonewton), +-1 beyond 19, NaN for NaN.
fn tanh_by_exp(x: f64) -> f64 {
    let t = (-2.0 * x.abs()).exp();
    ((1.0 - t) / (1.0 + t)).copysign(x)
}

/// The paper's plant (eqs. 1-8) with [`PlantEffects`], one current-loop step at a time.
#[derive(Debug, Clone)]
pub struct EffectPlant {
    params: PlantParams,
    effects: PlantEffects,
    ad: [[f64; 7]; 7],
    /// Columns: voltage, torque at the motor, torque at the screw.
    bd: [[f64; 3]; 7],
    x: [f64; 7],
    dt_s: f64,
    /// Half the belt play at the nut, rad.
    belt_half_nut_rad: f64,
    column_play: Play,
    column_rad: f64,
    tire: Bristle,
}

impl EffectPlant {
    pub fn new(
        params: PlantParams,
        effects: PlantEffects,
        dt_s: f64,
    ) -> Result<EffectPlant, PlantError> {
        params.check(dt_s)?;
        let (a, b) = params.electromechanical_state_space();
        let mut aug = SMatrix::<f64, 10, 10>::zeros();
        aug.fixed_view_mut::<7, 7>(0, 0).copy_from(&(a * dt_s));
        for i in 0..7 {
            aug[(i, 7)] = b[i] * dt_s;
        }
        aug[(state::W_ROT, 8)] = dt_s / params.j_rot;
        aug[(state::W_BS, 9)] = dt_s / params.j_bs_equivalent();
        let e = aug.exp();
        let mut ad = [[0.0; 7]; 7];
        let mut bd = [[0.0; 3]; 7];
        for i in 0..7 {
            for j in 0..7 {
                ad[i][j] = e[(i, j)];
            }
            for j in 0..3 {
                bd[i][j] = e[(i, 7 + j)];
            }
        }
        let mut plant = EffectPlant {
            params,
            effects,
            ad,
            bd,
            x: [0.0; 7],
            dt_s,
            belt_half_nut_rad: 0.5 * effects.belt_play_deg.to_radians() / params.screw_to_pinion(),
            column_play: Play::new(0.0, 0.0),
            column_rad: 0.0,
            tire: Bristle::new(0.0, 0.0, 0.0),
        };
        plant.set_at_rest(0.0);
        Ok(plant)
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }
    pub fn effects(&self) -> &PlantEffects {
        &self.effects
    }
    pub fn state(&self) -> [f64; 7] {
        self.x
    }
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The pinion angle (delta_P), rad: where the column encoder would sit without play.
    pub fn pinion_rad(&self) -> f64 {
        self.x[state::THETA_BS] * self.params.screw_to_pinion()
    }

    /// The torques the effects add over the next step: (at the motor, at the screw), Nm.
    fn effect_torques(&mut self) -> (f64, f64) {
        let (p, fx, x, dt) = (&self.params, &self.effects, &self.x, self.dt_s);
        let tb = 1.0 / p.belt_reduction;
        let j_screw = p.j_bs_equivalent();
        let mut motor = friction(
            fx.motor_coulomb_nm,
            fx.motor_stribeck_nm,
            if fx.stribeck_velocity_rad_s > 0.0 {
                fx.stribeck_velocity_rad_s
            } else {
                1.0
            },
            0.0,
            x[state::W_ROT],
            p.j_rot,
            dt,
        );
        let mut screw = friction(
            fx.rack_coulomb_n * p.tau_bs,
            0.0,
            1.0,
            fx.rack_creep_mm_s * 1e-3 / p.tau_bs,
            x[state::W_BS],
            j_screw,
            dt,
        );
        screw -= self.tire.force(x[state::THETA_BS] * p.tau_bs) * p.tau_bs;
        if self.belt_half_nut_rad > 0.0 {
            // The linear model's belt pulls the nut with k_B s + beta_B s' (s = stretch at the
            // nut); with play it pulls only once the gap is taken up, with the stretch beyond
            // it. The difference is added at both ends (the motor sees it through the belt
            // ratio).
            let s = tb * x[state::THETA_ROT] - x[state::THETA_BS];
            let ds = tb * x[state::W_ROT] - x[state::W_BS];
            let h = self.belt_half_nut_rad;
            let actual = if s > h {
                p.k_b * (s - h) + p.beta_b * ds
            } else if s < -h {
                p.k_b * (s + h) + p.beta_b * ds
            } else {
                0.0
            };
            let correction = actual - (p.k_b * s + p.beta_b * ds);
            screw += correction;
            motor -= tb * correction;
        }
        (motor, screw)
    }
}

impl EffectPlant {
    /// One step with an external torque on the motor shaft besides the winding's (a test
    /// stand driving the rotor), Nm.
    pub fn step_driven(&mut self, voltage_v: f64, motor_torque_nm: f64) {
        let (t_motor, t_screw) = self.effect_torques();
        self.advance(voltage_v, t_motor + motor_torque_nm, t_screw);
    }

    fn advance(&mut self, voltage_v: f64, t_motor: f64, t_screw: f64) {
        // x' = Bd u + Ad x.
        let mut next = [0.0; 7];
        for (acc, b) in next.iter_mut().zip(self.bd.iter()) {
            *acc = b[0] * voltage_v + b[1] * t_motor + b[2] * t_screw;
        }
        self.x = crate::plant::add_ad_x(next, &self.ad, &self.x);
        self.column_rad = self.column_play.step(self.pinion_rad());
    }
}

impl Actuator for EffectPlant {
    fn step(&mut self, voltage_v: f64) {
        let (t_motor, t_screw) = self.effect_torques();
        self.advance(voltage_v, t_motor, t_screw);
    }

    fn current_a(&self) -> f64 {
        self.x[state::CURRENT]
    }

    fn motor_rad(&self) -> f64 {
        self.x[state::THETA_ROT]
    }

    fn motor_speed_rad_s(&self) -> f64 {
        self.x[state::W_ROT]
    }

    fn column_rad(&self) -> f64 {
        self.column_rad
    }

    fn set_at_rest(&mut self, column_rad: f64) {
        self.x = self.params.at_rest(column_rad);
        self.column_play = Play::new(self.effects.column_play_deg.to_radians(), column_rad);
        self.column_rad = column_rad;
        let rack = self.x[state::THETA_BS] * self.params.tau_bs;
        self.tire = Bristle::new(
            self.effects.tire_force_n,
            self.effects.tire_stiffness_n_per_mm * 1e3,
            rack,
        );
        if self.effects.tire_dahl {
            self.tire = self.tire.dahl();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::LinearPlant;

    #[test]
    fn tanh_by_exp_is_the_library_tanh_to_a_bit_of_one() {
        // Every scale the friction meets: speeds far below the creep speed to far above it.
        let mut worst: f64 = 0.0;
        for k in 0..200_000 {
            let x = -25.0 + 50.0 * k as f64 / 200_000.0;
            worst = worst.max((tanh_by_exp(x) - x.tanh()).abs());
        }
        for e in -300..2 {
            let x = 10f64.powi(e) * 1.37;
            for x in [x, -x] {
                worst = worst.max((tanh_by_exp(x) - x.tanh()).abs());
            }
        }
        assert!(worst <= 2.3e-16, "{worst:e}");
        assert_eq!(tanh_by_exp(f64::INFINITY), 1.0);
        assert_eq!(tanh_by_exp(f64::NEG_INFINITY), -1.0);
        assert_eq!(tanh_by_exp(40.0), 1.0);
        assert!(tanh_by_exp(f64::NAN).is_nan());
        assert_eq!(tanh_by_exp(0.0), 0.0);
    }

    #[test]
    fn without_effects_it_is_the_linear_plant() {
        let dt = 5e-5;
        let mut a = LinearPlant::new(PlantParams::PAPER, dt).unwrap();
        let mut b = EffectPlant::new(PlantParams::PAPER, PlantEffects::NONE, dt).unwrap();
        a.set_at_rest(0.1);
        b.set_at_rest(0.1);
        for k in 0..4000 {
            let v = 6.0 * (k as f64 * 0.003).sin();
            a.step(v);
            b.step(v);
        }
        for (x, y) in a.state().iter().zip(b.state().iter()) {
            assert!((x - y).abs() <= 1e-9 * (1.0 + x.abs()), "{x} vs {y}");
        }
        assert!((a.column_rad() - b.column_rad()).abs() < 1e-12);
    }

    #[test]
    fn belt_play_lets_the_motor_turn_without_the_rack() {
        // 2 deg of play at the wheel (+-1 deg): a stiff servo turns the motor by what 0.8 deg
        // at the pinion would take. With play the pinion stays (the gap is not taken up);
        // without it, the pinion follows through the belt.
        let dt = 5e-5;
        let p = PlantParams::PAPER;
        let target = 0.8f64.to_radians() * p.motor_per_pinion();
        let pinion_after = |fx: PlantEffects| {
            let mut plant = EffectPlant::new(p, fx, dt).unwrap();
            plant.set_at_rest(0.0);
            let wn = std::f64::consts::TAU * 50.0;
            for _ in 0..40_000 {
                let x = plant.state();
                let torque = p.j_rot
                    * (wn * wn * (target - x[state::THETA_ROT]) - 2.0 * wn * x[state::W_ROT]);
                plant.step_driven(p.ke * x[state::W_ROT], torque);
            }
            plant.pinion_rad().to_degrees()
        };
        let with_play = pinion_after(PlantEffects::parse("backlash_deg=2").unwrap());
        let rigid = pinion_after(PlantEffects::NONE);
        assert!((rigid - 0.8).abs() < 0.1, "rigid pinion at {rigid} deg");
        assert!(
            with_play.abs() < 0.01,
            "pinion moved {with_play} deg inside the play"
        );
        // Past the play it moves by the excess: 0.8 deg of motion on a +-0.5 deg gap.
        let half = pinion_after(PlantEffects::parse("backlash_deg=1").unwrap());
        assert!((half - 0.3).abs() < 0.05, "pinion at {half} deg, want 0.3");
    }

    #[test]
    fn column_play_holds_the_encoder_until_the_gap_is_taken_up() {
        let fx = PlantEffects::parse("column_play_deg=1").unwrap();
        let mut p = EffectPlant::new(PlantParams::PAPER, fx, 5e-5).unwrap();
        p.set_at_rest(0.0);
        let mut worst: f64 = 0.0;
        for k in 0..20_000 {
            p.step(if (k / 5000) % 2 == 0 { 4.0 } else { -4.0 });
            let lag = (p.pinion_rad() - p.column_rad()).to_degrees();
            assert!(
                lag.abs() <= 0.5 + 1e-9,
                "lag {lag} deg beyond half the play"
            );
            worst = worst.max(lag.abs());
        }
        assert!(worst > 0.49, "the play never opened: {worst} deg");
    }

    #[test]
    fn rack_friction_holds_a_small_push() {
        // 200 N at the rack is 0.064 Nm at the screw, 0.032 Nm at the motor through the belt:
        // 0.3 A of torque (kt 52.5 mNm/A) cannot move it; without friction it moves.
        let drift = |fx: PlantEffects| {
            let mut p = EffectPlant::new(PlantParams::PAPER, fx, 5e-5).unwrap();
            p.set_at_rest(0.0);
            for _ in 0..20_000 {
                // Hold about 0.3 A: a current controller's job, here a crude voltage law.
                let v = 0.293 * 0.3 + 0.0525 * p.state()[state::W_ROT];
                p.step(v);
            }
            p.pinion_rad().to_degrees().abs()
        };
        let held = drift(PlantEffects::parse("coulomb_n=200").unwrap());
        let free = drift(PlantEffects::NONE);
        assert!(free > 1.0, "free pinion moved only {free} deg");
        assert!(held < 0.05 * free, "held {held} deg vs free {free} deg");
        // With a creep speed the same friction only slows the push (about 100 N against 200:
        // tanh(v / 2 mm/s) = 1/2 at 1.1 mm/s), so the rack creeps where the sharp one held.
        let creeping = drift(PlantEffects::parse("coulomb_n=200,coulomb_creep_mm_s=2").unwrap());
        assert!(
            creeping > 10.0 * held && creeping < 0.9 * free,
            "creeping {creeping} deg, held {held} deg, free {free} deg"
        );
    }

    #[test]
    fn a_creep_speed_below_the_stable_slope_is_the_sharp_friction() {
        // 1e-6 mm/s is far below what one 50 us step can resolve: the same torque as none.
        let run = |fx: PlantEffects| {
            let mut p = EffectPlant::new(PlantParams::PAPER, fx, 5e-5).unwrap();
            p.set_at_rest(0.0);
            for k in 0..4000 {
                p.step(if (k / 1000) % 2 == 0 { 3.0 } else { -3.0 });
            }
            p.state()
        };
        let sharp = run(PlantEffects::parse("coulomb_n=300").unwrap());
        let tiny = run(PlantEffects::parse("coulomb_n=300,coulomb_creep_mm_s=1e-6").unwrap());
        assert_eq!(sharp, tiny);
        let fx = PlantEffects::parse("coulomb_n=300,coulomb_creep_mm_s=1.5").unwrap();
        assert_eq!(fx.to_string(), "coulomb_n=300,coulomb_creep_mm_s=1.5");
    }

    #[test]
    fn dahl_tyre_approaches_its_force_smoothly_and_the_bristle_has_a_corner() {
        // 1000 N, 500 N/mm: z_max = 2 mm. After 1 mm of travel from rest the elasto-plastic
        // bristle is linear (500 N); Dahl's is below it (1000 (1 - e^-0.5) = 393 N); after
        // 10 mm both are at the largest force, within 1 %.
        let travel = |dahl: bool, mm: f64| {
            let mut b = Bristle::new(1000.0, 500e3, 0.0);
            if dahl {
                b = b.dahl();
            }
            let mut f = 0.0;
            for k in 1..=1000 {
                f = b.force(mm * 1e-3 * k as f64 / 1000.0);
            }
            f
        };
        assert!((travel(false, 1.0) - 500.0).abs() < 1e-6);
        assert!(
            (travel(true, 1.0) - 393.5).abs() < 0.5,
            "{}",
            travel(true, 1.0)
        );
        assert!((travel(true, 10.0) - 1000.0).abs() < 10.0);
        assert!((travel(false, 10.0) - 1000.0).abs() < 1e-6);
    }

    #[test]
    fn bad_effect_lists_are_refused_with_the_reason() {
        for (list, want) in [
            ("backlash_deg", "expected KEY=VALUE"),
            ("backlash=1", "unknown effect `backlash`"),
            ("coulomb_n=-5", "finite number >= 0"),
            ("coulomb_n=nan", "finite number >= 0"),
            ("coulomb_n=1e400", "finite number >= 0"),
            ("tire_n=100", "go together"),
        ] {
            let err = PlantEffects::parse(list).unwrap_err().to_string();
            assert!(err.contains(want), "{list}: {err}");
        }
        // A bad value: the key and the value named apart, once each, with what the key takes
        // (the caller quotes the list itself, so the item again would say it twice).
        let err = PlantEffects::parse("backlash_deg=nan")
            .unwrap_err()
            .to_string();
        assert!(!err.contains("backlash_deg=nan"), "{err}");
        assert_eq!(err.matches("backlash_deg").count(), 1, "{err}");
        for part in ["`nan`", "finite number >= 0", "deg at the wheel"] {
            assert!(err.contains(part), "{part}: {err}");
        }
        // An unknown key is named as unknown, whatever its value.
        let err = PlantEffects::parse("backlash=nan").unwrap_err().to_string();
        assert!(err.contains("unknown effect `backlash`"), "{err}");
        let fx = PlantEffects::parse(" backlash_deg=1.5 , coulomb_n=200 ").unwrap();
        assert_eq!(fx.belt_play_deg, 1.5);
        assert_eq!(fx.rack_coulomb_n, 200.0);
        assert_eq!(fx.to_string(), "backlash_deg=1.5,coulomb_n=200");
        assert_eq!(PlantEffects::parse(&fx.to_string()).unwrap(), fx);
        assert!(PlantEffects::parse("").unwrap().is_none());
    }
}

//! The nominal models of a rig with the candidate effects added, simulated in closed loop from
//! a log's reference: the paper's actuator under the firmware's own cascade (paper mode), and
//! the EMPS axis under its P-PD controller.
//!
//! Each effect is zero-sized by default (`Effects::default()` is the nominal model). The
//! nonlinear effects are written so that they stay stable at the loop rates: Coulomb friction
//! is a saturated-linear torque whose slope is bounded by the step (a stick-aware model for the
//! 1-DOF EMPS axis), the tyre is an elasto-plastic bristle whose deflection is clamped, backlash
//! is a play operator on the measured angle, and the delay shifts the reference.

use super::Record;
use super::rig::{EmpsModel, PaperModel};
use crate::plant::{PlantParams, state};
use nalgebra::SMatrix;
use steering_ecu::gearing::Gearing;
use steering_ecu::paper_mode::{
    CURRENT_LOOP_HZ, CURRENT_TICKS_PER_POSITION_TICK, Cascade, POSITION_TICKS_PER_REFERENCE,
    REFERENCE_HZ,
};
use steering_ecu::sensors::{ColumnEncoder, hall_from_motor, motor_from_hall};
use steering_ecu::units::{Amps, SteeringDeg, Volts};

/// The candidate effects, each with its size; zero means absent.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Effects {
    /// Dead band between the pinion and the column encoder, full width, in output units
    /// (deg at the wheel for the paper rig, m for EMPS).
    pub backlash: f64,
    /// Coulomb friction: torque at the motor, Nm (paper rig) or force at the load, N (EMPS).
    pub coulomb: f64,
    /// Extra static (Stribeck) friction above `coulomb` at standstill, same unit.
    pub stribeck: f64,
    /// Stribeck velocity, rad/s at the motor or m/s at the load (0 = 1 rad/s, 1 mm/s).
    pub stribeck_velocity: f64,
    /// Viscous coefficient replacing the nominal one (EMPS only, N s/m; NaN = nominal).
    pub viscous_override: f64,
    /// Transport delay of the reference, s.
    pub delay_s: f64,
    /// Tyre scrub: largest force of the bristle at the rack (N) / at the load (N).
    pub tire_force_n: f64,
    /// Tyre scrub: bristle stiffness, N/mm at the rack (or load).
    pub tire_stiffness_n_per_mm: f64,
    /// Supply voltage replacing the rig's (paper rig only, V; 0 = nominal).
    pub supply_v: f64,
    /// Coulomb friction at the rack, N (paper rig only).
    pub rack_coulomb_n: f64,
}

impl Effects {
    pub fn nominal() -> Self {
        Effects {
            viscous_override: f64::NAN,
            ..Effects::default()
        }
    }
}

/// What one simulation gives on the record's time grid.
#[derive(Debug, Clone, Default)]
pub struct SimOut {
    pub output: Vec<f64>,
    pub effort: Vec<f64>,
    /// Motor angle in output units through the rigid gearing (paper rig), for the segment
    /// analysis; empty for rigs without it.
    pub motor: Vec<f64>,
}

/// The reference delayed by `delay_s`, linearly interpolated on its own grid of step `dt`.
fn delayed(reference: &[f64], delay_s: f64, dt: f64) -> Vec<f64> {
    if delay_s <= 0.0 || reference.is_empty() {
        return reference.to_vec();
    }
    let shift = delay_s / dt;
    let whole = shift.floor() as usize;
    let frac = shift - whole as f64;
    (0..reference.len())
        .map(|k| {
            let a = reference[k.saturating_sub(whole)];
            let b = reference[k.saturating_sub(whole + 1)];
            a + frac * (b - a)
        })
        .collect()
}

/// Play (backlash) operator: the output follows the input only once the gap is taken up.
#[derive(Debug, Clone, Copy)]
struct Play {
    half: f64,
    y: f64,
}

impl Play {
    fn new(width: f64, y0: f64) -> Self {
        Play {
            half: 0.5 * width.max(0.0),
            y: y0,
        }
    }
    fn step(&mut self, x: f64) -> f64 {
        self.y = self.y.clamp(x - self.half, x + self.half);
        self.y
    }
}

/// Elasto-plastic bristle: deflection follows the motion, clamped at `f_max / k`.
#[derive(Debug, Clone, Copy)]
struct Bristle {
    k: f64,
    z_max: f64,
    z: f64,
    x_last: f64,
}

impl Bristle {
    fn new(f_max: f64, k_n_per_m: f64, x0: f64) -> Self {
        let on = f_max > 0.0 && k_n_per_m > 0.0;
        Bristle {
            k: if on { k_n_per_m } else { 0.0 },
            z_max: if on { f_max / k_n_per_m } else { 0.0 },
            z: 0.0,
            x_last: x0,
        }
    }
    /// Force opposing the motion, N.
    fn force(&mut self, x: f64) -> f64 {
        if self.k == 0.0 {
            return 0.0;
        }
        self.z = (self.z + x - self.x_last).clamp(-self.z_max, self.z_max);
        self.x_last = x;
        self.k * self.z
    }
}

/// The paper's plant with two torque inputs added (motor shaft, ball screw), discretised
/// exactly for the current-loop step like [`crate::plant::LinearPlant`].
#[derive(Debug, Clone)]
pub struct EffectPlant {
    params: PlantParams,
    ad: [[f64; 7]; 7],
    /// Columns: voltage, torque at the motor, torque at the screw.
    bd: [[f64; 3]; 7],
    x: [f64; 7],
    dt_s: f64,
}

impl EffectPlant {
    pub fn new(params: PlantParams, dt_s: f64) -> Self {
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
        EffectPlant {
            params,
            ad,
            bd,
            x: [0.0; 7],
            dt_s,
        }
    }

    pub fn set_at_rest(&mut self, column_rad: f64) {
        self.x = self.params.at_rest(column_rad);
    }

    pub fn step(&mut self, voltage_v: f64, motor_torque: f64, screw_torque: f64) {
        let x = self.x;
        for i in 0..7 {
            let b = &self.bd[i];
            let mut acc = b[0] * voltage_v + b[1] * motor_torque + b[2] * screw_torque;
            for (a, xj) in self.ad[i].iter().zip(x.iter()) {
                acc += a * xj;
            }
            self.x[i] = acc;
        }
    }

    pub fn x(&self) -> &[f64; 7] {
        &self.x
    }
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }
    pub fn column_rad(&self) -> f64 {
        self.x[state::THETA_BS] * self.params.screw_to_pinion()
    }
}

/// Smooth-enough Coulomb(+Stribeck) torque opposing `w`: saturated-linear around zero with a
/// slope that one explicit step of inertia `j` at step `dt` cannot overshoot (c dt / j <= 1/4).
fn friction(fc: f64, fs: f64, vs: f64, w: f64, j: f64, dt: f64) -> f64 {
    let level = fc + fs * (-(w / vs).powi(2)).exp();
    if level <= 0.0 {
        return 0.0;
    }
    let w_eps = 4.0 * level * dt / j;
    -level * (w / w_eps).clamp(-1.0, 1.0)
}

/// The paper's actuator in paper mode with `effects`, from `rec.reference` (100 Hz, deg).
/// The record's grid is the 100 Hz reference grid; angles are taken at the end of each 10 ms
/// period, the current is averaged over it (the log's semantics, [`super::Record`]).
pub fn simulate_paper(m: &PaperModel, rec: &Record, fx: &Effects) -> SimOut {
    let p = m.plant;
    let dt = 1.0 / CURRENT_LOOP_HZ as f64;
    let reference = delayed(&rec.reference, fx.delay_s, 1.0 / REFERENCE_HZ as f64);
    let mut out = SimOut {
        output: Vec::with_capacity(reference.len()),
        effort: Vec::with_capacity(reference.len()),
        motor: Vec::with_capacity(reference.len()),
    };
    let Some(&first) = reference.first() else {
        return out;
    };
    let gains = match m.gains.to_epos().to_si() {
        Ok(g) => g,
        Err(_) => return out,
    };
    let Some(gearing) = Gearing::new(p.belt_reduction as f32, p.tau_bs as f32, p.tau_p as f32)
    else {
        return out;
    };
    let mut cascade = Cascade::new(&gains, gearing);
    cascade.set_winding(p.ra as f32, p.la as f32);
    let supply = if fx.supply_v > 0.0 {
        fx.supply_v
    } else {
        m.supply_v
    };
    cascade.set_voltage_limit(Volts(supply as f32));
    let mut plant = EffectPlant::new(p, dt);
    plant.set_at_rest(first.to_radians());
    let x0 = plant.x();
    cascade.reset(hall_from_motor(x0[state::THETA_ROT]));
    let encoder = ColumnEncoder { zero_raw: 0 };
    let mut play = Play::new(fx.backlash.to_radians(), plant.column_rad());
    let rack0 = x0[state::THETA_BS] * p.tau_bs;
    let mut bristle = Bristle::new(fx.tire_force_n, fx.tire_stiffness_n_per_mm * 1e3, rack0);
    let vs = if fx.stribeck_velocity > 0.0 {
        fx.stribeck_velocity
    } else {
        1.0
    };
    let per_motor = p.motor_per_pinion();
    let j_screw = p.j_bs_equivalent();
    let n_cur = (POSITION_TICKS_PER_REFERENCE * CURRENT_TICKS_PER_POSITION_TICK) as f64;
    for &sample in &reference {
        let _ = cascade.push_reference(SteeringDeg(sample as f32));
        let mut i_acc = 0.0;
        let mut col = plant.column_rad();
        for _ in 0..POSITION_TICKS_PER_REFERENCE {
            let x = plant.x();
            let hall = hall_from_motor(x[state::THETA_ROT]);
            cascade.position_step(hall);
            for _ in 0..CURRENT_TICKS_PER_POSITION_TICK {
                let x = plant.x();
                let i_meas = x[state::CURRENT];
                let v = cascade.current_step(Amps(i_meas as f32)).voltage.0 as f64;
                let t_motor = friction(fx.coulomb, fx.stribeck, vs, x[state::W_ROT], p.j_rot, dt);
                let rack = x[state::THETA_BS] * p.tau_bs;
                let t_rack_friction = friction(
                    fx.rack_coulomb_n * p.tau_bs,
                    0.0,
                    1.0,
                    x[state::W_BS],
                    j_screw,
                    dt,
                );
                let t_screw = -bristle.force(rack) * p.tau_bs + t_rack_friction;
                plant.step(v, t_motor, t_screw);
                i_acc += plant.x()[state::CURRENT];
            }
            // The play follows the column at the position rate, as the encoder would see it.
            col = play.step(plant.column_rad());
        }
        // The log's semantics: angles at the instant the period ends, the current's mean
        // over the period.
        let sw = encoder.angle(encoder.raw_from_angle(col));
        let hall_end = hall_from_motor(plant.x()[state::THETA_ROT]);
        out.output.push((sw.0 as f64).to_degrees());
        out.effort.push(i_acc / n_cur);
        out.motor
            .push((motor_from_hall(hall_end).0 as f64 / per_motor).to_degrees());
    }
    out
}

/// Replays the motor -> steering segment (belt, screw, rack, column, encoder) from a motor
/// angle: the record's `motor` signal (output units through the rigid gearing) drives the
/// plant's rotor through a stiff virtual servo (300 Hz, critically damped, on the rotor
/// inertia; the winding's back-EMF is cancelled so it carries no current), and the chain
/// downstream responds with its own dynamics and the effects of `fx` (backlash, tyre). The
/// result is the column encoder's reading at the end of each step; `None` without a motor
/// signal. Against the measured output it tells how much of the gap lies after the motor.
pub fn replay_downstream(m: &PaperModel, rec: &Record, fx: &Effects) -> Option<Vec<f64>> {
    let motor = rec.motor.as_ref()?;
    let p = m.plant;
    let dt = 1.0 / CURRENT_LOOP_HZ as f64;
    let per_motor = p.motor_per_pinion();
    let rad = |deg: f64| deg.to_radians() * per_motor;
    let first = *motor.first()?;
    let mut plant = EffectPlant::new(p, dt);
    plant.set_at_rest(first.to_radians());
    let encoder = ColumnEncoder { zero_raw: 0 };
    let mut play = Play::new(fx.backlash.to_radians(), plant.column_rad());
    let rack0 = plant.x()[state::THETA_BS] * p.tau_bs;
    let mut bristle = Bristle::new(fx.tire_force_n, fx.tire_stiffness_n_per_mm * 1e3, rack0);
    let wn = std::f64::consts::TAU * 300.0;
    let substeps = ((rec.dt / dt).round() as usize).max(1);
    let mut out = Vec::with_capacity(motor.len());
    for k in 0..motor.len() {
        // The record holds the angle at the end of each step: a line from the last one.
        let here = rad(motor[k.saturating_sub(1)]);
        let next = rad(motor[k]);
        let w_ref = (next - here) / rec.dt;
        let mut col = plant.column_rad();
        for j in 0..substeps {
            let x = *plant.x();
            let theta_ref = here + w_ref * ((j + 1) as f64 * dt);
            let torque = p.j_rot
                * (wn * wn * (theta_ref - x[state::THETA_ROT])
                    + 2.0 * wn * (w_ref - x[state::W_ROT]));
            let rack = x[state::THETA_BS] * p.tau_bs;
            let t_screw = -bristle.force(rack) * p.tau_bs;
            plant.step(p.ke * x[state::W_ROT], torque, t_screw);
            col = play.step(plant.column_rad());
        }
        out.push((encoder.angle(encoder.raw_from_angle(col)).0 as f64).to_degrees());
    }
    Some(out)
}

/// The EMPS axis under its P-PD controller (`host-sim/data/emps/README.md`), on the record's
/// 1 kHz grid: `c(k) = kv (kp (qg(k) - q(k)) - dq(k))`, `vir(k) = sat(c(k-1)) + pulse(k)`,
/// `M q'' = gtau vir - Fv q' - Fc sign(q') - offset`, integrated with `substeps` per sample.
pub fn simulate_emps(m: &EmpsModel, rec: &Record, fx: &Effects) -> SimOut {
    let n = rec.reference.len();
    let mut out = SimOut {
        output: Vec::with_capacity(n),
        effort: Vec::with_capacity(n),
        motor: Vec::new(),
    };
    if n == 0 {
        return out;
    }
    let ts = m.ts_s;
    let reference = delayed(&rec.reference, fx.delay_s, ts);
    let sub = m.substeps.max(1);
    let h = ts / sub as f64;
    let fv = if fx.viscous_override.is_finite() {
        fx.viscous_override
    } else {
        m.fv
    };
    let fc = fx.coulomb.max(0.0);
    let fs = fx.stribeck.max(0.0);
    let vs = if fx.stribeck_velocity > 0.0 {
        fx.stribeck_velocity
    } else {
        1e-3
    };
    // Start at the first measured position, at rest.
    let mut q = rec.output.first().copied().unwrap_or(reference[0]);
    let mut v = 0.0;
    let mut play = Play::new(fx.backlash, q);
    let mut bristle = Bristle::new(fx.tire_force_n, fx.tire_stiffness_n_per_mm * 1e3, q);
    let mut q_prev = q;
    let mut qf_prev = q;
    let mut c_prev: f64 = 0.0;
    for k in 0..n {
        let qm = play.step(q);
        let qf = 0.5 * (q + q_prev);
        let dq = (qf - qf_prev) / ts;
        let c = m.kv * (m.kp * (reference[k] - q) - dq);
        let pulse = rec.disturbance.as_ref().map_or(0.0, |d| d[k]);
        let vir = c_prev.clamp(-m.vsat, m.vsat) + pulse;
        out.output.push(qm);
        out.effort.push(vir);
        c_prev = c;
        q_prev = q;
        qf_prev = qf;
        let drive = m.gtau * vir - m.offset;
        for _ in 0..sub {
            let level = fc + fs * (-(v / vs).powi(2)).exp();
            let f_tire = bristle.force(q);
            let f_free = drive - fv * v - f_tire;
            // Stick-aware Coulomb: at rest, the friction holds whatever it can.
            if v == 0.0 && f_free.abs() <= level {
                continue;
            }
            let dir = if v != 0.0 {
                v.signum()
            } else {
                f_free.signum()
            };
            let a = (f_free - level * dir) / m.mass;
            let v_new = v + a * h;
            if level > 0.0 && v != 0.0 && v_new.signum() != v.signum() {
                // Crossed zero velocity within the step: stop there.
                q += v * h * 0.5;
                v = 0.0;
            } else {
                q += 0.5 * (v + v_new) * h;
                v = v_new;
            }
        }
    }
    out
}

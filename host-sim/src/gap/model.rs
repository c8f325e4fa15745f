//! The nominal models of a rig with the candidate effects added, simulated in closed loop from
//! a log's reference: the paper's actuator under the firmware's own cascade (paper mode), the
//! EMPS axis under its P-PD controller, and the BAM XL330 servo pendulum under its firmware's
//! P controller.
//!
//! Each effect is zero-sized by default (`Effects::default()` is the nominal model). The
//! nonlinear effects are written so that they stay stable at the loop rates: Coulomb friction
//! is a saturated-linear torque whose slope is bounded by the step (a stick-aware model for the
//! 1-DOF EMPS axis), the tyre is an elasto-plastic bristle whose deflection is clamped, backlash
//! is a play operator on the measured angle, and the delay shifts the reference.

use super::Record;
use super::rig::{BamModel, CarDrive, DriveCurrent, EmpsModel, PaperModel};
use crate::effect_plant::{Bristle, EffectPlant, PlantEffects, Play};
use crate::epos4_sim::DriveLoop;
use crate::plant::{Actuator, state};
use crate::sim::Controller;
use crate::sim::{self, RunConfig};
use steering_ecu::canopen::epos4::PositionScale;
use steering_ecu::ecu::Ecu;
use steering_ecu::ecu_mode::{ColumnShaper, EcuTuning};
use steering_ecu::enable_ramp::EnableRamp;
use steering_ecu::gearing::Gearing;
use steering_ecu::paper_mode::{
    CURRENT_LOOP_HZ, POSITION_LOOP_HZ, POSITION_TICKS_PER_REFERENCE, REFERENCE_HZ,
};
use steering_ecu::sensors::ColumnEncoder;
use steering_ecu::sensors::HALL_COUNTS_PER_REV;
use steering_ecu::units::{SteeringDeg, SteeringRad};

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
    /// Transport delay of the reference, s: its frames reach the ECU this much late, and the
    /// ECU takes each when it arrives (paper rig: whole periods, then the tick it lands on).
    /// A delay of every measured signal alike is the same thing to a log of a time-invariant
    /// loop (each logged signal is the undelayed one shifted by it), so this one parameter
    /// stands for both places.
    pub delay_s: f64,
    /// The log's stamps lag the instants its rows were sampled at by this much, s: every
    /// logged signal trails the reference by it, taken as the reference later by as much,
    /// linearly interpolated between its samples (a clock's offset, no frame arriving late).
    pub log_lag_s: f64,
    /// The measured effort (current) reaches the log this much later than the angles, s: a
    /// drive's averaged current reported once per SYNC and forwarded a period later.
    pub effort_delay_s: f64,
    /// Tyre scrub: largest force of the bristle at the rack (N) / at the load (N).
    pub tire_force_n: f64,
    /// Tyre scrub: bristle stiffness, N/mm at the rack (or load).
    pub tire_stiffness_n_per_mm: f64,
    /// Supply voltage replacing the rig's (paper rig only, V; 0 = nominal).
    pub supply_v: f64,
    /// Coulomb friction at the rack, N (paper rig only).
    pub rack_coulomb_n: f64,
    /// Rack speed over which that friction builds up (tanh), mm/s; 0 = sharp.
    pub rack_creep_mm_s: f64,
    /// Play in the belt/nut, full width, deg at the wheel (paper rig only).
    pub belt_play: f64,
    /// The tyre follows Dahl's law instead of the elasto-plastic bristle (paper rig only).
    pub tire_dahl: bool,
}

impl Effects {
    pub fn nominal() -> Self {
        Effects {
            viscous_override: f64::NAN,
            ..Effects::default()
        }
    }

    /// These effects on a log whose stamps lag the instants its rows were sampled at by
    /// `lag_s`: the model takes that as a reference later by as much (every logged signal
    /// trails it), on top of any delay the effects hold.
    pub fn with_log_lag(mut self, lag_s: f64) -> Effects {
        self.log_lag_s += lag_s;
        self
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

impl SimOut {
    /// `rec` with this simulation's columns in place of the log's: the model's run written as
    /// the log is (its grid, its reference, its readout).
    pub fn as_log(&self, rec: &Record) -> Record {
        Record {
            output: self.output.clone(),
            effort: self.effort.clone(),
            motor: (!self.motor.is_empty()).then(|| self.motor.clone()),
            ..rec.clone()
        }
    }
}

/// The reference `rows` samples later, the first sample held before it.
pub(crate) fn held_later(reference: &[f64], rows: usize) -> Vec<f64> {
    (0..reference.len())
        .map(|k| reference[k.saturating_sub(rows)])
        .collect()
}

/// The reference delayed by `delay_s`, linearly interpolated on its own grid of step `dt`.
pub(crate) fn delayed(reference: &[f64], delay_s: f64, dt: f64) -> Vec<f64> {
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

impl Effects {
    /// The effects that live in the paper actuator, as the effect plant takes them (the delay
    /// and the supply are the loop's, not the plant's).
    pub fn plant_effects(&self) -> PlantEffects {
        PlantEffects {
            belt_play_deg: self.belt_play,
            column_play_deg: self.backlash,
            motor_coulomb_nm: self.coulomb,
            motor_stribeck_nm: self.stribeck,
            stribeck_velocity_rad_s: self.stribeck_velocity,
            rack_coulomb_n: self.rack_coulomb_n,
            rack_creep_mm_s: self.rack_creep_mm_s,
            tire_force_n: self.tire_force_n,
            tire_stiffness_n_per_mm: self.tire_stiffness_n_per_mm,
            tire_dahl: self.tire_dahl,
        }
    }
}

/// The paper's actuator in paper mode with `effects`, from `rec.reference` (100 Hz, deg): the
/// closed loop of `sim::run` (the firmware's cascade, Hall and encoder quantisation) around the
/// effect plant, logged at 100 Hz. The record's grid is the 100 Hz reference grid, and the log
/// has its semantics ([`super::Record`]): angles at the end of each 10 ms period, the current
/// averaged over it. An unusable model gives an empty output (the caller's cost is then NaN).
pub fn simulate_paper(m: &PaperModel, rec: &Record, fx: &Effects) -> SimOut {
    if m.drive == CarDrive::Epos4 {
        return simulate_epos4(m, rec, fx);
    }
    let p = m.plant;
    // A reference late by `delay_s` reaches the ECU that much after the car's own
    // `push_tick`, and the ECU takes it when it arrives: whole periods of the reference, then
    // the position-loop tick it is pushed at (a held reference whose steps come late, never a
    // blend of two samples).
    let ticks = (fx.delay_s.max(0.0) * POSITION_LOOP_HZ as f64).round();
    let ticks = if ticks.is_finite() { ticks as u64 } else { 0 };
    let ticks = ticks.saturating_add(u64::from(m.push_tick));
    let per_period = u64::from(POSITION_TICKS_PER_REFERENCE);
    let whole = usize::try_from(ticks / per_period).unwrap_or(usize::MAX);
    let reference = delayed(
        &held_later(&rec.reference, whole),
        fx.log_lag_s,
        1.0 / REFERENCE_HZ as f64,
    );
    let cfg = RunConfig {
        reference_push_tick: (ticks % per_period) as u32,
        controller: m.controller,
        plant: p,
        gains: m.gains,
        supply_v: if fx.supply_v > 0.0 {
            fx.supply_v
        } else {
            m.supply_v
        },
        log_rate_hz: REFERENCE_HZ,
        effects: fx.plant_effects(),
        ..RunConfig::default()
    };
    let Ok(run) = sim::run(&reference, &cfg) else {
        return SimOut::default();
    };
    let per_motor = p.motor_per_pinion();
    let log = run.log;
    SimOut {
        output: log.sw_deg,
        effort: log.current_a,
        motor: log
            .motor_rad
            .iter()
            .map(|m| (m / per_motor).to_degrees())
            .collect(),
    }
}

/// Where an EPOS4 car latches each reference: `whole_periods` rows after its own, at
/// `sync_tick` (1..=ticks per period) current-loop ticks into that period.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Epos4Latch {
    whole_periods: usize,
    sync_tick: u64,
}

impl Epos4Latch {
    /// The latch `latency_s` after the push, on the grid of `dt` ticks, at least one tick.
    fn new(latency_s: f64, dt: f64, ticks_per_period: u64) -> Epos4Latch {
        let ticks = (latency_s / dt).round();
        // `as` saturates a NaN to 0 and a huge value to u64::MAX; the max keeps one tick.
        let ticks = (if ticks.is_finite() { ticks as u64 } else { 1 }).max(1);
        let tpp = ticks_per_period.max(1);
        let whole = (ticks - 1) / tpp;
        Epos4Latch {
            whole_periods: usize::try_from(whole).unwrap_or(usize::MAX),
            sync_tick: ticks - whole * tpp,
        }
    }
}

/// The paper's actuator behind an EPOS4 in CSP, from `rec.reference`: the chain the firmware's
/// EPOS4 build runs and `steer-can convert` logs, on the drive's own loop ([`DriveLoop`], the
/// one the simulated EPOS4 runs).
///
/// ```text
///  row k's reference --(ECU, when it arrives: paper: the angle at the motor; ecu: the column
///                       shaper on the newest column sample)--> CSP target, whole increments
///  SYNC, `sync_after_push_s` later: the drive latches it (interpolated over one period) and
///                       samples its position (increments) and current for TPDO1 / TPDO2
///                       (a delay moves the latch: whole periods later, then the SYNC's tick)
///  row k, as the log's readout (`m.epos4.readout`) reads it: convert's, the column at
///         push + 10 ms, the motor angle interpolated between the SYNC samples at push + 10 ms,
///         the current interpolated between them at push + 5 ms (logbuild's reading); a
///         team's logger may read the current at the row's end and hold an older column
/// ```
pub fn simulate_epos4(m: &PaperModel, rec: &Record, fx: &Effects) -> SimOut {
    epos4_samples(m, rec, fx).read(m.epos4.readout)
}

/// The largest drift of an EPOS4 car's SYNC grid the model takes, s per s (1 %: an ECU on
/// its internal RC oscillator; a crystal is off by 1e-4 at most).
pub const MAX_SYNC_DRIFT: f64 = 0.01;

/// What the EPOS4 model's run gives before a log's readout reads it into rows.
#[derive(Debug, Clone, Default)]
pub struct Epos4Samples {
    /// The SYNCs' instants (s from the first row's period start), the position (output units)
    /// and the current the drive sampled there.
    at: Vec<f64>,
    motor: Vec<f64>,
    current: Vec<f64>,
    /// The column at each row's end, every 1 ms from the start (the first at 1 ms), and,
    /// for convert's readout, the encoder's reading at the end of every current-loop tick
    /// (`tick` s): convert's line between the status frames' samples takes the encoder's own
    /// quantised sample of the tick they were read at, not a line between samples (a line
    /// between samples 1 ms apart moved the column of a 10 Hz sweep by a count, where the
    /// ECU sent the count it read). Empty where no readout asks for it (it is 20 values a
    /// millisecond).
    column: Vec<f64>,
    column_ms: Vec<f64>,
    column_ticks: Vec<f32>,
    /// The spacing of `column_ms`, s: 1 ms in whole ticks.
    column_ms_step: f64,
    tick: f64,
    period: f64,
    /// How fast the ECU's clock walks against the rows, s per s (its status frames walk with
    /// its SYNCs).
    drift: f64,
}

/// The grid a held column is read on, s (see [`Epos4Samples::read`]).
const COLUMN_MS_STEP_S: f64 = 1e-3;

impl Epos4Samples {
    /// The column `before` s before row `k`'s end, on the tick grid (held at the ends).
    fn column_before(&self, k: usize, before: f64) -> f64 {
        let t = (k + 1) as f64 * self.period - before;
        let last = self.column_ticks.len().saturating_sub(1);
        // Tick i ends at (i + 1) * tick; `as` saturates a negative or NaN index to 0.
        let i = ((t / self.tick).round() as usize)
            .saturating_sub(1)
            .min(last);
        self.column_ticks.get(i).map_or(f64::NAN, |v| f64::from(*v))
    }

    /// The rows as `readout` reads them.
    pub fn read(&self, readout: super::rig::Epos4Readout) -> SimOut {
        if self.at.is_empty() {
            return SimOut::default();
        }
        let n = self.column.len();
        let interp = |t: f64, v: &[f64]| super::interp_at(&self.at, v, t);
        let age = readout.column_age_s;
        let output = if age.is_nan() || age <= 0.0 {
            self.column.clone()
        } else if readout.column_interpolated && !self.column_ticks.is_empty() {
            // Convert's line from the sample before the row's end to the next, a period on;
            // on an ECU clock of its own the samples walk against the rows, as its SYNCs do.
            (0..n)
                .map(|k| {
                    let end = (k + 1) as f64 * self.period;
                    let age = (age - self.drift * end).rem_euclid(self.period);
                    let w = age / self.period;
                    (1.0 - w) * self.column_before(k, age)
                        + w * self.column_before(k, age - self.period)
                })
                .collect()
        } else {
            // A logger that holds the status frame's sample: the column on a 1 ms grid, a line
            // between (gap/NOTES.md, "The EPOS4 car's clock and convert's column": against
            // an encoder with noise before its quantisation, the model's exact counts lost
            // two effect-free cars of the world's EPOS4 car that the line keeps).
            let at: Vec<f64> = (1..=self.column_ms.len())
                .map(|i| i as f64 * self.column_ms_step)
                .collect();
            if at.is_empty() {
                self.column.clone()
            } else {
                (0..n)
                    .map(|k| {
                        let t = (k + 1) as f64 * self.period - age;
                        super::interp_at(&at, &self.column_ms, t)
                    })
                    .collect()
            }
        };
        SimOut {
            output,
            effort: (0..n)
                .map(|k| {
                    interp(
                        (k as f64 + readout.current_at_row) * self.period,
                        &self.current,
                    )
                })
                .collect(),
            motor: (0..n)
                .map(|k| interp((k + 1) as f64 * self.period, &self.motor))
                .collect(),
        }
    }
}

/// The EPOS4 model's run ([`simulate_epos4`]) before the log's readout, with the column at
/// every tick where `m`'s readout is convert's line between status samples.
pub fn epos4_samples(m: &PaperModel, rec: &Record, fx: &Effects) -> Epos4Samples {
    let keep_ticks = m.epos4.readout.column_interpolated && m.epos4.readout.column_age_s > 0.0;
    let p = m.plant;
    let period = 1.0 / REFERENCE_HZ as f64;
    let dt = 1.0 / CURRENT_LOOP_HZ as f64;
    let ticks_per_period = (period / dt).round() as u64;
    // A reference that reaches the ECU late is latched at the first SYNC after it arrives:
    // on an EPOS4 car a delay is a later latch, whole periods of the reference plus a SYNC
    // phase moved within the period, never a blend of two samples. The drive's position and
    // current are sampled at the same SYNC, so the phase is the one the log's sampling shows,
    // and a log cannot tell a delay from a SYNC grid that sits later (the ECU's grid starts
    // with the link, wherever the first frame put it). So `delay_s` is the latency beyond the
    // nominal SYNC phase, split into whole reference periods and the latch's tick.
    let latch = Epos4Latch::new(
        m.epos4.sync_after_push_s + fx.delay_s.max(0.0),
        dt,
        ticks_per_period,
    );
    let reference = delayed(
        &held_later(&rec.reference, latch.whole_periods),
        fx.log_lag_s,
        period,
    );
    let Some(&first) = reference.first() else {
        return Epos4Samples::default();
    };
    let Ok(mut plant) = EffectPlant::new(p, fx.plant_effects(), dt) else {
        return Epos4Samples::default();
    };
    let Some(gearing) = Gearing::new(p.belt_reduction as f32, p.tau_bs as f32, p.tau_p as f32)
    else {
        return Epos4Samples::default();
    };
    let Some(scale) = PositionScale::new(HALL_COUNTS_PER_REV) else {
        return Epos4Samples::default();
    };
    // The car's power-up, where the log shows one (`Record::powered_from`): its column where
    // the log's first row has it, the drive off until its first report, and the ECU's enable
    // ramp carrying the reference from the column, as the firmware does at every enable. ECU
    // mode's column integral holds what it gathered while the ramp ended and the column caught
    // up, and holds it until the column next stands a count off: started at rest at the
    // reference instead, the model of the simulated EPOS4 car's track under the ECU controller
    // is one motor increment off on 5.5 % of its targets, 94.1 % at the car's clock
    // (gap/NOTES.md, "The car's power-up").
    let powered_from = rec.powered_from.min(reference.len());
    let start = match rec.output.first() {
        Some(&c) if powered_from > 0 && c.is_finite() => c,
        _ => first,
    };
    plant.set_at_rest(start.to_radians());
    let mut drive = DriveLoop::new(plant).with_position_phase(m.epos4.position_phase_ticks);
    let gains = match m.controller {
        Controller::Paper => m.gains,
        Controller::Ecu => Ecu::ecu_mode_epos4_gains(),
    };
    if drive.set_gains(&gains).is_err() {
        return Epos4Samples::default();
    }
    drive.set_voltage_limit(if fx.supply_v > 0.0 {
        fx.supply_v
    } else {
        m.supply_v
    });
    let mut shaper = (m.controller == Controller::Ecu).then(|| {
        let mut s = ColumnShaper::new(gearing, EcuTuning::PAPER, 1);
        s.reset(gearing.motor_from_steering(SteeringRad::from(SteeringDeg(start as f32))));
        s
    });
    let encoder = ColumnEncoder { zero_raw: 0 };
    let column_deg = |d: &DriveLoop| {
        f64::from(
            encoder
                .angle(encoder.raw_from_angle(d.plant().column_rad()))
                .0,
        )
        .to_degrees()
    };
    let per_motor = p.motor_per_pinion();
    // The SYNCs on the ECU's grid: the first at the latch's tick, then every period of the
    // ECU's clock, which walks `sync_drift` against the reference's. A SYNC latches the target
    // made from the newest reference, whichever period it falls in.
    let drift = if m.epos4.sync_drift.is_finite() {
        m.epos4.sync_drift.clamp(-MAX_SYNC_DRIFT, MAX_SYNC_DRIFT)
    } else {
        0.0
    };
    let sync_at = |i: u64| {
        let walk = (i as f64 * ticks_per_period as f64 * drift).round() as i64;
        (latch.sync_tick + i * ticks_per_period).saturating_add_signed(walk)
    };
    let mut syncs_done: u64 = 0;
    let mut next_sync = sync_at(0);
    let n = reference.len();
    // SYNC samples: the tick they were taken at, the position (output units) and the current.
    let mut at = Vec::with_capacity(n + 1);
    let mut motor_s = Vec::with_capacity(n + 1);
    let mut current_s = Vec::with_capacity(n + 1);
    let mut column_rows = Vec::with_capacity(n);
    // The column every 1 ms too, and at every tick where asked, for a readout that takes it
    // before the row's end.
    let column_every = ((COLUMN_MS_STEP_S / dt).round() as u64).max(1);
    let mut column_ms = Vec::with_capacity(n * (ticks_per_period / column_every) as usize + 1);
    let mut column_ticks = Vec::with_capacity(if keep_ticks {
        n * ticks_per_period as usize
    } else {
        0
    });
    let mut target = gearing.motor_from_steering(SteeringRad::from(SteeringDeg(start as f32)));
    let mut tick: u64 = 0;
    // The ECU's column encoder task samples every 2 ms, on its own phase; the shaper takes the
    // newest sample.
    let encoder_ticks = (steering_ecu::tasks::ENCODER_PERIOD.as_micros() as f64 * 1e-6 / dt)
        .round()
        .max(1.0) as u64;
    let encoder_phase = ((m.epos4.encoder_phase_s / dt).round() as u64) % encoder_ticks;
    let mut encoder_sample = column_deg(&drive);
    let sample = |d: &DriveLoop| {
        let inc = scale
            .inc_from_motor(steering_ecu::units::MotorRad(d.plant().motor_rad() as f32))
            .unwrap_or(0);
        let motor = f64::from(scale.motor_from_inc(inc).0);
        let current = match m.epos4.current {
            DriveCurrent::Instantaneous => (d.plant().current_a() * 1e3).round() * 1e-3,
            DriveCurrent::Averaged => d.averaged_current_ma().round() * 1e-3,
        };
        ((motor / per_motor).to_degrees(), current)
    };
    // The enable ramp steps at each push, `k + 1` periods in (at rest at 0 before the first).
    // While the car powers up (up to and with the push before the drive's first report, when
    // the EPOS4 is not yet in Operation enabled) it waits at rest at the column.
    let period_us = (period * 1e6).round() as u64;
    let mut ramp = (powered_from > 0).then(|| EnableRamp::at_rest(SteeringDeg(start as f32), 0));
    // One period past the log's last row, its reference held: the readout reads each row off
    // samples after its end (the next SYNC's current, a line to the next status frame's
    // column), which the car had and a run that stopped at the row's end has not. Without
    // it, the last row of a log's head (what the drive's clock is fitted on) was read off
    // held samples: 3.6 A off on the simulated car's track, the whole of the head's residual
    // at the right clock, and enough to pick the wrong one.
    let past_the_end = reference.last().copied();
    for (k, &r) in reference.iter().chain(past_the_end.iter()).enumerate() {
        // The ECU takes the sample at the push (tick k * ticks_per_period).
        let mut angle = SteeringDeg(r as f32);
        let now_us = (k as u64 + 1) * period_us;
        let ramping = ramp.is_some();
        // The drive enters Operation enabled at its first report (at once without a power-up).
        if k == powered_from {
            drive.enable();
        }
        if let Some(rp) = &mut ramp {
            if k <= powered_from {
                angle = SteeringDeg(encoder_sample as f32);
                *rp = EnableRamp::at_rest(angle, now_us);
            } else {
                match rp.step(now_us, angle, period_us) {
                    Some(a) => angle = a,
                    None => ramp = None,
                }
            }
        }
        let running = k >= powered_from;
        match &mut shaper {
            None => {
                if let Ok(m) = steering_ecu::paper_mode::reference_at_motor(gearing, angle) {
                    target = m;
                }
            }
            Some(s) => {
                // The ramp's samples, its last included, are not shaped (as the firmware's).
                let _ = if ramping {
                    s.push_unshaped(angle)
                } else {
                    s.push_reference(angle)
                };
                let column = SteeringRad::from(SteeringDeg(encoder_sample as f32));
                target = s.next_target(Some(column));
            }
        }
        for _ in 0..ticks_per_period {
            drive.tick(running);
            tick += 1;
            // The encoder's reading only where a sample is kept (its quantisation costs).
            let (every_ms, encoder_tick) = (
                tick.is_multiple_of(column_every),
                tick % encoder_ticks == encoder_phase,
            );
            if keep_ticks || every_ms || encoder_tick {
                let column = column_deg(&drive);
                if keep_ticks {
                    column_ticks.push(column as f32);
                }
                if every_ms {
                    column_ms.push(column);
                }
                if encoder_tick {
                    encoder_sample = column;
                }
            }
            if tick >= next_sync {
                syncs_done += 1;
                next_sync = sync_at(syncs_done).max(tick + 1);
                // The target as whole increments of the drive, then back at the wheel, as the
                // drive reads it. The increments count from where the motor stood at power-up;
                // taken here as the column's zero (a car powered up straight).
                if let Some(inc) = scale.inc_from_motor(target) {
                    let motor = scale.motor_from_inc(inc);
                    let _ =
                        drive.push_target(SteeringDeg::from(gearing.steering_from_motor(motor)));
                }
                let (mo, cu) = sample(&drive);
                at.push(tick as f64 * dt);
                motor_s.push(mo);
                current_s.push(cu);
            }
        }
        if k < n {
            column_rows.push(column_deg(&drive));
        }
    }
    Epos4Samples {
        at,
        motor: motor_s,
        current: current_s,
        column: column_rows,
        column_ms,
        column_ticks,
        column_ms_step: column_every as f64 * dt,
        tick: dt,
        period,
        drift,
    }
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
    let mut plant = EffectPlant::new(p, fx.plant_effects(), dt).ok()?;
    plant.set_at_rest(first.to_radians());
    let encoder = ColumnEncoder { zero_raw: 0 };
    let wn = std::f64::consts::TAU * 300.0;
    let substeps = ((rec.dt / dt).round() as usize).max(1);
    let mut out = Vec::with_capacity(motor.len());
    for k in 0..motor.len() {
        // The record holds the angle at the end of each step: a line from the last one.
        let here = rad(motor[k.saturating_sub(1)]);
        let next = rad(motor[k]);
        let w_ref = (next - here) / rec.dt;
        for j in 0..substeps {
            let x = plant.state();
            let theta_ref = here + w_ref * ((j + 1) as f64 * dt);
            let torque = p.j_rot
                * (wn * wn * (theta_ref - x[state::THETA_ROT])
                    + 2.0 * wn * (w_ref - x[state::W_ROT]));
            plant.step_driven(p.ke * x[state::W_ROT], torque);
        }
        out.push((encoder.angle(encoder.raw_from_angle(plant.column_rad())).0 as f64).to_degrees());
    }
    Some(out)
}

/// One step `h` of a 1-DOF axis (position `x`, speed `v`, inertia or mass `m`) under the force
/// `free` besides Coulomb friction of size `level`, stick-aware: at rest the friction holds
/// whatever it can, and a step that would carry the speed through zero stops there.
fn stick_slip_step(x: f64, v: f64, free: f64, level: f64, m: f64, h: f64) -> (f64, f64) {
    if v == 0.0 && free.abs() <= level {
        return (x, v);
    }
    let dir = if v != 0.0 { v.signum() } else { free.signum() };
    let v_new = v + (free - level * dir) / m * h;
    if level > 0.0 && v != 0.0 && v_new.signum() != v.signum() {
        (x + v * h * 0.5, 0.0)
    } else {
        (x + 0.5 * (v + v_new) * h, v_new)
    }
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
    let reference = delayed(&rec.reference, fx.delay_s + fx.log_lag_s, ts);
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
            (q, v) = stick_slip_step(q, v, f_free, level, m.mass, h);
        }
    }
    out
}

/// Standard gravity, m/s^2.
const GRAVITY: f64 = 9.81;

/// The friction of the BAM servo's gearbox as a budget: the largest torque friction can
/// oppose, from the velocity `w`, the motor torque `tm` and the external (gravity) torque `te`,
/// all at the output shaft. Its form is BAM's widest (M6, Duclusaud et al., ICRA 2025,
/// arXiv 2410.08650, section on the friction models): `Kc + |Km tm - Ke te|
/// + exp(-|w / ws|^alpha) (Kcs + |Kms tm - Kes te| + Q)`, with `Q = Keq te^2` when the motor
/// drives (|tm| > |te|) and `Kmq tm^2` when the load backdrives it. The viscous term is the
/// model's own. Every field 0 is no friction; the diagnosis's Coulomb candidate fills `kc`
/// (and `kcs`, `ws` for Stribeck).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct GearFriction {
    /// Coulomb, N m.
    pub kc: f64,
    /// Extra static (Stribeck) friction, N m, its velocity (rad/s) and exponent.
    pub kcs: f64,
    pub ws: f64,
    pub alpha: f64,
    /// Load-dependent shares of the motor and the external torque, sliding and static.
    pub km: f64,
    pub ke: f64,
    pub kms: f64,
    pub kes: f64,
    /// Quadratic load terms, 1/(N m), driving (external) and backdriven (motor).
    pub keq: f64,
    pub kmq: f64,
}

impl GearFriction {
    fn budget(&self, w: f64, tm: f64, te: f64) -> f64 {
        let stribeck = if self.ws > 0.0 {
            (-(w / self.ws).abs().powf(self.alpha)).exp()
        } else {
            0.0
        };
        let q = if tm.abs() > te.abs() {
            self.keq * te * te
        } else {
            self.kmq * tm * tm
        };
        self.kc
            + (self.km * tm - self.ke * te).abs()
            + stribeck * (self.kcs + (self.kms * tm - self.kes * te).abs() + q)
    }
}

/// The BAM XL330 pendulum under its firmware P controller, on the record's uniform grid
/// (`Rig::bam`; model as in `host-sim/data/bam-xl330/README.md`), with the candidate effects:
/// Coulomb (and Stribeck) friction, play before the encoder, a delay of the goal. See
/// [`simulate_bam_with`].
pub fn simulate_bam(m: &BamModel, rec: &Record, fx: &Effects) -> SimOut {
    let friction = GearFriction {
        kc: fx.coulomb.max(0.0),
        kcs: fx.stribeck.max(0.0),
        ws: if fx.stribeck_velocity > 0.0 {
            fx.stribeck_velocity
        } else {
            1.0
        },
        alpha: 2.0,
        ..GearFriction::default()
    };
    let viscous = if fx.viscous_override.is_finite() {
        fx.viscous_override
    } else {
        m.viscous_nm_s_per_rad
    };
    simulate_bam_with(
        &BamModel {
            viscous_nm_s_per_rad: viscous,
            ..m.clone()
        },
        rec,
        &friction,
        fx.backlash,
        fx.delay_s + fx.log_lag_s,
    )
}

/// The BAM pendulum with a given gearbox friction, play (rad, full width) and goal delay (s).
/// At every integration step the firmware reads its encoder (4096 counts/rev) and sets
/// `duty = sat(error_gain kp (goal - position))`; the winding sees `duty vin`, and at the
/// output shaft `J w' = kt (duty vin - kt w) / R - Kv w - m g l sin(theta) - friction`, with
/// `J` the armature plus the point mass and the friction at most the budget of `friction`
/// (holding the shaft at rest while it can). While the drive is off (`supply_v` 0) the bridge
/// is open: no motor torque and no back-EMF braking, the pendulum falls freely against
/// friction alone. Each step logs the encoder reading and the duty at its start, as the
/// servo's registers are read.
pub fn simulate_bam_with(
    m: &BamModel,
    rec: &Record,
    friction: &GearFriction,
    backlash: f64,
    delay_s: f64,
) -> SimOut {
    let n = rec.reference.len();
    let mut out = SimOut {
        output: Vec::with_capacity(n),
        effort: Vec::with_capacity(n),
        motor: Vec::new(),
    };
    if n == 0 || m.r_ohm <= 0.0 {
        return out;
    }
    let reference = delayed(&rec.reference, delay_s, m.ts_s);
    let sub = m.substeps.max(1);
    let h = m.ts_s / sub as f64;
    let kv = m.viscous_nm_s_per_rad;
    let inertia = m.armature_kg_m2 + m.mass_kg * m.length_m * m.length_m;
    let weight = m.mass_kg * GRAVITY * m.length_m;
    let quantum = std::f64::consts::TAU / m.encoder_counts.max(1.0);
    let encoder = |theta: f64| (theta / quantum).round() * quantum;
    // The firmware's duty from what its encoder reads through the play.
    let duty = |goal: f64, read: f64| (m.error_gain * m.kp * (goal - read)).clamp(-1.0, 1.0);
    // Start at the first measured position, at rest.
    let mut theta = rec.output.first().copied().unwrap_or(reference[0]);
    let mut w = 0.0;
    let mut play = Play::new(backlash, theta);
    for k in 0..n {
        let vin = rec.supply_v.as_ref().map_or(0.0, |s| s[k]);
        let on = vin > 0.0;
        let read = encoder(play.step(theta));
        out.output.push(read);
        out.effort
            .push(if on { duty(reference[k], read) } else { 0.0 });
        for _ in 0..sub {
            let read = encoder(play.step(theta));
            let motor = if on {
                m.kt * (duty(reference[k], read) * vin - m.kt * w) / m.r_ohm
            } else {
                0.0
            };
            let external = -weight * theta.sin();
            let free = motor + external - kv * w;
            let level = friction.budget(w, motor, external);
            (theta, w) = stick_slip_step(theta, w, free, level, inertia, h);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::Epos4Latch;

    /// 50 us current-loop ticks, 200 to a 10 ms period.
    fn latch(latency_ms: f64) -> (usize, u64) {
        let l = Epos4Latch::new(latency_ms * 1e-3, 50e-6, 200);
        (l.whole_periods, l.sync_tick)
    }

    #[test]
    fn a_latch_within_the_period_stays_in_it_and_one_beyond_moves_a_whole_period() {
        assert_eq!(latch(1.75), (0, 35));
        // The SYNC at the end of the period is still this period's (the nominal phase may be
        // a whole period).
        assert_eq!(latch(10.0), (0, 200));
        assert_eq!(latch(10.05), (1, 1));
        assert_eq!(latch(38.0), (3, 160));
    }

    #[test]
    fn a_latch_is_at_least_one_tick_whatever_the_latency() {
        assert_eq!(latch(0.0), (0, 1));
        assert_eq!(latch(-3.0), (0, 1));
        // No number of ticks: the earliest latch, as for no latency at all.
        assert_eq!(latch(f64::NAN), (0, 1));
        assert_eq!(latch(f64::INFINITY), (0, 1));
    }
}

#[cfg(test)]
mod sync_drift {
    use super::epos4_samples;
    use crate::gap::Record;
    use crate::gap::model::Effects;
    use crate::gap::rig::{CarDrive, Rig, RigModel};

    /// The EPOS4 model's SYNC instants over `n` periods of a resting car, with its grid
    /// walking `drift` s per s.
    fn syncs(drift: f64, n: usize) -> Vec<f64> {
        let mut rig = Rig::paper();
        let RigModel::Paper(m) = &mut rig.model else {
            unreachable!("the paper rig")
        };
        m.drive = CarDrive::Epos4;
        m.epos4.sync_after_push_s = 0.003;
        m.epos4.sync_drift = drift;
        let rec = Record {
            dt: 0.01,
            reference: vec![0.0; n],
            output: vec![0.0; n],
            effort: vec![0.0; n],
            ..Record::default()
        };
        epos4_samples(m, &rec, &Effects::nominal()).at
    }

    #[test]
    fn on_one_clock_the_syncs_sit_a_period_apart_at_their_phase() {
        // One a period, and one in the period past the log's end that the readout reads the
        // last row's current off.
        let at = syncs(0.0, 100);
        assert_eq!(at.len(), 101);
        for (k, t) in at.iter().enumerate() {
            assert!(
                (t - (0.003 + 0.01 * k as f64)).abs() < 1e-9,
                "SYNC {k} at {t}"
            );
        }
    }

    #[test]
    fn a_drifting_grid_walks_by_its_drift_and_wraps_through_the_period() {
        // 1 %: the SYNC walks 0.1 ms a period, past a whole period over 200.
        for drift in [0.01, -0.01] {
            let at = syncs(drift, 200);
            let spacing = (at[at.len() - 1] - at[0]) / (at.len() - 1) as f64;
            assert!(
                (spacing - 0.01 * (1.0 + drift)).abs() < 1e-7,
                "{drift}: spacing {spacing}"
            );
            // One SYNC fewer (a slower grid) or more (a faster one) than periods, each at
            // most one tick off its place.
            assert!(at.len().abs_diff(200) <= 3, "{drift}: {} SYNCs", at.len());
            for (i, t) in at.iter().enumerate() {
                let want = 0.003 + 0.01 * i as f64 * (1.0 + drift);
                assert!(
                    (t - want).abs() <= 50e-6,
                    "{drift}: SYNC {i} at {t}, {want}"
                );
            }
        }
    }

    #[test]
    fn a_drift_that_is_no_number_or_past_one_percent_is_held_to_it() {
        assert_eq!(syncs(f64::NAN, 50), syncs(0.0, 50));
        assert_eq!(syncs(0.5, 300), syncs(0.01, 300));
    }
}

#[cfg(test)]
mod column_readout {
    use super::Epos4Samples;
    use crate::gap::rig::Epos4Readout;

    const PERIOD: f64 = 0.01;
    const TICK: f64 = 5e-5;

    /// Samples of a column that moves as t^2 (deg, t in s), every tick over `rows` periods.
    fn samples(rows: usize) -> Epos4Samples {
        let col = |t: f64| 100.0 * t * t;
        let ticks = (rows as f64 * PERIOD / TICK).round() as usize;
        Epos4Samples {
            at: vec![0.0, rows as f64 * PERIOD],
            motor: vec![0.0; 2],
            current: vec![0.0; 2],
            column: (1..=rows).map(|k| col(k as f64 * PERIOD)).collect(),
            column_ms: (1..=rows * 10).map(|i| col(i as f64 * 1e-3)).collect(),
            column_ticks: (1..=ticks).map(|i| col(i as f64 * TICK) as f32).collect(),
            column_ms_step: 1e-3,
            tick: TICK,
            period: PERIOD,
            drift: 0.0,
        }
    }

    fn read(age: f64, interpolated: bool) -> Vec<f64> {
        samples(20)
            .read(Epos4Readout {
                current_at_row: 0.5,
                column_age_s: age,
                column_interpolated: interpolated,
            })
            .output
    }

    #[test]
    fn convert_reads_the_column_off_a_line_between_the_samples_either_side_of_the_rows_end() {
        let col = |t: f64| 100.0 * t * t;
        let age = 2.3e-3;
        let w = age / PERIOD;
        let got = read(age, true);
        for (k, v) in got.iter().enumerate().take(15).skip(2) {
            let end = (k + 1) as f64 * PERIOD;
            let want = (1.0 - w) * col(end - age) + w * col(end - age + PERIOD);
            assert!((v - want).abs() < 1e-4, "row {k}: {v} against {want}");
            // A curve's chord lies above it: the line is not the column at the row's end.
            assert!(*v > col(end) + 1e-3, "row {k}");
        }
    }

    #[test]
    fn a_held_column_is_the_sample_itself_and_an_age_of_zero_the_rows_end() {
        let col = |t: f64| 100.0 * t * t;
        let held = read(4e-3, false);
        for (k, v) in held.iter().enumerate().take(15).skip(1) {
            let want = col((k + 1) as f64 * PERIOD - 4e-3);
            assert!((v - want).abs() < 1e-4, "row {k}: {v} against {want}");
        }
        let exact: Vec<f64> = (1..=20).map(|k| col(k as f64 * PERIOD)).collect();
        assert_eq!(read(0.0, true), exact);
        assert_eq!(read(0.0, false), exact);
        // No number for an age: the row's end, not a NaN column.
        assert_eq!(read(f64::NAN, true), exact);
    }
}

#[cfg(test)]
mod epos4_run {
    use super::{Effects, SimOut, simulate_epos4};
    use crate::gap::Record;
    use crate::gap::rig::{CarDrive, Epos4Readout, PaperModel, Rig, RigModel};
    use crate::sim::Controller;

    /// The paper rig's EPOS4 car under `controller`, read as convert reads it (the status
    /// frames' column 2.31 ms before each row's end, as on the simulated car).
    fn car(controller: Controller) -> PaperModel {
        let RigModel::Paper(mut m) = Rig::paper().model else {
            unreachable!("the paper rig runs the paper model")
        };
        m.drive = CarDrive::Epos4;
        m.controller = controller;
        m.epos4.readout = Epos4Readout {
            column_age_s: 2.31e-3,
            ..Epos4Readout::CONVERT
        };
        m
    }

    /// `rows` periods of `reference` (deg, of the period's start in s); the column at 0 deg.
    fn record(rows: usize, reference: impl Fn(f64) -> f64) -> Record {
        Record {
            dt: 0.01,
            reference: (0..rows).map(|k| reference(k as f64 * 0.01)).collect(),
            output: vec![0.0; rows],
            effort: vec![0.0; rows],
            ..Record::default()
        }
    }

    fn run(m: &PaperModel, rec: &Record) -> SimOut {
        simulate_epos4(m, rec, &Effects::nominal())
    }

    /// Each row is read off samples after its end (the next SYNC's current, a line to the next
    /// status frame's column): the model runs past a log's last row, so that a head of a log
    /// (what the drive's clock is fitted on) reads its last row as the whole log does. Stopped
    /// at the row's end, it read the last row off held samples.
    #[test]
    fn a_heads_last_row_is_read_as_the_whole_logs() {
        for controller in [Controller::Paper, Controller::Ecu] {
            let m = car(controller);
            let sine = |t: f64| 10.0 * (std::f64::consts::TAU * 2.0 * t).sin();
            let whole = run(&m, &record(300, sine));
            for rows in [97, 150, 233] {
                let head = run(&m, &record(rows, sine));
                assert_eq!(head.output.len(), rows);
                for (what, h, w) in [
                    ("column", &head.output, &whole.output),
                    ("current", &head.effort, &whole.effort),
                    ("motor", &head.motor, &whole.motor),
                ] {
                    assert_eq!(
                        h[..],
                        w[..rows],
                        "{controller:?}, the first {rows} rows: the {what}"
                    );
                }
            }
        }
    }

    /// A log from the car's power-up (`powered_from` rows before the drive first reported):
    /// the drive holds still and draws nothing until then, and the ECU's enable ramp then
    /// carries the reference from the log's first column (1000 deg/s^2 at the wheel: 0.1 deg
    /// in its first period), not a step of the whole way at the first row.
    #[test]
    fn a_log_from_power_up_holds_the_drive_then_ramps_from_the_column() {
        for controller in [Controller::Paper, Controller::Ecu] {
            let m = car(controller);
            let powered_from = 3;
            let rec = Record {
                powered_from,
                ..record(100, |_| 2.0)
            };
            let out = run(&m, &rec);
            for k in 0..=powered_from {
                assert_eq!(
                    (out.motor[k], out.effort[k], out.output[k]),
                    (0.0, 0.0, 0.0),
                    "{controller:?}, row {k}: the drive not yet running"
                );
            }
            // The first ramp step, 0.1 deg, is pushed at the row after the drive first
            // reported and moves the motor within that row; a step of the whole 2 deg would
            // have moved it a degree.
            let first = out.motor[powered_from + 1];
            assert!(
                first > 0.0 && first < 0.3,
                "{controller:?}: the motor at {first} deg after the first ramp step"
            );
            let settled = out.output[99];
            assert!(
                (settled - 2.0).abs() < 0.1,
                "{controller:?}: the column at {settled} deg after a second"
            );
            // Without the power-up, the car is taken at rest at the reference.
            let running = run(&m, &record(100, |_| 2.0));
            assert!(
                (running.output[0] - 2.0).abs() < 0.1,
                "{controller:?}: {}",
                running.output[0]
            );
        }
    }
}

//! The independent world's EPOS4 car: the world's plant ([`super::generator`]'s RK4 ODE
//! with its own effects) behind a drive written here, apart from the firmware's cascade and
//! from the simulated EPOS4 (`epos4_sim::DriveLoop`) that the diagnosis's EPOS4 model runs,
//! and logs written from the bus traffic as `steer-can convert` or a team's own logger
//! writes them.
//!
//! | what               | here                                        | the diagnosis's model          |
//! |--------------------|---------------------------------------------|--------------------------------|
//! | current loop       | PI at 25 kHz, f64, +-24 V, no winding guard  | the firmware's, 20 kHz, f32    |
//! | position loop      | PID + feedforward at 2.5 kHz                | the same law at 2 kHz          |
//! | CSP                | target latched at each SYNC, a line over the | the firmware's interpolator    |
//! |                    | 10 ms period from where the set-point stands |                                |
//! | current sensor     | 10 mA of noise in the loop and the sample    | exact                          |
//! | SYNC               | 0.5-9.5 ms after each reference, drawn       | fitted from the log            |
//! | TPDO1 / TPDO2      | sent 160 / 280 us after the SYNC             | dated at the SYNC              |
//!
//! The ECU runs the paper controller: each reference, on arrival, is the motor angle at the
//! wheel's angle through Table 2's gearing, in whole increments of the drive (84 per motor
//! revolution, counted from straight ahead), sent at once as the CSP target. A delay is the
//! reference frame reaching the ECU late; the drive then latches it at the first SYNC after.
//!
//! The loggers ([`LoggedCar`]):
//! - `Epos4Convert`: a row per reference period as `steer-can convert` builds one from a
//!   recording (the reference in force over the period ending at the row, the column from the
//!   ECU's status frame dated one encoder period before it was sent, the TPDOs' position and
//!   current dated when they were sent, read at push + 10 ms and push + 5 ms), with its header
//!   lines (`# drive: epos4`, `# current: sync-sample`, ...).
//! - `Epos4StatusFrame`: a team's logger that writes a row each time the drive's TPDO2
//!   arrives, stamped on arrival: the position and current the drive sampled at that SYNC,
//!   the column of the ECU's last status frame, the reference last sent; no header lines.

use super::generator::{GenCase, LoggedCar, Logger, Ode, Rows, State, at_rest, stamp_and_lose};
use super::rng;
use crate::plant::PlantParams;
use steering_ecu::gains::{EposGains, SiGains};
use steering_ecu::gearing::Gearing;
use steering_ecu::sensors::{ColumnEncoder, HALL_COUNTS_PER_REV};
use steering_ecu::units::SteeringDeg;

/// The drive's current loop, Hz (a real EPOS4's, not the firmware's 20 kHz).
pub const DRIVE_CURRENT_HZ: u32 = 25_000;
/// The drive's position loop, Hz.
pub const DRIVE_POSITION_HZ: u32 = 2_500;
/// Current-loop ticks per 10 ms reference period.
const CURRENT_TICKS_PER_PERIOD: u64 = (DRIVE_CURRENT_HZ / 100) as u64;
/// Current-loop ticks per position tick.
const CURRENT_TICKS_PER_POSITION: u64 = (DRIVE_CURRENT_HZ / DRIVE_POSITION_HZ) as u64;
/// Position ticks per 10 ms reference period.
const POSITION_TICKS_PER_PERIOD: u64 = (DRIVE_POSITION_HZ / 100) as u64;
/// One 8-byte frame at 1 Mbit/s, s.
const FRAME_S: f64 = 130e-6;
/// From the SYNC to the drive sending TPDO1 and TPDO2, s.
const TPDO1_AFTER_SYNC_S: f64 = 160e-6;
const TPDO2_AFTER_SYNC_S: f64 = 280e-6;
/// The ECU's column encoder task period, s (2 ms).
const ENCODER_PERIOD_S: f64 = 2e-3;
/// The drive's current sensor noise, A (in its loop and in the sample it reports).
const CURRENT_SENSOR_NOISE_A: f64 = 0.01;
/// Noise on the column angle before the encoder's quantisation, deg (as the direct world's).
const ANGLE_NOISE_DEG: f64 = 0.01;
/// Current and voltage limits, A and V (section 3.3).
const CURRENT_LIMIT_A: f64 = 20.0;
const VOLTAGE_LIMIT_V: f64 = 24.0;

/// What the car put on the bus, each value with the instant it was sent (s from the first
/// reference frame) or, for the encoder, measured.
#[derive(Debug, Default)]
struct Traffic {
    /// Reference frames: sent, angle at the wheel (deg).
    references: Vec<(f64, f64)>,
    /// The ECU's status frames: sent, the newest column-encoder sample (deg).
    status: Vec<(f64, f64)>,
    /// TPDO1: sent, the position the drive sampled at the SYNC (motor rad, whole increments).
    tpdo1: Vec<(f64, f64)>,
    /// TPDO2: sent, the current the drive sampled at the SYNC (A, whole mA).
    tpdo2: Vec<(f64, f64)>,
    /// At each SYNC (in the order of `tpdo1`/`tpdo2`): the reference frame whose target the
    /// drive latched (its index in `references`).
    latched: Vec<usize>,
}

/// The drive's cyclic synchronous position mode: the interpolated set-point, the position PID
/// with velocity and acceleration feedforward, the current PI (Table 3 gains in SI units).
struct Drive {
    kp: f64,
    ki: f64,
    kd: f64,
    kv: f64,
    ka: f64,
    ckp: f64,
    cki: f64,
    /// The line of the current period: start, end (motor rad), slope (rad/s), the slope's
    /// change over the period (rad/s^2), position ticks into it.
    start: f64,
    end: f64,
    slope: f64,
    accel: f64,
    tick: u64,
    /// The set-point has stood at the end of its line for a tick or more.
    held: bool,
    position_integral: f64,
    previous_error: Option<f64>,
    current_setpoint: f64,
    current_integral: f64,
}

impl Drive {
    fn new(gains: &SiGains, at_rest: f64) -> Drive {
        let f = |v: f32| f64::from(v);
        Drive {
            kp: f(gains.position_kp()),
            ki: f(gains.position_ki()),
            kd: f(gains.position_kd()),
            kv: f(gains.ff_velocity()),
            ka: f(gains.ff_acceleration()),
            ckp: f(gains.current_kp()),
            cki: f(gains.current_ki()),
            start: at_rest,
            end: at_rest,
            slope: 0.0,
            accel: 0.0,
            tick: POSITION_TICKS_PER_PERIOD,
            held: true,
            position_integral: 0.0,
            previous_error: None,
            current_setpoint: 0.0,
            current_integral: 0.0,
        }
    }

    fn setpoint_position(&self) -> f64 {
        let n = POSITION_TICKS_PER_PERIOD;
        if self.tick >= n {
            self.end
        } else {
            self.start + (self.end - self.start) * self.tick as f64 / n as f64
        }
    }

    /// At a SYNC: the target received last becomes the end of a line over one period from
    /// where the set-point stands now.
    fn latch(&mut self, target: f64) {
        let period = 0.01;
        let from = self.setpoint_position();
        // A set-point that stood at the end of its line for a position tick or more had
        // stopped; one that reached it just now still runs at the line's slope.
        let previous_slope = if self.held { 0.0 } else { self.slope };
        self.start = from;
        self.end = target;
        self.slope = (target - from) / period;
        self.accel = (self.slope - previous_slope) / period;
        self.tick = 0;
        self.held = false;
    }

    /// One position tick on the motor angle `measured` (rad).
    fn position_step(&mut self, measured: f64) {
        let dt = 1.0 / f64::from(DRIVE_POSITION_HZ);
        let moving = self.tick < POSITION_TICKS_PER_PERIOD;
        let position = self.setpoint_position();
        let (velocity, acceleration) = if moving {
            (self.slope, self.accel)
        } else {
            (0.0, 0.0)
        };
        if moving {
            self.tick += 1;
        } else {
            self.held = true;
        }
        let error = position - measured;
        let derivative = self.previous_error.map_or(0.0, |e| (error - e) / dt);
        self.previous_error = Some(error);
        let integral = self.position_integral + self.ki * error * dt;
        let demand = self.kp * error
            + integral
            + self.kd * derivative
            + self.kv * velocity
            + self.ka * acceleration;
        // Conditional integration: the integral moves only while the output is not limited.
        if demand.abs() <= CURRENT_LIMIT_A {
            self.position_integral = integral;
        }
        self.current_setpoint = demand.clamp(-CURRENT_LIMIT_A, CURRENT_LIMIT_A);
    }

    /// One current tick on the measured current (A): the voltage at the terminals (V).
    fn current_step(&mut self, measured: f64) -> f64 {
        let dt = 1.0 / f64::from(DRIVE_CURRENT_HZ);
        let error = self.current_setpoint - measured;
        let integral = self.current_integral + self.cki * error * dt;
        let demand = self.ckp * error + integral;
        if demand.abs() <= VOLTAGE_LIMIT_V {
            self.current_integral = integral;
        }
        demand.clamp(-VOLTAGE_LIMIT_V, VOLTAGE_LIMIT_V)
    }
}

/// Where a car's SYNCs and status frames sit after each reference frame is sent, s: drawn
/// per car from a stream apart from the car's and the logger's (the ECU's SYNC grid and its
/// tasks run on its own clock, started wherever the link came up).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Phases {
    pub sync_s: f64,
    /// The ECU's status frame; its encoder task ticks on the same clock, so each status
    /// frame carries the sample of the encoder tick one encoder period before it (the read of
    /// the tick's own sample takes longer than sending the frame).
    pub status_s: f64,
}

impl Phases {
    pub fn of(case: &GenCase, seed: u64) -> Phases {
        let mut rng = rng::seeded(seed ^ (case.index as u64).wrapping_mul(0x94d0_49bb_1331_11eb));
        let sync_s = rng.range(0.5e-3, 9.5e-3);
        let status_s = rng.range(0.0, 10e-3);
        // On the drive's current-loop grid, as the car runs them.
        let tick = 1.0 / f64::from(DRIVE_CURRENT_HZ);
        Phases {
            sync_s: (sync_s / tick).round() * tick,
            status_s: (status_s / tick).round() * tick,
        }
    }

    /// Where convert's log has the column sampled before each row's end, s: the status
    /// frame's sample (one encoder period before the frame was sent) last before the row's
    /// end, which is a frame after the reference was sent and a period on.
    pub fn column_age_convert_s(&self) -> f64 {
        (FRAME_S + ENCODER_PERIOD_S - self.status_s).rem_euclid(0.010)
    }

    /// How old the column is in a row written as TPDO2 arrives ([`LoggedCar::Epos4StatusFrame`]):
    /// from the encoder sample of the last status frame the logger had to the row's stamp, s.
    pub fn column_age_per_tpdo_s(&self) -> f64 {
        let row = self.sync_s + TPDO2_AFTER_SYNC_S + FRAME_S;
        // The last status frame the logger had received (sent a frame before the row).
        let since = (row - FRAME_S - self.status_s).rem_euclid(0.010);
        since + FRAME_S + ENCODER_PERIOD_S
    }
}

/// How far the car's ECU clock runs off the vehicle computer's for `logger`: its periods
/// are (1 + this) of the vehicle's, so its SYNC grid walks this many seconds later per second
/// (the model's `Epos4Timing::sync_drift`). Drawn per car, 20-100 ppm either way, from a
/// stream of its own; 0 where the logger's car runs on one clock.
pub fn ecu_clock_drift(case: &GenCase, seed: u64, logger: &Logger) -> f64 {
    if !logger.drifting_clock {
        return 0.0;
    }
    let mut rng = rng::seeded(
        seed ^ (case.index as u64).wrapping_mul(0x5851_f42d_4c95_7f2d) ^ 0x1f83_d9ab_fb41_bd6b,
    );
    let ppm = rng.range(20.0, 100.0);
    let sign = if rng.unit() < 0.5 { 1.0 } else { -1.0 };
    sign * ppm * 1e-6
}

/// Events on the ECU's clock, counted in the world's (the vehicle computer's) ticks: the
/// `i`-th at `phase + i period (1 + drift)`, rounded to a tick.
struct EcuGrid {
    phase: u64,
    period: u64,
    drift: f64,
    next: u64,
    count: u64,
}

impl EcuGrid {
    fn new(phase: u64, period: u64, drift: f64) -> EcuGrid {
        EcuGrid {
            phase,
            period: period.max(1),
            drift,
            next: phase,
            count: 0,
        }
    }

    /// Whether an event falls on tick `n` (called for every tick in order).
    fn due(&mut self, n: u64) -> bool {
        if n < self.next {
            return false;
        }
        self.count += 1;
        let at = self.count as f64 * self.period as f64 * (1.0 + self.drift);
        self.next = (self.phase + at.round() as u64).max(n + 1);
        true
    }
}

/// The car's run on the case's reference, its ECU's clock `drift` off the vehicle's
/// ([`ecu_clock_drift`]): the frames on its bus.
fn run(case: &GenCase, seed: u64, drift: f64) -> Traffic {
    let mut traffic = Traffic::default();
    let truth = case.truth;
    let ode = Ode::new(truth);
    let nominal = PlantParams::PAPER;
    let (Some(&first), Ok(gains), Some(gearing)) = (
        case.reference.first(),
        EposGains::PAPER.to_si(),
        Gearing::new(
            nominal.belt_reduction as f32,
            nominal.tau_bs as f32,
            nominal.tau_p as f32,
        ),
    ) else {
        return traffic;
    };
    let p = truth.plant;
    let h = 1.0 / f64::from(DRIVE_CURRENT_HZ);
    let (ticks_per_period, ticks_per_position) =
        (CURRENT_TICKS_PER_PERIOD, CURRENT_TICKS_PER_POSITION);
    let inc_rad = std::f64::consts::TAU / f64::from(HALL_COUNTS_PER_REV);
    // The ECU's target for a wheel angle, in whole increments, as motor rad.
    let target_of = |deg: f64| {
        steering_ecu::paper_mode::reference_at_motor(gearing, SteeringDeg(deg as f32))
            .ok()
            .map(|m| (f64::from(m.0) / inc_rad).round() * inc_rad)
    };
    let tick_of = |s: f64| (s / h).round() as u64;
    let phases = Phases::of(case, seed);
    let sync_phase = tick_of(phases.sync_s);
    let status_phase = tick_of(phases.status_s);
    let encoder_ticks = tick_of(ENCODER_PERIOD_S);
    let encoder_phase = status_phase % encoder_ticks;
    let mut sync_grid = EcuGrid::new(sync_phase, ticks_per_period, drift);
    let mut status_grid = EcuGrid::new(status_phase, ticks_per_period, drift);
    let mut encoder_grid = EcuGrid::new(encoder_phase, encoder_ticks, drift);
    // The ECU takes reference m when its frame arrives (late by the delay), the drive its
    // target one frame later.
    let arrive = tick_of(FRAME_S + truth.reference_delay_s);
    let rpdo = tick_of(FRAME_S);
    let mut x: State = at_rest(&p, first.to_radians());
    let mut noise = rng::seeded(seed ^ (case.index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let sensor = ColumnEncoder { zero_raw: 0 };
    let encoder = truth.unmodelled.column_encoder();
    let mut drive = Drive::new(&gains, target_of(first).unwrap_or(x[1]));
    let mut target = target_of(first).unwrap_or(x[1]);
    let mut target_frame = 0usize;
    // Targets on their way to the drive: (tick it has it, motor rad, reference frame).
    let mut in_flight: std::collections::VecDeque<(u64, f64, usize)> = Default::default();
    let mut column_sample = first;
    let periods = case.reference.len() as u64;
    for n in 0..periods * ticks_per_period {
        let t = n as f64 * h;
        if n.is_multiple_of(ticks_per_period) {
            let m = (n / ticks_per_period) as usize;
            traffic.references.push((t, case.reference[m]));
        }
        // Reference m reaches the ECU `arrive` ticks after it was sent.
        if n >= arrive && (n - arrive).is_multiple_of(ticks_per_period) {
            let m = ((n - arrive) / ticks_per_period) as usize;
            if let Some(tg) = case.reference.get(m).and_then(|&r| target_of(r)) {
                in_flight.push_back((n + rpdo, tg, m));
            }
        }
        while in_flight.front().is_some_and(|&(at, _, _)| at <= n) {
            if let Some((_, tg, m)) = in_flight.pop_front() {
                target = tg;
                target_frame = m;
            }
        }
        let measured =
            x[0] + truth.unmodelled.current_offset_a + CURRENT_SENSOR_NOISE_A * noise.normal();
        if sync_grid.due(n) {
            drive.latch(target);
            traffic.latched.push(target_frame);
            let position = (x[1] / inc_rad).round() * inc_rad;
            traffic.tpdo1.push((t + TPDO1_AFTER_SYNC_S, position));
            traffic
                .tpdo2
                .push((t + TPDO2_AFTER_SYNC_S, (measured * 1e3).round() * 1e-3));
        }
        if status_grid.due(n) {
            traffic.status.push((t, column_sample));
        }
        if encoder_grid.due(n) {
            // The encoder sits at the pinion end of the torsion bar (delta_P, section 3.2).
            let col = x[3] * p.screw_to_pinion() + (ANGLE_NOISE_DEG * noise.normal()).to_radians();
            column_sample = f64::from(encoder.angle(sensor.raw_from_angle(col)).0).to_degrees();
        }
        if n.is_multiple_of(ticks_per_position) {
            drive.position_step(x[1]);
        }
        let v = drive.current_step(measured);
        ode.rk4(&mut x, v, h);
    }
    traffic
}

/// Linear interpolation in `(t, value)` pairs at `at`; `None` outside them.
fn at(series: &[(f64, f64)], at: f64) -> Option<f64> {
    let j = series.partition_point(|&(t, _)| t < at);
    if j == 0 || j >= series.len() {
        return (j < series.len() && (series[j].0 - at).abs() < 1e-12).then(|| series[j].1);
    }
    let ((t0, v0), (t1, v1)) = (series[j - 1], series[j]);
    Some(v0 + (v1 - v0) * (at - t0) / (t1 - t0))
}

/// The value last sent at or before `t`.
fn last_before(series: &[(f64, f64)], t: f64) -> Option<f64> {
    let j = series.partition_point(|&(s, _)| s <= t);
    (j > 0).then(|| series[j - 1].1)
}

/// One row of a logger that writes a row as each TPDO2 arrives ([`LoggedCar::Epos4StatusFrame`]).
struct StatusRow {
    /// The SYNC it answers (its index in `tpdo2` and `latched`).
    sync: usize,
    /// Stamped on arrival, s.
    t: f64,
    /// The reference frame last sent before it (its index in `references`) and its angle.
    frame: usize,
    reference: f64,
    /// The column of the ECU's last status frame, the position and current of that SYNC.
    sw: f64,
    motor: f64,
    current: f64,
}

/// The rows such a logger writes off `traffic`: one per TPDO2 from the first it can fill (a
/// position, a column and a reference already on the bus).
fn status_frame_rows(traffic: &Traffic) -> Vec<StatusRow> {
    let mut rows = Vec::with_capacity(traffic.tpdo2.len());
    for (sync, &(sent, current)) in traffic.tpdo2.iter().enumerate() {
        let t = sent + FRAME_S;
        let seen = traffic
            .references
            .partition_point(|&(s, _)| s <= t - FRAME_S);
        let (Some(frame), Some(motor), Some(sw)) = (
            seen.checked_sub(1),
            last_before(&traffic.tpdo1, t - FRAME_S),
            last_before(&traffic.status, t - FRAME_S),
        ) else {
            continue;
        };
        rows.push(StatusRow {
            sync,
            t,
            frame,
            reference: traffic.references[frame].1,
            sw,
            motor,
            current,
        });
    }
    rows
}

/// The rows of the case's log under a row-per-TPDO `logger` ([`LoggedCar::Epos4StatusFrame`])
/// whose reference column holds another frame than the one the drive latched at that row's
/// SYNC, with how many frames later the column's is (the world's truth for
/// `gap::reference_window`; empty under other loggers). Rows as [`rows_logged`] writes them,
/// before the logger's own stamping and losses.
pub fn column_off_the_latch(case: &GenCase, seed: u64, logger: &Logger) -> Vec<(usize, i64)> {
    if logger.car != LoggedCar::Epos4StatusFrame {
        return Vec::new();
    }
    let traffic = run(case, seed, ecu_clock_drift(case, seed, logger));
    status_frame_rows(&traffic)
        .iter()
        .enumerate()
        .filter_map(|(row, r)| {
            let latched = *traffic.latched.get(r.sync)?;
            (r.frame != latched).then(|| (row, r.frame as i64 - latched as i64))
        })
        .collect()
}

/// The case's EPOS4 car logged by `logger` (its `car` is one of the EPOS4 loggers).
pub fn rows_logged(case: &GenCase, seed: u64, logger: &Logger) -> Rows {
    let traffic = run(case, seed, ecu_clock_drift(case, seed, logger));
    let mut rows = Rows::default();
    match logger.car {
        LoggedCar::Epos4StatusFrame => {
            for r in status_frame_rows(&traffic) {
                rows.push(r.t, r.reference, r.sw, r.motor, r.current);
            }
        }
        LoggedCar::Direct | LoggedCar::Epos4Convert => {
            // The column's sample was taken up to one encoder period before its frame; convert
            // dates it a whole period back.
            let column: Vec<(f64, f64)> = traffic
                .status
                .iter()
                .map(|&(t, v)| (t - ENCODER_PERIOD_S, v))
                .collect();
            let mut first_row: Option<usize> = None;
            for (m, &(sent, reference)) in traffic.references.iter().enumerate() {
                let push = sent + FRAME_S;
                let (Some(sw), Some(motor), Some(current)) = (
                    at(&column, push + 0.010),
                    at(&traffic.tpdo1, push + 0.010),
                    at(&traffic.tpdo2, push + 0.005),
                ) else {
                    continue;
                };
                // Convert counts its rows from the first it could fill.
                let m0 = *first_row.get_or_insert(m);
                rows.push((m - m0 + 1) as f64 * 0.01, reference, sw, motor, current);
            }
        }
    }
    stamp_and_lose(
        &mut rows,
        logger,
        seed ^ (case.index as u64).wrapping_mul(0x2545_f491_4f6c_dd1d),
    );
    rows
}

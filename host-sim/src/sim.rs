//! The closed loop: the firmware's [`Cascade`] against the simulated actuator, at the
//! paper-mode rates, with the sensors quantised as on the car (Hall counts, 12-bit column
//! encoder).
//!
//! Timing per reference period (10 ms): the sample arrives at the start of the period and is
//! pushed first; then 20 position ticks, each followed by 10 current ticks; each current tick
//! samples the current, computes the voltage and holds it for 50 us (no computation delay is
//! modelled: the EPOS4 updates its PWM within the period).

use crate::effect_plant::{EffectPlant, PlantEffects};
use crate::logfmt::{Log, Row};
use crate::plant::{Actuator, LinearPlant, PlantError, PlantParams};
use steering_ecu::control::AntiWindup;
use steering_ecu::control::current::{CurrentOutput, CurrentStatus};
use steering_ecu::control::position::{PositionOutput, PositionStatus};
use steering_ecu::controller::SteeringController;
use steering_ecu::ecu_mode::{ColumnCascade, EcuTuning};
use steering_ecu::gains::{EposGains, GainError};
use steering_ecu::gearing::Gearing;
use steering_ecu::paper_mode::{
    CURRENT_LOOP_HZ, CURRENT_TICKS_PER_POSITION_TICK, Cascade, POSITION_LOOP_HZ,
    POSITION_TICKS_PER_REFERENCE,
};
use steering_ecu::reference::ReferenceError;
use steering_ecu::sensors::{ColumnEncoder, hall_from_motor, motor_from_hall};
use steering_ecu::tasks;
use steering_ecu::units::{Amps, MotorRad, SteeringDeg, SteeringRad, Volts};

/// Position ticks per column-encoder sample: the firmware samples it at 500 Hz.
const COLUMN_SAMPLE_TICKS: u64 =
    (tasks::ENCODER_PERIOD.as_micros() * POSITION_LOOP_HZ as u64) / 1_000_000;

/// Extra log columns a simulated run writes after the five required ones.
pub const SIM_EXTRA_COLUMNS: [&str; 3] = ["current_setpoint_a", "voltage_v", "setpoint_motor_rad"];

pub use crate::car::Controller;

/// Everything a closed-loop run depends on besides the reference.
#[derive(Debug, Clone)]
pub struct RunConfig {
    pub plant: PlantParams,
    pub gains: EposGains,
    pub anti_windup: AntiWindup,
    /// Position feedback from the Hall sensors (paper mode). `false` feeds the loop the exact
    /// motor angle, to show what the 84-count quantisation costs.
    pub hall_feedback: bool,
    /// Supply voltage = the current loop's voltage limit, V (paper: the 24 V LV battery).
    pub supply_v: f64,
    /// Log rate, Hz; must divide the 2 kHz position-loop rate. 0 = no log (benchmarks).
    pub log_rate_hz: u32,
    /// The current guard (`src/FIRMWARE.md`, "Current guard"): the voltage clamp that keeps the
    /// current predicted at the end of each period within the limit. `false` runs without it, to
    /// see the overshoot it prevents; it replaces an undocumented environment switch.
    pub current_guard: bool,
    pub controller: Controller,
    /// What the log's angle columns hold (the control loop is not affected).
    pub logged_angles: LoggedAngles,
    /// Effects added to the plant (`--plant-effects`); none runs the linear plant.
    pub effects: PlantEffects,
    /// Position-loop ticks (0.5 ms) into each reference period at which its sample is pushed:
    /// 0 at the period's start, as the vehicle's frames reach an ECU on time; a frame that
    /// arrives late within the period is taken when it arrives. At most a period less a tick.
    pub reference_push_tick: u32,
}

/// What the log's `sw_deg` and `motor_rad` columns hold.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LoggedAngles {
    /// What the car's sensors read: the 12-bit column encoder (0.088 deg steps) and the
    /// 84-count Hall angle (4.3 deg steps of the motor). Paper mode.
    #[default]
    Sensors,
    /// The plant's exact column angle (delta_P, the pinion end) and motor angle, for comparing
    /// a small-signal run with the linear model (`linear_model.rs`), where the encoder's step
    /// would be a sizeable share of a 0.5 deg signal.
    Exact,
}

impl Default for RunConfig {
    fn default() -> Self {
        RunConfig {
            plant: PlantParams::PAPER,
            gains: EposGains::PAPER,
            anti_windup: AntiWindup::ConditionalIntegration,
            hall_feedback: true,
            supply_v: 24.0,
            log_rate_hz: 1000,
            controller: Controller::Paper,
            logged_angles: LoggedAngles::Sensors,
            current_guard: true,
            effects: PlantEffects::NONE,
            reference_push_tick: 0,
        }
    }
}

/// Figures every run reports, taken over every current-loop tick (not only logged samples).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct RunSummary {
    pub duration_s: f64,
    pub max_current_a: f64,
    /// When the largest |current| occurred, s.
    pub max_current_at_s: f64,
    pub max_voltage_v: f64,
    /// Share of position ticks with the current set-point at the limit.
    pub current_limited_share: f64,
    /// Share of current ticks with the voltage at the limit.
    pub voltage_limited_share: f64,
    /// Reference samples the cascade refused (out of range or not finite).
    pub rejected_references: u32,
    pub current_ticks: u64,
}

#[derive(Debug, Clone)]
pub struct Run {
    pub log: Log,
    pub summary: RunSummary,
}

/// Why a run could not start.
#[derive(Debug)]
pub enum SimError {
    Plant(PlantError),
    Gains(GainError),
    LogRate { hz: u32 },
    Supply { volts: f64 },
    EmptyReference,
}

impl std::fmt::Display for SimError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SimError::Plant(e) => write!(f, "plant: {e}"),
            SimError::Gains(e) => write!(f, "gains: {e}"),
            SimError::LogRate { hz } => write!(
                f,
                "log rate {hz} Hz does not divide the {POSITION_LOOP_HZ} Hz position loop \
                 (try 2000, 1000, 500, 200 or 100)"
            ),
            SimError::Supply { volts } => {
                write!(f, "supply {volts} V: must be a finite voltage in (0, 60] V")
            }
            SimError::EmptyReference => write!(f, "the reference has no samples"),
        }
    }
}

impl std::error::Error for SimError {}

/// Sees every input the cascade gets and every output it gives, in call order (the golden
/// vectors of `golden.rs` are recorded through it).
pub trait Tap {
    /// The cascade was reset to this Hall count, before the first sample.
    fn reset(&mut self, hall: i32);
    fn reference(&mut self, deg: f32, result: Result<(), ReferenceError>);
    /// A position step with its Hall count and the column the controller was given (`None`:
    /// paper mode, whose loop sees only the motor).
    fn position(&mut self, hall: i32, column: Option<SteeringRad>, out: &PositionOutput);
    fn current(&mut self, measured: Amps, out: &CurrentOutput);
}

/// A tap that looks at nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct NoTap;

impl Tap for NoTap {
    fn reset(&mut self, _: i32) {}
    fn reference(&mut self, _: f32, _: Result<(), ReferenceError>) {}
    fn position(&mut self, _: i32, _: Option<SteeringRad>, _: &PositionOutput) {}
    fn current(&mut self, _: Amps, _: &CurrentOutput) {}
}

/// Run the closed loop over a reference sampled at 100 Hz (deg at the wheel; sample `n` at
/// `t = n / 100 s`), starting at rest at the first sample.
pub fn run(reference_deg: &[f64], cfg: &RunConfig) -> Result<Run, SimError> {
    run_tapped(reference_deg, cfg, &mut NoTap)
}

/// [`run`], with every cascade call shown to `tap` (Hall feedback only: the tap sees Hall counts).
/// The plant is the linear one of eqs. 1-8, or the effect plant when `cfg.effects` has any.
pub fn run_tapped(
    reference_deg: &[f64],
    cfg: &RunConfig,
    tap: &mut impl Tap,
) -> Result<Run, SimError> {
    let dt = 1.0 / CURRENT_LOOP_HZ as f64;
    if cfg.effects.is_none() {
        let mut plant = LinearPlant::new(cfg.plant, dt).map_err(SimError::Plant)?;
        run_on(&mut plant, reference_deg, cfg, tap)
    } else {
        let mut plant = EffectPlant::new(cfg.plant, cfg.effects, dt).map_err(SimError::Plant)?;
        run_on(&mut plant, reference_deg, cfg, tap)
    }
}

/// The closed loop around any [`Actuator`] stepped at the current-loop rate (its parameters
/// must be `cfg.plant`: the controller's gearing and winding model are taken from there).
pub fn run_on<A: Actuator>(
    plant: &mut A,
    reference_deg: &[f64],
    cfg: &RunConfig,
    tap: &mut impl Tap,
) -> Result<Run, SimError> {
    let first = *reference_deg.first().ok_or(SimError::EmptyReference)?;
    let log_every = match cfg.log_rate_hz {
        0 => None,
        hz if POSITION_LOOP_HZ.is_multiple_of(hz) => Some(POSITION_LOOP_HZ / hz),
        hz => return Err(SimError::LogRate { hz }),
    };
    if !(cfg.supply_v.is_finite() && cfg.supply_v > 0.0 && cfg.supply_v <= 60.0) {
        return Err(SimError::Supply {
            volts: cfg.supply_v,
        });
    }
    let si = cfg.gains.to_si().map_err(SimError::Gains)?;
    let gearing = Gearing::new(
        cfg.plant.belt_reduction as f32,
        cfg.plant.tau_bs as f32,
        cfg.plant.tau_p as f32,
    )
    .ok_or(SimError::Plant(PlantError::BadParameter {
        name: "gear ratios",
        value: cfg.plant.motor_per_pinion(),
    }))?;
    let mut cascade = match cfg.controller {
        Controller::Paper => {
            let mut c = Cascade::new(&si, gearing);
            c.set_anti_windup(cfg.anti_windup);
            c.set_winding(cfg.plant.ra as f32, cfg.plant.la as f32);
            c.set_voltage_limit(Volts(cfg.supply_v as f32));
            SteeringController::Paper(c)
        }
        Controller::Ecu => {
            let mut c = ColumnCascade::new(&si, gearing, EcuTuning::PAPER);
            c.set_anti_windup(cfg.anti_windup);
            c.set_winding(cfg.plant.ra as f32, cfg.plant.la as f32);
            c.set_voltage_limit(Volts(cfg.supply_v as f32));
            SteeringController::Ecu(c)
        }
    };
    if !cfg.current_guard {
        // The guard needs the winding model; a winding it refuses (NaN) leaves it off.
        cascade.set_winding(f32::NAN, 0.0);
    }
    let encoder = ColumnEncoder { zero_raw: 0 };

    plant.set_at_rest(first.to_radians());
    cascade.reset(hall_from_motor(plant.motor_rad()));
    tap.reset(hall_from_motor(plant.motor_rad()));

    let mut log = match log_every {
        Some(_) => Log::with_extra_columns(&SIM_EXTRA_COLUMNS),
        None => Log::default(),
    };
    // What the car is, for `gap`: this loop is the direct drive (the cascade on Hall counts).
    log.comments = crate::car::header_lines(crate::car::CarDrive::Direct, cfg.controller);
    log.comments.push("current: interval-mean".into());
    log.comments.push("reference: period-ending".into());
    let mut summary = RunSummary::default();
    let mut current_limited = 0u64;
    let mut voltage_limited = 0u64;
    let mut tick: u64 = 0;
    let mut column = None;
    let dt_position = 1.0 / POSITION_LOOP_HZ as f64;
    // The logged current is the mean over the interval that ends at the row (what the 0x102
    // frame and the EPOS4's averaged current report), not an instant of the PWM chatter.
    let (mut current_sum, mut current_n) = (0.0f64, 0u32);

    let push_tick = cfg
        .reference_push_tick
        .min(POSITION_TICKS_PER_REFERENCE - 1);
    for &sample in reference_deg {
        for j in 0..POSITION_TICKS_PER_REFERENCE {
            if j == push_tick {
                let pushed = cascade.push_reference(SteeringDeg(sample as f32));
                tap.reference(sample as f32, pushed);
                if pushed.is_err() {
                    summary.rejected_references += 1;
                }
            }
            let hall = hall_from_motor(plant.motor_rad());
            let pos = match &mut cascade {
                SteeringController::Paper(c) if cfg.hall_feedback => {
                    let pos = c.position_step(hall);
                    tap.position(hall, None, &pos);
                    pos
                }
                SteeringController::Paper(c) => {
                    c.position_step_at(MotorRad(plant.motor_rad() as f32))
                }
                SteeringController::Ecu(c) => {
                    // The firmware reads the column encoder at 500 Hz (`tasks::ENCODER_PERIOD`)
                    // and the position loop uses the newest sample.
                    if tick.is_multiple_of(COLUMN_SAMPLE_TICKS) {
                        column = Some(encoder.angle(encoder.raw_from_angle(plant.column_rad())));
                    }
                    let pos = c.position_step(hall, column);
                    tap.position(hall, column, &pos);
                    pos
                }
            };
            if pos.status == PositionStatus::Saturated {
                current_limited += 1;
            }
            let mut voltage = 0.0f64;
            for _ in 0..CURRENT_TICKS_PER_POSITION_TICK {
                let measured = Amps(plant.current_a() as f32);
                let out = cascade.current_step(measured);
                tap.current(measured, &out);
                if matches!(
                    out.status,
                    CurrentStatus::Saturated | CurrentStatus::CurrentLimited
                ) {
                    voltage_limited += 1;
                }
                voltage = out.voltage.0 as f64;
                summary.max_voltage_v = summary.max_voltage_v.max(voltage.abs());
                plant.step(voltage);
                current_sum += plant.current_a();
                current_n += 1;
                if plant.current_a().abs() > summary.max_current_a {
                    summary.max_current_a = plant.current_a().abs();
                    summary.max_current_at_s = tick as f64 * dt_position;
                }
            }
            tick += 1;
            // A row at the end of every log interval: the angles at that instant, the current
            // averaged over the interval, the reference in force over it.
            if let Some(every) = log_every
                && tick.is_multiple_of(every as u64)
            {
                let (sw_rad, motor_rad) = match cfg.logged_angles {
                    LoggedAngles::Sensors => (
                        encoder.angle(encoder.raw_from_angle(plant.column_rad())).0 as f64,
                        motor_from_hall(hall_from_motor(plant.motor_rad())).0 as f64,
                    ),
                    LoggedAngles::Exact => (plant.column_rad(), plant.motor_rad()),
                };
                let current_mean = current_sum / f64::from(current_n.max(1));
                (current_sum, current_n) = (0.0, 0);
                log.push(
                    Row {
                        t: tick as f64 * dt_position,
                        ref_sw_deg: sample,
                        sw_deg: sw_rad.to_degrees(),
                        motor_rad,
                        current_a: current_mean,
                    },
                    &[
                        cascade.current_setpoint().0 as f64,
                        voltage,
                        cascade.setpoint().position.0 as f64,
                    ],
                );
            }
        }
    }
    summary.duration_s = tick as f64 * dt_position;
    summary.current_ticks = tick * CURRENT_TICKS_PER_POSITION_TICK as u64;
    summary.current_limited_share = current_limited as f64 / tick.max(1) as f64;
    summary.voltage_limited_share = voltage_limited as f64 / summary.current_ticks.max(1) as f64;
    Ok(Run { log, summary })
}

/// Reference samples per second, for scenario builders (defined beside them, in host-io).
pub use crate::scenario::REFERENCE_RATE_HZ;

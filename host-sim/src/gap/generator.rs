//! The selftest's own world, independent of the diagnosis's model: the paper's actuator as a
//! nonlinear ODE integrated by RK4 at the current-loop step, under the firmware's own
//! [`Cascade`] at the firmware's rates, with effects in forms and places that differ from the
//! candidates the diagnosis fits, and logs written as a logger on the car writes them.
//!
//! | hidden label       | here                                       | the diagnosis's candidate |
//! |--------------------|--------------------------------------------|---------------------------|
//! | `coulomb_friction` | smooth (tanh) friction at the rack          | saturated-linear, motor   |
//! | `backlash`         | dead band in the belt (a spring with play)  | play at the column        |
//! | `tire_ground`      | Dahl tyre force at the rack                 | elasto-plastic bristle    |
//! | `delay`            | the reference pushed late (0.5 ms steps)    | interpolated reference    |
//! | `parameters`       | one or two Table 4 parameters x2-3 or /2-3  | `identify`'s refit        |
//!
//! Every case has all nine Table 4 parameters off by up to 10 % (no car matches the table).
//! Logs are written at 100, 200 or 1000 Hz: the column and motor angles as instants, the
//! current as the mean over the row's interval plus sensor noise; the rows' stamps are late
//! by 0-3 ms against the instants the samples were taken (a logger stamps on receipt).
//!
//! The log's timing belongs to the logger, not to the car, so each case also draws a
//! [`Logger`] of its own, from a stream apart from the car's (the car of a seed and index is
//! the same whichever logger writes it): which reference a row at a reference instant holds
//! (the previous one, as host-sim and steer-can write, or already the new one), its rate,
//! stamp jitter, rows lost as in a CAN recording, and no header lines. Every logger samples
//! the world's own simulation at its own rate; none rewrites another's log.

use super::rng;
use super::{CurrentSamples, Record};
use crate::plant::{Actuator, PlantParams};
use crate::scenario::Sweep;
use steering_ecu::gains::EposGains;
use steering_ecu::gearing::Gearing;
use steering_ecu::paper_mode::{
    CURRENT_LOOP_HZ, CURRENT_TICKS_PER_POSITION_TICK, Cascade, POSITION_TICKS_PER_REFERENCE,
};
use steering_ecu::sensors::{
    COLUMN_ENCODER_COUNTS, ColumnEncoder, hall_from_motor, motor_from_hall,
};
use steering_ecu::units::{Amps, SteeringDeg, Volts};

/// What the world hides, in its own forms and units.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Truth {
    /// The car's plant: Table 4 off by up to 10 % (more in the `parameters` class). Written
    /// as each identified parameter's factor against Table 4, so a miss can be read.
    #[serde(rename = "table4_factors", serialize_with = "table4_factors")]
    pub plant: PlantParams,
    /// Smooth Coulomb friction at the rack, N (0 = none).
    pub rack_friction_n: f64,
    /// Play in the belt, full width, expressed at the steering column, deg (0 = none).
    pub belt_play_deg: f64,
    /// Dahl tyre: largest force at the rack, N (0 = none), and its rest stiffness, N/mm.
    pub dahl_force_n: f64,
    pub dahl_stiffness_n_per_mm: f64,
    /// The reference reaches the ECU this late, s.
    pub reference_delay_s: f64,
    /// What no candidate is ([`Unmodelled`]); [`Unmodelled::NONE`] in every case of
    /// [`draw`].
    pub unmodelled: Unmodelled,
}

/// Effects the diagnosis has no candidate for and Table 4 does not hold, in this world's own
/// forms: a car with one is answered right by `unexplained` or `parameters`, never by a named
/// effect and never by `none` ([`draw_unmodelled`]).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Unmodelled {
    /// The motor's torque constant, and with it its back-EMF constant, against Table 1's
    /// 52.5 mNm/A (1 = the table's).
    pub torque_constant_factor: f64,
    /// Offset of the current sensor, A: the ECU's current loop and the log read the same one.
    pub current_offset_a: f64,
    /// Cogging torque at the motor shaft, Nm: a sine of [`COGGING_PERIODS_PER_REV`] periods
    /// per motor turn.
    pub cogging_nm: f64,
    /// The column encoder's zero set at bring-up off the rack's centre, counts of 360/4096 deg:
    /// the ECU reads the column this many counts high, and logs what it reads.
    pub column_zero_counts: i32,
}

impl Truth {
    /// The car `plant` with no effect.
    pub fn effect_free(plant: PlantParams) -> Truth {
        Truth {
            plant,
            rack_friction_n: 0.0,
            belt_play_deg: 0.0,
            dahl_force_n: 0.0,
            dahl_stiffness_n_per_mm: 0.0,
            reference_delay_s: 0.0,
            unmodelled: Unmodelled::NONE,
        }
    }
}

impl Unmodelled {
    /// Nothing unmodelled.
    pub const NONE: Unmodelled = Unmodelled {
        torque_constant_factor: 1.0,
        current_offset_a: 0.0,
        cogging_nm: 0.0,
        column_zero_counts: 0,
    };

    /// The ECU's column encoder: its zero word [`Unmodelled::column_zero_counts`] off the one
    /// that reads the rack's centre as straight ahead (the sensor's own word, zero 0).
    pub fn column_encoder(&self) -> ColumnEncoder {
        let counts = i64::from(COLUMN_ENCODER_COUNTS);
        ColumnEncoder {
            zero_raw: (-i64::from(self.column_zero_counts)).rem_euclid(counts) as u16,
        }
    }
}

/// Cogging periods per motor turn: the least common multiple of a 12-slot, 8-pole motor's
/// slots and poles (the world's choice; Table 1 does not give the motor's build).
pub const COGGING_PERIODS_PER_REV: f64 = 24.0;

fn table4_factors<S: serde::Serializer>(plant: &PlantParams, s: S) -> Result<S::Ok, S::Error> {
    use serde::ser::SerializeMap;
    let table = PlantParams::PAPER.identified();
    let mut map = s.serialize_map(Some(table.len()))?;
    for ((name, car), (_, paper)) in plant.identified().iter().zip(table.iter()) {
        // A parameter the table gives as zero has no factor: its value then.
        let v = if *paper == 0.0 { *car } else { car / paper };
        map.serialize_entry(name, &((v * 1e3).round() / 1e3))?;
    }
    map.end()
}

/// One generated case: what it hides and how its log is written.
#[derive(Debug, Clone, serde::Serialize)]
pub struct GenCase {
    pub index: usize,
    pub scenario: String,
    /// Hidden labels, sorted (`parameters` for that class); empty for none.
    pub hidden: Vec<String>,
    pub truth: Truth,
    pub log_rate_hz: u32,
    /// How late the rows are stamped, s.
    pub skew_s: f64,
    #[serde(skip)]
    pub reference: Vec<f64>,
    /// The logger drawn with the case, for a run that diagnoses the car as another logger
    /// wrote it (the case's own log, [`rows_of`], is [`Logger::ours`]).
    #[serde(skip)]
    pub logger: Logger,
}

pub use super::record::ReferenceConvention;

/// How a log is written from the world: the logger's part of a log's timing.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Logger {
    pub reference: ReferenceConvention,
    /// Rows per second (the row grid).
    pub rate_hz: u32,
    /// The direct drive only: each row's current is the sensor's sample at the row's instant
    /// (a logger that reads the ECU's last current sample), not the mean over the row's
    /// interval that host-sim's logs and the 0x102 frame carry.
    pub instant_current: bool,
    /// A team's signs: the current written negated (a current sensor mounted the other way
    /// round) or the reference (the vehicle computer's convention against the car's).
    pub negated: Negated,
    /// The direct drive above 100 Hz only: the logger writes its rows faster than the car's
    /// status frames come (one a reference period, [`FRAME_LATENCY_S`] after its end), each
    /// row holding the last frame received: the column at the frame's period end, the
    /// current its period's mean. A vehicle computer's logger of the CAN bus.
    pub held_frames: bool,
    /// Stamp jitter, s: each stamp lies within +-this of the row's place on the logger's grid
    /// (uniform), the rows kept in order as a receiver stamps frames in the order they come.
    pub jitter_s: f64,
    /// The chance that a row is lost (a frame a CAN recording missed).
    pub drop_chance: f64,
    /// Writes the header lines host-sim and steer-can write (`# drive: direct`, ...,
    /// `# reference: ...`); a team's own logger writes none.
    pub header: bool,
    /// Which car it logs, and how: the direct drive on the logger's grid, or the world's
    /// EPOS4 car ([`super::generator_epos4`]) as `steer-can convert` or a team's logger of
    /// the drive's status frames writes it.
    pub car: LoggedCar,
    /// The EPOS4 car only: its ECU runs on a clock of its own, drawn per car 20-100 ppm off
    /// the vehicle computer's either way, so its SYNC grid walks against the reference frames
    /// (a crystal against a PC's); otherwise one clock.
    pub drifting_clock: bool,
}

/// The car a [`Logger`] logs, and how.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoggedCar {
    /// The direct drive, rows on the logger's grid at its rate.
    #[default]
    Direct,
    /// The EPOS4 car, a row per reference period as `steer-can convert` builds it, with its
    /// header lines.
    Epos4Convert,
    /// The EPOS4 car, a row per TPDO2 as it arrives (the drive's SYNC samples), no header.
    Epos4StatusFrame,
}

/// A column a team's [`Logger`] writes with the other sign than the car's.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum Negated {
    /// Every column as the car has it.
    #[default]
    None,
    /// The current (a sensor mounted the other way round).
    Current,
    /// The reference (the vehicle computer's convention against the car's).
    Reference,
}

/// A logger of the direct drive can write at `rate_hz`: 100 Hz (the reference's rate) to
/// 1 kHz, a whole number of the plant's current-loop ticks a row.
pub fn logs_at(rate_hz: u32) -> bool {
    (100..=1000).contains(&rate_hz) && CURRENT_LOOP_HZ.is_multiple_of(rate_hz)
}

/// The jitter a jittery logger draws, s: +-1 ms, a receiver's stamping on a loaded host.
pub const LOGGER_JITTER_S: f64 = 1e-3;
/// The share of rows a lossy logger drops.
pub const LOGGER_DROP_CHANCE: f64 = 0.01;

impl Logger {
    /// Ours: the reference of the period ending at each row, stamps on the logger's grid,
    /// every row, the header lines.
    pub fn ours(rate_hz: u32) -> Logger {
        Logger {
            reference: ReferenceConvention::PeriodEnding,
            rate_hz,
            jitter_s: 0.0,
            drop_chance: 0.0,
            header: true,
            car: LoggedCar::Direct,
            drifting_clock: false,
            instant_current: false,
            negated: Negated::None,
            held_frames: false,
        }
    }

    /// A team's logger for case `index` of a run seeded with `seed`: each property drawn
    /// apart (convention, rate 100/200/1000 Hz, jitter 0 or +-1 ms, none or 1 % of rows
    /// lost), no header lines. Its own stream: drawing it changes nothing of the car.
    pub fn draw(seed: u64, index: usize) -> Logger {
        let mut rng = rng::seeded(
            seed.wrapping_mul(0x4f1b_bcdc_bfa5_3e0b)
                ^ (index as u64).wrapping_mul(0xd1b5_4a32_d192_ed03),
        );
        let reference = if rng.unit() < 0.5 {
            ReferenceConvention::PeriodEnding
        } else {
            ReferenceConvention::PeriodStarting
        };
        let rate_hz = [100, 200, 1000][(rng.next_u64() % 3) as usize];
        let jitter_s = if rng.unit() < 0.5 {
            0.0
        } else {
            LOGGER_JITTER_S
        };
        let drop_chance = if rng.unit() < 0.5 {
            0.0
        } else {
            LOGGER_DROP_CHANCE
        };
        Logger {
            reference,
            rate_hz,
            jitter_s,
            drop_chance,
            header: false,
            car: LoggedCar::Direct,
            drifting_clock: false,
            instant_current: false,
            negated: Negated::None,
            held_frames: false,
        }
    }

    /// A short name: `ending 100 Hz`, `starting 1000 Hz +-1 ms 1 % lost`, `... header`.
    pub fn describe(&self) -> String {
        let mut s = match self.car {
            LoggedCar::Direct => format!("{} {} Hz", self.reference.short(), self.rate_hz),
            LoggedCar::Epos4Convert => "EPOS4 car, steer-can convert".into(),
            LoggedCar::Epos4StatusFrame => "EPOS4 car, a row per TPDO".into(),
        };
        if self.jitter_s > 0.0 {
            s.push_str(&format!(" +-{:.0} ms", 1e3 * self.jitter_s));
        }
        if self.drop_chance > 0.0 {
            s.push_str(&format!(" {:.0} % lost", 100.0 * self.drop_chance));
        }
        if self.drifting_clock {
            s.push_str(" ECU clock drifting");
        }
        if self.instant_current {
            s.push_str(" current at the instant");
        }
        if self.held_frames {
            s.push_str(" holding 100 Hz frames");
        }
        match self.negated {
            Negated::None => {}
            Negated::Current => s.push_str(" current negated"),
            Negated::Reference => s.push_str(" reference negated"),
        }
        if self.header {
            s.push_str(" header");
        }
        s
    }
}

/// Rack speed of the friction's tanh, m/s: sharp against the rack's 10-100 mm/s in a sweep,
/// smooth enough for RK4 at 50 us.
const FRICTION_SPEED_M_S: f64 = 1e-3;
/// Sensor noise on the interval-mean current, A (the EPOS4's averaged current).
const CURRENT_NOISE_A: f64 = 0.1;
/// Noise on the column angle before the 12-bit encoder's quantisation, deg.
const ANGLE_NOISE_DEG: f64 = 0.01;

/// Table 4's parameter `name` of `p` scaled by `f`.
fn scale_parameter(p: &mut PlantParams, name: &str, f: f64) {
    match name {
        "j_bs" => p.j_bs *= f,
        "j_sw" => p.j_sw *= f,
        "j_w" => p.j_w *= f,
        "k_b" => p.k_b *= f,
        "beta_b" => p.beta_b *= f,
        "beta_bs" => p.beta_bs *= f,
        "k_tb" => p.k_tb *= f,
        "beta_tb" => p.beta_tb *= f,
        _ => p.beta_sw *= f,
    }
}

/// Draw case `index` of a run seeded with `seed`. `sweep_s` is the length of a sweep; tracks
/// are 120 s.
/// Table 4 with each of its nine identified parameters off by up to 10 %, drawn in their
/// order from `rng` (every case of the world is such a car before its effect).
fn within_ten_percent(rng: &mut rng::Rng) -> PlantParams {
    let mut plant = PlantParams::PAPER;
    for (name, _) in PlantParams::PAPER.identified().iter() {
        let f = rng.range(0.9, 1.1);
        scale_parameter(&mut plant, name, f);
    }
    plant
}

pub fn draw(seed: u64, index: usize, sweep_s: f64) -> GenCase {
    let mut rng = rng::seeded(seed.wrapping_mul(0x2545_f491_4f6c_dd1d) ^ index as u64);
    let plant = within_ten_percent(&mut rng);
    let mut truth = Truth::effect_free(plant);
    let effects = ["backlash", "coulomb_friction", "delay", "tire_ground"];
    let roll = rng.unit();
    let mut hidden: Vec<String> = Vec::new();
    if roll < 0.2 {
        // none
    } else if roll < 0.35 {
        // parameters: one or two of the physically prominent ones far off.
        hidden.push("parameters".into());
        let prominent = ["k_b", "beta_bs", "j_w", "k_tb", "beta_sw"];
        let count = 1 + (rng.next_u64() % 2) as usize;
        let first = (rng.next_u64() % 5) as usize;
        for i in 0..count {
            let name = prominent[(first + 2 * i) % 5];
            let f = rng.range(2.0, 3.0);
            let f = if rng.unit() < 0.5 { f } else { 1.0 / f };
            scale_parameter(&mut truth.plant, name, f);
        }
    } else if roll < 0.8 {
        hidden.push(effects[(rng.next_u64() % 4) as usize].into());
    } else {
        let a = (rng.next_u64() % 4) as usize;
        let b = (a + 1 + (rng.next_u64() % 3) as usize) % 4;
        hidden.push(effects[a].into());
        hidden.push(effects[b].into());
    }
    for h in &hidden {
        match h.as_str() {
            // Sizes like the candidates' ranges, in this world's own forms: 300-1200 N at the
            // rack is 0.05-0.19 Nm at the motor through tau_bs and the belt (Table 2).
            "coulomb_friction" => truth.rack_friction_n = rng.range(300.0, 1200.0),
            "backlash" => truth.belt_play_deg = rng.range(0.6, 2.5),
            "tire_ground" => {
                truth.dahl_force_n = rng.range(300.0, 1500.0);
                truth.dahl_stiffness_n_per_mm = rng.range(200.0, 1000.0);
            }
            "delay" => truth.reference_delay_s = rng.range(0.015, 0.06),
            _ => {}
        }
    }
    hidden.sort();
    let log_rate_hz = [100, 200, 1000][(rng.next_u64() % 3) as usize];
    // Whole 50 us ticks, 0-3 ms.
    let skew_s = (rng.range(0.0, 3.0e-3) * CURRENT_LOOP_HZ as f64).round() / CURRENT_LOOP_HZ as f64;
    let (scenario, reference) = if rng.unit() < 0.7 {
        let amp = if rng.unit() < 0.5 { 5.0 } else { 10.0 };
        let f1 = rng.range(3.0, 6.0);
        (
            format!("sweep {amp:.0} deg 0.2-{f1:.1} Hz"),
            Sweep {
                amplitude_deg: amp,
                f_start_hz: 0.2,
                f_end_hz: f1,
                duration_s: sweep_s,
            }
            .samples(),
        )
    } else {
        ("track 120 s".to_string(), crate::scenario::builtin_track())
    };
    GenCase {
        index,
        scenario: format!("{scenario}, {log_rate_hz} Hz, skew {:.2} ms", skew_s * 1e3),
        hidden,
        truth,
        log_rate_hz,
        skew_s,
        reference,
        logger: Logger::draw(seed, index),
    }
}

/// Case `index` of the world's cars with an effect no candidate has: the scenario, log rate,
/// stamping lag and logger of [`draw`]'s case `index`, Table 4 off by up to 10 % again, and one
/// of: the torque constant x0.7-0.8 or x1.25-1.4, a current sensor offset of 0.3-0.6 A either
/// way, 0.01-0.03 Nm of cogging at the motor (0.2-0.6 A of Table 1's torque constant), or the
/// column encoder's zero 3-11 counts (0.26-0.97 deg) off either way.
/// Labelled `unmodelled`. Its own stream: the world's case `index` is unchanged.
pub fn draw_unmodelled(seed: u64, index: usize, sweep_s: f64) -> GenCase {
    let mut case = draw(seed, index, sweep_s);
    let mut rng = rng::seeded(
        seed.wrapping_mul(0x7c3a_91e5_2b6d_f04f)
            ^ (index as u64).wrapping_mul(0x94d0_49bb_1331_11eb),
    );
    let plant = within_ten_percent(&mut rng);
    let either_way = |rng: &mut rng::Rng, v: f64| if rng.unit() < 0.5 { v } else { -v };
    let mut unmodelled = Unmodelled::NONE;
    let what = match rng.next_u64() % 4 {
        0 => {
            let f = if rng.unit() < 0.5 {
                rng.range(0.7, 0.8)
            } else {
                rng.range(1.25, 1.4)
            };
            unmodelled.torque_constant_factor = f;
            format!("torque constant x{f:.2}")
        }
        1 => {
            let a = rng.range(0.3, 0.6);
            unmodelled.current_offset_a = either_way(&mut rng, a);
            format!("current offset {:+.2} A", unmodelled.current_offset_a)
        }
        2 => {
            unmodelled.cogging_nm = rng.range(0.01, 0.03);
            format!("cogging {:.3} Nm", unmodelled.cogging_nm)
        }
        _ => {
            // 3-11 counts (0.26-0.97 deg) either way.
            let counts = 3 + (rng.next_u64() % 9) as i32;
            unmodelled.column_zero_counts = if rng.unit() < 0.5 { counts } else { -counts };
            format!(
                "column zero {:+.2} deg",
                f64::from(unmodelled.column_zero_counts) * 360.0 / f64::from(COLUMN_ENCODER_COUNTS)
            )
        }
    };
    case.truth = Truth {
        unmodelled,
        ..Truth::effect_free(plant)
    };
    case.hidden = vec!["unmodelled".into()];
    case.scenario = format!("{}, {what}", case.scenario);
    case
}

/// State: winding current, motor angle and speed, nut angle and speed, column angle and
/// speed, Dahl force at the rack.
pub(super) type State = [f64; 8];

/// The plant at rest with the column at `column_rad`, the belt unloaded.
pub(super) fn at_rest(p: &PlantParams, column_rad: f64) -> State {
    let th_bs = column_rad / p.screw_to_pinion();
    [
        0.0,
        th_bs * p.belt_reduction,
        0.0,
        th_bs,
        0.0,
        column_rad,
        0.0,
        0.0,
    ]
}

/// The ODE of the paper's plant (eqs. 1-8 with the printing errors corrected, see
/// `plant-and-control.md`), written out term by term with the effects in place.
#[derive(Debug, Clone)]
pub(super) struct Ode {
    p: PlantParams,
    j_bs: f64,
    g: f64,
    belt_half_play_rad: f64,
    truth: Truth,
}

impl Ode {
    pub(super) fn new(truth: Truth) -> Ode {
        let p = truth.plant;
        let g = p.screw_to_pinion();
        Ode {
            p,
            j_bs: p.j_bs_equivalent(),
            g,
            // Column degrees to nut radians: the nut turns 1/g times the pinion.
            belt_half_play_rad: 0.5 * truth.belt_play_deg.to_radians() / g,
            truth,
        }
    }

    fn deriv(&self, x: &State, v: f64) -> State {
        let p = &self.p;
        let [i, th_rot, w_rot, th_bs, w_bs, d_sw, w_sw, f_dahl] = *x;
        let tb = 1.0 / p.belt_reduction;
        // Belt: a spring with play; its damper acts only while the belt is taut.
        let stretch = x[1] * tb - th_bs;
        let h = self.belt_half_play_rad;
        let (spring, taut) = if stretch > h {
            (stretch - h, 1.0)
        } else if stretch < -h {
            (stretch + h, 1.0)
        } else {
            (0.0, 0.0)
        };
        let t_belt = p.k_b * spring + taut * p.beta_b * (w_rot * tb - w_bs);
        // Torsion bar between the pinion and the column.
        let t_tb = p.k_tb * (self.g * th_bs - d_sw) + p.beta_tb * (self.g * w_bs - w_sw);
        // Rack friction (smooth) and the Dahl tyre, both at the rack, to the nut by tau_bs.
        let v_rack = w_bs * p.tau_bs;
        let f_fric = self.truth.rack_friction_n * (v_rack / FRICTION_SPEED_M_S).tanh();
        let t_rack = (f_fric + f_dahl) * p.tau_bs;
        let u = &self.truth.unmodelled;
        let cogging = u.cogging_nm * (COGGING_PERIODS_PER_REV * th_rot).sin();
        let (kt, ke) = (
            p.kt * u.torque_constant_factor,
            p.ke * u.torque_constant_factor,
        );
        let di = (v - p.ra * i - ke * w_rot) / p.la;
        let dw_rot = (kt * i - p.r * w_rot - tb * t_belt - cogging) / p.j_rot;
        let dw_bs = (t_belt - p.beta_bs * w_bs - self.g * t_tb - t_rack) / self.j_bs;
        let dw_sw = (t_tb - p.beta_sw * w_sw) / p.j_sw;
        // Dahl: dF/dt = sigma v (1 - F/Fmax sgn v).
        let df = if self.truth.dahl_force_n > 0.0 {
            let sigma = self.truth.dahl_stiffness_n_per_mm * 1e3;
            sigma * v_rack * (1.0 - f_dahl / self.truth.dahl_force_n * v_rack.signum())
        } else {
            0.0
        };
        [di, w_rot, dw_rot, w_bs, dw_bs, w_sw, dw_sw, df]
    }

    pub(super) fn rk4(&self, x: &mut State, v: f64, h: f64) {
        let add = |a: &State, b: &State, s: f64| -> State {
            let mut o = *a;
            for (o, b) in o.iter_mut().zip(b) {
                *o += s * b;
            }
            o
        };
        let k1 = self.deriv(x, v);
        let k2 = self.deriv(&add(x, &k1, 0.5 * h), v);
        let k3 = self.deriv(&add(x, &k2, 0.5 * h), v);
        let k4 = self.deriv(&add(x, &k3, h), v);
        for j in 0..8 {
            x[j] += h / 6.0 * (k1[j] + 2.0 * k2[j] + 2.0 * k3[j] + k4[j]);
        }
        if self.truth.dahl_force_n > 0.0 {
            x[7] = x[7].clamp(-self.truth.dahl_force_n, self.truth.dahl_force_n);
        }
    }
}

/// The world's plant as an [`Actuator`], so `sim::run_on` can close any of the firmware's
/// loops around it: a second plant, integrated and written independently of
/// `effect_plant.rs`, to check figures measured on that one (the track with play and
/// friction).
#[derive(Debug, Clone)]
pub struct RkPlant {
    ode: Ode,
    x: State,
}

impl RkPlant {
    /// The world of `truth` (its plant and its effects; the reference delay is the loop's
    /// and is not applied here).
    pub fn new(truth: Truth) -> RkPlant {
        RkPlant {
            ode: Ode::new(truth),
            x: [0.0; 8],
        }
    }
}

impl Actuator for RkPlant {
    fn step(&mut self, voltage_v: f64) {
        self.ode
            .rk4(&mut self.x, voltage_v, 1.0 / CURRENT_LOOP_HZ as f64);
    }
    fn current_a(&self) -> f64 {
        self.x[0]
    }
    fn motor_rad(&self) -> f64 {
        self.x[1]
    }
    fn motor_speed_rad_s(&self) -> f64 {
        self.x[2]
    }
    fn column_rad(&self) -> f64 {
        self.x[3] * self.ode.g
    }
    fn set_at_rest(&mut self, column_rad: f64) {
        self.x = at_rest(&self.ode.p, column_rad);
    }
}

/// A log as rows: `t` (the logger's stamps, s), the reference the logger's convention puts
/// in each row, the column angle (deg), the motor angle (rad), the interval-mean current (A).
#[derive(Debug, Clone, Default)]
pub struct Rows {
    pub t: Vec<f64>,
    /// Each row's place on the logger's grid, s: its stamp without jitter (what a lost row
    /// leaves a gap in).
    pub grid_s: Vec<f64>,
    pub reference: Vec<f64>,
    pub sw_deg: Vec<f64>,
    pub motor_rad: Vec<f64>,
    pub current_a: Vec<f64>,
}

impl Rows {
    /// One row.
    pub(super) fn push(
        &mut self,
        t: f64,
        reference: f64,
        sw_deg: f64,
        motor_rad: f64,
        current_a: f64,
    ) {
        self.t.push(t);
        self.grid_s.push(t);
        self.reference.push(reference);
        self.sw_deg.push(sw_deg);
        self.motor_rad.push(motor_rad);
        self.current_a.push(current_a);
    }
}

/// Run the case's world and write its log as our logger does at the case's rate.
pub fn rows_of(case: &GenCase, seed: u64) -> Rows {
    rows_logged(case, seed, &Logger::ours(case.log_rate_hz))
}

/// Run the case's world and write its log as `logger` does: the logger samples the
/// simulation at its own rate, the case's stamping lag (`skew_s`) is its receiver's, and
/// the sensor noise of each row is the same draw whatever the logger's jitter and losses.
pub fn rows_logged(case: &GenCase, seed: u64, logger: &Logger) -> Rows {
    let truth = case.truth;
    let ode = Ode::new(truth);
    let nominal = PlantParams::PAPER;
    let mut rows = Rows::default();
    let Some(&first) = case.reference.first() else {
        return rows;
    };
    // The ECU is set up from the table, not from the car.
    let Ok(gains) = EposGains::PAPER.to_si() else {
        return rows;
    };
    let Some(gearing) = Gearing::new(
        nominal.belt_reduction as f32,
        nominal.tau_bs as f32,
        nominal.tau_p as f32,
    ) else {
        return rows;
    };
    let mut cascade = Cascade::new(&gains, gearing);
    cascade.set_winding(nominal.ra as f32, nominal.la as f32);
    cascade.set_voltage_limit(Volts(24.0));
    let p = truth.plant;
    let mut x = at_rest(&p, first.to_radians());
    cascade.reset(hall_from_motor(x[1]));
    let mut rng = rng::seeded(seed ^ (case.index as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15));
    let sensor = ColumnEncoder { zero_raw: 0 };
    let encoder = truth.unmodelled.column_encoder();
    let h = 1.0 / CURRENT_LOOP_HZ as f64;
    let ticks_per_row = CURRENT_LOOP_HZ as u64 / logger.rate_hz.max(1) as u64;
    // Which reference a row holds: the one of the half row interval before its stamp
    // (period-ending: at a reference instant, the previous sample) or after it.
    let reference_lead = match logger.reference {
        ReferenceConvention::PeriodEnding => -0.5,
        ReferenceConvention::PeriodStarting => 0.5,
    };
    let skew_ticks = (case.skew_s * CURRENT_LOOP_HZ as f64).round() as u64;
    // The reference's late arrival, in position ticks (0.5 ms).
    let delay_pos = (truth.reference_delay_s * (CURRENT_LOOP_HZ as f64)
        / CURRENT_TICKS_PER_POSITION_TICK as f64)
        .round() as i64;
    let n_pos = case.reference.len() as i64 * POSITION_TICKS_PER_REFERENCE as i64;
    let period_pos = POSITION_TICKS_PER_REFERENCE as i64;
    let offset_a = truth.unmodelled.current_offset_a;
    let mut current_integral = 0.0;
    let mut integral_at_last_row = 0.0;
    let mut tick: u64 = 0;
    let mut tick_at_last_row: u64 = 0;
    let ticks_per_period = CURRENT_LOOP_HZ as u64 / steering_ecu::paper_mode::REFERENCE_HZ as u64;
    let mut frames: Vec<Frame> = Vec::new();
    let mut integral_at_last_frame = 0.0;
    // The column as the ECU's encoder reads it, deg: the encoder sits at the pinion end of
    // the torsion bar (delta_P of section 3.2), not at the steering wheel.
    let column_deg = |screw_rad: f64, rng: &mut rng::Rng| {
        let col = screw_rad * p.screw_to_pinion() + (ANGLE_NOISE_DEG * rng.normal()).to_radians();
        (encoder.angle(sensor.raw_from_angle(col)).0 as f64).to_degrees()
    };
    // The motor as its Hall counts read it, rad.
    let motor_rad = |motor: f64| motor_from_hall(hall_from_motor(motor)).0 as f64;
    for n in 0..n_pos {
        // The ECU receives sample m at position tick m * 20 + delay: before the first one,
        // it holds the rest angle (the first sample).
        if n == 0 || (n - delay_pos) % period_pos == 0 {
            let m =
                ((n - delay_pos).div_euclid(period_pos)).clamp(0, case.reference.len() as i64 - 1);
            let _ = cascade.push_reference(SteeringDeg(case.reference[m as usize] as f32));
        }
        let hall = hall_from_motor(x[1]);
        cascade.position_step(hall);
        for _ in 0..CURRENT_TICKS_PER_POSITION_TICK {
            let sensed = x[0] + offset_a;
            let v = cascade.current_step(Amps(sensed as f32)).voltage.0 as f64;
            // The current over the step, by the trapezoid of its ends.
            let i0 = x[0];
            ode.rk4(&mut x, v, h);
            current_integral += 0.5 * (i0 + x[0]) * h;
            tick += 1;
            // The car's status frame at each reference period's end: the column and motor
            // sampled there, the current the period's mean.
            if logger.held_frames && tick.is_multiple_of(ticks_per_period) {
                let sw_deg = column_deg(x[3], &mut rng);
                let mean =
                    (current_integral - integral_at_last_frame) / (ticks_per_period as f64 * h);
                integral_at_last_frame = current_integral;
                frames.push(Frame {
                    t: tick as f64 * h,
                    sw_deg,
                    motor_rad: motor_rad(x[1]),
                    current_a: mean + offset_a + CURRENT_NOISE_A * rng.normal(),
                });
            }
            // A row: the logger's clock ticks every row interval from the first push, but
            // what it stamps `t` was sampled `skew` earlier (it stamps on receipt).
            let stamp = tick + skew_ticks;
            if stamp.is_multiple_of(ticks_per_row) {
                let row_s = ticks_per_row as f64 * h;
                let t = stamp as f64 * h;
                // The reference the logger sent, by its convention.
                let k = (((t + reference_lead * row_s) * 100.0).floor().max(0.0) as usize)
                    .min(case.reference.len() - 1);
                let sw_deg = column_deg(x[3], &mut rng);
                let span = (tick - tick_at_last_row).max(1) as f64 * h;
                let mean_current = (current_integral - integral_at_last_row) / span;
                integral_at_last_row = current_integral;
                tick_at_last_row = tick;
                rows.t.push(t);
                rows.grid_s.push(t);
                rows.reference.push(case.reference[k]);
                rows.sw_deg.push(sw_deg);
                rows.motor_rad.push(motor_rad(x[1]));
                let current = if logger.instant_current {
                    x[0]
                } else {
                    mean_current
                };
                rows.current_a
                    .push(current + offset_a + CURRENT_NOISE_A * rng.normal());
            }
        }
    }
    if logger.held_frames {
        hold_frames(&mut rows, &frames, skew_ticks as f64 * h);
    }
    stamp_and_lose(
        &mut rows,
        logger,
        seed ^ (case.index as u64).wrapping_mul(0x2545_f491_4f6c_dd1d),
    );
    rows
}

/// From the end of a reference period to the row that first holds its status frame, s: the
/// frame's time on the bus and the receiver's.
pub const FRAME_LATENCY_S: f64 = 0.0005;

/// The car's status frame of one reference period.
struct Frame {
    /// The period's end, s on the car's clock.
    t: f64,
    sw_deg: f64,
    motor_rad: f64,
    /// The period's mean current, A.
    current_a: f64,
}

/// `rows` (sampled on the car's clock `skew_s` before their stamps) as a logger of the car's
/// status `frames` writes them: each row holds the last frame received ([`FRAME_LATENCY_S`]
/// after its period's end). The reference, the logger's own, stays as sampled; rows before
/// the first frame hold their own samples.
fn hold_frames(rows: &mut Rows, frames: &[Frame], skew_s: f64) {
    for j in 0..rows.t.len() {
        let car_time = rows.grid_s[j] - skew_s;
        let received = frames.partition_point(|f| f.t + FRAME_LATENCY_S <= car_time + 1e-9);
        if let Some(f) = received.checked_sub(1).map(|i| &frames[i]) {
            rows.sw_deg[j] = f.sw_deg;
            rows.motor_rad[j] = f.motor_rad;
            rows.current_a[j] = f.current_a;
        }
    }
}

/// The logger's receiver: each row stamped within +-`jitter_s` of its grid place (in whole
/// microseconds, as a log file holds them, and in order: a stamp never falls on or before
/// the one before), then a row lost with `drop_chance`. A logger without either is left
/// as sampled. Drawn from its own stream, apart from the sensor noise.
pub(super) fn stamp_and_lose(rows: &mut Rows, logger: &Logger, stream: u64) {
    if logger.jitter_s <= 0.0 && logger.drop_chance <= 0.0 {
        return;
    }
    let mut rng = rng::seeded(stream ^ 0x6a09_e667_f3bc_c908);
    let jitter_us = (logger.jitter_s * 1e6).round() as i64;
    let mut prev_us = i64::MIN;
    let mut kept = Rows::default();
    for k in 0..rows.t.len() {
        let (u, lost) = (rng.range(-1.0, 1.0), rng.unit() < logger.drop_chance);
        let grid_us = (rows.grid_s[k] * 1e6).round() as i64;
        // In order: a frame is received after the one before it. The bound holds still: the
        // one before is stamped at most one jitter after its own place, a row interval back.
        let stamp_us =
            (grid_us + (u * jitter_us as f64).round() as i64).max(prev_us.saturating_add(1));
        prev_us = stamp_us;
        if lost {
            continue;
        }
        kept.t.push(if jitter_us > 0 {
            stamp_us as f64 * 1e-6
        } else {
            rows.t[k]
        });
        kept.grid_s.push(rows.grid_s[k]);
        kept.reference.push(rows.reference[k]);
        kept.sw_deg.push(rows.sw_deg[k]);
        kept.motor_rad.push(rows.motor_rad[k]);
        kept.current_a.push(rows.current_a[k]);
    }
    *rows = kept;
}

/// The case's log as `logger` writes it, in the project's file format (what `host-sim gap`
/// reads): our logger's with the header lines host-sim writes of this car (the direct drive,
/// the paper controller, interval-mean current, its reference convention), a team's without.
pub fn log_of(case: &GenCase, seed: u64, logger: &Logger) -> crate::logfmt::Log {
    let rows = match logger.car {
        LoggedCar::Direct => rows_logged(case, seed, logger),
        LoggedCar::Epos4Convert | LoggedCar::Epos4StatusFrame => {
            super::generator_epos4::rows_logged(case, seed, logger)
        }
    };
    let comments = if logger.car == LoggedCar::Epos4Convert {
        // What `steer-can convert` writes of an EPOS4 car: the bus shows the drive, not the
        // ECU's controller; and, where the ECU's clock runs apart, how fast the drive's PDOs
        // (its SYNC grid) walk against the reference frames.
        let mut c: Vec<String> = vec![
            "drive: epos4".into(),
            "current: sync-sample".into(),
            "reference: period-ending".into(),
        ];
        let d = super::generator_epos4::ecu_clock_drift(case, seed, logger);
        if logger.drifting_clock {
            c.push(format!("sync-drift: {:+.1} ppm", 1e6 * d));
        }
        // Where the status frames' column samples sit before each row's end, read as convert
        // reads it: the middle of the first 10 s (or of the log).
        let middle = 0.5 * (case.reference.len() as f64 * 0.010).min(10.0);
        let age = super::generator_epos4::Phases::of(case, seed).column_age_convert_s();
        c.push(format!(
            "column-sampled: {:.2} ms before each row's end",
            1e3 * (age - d * middle).rem_euclid(0.010)
        ));
        c
    } else if logger.car == LoggedCar::Epos4StatusFrame {
        Vec::new()
    } else if logger.header {
        let mut c = super::drive::LogHeader::lines(
            super::rig::CarDrive::Direct,
            crate::sim::Controller::Paper,
        );
        c.push("current: interval-mean".into());
        c.push(format!("reference: {}", logger.reference.name()));
        c
    } else {
        Vec::new()
    };
    let negate = |v: Vec<f64>, yes: bool| {
        if yes {
            v.into_iter().map(|x| -x).collect()
        } else {
            v
        }
    };
    crate::logfmt::Log {
        t: rows.t,
        ref_sw_deg: negate(rows.reference, logger.negated == Negated::Reference),
        sw_deg: rows.sw_deg,
        motor_rad: rows.motor_rad,
        current_a: negate(rows.current_a, logger.negated == Negated::Current),
        extra: Vec::new(),
        comments,
    }
}

/// The case's log read as the diagnosis reads a file (the paper rig's columns and grid).
pub fn record_of(case: &GenCase, seed: u64) -> Record {
    let rows = rows_of(case, seed);
    let per = PlantParams::PAPER.motor_per_pinion();
    let motor_deg = rows
        .motor_rad
        .iter()
        .map(|v| (v / per).to_degrees())
        .collect();
    Record::from_samples(
        &rows.t,
        &rows.reference,
        &rows.sw_deg,
        &rows.current_a,
        Some(motor_deg),
        0.01,
        CurrentSamples::IntervalMean,
        Some(super::ReferenceConvention::PeriodEnding),
    )
}

impl GenCase {
    /// A case with the table's plant and no effect, logged at `log_rate_hz` without skew: the
    /// world the diagnosis's nominal model should reproduce.
    pub fn nominal(reference: Vec<f64>, log_rate_hz: u32) -> GenCase {
        GenCase {
            index: 0,
            scenario: "nominal".into(),
            hidden: vec![],
            truth: Truth::effect_free(PlantParams::PAPER),
            log_rate_hz,
            skew_s: 0.0,
            reference,
            logger: Logger::ours(log_rate_hz),
        }
    }
}

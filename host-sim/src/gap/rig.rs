//! A rig file: which model and controller a log came from, its parameters, and which CSV
//! columns hold the reference, the output and the effort. Three ship with host-sim
//! (`host-sim/rigs/`): the paper's actuator (the default, built in), EMPS and the BAM XL330
//! servo pendulum.

use super::{CurrentSamples, Record, ReferenceConvention};
use crate::logfmt::{LogError, Reads, Table, TimeOrder, fill_missing, hold_missing};
use crate::plant::PlantParams;
use std::path::Path;
use steering_ecu::gains::EposGains;

/// The CSV columns the diagnosis reads.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Columns {
    pub time: String,
    pub reference: String,
    /// The measured output (what the loop is meant to follow).
    pub output: String,
    /// The effort (motor current, drive voltage): where friction hides when the loop holds.
    pub effort: String,
    /// Motor angle (rad), for the segment analysis; optional.
    #[serde(default)]
    pub motor: Option<String>,
    /// A known disturbance added to the effort (EMPS pulses, V); optional.
    #[serde(default)]
    pub disturbance: Option<String>,
    /// The measured supply voltage (BAM: `input_volts_V`); required by the BAM model.
    #[serde(default)]
    pub supply: Option<String>,
    /// 1 while the drive is on, 0 when torque is disabled (BAM: `torque_enable`); required
    /// by the BAM model.
    #[serde(default)]
    pub torque_enable: Option<String>,
}

/// A rig file's gains when it gives none: the paper's Table 3.
fn paper_gains() -> EposGains {
    EposGains::PAPER
}

fn default_supply() -> f64 {
    24.0
}

/// The paper's actuator (Tables 1-4) under the firmware's cascade in paper mode.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PaperModel {
    #[serde(default)]
    pub plant: PlantParams,
    /// Table 3 in EPOS4 units, the firmware's own type (its field names are the file's keys).
    #[serde(default = "paper_gains")]
    pub gains: EposGains,
    #[serde(default = "default_supply")]
    pub supply_v: f64,
    /// Which drive closes the loops on the car (the firmware's build): the ECU's own bridge,
    /// or an EPOS4 in CSP fed a target each SYNC.
    #[serde(default)]
    pub drive: CarDrive,
    /// Which steering controller the ECU runs.
    #[serde(default)]
    pub controller: crate::sim::Controller,
    /// EPOS4 mode: how the drive's frames are timed against the log (fitted from the log
    /// when the diagnosis is not told).
    #[serde(default)]
    pub epos4: Epos4Timing,
    /// Direct drive: the position-loop tick (0.5 ms) into each reference period at which the
    /// ECU takes that period's sample. The frame crosses the bus, and the next tick of the
    /// ECU's free-running position loop takes it, so it lands a fraction of a millisecond
    /// after the vehicle computer sent it. Fitted from every log (0-2 ticks); 0 is the
    /// period's start.
    #[serde(default)]
    pub push_tick: u32,
    /// A delay the log's own timing can explain (its stamps' jitter, a reference convention
    /// the log does not state), s: a `delay` is named only beyond it.
    #[serde(default)]
    pub timing_bound_s: f64,
}

/// A log on the rig's grid, with what else its file says.
#[derive(Debug, Clone)]
pub struct LoadedLog {
    pub record: Record,
    /// The log read with each reference convention (period-ending, period-starting), where
    /// it has several rows a period on the periods' boundaries, no header states which period
    /// a boundary's row holds, and the two readings differ: a row apart, which the car's fit
    /// chooses (`drive::choose`).
    pub by_convention: Option<[Record; 2]>,
    /// What the reader had to fill in (missing samples), for the caller to show.
    pub notes: Vec<String>,
    /// The comment lines before the header, without their `#`: what the log says of the car
    /// (`drive: epos4`, ...).
    pub comments: Vec<String>,
    /// The stamps' timing (the logger's).
    pub timing: super::LogTiming,
}

pub use crate::car::CarDrive;

/// Which current an EPOS4's TPDO carries (the link's `current_object`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DriveCurrent {
    /// 0x30D1 sub 2, the current at the SYNC (the firmware's default mapping).
    #[default]
    Instantaneous,
    /// 0x30D1 sub 1, the drive's ~1 ms average at the SYNC.
    Averaged,
}

/// The timing of an EPOS4 car's log against its reference rows.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Epos4Timing {
    /// From the instant the ECU takes a reference sample to the SYNC at which the drive
    /// latches the target made from it (and samples the position and current it reports), s;
    /// in (0, one reference period]. The ECU's SYNC grid runs on its own clock, so on a car
    /// this phase is the log's, not a constant. With a [`Epos4Timing::sync_drift`], the
    /// phase at the log's start.
    pub sync_after_push_s: f64,
    /// How fast the ECU's SYNC grid walks against the reference frames, s per s: the ECU's
    /// clock against the vehicle computer's (5e-5 is 50 ppm, which moves the SYNC 6 ms later
    /// over a 120 s track). Each reference is latched at the first SYNC after it is taken,
    /// wherever the grid has walked to. 0 on one clock (the simulated car).
    #[serde(default)]
    pub sync_drift: f64,
    pub current: DriveCurrent,
    /// When, after each reference sample, the ECU's 2 ms column-encoder task samples, modulo
    /// its period, s (the ECU controller's column terms take the newest sample).
    #[serde(default)]
    pub encoder_phase_s: f64,
    /// How the log reads the drive's samples: where in each row the current is taken, and
    /// how old the column is against the row. `steer-can convert`'s by default.
    #[serde(default)]
    pub readout: Epos4Readout,
    /// Current-loop ticks (0-9, 50 us each) from the start of each reference period on the
    /// model's grid to the drive's next position-loop tick: the drive runs its 2 kHz position
    /// loop on its own clock, so where its ticks fall against the SYNC is the car's, and
    /// decides on which tick a latched target first moves the motor.
    #[serde(default)]
    pub position_phase_ticks: u32,
    /// The SYNC and the position loop's phase were fitted on the nominal model (the car is
    /// chosen before any effect), on one SYNC phase: the diagnosis fits them again with its
    /// best single candidate in the model ([`super::drive_clock::with_best`]).
    #[serde(default)]
    pub clock_from_nominal: bool,
}

impl Default for Epos4Timing {
    fn default() -> Self {
        Epos4Timing {
            sync_after_push_s: 0.005,
            sync_drift: 0.0,
            current: DriveCurrent::Instantaneous,
            encoder_phase_s: 0.0,
            readout: Epos4Readout::CONVERT,
            position_phase_ticks: 0,
            clock_from_nominal: false,
        }
    }
}

/// How an EPOS4 car's log reads the drive's SYNC samples and the ECU's column into its rows:
/// a logger's property, not the car's. `steer-can convert` interpolates the TPDO current to
/// the middle of each row's period, dates each status frame's column when the ECU measured it
/// and draws a line between those samples (one a period) to the row's end; a team's logger
/// that writes a row as each TPDO arrives holds the current the drive sampled at that SYNC
/// (the row's end) and the column of the ECU's last status frame (up to a period and an
/// encoder tick old).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Epos4Readout {
    /// Where in the row interval the current is read, a fraction of it (0.5 the middle, 1 the
    /// row's end).
    pub current_at_row: f64,
    /// How much earlier than the row's end the column was measured, s: the sample a row
    /// holds, or with `column_interpolated` the last sample before the row's end.
    pub column_age_s: f64,
    /// The column at the row's end read off a line between the sample `column_age_s` before
    /// it and the one a period later (convert's reading of the status frames), instead of the
    /// sample itself. With an age of 0 the two are one.
    #[serde(default)]
    pub column_interpolated: bool,
}

impl Epos4Readout {
    /// `steer-can convert`'s (and host-sim's) reading, with the column sampled at the row's
    /// end; on a car, where the status frames sit is fitted (`column_age_s`).
    pub const CONVERT: Epos4Readout = Epos4Readout {
        current_at_row: 0.5,
        column_age_s: 0.0,
        column_interpolated: true,
    };

    /// Whether the rows are the drive's SYNCs (a row as each TPDO arrives, the current at its
    /// end) rather than the reference's periods (convert's rows).
    pub fn rows_per_sync(&self) -> bool {
        self.current_at_row > 0.75
    }
}

impl Default for Epos4Readout {
    fn default() -> Self {
        Epos4Readout::CONVERT
    }
}

/// A 1-DOF axis (mass, viscous friction, offset) under a P-PD controller with a one-sample
/// delay and a saturated output: the EMPS benchmark's reference model.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EmpsModel {
    /// Moving mass at the load, kg.
    pub mass: f64,
    /// Viscous friction, N s/m.
    pub fv: f64,
    /// Constant force offset, N.
    pub offset: f64,
    /// Drive gain, N/V.
    pub gtau: f64,
    /// Position gain, 1/s.
    pub kp: f64,
    /// Velocity gain, V/(m/s).
    pub kv: f64,
    /// Controller output limit, V.
    pub vsat: f64,
    /// Sample period, s.
    pub ts_s: f64,
    /// Integration steps per sample.
    pub substeps: u32,
}

/// A Dynamixel XL330 geared servo swinging a pendulum under its own firmware P controller, as
/// the BAM logs record it (`host-sim/data/bam-xl330/README.md`): a voltage-driven DC motor
/// behind its gearbox, every quantity at the output shaft. The nominal model is Coulomb-free
/// (torque constant, winding resistance, armature, viscous friction) so that friction is left
/// for the diagnosis to find.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct BamModel {
    /// Torque constant at the output shaft, N m/A (also the back-EMF constant, V s/rad).
    pub kt: f64,
    /// Winding resistance, ohm.
    pub r_ohm: f64,
    /// Rotor and gearbox inertia at the output shaft, kg m^2.
    pub armature_kg_m2: f64,
    /// Viscous friction at the output shaft, N m s/rad.
    pub viscous_nm_s_per_rad: f64,
    /// Pendulum point mass, kg, and its distance from the axis, m (angle 0 = hanging down).
    pub mass_kg: f64,
    pub length_m: f64,
    /// The firmware's position P gain, in firmware units (the log's `kp`).
    pub kp: f64,
    /// Duty per firmware gain unit per rad: `duty = error_gain kp (goal - position)`.
    pub error_gain: f64,
    /// The PWM register's full scale: `duty = load_raw / pwm_full_scale`.
    pub pwm_full_scale: f64,
    /// Encoder resolution, counts per revolution (the position the firmware sees).
    pub encoder_counts: f64,
    /// Step of the uniform grid the log is resampled onto, s.
    pub ts_s: f64,
    /// Integration steps per grid step (the firmware's loop runs faster than the log).
    pub substeps: u32,
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RigModel {
    Paper(PaperModel),
    Emps(EmpsModel),
    Bam(BamModel),
}

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rig {
    pub name: String,
    pub columns: Columns,
    pub model: RigModel,
    /// Leading seconds left out of every figure (initialisation transient).
    #[serde(default)]
    pub skip_s: f64,
}

/// Why a rig or a log could not be read.
#[derive(Debug)]
pub enum RigError {
    Io {
        path: String,
        source: std::io::Error,
    },
    Parse {
        path: String,
        message: String,
    },
    /// The log has no column of the rig's name for a signal; `found` is the header's names,
    /// comma-separated.
    MissingColumn {
        path: String,
        column: String,
        found: String,
    },
    TooShort {
        path: String,
    },
    /// The log could not be read, or breaks the log format's rules (file, line, reason).
    Log(LogError),
    /// A required column holds no sample, only `nan`.
    NoSamples {
        path: String,
        column: String,
    },
    /// A required signal holds one value in every row: no signal to compare a model with.
    Constant {
        path: String,
        column: String,
        value: f64,
    },
    /// A stretch of the log with no row, or a required sample `nan`, longer than
    /// [`MAX_HOLE_STEPS`] grid steps: the signals across it are not known. Times as the file
    /// stamps them.
    Hole {
        path: String,
        from_s: f64,
        to_s: f64,
        grid_s: f64,
    },
    /// The rows sit further apart than the model's grid can follow ([`MAX_ROW_STEPS`] steps,
    /// median): the reference between them is not known.
    Sparse {
        path: String,
        column: String,
        spacing_s: f64,
        grid_s: f64,
    },
    /// The paper rig: the rows sit further apart than the reference's period (beyond the
    /// clock error a row-a-period logger may have): the samples the car steered to between
    /// two rows are not in the log.
    SparserThanReference {
        path: String,
        spacing_s: f64,
        period_s: f64,
    },
}

/// The longest stretch of a log without its samples (no row, or a required one `nan`) the
/// diagnosis bridges by a line between its ends, in grid steps: 0.1 s on the paper rig's
/// 10 ms grid, ten reference periods. 1 % of rows lost at random leaves holes of one or two.
pub const MAX_HOLE_STEPS: f64 = 10.0;

/// The widest median spacing of a log's rows the diagnosis takes, in grid steps: 40 ms on
/// the paper rig's 10 ms grid. A reference of 100 Hz logged more sparsely is not known
/// between its rows, and stamps in milliseconds read as seconds sit 1000 x too far apart.
pub const MAX_ROW_STEPS: f64 = 4.0;

/// `line` as a candump log's frame: `(1700000000.123456) can0 101#0011`.
fn is_candump_line(line: &str) -> bool {
    let mut parts = line.split_whitespace();
    let stamp = parts.next().unwrap_or_default();
    let frame = parts.nth(1).unwrap_or_default();
    stamp.starts_with('(') && stamp.ends_with(')') && frame.contains('#')
}

impl std::fmt::Display for RigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RigError::Io { path, source } => write!(f, "{path}: {source}"),
            RigError::Parse { path, message } => write!(f, "{path}: {message}"),
            // A recording of the bus is no log yet: its first line is a candump frame.
            RigError::MissingColumn { path, found, .. } if is_candump_line(found) => write!(
                f,
                "{path}: a recording of the CAN bus (candump), not a log: `steer-can convert \
                 {path} --out log.csv` writes the log `gap` reads"
            ),
            RigError::MissingColumn {
                path,
                column,
                found,
            } => write!(
                f,
                "{path}: no column named {column:?}: the header names `{found}`. A log whose \
                 columns carry other names is read through a rig file that names them: copy \
                 host-sim/rigs/paper.json, set its `columns` to the log's names and pass \
                 `--rig FILE`"
            ),
            RigError::TooShort { path } => write!(f, "{path}: fewer than 20 samples"),
            RigError::Log(e) => write!(f, "{e}"),
            RigError::NoSamples { path, column } => {
                write!(f, "{path}: column {column:?} holds no sample, only nan")
            }
            RigError::Constant {
                path,
                column,
                value,
            } => write!(
                f,
                "{path}: column {column:?} holds {value} in every row: no signal to diagnose (a \
                 stuck sensor, or the wrong column?)"
            ),
            RigError::Hole {
                path,
                from_s,
                to_s,
                grid_s,
            } => write!(
                f,
                "{path}: nothing from t = {from_s:.3} s to {to_s:.3} s (no row, or a required \
                 sample nan): {:.0} ms, longer than the {:.0} ms the diagnosis bridges; what the \
                 car did across it is not known. Diagnose the parts before and after it as logs \
                 of their own",
                1e3 * (to_s - from_s),
                1e3 * MAX_HOLE_STEPS * grid_s
            ),
            RigError::Sparse {
                path,
                column,
                spacing_s,
                grid_s,
            } => write!(
                f,
                "{path}: rows {} ms apart (median), too far apart for the diagnosis's {} ms \
                 grid (it needs a row at least every {} ms); is `{column}` in seconds?",
                1e3 * spacing_s,
                1e3 * grid_s,
                1e3 * MAX_ROW_STEPS * grid_s
            ),
            RigError::SparserThanReference {
                path,
                spacing_s,
                period_s,
            } => write!(
                f,
                "{path}: rows {:.2} ms apart, further apart than the reference's \
                 {:.0} ms period: the samples the car steered to between two rows are not in \
                 the log, and a diagnosis against a guess of them would be the guess's; log \
                 a row at least every period ({:.0} Hz or faster)",
                1e3 * spacing_s,
                1e3 * period_s,
                1.0 / period_s
            ),
        }
    }
}

impl std::error::Error for RigError {}

impl Rig {
    /// The paper's actuator, Tables 1-4, paper mode, the project log format.
    pub fn paper() -> Rig {
        Rig {
            name: "paper".into(),
            columns: Columns {
                time: "t".into(),
                reference: "ref_sw_deg".into(),
                output: "sw_deg".into(),
                effort: "current_a".into(),
                motor: Some("motor_rad".into()),
                disturbance: None,
                supply: None,
                torque_enable: None,
            },
            model: RigModel::Paper(PaperModel {
                plant: PlantParams::PAPER,
                gains: EposGains::PAPER,
                supply_v: 24.0,
                drive: CarDrive::Direct,
                controller: crate::sim::Controller::Paper,
                epos4: Epos4Timing::default(),
                push_tick: 0,
                timing_bound_s: 0.0,
            }),
            skip_s: 0.2,
        }
    }

    /// EMPS with the linear refit of its README (Fc = 0: M 95.10 kg, Fv 411.1 N s/m,
    /// offset -3.16 N) and the benchmark's controller.
    pub fn emps() -> Rig {
        Rig {
            name: "emps".into(),
            columns: Columns {
                time: "t_s".into(),
                reference: "qg_m".into(),
                output: "qm_m".into(),
                effort: "vir_V".into(),
                motor: None,
                disturbance: Some("pulses_N".into()),
                supply: None,
                torque_enable: None,
            },
            model: RigModel::Emps(EmpsModel {
                mass: 95.10,
                fv: 411.1,
                offset: -3.16,
                gtau: 35.15065188248547,
                kp: 160.18,
                kv: 243.45,
                vsat: 10.0,
                ts_s: 1e-3,
                substeps: 10,
            }),
            skip_s: 0.05,
        }
    }

    /// The BAM XL330 pendulum at the firmware gain kp = 400. The motor's constants are BAM's
    /// Coulomb-viscous model M1 (`host-sim/data/bam-xl330/README.md`) with its Coulomb term
    /// left out; the pendulum (0.49 kg at 0.10 m) and the P law are the data README's. The
    /// log is resampled onto a 5 ms grid, about its median row spacing (5.3 ms).
    pub fn bam() -> Rig {
        Rig {
            name: "bam".into(),
            columns: Columns {
                time: "t_s".into(),
                reference: "goal_position_rad".into(),
                output: "position_rad".into(),
                effort: "load_raw".into(),
                motor: None,
                disturbance: None,
                supply: Some("input_volts_V".into()),
                torque_enable: Some("torque_enable".into()),
            },
            model: RigModel::Bam(BamModel {
                kt: 0.3867,
                r_ohm: 4.017,
                armature_kg_m2: 1.814e-3,
                viscous_nm_s_per_rad: 0.003662,
                mass_kg: 0.49,
                length_m: 0.10,
                kp: 400.0,
                // Counts per rad over BAM's empirical KP divisor (256) and the PWM scale (885).
                error_gain: (4096.0 / std::f64::consts::TAU) / (256.0 * 885.0),
                pwm_full_scale: 885.0,
                encoder_counts: 4096.0,
                ts_s: 0.005,
                substeps: 5,
            }),
            skip_s: 0.05,
        }
    }

    /// The BAM rig at another firmware gain (the logs come at kp 100, 200, 400 and 800).
    pub fn bam_at_kp(kp: f64) -> Rig {
        let mut rig = Rig::bam();
        if let RigModel::Bam(m) = &mut rig.model {
            m.kp = kp;
        }
        rig
    }

    /// A rig from a JSON file (`host-sim/rigs/*.json`); the names `paper`, `emps` and `bam`
    /// give the built-in ones.
    pub fn load(path: &Path) -> Result<Rig, RigError> {
        match path.to_str() {
            Some("paper") => return Ok(Rig::paper()),
            Some("emps") => return Ok(Rig::emps()),
            Some("bam") => return Ok(Rig::bam()),
            _ => {}
        }
        let name = path.display().to_string();
        let text = std::fs::read_to_string(path).map_err(|source| RigError::Io {
            path: name.clone(),
            source,
        })?;
        serde_json::from_str(&text).map_err(|e| RigError::Parse {
            path: name,
            message: e.to_string(),
        })
    }

    /// One count of the output's position sensor, in the output's unit: the column encoder's
    /// (deg) on the paper rig, the servo's encoder (rad) on BAM; 0 where the log does not say
    /// (EMPS).
    pub fn output_count(&self) -> f64 {
        match &self.model {
            RigModel::Paper(_) => 360.0 / f64::from(steering_ecu::sensors::COLUMN_ENCODER_COUNTS),
            RigModel::Emps(_) => 0.0,
            RigModel::Bam(m) => std::f64::consts::TAU / m.encoder_counts,
        }
    }

    /// Seconds per sample of the diagnosis grid.
    pub fn grid_s(&self) -> f64 {
        match &self.model {
            RigModel::Paper(_) => 0.01,
            RigModel::Emps(m) => m.ts_s,
            RigModel::Bam(m) => m.ts_s,
        }
    }

    /// Read a CSV (or .csv.gz) log with the rig's columns onto the rig's grid.
    pub fn load_record(&self, path: &Path) -> Result<Record, RigError> {
        self.load_record_noting(path).map(|(record, _)| record)
    }

    /// As [`Rig::load_record`], with a note for each column whose missing samples (`nan`) were
    /// filled, for the caller to show. The file is read and checked by the project's log reader
    /// (`logfmt::Table`): time strictly increasing (on the paper rig, or stamps that go back
    /// within their jitter, each row then at its place), values within physical bounds, errors with
    /// file and line.
    pub fn load_record_noting(&self, path: &Path) -> Result<(Record, Vec<String>), RigError> {
        self.load_log(path).map(|l| (l.record, l.notes))
    }

    /// As [`Rig::load_record_noting`], with the log's comment lines before its header and its
    /// stamps' timing.
    pub fn load_log(&self, path: &Path) -> Result<LoadedLog, RigError> {
        let name = path.display().to_string();
        // The car's logs may come from a receiver that stamps each row within a millisecond of
        // its place, in the rows' order: at 1 kHz such stamps go back now and then. They are
        // read as stamped and placed below; every other rig's time must increase.
        let order = match self.model {
            RigModel::Paper(_) => TimeOrder::AsStamped,
            _ => TimeOrder::Increasing,
        };
        // The rig's columns alone are read: a team's logger writes others of its own beside
        // them (a row index without a name, a state as text), which tell the diagnosis
        // nothing.
        let c = &self.columns;
        // The reference and the car's columns: a row for each CAN frame leaves some empty.
        let car: Vec<&str> = [
            Some(&c.reference),
            Some(&c.output),
            Some(&c.effort),
            c.motor.as_ref(),
        ]
        .into_iter()
        .flatten()
        .map(String::as_str)
        .collect();
        let reads: Vec<&str> = car
            .iter()
            .copied()
            .chain(
                [&c.disturbance, &c.supply, &c.torque_enable]
                    .into_iter()
                    .flatten()
                    .map(String::as_str),
            )
            .collect();
        let table =
            Table::load_reading(path, &c.time, Reads::Only(&reads), order).map_err(|e| match e
                .root()
            {
                LogError::MissingNamedColumn {
                    expected,
                    found_header,
                } => RigError::MissingColumn {
                    path: path.display().to_string(),
                    column: expected.clone(),
                    found: found_header.clone(),
                },
                _ => RigError::Log(e),
            })?;
        let mut notes = Vec::new();
        // A log whose rows each hold one CAN frame's columns, the other frames' left empty
        // (a recording's decoded signals exported row by row): each signal holds from its
        // frame to its next, as the car saw it, not a line between them.
        let named: Vec<&[f64]> = car.iter().filter_map(|n| table.column(n)).collect();
        let blank = super::held::blank_share(&named);
        let frames =
            matches!(self.model, RigModel::Paper(_)) && blank >= super::held::FRAMES_BLANK_SHARE;
        if frames {
            notes.push(format!(
                "{name}: {:.0} % of rows leave a column of the car or the reference empty (a \
                 row for each CAN frame, holding that frame's columns?); each empty sample is \
                 read as its column's last",
                100.0 * blank
            ));
        }
        // Missing samples are filled so that no NaN reaches the simulation and the costs; a
        // required column with no sample at all is refused, an optional one is left out.
        let mut col = |c: &str, required: bool| -> Result<Option<Vec<f64>>, RigError> {
            let Some(values) = table.column(c) else {
                return if required {
                    Err(RigError::MissingColumn {
                        path: name.clone(),
                        column: c.to_string(),
                        found: [&table.names[..], &table.unread[..]].concat().join(","),
                    })
                } else {
                    Ok(None)
                };
            };
            let mut values = values.to_vec();
            let filled = if frames {
                hold_missing(&mut values)
            } else {
                fill_missing(&mut values)
            };
            match filled {
                Some(0) => {}
                Some(_) if frames => {}
                Some(n) => notes.push(format!(
                    "{name}: column `{c}`: {n} missing samples (nan) of {} filled by linear \
                     interpolation between their neighbours",
                    values.len()
                )),
                None if required && !values.is_empty() => {
                    return Err(RigError::NoSamples {
                        path: name.clone(),
                        column: c.to_string(),
                    });
                }
                None if !values.is_empty() => {
                    notes.push(format!("{name}: column `{c}` is all nan; left out"));
                    return Ok(None);
                }
                None => {}
            }
            Ok(Some(values))
        };
        let mut t = col(&self.columns.time, true)?.unwrap_or_default();
        // The stamps' timing, where they had to be placed in order (read before they were)
        // or the rows' spacing was checked against the reference's period.
        let mut stamped: Option<super::LogTiming> = None;
        let reference = col(&self.columns.reference, true)?.unwrap_or_default();
        let output = col(&self.columns.output, true)?.unwrap_or_default();
        let effort = col(&self.columns.effort, true)?.unwrap_or_default();
        // `# current: instantaneous` before the header: the current column holds instants,
        // not the interval means the project's logs carry.
        let current = table
            .comments
            .iter()
            .filter_map(|c| c.split_once(':'))
            .filter(|(k, _)| k.trim() == "current")
            .find_map(|(_, v)| CurrentSamples::from_name(v))
            .unwrap_or_default();
        // `# reference: period-ending|period-starting`: which period a row on a period's
        // boundary holds, which places the periods in a log of several rows a period.
        let stated = table
            .comments
            .iter()
            .filter_map(|c| c.split_once(':'))
            .filter(|(k, _)| k.trim() == "reference")
            .find_map(|(_, v)| ReferenceConvention::from_name(v));
        let motor = match &self.columns.motor {
            Some(c) => col(c, false)?,
            None => None,
        };
        let disturbance = match &self.columns.disturbance {
            Some(c) => col(c, false)?,
            None => None,
        };
        // The BAM model needs both; a log without them is refused, not run at a guessed supply.
        let bam_column = |c: &Option<String>, what: &str| -> Result<String, RigError> {
            c.clone().ok_or_else(|| RigError::Parse {
                path: name.clone(),
                message: format!("the BAM rig names no {what} column"),
            })
        };
        let (supply, torque_enable) = match &self.model {
            RigModel::Bam(_) => (
                col(&bam_column(&self.columns.supply, "supply")?, true)?,
                col(
                    &bam_column(&self.columns.torque_enable, "torque_enable")?,
                    true,
                )?,
            ),
            _ => (None, None),
        };
        if t.len() < 20 {
            return Err(RigError::TooShort { path: name });
        }
        let time_back = table.first_time_back(&t);
        if !matches!(self.model, RigModel::Emps(_)) {
            // A logger on the wall clock stamps Unix seconds: read from the first stamp's
            // whole second.
            let first = t[0];
            if let Some(from) = crate::logfmt::from_wall_clock(&mut t) {
                notes.push(format!(
                    "{name}: stamps start at {first:.3} s (a wall clock's?); read as seconds \
                     from {from:.0} s"
                ));
            }
            if let Some(back) = time_back {
                let (placed, timing) = super::record::placed_in_order(&t)
                    .ok_or_else(|| RigError::Log(back.in_file(path)))?;
                notes.push(format!(
                    "{name}: {}, within the stamps' jitter ({:.2} ms RMS); each row is taken \
                     in the file's order at its place on the rows' grid",
                    stamps_out_of_order(&t),
                    1e3 * timing.jitter_s
                ));
                stamped = Some(timing);
                t = placed;
            }
            let spacing_s = host_io::grid::median_gap(&t);
            if spacing_s > MAX_ROW_STEPS * self.grid_s() {
                return Err(RigError::Sparse {
                    path: name,
                    column: self.columns.time.clone(),
                    spacing_s,
                    grid_s: self.grid_s(),
                });
            }
            if let RigModel::Paper(_) = self.model {
                // The rows' period is the grid's where the stamps form one: with a stamp's
                // jitter a few tenths of a period (a PC's clock), the median gap of a
                // row-a-period log wanders 1 % either side of its period.
                let timing = *stamped.get_or_insert_with(|| super::LogTiming::of(&t));
                let row_dt_s = if timing.is_regular() {
                    timing.row_dt_s
                } else {
                    spacing_s
                };
                if row_dt_s > (1.0 + super::record::ONE_ROW_A_STEP) * self.grid_s() {
                    return Err(RigError::SparserThanReference {
                        path: name,
                        spacing_s: row_dt_s,
                        period_s: self.grid_s(),
                    });
                }
            }
            // A stretch with no row, or with a required sample `nan`, is filled by a line
            // between its ends; over more than a few reference periods that line is a guess
            // the model would be scored against (2 s of a 100 Hz track missing turned an
            // effect-free car `unexplained`).
            // Each column by its own samples: a log of a row per CAN frame holds the
            // reference and the car's columns in rows of their own.
            let hole = [
                &self.columns.reference,
                &self.columns.output,
                &self.columns.effort,
            ]
            .iter()
            .filter_map(|c| table.column(c))
            .filter_map(|v| {
                let present: Vec<f64> = (0..t.len())
                    .filter(|&j| !v[j].is_nan())
                    .map(|j| t[j])
                    .collect();
                let spacing = if frames {
                    host_io::grid::median_gap(&present)
                } else {
                    spacing_s
                };
                longest_hole(&t, &present, spacing)
            })
            .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)));
            if let Some((from, to)) = hole
                && ((to - from) / self.grid_s()).round() > MAX_HOLE_STEPS
            {
                let whole_s = first - t[0];
                return Err(RigError::Hole {
                    path: name,
                    from_s: from + whole_s,
                    to_s: to + whole_s,
                    grid_s: self.grid_s(),
                });
            }
        }
        // A signal with one value in every row has no variance for a GoF to be scored on
        // (eq. 11 divides by it): a required one is refused, the motor angle left out.
        for (c, values) in [
            (&self.columns.reference, &reference),
            (&self.columns.output, &output),
            (&self.columns.effort, &effort),
        ] {
            if let Some(value) = one_value(values) {
                return Err(RigError::Constant {
                    path: name,
                    column: c.clone(),
                    value,
                });
            }
        }
        let motor = motor.filter(|m| match one_value(m) {
            Some(v) => {
                let c = self.columns.motor.as_deref().unwrap_or("motor");
                notes.push(format!(
                    "{name}: column `{c}` holds {v} in every row; left out"
                ));
                false
            }
            None => true,
        });
        // The rows' timing; on the paper rig, the rows as read (held frames at their
        // arrivals).
        let mut timing = stamped.unwrap_or_else(|| super::LogTiming::of(&t));
        let (record, by_convention) = match &self.model {
            RigModel::Paper(m) => {
                let per = m.plant.motor_per_pinion();
                let powered_from = powered_from(&table, &self.columns, &t, 0.01);
                // Rows faster than the car's frames, each holding the last: read at the rows
                // where a frame arrived.
                let mut car: Vec<&[f64]> = vec![&output, &effort];
                car.extend(motor.as_deref());
                let held_share = if frames {
                    super::held::FRAMES_HELD_SHARE
                } else {
                    super::held::HELD_SHARE
                };
                let arrived = super::held::arrivals(&t, &car, self.grid_s(), held_share);
                let held = arrived.as_ref().map(|rows| {
                    let kept = super::held::unambiguous(&t, rows, timing.jitter_s);
                    let left_out = match rows.len() - kept.len() {
                        0 => String::new(),
                        n => format!(
                            " ({n} frames left out: a row lost just before each hides when \
                             it came)"
                        ),
                    };
                    notes.push(if frames {
                        format!(
                            "{name}: read at the {} of {} rows where the car's frames \
                             arrived{left_out}",
                            kept.len(),
                            t.len(),
                        )
                    } else {
                        format!(
                            "{name}: {} of {} rows repeat the row before in every column of \
                             the car (a logger faster than the car's frames, each row holding \
                             the last); read at the {} rows where a frame arrived{left_out}",
                            t.len() - rows.len(),
                            t.len(),
                            kept.len(),
                        )
                    });
                    kept
                });
                let (t, reference, output, effort, motor) = match &held {
                    Some(rows) => {
                        let at = |v: &[f64]| super::held::at(v, rows);
                        let before = super::held::before(rows);
                        (
                            super::held::at(&t, &before),
                            super::held::at(&reference, &before),
                            at(&output),
                            at(&effort),
                            motor.as_deref().map(at),
                        )
                    }
                    None => (t, reference, output, effort, motor),
                };
                // A reference the logger printed coarser than the car received it.
                let reference = match super::rounded::step_of(&reference) {
                    Some(step) => {
                        notes.push(format!(
                            "{name}: the reference column holds whole multiples of {step} deg, \
                             coarser than the 0.01 deg the car receives: read as the smoothest \
                             line within half a step of each row"
                        ));
                        super::rounded::smoothed_within(&reference, step)
                    }
                    None => reference,
                };
                let motor_deg: Option<Vec<f64>> =
                    motor.map(|mr| mr.iter().map(|v| (v / per).to_degrees()).collect());
                let read = |stated: Option<ReferenceConvention>| Record {
                    powered_from,
                    ..Record::from_samples(
                        &t,
                        &reference,
                        &output,
                        &effort,
                        motor_deg.clone(),
                        0.01,
                        current,
                        stated,
                    )
                };
                let record = read(stated);
                // Several rows a period on the periods' boundaries and no header to say which
                // period a boundary's row holds: the log read both ways, for the car's fit to
                // choose (`drive::choose`), where the two differ.
                let several_rows = held.is_none()
                    && timing.is_regular()
                    && timing.row_dt_s < super::record::FEWER_ROWS_A_STEP * 0.01;
                let by_convention = (stated.is_none() && several_rows)
                    .then(|| ReferenceConvention::ALL.map(|c| read(Some(c))))
                    .filter(|[ending, starting]| ending != starting);
                if held.is_some() {
                    timing = super::LogTiming::of(&t);
                }
                (record, by_convention)
            }
            RigModel::Emps(_) => (
                Record {
                    dt: self.grid_s(),
                    reference,
                    output,
                    effort,
                    motor: None,
                    disturbance,
                    supply_v: None,
                    powered_from: 0,
                    current_chatter: false,
                },
                None,
            ),
            RigModel::Bam(m) => (
                bam_record(
                    m,
                    &name,
                    &BamColumns {
                        t: &t,
                        goal: &reference,
                        position: &output,
                        pwm: &effort,
                        supply: &supply.unwrap_or_default(),
                        torque_enable: &torque_enable.unwrap_or_default(),
                        lines: &table.lines,
                    },
                )?,
                None,
            ),
        };
        Ok(LoadedLog {
            record,
            by_convention,
            notes,
            comments: table.comments.clone(),
            timing,
        })
    }
}

/// The longest stretch of `t` without a row in `present` (the stamps of the rows that hold
/// every required sample, in order), as the time from the last row before it to the first
/// after it less one row `spacing`; a stretch at either end runs to the log's first or last
/// stamp. `None` when every row is present.
fn longest_hole(t: &[f64], present: &[f64], spacing: f64) -> Option<(f64, f64)> {
    let (&start, &end) = (t.first()?, t.last()?);
    let Some((&first, &last)) = present.first().zip(present.last()) else {
        return Some((start, end));
    };
    let inner = present
        .windows(2)
        .map(|w| (w[0] + spacing, w[1]))
        .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)));
    [Some((start, first)), Some((last, end)), inner]
        .into_iter()
        .flatten()
        .filter(|(a, b)| b > a)
        .max_by(|a, b| (a.1 - a.0).total_cmp(&(b.1 - b.0)))
}

/// The one value every sample holds, if they all hold the same.
fn one_value(values: &[f64]) -> Option<f64> {
    let first = *values.first()?;
    values.iter().all(|v| *v == first).then_some(first)
}

/// The steps of the grid (`dt` s each, from the first row) before the first row with a motor
/// angle or a current (`t` the rows' stamps, as read): the rows a logger wrote while the car's
/// drive had not yet reported, as `steer-can convert` writes the rows before the EPOS4's first
/// status frame (its current and position `nan`). A log whose first row has either starts
/// with the drive running: 0.
fn powered_from(table: &Table, columns: &Columns, t: &[f64], dt: f64) -> usize {
    let effort = table.column(&columns.effort);
    let motor = columns.motor.as_deref().and_then(|c| table.column(c));
    let reported = |j: usize| {
        [effort, motor]
            .iter()
            .flatten()
            .any(|v| v.get(j).is_some_and(|x| x.is_finite()))
    };
    match (0..t.len()).find(|&j| reported(j)) {
        Some(j) if j > 0 => ((t[j] - t[0]) / dt + 1e-6).floor().max(0.0) as usize,
        _ => 0,
    }
}

/// A BAM log's columns as read.
struct BamColumns<'a> {
    t: &'a [f64],
    goal: &'a [f64],
    position: &'a [f64],
    pwm: &'a [f64],
    supply: &'a [f64],
    torque_enable: &'a [f64],
    /// The file's line of each row, for errors.
    lines: &'a [usize],
}

/// A BAM log on the model's uniform grid `t0 + k ts`. The servo is read at its own uneven
/// pace (5.3 ms median, 3.5 ms in `lift_and_drop`), and the diagnosis wants one step: the
/// goal is the last one written at or before each grid time (what the firmware holds), the
/// position, the PWM (as duty) and the supply are interpolated to it, and the drive counts
/// as off when the last row at or before it says torque disabled; the record's `supply_v`
/// is then 0. Before the model runs on it, the log's own PWM is checked against the rig's P
/// law: a log taken at another gain is refused with the gain it shows, not fitted wrongly.
fn bam_record(m: &BamModel, name: &str, c: &BamColumns) -> Result<Record, RigError> {
    let t = c.t;
    // A flag that is neither 0 nor 1, or a drive on without a supply, would be simulated as
    // something the servo never did: refused with its line.
    for j in 0..t.len() {
        let line = c.lines.get(j).copied().unwrap_or(0);
        let refuse = |message: String| RigError::Parse {
            path: name.to_string(),
            message: format!("line {line}: {message}"),
        };
        match c.torque_enable[j] {
            0.0 => {}
            1.0 if c.supply[j] >= 1.0 => {}
            1.0 => {
                return Err(refuse(format!(
                    "supply {} V with torque enabled: the motor's voltage is unknown",
                    c.supply[j]
                )));
            }
            v => return Err(refuse(format!("torque_enable is {v}, neither 0 nor 1"))),
        }
    }
    let last = t.len() - 1;
    let n = ((t[last] - t[0]) / m.ts_s + 1e-6).floor() as usize + 1;
    let held = |k: usize| t.partition_point(|v| *v <= t[0] + k as f64 * m.ts_s).max(1) - 1;
    let at = |y: &[f64], k: usize| super::interp_at(t, y, t[0] + k as f64 * m.ts_s);
    let on = |j: usize| c.torque_enable[j] >= 0.5;
    let record = Record {
        dt: m.ts_s,
        reference: (0..n).map(|k| c.goal[held(k)]).collect(),
        output: (0..n).map(|k| at(c.position, k)).collect(),
        effort: (0..n).map(|k| at(c.pwm, k) / m.pwm_full_scale).collect(),
        motor: None,
        disturbance: None,
        supply_v: Some(
            (0..n)
                .map(|k| if on(held(k)) { at(c.supply, k) } else { 0.0 })
                .collect(),
        ),
        powered_from: 0,
        current_chatter: false,
    };
    // The gain the log's rows show: duty over error, where the firmware's output is neither
    // saturated nor within a few encoder counts of zero.
    let quantum = std::f64::consts::TAU / m.encoder_counts;
    let mut ratios: Vec<f64> = (0..t.len())
        .filter(|&j| on(j))
        .filter_map(|j| {
            let err = c.goal[j] - c.position[j];
            let duty = c.pwm[j] / m.pwm_full_scale;
            (err.abs() > 20.0 * quantum && duty.abs() < 0.9 && duty.abs() > 0.05)
                .then(|| duty / (m.error_gain * err))
        })
        .collect();
    if ratios.len() >= 20 {
        ratios.sort_by(|a, b| a.total_cmp(b));
        let shown = ratios[ratios.len() / 2];
        if !(0.75 * m.kp..=1.33 * m.kp).contains(&shown) {
            return Err(RigError::Parse {
                path: name.to_string(),
                message: format!(
                    "the PWM follows a firmware gain of about kp = {shown:.0}, not the rig's \
                     kp = {}: give a rig file with that `kp` (a copy of \
                     host-sim/rigs/bam.json)",
                    m.kp
                ),
            });
        }
    }
    Ok(record)
}

/// How often stamps `t` go back and how often one repeats the one before it (a clock in whole
/// milliseconds at 1 kHz), in words: "stamps go back 3 times and repeat 2 times".
fn stamps_out_of_order(t: &[f64]) -> String {
    let back = t.windows(2).filter(|w| w[1] < w[0]).count();
    let same = t.windows(2).filter(|w| w[1] == w[0]).count();
    match (back, same) {
        (_, 0) => format!("stamps go back {back} times"),
        (0, _) => format!("stamps repeat {same} times"),
        _ => format!("stamps go back {back} times and repeat {same} times"),
    }
}

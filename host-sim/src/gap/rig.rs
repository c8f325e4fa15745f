//! A rig file: which model and controller a log came from, its parameters, and which CSV
//! columns hold the reference, the output and the effort. Two ship with host-sim
//! (`host-sim/rigs/`): the paper's actuator (the default, built in) and EMPS.

use super::{CurrentSamples, Record};
use crate::logfmt::{LogError, Table, fill_missing};
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
}

/// Table 3 gains in EPOS4 units, as in `steering_ecu::gains::EposGains`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct GainsFile {
    pub current_kp_mv_per_a: f32,
    pub current_ki_mv_per_a_ms: f32,
    pub position_kp_ma_per_rad: f32,
    pub position_ki_ma_per_rad_s: f32,
    pub position_kd_ma_s_per_rad: f32,
    pub ff_velocity_ma_s_per_rad: f32,
    pub ff_acceleration_ma_s2_per_rad: f32,
}

impl Default for GainsFile {
    fn default() -> Self {
        let g = EposGains::PAPER;
        GainsFile {
            current_kp_mv_per_a: g.current_kp_mv_per_a,
            current_ki_mv_per_a_ms: g.current_ki_mv_per_a_ms,
            position_kp_ma_per_rad: g.position_kp_ma_per_rad,
            position_ki_ma_per_rad_s: g.position_ki_ma_per_rad_s,
            position_kd_ma_s_per_rad: g.position_kd_ma_s_per_rad,
            ff_velocity_ma_s_per_rad: g.ff_velocity_ma_s_per_rad,
            ff_acceleration_ma_s2_per_rad: g.ff_acceleration_ma_s2_per_rad,
        }
    }
}

impl GainsFile {
    pub fn to_epos(&self) -> EposGains {
        EposGains {
            current_kp_mv_per_a: self.current_kp_mv_per_a,
            current_ki_mv_per_a_ms: self.current_ki_mv_per_a_ms,
            position_kp_ma_per_rad: self.position_kp_ma_per_rad,
            position_ki_ma_per_rad_s: self.position_ki_ma_per_rad_s,
            position_kd_ma_s_per_rad: self.position_kd_ma_s_per_rad,
            ff_velocity_ma_s_per_rad: self.ff_velocity_ma_s_per_rad,
            ff_acceleration_ma_s2_per_rad: self.ff_acceleration_ma_s2_per_rad,
        }
    }
}

fn default_supply() -> f64 {
    24.0
}

/// The paper's actuator (Tables 1-4) under the firmware's cascade in paper mode.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PaperModel {
    #[serde(default)]
    pub plant: PlantParams,
    #[serde(default)]
    pub gains: GainsFile,
    #[serde(default = "default_supply")]
    pub supply_v: f64,
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

#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum RigModel {
    Paper(PaperModel),
    Emps(EmpsModel),
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
    MissingColumn {
        path: String,
        column: String,
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
}

impl std::fmt::Display for RigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RigError::Io { path, source } => write!(f, "{path}: {source}"),
            RigError::Parse { path, message } => write!(f, "{path}: {message}"),
            RigError::MissingColumn { path, column } => {
                write!(
                    f,
                    "{path}: no column named {column:?} (the rig file names it)"
                )
            }
            RigError::TooShort { path } => write!(f, "{path}: fewer than 20 samples"),
            RigError::Log(e) => write!(f, "{e}"),
            RigError::NoSamples { path, column } => {
                write!(f, "{path}: column {column:?} holds no sample, only nan")
            }
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
            },
            model: RigModel::Paper(PaperModel {
                plant: PlantParams::PAPER,
                gains: GainsFile::default(),
                supply_v: 24.0,
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

    /// A rig from a JSON file (`host-sim/rigs/*.json`); the names `paper` and `emps` give
    /// the built-in ones.
    pub fn load(path: &Path) -> Result<Rig, RigError> {
        match path.to_str() {
            Some("paper") => return Ok(Rig::paper()),
            Some("emps") => return Ok(Rig::emps()),
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

    /// Seconds per sample of the diagnosis grid.
    pub fn grid_s(&self) -> f64 {
        match &self.model {
            RigModel::Paper(_) => 0.01,
            RigModel::Emps(m) => m.ts_s,
        }
    }

    /// Read a CSV (or .csv.gz) log with the rig's columns onto the rig's grid.
    pub fn load_record(&self, path: &Path) -> Result<Record, RigError> {
        self.load_record_noting(path).map(|(record, _)| record)
    }

    /// As [`Rig::load_record`], with a note for each column whose missing samples (`nan`) were
    /// filled, for the caller to show. The file is read and checked by the project's log reader
    /// (`logfmt::Table`): time strictly increasing, values within physical bounds, errors with
    /// file and line.
    pub fn load_record_noting(&self, path: &Path) -> Result<(Record, Vec<String>), RigError> {
        let name = path.display().to_string();
        let table = Table::load(path, &self.columns.time).map_err(RigError::Log)?;
        let mut notes = Vec::new();
        // Missing samples are filled so that no NaN reaches the simulation and the costs; a
        // required column with no sample at all is refused, an optional one is left out.
        let mut col = |c: &str, required: bool| -> Result<Option<Vec<f64>>, RigError> {
            let Some(values) = table.column(c) else {
                return if required {
                    Err(RigError::MissingColumn {
                        path: name.clone(),
                        column: c.to_string(),
                    })
                } else {
                    Ok(None)
                };
            };
            let mut values = values.to_vec();
            match fill_missing(&mut values) {
                Some(0) => {}
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
        let t = col(&self.columns.time, true)?.unwrap_or_default();
        let reference = col(&self.columns.reference, true)?.unwrap_or_default();
        let output = col(&self.columns.output, true)?.unwrap_or_default();
        let effort = col(&self.columns.effort, true)?.unwrap_or_default();
        // `# current: instantaneous` before the header: the current column holds instants,
        // not the interval means the project's logs carry.
        let current = if table.comments.iter().any(|c| {
            c.split_once(':')
                .is_some_and(|(k, v)| k.trim() == "current" && v.trim() == "instantaneous")
        }) {
            CurrentSamples::Instantaneous
        } else {
            CurrentSamples::IntervalMean
        };
        let motor = match &self.columns.motor {
            Some(c) => col(c, false)?,
            None => None,
        };
        let disturbance = match &self.columns.disturbance {
            Some(c) => col(c, false)?,
            None => None,
        };
        if t.len() < 20 {
            return Err(RigError::TooShort { path: name });
        }
        let record = match &self.model {
            RigModel::Paper(m) => {
                let per = m.plant.motor_per_pinion();
                let motor_deg = motor.map(|mr| mr.iter().map(|v| (v / per).to_degrees()).collect());
                Record::from_samples(&t, &reference, &output, &effort, motor_deg, 0.01, current)
            }
            RigModel::Emps(_) => Record {
                dt: self.grid_s(),
                reference,
                output,
                effort,
                motor: None,
                disturbance,
            },
        };
        Ok((record, notes))
    }
}

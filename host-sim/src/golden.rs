//! Golden vectors for the emulated suite (`hil-tests/emulated`): the control core run here, on
//! the host, and written in the format of `hil-tests/golden` for the Cortex-M4F under QEMU to
//! reproduce bit for bit.
//!
//! - `sweep.bin`: the paper's sweep (10 deg, 0-10 Hz in 10 s), the window 6.0-6.6 s (about
//!   6 Hz, the current at its limit), started at rest on the window's first sample.
//! - `track.bin`: the built-in track, 110.0-110.5 s (the 4.5 Hz burst), likewise.
//! - `ecu_sweep.bin`, `ecu_track.bin`: the first halves of those two windows under ECU mode
//!   (`--controller ecu`), which also records the column angle each position step was given.
//! - `cases.bin`: the codec, CANopen, CiA 402, ECU and arbitrary-input cases of
//!   `golden_vectors::cases`, one hash per case.
//!
//! `host-sim golden --write hil-tests/vectors` regenerates them; the test
//! `host-sim/tests/golden.rs` fails when the stored files are stale.

use crate::scenario::{self, Sweep};
use crate::sim::{self, Controller, RunConfig, SimError, Tap};
use golden_vectors::loops::{self, Header};
use std::path::Path;
use steering_ecu::control::current::CurrentOutput;
use steering_ecu::control::position::PositionOutput;
use steering_ecu::controller::ControllerKind;
use steering_ecu::reference::ReferenceError;
use steering_ecu::units::{Amps, SteeringRad};

/// Where the stored vectors live, from the repository root.
pub const DIR: &str = "hil-tests/vectors";
/// Window of the paper's sweep, s.
pub const SWEEP_WINDOW_S: (f64, f64) = (6.0, 6.6);
/// Window of the built-in track, s.
pub const TRACK_WINDOW_S: (f64, f64) = (110.0, 110.5);
/// ECU mode's windows: the first halves of the two above, so that every vector still fits the
/// emulated suite's 512 KiB of flash beside its code.
pub const ECU_SWEEP_WINDOW_S: (f64, f64) = (6.0, 6.3);
pub const ECU_TRACK_WINDOW_S: (f64, f64) = (110.0, 110.25);

/// One stored file: its name and contents.
#[derive(Debug, Clone)]
pub struct Vector {
    pub name: &'static str,
    pub bytes: Vec<u8>,
}

#[derive(Default)]
struct Recorder {
    hall0: i32,
    body: Vec<u8>,
}

impl Tap for Recorder {
    fn reset(&mut self, hall: i32) {
        self.hall0 = hall;
    }
    fn reference(&mut self, deg: f32, result: Result<(), ReferenceError>) {
        self.body
            .extend_from_slice(&loops::reference_record(deg, result));
    }
    fn position(&mut self, hall: i32, column: Option<SteeringRad>, out: &PositionOutput) {
        let column = column.map_or(f32::NAN, |c| c.0);
        self.body
            .extend_from_slice(&loops::position_record(hall, column, out));
    }
    fn current(&mut self, measured: Amps, out: &CurrentOutput) {
        self.body
            .extend_from_slice(&loops::current_record(measured, out));
    }
}

fn window(samples: &[f64], (start_s, end_s): (f64, f64)) -> &[f64] {
    let at = |s: f64| ((s * sim::REFERENCE_RATE_HZ).round() as usize).min(samples.len());
    &samples[at(start_s)..at(end_s)]
}

/// A closed-loop run of host-sim with every controller call recorded (paper rig, Hall
/// feedback).
pub fn record_loop(reference_deg: &[f64], controller: Controller) -> Result<Vec<u8>, SimError> {
    let cfg = RunConfig {
        log_rate_hz: 0,
        controller,
        ..RunConfig::default()
    };
    let mut recorder = Recorder::default();
    sim::run_tapped(reference_deg, &cfg, &mut recorder)?;
    let header = Header {
        periods: reference_deg.len() as u32,
        hall0: recorder.hall0,
        belt_reduction: cfg.plant.belt_reduction as f32,
        tau_bs: cfg.plant.tau_bs as f32,
        tau_p: cfg.plant.tau_p as f32,
        ra_ohm: cfg.plant.ra as f32,
        la_h: cfg.plant.la as f32,
        supply_v: cfg.supply_v as f32,
        controller: match controller {
            Controller::Paper => ControllerKind::Paper,
            Controller::Ecu => ControllerKind::Ecu,
        },
    };
    let mut bytes = header.to_bytes().to_vec();
    bytes.extend_from_slice(&recorder.body);
    Ok(bytes)
}

/// Every golden file, generated now.
pub fn generate() -> Result<Vec<Vector>, SimError> {
    let sweep = Sweep::PAPER.samples();
    let track = scenario::builtin_track();
    let mut cases = Vec::new();
    golden_vectors::cases::write(&mut |b| cases.extend_from_slice(b));
    Ok(vec![
        Vector {
            name: "sweep.bin",
            bytes: record_loop(window(&sweep, SWEEP_WINDOW_S), Controller::Paper)?,
        },
        Vector {
            name: "track.bin",
            bytes: record_loop(window(&track, TRACK_WINDOW_S), Controller::Paper)?,
        },
        Vector {
            name: "ecu_sweep.bin",
            bytes: record_loop(window(&sweep, ECU_SWEEP_WINDOW_S), Controller::Ecu)?,
        },
        Vector {
            name: "ecu_track.bin",
            bytes: record_loop(window(&track, ECU_TRACK_WINDOW_S), Controller::Ecu)?,
        },
        Vector {
            name: "cases.bin",
            bytes: cases,
        },
    ])
}

/// Generate and write every file into `dir`.
pub fn write(dir: &Path) -> Result<Vec<Vector>, Box<dyn std::error::Error>> {
    let vectors = generate()?;
    std::fs::create_dir_all(dir)?;
    for v in &vectors {
        std::fs::write(dir.join(v.name), &v.bytes)?;
    }
    Ok(vectors)
}

//! A team's logger on the vehicle computer may write rows faster than the car's status frames
//! come (100 Hz), each row holding the last frame it received. The independent world's car
//! (`gap::generator`, an RK4 plant under the firmware's cascade) written so, read as
//! `host-sim gap FILE` reads it: at the rows where a frame arrived, and diagnosed as a log of
//! the frames.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/gap_file.rs"]
mod gap_file;
#[path = "support/world_sweep.rs"]
mod world_sweep;

use host_sim::gap::generator::{
    GenCase, LOGGER_DROP_CHANCE, LOGGER_JITTER_S, Logger, ReferenceConvention, log_of, rows_logged,
};
use host_sim::gap::rig::Rig;
use world_sweep::sweep_of;

/// A team's logger at `rate_hz` of the car's frames, each row holding the last, no header.
fn held(rate_hz: u32) -> Logger {
    Logger {
        reference: ReferenceConvention::PeriodStarting,
        header: false,
        held_frames: true,
        ..Logger::ours(rate_hz)
    }
}

#[test]
fn a_held_logger_repeats_each_frame_until_the_next() {
    let case = GenCase::nominal(sweep_of(10.0), 100);
    let rows = rows_logged(&case, 5, &held(1000));
    let samples = rows_logged(
        &case,
        5,
        &Logger {
            held_frames: false,
            ..held(1000)
        },
    );
    let n = rows.t.len();
    let repeats = (1..n)
        .filter(|&k| {
            rows.sw_deg[k] == rows.sw_deg[k - 1] && rows.current_a[k] == rows.current_a[k - 1]
        })
        .count();
    // Nine rows of ten hold the frame before them.
    assert!(repeats > 85 * n / 100, "{repeats} of {n}");
    // The values change once a frame, 10 ms apart.
    let changes: Vec<f64> = (1..n)
        .filter(|&k| rows.current_a[k] != rows.current_a[k - 1])
        .map(|k| rows.t[k])
        .collect();
    let mut gaps: Vec<f64> = changes.windows(2).map(|w| w[1] - w[0]).collect();
    gaps.sort_by(f64::total_cmp);
    assert!(
        (gaps[gaps.len() / 2] - 0.01).abs() < 1e-6,
        "{:?}",
        &gaps[..5]
    );
    // The reference is the logger's own, as sampled.
    assert_eq!(rows.reference, samples.reference);
}

#[test]
fn a_logger_faster_than_the_cars_frames_is_read_at_their_arrivals() {
    let case = GenCase::nominal(sweep_of(10.0), 100);
    let dir = tempfile::tempdir().unwrap();
    // At 1 kHz, at 500 Hz, and at 200 Hz with stamps +-1 ms and 1 % of rows lost (a frame
    // whose row before was lost is left out).
    let lossy = Logger {
        jitter_s: LOGGER_JITTER_S,
        drop_chance: LOGGER_DROP_CHANCE,
        ..held(200)
    };
    for logger in [held(1000), held(500), lossy] {
        let rate = logger.describe();
        let path = dir.path().join("held.csv");
        log_of(&case, 5, &logger).save(&path).unwrap();
        let loaded = Rig::paper().load_log(&path).unwrap();
        gap_file::assert_noted(&loaded.notes, "where a frame arrived");
        // The rows read are the frames': one a reference period.
        assert!(
            (loaded.timing.row_dt_s - 0.01).abs() < 5e-4,
            "{:?}",
            loaded.timing
        );
        gap_file::assert_none(&path, &rate);
    }
    // A logger of real samples at 1 kHz is read as it is.
    let path = dir.path().join("samples.csv");
    log_of(
        &case,
        5,
        &Logger {
            held_frames: false,
            ..held(1000)
        },
    )
    .save(&path)
    .unwrap();
    let loaded = Rig::paper().load_log(&path).unwrap();
    assert!(loaded.notes.is_empty(), "{:?}", loaded.notes);
    assert!((loaded.timing.row_dt_s - 0.001).abs() < 1e-4);
}

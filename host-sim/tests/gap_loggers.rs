//! A log's timing belongs to the logger: the independent world's cars (`gap::generator`, an
//! RK4 plant under the firmware's cascade, not the diagnosis's model) written by two loggers,
//! ours (the reference in force over the period that ends at each row, stamps on the grid)
//! and another (the reference that starts at each row, stamps +-1 ms, 1 % of rows missing, no
//! header saying which), and diagnosed as `host-sim gap` diagnoses a file: the log's timing
//! estimated, its reference convention fitted where the header is silent. The verdict must
//! not depend on the logger.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use host_sim::gap::drive;
use host_sim::gap::generator::{GenCase, Rows, rows_of};
use host_sim::gap::rig::{CarDrive, Rig};
use host_sim::gap::{EffectKind, Options, VerdictKind, diagnose};
use host_sim::sim::Controller;
use std::fmt::Write as _;
use std::path::Path;

fn sweep() -> Vec<f64> {
    host_sim::scenario::Sweep {
        amplitude_deg: 8.0,
        f_start_hz: 0.2,
        f_end_hz: 4.0,
        duration_s: 10.0,
    }
    .samples()
}

/// The log file the other logger writes from the world's rows: each row's reference is the
/// one that starts at its stamp, the stamps jitter (uniform, +-1 ms), and a row is lost now
/// and then (a CAN recording); `seed` picks which.
fn write_theirs(rows: &Rows, path: &Path, seed: u64) {
    let mut state = seed;
    let mut next = || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 11) as f64 / (1u64 << 53) as f64
    };
    let mut text = String::from("t,ref_sw_deg,sw_deg,motor_rad,current_a\n");
    let n = rows.t.len();
    for k in 0..n {
        let (jitter, drop) = (next(), next());
        if drop < 0.01 {
            continue;
        }
        let reference = rows.reference[(k + 1).min(n - 1)];
        writeln!(
            text,
            "{:.6},{:.4},{:.4},{:.6},{:.5}",
            rows.t[k] + 2e-3 * (jitter - 0.5),
            reference,
            rows.sw_deg[k],
            rows.motor_rad[k],
            rows.current_a[k]
        )
        .unwrap();
    }
    std::fs::write(path, text).unwrap();
}

/// Ours: the rows as the world wrote them, with the header lines host-sim writes.
fn write_ours(rows: &Rows, path: &Path) {
    let mut text = String::from(
        "# drive: direct\n# controller: paper\n# current: interval-mean\n# reference: period-ending\n\
         t,ref_sw_deg,sw_deg,motor_rad,current_a\n",
    );
    for k in 0..rows.t.len() {
        writeln!(
            text,
            "{:.6},{:.4},{:.4},{:.6},{:.5}",
            rows.t[k], rows.reference[k], rows.sw_deg[k], rows.motor_rad[k], rows.current_a[k]
        )
        .unwrap();
    }
    std::fs::write(path, text).unwrap();
}

/// The verdict on a file, read as the CLI reads it (the car given, as `--drive direct
/// --controller paper` would).
fn verdict_on(path: &Path) -> (Vec<String>, VerdictKind, drive::CarChoice) {
    let rig = Rig::paper();
    let loaded = rig.load_log(path).unwrap();
    let header = drive::LogHeader::parse(&loaded.comments).unwrap();
    let (rig, rec, choice) = drive::choose_for_log(
        &rig,
        &loaded.record,
        &header,
        loaded.timing,
        Some(CarDrive::Direct),
        Some(Controller::Paper),
        2,
    );
    let choice = choice.unwrap();
    let d = diagnose(
        &rig,
        &rec,
        None,
        // The candidates `host-sim gap` fits on this rig, as the command sets them.
        &Options {
            effects: EffectKind::for_rig(&rig),
            threads: 2,
            ..Options::default()
        },
    );
    println!("{}\n{}", choice.describe(), d.summary());
    (d.verdict.effects.clone(), d.verdict.kind, choice)
}

fn both_loggers(case: &GenCase) -> [(Vec<String>, VerdictKind, drive::CarChoice); 2] {
    let rows = rows_of(case, 5);
    let dir = tempfile::tempdir().unwrap();
    let (ours, theirs) = (dir.path().join("ours.csv"), dir.path().join("theirs.csv"));
    write_ours(&rows, &ours);
    write_theirs(&rows, &theirs, 11);
    [verdict_on(&ours), verdict_on(&theirs)]
}

#[test]
fn an_effect_free_car_is_none_whichever_logger_wrote_it() {
    let [ours, theirs] = both_loggers(&GenCase::nominal(sweep(), 100));
    assert_eq!(ours.1, VerdictKind::None, "ours: {:?}", ours.0);
    assert_eq!(theirs.1, VerdictKind::None, "theirs: {:?}", theirs.0);
    // Ours states its convention; the other logger's is found, one row late.
    assert_eq!(ours.2.reference_shift_rows, None);
    assert_eq!(theirs.2.reference_shift_rows, Some(1));
    assert!(
        theirs.2.timing_bound_s > 0.010,
        "{}",
        theirs.2.timing_bound_s
    );
}

#[test]
fn a_late_reference_is_a_delay_whichever_logger_wrote_it() {
    let mut case = GenCase::nominal(sweep(), 100);
    case.truth.reference_delay_s = 0.035;
    case.hidden = vec!["delay".into()];
    let [ours, theirs] = both_loggers(&case);
    assert_eq!(ours.0, vec!["delay".to_string()], "ours");
    assert_eq!(theirs.0, vec!["delay".to_string()], "theirs");
}

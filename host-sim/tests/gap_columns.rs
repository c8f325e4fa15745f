//! A team's logger decides the signs of its columns on its own: a current sensor mounted the
//! other way round, a column counted clockwise, a reference in the vehicle computer's
//! convention, a motor angle in degrees. The independent world's effect-free car
//! (`gap::generator`, an RK4 plant under the firmware's cascade) written so, read as
//! `host-sim gap FILE` reads it: each such column is read as the car has it and said so, and
//! the verdict is the one on the log as the car's own logger writes it.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/gap_file.rs"]
mod gap_file;
#[path = "support/world_sweep.rs"]
mod world_sweep;

use host_sim::gap::Record;
use host_sim::gap::columns::{self, ColumnSigns};
use host_sim::gap::generator::{GenCase, LoggedCar, Logger, ReferenceConvention, log_of};
use host_sim::gap::rig::Rig;
use host_sim::logfmt::Log;
use std::path::Path;
use world_sweep::sweep_of;

/// A team's 100 Hz logger of the direct drive: the reference that starts at each row, no
/// header.
fn team() -> Logger {
    Logger {
        reference: ReferenceConvention::PeriodStarting,
        header: false,
        ..Logger::ours(100)
    }
}

/// The effect-free car's 10 s sweep as `logger` writes it, each column through `edit`.
fn written(logger: &Logger, edit: impl Fn(&mut Log)) -> Log {
    let mut log = log_of(&GenCase::nominal(sweep_of(10.0), 100), 5, logger);
    edit(&mut log);
    log
}

fn negate(v: &mut [f64]) {
    for x in v {
        *x = -*x;
    }
}

/// `log` saved and read back as the paper rig reads a file.
fn record_of(log: &Log, dir: &Path) -> Record {
    let path = dir.join("log.csv");
    log.save(&path).unwrap();
    Rig::paper().load_log(&path).unwrap().record
}

/// How the columns of `log` are read.
fn signs_of(log: &Log) -> ColumnSigns {
    let dir = tempfile::tempdir().unwrap();
    columns::read(&Rig::paper(), &record_of(log, dir.path())).unwrap()
}

/// `log` diagnosed as `host-sim gap FILE` does, the car fitted: it must be `none`, with its
/// columns read as `expected`.
fn none_with(log: &Log, expected: impl Fn(&ColumnSigns) -> bool) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("log.csv");
    log.save(&path).unwrap();
    let (_, choice) = gap_file::assert_none(&path, "log.csv");
    let signs = choice.columns.unwrap();
    assert!(expected(&signs), "{signs:?}: {}", choice.describe());
}

#[test]
fn columns_written_as_the_car_has_them_are_read_as_logged() {
    for logger in [
        team(),
        Logger::ours(1000),
        Logger {
            instant_current: true,
            ..team()
        },
        Logger {
            car: LoggedCar::Epos4StatusFrame,
            header: false,
            ..Logger::ours(100)
        },
    ] {
        let s = signs_of(&written(&logger, |_| {}));
        assert!(!s.any(), "{}: {s:?}", logger.describe());
        assert_eq!(s.refusal(), None, "{}: {s:?}", logger.describe());
        assert!(s.output_correlation > 0.9, "{}: {s:?}", logger.describe());
        assert!(s.effort_scale > 0.5, "{}: {s:?}", logger.describe());
    }
}

/// A reference that reaches the car 60 ms late (the world's longest) lags every column
/// alike: read at no lag, the world's sweep with a 59 ms late reference and rack friction
/// read its column at 0.48-0.59 against the nominal model's and its current at x-0.20 to
/// x0.21, near the other sign's bar. Read at the lag where the column follows the model's,
/// nothing is reversed; the current sensor the other way round on the same car still is.
#[test]
fn a_late_car_is_read_at_its_lag_not_as_a_column_of_the_other_sign() {
    let mut case = GenCase::nominal(sweep_of(10.0), 100);
    case.truth.reference_delay_s = 0.06;
    let dir = tempfile::tempdir().unwrap();
    let mut log = log_of(&case, 5, &team());
    let s = columns::read(&Rig::paper(), &record_of(&log, dir.path())).unwrap();
    assert!(!s.any() && s.refusal().is_none(), "{s:?}");
    assert!((0.05..=0.08).contains(&s.lag_s), "{s:?}");
    assert!(s.output_correlation > 0.9 && s.effort_scale > 0.5, "{s:?}");
    negate(&mut log.current_a);
    let s = columns::read(&Rig::paper(), &record_of(&log, dir.path())).unwrap();
    assert!(s.effort_reversed && !s.output_reversed, "{s:?}");
}

/// The current sensor the other way round. Read as logged, the same car was named a 100 ms
/// late current.
#[test]
fn a_current_logged_with_the_other_sign_is_read_negated() {
    let log = written(&team(), |l| negate(&mut l.current_a));
    none_with(&log, |s| {
        s.effort_reversed && !s.output_reversed && !s.reference_reversed && !s.motor_reversed
    });
    // The EPOS4 car as a team's logger of its status frames writes it: the same.
    let epos4 = Logger {
        car: LoggedCar::Epos4StatusFrame,
        header: false,
        ..Logger::ours(100)
    };
    let s = signs_of(&written(&epos4, |l| negate(&mut l.current_a)));
    assert!(s.effort_reversed && !s.output_reversed, "{s:?}");
}

/// The reference in the other convention: every column of the car opposes it, and the
/// reference is the one read negated.
#[test]
fn a_reference_logged_with_the_other_sign_is_read_negated() {
    let log = written(&team(), |l| negate(&mut l.ref_sw_deg));
    none_with(&log, |s| {
        s.reference_reversed && !s.output_reversed && !s.effort_reversed && !s.motor_reversed
    });
}

/// The column counted the other way: read negated, and with it the diagnosis's own.
#[test]
fn a_column_logged_with_the_other_sign_is_read_negated() {
    let log = written(&team(), |l| negate(&mut l.sw_deg));
    none_with(&log, |s| {
        s.output_reversed && !s.effort_reversed && !s.reference_reversed && !s.motor_reversed
    });
}

/// The motor angle counted the other way is read negated; in degrees for radians it is no
/// gearing's and is left out, as a log without one.
#[test]
fn a_motor_angle_of_the_other_sign_or_unit_is_read_so() {
    let s = signs_of(&written(&team(), |l| negate(&mut l.motor_rad)));
    assert!(
        s.motor_reversed && !s.motor_left_out && !s.output_reversed,
        "{s:?}"
    );
    let degrees = written(&team(), |l| {
        for x in &mut l.motor_rad {
            *x = x.to_degrees();
        }
    });
    let s = signs_of(&degrees);
    assert!(s.motor_left_out && !s.motor_reversed, "{s:?}");
    assert!((s.motor_slope.unwrap() - 57.3).abs() < 3.0, "{s:?}");
    let dir = tempfile::tempdir().unwrap();
    let read = s.apply(&record_of(&degrees, dir.path()));
    assert_eq!(read.motor, None);
}

/// A current in another unit (x100: centiamperes; x1000: milliamperes, which on this sweep
/// stay under the reader's +-1e4 A bound) is refused with its figure; a torque constant as
/// far off as the world's (x0.7) is not.
#[test]
fn a_current_in_another_unit_than_amperes_is_refused() {
    let scaled = |k: f64| {
        written(&team(), move |l| {
            for x in &mut l.current_a {
                *x *= k;
            }
        })
    };
    for k in [100.0, 1000.0] {
        let s = signs_of(&scaled(k));
        assert!(s.effort_unit_suspect && !s.any(), "{s:?}");
        assert!((s.effort_scale / k - 1.0).abs() < 0.1, "{s:?}");
        assert!(
            s.refusal().is_some_and(|r| r.contains("log it in amperes")),
            "{s:?}"
        );
    }
    let s = signs_of(&scaled(0.7));
    assert!(!s.effort_unit_suspect && !s.any(), "{s:?}");
    assert_eq!((s.describe().as_str(), s.refusal()), ("", None));
}

/// The record as read: a reversed column negated, the others as logged.
#[test]
fn reading_a_column_negated_changes_that_column_alone() {
    let dir = tempfile::tempdir().unwrap();
    let rec = record_of(&written(&team(), |_| {}), dir.path());
    let signs = ColumnSigns {
        effort_reversed: true,
        ..ColumnSigns::default()
    };
    let read = signs.apply(&rec);
    assert!(read.effort.iter().zip(&rec.effort).all(|(a, b)| *a == -*b));
    assert_eq!(
        (&read.reference, &read.output, &read.motor),
        (&rec.reference, &rec.output, &rec.motor)
    );
    assert_eq!(ColumnSigns::default().apply(&rec), rec);
}

/// A column in radians beside a reference in degrees, or in degrees beside one in radians,
/// is refused, with the figure; the same log in one unit, and with its column negated, is
/// not.
#[test]
fn a_column_in_another_unit_than_its_reference_is_refused() {
    let scaled = |k: f64| {
        signs_of(&written(&team(), |l| {
            for x in &mut l.sw_deg {
                *x *= k;
            }
        }))
    };
    for (k, slope) in [(1f64.to_radians(), 0.0175), (1f64.to_degrees(), 57.3)] {
        let s = scaled(k);
        assert!((s.output_slope / slope - 1.0).abs() < 0.2, "{s:?}");
        assert!(
            s.refusal().is_some_and(|r| r.contains("not in one unit")),
            "{s:?}"
        );
    }
    for k in [1.0, -1.0] {
        let s = scaled(k);
        assert!((s.output_slope.abs() - 1.0).abs() < 0.1, "{s:?}");
        assert_eq!(s.refusal(), None, "{s:?}");
    }
}

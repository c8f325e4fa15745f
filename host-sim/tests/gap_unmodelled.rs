//! The independent world's cars with an effect no candidate has
//! ([`host_sim::gap::generator::draw_unmodelled`]): each effect shows in the log it writes, the
//! cars are the world's own cases otherwise, and the diagnosis, run as `host-sim gap selftest
//! --unmodelled --case` runs it, answers them `unexplained` or `parameters`, never a named
//! effect.

use host_sim::gap::generator::{GenCase, Unmodelled, draw, draw_unmodelled, record_of};
use host_sim::gap::selftest::{self, World};

#[path = "support/world_sweep.rs"]
mod world_sweep;
use world_sweep::sweep;

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len().max(1) as f64
}

fn rms(v: &[f64]) -> f64 {
    (v.iter().map(|x| x * x).sum::<f64>() / v.len().max(1) as f64).sqrt()
}

/// The table's car under a sweep with `unmodelled`, logged at 200 Hz.
fn logged(unmodelled: Unmodelled) -> host_sim::gap::Record {
    let mut case = GenCase::nominal(sweep(), 200);
    case.truth.unmodelled = unmodelled;
    record_of(&case, 3)
}

#[test]
fn each_unmodelled_effect_shows_in_the_log() {
    let clean = logged(Unmodelled::NONE);
    // The sensor reads 0.4 A high, and the log reads the sensor.
    let offset = logged(Unmodelled {
        current_offset_a: 0.4,
        ..Unmodelled::NONE
    });
    let shift = mean(&offset.effort) - mean(&clean.effort);
    println!("offset: log's mean current moved {shift:+.3} A");
    assert!(shift.abs() > 0.2, "{shift} A");
    // A weaker magnet: the same motion needs a third more current.
    let weak = logged(Unmodelled {
        torque_constant_factor: 0.75,
        ..Unmodelled::NONE
    });
    let gain = rms(&weak.effort) / rms(&clean.effort);
    println!("torque constant x0.75: RMS current x{gain:.3}");
    assert!((1.2..1.45).contains(&gain), "x{gain}");
    // Cogging: a torque the current must cancel, so the current differs from the clean car's
    // by more than the sensor's 0.1 A of noise.
    let cogged = logged(Unmodelled {
        cogging_nm: 0.03,
        ..Unmodelled::NONE
    });
    let diff: Vec<f64> = cogged
        .effort
        .iter()
        .zip(&clean.effort)
        .map(|(a, b)| a - b)
        .collect();
    println!(
        "cogging 0.03 Nm: current differs by {:.3} A RMS",
        rms(&diff)
    );
    assert!(rms(&diff) > 0.1, "{} A", rms(&diff));
    // The column encoder's zero 5 counts off: every row's column reads 5 counts high.
    let zeroed = logged(Unmodelled {
        column_zero_counts: 5,
        ..Unmodelled::NONE
    });
    let count = 360.0 / 4096.0;
    let shifts: Vec<f64> = zeroed
        .output
        .iter()
        .zip(&clean.output)
        .map(|(a, b)| (a - b) / count)
        .collect();
    println!(
        "column zero 5 counts: the column moved {:.2}-{:.2} counts",
        shifts.iter().cloned().fold(f64::INFINITY, f64::min),
        shifts.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
    );
    assert!(shifts.iter().all(|d| (d - 5.0).abs() < 1e-3));
}

#[test]
fn an_unmodelled_car_is_the_worlds_case_with_its_effects_replaced() {
    for i in 0..12 {
        let world = draw(1, i, 12.0);
        let car = draw_unmodelled(1, i, 12.0);
        assert!(
            car.scenario.starts_with(&world.scenario),
            "{}",
            car.scenario
        );
        assert_eq!(car.hidden, ["unmodelled"]);
        assert_eq!(
            (car.log_rate_hz, car.skew_s),
            (world.log_rate_hz, world.skew_s)
        );
        assert_eq!(car.reference, world.reference);
        let t = car.truth;
        assert_eq!(
            (t.rack_friction_n, t.belt_play_deg, t.dahl_force_n),
            (0.0, 0.0, 0.0)
        );
        assert_eq!(t.reference_delay_s, 0.0);
        // Exactly one unmodelled effect.
        let u = t.unmodelled;
        let set = [
            u.torque_constant_factor != 1.0,
            u.current_offset_a != 0.0,
            u.cogging_nm != 0.0,
            u.column_zero_counts != 0,
        ];
        assert_eq!(set.iter().filter(|s| **s).count(), 1, "{u:?}");
        // Table 4 off by up to 10 %, as every car of the world.
        for (name, factor) in table_factors(&t.plant) {
            assert!((0.9..=1.1).contains(&factor), "case {i}: {name} x{factor}");
        }
    }
}

fn table_factors(plant: &host_sim::plant::PlantParams) -> Vec<(&'static str, f64)> {
    let table = host_sim::plant::PlantParams::PAPER.identified();
    plant
        .identified()
        .iter()
        .zip(table.iter())
        .filter(|(_, (_, paper))| *paper != 0.0)
        .map(|((name, car), (_, paper))| (*name, car / paper))
        .collect()
}

/// Four of the world's unmodelled cars on seed 1 (as `gap selftest --unmodelled --case
/// 7,15,22,26`): the current sensor 0.31 A low, the torque constant x1.36, the column encoder's
/// zero 3 counts (0.26 deg) high, and the torque constant x0.72. None may be named an effect,
/// nor `none`: the first is a constant left in the current, the second a current 0.72 times the
/// model's throughout (before that scale was read, `none` at a nominal GoF of 68.7 %: the refit
/// of Table 4 within x1.5 left 2.8 times the floor), the third a constant left in the column
/// (unread, it would be `none` at 91.7 %), the fourth a car off Table 4 to the fits.
#[test]
fn a_car_with_an_effect_no_candidate_has_is_answered_unexplained_or_parameters() {
    let report = unmodelled(&[7, 15, 22, 26]);
    for r in &report.cases {
        println!(
            "case {} {}: {:?}, {}",
            r.case.index, r.case.scenario, r.named, r.reason
        );
        assert!(
            matches!(r.named.as_slice(), [n] if n == "unexplained" || n == "parameters"),
            "case {}: {:?}",
            r.case.index,
            r.named
        );
        assert!(r.correct);
    }
    // The rule the selftest scores by: a named effect or `none` is wrong on such a car.
    let hidden = ["unmodelled".to_string()];
    assert!(!selftest::right(&hidden, &[]));
    assert!(!selftest::right(&hidden, &["delay".to_string()]));
    assert!(selftest::right(&hidden, &["parameters".to_string()]));
}

/// The world's unmodelled cars `cases` of seed 1, diagnosed as `gap selftest --unmodelled
/// --case` diagnoses them.
fn unmodelled(cases: &[usize]) -> selftest::SelftestReport {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    selftest::run(World::Unmodelled, cases, 1, 12.0, &opts, &|_| {})
}

/// The world's unmodelled car `case` of seed 1 from our logger's file and from `logger`'s, as
/// `gap selftest --unmodelled --case CASE --loggers LOGGER` diagnoses them (the car read from
/// each file).
fn unmodelled_under(case: usize, logger: selftest::LoggerKind) -> selftest::LoggersReport {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let cars = selftest::Cars {
        world: World::Unmodelled,
        cases: &[case],
        seed: 1,
        duration_s: 12.0,
    };
    selftest::run_loggers(&[logger], (None, None), cars, &opts, None, &|_| {})
        .unwrap_or_else(|e| panic!("{e}"))
}

/// One of them, with its verdict printed.
fn diagnosed(case: usize) -> selftest::CaseResult {
    let r = unmodelled(&[case]).cases.remove(0);
    println!(
        "case {case} {}: {:?}, {}",
        r.case.scenario, r.named, r.reason
    );
    r
}

/// The world's cogging track on seed 1 (as `gap selftest --unmodelled --case 39`): 0.027 Nm
/// at 24 periods a motor turn, logged at 100 Hz. Its nominal GoF (88.9 %) and a refit of
/// Table 4 within x1.5 leave no more than an effect-free car's, so those alone say `none`; where
/// the motor is slow the current keeps the cogging against the rotor's angle, a line no
/// candidate effect makes, and the car is `unexplained` with that line named.
#[test]
fn a_cogging_motor_is_read_from_the_current_against_the_rotors_angle() {
    let r = &diagnosed(39);
    assert!(r.case.scenario.contains("cogging"), "{}", r.case.scenario);
    assert_eq!(r.named, ["unexplained"]);
    let line = r.motor_ripple.expect("a motor column and slow rows");
    println!("{line:?}, ratio {:.1}", line.ratio());
    assert_eq!(line.periods_per_rev, 24);
    assert!(line.stands_out());
    assert!(r.reason.contains("24 periods a motor turn"), "{}", r.reason);
}

/// The column encoder's zero 3 counts (0.26 deg) high, the smallest the world draws, on a
/// 1 kHz sweep (`--unmodelled --case 22`): the column's residual keeps it throughout, and the
/// car is `unexplained` with the offset read within a count.
#[test]
fn a_column_whose_zero_is_off_is_unexplained_with_the_offset_read() {
    let r = &diagnosed(22);
    assert!(
        r.case.scenario.contains("column zero +0.26"),
        "{}",
        r.case.scenario
    );
    assert_eq!(r.named, ["unexplained"]);
    let zero = r.output_offset;
    println!("{zero:?}");
    assert!(zero.stands_out());
    assert!(
        (zero.mean - 3.0 * 360.0 / 4096.0).abs() < 360.0 / 4096.0,
        "{zero:?}"
    );
    assert!(r.reason.contains("a sensor's zero off"), "{}", r.reason);
}

/// The torque constant x0.71 on a 200 Hz sweep (`--unmodelled --case 57`), from our logger's
/// file and from the team's logger drawn with the case (1 kHz, 1 % of rows lost), as
/// `gap selftest --unmodelled --case 57 --loggers drawn` runs it. The current is 1.4 times
/// the model's; rack friction, fitted alone, takes most of that share (where the damping's
/// current goes with the motion's sign) and removes 67 % of the cost. But the share holds in
/// every part of the log, at 47 standard errors, which no friction makes (the world's read at
/// most 6): the car is `unexplained`, never `coulomb_friction`.
#[test]
fn a_weak_torque_constant_is_not_named_friction_under_either_logger() {
    let report = unmodelled_under(57, selftest::LoggerKind::Drawn);
    assert_eq!(report.loggers.len(), 2);
    for l in &report.loggers {
        let r = &l.report.cases[0];
        let beside = r.effort_scale_beside_friction;
        println!(
            "{}: {} {:?}, scale x{:.3}, beside friction x{:.3} +- {:.3}; {}",
            l.kind,
            r.case.scenario,
            r.named,
            r.effort_scale.factor,
            beside.factor,
            beside.standard_error,
            r.reason
        );
        assert!(
            r.case.scenario.contains("torque constant x0.71"),
            "{}",
            r.case.scenario
        );
        assert_eq!(r.named, ["unexplained"], "{}: {}", l.kind, r.reason);
        assert!(r.effort_scale.significance() > 12.0, "{:?}", r.effort_scale);
        assert!(r.reason.contains("the effort is x1.40"), "{}", r.reason);
    }
    // The team's file is the one friction had been named on.
    let team = &report.loggers[1].report.cases[0];
    assert!(
        team.reason.contains("stands in for a torque constant off"),
        "{}",
        team.reason
    );
}

/// The default car: the torque constant x0.74 (`--unmodelled --case 34`) on the world's EPOS4
/// car, as a team's logger writes a row per TPDO on an ECU clock that drifts, as
/// `gap selftest --unmodelled --case 34 --loggers epos4-status-drift` runs it. Friction fitted
/// alone removes 62 % of the cost; beside a friction of the motion's sign the current reads
/// only x1.15, but alone it is x1.22 the model's at 93 standard errors: `unexplained`.
#[test]
fn a_weak_torque_constant_on_the_epos4_car_is_not_named_friction() {
    let team = selftest::LoggerKind::parse("epos4-status-drift").unwrap();
    let report = unmodelled_under(34, team);
    let r = &report.loggers[1].report.cases[0];
    println!(
        "{}: {:?}, scale {:?}; {}",
        r.case.scenario, r.named, r.effort_scale, r.reason
    );
    assert!(
        r.case.scenario.contains("torque constant x0.74"),
        "{}",
        r.case.scenario
    );
    assert_eq!(r.named, ["unexplained"], "{}", r.reason);
    assert!(
        r.reason.contains("stands in for a torque constant off"),
        "{}",
        r.reason
    );
}

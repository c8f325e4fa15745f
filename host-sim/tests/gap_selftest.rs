//! The withheld-effect checks. On the diagnosis's own model (`World::Model`): 50 logs with a hidden
//! effect (or none, or two) in the candidate forms, diagnosed blind; at least 90 % must be named
//! right. It checks the search and the verdict rules. On the independent world
//! (`World::Independent`, host-sim/README.md's figure, `host-sim gap selftest`): its first 50
//! cases, which check the model. And two of its cars written by two of its loggers
//! (`host-sim gap selftest --loggers`), which check that the verdict is the car's, not the
//! logger's.

#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use host_sim::gap::selftest;

/// Cases `0..n` of seed 1 in `world`, diagnosed as `host-sim gap selftest` does, and printed.
fn run(world: selftest::World, n: usize) -> selftest::SelftestReport {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let report = selftest::run(world, &(0..n).collect::<Vec<_>>(), 1, 12.0, &opts, &|_| {});
    print(&report);
    report
}

fn print(report: &selftest::SelftestReport) {
    for r in &report.cases {
        println!(
            "case {:3} {:<40} hidden {:<28} named {:<28} GoF {:5.1} -> {:5.1} %",
            r.case.index,
            r.case.scenario,
            selftest::label(&r.case.hidden),
            selftest::label(&r.named),
            100.0 * r.gof_before,
            100.0 * r.gof_after
        );
    }
    println!("{}", report.confusion_table());
}

#[test]
fn selftest_names_at_least_90_percent_of_withheld_effects() {
    let report = run(selftest::World::Model, 50);
    assert!(report.cases.len() >= 50);
    assert!(
        report.accuracy >= 0.9,
        "named right {:.0} %\n{}",
        100.0 * report.accuracy,
        report.confusion_table()
    );
}

/// The independent world's first 50 cases (seed 1; host-sim/README.md's 200 are a superset): 46
/// named right (92 %) in the 200's release run, every effect-free car `none`. The bar, 43, was
/// set when the figure was 44: a change to the diagnosis that loses four of these fails here,
/// before anyone runs the 10-minute 200.
#[test]
fn the_independent_worlds_first_50_cases() {
    let report = run(selftest::World::Independent, 50);
    assert_eq!(report.cases.len(), 50);
    let right = report.cases.iter().filter(|r| r.correct).count();
    assert!(
        right >= 43,
        "{right} of 50 named right\n{}",
        report.confusion_table()
    );
    for r in report.cases.iter().filter(|r| r.case.hidden.is_empty()) {
        assert!(
            r.named.is_empty(),
            "case {}: an effect-free car named {:?}: {}",
            r.case.index,
            r.named,
            r.reason
        );
    }
    the_balance_reads_each_car_on_the_right_side_of_its_rule(&report);
}

/// The torque balance, the model-free reading beside the verdicts, on the same 50 cars: where
/// it holds, it reads every car with play above half the smallest play the diagnosis names
/// (the size under which it rules the candidate out) and every car without below it, and the
/// same for the force at the rack on cars with rack friction and on cars with neither friction
/// nor a tyre. The summary the selftest prints says so.
fn the_balance_reads_each_car_on_the_right_side_of_its_rule(report: &selftest::SelftestReport) {
    use host_sim::gap::{EffectKind, rig::Rig};
    // The diagnosis rules a candidate out below half its minimum size (`diagnose`'s `half`).
    let rig = Rig::paper();
    let play_limit = EffectKind::BeltPlay.min_size(&rig) / 2.0;
    let force_limit = EffectKind::RackFriction.min_size(&rig) / 2.0;
    let mut held = 0;
    for r in &report.cases {
        let (Some(case), Some(g)) = (&r.case.truth, &r.signature) else {
            continue;
        };
        if !g.holds {
            continue;
        }
        held += 1;
        let t = &case.truth;
        let play_seen = g.belt_play_deg > play_limit;
        assert_eq!(
            play_seen,
            t.belt_play_deg > 0.0,
            "case {}: play {:.2} deg hidden, {:.2} +- {:.2} read",
            r.case.index,
            t.belt_play_deg,
            g.belt_play_deg,
            g.belt_play_se_deg
        );
        if t.rack_friction_n > 0.0 || t.dahl_force_n == 0.0 {
            assert_eq!(
                g.rack_coulomb_n > force_limit,
                t.rack_friction_n > 0.0,
                "case {}: rack friction {:.0} N hidden, {:.0} +- {:.0} read",
                r.case.index,
                t.rack_friction_n,
                g.rack_coulomb_n,
                g.rack_coulomb_se_n
            );
        }
    }
    assert!(held >= 40, "the balance holds on only {held} of 50 logs");
    let summary = report.balance_summary();
    assert!(
        summary.contains("play in the belt") && summary.contains("Coulomb force at the rack"),
        "{summary}"
    );
    println!("{summary}");
}

/// Two of the independent world's cars at 100 Hz (seed 1: an effect-free sweep and a late
/// reference) diagnosed from our logger's file and from a team's (the reference that starts
/// at each row, stamps +-1 ms, 1 % of rows lost, no header), as `host-sim gap selftest
/// --case 0,9 --loggers starting-100-jitter-drop --drive direct --controller paper` runs
/// them: the same car gets the same verdict, and the team's convention is found from the log.
/// The car is given, as a team that knows its drive gives it: with the drive fitted, the late
/// reference's log goes to the EPOS4 car, whose SYNC phase takes up part of the
/// delay (nominal GoF 71.7 % against the direct car's 65.0 %), and is called `parameters`,
/// a defect still open.
#[test]
fn two_cars_under_two_loggers() {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let team = selftest::LoggerKind::parse("starting-100-jitter-drop").unwrap();
    let car = (
        Some(host_sim::gap::rig::CarDrive::Direct),
        Some(host_sim::sim::Controller::Paper),
    );
    let cars = selftest::Cars {
        world: selftest::World::Independent,
        cases: &[0, 9],
        seed: 1,
        duration_s: 12.0,
    };
    let report = selftest::run_loggers(&[team], car, cars, &opts, None, &|_| {}).unwrap();
    print!("{}", report.table());
    let kinds: Vec<&str> = report.loggers.iter().map(|l| l.kind.as_str()).collect();
    assert_eq!(kinds, ["ours", "starting-100-jitter-drop"]);
    for l in &report.loggers {
        assert_eq!(l.report.cases.len(), 2, "{}", l.kind);
        for r in &l.report.cases {
            let by = r.logger.as_ref().unwrap();
            let car = by.car.as_ref().unwrap();
            println!(
                "{} case {}: {} ({}); {:?} {}",
                l.kind,
                r.case.index,
                selftest::label(&r.named),
                car.describe(),
                by.log_timing,
                r.reason
            );
            assert_eq!(by.kind, l.kind);
            assert_eq!(by.logger.rate_hz, 100);
            assert_eq!(
                r.named, r.case.hidden,
                "{} case {}: {}",
                l.kind, r.case.index, r.reason
            );
        }
    }
    // Ours says its convention in its header; the team's is found, one row late.
    let team = &report.loggers[1];
    for r in &team.report.cases {
        let by = r.logger.as_ref().unwrap();
        assert_eq!(by.car.as_ref().unwrap().reference_shift_rows, Some(1));
        assert!(by.log_timing.missing_rows > 0, "{:?}", by.log_timing);
    }
    assert!(
        team.changed_vs_ours.is_empty(),
        "{:?}",
        team.changed_vs_ours
    );
}

//! The withheld-effect checks. On the diagnosis's own model (`World::Model`): 50 logs with a hidden
//! effect (or none, or two) in the candidate forms, diagnosed blind; at least 90 % must be named
//! right. It checks the search and the verdict rules. On the independent world
//! (`World::Independent`, host-sim/README.md's figure, `host-sim gap selftest`): its first 50
//! cases, which check the model.

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

/// The independent world's first 50 cases (seed 1; host-sim/README.md's 200 are a superset): 44
/// named right (88 %), every effect-free car `none`. The bar is the figure less one
/// case: a change to the diagnosis that loses two of these fails here, before anyone runs the
/// 18-minute 200.
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
}

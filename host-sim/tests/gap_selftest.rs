//! The withheld-effect check: 50 logs with a hidden effect (or none, or two), diagnosed blind;
//! at least 90 % must be named right.

use host_sim::gap::selftest;

#[test]
fn selftest_names_at_least_90_percent_of_withheld_effects() {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let report = selftest::run(50, 1, 12.0, &opts, &|_| {});
    for r in &report.cases {
        println!(
            "case {:3} {:<32} hidden {:<28} named {:<28} GoF {:5.1} -> {:5.1} %",
            r.case.index,
            r.case.scenario,
            selftest::label(&r.case.hidden),
            selftest::label(&r.named),
            100.0 * r.gof_before,
            100.0 * r.gof_after
        );
    }
    println!("{}", report.confusion_table());
    assert!(report.cases.len() >= 50);
    assert!(
        report.accuracy >= 0.9,
        "named right {:.0} %\n{}",
        100.0 * report.accuracy,
        report.confusion_table()
    );
}

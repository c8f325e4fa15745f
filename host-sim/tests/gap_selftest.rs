//! The withheld-effect check on the diagnosis's own model (`World::Model`): 50 logs with a
//! hidden effect (or none, or two) in the candidate forms, diagnosed blind; at least 90 % must
//! be named right. It checks the search and the verdict rules; the independent world's figure
//! (`host-sim gap selftest`) is the one that checks the model.

use host_sim::gap::selftest;

#[test]
fn selftest_names_at_least_90_percent_of_withheld_effects() {
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let report = selftest::run(
        selftest::World::Model,
        &(0..50).collect::<Vec<_>>(),
        1,
        12.0,
        &opts,
        &|_| {},
    );
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

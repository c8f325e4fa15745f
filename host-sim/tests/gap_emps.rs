//! EMPS (real data, `host-sim/data/emps`, in the repository so that a clone alone passes):
//! fitted on DATA_EMPS, checked on DATA_EMPS_PULSES,
//! the verdict is Coulomb friction and the effort's relative error falls from the linear
//! model's (about 17 %) to 9 % or less (published reference model: 5.85 % / 8.94 %).

use host_sim::gap::rig::Rig;
use host_sim::gap::{EffectKind, Options, diagnose};
use std::path::PathBuf;

fn emps_dir() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("data/emps")
}

#[test]
fn emps_verdict_is_coulomb_friction_and_effort_error_falls_below_9_percent() {
    let dir = emps_dir();
    let rig_file = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("rigs/emps.json");
    let rig = Rig::load(&rig_file).expect("rigs/emps.json");
    assert_eq!(
        rig,
        Rig::emps(),
        "rigs/emps.json matches the built-in EMPS rig"
    );
    let train = rig
        .load_record(&dir.join("DATA_EMPS.csv.gz"))
        .expect("DATA_EMPS.csv.gz");
    let test = rig
        .load_record(&dir.join("DATA_EMPS_PULSES.csv.gz"))
        .expect("DATA_EMPS_PULSES.csv.gz");
    let opts = Options {
        effects: EffectKind::for_rig(&rig),
        threads: 2,
        ..Options::default()
    };
    let d = diagnose(&rig, &train, Some(&test), &opts);
    println!("{}", d.summary());
    assert_eq!(d.verdict.effects, vec!["coulomb_friction".to_string()]);
    let before = d
        .baseline_validation
        .expect("validation fit")
        .effort_rel_error_pct;
    let after = d
        .verdict
        .fit_validation
        .expect("validation fit")
        .effort_rel_error_pct;
    assert!(
        (15.0..20.0).contains(&d.baseline.effort_rel_error_pct) && (15.0..20.0).contains(&before),
        "linear model: {:.2} % / {before:.2} %, expected about 17 %",
        d.baseline.effort_rel_error_pct
    );
    assert!(
        after <= 9.0,
        "validation effort error with Coulomb {after:.2} %"
    );
    assert!(d.verdict.fit_after.effort_rel_error_pct <= 7.0);
    let fc = d.ranking[0].params["force_n"];
    assert!((15.0..25.0).contains(&fc), "Fc {fc} N (published 20.39 N)");
}

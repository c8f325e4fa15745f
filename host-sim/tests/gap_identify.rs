//! `identify` (the paper's section 4.3) on a log whose Table 4 parameters are known and differ
//! from the rig's: the fit must move them toward the truth and raise the GoF, and `gap
//! --refit-linear` must then find no unmodelled effect in that log. Own test binary, so it
//! runs beside the other gap tests.

use host_sim::gap::identify::{apply, identify};
use host_sim::gap::model::Effects;
use host_sim::gap::rig::{Rig, RigModel};
use host_sim::gap::selftest::{Case, record_of};
use host_sim::gap::{EffectKind, Options, diagnose};

/// The linear chirp of `host_sim::scenario::Sweep` from 0.2 Hz, deg at the wheel, 100 Hz.
fn chirp(amplitude: f64, f1: f64, duration_s: f64) -> Vec<f64> {
    host_sim::scenario::Sweep {
        amplitude_deg: amplitude,
        f_start_hz: 0.2,
        f_end_hz: f1,
        duration_s,
    }
    .samples()
}

#[test]
fn identify_recovers_a_changed_belt_and_refit_leaves_no_effect() {
    // The "car": the belt twice as stiff and the screw's damping 1.6 times the paper's.
    let rig = Rig::paper();
    let mut car = rig.clone();
    let RigModel::Paper(m) = &mut car.model else {
        panic!("the paper rig is paper-type");
    };
    let (k_b, beta_bs) = (m.plant.k_b * 2.0, m.plant.beta_bs * 1.6);
    m.plant.k_b = k_b;
    m.plant.beta_bs = beta_bs;
    let case = Case {
        index: 1,
        scenario: "chirp".into(),
        hidden: vec![],
        effects: Effects::nominal(),
        reference: chirp(8.0, 6.0, 12.0),
    };
    let rec = record_of(&car, &case, 5);

    let id = identify(&rig, &rec, 10, false).expect("paper rig");
    println!("{}", id.summary());
    println!("GoF {:.4} -> {:.4}", id.gof_before, id.gof);
    assert!(
        id.gof > id.gof_before + 0.02,
        "{} -> {}",
        id.gof_before,
        id.gof
    );
    let fitted = id.params["k_b"];
    let paper = k_b / 2.0;
    assert!(
        (fitted - k_b).abs() < (paper - k_b).abs() / 2.0,
        "k_b fitted {fitted:.4}, truth {k_b:.4}, rig {paper:.4}"
    );

    // --refit-linear: the diagnosis against the refitted model finds nothing to add.
    let mut refit = rig.clone();
    apply(&mut refit, &id);
    let opts = Options {
        threads: 2,
        ..Options::default()
    };
    let d = diagnose(&refit, &rec, None, &opts);
    println!("{}", d.summary());
    // No candidate effect may be named: `none`, or `unexplained` when the refit leaves more
    // than the noise (the refit is a local fit of nine parameters).
    assert!(
        d.verdict
            .effects
            .iter()
            .all(|e| EffectKind::from_name(e).is_none()),
        "a linear change is no unmodelled effect once refitted: {:?}",
        d.verdict
    );
}

//! The selftest's world ([`host_sim::gap::generator`]) against the diagnosis's model: with the
//! table's plant and no effect they must agree (two implementations of one physics), at every
//! log rate; with belt play the column lags the motor at reversals, which the nominal model
//! cannot follow.

use host_sim::gap::generator::{GenCase, record_of};
use host_sim::gap::model::Effects;
use host_sim::gap::rig::Rig;
use host_sim::gap::{Scorer, simulate};

fn sweep() -> Vec<f64> {
    host_sim::scenario::Sweep {
        amplitude_deg: 8.0,
        f_start_hz: 0.2,
        f_end_hz: 4.0,
        duration_s: 6.0,
    }
    .samples()
}

#[test]
fn the_rk4_world_and_the_model_agree_without_effects_at_every_log_rate() {
    let rig = Rig::paper();
    for rate in [100, 200, 1000] {
        let case = GenCase::nominal(sweep(), rate);
        let rec = record_of(&case, 3);
        let sim = simulate(&rig, &rec, &Effects::nominal());
        let fit = Scorer::new(&rig, &rec).fit(&rec, &sim);
        println!("{rate} Hz: {fit:?}");
        assert!(rec.len() >= 590, "{} steps", rec.len());
        // The output to within the encoder's and the Hall's resolution; the current within
        // its chatter and noise.
        assert!(
            fit.rms_output < 0.08,
            "{rate} Hz: output RMS {}",
            fit.rms_output
        );
        assert!(fit.gof_output > 0.98, "{rate} Hz: {fit:?}");
        assert!(fit.gof_effort > 0.7, "{rate} Hz: {fit:?}");
    }
}

#[test]
fn belt_play_shows_in_the_column_angle() {
    let rig = Rig::paper();
    let mut case = GenCase::nominal(sweep(), 200);
    let clean = record_of(&case, 3);
    case.truth.belt_play_deg = 2.0;
    let played = record_of(&case, 3);
    let sim = simulate(&rig, &clean, &Effects::nominal());
    let scorer = Scorer::new(&rig, &clean);
    let a = scorer.fit(&clean, &sim);
    let b = scorer.fit(&played, &sim);
    println!("clean {a:?}\nplay {b:?}");
    assert!(b.rms_output > 3.0 * a.rms_output, "{a:?} {b:?}");
}

/// Case 109 of the independent world (seed 1): 2.0 deg of play in the belt and 1050 N of
/// creeping friction at the rack under a 5 deg sweep. Fitted alone the friction grows to
/// stand in for the play (1570 N, sharp), and a pair fit that starts there keeps the play at
/// zero, 10 times the noise floor; started where the two share the work it finds both. The
/// diagnosis is run as `host-sim gap selftest --case 109` runs it.
#[test]
fn play_in_the_belt_beside_rack_friction_is_named_on_a_sweep() {
    use host_sim::gap::selftest;
    let mut opts = selftest::default_options();
    opts.threads = 2;
    let report = selftest::run(
        selftest::World::Independent,
        &[109],
        1,
        12.0,
        &opts,
        &|_| {},
    );
    let case = &report.cases[0];
    assert_eq!(case.case.hidden, ["backlash", "coulomb_friction"]);
    assert_eq!(case.named, case.case.hidden, "{}", case.reason);
}

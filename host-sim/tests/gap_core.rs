//! The diagnosis end to end on logs written to disk in the project log format: a nominal log
//! gets the verdict "none", a log with hidden Coulomb friction gets "coulomb_friction", and the
//! JSON carries the fields a team reads (baseline GoF, verdict, ranking, where).

use host_sim::gap::model::Effects;
use host_sim::gap::rig::Rig;
use host_sim::gap::selftest::{Case, record_of};
use host_sim::gap::{Options, diagnose};
use host_sim::logfmt::{Log, Row};

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

/// A log of the paper rig with `effects`, in the project log format (`logfmt`).
fn write_log(dir: &std::path::Path, name: &str, effects: Effects) -> std::path::PathBuf {
    write_log_of(dir, name, effects, chirp(6.0, 4.0, 10.0))
}

/// [`write_log`] with its own reference.
fn write_log_of(
    dir: &std::path::Path,
    name: &str,
    effects: Effects,
    reference: Vec<f64>,
) -> std::path::PathBuf {
    let rig = Rig::paper();
    let case = Case {
        index: 3,
        scenario: "chirp".into(),
        hidden: vec![],
        effects,
        reference,
    };
    let rec = record_of(&rig, &case, 11);
    let per = motor_per_pinion();
    let motor = rec.motor.clone().unwrap_or_default();
    let mut log = Log::new();
    #[allow(clippy::needless_range_loop)]
    for k in 0..rec.len() {
        log.push(
            Row {
                t: (k + 1) as f64 * 0.01,
                ref_sw_deg: rec.reference[k],
                sw_deg: rec.output[k],
                motor_rad: motor[k].to_radians() * per,
                current_a: rec.effort[k],
            },
            &[],
        );
    }
    let path = dir.join(name);
    log.save(&path).expect("write log");
    path
}

fn motor_per_pinion() -> f64 {
    host_sim::plant::PlantParams::PAPER.motor_per_pinion()
}

fn opts() -> Options {
    Options {
        threads: 2,
        ..Options::default()
    }
}

#[test]
fn nominal_log_gets_no_effect_and_coulomb_log_gets_coulomb() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = Rig::paper();

    let nominal = write_log(dir.path(), "nominal.csv", Effects::nominal());
    let rec = rig.load_record(&nominal).expect("load nominal");
    let d = diagnose(&rig, &rec, None, &opts());
    println!("{}", d.summary());
    assert!(d.verdict.effects.is_empty(), "{:?}", d.verdict);

    let mut fx = Effects::nominal();
    fx.coulomb = 0.15;
    let friction = write_log(dir.path(), "coulomb.csv", fx);
    // The validation log: the same car, another excitation.
    let second = write_log_of(dir.path(), "coulomb2.csv", fx, chirp(8.0, 3.0, 10.0));
    let rec = rig.load_record(&friction).expect("load coulomb");
    let d = diagnose(
        &rig,
        &rec,
        Some(&rig.load_record(&second).expect("second")),
        &opts(),
    );
    println!("{}", d.summary());
    assert_eq!(d.verdict.effects, vec!["coulomb_friction".to_string()]);
    assert!(
        d.verdict.gof_validation.unwrap() > d.baseline_validation.unwrap().gof,
        "the validation log agrees"
    );
    assert!(d.verdict.gof_after > d.baseline_gof + 0.05);
    let fc = d.ranking[0].params["torque_nm"];
    assert!((0.1..0.2).contains(&fc), "fitted {fc} Nm, hidden 0.15 Nm");

    let json = d.to_json();
    for key in ["baseline_gof", "verdict", "ranking", "where"] {
        assert!(json.get(key).is_some(), "JSON lacks {key}");
    }
    assert!(json["verdict"]["effects"].is_array());
    assert!(json["verdict"]["gof_validation"].is_number());
    assert!(json["ranking"][0]["params"].is_object());
    assert!(
        json["where"]["bands"]
            .as_array()
            .is_some_and(|b| !b.is_empty())
    );
    assert!(
        json["where"]["regimes"]
            .as_array()
            .is_some_and(|r| r.len() == 4)
    );
    assert!(json["where"]["segment"].is_string());
}

/// An honest verdict: an effect whose fit leaves the validation log further from the car than
/// the nominal model is not named. The friction car's log validated on an effect-free car's:
/// the friction fitted on the first makes the second worse (GoF 92.8 -> 48.0 %); it was named
/// before.
#[test]
fn an_effect_the_validation_log_refutes_is_not_named() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = Rig::paper();
    let nominal = write_log(dir.path(), "nominal.csv", Effects::nominal());
    let mut fx = Effects::nominal();
    fx.coulomb = 0.15;
    let friction = write_log(dir.path(), "coulomb.csv", fx);
    let d = diagnose(
        &rig,
        &rig.load_record(&friction).expect("coulomb"),
        Some(&rig.load_record(&nominal).expect("nominal")),
        &opts(),
    );
    println!("{}", d.summary());
    assert!(
        !d.verdict
            .effects
            .iter()
            .any(|e| e == "coulomb_friction" || e == "parameters"),
        "{:?}: {}",
        d.verdict.effects,
        d.verdict.reason
    );
    assert!(
        d.verdict.reason.contains("below the nominal"),
        "{}",
        d.verdict.reason
    );
    let v = d.verdict.gof_validation.unwrap();
    assert!(
        v >= d.baseline_validation.unwrap().gof,
        "the verdict's validation GoF {v} is not below the nominal's"
    );
}

#[test]
fn rows_on_the_grid_each_fill_their_own_step() {
    // 100 Hz rows at the ends of the 10 ms periods (what host-sim and steer-can write): each
    // row is its own step, the angles and the current exactly, whatever the float rounding of
    // binary fractions of 0.01 s.
    let t: Vec<f64> = (0..12_000).map(|k| (k + 1) as f64 * 0.01).collect();
    let y: Vec<f64> = (0..12_000).map(|k| k as f64).collect();
    let rec = host_sim::gap::Record::from_samples(
        &t,
        &y,
        &y,
        &y,
        None,
        0.01,
        host_sim::gap::CurrentSamples::IntervalMean,
        None,
    );
    assert_eq!(rec.len(), 12_000);
    for k in 0..rec.len() {
        assert_eq!(rec.reference[k], k as f64, "reference, step {k}");
        assert!((rec.output[k] - k as f64).abs() < 1e-9, "output, step {k}");
        assert!((rec.effort[k] - k as f64).abs() < 1e-9, "effort, step {k}");
    }
}

/// A row per SYNC stamped on another clock: a team's logger writes a row as each TPDO
/// arrives, and the ECU's clock runs 72 ppm slow against the vehicle computer's that stamps
/// them, so over 120 s the rows walk 8.6 ms against steps of exactly 10 ms. Each row is still
/// its own step (the rows' spacing is the step at the grid's own rate): read at 10 ms steps,
/// a current that alternates between SYNCs was averaged towards zero where the walk reached
/// half a step.
#[test]
fn rows_a_step_apart_on_a_clock_of_their_own_each_fill_their_own_step() {
    let spacing = 0.01 * (1.0 + 72e-6);
    let t: Vec<f64> = (0..12_000)
        .map(|k| 0.0041 + (k + 1) as f64 * spacing)
        .collect();
    let y: Vec<f64> = (0..12_000).map(|k| k as f64).collect();
    let chatter: Vec<f64> = (0..12_000)
        .map(|k| if k % 2 == 0 { 1.0 } else { -1.0 })
        .collect();
    for current in [
        host_sim::gap::CurrentSamples::IntervalMean,
        host_sim::gap::CurrentSamples::Instantaneous,
    ] {
        let rec = host_sim::gap::Record::from_samples(
            &t,
            &y,
            &y,
            &chatter,
            Some(y.clone()),
            0.01,
            current,
            None,
        );
        assert_eq!(rec.len(), 12_000, "{current:?}");
        assert_eq!(
            rec.dt, 0.01,
            "the model's steps stay the reference's periods"
        );
        for (k, want) in chatter.iter().enumerate() {
            assert_eq!(
                rec.reference[k], k as f64,
                "{current:?}: reference, step {k}"
            );
            assert!(
                (rec.output[k] - k as f64).abs() < 1e-6,
                "{current:?}: output, step {k}"
            );
            let motor = rec.motor.as_ref().unwrap()[k];
            assert!(
                (motor - k as f64).abs() < 1e-6,
                "{current:?}: motor, step {k}"
            );
            assert!(
                (rec.effort[k] - want).abs() < 1e-6,
                "{current:?}: effort, step {k}: {}",
                rec.effort[k]
            );
        }
    }
}

#[test]
fn a_1_khz_log_is_read_as_instants_and_interval_means() {
    // 1 kHz rows: y = t (s) for the angle, the current the mean of t over each 1 ms row
    // interval. The step ends' angle is the period's end; the current is the period's mean.
    let t: Vec<f64> = (1..=2_000).map(|k| k as f64 * 1e-3).collect();
    let mean: Vec<f64> = t.iter().map(|t| t - 0.5e-3).collect();
    let rec = host_sim::gap::Record::from_samples(
        &t,
        &t,
        &t,
        &mean,
        None,
        0.01,
        host_sim::gap::CurrentSamples::IntervalMean,
        None,
    );
    assert_eq!(rec.len(), 200);
    for k in 0..rec.len() {
        let end = (k + 1) as f64 * 0.01;
        assert!((rec.output[k] - end).abs() < 1e-9, "output, step {k}");
        assert!(
            (rec.effort[k] - (end - 0.005)).abs() < 1e-9,
            "effort, step {k}"
        );
    }
}

#[test]
fn the_segment_replay_puts_a_delay_before_the_motor_and_backlash_after_it() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = Rig::paper();
    let mut delay = Effects::nominal();
    delay.delay_s = 0.04;
    let mut backlash = Effects::nominal();
    backlash.backlash = 3.0;
    for (name, fx, segment) in [
        ("delay.csv", delay, "reference->motor"),
        ("backlash.csv", backlash, "motor->steering"),
    ] {
        let rec = rig
            .load_record(&write_log(dir.path(), name, fx))
            .expect("load");
        let d = diagnose(&rig, &rec, None, &opts());
        let json = d.to_json();
        println!("{name}: {}", json["where"]);
        assert_eq!(json["where"]["segment"], segment, "{name}");
    }
}

/// The log at `path` again, with its current column `rows` rows late (each row takes the
/// current of the row `rows` before it; the first rows repeat the first current): a current
/// that reaches the logger later than the angles, made here on the file, not by the model.
fn current_late_by_rows(path: &std::path::Path, rows: usize) -> std::path::PathBuf {
    let mut log = Log::load(path).expect("read log");
    let prompt = log.current_a.clone();
    for (k, current) in log.current_a.iter_mut().enumerate() {
        *current = prompt[k.saturating_sub(rows)];
    }
    let out = path.with_extension("late.csv");
    log.save(&out).expect("write log");
    out
}

#[test]
fn a_current_two_periods_late_against_the_angles_is_named_a_delay_of_the_current() {
    let dir = tempfile::tempdir().expect("tempdir");
    let rig = Rig::paper();
    let nominal = write_log(dir.path(), "nominal.csv", Effects::nominal());
    let late = current_late_by_rows(&nominal, 2);
    let rec = rig.load_record(&late).expect("load");
    let opts = Options {
        effects: host_sim::gap::EffectKind::for_rig(&rig),
        ..opts()
    };
    let d = diagnose(&rig, &rec, None, &opts);
    println!("{}", d.summary());
    assert_eq!(
        d.verdict.effects,
        vec!["delay".to_string()],
        "{}",
        d.verdict.reason
    );
    assert_eq!(d.ranking[0].effect, "delay_current", "{}", d.verdict.reason);
    let ms = d.ranking[0].params["delay_ms"];
    assert!(
        (15.0..25.0).contains(&ms),
        "fitted {ms} ms, the file's current is 20 ms late"
    );
}

#[test]
fn a_late_reference_and_every_measurement_late_are_one_delay_to_a_log() {
    // Why the diagnosis has one `delay` for the reference and for all measurements alike: the
    // loop is time-invariant, so the log of a reference 30 ms late is the log of the prompt
    // reference with every signal 30 ms late (3 rows), to well within the sensors' noise
    // (0.02 deg on the angle, 0.1 A on the current), while the delay itself moves the
    // signals far more.
    let rig = Rig::paper();
    let rec = host_sim::gap::Record {
        dt: 0.01,
        reference: chirp(6.0, 4.0, 10.0),
        ..host_sim::gap::Record::default()
    };
    let prompt = host_sim::gap::simulate(&rig, &rec, &Effects::nominal());
    let mut fx = Effects::nominal();
    fx.delay_s = 0.03;
    let late_reference = host_sim::gap::simulate(&rig, &rec, &fx);
    let rms = |a: &[f64], b: &[f64], shift: usize| -> f64 {
        let n = a.len() - shift;
        (a[shift..]
            .iter()
            .zip(&b[..n])
            .map(|(x, y)| (x - y).powi(2))
            .sum::<f64>()
            / n as f64)
            .sqrt()
    };
    let angle_shifted = rms(&late_reference.output, &prompt.output, 3);
    let angle_moved = rms(&late_reference.output, &prompt.output, 0);
    let current_shifted = rms(&late_reference.effort, &prompt.effort, 3);
    let current_moved = rms(&late_reference.effort, &prompt.effort, 0);
    println!(
        "angle: {angle_shifted:.4} deg against the shifted log, {angle_moved:.3} deg unshifted; \
         current: {current_shifted:.4} A, {current_moved:.3} A"
    );
    assert!(angle_shifted < 0.02 && angle_moved > 10.0 * angle_shifted);
    assert!(current_shifted < 0.1 && current_moved > 5.0 * current_shifted);
}

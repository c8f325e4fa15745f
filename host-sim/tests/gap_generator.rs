//! The selftest's world ([`host_sim::gap::generator`]) against the diagnosis's model: with the
//! table's plant and no effect they must agree (two implementations of one physics), at every
//! log rate; with belt play the column lags the motor at reversals, which the nominal model
//! cannot follow.

use host_sim::gap::generator::{GenCase, record_of};
use host_sim::gap::model::Effects;
use host_sim::gap::rig::Rig;
use host_sim::gap::{Scorer, simulate};

#[path = "support/world_sweep.rs"]
mod world_sweep;
use world_sweep::sweep;

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

/// The diagnosis of a case of the independent world (seed 1), as `gap selftest --case` runs
/// it, with the log's torque balance used or not. Off, the diagnosis runs as it
/// does where the balance does not hold (an EPOS4 car): the rules tested below are those that
/// decide there. On the cars below the balance rules the play out and the verdicts stay right
/// with it as well.
fn selftest_case_with(index: usize, torque_balance: bool) -> host_sim::gap::selftest::CaseResult {
    selftest_case_of_seed(1, index, torque_balance)
}

/// [`selftest_case_with`] on the world's seed `seed`.
fn selftest_case_of_seed(
    seed: u64,
    index: usize,
    torque_balance: bool,
) -> host_sim::gap::selftest::CaseResult {
    use host_sim::gap::selftest;
    let mut opts = selftest::default_options();
    opts.threads = 2;
    opts.torque_balance = torque_balance;
    let mut report = selftest::run(
        selftest::World::Independent,
        &[index],
        seed,
        12.0,
        &opts,
        &|_| {},
    );
    report.cases.remove(0)
}

/// [`selftest_case_with`] (the balance used) for a case whose hidden effects are `hidden`, checked to be named so.
fn named_right(index: usize, hidden: &[&str]) -> host_sim::gap::selftest::CaseResult {
    named_right_with(index, hidden, true)
}

/// [`named_right`] with the torque balance off ([`selftest_case_with`]).
fn named_right_without_balance(
    index: usize,
    hidden: &[&str],
) -> host_sim::gap::selftest::CaseResult {
    named_right_with(index, hidden, false)
}

fn named_right_with(
    index: usize,
    hidden: &[&str],
    torque_balance: bool,
) -> host_sim::gap::selftest::CaseResult {
    let case = selftest_case_with(index, torque_balance);
    assert_eq!(case.case.hidden, hidden);
    assert_eq!(case.named, case.case.hidden, "{}", case.reason);
    case
}

/// A car of the independent world (seed 1, the index below): 2.0 deg of play in the belt and 1050 N
/// of creeping friction at the rack under a 5 deg sweep. Fitted alone the friction grows to stand
/// in for the play (1570 N, sharp), and a pair fit that starts there keeps the play at zero, 10
/// times the noise floor; started where the two share the work it finds both. The diagnosis is run
/// as `host-sim gap selftest --case` runs it.
#[test]
fn play_in_the_belt_beside_rack_friction_is_named_on_a_sweep() {
    named_right(109, &["backlash", "coulomb_friction"]);
}

/// A car of the independent world (seed 1, the index below): a Dahl tyre alone, under a 5 deg sweep
/// logged at 100 Hz with stamps 1.85 ms late. Belt play beside the tyre removed 46 % of what the
/// tyre alone left, and the pair was named; the tyre with the log's lag fitted beside it leaves
/// less than the pair does, so the play was standing in for the clock. Run as `gap selftest --case`
/// runs it.
#[test]
fn a_late_clock_is_not_named_as_a_second_effect() {
    let case = named_right_without_balance(30, &["tire_ground"]);
    assert!(case.reason.contains("stamps"), "{}", case.reason);
}

/// A car of the independent world (seed 1, the index below): 1050 N of rack friction alone on a
/// 120 s track logged at 200 Hz with stamps 2.05 ms late. With the delay's minimum at half a
/// reference period, a 5.2 ms delay beside the friction was named (a delay the car does not
/// have); a delay under one 10 ms period is within the frame's own jitter and the logger's clock.
#[test]
fn a_delay_under_one_reference_period_is_not_named() {
    named_right(27, &["coulomb_friction"]);
}

/// A car of the independent world (seed 1, the index below): a 52 ms late reference and a Dahl tyre
/// under a 5 deg sweep at 1 kHz. Column play at 3 deg removes the most alone (85 %), the delay
/// alone nearly as much (82 %); fitted on top of the play, a 26 ms delay was named with the play.
/// The pairs grown from the runner-up (the delay) find the tyre beside it.
#[test]
fn a_pair_is_also_grown_from_the_runner_up() {
    let case = named_right_without_balance(14, &["delay", "tire_ground"]);
    assert!(case.reason.starts_with("backlash"), "{}", case.reason);
}

/// A car of the independent world (seed 1, the index below): 2.4 deg of play in the belt and 860 N
/// of creeping friction at the rack on a 120 s track logged at 1 kHz, stamps 2.3 ms late. Each
/// alone stands in for both (the friction at 1710 N removes 98 % of the nominal cost, the play at
/// its 4 deg limit 78 %); grown from the friction, the pair kept the play at 0.66 deg and removed
/// 15 % of what the friction left, and the tyre beside the friction, the best pair, was the log's
/// lag. Started where the two share the work (the play at its size alone, the friction at half its
/// own), the pair finds both.
#[test]
fn play_and_rack_friction_that_share_the_work_are_both_named_on_a_track() {
    named_right(46, &["backlash", "coulomb_friction"]);
}

/// A car of the independent world (seed 1, the index below): 750 N of rack friction and a 20 ms
/// late reference under a 10 deg sweep. Column play at its 4 deg limit removes the most alone (92
/// %), and the delay beside it was named with it. The runner-up family is friction, whose two
/// places nearly tie alone (at the motor 80.4 %, at the rack 79.9 %): the pairs are grown from
/// both, and the rack friction beside the delay explains the log.
#[test]
fn a_pair_is_grown_from_every_place_of_the_runner_up_family() {
    let case = named_right_without_balance(75, &["coulomb_friction", "delay"]);
    assert!(case.reason.starts_with("backlash"), "{}", case.reason);
}

/// A car of the independent world (seed 1, the index below): a 28 ms late reference alone under a 5
/// deg sweep at 1 kHz, Table 4 off by 8-10 % in four parameters. Belt play at 0.58 deg beside the
/// delay removed 63 % of what the delay left and was named; rack friction at 160 N and a tyre at
/// 125 N, both under their minimum size, removed more. What is left is then no effect.
#[test]
fn a_second_effect_that_one_below_its_minimum_outdoes_is_not_named() {
    let case = named_right_without_balance(151, &["delay"]);
    assert!(
        case.reason.contains("below its minimum size"),
        "{}",
        case.reason
    );
}

/// A car of the independent world (seed 1, the index below): a wheel 2.1 times heavier and 0.34
/// times as damped as Table 4's, on a 120 s track logged at 100 Hz. The refit from the table's own
/// values left 6 times the noise floor and the log was called `unexplained`; from a start with the
/// wheel far off the table it explains the log, and the verdict is `parameters`.
#[test]
fn a_car_far_off_the_table_is_not_called_unexplained() {
    let case = named_right(164, &["parameters"]);
    assert!(case.reason.contains("j_w"), "{}", case.reason);
}

/// A car of the independent world (seed 1, the index below): J_W x0.37 and beta_sw x0.49 under a 5
/// deg sweep logged at 100 Hz, stamps 0.95 ms late. From the table's own values the refit stays
/// within x1.5 (1.5 times the noise floor) and the log was called `none`; Table 4 with the log's
/// lag fitted beside it, from a start with the wheel's inertia at x0.4, finds the lighter wheel and
/// removes from what the best car within x1.5 leaves what a second effect would have to:
/// `parameters`.
#[test]
fn a_lighter_wheel_is_found_from_a_far_start() {
    let case = named_right(60, &["parameters"]);
    assert!(
        case.reason.contains("far off the table") && case.reason.contains("j_w x0."),
        "{}",
        case.reason
    );
}

/// A car of the independent world (seed 5, the index below): a belt 0.43 times as stiff as
/// Table 4's under a 10 deg sweep logged at 200 Hz. From the table's own values, and from the
/// wheel's far starts, the refit stayed within x1.5 at 6-7 times the noise floor, and the log
/// was called `unexplained` (its current read x0.64 the model's throughout, as a torque
/// constant off Table 1 would make it); from a start with the belt's stiffness at x0.4 the
/// refit reaches the noise floor: `parameters`.
#[test]
fn a_softer_belt_is_found_from_a_far_start() {
    let case = selftest_case_of_seed(5, 19, true);
    assert_eq!(case.case.hidden, ["parameters"]);
    assert_eq!(case.named, case.case.hidden, "{}", case.reason);
    assert!(
        case.reason.contains("far off the table") && case.reason.contains("k_b x0."),
        "{}",
        case.reason
    );
}

/// The steering wheel hangs on the torsion bar and, in a driverless car, on nothing else: a
/// column-angle and current log sees it only through the bar, reflected to the screw by
/// g^2 = (tau_bs / tau_p)^2 (eq. 6 with printing error 2 mended). Its damping is 1/15 of the
/// screw's own beta_bs and its inertia 1/60 of J*_bs (eq. 8). Measured in the independent
/// world on a 1 kHz log of an 8 deg sweep, against the chatter two nearly equal cars already
/// show (beta_bs x1.01): k_tb x3 changes the log less than that chatter; beta_sw x3 changes
/// it more, and beta_bs raised by the reflected amount (x1.13) takes away only part of it
/// (the bar's corner, k_tb / beta_sw = 104 rad/s, is near the sweep's top). host-sim/README.md's
/// account of the selftest's `parameters` misses rests on these figures.
#[test]
fn the_steering_wheel_side_seen_through_the_torsion_bar() {
    use host_sim::plant::PlantParams;
    let p = PlantParams::PAPER;
    let g2 = p.screw_to_pinion().powi(2);
    let damping_share = g2 * p.beta_sw / p.beta_bs;
    let inertia_share = g2 * p.j_sw / p.j_bs_equivalent();
    println!(
        "beta_sw at the screw: {damping_share:.4} of beta_bs; j_sw: {inertia_share:.5} of J*_bs"
    );
    assert!((damping_share - 0.065).abs() < 0.002, "{damping_share}");
    assert!((inertia_share - 0.0168).abs() < 0.001, "{inertia_share}");

    let log = |f: &dyn Fn(&mut PlantParams)| {
        let mut case = GenCase::nominal(sweep(), 1000);
        f(&mut case.truth.plant);
        record_of(&case, 3)
    };
    let table = log(&|_| {});
    let rms = |a: &[f64], b: &[f64]| {
        (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
    };
    let apart = |r: &host_sim::gap::Record, o: &host_sim::gap::Record| {
        (rms(&r.output, &o.output), rms(&r.effort, &o.effort))
    };
    let chatter = apart(&log(&|q| q.beta_bs *= 1.01), &table);
    let bar = apart(&log(&|q| q.k_tb *= 3.0), &table);
    let wheel_log = log(&|q| q.beta_sw *= 3.0);
    let wheel = apart(&wheel_log, &table);
    let reflected = apart(
        &wheel_log,
        &log(&|q| q.beta_bs *= 1.0 + 2.0 * damping_share),
    );
    println!(
        "(column deg, current A) against the table: beta_bs x1.01 {chatter:.4?}, k_tb x3 \
         {bar:.4?}, beta_sw x3 {wheel:.4?}; beta_sw x3 against beta_bs x{:.3}: {reflected:.4?}",
        1.0 + 2.0 * damping_share
    );
    assert!(
        bar.0 < chatter.0 && bar.1 < chatter.1,
        "{bar:?} {chatter:?}"
    );
    assert!(wheel.0 > 3.0 * chatter.0, "{wheel:?} {chatter:?}");
    assert!(
        reflected.0 < 0.7 * wheel.0 && reflected.0 > 0.3 * wheel.0,
        "{reflected:?} {wheel:?}"
    );
}

/// A car of the independent world (seed 1, the index below): J_W at x0.46 of Table 4 (the rest
/// within 10 %), logged 2.6 ms late. A lighter wheel answers sooner, and the late stamps take that
/// lead back: on the log as drawn the table's car leaves less than the true car does, and with the
/// stamps on time the true car is at the noise and the table's far above it. The lag is the log's
/// and unknown (0-3 ms in the world); this is why a lighter wheel is named `parameters` in so few
/// of the selftest's cars (host-sim/README.md, "Where it fails").
#[test]
fn a_lighter_wheel_hides_behind_late_stamps() {
    use host_sim::gap::generator::draw;
    use host_sim::gap::rig::RigModel;
    let case = draw(1, 87, 12.0);
    let jw = case.truth.plant.j_w / host_sim::plant::PlantParams::PAPER.j_w;
    assert!(jw < 0.5 && case.skew_s > 2e-3, "{jw} {}", case.skew_s);
    let rig = Rig::paper();
    let mut car = rig.clone();
    if let RigModel::Paper(m) = &mut car.model {
        m.plant = case.truth.plant;
    }
    let costs = |case: &GenCase| {
        let rec = record_of(case, 1);
        let scorer =
            Scorer::new(&rig, &rec).with_noise(&rec, &simulate(&rig, &rec, &Effects::nominal()));
        let cost = |r: &Rig| -> f64 {
            let res = scorer.residual(&rec, &simulate(r, &rec, &Effects::nominal()));
            res.iter().map(|v| v * v).sum()
        };
        (cost(&rig), cost(&car), scorer.noise_floor_cost(&rec))
    };
    let (table_late, car_late, floor) = costs(&case);
    let mut on_time = case.clone();
    on_time.skew_s = 0.0;
    let (table_on_time, car_on_time, _) = costs(&on_time);
    println!(
        "stamped {:.2} ms late: table {table_late:.0}, true car {car_late:.0}; on time: table \
         {table_on_time:.0}, true car {car_on_time:.0}; noise floor {floor:.0}",
        1e3 * case.skew_s
    );
    assert!(table_late < car_late, "{table_late} {car_late}");
    assert!(car_on_time < floor, "{car_on_time} {floor}");
    assert!(table_on_time > 5.0 * floor, "{table_on_time} {floor}");
}

/// Case `index` of the independent world's `seed`, diagnosed as `gap selftest --seed SEED
/// --case INDEX` diagnoses it (the selftest's options, two threads).
fn diagnosed(seed: u64, index: usize) -> host_sim::gap::selftest::CaseResult {
    selftest_of(seed, index).cases.remove(0)
}

/// The selftest of the independent world's car `index` of `seed`, as `gap selftest --seed
/// --case` runs it.
fn selftest_of(seed: u64, index: usize) -> host_sim::gap::selftest::SelftestReport {
    use host_sim::gap::selftest;
    let mut opts = selftest::default_options();
    opts.threads = 2;
    selftest::run(
        selftest::World::Independent,
        &[index],
        seed,
        12.0,
        &opts,
        &|_| {},
    )
}

/// A car of the independent world (seed 3, the index below): a soft Dahl tyre (1056 N, 203
/// N/mm) under a 5 deg sweep logged at 100 Hz. The tyre's fit from its spec's start (600 N/mm)
/// ends at no force, where its stiffness moves nothing, and the log was called `unexplained`;
/// from a soft start too the tyre is found. Run as `gap selftest --seed 3 --case` runs it.
#[test]
fn a_soft_tyre_is_found_from_a_soft_start() {
    let case = diagnosed(3, 29);
    assert_eq!(case.case.hidden, ["tire_ground"]);
    assert_eq!(case.named, case.case.hidden, "{}", case.reason);
}

/// A car of the independent world (seed 3, the index below): 1.36 deg of play in the belt on
/// a 120 s track logged at 100 Hz. A stiff Dahl tyre left the least on the fit's window (the
/// column's stand at each reversal taken for a force) but the log's GoF below the nominal
/// model's, and the log was called `unexplained`; the torque balance shows the play, and the
/// play's own fit raises the GoF. Run as `gap selftest --seed 3 --case` runs it.
#[test]
fn play_that_a_stiff_tyre_hides_is_named_where_the_torque_balance_shows_it() {
    let case = diagnosed(3, 6);
    assert_eq!(case.case.hidden, ["backlash"]);
    assert_eq!(case.named, case.case.hidden, "{}", case.reason);
    assert!(
        case.gof_after > case.gof_before,
        "GoF {} -> {}",
        case.gof_before,
        case.gof_after
    );
}

/// A car of the independent world (seed 3, the index below): 1.27 deg of play in the belt
/// under a 10 deg sweep logged at 1 kHz. The verdict names the play with the size it was
/// fitted at, and the selftest sets it beside the torque balance's reading of the same play,
/// each against what the car hides: two methods, one a fit of the model and one read off the
/// log without it. Run as `gap selftest --seed 3 --case` runs it.
#[test]
fn a_named_play_carries_its_fitted_size_beside_the_balances() {
    let report = selftest_of(3, 1);
    let case = &report.cases[0];
    assert_eq!(case.named, ["backlash"], "{}", case.reason);
    let hidden = case.case.truth.as_ref().unwrap().truth.belt_play_deg;
    let (kind, fitted) = case
        .fitted
        .as_ref()
        .and_then(|f| f.play_deg())
        .expect("a named play has a fitted size");
    assert!(kind.starts_with("backlash"), "{kind}");
    // The fit's size and the balance's, each of the play's order (no hard-coded value: the
    // fit and the balance are two readings of what the car hides).
    assert!(
        (0.5..2.0).contains(&(fitted / hidden)),
        "{fitted} of {hidden}"
    );
    let balance = case.signature.as_ref().filter(|g| g.holds).unwrap();
    assert!(
        (balance.belt_play_deg / hidden - 1.0).abs() < 0.25,
        "{} of {hidden}",
        balance.belt_play_deg
    );
    let summary = report.balance_summary();
    assert!(
        summary.contains("the play's size where a car with play was named right (1 logs)"),
        "{summary}"
    );
}

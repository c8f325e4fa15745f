//! The `steer-can` binary end to end: every command with `--iface sim` (the simulated ECU in
//! virtual time), the candump fixtures, and the errors a team meets on the first day.
#![cfg(feature = "sim")]
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

/// The simulated ECU at CPU speed (`--fast`, a global option, so it may go last): the tests
/// would otherwise wait for the wall clock.
fn steer_can(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(args)
        .arg("--fast")
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

/// The number after `label` in `text` (e.g. "column" in "column  +5.10 deg").
fn number_after(text: &str, label: &str) -> f64 {
    let rest = &text[text.find(label).unwrap() + label.len()..];
    rest.split_whitespace()
        .next()
        .unwrap()
        .trim_end_matches(',')
        .parse()
        .unwrap()
}

/// The frames a second of the summary counted for `kind`, and their rate, Hz.
fn count_and_rate(summary: &str, kind: &str) -> (u64, f64) {
    let line = summary
        .lines()
        .rev()
        .find(|l| l.trim_start().starts_with(kind))
        .unwrap_or_else(|| panic!("no `{kind}` line in {summary}"));
    let mut words = line.trim_start()[kind.len()..].split_whitespace();
    let n = words.next().unwrap().parse().unwrap();
    let rate = words.next().unwrap().parse().unwrap();
    (n, rate)
}

/// The simulated car runs the default firmware (EPOS4 mode): besides the ECU's status and
/// motor frames at 100 Hz the bus carries the link's SYNC and RPDO, the drive's TPDOs and
/// its heartbeat, as on the car.
#[test]
fn monitor_decodes_the_simulated_bus() {
    let o = steer_can(&["--iface", "sim", "monitor", "--duration-s", "1", "--each"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    for kind in [
        "status 0x101",
        "motor 0x102",
        "SYNC",
        "EPOS4 RPDO1",
        "EPOS4 TPDO1",
    ] {
        let (n, rate) = count_and_rate(&out, kind);
        // One second: 99 or 100 frames; the rate is counted over the span of all frames.
        assert!(
            n >= 98 && (98.0..=101.0).contains(&rate),
            "{kind}: {n} at {rate} Hz: {out}"
        );
    }
    assert!(count_and_rate(&out, "EPOS4 heartbeat").0 >= 1, "{out}");
    assert!(
        out.contains("state idle  faults: none"),
        "each frame decoded: {out}"
    );
    assert!(out.contains("EPOS4      NMT operational"), "{out}");
    assert!(!out.contains("CRC errors 1"), "{out}");
}

/// A summary per refresh period and one at the end, never two for the same instant (a
/// monitor as long as its refresh period printed the same summary twice).
#[test]
fn monitor_prints_each_summary_once() {
    for (duration, periodic) in [("1", 0), ("2.5", 2), ("3", 2)] {
        let o = steer_can(&["--iface", "sim", "monitor", "--duration-s", duration]);
        assert!(o.status.success(), "{}", stderr(&o));
        let out = stdout(&o);
        let count = |head: &str| out.lines().filter(|l| l.starts_with(head)).count();
        assert_eq!(
            (count("--- sim ---"), count("=== sim ===")),
            (periodic, 1),
            "--duration-s {duration}: {out}"
        );
    }
}

/// `monitor --plot` redraws in place 10 times a second: three charts of the simulated car at
/// its power-up angle, the state below them, and the text summary at the end.
#[test]
fn monitor_plot_draws_the_charts_in_place() {
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["--iface", "sim", "--fast", "--sim-column-deg", "3"])
        .args(["monitor", "--plot", "--duration-s", "1"])
        .env("COLUMNS", "80")
        .env("LINES", "30")
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let frames: Vec<&str> = out.split("\x1b[H\x1b[J").skip(1).collect();
    assert_eq!(frames.len(), 9, "redrawn every 0.1 s before the end");
    // The last picture, without the text summary printed after it at the end.
    let last = frames[frames.len() - 1]
        .split("=== sim ===")
        .next()
        .unwrap();
    for part in [
        "angle at the wheel, deg",
        "motor angle, rad",
        "current, A",
        "state idle, faults: none",
    ] {
        assert!(last.contains(part), "{part} not in {last}");
    }
    // The column sits at its power-up angle: one row of marks, inside the scale's ends.
    let angle: Vec<&str> = last
        .split("motor angle")
        .next()
        .unwrap()
        .lines()
        .filter(|l| l.contains('|'))
        .collect();
    assert_eq!(
        angle.iter().filter(|l| l.contains('#')).count(),
        1,
        "{last}"
    );
    assert!(angle[0].trim_start().starts_with("+3.99|"), "{last}");
    assert!(last.lines().all(|l| l.chars().count() <= 80), "{last}");
    assert!(out.contains("=== sim ==="), "the summary at the end");
}

/// `rehearse` runs on the simulated car only: there `--iface` means `sim` unless given.
#[test]
fn rehearse_defaults_to_the_simulated_car() {
    let dir = tempfile::tempdir().unwrap();
    let o = steer_can(&[
        "--iface",
        "can0",
        "rehearse",
        "--dir",
        dir.path().to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("simulated car only"), "{}", stderr(&o));
    let o = steer_can(&["rehearse", "--dir", dir.path().to_str().unwrap()]);
    assert!(o.status.success(), "{}\n{}", stdout(&o), stderr(&o));
    assert!(stdout(&o).contains("rehearsal of the README's first day on the simulated car"));
}

/// `convert --help` lists what applies to a file: not the interface nor the simulated car's
/// options; a command on the bus still lists them.
#[test]
fn convert_help_lists_only_the_options_that_apply() {
    let help = |args: &[&str]| {
        let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let convert = help(&["convert", "--help"]);
    for absent in [
        "--iface",
        "--fast",
        "--sim-column-deg",
        "--controller",
        "--drive",
    ] {
        assert!(!convert.contains(absent), "{absent} in: {convert}");
    }
    assert!(
        convert.contains("--node") && convert.contains("--all-rows"),
        "{convert}"
    );
    let monitor = help(&["monitor", "--help"]);
    for present in [
        "--iface",
        "--fast",
        "--sim-column-deg",
        "--controller",
        "--drive",
    ] {
        assert!(monitor.contains(present), "{present} not in: {monitor}");
    }
}

#[test]
fn epos_check_compares_the_gains_with_ours() {
    let o = steer_can(&["--iface", "sim", "epos", "check"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("mode             8 (cyclic synchronous position"),
        "the ECU's link put the drive in CSP: {out}"
    );
    let gains_ok = out
        .lines()
        .filter(|l| l.contains("0x30A") && l.ends_with("  ok"))
        .count();
    assert_eq!(gains_ok, 7, "the seven gains as ours: {out}");
    assert!(!out.contains("DIFFERS"), "{out}");
    assert!(out.contains("error register   0x00 (no error)"));
    assert!(out.contains("error history    empty"));
    assert!(out.contains("verdict          ok"), "{out}");
}

/// The direct-drive car (`--drive direct`) leaves the EPOS4 on the bus unconfigured: the check
/// says so rather than passing.
#[test]
fn epos_check_on_the_direct_drive_car_finds_the_drive_unconfigured() {
    let o = steer_can(&["--iface", "sim", "--drive", "direct", "epos", "check"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("mode             1 (profile position)"),
        "{out}"
    );
    assert!(
        out.contains("0x30A1/1     4390000     1500000  DIFFERS"),
        "{out}"
    );
}

#[test]
fn send_step_moves_the_wheel_and_ends_with_the_drive_disabled() {
    let o = steer_can(&[
        "--iface",
        "sim",
        "send",
        "--as-state",
        "driving",
        "step",
        "--amplitude-deg",
        "5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let column = number_after(&out, "ECU        column");
    assert!((column - 5.0).abs() < 0.5, "column {column} deg: {out}");
    assert!(out.contains("state idle, faults: none"), "{out}");
    assert!(stderr(&o).contains("AS Finished sent"));
}

#[test]
fn send_without_finish_leaves_the_ecu_to_time_out() {
    let o = steer_can(&[
        "--iface",
        "sim",
        "send",
        "--as-state",
        "driving",
        "--no-finish",
        "step",
        "--amplitude-deg",
        "0",
        "--duration-s",
        "0.5",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(
        out.contains("state faulted, faults: reference timeout"),
        "{out}"
    );
    assert!(out.contains("reference 0x100"), "own frames counted: {out}");
}

/// The README's order (`send step --as-state driving`, options after the profile and the
/// global ones last) works as well as the order above; piped stderr has no progress redraws.
#[test]
fn options_after_the_subcommand_work_and_piped_progress_stays_quiet() {
    let o = steer_can(&[
        "send",
        "step",
        "--as-state",
        "driving",
        "--amplitude-deg",
        "2",
        "--iface",
        "sim",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    let column = number_after(&out, "ECU        column");
    assert!((column - 2.0).abs() < 0.5, "column {column} deg: {out}");
    let err = stderr(&o);
    assert!(!err.contains('\r'), "progress redraws in a pipe: {err:?}");
    assert!(
        err.lines().all(|l| !l.trim().is_empty()),
        "blank lines: {err:?}"
    );
}

/// Without `--fast` the simulated ECU keeps to the wall clock: half a second of monitoring
/// takes half a second, and shows the same 100 Hz traffic.
#[test]
fn the_simulation_follows_the_wall_clock_unless_fast() {
    let started = std::time::Instant::now();
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["--iface", "sim", "monitor", "--duration-s", "0.5"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let wall = started.elapsed().as_secs_f64();
    assert!(o.status.success(), "{}", stderr(&o));
    // Virtual time may lead the wall clock by one 10 ms status period (WallPaced::LEAD_US).
    assert!(wall >= 0.49, "0.5 s of the simulated bus took {wall:.3} s");
    let (n, _) = count_and_rate(&stdout(&o), "status 0x101");
    assert!((48..=50).contains(&n), "{n} status frames: {}", stdout(&o));
}

#[test]
fn send_needs_the_as_state_said() {
    let o = steer_can(&["--iface", "sim", "send", "sine"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--as-state"), "{}", stderr(&o));
}

#[test]
fn campaign_sweep_writes_a_log_that_convert_reproduces_from_the_recording() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("sweep.csv");
    let o = steer_can(&[
        "--iface",
        "sim",
        "campaign",
        "sweep",
        "--f-end-hz",
        "5",
        "--duration-s",
        "5",
        "--yes",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("completed: 501 profile samples sent"), "{out}");
    // Piped, as here, there is no progress bar: it redraws a line, so it is drawn only on a
    // terminal.
    assert!(!stderr(&o).contains('\r'), "progress bar in a pipe");
    let recording = dir.path().join("sweep.csv.candump");
    assert!(recording.exists());
    let converted = dir.path().join("converted.csv");
    let o = steer_can(&[
        "convert",
        recording.to_str().unwrap(),
        "--out",
        converted.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&log).unwrap(),
        std::fs::read_to_string(&converted).unwrap(),
        "the recording holds everything the log was built from"
    );
}

/// README step 6 on a fresh simulated car (the default EPOS4 build, paper mode): the paper's
/// whole 0-10 Hz, 10 deg sweep runs to its end. Near 10 Hz the saturated loop flips its
/// current with the error every 50 ms while the column, behind the belt, still moves away:
/// the runaway check took that for a drive pushing the wrong way and aborted at 9.7 Hz.
#[test]
fn the_papers_whole_sweep_runs_to_the_end_on_a_fresh_car() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("sweep.csv");
    let o = steer_can(&[
        "--iface",
        "sim",
        "campaign",
        "sweep",
        "--yes",
        "--out",
        log.to_str().unwrap(),
    ]);
    let out = stdout(&o);
    assert!(o.status.success(), "{out}\n{}", stderr(&o));
    assert!(
        out.contains("completed: 1001 profile samples sent"),
        "{out}"
    );
    assert!(out.contains("faults: none"), "{out}");
}

#[test]
fn campaign_with_a_fault_mid_run_aborts_and_still_writes_the_log() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("track.csv");
    let o = steer_can(&[
        "--iface",
        "sim",
        "--sim-inject",
        "encoder@2.0",
        "campaign",
        "track",
        "--yes",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert_eq!(o.status.code(), Some(3), "{}", stderr(&o));
    let out = stdout(&o);
    assert!(out.contains("ABORTED: fault at"), "{out}");
    assert!(out.contains("column encoder"), "{out}");
    assert!(out.contains("ECU faulted"), "{out}");
    let written = host_io::logfmt::Log::load(&log).unwrap();
    assert!(
        written.len() > 100 && written.len() < 300,
        "{} rows",
        written.len()
    );
}

#[test]
fn campaign_without_confirmation_sends_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("x.csv");
    let o = steer_can(&[
        "--iface",
        "sim",
        "campaign",
        "sweep",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("not confirmed"), "{}", stderr(&o));
    assert!(!log.exists());
}

/// `steer-can record` on the simulated car into `file` for `duration_s`, which must succeed.
fn record_on_sim(file: &Path, duration_s: &str) -> Output {
    let out = file.to_str().unwrap();
    let o = steer_can(&[
        "--iface",
        "sim",
        "record",
        "--out",
        out,
        "--duration-s",
        duration_s,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    o
}

/// `record` on the simulated car records what the vehicle side sends too (a simulated vehicle
/// computer steers while it listens), so the README's `record` then `convert` gives a log.
#[test]
fn record_on_sim_holds_the_vehicle_frames_and_converts_to_a_log() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bus.candump");
    record_on_sim(&file, "3");
    let text = std::fs::read_to_string(&file).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert!(lines[0].starts_with("(1700000000.000"), "{}", lines[0]);
    let count = |id: &str| lines.iter().filter(|l| l.contains(id)).count();
    // 0.3 s Ready + 2.01 s of sine + 0.2 s Finished + 0.2 s Off, one frame per 10 ms.
    assert_eq!(count(" can0 100#"), 30 + 201 + 20 + 20, "{text:.400}");
    assert!(count(" can0 101#") >= 299, "status frames");
    // SYNC from the end of the link's configuration, every 10 ms.
    assert!(count(" can0 080#") >= 290, "SYNC frames");

    let log = dir.path().join("log.csv");
    let o = steer_can(&[
        "convert",
        file.to_str().unwrap(),
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let written = host_io::logfmt::Log::load(&log).unwrap();
    // The rows in AS Ready and Driving.
    assert_eq!(written.len(), 30 + 201, "{}", stdout(&o));
    let peak = written.sw_deg.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    assert!(
        (4.0..6.0).contains(&peak),
        "the wheel followed the 5 deg sine: {peak} deg"
    );
}

#[test]
fn candump_fixture_converts_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("ramp.csv");
    let o = steer_can(&[
        "convert",
        fixture("bringup_ramp.candump").to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(fixture("bringup_ramp.csv")).unwrap()
    );
    let said = stdout(&o);
    assert!(said.contains("1 skipped"), "{said}");
    assert!(said.contains("1 invalid frames"), "{said}");
}

/// The fixture reads as the current firmware: each motor frame (0x102) carries, in
/// `MOT_RefCounter`, the counter of the last reference frame (0x100) before it that passed the
/// CRC, 0 before the first; the firmware before that field wrote 0 throughout.
#[test]
fn candump_fixtures_motor_frames_carry_the_last_reference_counter() {
    use steer_can::decode::{Decoded, Decoder};
    use steering_ecu::canopen::NodeId;
    use steering_ecu::canopen::epos4::PositionScale;
    let dec = Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(84).unwrap());
    let file = steer_can::candump::read(&fixture("bringup_ramp.candump")).unwrap();
    let (mut last, mut motors) = (0, 0);
    for f in &file.frames {
        match dec.decode(&f.frame) {
            Decoded::Reference(Ok(r)) => last = r.counter.raw(),
            Decoded::Motor(Ok(m)) => {
                assert_eq!(
                    m.reference_counter.raw(),
                    last,
                    "motor frame at {} us",
                    f.t_us
                );
                motors += 1;
            }
            _ => {}
        }
    }
    assert!(motors >= 10, "{motors} motor frames");
    assert_ne!(last, 0, "the references count up from 1");
}

#[test]
fn malformed_candump_is_refused_with_the_line_number() {
    let dir = tempfile::tempdir().unwrap();
    let o = steer_can(&[
        "convert",
        fixture("bringup_malformed.candump").to_str().unwrap(),
        "--out",
        dir.path().join("x.csv").to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    assert!(
        err.contains("bringup_malformed.candump:3: ID `10X` is not hexadecimal"),
        "{err}"
    );
    let o = steer_can(&["convert", "no-such.candump", "--out", "x.csv"]);
    assert!(stderr(&o).contains("cannot open candump file no-such.candump"));
}

/// `--controller ecu` on the simulated car runs the ECU's own controller through the
/// firmware's tasks: the same track campaign (a 2 Hz, 10 deg sine for 3 s) is followed more
/// closely than in paper mode (RMS error of the logged column against the logged reference).
#[test]
fn the_simulated_car_runs_either_controller() {
    let dir = tempfile::tempdir().unwrap();
    let profile = dir.path().join("sine.csv");
    let mut text = String::from("t,ref_sw_deg\n");
    for k in 0..=300 {
        let t = f64::from(k) * 0.01;
        text += &format!("{t},{}\n", 10.0 * (std::f64::consts::TAU * 2.0 * t).sin());
    }
    std::fs::write(&profile, text).unwrap();
    let rms_error = |controller: &str| -> f64 {
        let log = dir.path().join(format!("track-{controller}.csv"));
        let o = steer_can(&[
            "--iface",
            "sim",
            "--controller",
            controller,
            "campaign",
            "track",
            "--csv",
            profile.to_str().unwrap(),
            "--yes",
            "--out",
            log.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{controller}: {}", stderr(&o));
        let log = host_io::logfmt::Log::load(&log).unwrap();
        let (sum, n) = log
            .ref_sw_deg
            .iter()
            .zip(&log.sw_deg)
            .fold((0.0, 0usize), |(s, n), (r, y)| (s + (r - y).powi(2), n + 1));
        assert!(n > 250, "{controller}: {n} rows");
        (sum / n as f64).sqrt()
    };
    let (paper, ecu) = (rms_error("paper"), rms_error("ecu"));
    println!("2 Hz sine on the simulated car: RMS error paper {paper:.2} deg, ECU {ecu:.2} deg");
    assert!(ecu < 0.6 * paper, "paper {paper} deg, ECU {ecu} deg");
}

/// The ready check's advice for a latched fault is a command the tool accepts (it named a
/// `--clear-faults` option that does not exist).
#[test]
fn the_ready_checks_advice_is_a_command_that_runs() {
    let dir = tempfile::tempdir().unwrap();
    let log = dir.path().join("x.csv");
    // The column encoder silent from power-up: the fault is latched before the ready check.
    let o = steer_can(&[
        "--iface",
        "sim",
        "--sim-inject",
        "encoder@0",
        "campaign",
        "sweep",
        "--yes",
        "--out",
        log.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = stderr(&o);
    let advice = err
        .split('`')
        .nth(1)
        .unwrap_or_else(|| panic!("no command in {err}"));
    assert!(advice.starts_with("steer-can "), "{err}");
    let words: Vec<&str> = advice.split_whitespace().skip(1).collect();
    let mut args = vec!["--iface", "sim"];
    args.extend(&words);
    let o = steer_can(&args);
    assert!(o.status.success(), "`{advice}` is refused: {}", stderr(&o));
}

/// A current-sense fault needs the ECU's own current sensing: on the EPOS4-mode car it is
/// refused with the option that has it, not silently ignored; on the direct-drive car it
/// trips the over-current check.
#[test]
fn a_current_sense_fault_is_for_the_direct_drive_car() {
    let o = steer_can(&[
        "--iface",
        "sim",
        "--sim-inject",
        "overcurrent@0.2",
        "monitor",
        "--duration-s",
        "0.5",
    ]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("--drive direct"), "{}", stderr(&o));
    let o = steer_can(&[
        "--iface",
        "sim",
        "--drive",
        "direct",
        "--sim-inject",
        "overcurrent@0.2",
        "send",
        "--as-state",
        "driving",
        "step",
    ]);
    assert!(stdout(&o).contains("over-current"), "{}", stdout(&o));
}

/// A bad `--plant-effects` value on the simulated car: the list quoted once, the reason naming
/// the key and the value apart, with what the key takes (host-sim's parser, shared).
#[test]
fn a_bad_plant_effect_is_named_once_with_what_it_takes() {
    for (list, item, reason) in [
        (
            "coulomb_n=200,backlash_deg=nan",
            "backlash_deg=nan",
            "backlash_deg takes a finite number >= 0",
        ),
        (
            "reference_delay_ms=300",
            "reference_delay_ms=300",
            "reference_delay_ms takes a number of ms within 0..=200, not `300`",
        ),
    ] {
        let o = steer_can(&[
            "--iface",
            "sim",
            "--plant-effects",
            list,
            "monitor",
            "--duration-s",
            "0.1",
        ]);
        assert!(!o.status.success());
        let err = stderr(&o);
        assert_eq!(err.matches(item).count(), 1, "{err}");
        assert!(err.contains(reason), "{err}");
    }
}

/// `record --out` and `campaign --out` create a missing directory, as `convert --out` does, and
/// say where the file went.
#[test]
fn record_and_campaign_create_a_missing_output_directory() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("day1/bus/bus.candump");
    let o = record_on_sim(&file, "0.5");
    assert!(std::fs::metadata(&file).unwrap().len() > 0);
    let said = stdout(&o);
    assert!(
        said.contains(&format!(
            "created directory {}",
            dir.path().join("day1/bus").display()
        )),
        "{said}"
    );
    assert!(
        said.contains(&format!("frames written to {}", file.display())),
        "{said}"
    );

    let profile = dir.path().join("hold.csv");
    let rows: String = (0..=120)
        .map(|k| format!("{},0\n", f64::from(k) * 0.01))
        .collect();
    std::fs::write(&profile, format!("t,ref_sw_deg\n{rows}")).unwrap();
    let log = dir.path().join("day2/track.csv.gz");
    let (csv, out) = (profile.to_str().unwrap(), log.to_str().unwrap());
    let o = steer_can(&[
        "--iface", "sim", "campaign", "track", "--csv", csv, "--yes", "--out", out,
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(log.exists());
    let recording = dir.path().join("day2/track.csv.gz.candump");
    assert!(recording.exists());
    assert!(
        stdout(&o).contains(&format!("recording written to {}", recording.display())),
        "{}",
        stdout(&o)
    );
}

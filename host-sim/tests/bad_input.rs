//! The bad-input table (host-sim/README.md, "The log format"), row by row, through the real
//! binaries: every input has a defined
//! outcome (handled with a warning, or refused with file, line and reason), never a panic and
//! never a plausible-looking answer computed from garbage. Row 4 (`steer-can convert`) is in
//! steer-can's own `tests/bad_input.rs`.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/refusal.rs"]
mod refusal;

use refusal::{assert_refused, gzip, s, stderr, stdout, write_lines};
use std::path::Path;
use std::process::{Command, Output, Stdio};

fn host_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

/// The lines of a log that host-sim itself wrote: a 1.5 s step at 1 kHz, without the comment
/// lines that name the car, so the header is on line 1 (the tests count file lines).
fn step_log(dir: &Path) -> Vec<String> {
    let path = dir.join("step.csv");
    let o = host_sim(&["step", "--log", s(&path)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(
        text.starts_with("# drive: direct\n"),
        "host-sim names the car it simulated"
    );
    text.lines()
        .filter(|l| !l.starts_with('#'))
        .map(str::to_string)
        .collect()
}

/// `lines` written as `name` in `dir`, and `host-sim gap` run on that file on two threads.
fn gap_of(dir: &Path, name: &str, lines: &[String]) -> Output {
    let log = dir.join(name);
    write_lines(&log, lines);
    host_sim(&["gap", s(&log), "--threads", "2"])
}

/// Sets field `column` of file line `line` (1-based, as an editor shows it).
fn set_field(lines: &mut [String], line: usize, column: usize, value: &str) {
    let mut fields: Vec<String> = lines[line - 1].split(',').map(str::to_string).collect();
    fields[column] = value.to_string();
    lines[line - 1] = fields.join(",");
}

/// Row 1: `nan` cells (the format's missing-sample marker) on six rows, to `gap`.
#[test]
fn gap_fills_nan_cells_says_so_and_prints_finite_figures() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in [40, 41, 42] {
        set_field(&mut lines, line, 2, "nan"); // sw_deg
    }
    for line in [300, 650, 651] {
        set_field(&mut lines, line, 4, "NaN"); // current_a
    }
    let log = dir.path().join("holes.csv");
    write_lines(&log, &lines);
    let json = dir.path().join("gap.json");
    let o = host_sim(&["gap", s(&log), "--threads", "2", "--json", s(&json)]);
    let (out, err) = (stdout(&o), stderr(&o));
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("holes.csv: column `sw_deg`: 3 missing samples (nan)"),
        "{err}"
    );
    assert!(
        err.contains("holes.csv: column `current_a`: 3 missing samples (nan)"),
        "{err}"
    );
    // The filled log reads as the clean one does: no NaN or inf that the clean log's report
    // does not have too (a regime with no time in it has no GoF either way), and a noise floor
    // of the clean log's order, not the 8.5e23 of a NaN that got through.
    let clean_log = dir.path().join("step.csv");
    let clean_json = dir.path().join("clean.json");
    let clean = host_sim(&[
        "gap",
        s(&clean_log),
        "--threads",
        "2",
        "--json",
        s(&clean_json),
    ]);
    assert!(clean.status.success(), "{}", stderr(&clean));
    let clean_out = stdout(&clean);
    for garbage in ["NaN", "inf"] {
        assert_eq!(
            out.matches(garbage).count(),
            clean_out.matches(garbage).count(),
            "`{garbage}` in the report:\n{out}\nclean:\n{clean_out}"
        );
    }
    // Each signal's noise (what the likelihood divides by and the floor is made of) is of the
    // clean log's order, not the 8.5e23 of a NaN that got through.
    let noise = |path: &Path, signal: &str| -> f64 {
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        v["noise"][signal].as_f64().unwrap()
    };
    for signal in ["output", "effort"] {
        let (filled, original) = (noise(&json, signal), noise(&clean_json, signal));
        assert!(
            filled.is_finite() && (filled - original).abs() <= 0.1 * original,
            "{signal} noise {filled} against {original} on the clean log"
        );
    }
    // Piped, the progress bar stays off: stderr is one line per event.
    assert!(!err.contains('\r'), "{err:?}");
    // serde_json writes a non-finite figure as null.
    let text = std::fs::read_to_string(&json).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v["baseline"]["gof"].is_f64(), "{}", v["baseline"]);
}

/// Row 1 again, for `identify`.
#[test]
fn identify_fills_nan_cells_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in [100, 500, 900, 901, 902, 1200] {
        set_field(&mut lines, line, 3, "nan"); // motor_rad
    }
    let log = dir.path().join("holes.csv");
    write_lines(&log, &lines);
    let o = host_sim(&["identify", s(&log), "--iterations", "1"]);
    let (out, err) = (stdout(&o), stderr(&o));
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("column `motor_rad`: 6 missing samples (nan)"),
        "{err}"
    );
    assert!(!out.contains("NaN"), "{out}");
}

/// A column with no sample at all cannot be filled: refused, not diagnosed.
#[test]
fn gap_refuses_a_required_column_that_is_all_nan() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in 2..=lines.len() {
        set_field(&mut lines, line, 4, "nan");
    }
    let o = gap_of(dir.path(), "no_current.csv", &lines);
    assert_refused(&o, &["no_current.csv", "current_a", "only nan"]);
}

/// A required column that holds one value in every row (a stuck current sensor) carries no
/// signal: refused with the column and its value, not diagnosed (the old reader called such a
/// log `parameters` at a GoF of -1e15 %, the effort's variance being zero).
#[test]
fn gap_refuses_a_required_column_that_never_changes() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in 2..=lines.len() {
        set_field(&mut lines, line, 4, "0.2");
    }
    let o = gap_of(dir.path(), "stuck_current.csv", &lines);
    assert_refused(&o, &["stuck_current.csv", "current_a", "0.2 in every row"]);
}

/// A motor angle that never changes while the column moves (a Hall sensor that died) is left
/// out, with a note, as a column of nan is: the log is diagnosed on what it still has.
#[test]
fn gap_leaves_out_a_motor_angle_that_never_changes_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in 2..=lines.len() {
        set_field(&mut lines, line, 3, "0.1");
    }
    let o = gap_of(dir.path(), "stuck_motor.csv", &lines);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("column `motor_rad` holds 0.1 in every row; left out"),
        "{err}"
    );
}

/// A logger on a wall clock stamps its rows in Unix seconds (1.7e9 s, as candump and a ROS
/// export do): the log is read from its first whole second, says so, and is diagnosed as the
/// same rows stamped from 0 are.
#[test]
fn gap_reads_stamps_of_a_wall_clock_from_their_first_whole_second() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());
    let mut wall = lines.clone();
    for line in 2..=wall.len() {
        let t: f64 = wall[line - 1].split(',').next().unwrap().parse().unwrap();
        set_field(&mut wall, line, 0, &format!("{:.6}", t + 1_733_300_000.0));
    }
    let gof = |lines: &[String], name: &str| -> (f64, String, String) {
        let (log, json) = (
            dir.path().join(name),
            dir.path().join(format!("{name}.json")),
        );
        write_lines(&log, lines);
        let o = host_sim(&["gap", s(&log), "--threads", "2", "--json", s(&json)]);
        assert!(o.status.success(), "{name}: {}", stderr(&o));
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(&json).unwrap()).unwrap();
        let gof = v["baseline"]["gof"].as_f64().unwrap();
        (gof, v["verdict"]["kind"].to_string(), stderr(&o))
    };
    let (gof_from_0, kind_from_0, _) = gof(&lines, "from0.csv");
    let (gof_wall, kind_wall, err) = gof(&wall, "wall.csv");
    assert!(
        err.contains("stamps start at 1733300000.0"),
        "the shift is said: {err}"
    );
    assert_eq!(kind_wall, kind_from_0);
    assert!(
        (gof_wall - gof_from_0).abs() < 1e-6,
        "GoF {gof_wall} on the wall clock's stamps, {gof_from_0} from 0"
    );
}

/// Stamps in milliseconds written under `t` (seconds) put 100 Hz rows 10 s apart: a 20 s log
/// read as 5.5 hours of a reference interpolated across 10 s. Refused, with the spacing and
/// the question of the unit, not diagnosed (the old reader ran it for minutes).
#[test]
fn gap_refuses_rows_too_far_apart_for_the_grid_and_asks_for_seconds() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in 2..=lines.len() {
        let t: f64 = lines[line - 1].split(',').next().unwrap().parse().unwrap();
        set_field(&mut lines, line, 0, &format!("{:.3}", 1e3 * t));
    }
    let o = gap_of(dir.path(), "ms.csv", &lines);
    assert_refused(&o, &["ms.csv", "apart", "`t` in seconds"]);
}

/// A 50 Hz logger: rows 20 ms apart, every other 10 ms reference sample never logged.
/// Refused with the spacing and the period, not diagnosed against a guess of the samples
/// between rows (the old reader gave a car with play a nominal GoF of 13 % and
/// `parameters`).
#[test]
fn gap_refuses_rows_further_apart_than_the_reference_period() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());
    let sparse: Vec<String> = lines
        .iter()
        .enumerate()
        .filter(|(i, _)| *i == 0 || i % 20 == 0)
        .map(|(_, l)| l.clone())
        .collect();
    let o = gap_of(dir.path(), "fifty.csv", &sparse);
    assert_refused(
        &o,
        &[
            "fifty.csv",
            "rows 20.00 ms apart",
            "the reference's 10 ms period",
            "100 Hz",
        ],
    );
}

/// A logger that stalled (0.2 s without a row) or a sensor that dropped out (0.15 s of `nan`
/// current) leaves a stretch the reader can only fill with a line between its ends: refused,
/// with where, not scored against the line (2 s of a 100 Hz track missing turned an
/// effect-free car `unexplained`). A dropout of 50 ms is bridged.
#[test]
fn gap_refuses_a_hole_longer_than_it_bridges_and_says_where() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());
    assert!(lines[500].starts_with("0.500000,"), "{}", lines[500]);

    let mut stalled = lines.clone();
    stalled.drain(500..700);
    let o = gap_of(dir.path(), "stalled.csv", &stalled);
    assert_refused(
        &o,
        &[
            "stalled.csv",
            "nothing from t = 0.500 s to 0.700 s",
            "200 ms",
        ],
    );

    let mut dropout = lines.clone();
    for line in 801..951 {
        set_field(&mut dropout, line, 4, "nan");
    }
    let o = gap_of(dir.path(), "dropout.csv", &dropout);
    assert_refused(&o, &["dropout.csv", "nothing from t = 0.800 s to 0.950 s"]);

    let mut short = lines;
    for line in 801..851 {
        set_field(&mut short, line, 4, "nan");
    }
    let o = gap_of(dir.path(), "short.csv", &short);
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Row 1, as a spreadsheet or pandas writes a missing value: an empty cell is a `nan` cell,
/// filled and counted as one; an empty time is refused with its line.
#[test]
fn gap_reads_empty_cells_as_missing_samples_and_refuses_an_empty_time() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    for line in [40, 41, 300] {
        set_field(&mut lines, line, 2, ""); // sw_deg
    }
    let o = gap_of(dir.path(), "empty.csv", &lines);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("empty.csv: column `sw_deg`: 3 missing samples (nan)"),
        "{}",
        stderr(&o)
    );
    set_field(&mut lines, 500, 0, "");
    let o = gap_of(dir.path(), "no-time.csv", &lines);
    assert_refused(
        &o,
        &[
            "no-time.csv",
            "line 500",
            "time `t` must be a finite number",
        ],
    );
}

/// Row 2: duplicated time, time going back, and t = 1e300.
#[test]
fn gap_refuses_time_that_does_not_increase_with_file_line_and_reason() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());

    let mut dup = lines.clone();
    let t_before = dup[99].split(',').next().unwrap().to_string();
    set_field(&mut dup, 101, 0, &t_before);
    let o = gap_of(dir.path(), "dup.csv", &dup);
    assert_refused(&o, &["dup.csv", "line 101", "strictly increase"]);

    let mut back = lines.clone();
    set_field(&mut back, 700, 0, "0.1");
    let o = gap_of(dir.path(), "back.csv", &back);
    assert_refused(&o, &["back.csv", "line 700", "strictly increase"]);

    let mut far = lines;
    set_field(&mut far, 800, 0, "1e300");
    let o = gap_of(dir.path(), "far.csv", &far);
    assert_refused(&o, &["far.csv", "line 800", "column `t`", "physical bound"]);
}

/// Row 3: a value of 1e300, to `gap` (in any column the paper rig reads) and to `track --csv`.
#[test]
fn values_beyond_physical_bounds_are_refused_with_their_line() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());
    for (column, name) in [
        (1, "ref_sw_deg"),
        (2, "sw_deg"),
        (3, "motor_rad"),
        (4, "current_a"),
    ] {
        let mut bad = lines.clone();
        set_field(&mut bad, 321, column, "1e300");
        let log = dir.path().join(format!("big_{name}.csv"));
        write_lines(&log, &bad);
        let o = host_sim(&["gap", s(&log), "--threads", "2"]);
        let col = format!("column `{name}`");
        assert_refused(&o, &[s(&log), "line 321", &col, "physical bound"]);
    }
    // A current in milliamperes, as an EPOS4 reports it: the refusal asks.
    let mut milli = lines.clone();
    set_field(&mut milli, 321, 4, "15200");
    let log = dir.path().join("milliamperes.csv");
    write_lines(&log, &milli);
    let o = host_sim(&["gap", s(&log), "--threads", "2"]);
    assert_refused(&o, &["line 321", "column `current_a`", "milliamperes"]);

    let track = dir.path().join("track.csv");
    std::fs::write(&track, "t,ref_sw_deg\n0,0\n1,1e300\n2,0\n").unwrap();
    let o = host_sim(&["track", "--csv", s(&track)]);
    assert_refused(
        &o,
        &[
            "track.csv",
            "line 3",
            "column `ref_sw_deg`",
            "physical bound",
        ],
    );
}

/// Row 3 for `track --csv` with a full project log as the reference: the reference column
/// is checked; a column the track does not read is skipped unread, garbage and all (a team's
/// own log carries columns of its own).
#[test]
fn track_checks_a_project_logs_reference_and_skips_its_other_columns() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = step_log(dir.path());
    set_field(&mut lines, 10, 4, "-1e300");
    let log = dir.path().join("as_reference.csv");
    write_lines(&log, &lines);
    let o = host_sim(&["track", "--csv", s(&log)]);
    assert!(o.status.success(), "{}", stderr(&o));
    set_field(&mut lines, 10, 1, "-1e300");
    write_lines(&log, &lines);
    let o = host_sim(&["track", "--csv", s(&log)]);
    assert_refused(&o, &["as_reference.csv", "line 10", "column `ref_sw_deg`"]);
}

/// A 3 s track reference with enough samples that its gzip is several blocks long.
fn track_text() -> String {
    let mut text = String::from("t,ref_sw_deg\n");
    for i in 0..=3000 {
        let t = i as f64 * 1e-3;
        text += &format!("{t:.3},{:.6}\n", 5.0 * (2.0 * t).sin());
    }
    text
}

/// Row 5: `track --csv file.csv.gz` is read as gzip; a truncated one is said to be truncated.
#[test]
fn track_reads_gzip_and_names_a_truncated_one() {
    let dir = tempfile::tempdir().unwrap();
    let plain = dir.path().join("ref.csv");
    let packed = dir.path().join("ref.csv.gz");
    let text = track_text();
    std::fs::write(&plain, &text).unwrap();
    let gz = gzip(text.as_bytes());
    std::fs::write(&packed, &gz).unwrap();
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let o = host_sim(&["track", "--csv", s(&plain), "--json", s(&a)]);
    assert!(o.status.success(), "{}", stderr(&o));
    let o = host_sim(&["track", "--csv", s(&packed), "--json", s(&b)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&a).unwrap(),
        std::fs::read_to_string(&b).unwrap(),
        "the same reference, plain or gzip, gives the same run"
    );

    let cut = dir.path().join("cut.csv.gz");
    std::fs::write(&cut, &gz[..gz.len() * 2 / 3]).unwrap();
    let o = host_sim(&["track", "--csv", s(&cut)]);
    assert_refused(&o, &["cut.csv.gz", "truncated gzip"]);
    assert!(!stderr(&o).contains("UTF-8"), "{}", stderr(&o));
}

/// Row 5 for `gap` too, which reads through the same reader.
#[test]
fn gap_names_a_truncated_gzip_log() {
    let dir = tempfile::tempdir().unwrap();
    let lines = step_log(dir.path());
    let gz = gzip((lines.join("\n") + "\n").as_bytes());
    let cut = dir.path().join("cut.csv.gz");
    std::fs::write(&cut, &gz[..gz.len() / 2]).unwrap();
    let o = host_sim(&["gap", s(&cut), "--threads", "2"]);
    assert_refused(&o, &["cut.csv.gz", "truncated gzip"]);
}

/// Row 1's last clause: a worker thread that fails fails the run. A record with a NaN in it
/// (what the reader now fills, forced here past the reader) must not come back as a diagnosis
/// with the failed candidates silently left out.
#[test]
fn a_failed_worker_fails_the_diagnosis() {
    use host_sim::gap::rig::Rig;
    use host_sim::gap::{Options, diagnose};
    let dir = tempfile::tempdir().unwrap();
    step_log(dir.path());
    let rig = Rig::paper();
    let mut record = rig.load_record(&dir.path().join("step.csv")).unwrap();
    for v in &mut record.output[40..46] {
        *v = f64::NAN;
    }
    let opts = Options {
        threads: 2,
        ..Options::default()
    };
    let outcome = std::panic::catch_unwind(|| diagnose(&rig, &record, None, &opts));
    match outcome {
        Err(_) => {}
        Ok(d) => {
            // If no worker fails on it, every candidate must still be in the ranking.
            assert_eq!(d.ranking.len(), opts.effects.len(), "{}", d.summary());
        }
    }
}

/// A file that is not a log, with no line end for megabytes (a binary file, `truncate -s 2G`),
/// is refused at the line that is too long, without reading it whole.
#[test]
fn gap_refuses_an_overlong_line_without_reading_it_whole() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("zeros.csv");
    let mut bytes = b"t,ref_sw_deg,sw_deg,motor_rad,current_a\n".to_vec();
    bytes.resize(bytes.len() + 8 * 1024 * 1024, 0);
    std::fs::write(&path, &bytes).unwrap();
    let o = host_sim(&["gap", s(&path), "--threads", "2"]);
    assert_refused(&o, &["zeros.csv", "line 2 is longer than 64 KiB"]);
}

/// Two rows are a straight line, not a track: `track --csv` refuses them instead of printing
/// the tracking error of a run that never steered.
#[test]
fn track_refuses_a_reference_too_short_to_be_a_track() {
    let dir = tempfile::tempdir().unwrap();
    for (name, text) in [
        ("two_rows.csv", "t,ref_sw_deg\n0,0\n0.01,1\n"),
        ("two_far_rows.csv", "t,ref_sw_deg\n0,0\n5,10\n"),
        (
            "short.csv",
            "t,ref_sw_deg\n0,0\n0.1,1\n0.2,2\n0.3,1\n0.4,0\n0.5,1\n0.6,0\n0.7,1\n0.8,0\n0.9,1\n",
        ),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, text).unwrap();
        let o = host_sim(&["track", "--csv", s(&path)]);
        assert_refused(&o, &[name, "at least 10 samples over at least 1 s"]);
        assert!(!stdout(&o).contains("RMSE"), "{}", stdout(&o));
    }
}

/// A header line with a value the reader does not know (`# column-sampled:` as convert writes
/// it, but not a place within a period) is refused with what it expects, not read as no line.
#[test]
fn gap_refuses_a_header_line_it_cannot_read() {
    let dir = tempfile::tempdir().unwrap();
    let rows = step_log(dir.path());
    for bad in [
        "# column-sampled: 12.5 ms before each row's end",
        "# column-sampled: soon",
        "# sync-drift: 35 ppb",
    ] {
        let mut lines = vec!["# drive: epos4".to_string(), bad.to_string()];
        lines.extend(rows.iter().cloned());
        let o = gap_of(dir.path(), "header.csv", &lines);
        assert!(!o.status.success(), "{bad}: {}", stdout(&o));
        let err = stderr(&o);
        assert!(err.contains(bad.trim_start_matches("# ")), "{bad}: {err}");
        assert!(err.contains("expected"), "{bad}: {err}");
    }
}

/// A current logged with the other sign (a sensor mounted the other way round) is read as the
/// car has it, and the car line says so: the verdict is the one on the log as written by the
/// car's own logger. Read as logged, the same file was `unexplained` at 146 times its noise
/// floor.
#[test]
fn gap_reads_a_current_logged_with_the_other_sign_as_the_car_has_it() {
    let dir = tempfile::tempdir().unwrap();
    let rows = step_log(dir.path());
    let verdict = |o: &Output| {
        assert!(o.status.success(), "{}", stderr(o));
        let out = stdout(o);
        let v = out
            .lines()
            .find(|l| l.starts_with("verdict:"))
            .unwrap_or("");
        (v.to_string(), out)
    };
    let (as_written, _) = verdict(&gap_of(dir.path(), "own.csv", &rows));
    let mut negated = rows.clone();
    for line in negated.iter_mut().skip(1) {
        let mut fields: Vec<String> = line.split(',').map(str::to_string).collect();
        let current: f64 = fields[4].parse().unwrap();
        fields[4] = format!("{}", -current);
        *line = fields.join(",");
    }
    let (read, out) = verdict(&gap_of(dir.path(), "negated.csv", &negated));
    assert!(as_written.starts_with("verdict: none"), "{as_written}");
    assert_eq!(read, as_written, "{out}");
    assert!(
        out.contains("the current read with its sign reversed"),
        "{out}"
    );
    // `identify` reads it so too, and fits what it fits on the log as written.
    let identified = |name: &str| {
        let o = host_sim(&["identify", s(&dir.path().join(name))]);
        assert!(o.status.success(), "{}", stderr(&o));
        stdout(&o)
    };
    let (own, read) = (identified("own.csv"), identified("negated.csv"));
    assert!(
        read.starts_with("columns: the current read with its sign reversed"),
        "{read}"
    );
    assert_eq!(
        read.lines().skip(1).collect::<Vec<_>>(),
        own.lines().collect::<Vec<_>>()
    );
}

/// A team's logger that names its columns otherwise (`time_s`, `current`) is refused with the
/// names its header has and the way to read it: a rig file naming them. Read through such a
/// file (the built-in paper rig's, its columns renamed), the same log is diagnosed as the
/// log with the project's names is.
#[test]
fn gap_names_the_columns_it_lacks_and_reads_them_through_a_rig_file() {
    let dir = tempfile::tempdir().unwrap();
    let ours = step_log(dir.path());
    let verdict = |o: &Output| -> String {
        assert!(o.status.success(), "{}", stderr(o));
        let out = stdout(o);
        out.lines()
            .find(|l| l.starts_with("verdict:"))
            .unwrap_or_else(|| panic!("no verdict: {out}"))
            .to_string()
    };
    let expected = verdict(&gap_of(dir.path(), "ours.csv", &ours));

    // The team's names for the project's, in the header host-sim wrote.
    let renamed = |names: &[(&str, &str)]| -> String {
        let header: Vec<&str> = ours[0]
            .split(',')
            .map(|n| names.iter().find(|(a, _)| *a == n).map_or(n, |(_, b)| *b))
            .collect();
        header.join(",")
    };
    for (names, column) in [
        (&[("t", "time_s")][..], "t"),
        (&[("current_a", "current")][..], "current_a"),
    ] {
        let mut lines = ours.clone();
        lines[0] = renamed(names);
        let o = gap_of(dir.path(), "team.csv", &lines);
        assert_refused(
            &o,
            &["team.csv", &format!("{column:?}"), &lines[0], "--rig FILE"],
        );
    }

    let rig: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/rigs/paper.json")).unwrap(),
    )
    .unwrap();
    let mut rig = rig;
    rig["columns"]["time"] = "time_s".into();
    rig["columns"]["effort"] = "current".into();
    let rig_path = dir.path().join("team_rig.json");
    std::fs::write(&rig_path, rig.to_string()).unwrap();
    let mut lines = ours.clone();
    lines[0] = renamed(&[("t", "time_s"), ("current_a", "current")]);
    let log = dir.path().join("team.csv");
    write_lines(&log, &lines);
    let o = host_sim(&["gap", s(&log), "--rig", s(&rig_path), "--threads", "2"]);
    assert_eq!(verdict(&o), expected);
}

/// A log exported with `;` between its fields (a spreadsheet in a comma-decimal locale) or
/// tabs is refused with the separator it has, not read as one column named by the whole line.
#[test]
fn gap_refuses_a_log_not_separated_by_commas_and_names_its_separator() {
    let dir = tempfile::tempdir().unwrap();
    let ours = step_log(dir.path());
    for (name, separator, decimal, named) in [
        ("semicolons.csv", ";", ",", "`;`"),
        ("tabs.csv", "\t", ".", "tabs"),
    ] {
        let lines: Vec<String> = ours
            .iter()
            .map(|l| l.replace(',', separator).replace('.', decimal))
            .collect();
        let o = gap_of(dir.path(), name, &lines);
        assert_refused(&o, &[name, named, "comma-separated"]);
    }
}

/// A recording of the bus (candump) given to `gap` or `identify` is no log yet: it is
/// refused pointing to `steer-can convert`, not as a header that lacks a column named `t`.
#[test]
fn gap_points_a_recording_of_the_bus_to_steer_can_convert() {
    let dir = tempfile::tempdir().unwrap();
    let lines = [
        "(1796667001.000100) can0 100#00112233445566".to_string(),
        "(1796667001.000350) can0 101#0011223344".to_string(),
    ];
    let o = gap_of(dir.path(), "bus.candump", &lines);
    assert_refused(
        &o,
        &[
            "bus.candump",
            "recording of the CAN bus",
            "steer-can convert",
        ],
    );
    let o = host_sim(&["identify", s(&dir.path().join("bus.candump"))]);
    assert_refused(&o, &["bus.candump", "steer-can convert"]);
}

/// `rows` (a header, then data) with field `column` of every data row rewritten by `unit`.
fn in_another_unit(rows: &[String], column: usize, unit: fn(f64) -> f64) -> Vec<String> {
    let mut rows = rows.to_vec();
    for line in 2..=rows.len() {
        let v: f64 = rows[line - 1]
            .split(',')
            .nth(column)
            .unwrap()
            .parse()
            .unwrap();
        set_field(&mut rows, line, column, &format!("{:.6}", unit(v)));
    }
    rows
}

/// The step log with field `column` of every row rewritten in another unit by `unit`,
/// written as `name`: `gap` and `identify` must both refuse it, naming the file and saying
/// `said` (the unit to log comes last; `identify` must say it too).
fn refused_in_another_unit(column: usize, unit: fn(f64) -> f64, name: &str, said: &[&str]) {
    let dir = tempfile::tempdir().unwrap();
    let rows = in_another_unit(&step_log(dir.path()), column, unit);
    let o = gap_of(dir.path(), name, &rows);
    assert_refused(&o, &[&[name], said].concat());
    let o = host_sim(&["identify", s(&dir.path().join(name))]);
    assert_refused(&o, &[name, said[said.len() - 1]]);
}

/// A current in centiamperes (x100 of amperes), under the reader's +-1e4 A bound as a
/// milliampere column of a gentle sweep is: read as logged it was all residual, the log was
/// taken for the loop's chatter and a verdict came from the angles alone. `gap` and
/// `identify` now refuse it, with the figure and the unit to log.
#[test]
fn gap_refuses_a_current_in_another_unit_than_amperes() {
    refused_in_another_unit(
        4,
        |a| a * 100.0,
        "centiamperes.csv",
        &["the current is x", "log it in amperes"],
    );
}

/// A validation log whose current is in another unit than the log's amperes is refused by
/// the same rule, naming it: read as written, every candidate would fail its validation.
#[test]
fn gap_refuses_a_validation_log_with_its_current_in_another_unit() {
    let dir = tempfile::tempdir().unwrap();
    let rows = step_log(dir.path());
    let log = dir.path().join("log.csv");
    write_lines(&log, &rows);
    let validation = dir.path().join("validation.csv");
    write_lines(&validation, &in_another_unit(&rows, 4, |a| a * 100.0));
    let o = host_sim(&[
        "gap",
        s(&log),
        "--validate",
        s(&validation),
        "--threads",
        "2",
    ]);
    assert_refused(&o, &["validation.csv (--validate)", "log it in amperes"]);
}

/// A column in radians beside a reference in degrees (a team's logger writing the encoder's
/// angle as its driver gives it): the car turns its column x0.017 of what the model does for
/// that reference, which no fault of a car does. Read as logged, the world's sweep with play
/// was named play and rack friction; `gap` and `identify` now refuse it, with the figure and
/// the units to check.
#[test]
fn gap_refuses_a_column_in_another_unit_than_its_reference() {
    refused_in_another_unit(
        2,
        f64::to_radians,
        "radians.csv",
        &["the column turns x0.017", "not in one unit"],
    );
}

//! The bad-input table's `steer-can convert` rows (host-sim/README.md, "The log format"),
//! through the real binary:
//! `steer-can convert` refuses a file it cannot read honestly with file, line and reason, or
//! drops what it must with a count and a warning; never a panic. In the laptop build (no
//! `sim` feature) a request for the simulated car is bad input too, answered with how to get
//! a build that has one. (host-sim's rows are in host-sim's `tests/bad_input.rs`.)
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "../../tests/support/refusal.rs"]
mod refusal;

use refusal::{assert_refused, gzip, s, stderr, stdout, write_lines};
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};

fn steer_can(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(args)
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

fn fixture(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/fixtures")
        .join(name)
}

fn ramp_lines() -> Vec<String> {
    std::fs::read_to_string(fixture("bringup_ramp.candump"))
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect()
}

/// Replaces the time stamp of candump line `line` (1-based).
fn set_stamp(lines: &mut [String], line: usize, stamp: &str) {
    let rest = lines[line - 1].split_once(' ').unwrap().1.to_string();
    lines[line - 1] = format!("({stamp}) {rest}");
}

fn stamp_of(lines: &[String], line: usize) -> f64 {
    let l = &lines[line - 1];
    l[1..l.find(')').unwrap()].parse().unwrap()
}

/// Row 4: `steer-can convert` with a time stamp of 1e300: refused with file and line.
#[test]
fn convert_refuses_an_absurd_time_stamp_with_file_and_line() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = ramp_lines();
    set_stamp(&mut lines, 20, "1e300");
    let dump = dir.path().join("far.candump");
    write_lines(&dump, &lines);
    let out = dir.path().join("far.csv");
    let o = steer_can(&["convert", s(&dump), "--out", s(&out)]);
    assert_refused(&o, &["far.candump:20", "1e300", "Unix time"]);
    assert!(!out.exists(), "no log from a refused file");
}

/// Row 4: a frame stamped 1 s back is dropped, counted and warned about; the rest converts as
/// before, nothing moved in time.
#[test]
fn convert_drops_a_frame_a_second_back_with_count_and_warning() {
    let dir = tempfile::tempdir().unwrap();
    let mut lines = ramp_lines();
    let line = 25;
    let back = stamp_of(&lines, line) - 1.0;
    set_stamp(&mut lines, line, &format!("{back:.6}"));
    let dump = dir.path().join("back.candump");
    write_lines(&dump, &lines);
    let out = dir.path().join("back.csv");
    let o = steer_can(&["convert", s(&dump), "--out", s(&out)]);
    let err = stderr(&o);
    assert!(o.status.success(), "{err}");
    assert!(
        err.contains("warning: ") && err.contains("back.candump: 1 frames stamped"),
        "{err}"
    );
    assert!(err.contains("dropped (the first at line 25)"), "{err}");
    let said = stdout(&o);
    let clean = steer_can(&[
        "convert",
        s(&fixture("bringup_ramp.candump")),
        "--out",
        s(&dir.path().join("clean.csv")),
    ]);
    let frames = |text: &str| -> usize {
        let after = &text[text.find(": ").unwrap() + 2..];
        after.split_whitespace().next().unwrap().parse().unwrap()
    };
    assert_eq!(frames(&said) + 1, frames(&stdout(&clean)), "{said}");
}

/// Section 4, and row 5 for candump: `convert` reads `.candump.gz`, and its errors name the
/// file.
#[test]
fn convert_reads_gzip_candump_and_names_the_file_in_errors() {
    let dir = tempfile::tempdir().unwrap();
    let packed = dir.path().join("ramp.candump.gz");
    let raw = std::fs::read(fixture("bringup_ramp.candump")).unwrap();
    std::fs::write(&packed, gzip(&raw)).unwrap();
    let out = dir.path().join("ramp.csv");
    let o = steer_can(&["convert", s(&packed), "--out", s(&out)]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(
        std::fs::read_to_string(&out).unwrap(),
        std::fs::read_to_string(fixture("bringup_ramp.csv")).unwrap()
    );

    let cut = dir.path().join("cut.candump.gz");
    let gz = gzip(&raw);
    std::fs::write(&cut, &gz[..gz.len() / 2]).unwrap();
    let o = steer_can(&["convert", s(&cut), "--out", s(&out)]);
    assert_refused(&o, &["cut.candump.gz", "truncated gzip"]);

    // A recording without the vehicle's references: the error names the file it read.
    let ecu_only: Vec<String> = ramp_lines()
        .into_iter()
        .filter(|l| !l.contains(" 100#"))
        .collect();
    let dump = dir.path().join("ecu_only.candump");
    write_lines(&dump, &ecu_only);
    let o = steer_can(&["convert", s(&dump), "--out", s(&out)]);
    assert_refused(&o, &["ecu_only.candump: no valid reference frame (0x100)"]);
}

/// An interface that is missing or down (the first thing the laptop on the car meets): refused
/// with the command that brings it up, in either build.
#[test]
fn a_missing_interface_says_how_to_bring_it_up() {
    let o = steer_can(&["--iface", "nocan7", "monitor", "--duration-s", "0.1"]);
    assert_refused(
        &o,
        &[
            "nocan7: no such interface",
            "sudo ip link set nocan7 up type can bitrate 1000000",
        ],
    );
}

/// A shared simulated car that is not there: the advice is to start one, not `ip link`.
#[cfg(all(unix, feature = "sim"))]
#[test]
fn a_missing_simulated_car_says_how_to_start_one() {
    let o = steer_can(&[
        "--iface",
        "sim:/nonexistent.sock",
        "monitor",
        "--duration-s",
        "0.1",
    ]);
    assert_refused(
        &o,
        &[
            "--iface sim:/nonexistent.sock: no simulated car serves this socket",
            "steer-can sim-car --socket /nonexistent.sock",
        ],
    );
    assert!(!stderr(&o).contains("ip link"), "{}", stderr(&o));
}

/// A file that is not a candump log, with no line end for megabytes (`truncate -s 2G`), is
/// refused at its first line, without reading it whole.
#[test]
fn convert_refuses_an_overlong_line_without_reading_it_whole() {
    let dir = tempfile::tempdir().unwrap();
    let dump = dir.path().join("zeros.candump");
    std::fs::write(&dump, vec![0u8; 8 * 1024 * 1024]).unwrap();
    let out = dir.path().join("log.csv");
    let o = steer_can(&["convert", s(&dump), "--out", s(&out)]);
    assert_refused(&o, &["zeros.candump:1: longer than 4096 bytes"]);
    assert!(!out.exists());
}

/// The laptop build has no simulated car: `--iface sim`, `--iface sim:PATH`, `rehearse` and
/// `sim-car` each say so and how to get a build with one, before touching any bus or file.
#[cfg(not(feature = "sim"))]
#[test]
fn the_laptop_build_says_it_has_no_simulated_car_and_how_to_get_one() {
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("car.sock");
    let sim_path = format!("sim:{}", s(&socket));
    for (args, asked) in [
        (
            vec!["monitor", "--iface", "sim", "--duration-s", "0.1"],
            "--iface sim",
        ),
        (vec!["epos", "check", "--iface", &sim_path], "--iface sim:"),
        (
            vec!["--iface", "sim", "rehearse", "--dir", s(dir.path())],
            "rehearse",
        ),
        (vec!["sim-car", "--socket", s(&socket)], "sim-car"),
    ] {
        let o = steer_can(&args);
        assert_refused(
            &o,
            &[
                asked,
                "built without the simulated car",
                "cargo install --path host-sim/steer-can",
            ],
        );
        assert!(!socket.exists(), "{args:?} served a socket");
    }
}

/// `convert --help` states the most frames it reads, the number the reader enforces.
#[test]
fn convert_help_states_its_frame_bound() {
    let o = steer_can(&["convert", "--help"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let bound = steer_can::candump::MAX_FRAMES.to_string();
    let help = stdout(&o).split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(help.contains(&format!("at most {bound} frames")), "{help}");
    assert!(help.contains(&format!("split -l {bound}")), "{help}");
}

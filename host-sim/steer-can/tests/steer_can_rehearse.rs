//! `steer-can rehearse` as a process, as a team runs it: the README's first day on the
//! simulated car in one session, every step matching what the README says to expect. The
//! number of steps is counted here from the README independently of the tool, so a rehearsal
//! that silently ran fewer steps than the README names fails.
#![cfg(feature = "sim")]
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "../../tests/support/gap_file.rs"]
mod gap_file;

use std::process::{Command, Stdio};

/// The inline `steer-can ...` commands of the README's bring-up section from its numbered
/// list on (outside fenced blocks), mentions of `rehearse` itself left out.
fn readme_steer_can_commands() -> usize {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/README.md")).unwrap();
    let start = readme
        .find("### Bring-up on the car with `steer-can`")
        .unwrap();
    let body = &readme[start..];
    let end = body[4..]
        .find("\n## ")
        .into_iter()
        .chain(body[4..].find("\n### "))
        .chain(body[4..].find("\n<!--"))
        .min()
        .unwrap()
        + 4;
    let list = body.find("\n1. **").unwrap();
    let mut text = String::new();
    let mut fenced = false;
    for line in body[list..end].lines() {
        if line.starts_with("```") {
            fenced = !fenced;
        } else if !fenced {
            text.push_str(line);
            text.push(' ');
        }
    }
    // Odd pieces of a split on backticks are the inline code spans.
    text.split('`')
        .skip(1)
        .step_by(2)
        .map(|code| code.split_whitespace().collect::<Vec<_>>().join(" "))
        .filter(|c| c.starts_with("steer-can ") && !c.split(' ').any(|w| w == "rehearse"))
        .count()
}

#[test]
fn rehearse_runs_the_readme_first_day_and_every_step_passes() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["--iface", "sim", "--fast", "rehearse", "--dir"])
        .arg(dir.path())
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{out}\n{err}");
    let n = readme_steer_can_commands();
    assert!(n >= 10, "the README's list has {n} steer-can commands");
    let verdicts: Vec<&str> = out
        .lines()
        .map(str::trim)
        .filter(|l| *l == "PASS" || *l == "FAIL")
        .collect();
    assert_eq!(verdicts.len(), n, "one verdict per README command: {out}");
    assert!(verdicts.iter().all(|v| *v == "PASS"), "{out}");
    assert!(out.contains(&format!("rehearsal: {n} of {n} steps match the README")));
    // One session: the timeout left by `send --no-finish` is what the next monitor shows.
    assert!(
        out.contains("seen:           state faulted, faults reference timeout"),
        "{out}"
    );
    // The steps' files are where the README's commands put them, in --dir.
    for f in [
        "sweep.csv.gz",
        "sweep.csv.gz.candump",
        "track.csv.gz",
        "profile.csv",
        "bus.candump",
        "log.csv",
    ] {
        assert!(dir.path().join(f).exists(), "{f} missing");
    }
    let log = host_io::logfmt::Log::load(&dir.path().join("log.csv")).unwrap();
    assert!(!log.is_empty());
    // Step 8: the sweep diagnosed as `host-sim gap sweep.csv.gz` diagnoses it. The car
    // is exactly Table 4 and has moved before the sweep (the step, the timeout), so it stands
    // within a count of where the model starts it: `none`.
    let (d, choice) = gap_file::diagnose_file(&dir.path().join("sweep.csv.gz"), None, None);
    println!(
        "sweep: {:?} ({}), GoF {:.1} %, output offset {:?}; {}",
        d.verdict.kind,
        choice.describe(),
        100.0 * d.baseline_gof,
        d.output_offset,
        d.verdict.reason
    );
    assert_eq!(
        d.verdict.kind,
        host_sim::gap::VerdictKind::None,
        "{}",
        d.verdict.reason
    );
}

/// A rehearsal on the car's interface is refused: it drives the simulated car only.
#[test]
fn rehearse_refuses_a_real_interface() {
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["--iface", "can0", "rehearse"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("simulated car only"), "{err}");
}

/// A car that is not fine fails the rehearsal: a column encoder that stops answering half a
/// second in shows in the first monitor step, and the exit code says so.
#[test]
fn a_broken_car_fails_the_rehearsal() {
    let dir = tempfile::tempdir().unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args([
            "--iface",
            "sim",
            "--fast",
            "--sim-inject",
            "encoder@0.5",
            "rehearse",
            "--dir",
        ])
        .arg(dir.path())
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let out = String::from_utf8_lossy(&o.stdout);
    assert_eq!(o.status.code(), Some(1), "{out}");
    let first = out
        .lines()
        .map(str::trim)
        .find(|l| *l == "PASS" || *l == "FAIL");
    assert_eq!(first, Some("FAIL"), "{out}");
    assert!(out.contains("column encoder"), "{out}");
    assert!(out.contains("see FAIL above"), "{out}");
}

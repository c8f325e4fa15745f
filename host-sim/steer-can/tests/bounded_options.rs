//! Every numeric option of every `steer-can` command has a range: the binary, given NaN, an
//! infinity, a negative or a huge value, refuses it before it touches a bus or a file, naming
//! the option and the value (not clap's "unexpected argument", not a run of zero length, not a
//! profile too large for memory). The table is checked against the options `--help` lists, so
//! a new numeric option without a row fails here.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use clap::CommandFactory;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// One numeric option: the command line that reaches it (`{}` is the option and its value)
/// and the values it must refuse.
struct Row {
    command: &'static str,
    option: &'static str,
    refused: &'static [&'static str],
}

const TIMES: &[&str] = &["nan", "inf", "-1", "0", "1e9"];

const TABLE: &[Row] = &[
    Row {
        command: "monitor",
        option: "--node",
        refused: &["0", "128", "-1", "1e9"],
    },
    Row {
        command: "monitor",
        option: "--sim-column-deg",
        refused: &["nan", "inf", "500", "-500"],
    },
    Row {
        command: "monitor",
        option: "--duration-s",
        refused: TIMES,
    },
    Row {
        command: "monitor",
        option: "--refresh-s",
        refused: TIMES,
    },
    Row {
        command: "record --out never.candump",
        option: "--duration-s",
        refused: TIMES,
    },
    Row {
        command: "send step",
        option: "--amplitude-deg",
        refused: &["nan", "inf", "500", "-500"],
    },
    Row {
        command: "send step",
        option: "--at-s",
        refused: &["nan", "inf", "-1", "601", "1e9"],
    },
    Row {
        command: "send step",
        option: "--duration-s",
        refused: TIMES,
    },
    Row {
        command: "send sine",
        option: "--amplitude-deg",
        refused: &["nan", "inf", "500", "-500"],
    },
    Row {
        command: "send sine",
        option: "--freq-hz",
        refused: &["nan", "inf", "-1", "0", "50", "1e9"],
    },
    Row {
        command: "send sine",
        option: "--duration-s",
        refused: TIMES,
    },
    Row {
        command: "send sweep",
        option: "--amplitude-deg",
        refused: &["nan", "inf", "-1", "0", "500"],
    },
    Row {
        command: "send sweep",
        option: "--f-start-hz",
        refused: &["nan", "inf", "-1", "10", "1e9"],
    },
    Row {
        command: "send sweep",
        option: "--f-end-hz",
        refused: &["nan", "inf", "-1", "0", "51"],
    },
    Row {
        command: "send sweep",
        option: "--duration-s",
        refused: TIMES,
    },
    Row {
        command: "campaign sweep --out never.csv",
        option: "--amplitude-deg",
        refused: &["nan", "inf", "-1", "0", "500"],
    },
    Row {
        command: "campaign sweep --out never.csv",
        option: "--f-start-hz",
        refused: &["nan", "inf", "-1", "10", "1e9"],
    },
    Row {
        command: "campaign sweep --out never.csv",
        option: "--f-end-hz",
        refused: &["nan", "inf", "-1", "0", "51"],
    },
    Row {
        command: "campaign sweep --out never.csv",
        option: "--duration-s",
        refused: TIMES,
    },
];

#[test]
fn every_numeric_option_refuses_what_it_cannot_mean() {
    let dir = tempfile::tempdir().unwrap();
    let mut failures = Vec::new();
    for row in TABLE {
        for value in row.refused {
            let mut args: Vec<&str> = row.command.split_whitespace().collect();
            args.extend([row.option, value]);
            let started = Instant::now();
            let out = Command::new(env!("CARGO_BIN_EXE_steer-can"))
                .args(&args)
                .current_dir(dir.path())
                .stdin(Stdio::null())
                .output()
                .unwrap();
            let err = String::from_utf8_lossy(&out.stderr);
            let named = err.contains(row.option)
                && (err.contains(value)
                    || err.contains(&format!("{}", value.parse::<f64>().unwrap())));
            if out.status.success()
                || !named
                || err.contains("unexpected argument")
                || started.elapsed() > Duration::from_secs(5)
            {
                failures.push(format!(
                    "steer-can {}: exit {:?} in {:.1?}, stderr `{}`",
                    args.join(" "),
                    out.status.code(),
                    started.elapsed(),
                    err.trim()
                ));
            }
        }
    }
    // Nothing was written by a refused command.
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "files written: {left:?}");
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

/// The message says the range and why, as host-sim's do.
#[test]
fn a_refusal_gives_the_range_and_its_reason() {
    let out = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["send", "sine", "--freq-hz", "50", "--as-state", "driving"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "--freq-hz 50: must be in (0, 50) Hz (below the 100 Hz reference's Nyquist limit)"
        ),
        "{err}"
    );
    let out = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["monitor", "--node", "0"])
        .stdin(Stdio::null())
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.starts_with("steer-can: error: --node 0: must be in [1, 127]"),
        "{err}"
    );
}

/// The table above covers every option of the command tree that takes a number (a time, an
/// angle, a frequency, the node).
#[test]
fn the_table_covers_every_numeric_option_help_lists() {
    fn walk(cmd: &clap::Command, path: &str, found: &mut Vec<(String, String)>) {
        for arg in cmd.get_arguments() {
            let numeric = arg.get_id() == "node"
                || arg
                    .get_value_names()
                    .is_some_and(|v| v.iter().any(|n| ["S", "DEG", "HZ"].contains(&n.as_str())));
            if numeric && !arg.is_hide_set() {
                let long = format!("--{}", arg.get_long().unwrap());
                // A global option is checked once, under the first command of the table.
                let at = if arg.is_global_set() { "monitor" } else { path };
                found.push((at.trim().to_string(), long));
            }
        }
        for sub in cmd.get_subcommands() {
            walk(sub, &format!("{path} {}", sub.get_name()), found);
        }
    }
    let mut found = Vec::new();
    walk(&steer_can::args::Cli::command(), "", &mut found);
    assert!(found.len() >= TABLE.len());
    for (path, long) in found {
        let covered = TABLE.iter().any(|r| {
            r.option == long
                && r.command
                    .split_whitespace()
                    .filter(|w| !w.starts_with('-') && !w.contains('.'))
                    .collect::<Vec<_>>()
                    .join(" ")
                    == path
        });
        assert!(covered, "`steer-can {path} {long}` has no row in the table");
    }
}

/// The hidden `--sim-inject KIND@SECONDS` checks its time too.
#[cfg(feature = "sim")]
#[test]
fn a_fault_injection_time_is_bounded() {
    for at in ["nan", "-1", "1e9"] {
        let spec = format!("encoder@{at}");
        let out = Command::new(env!("CARGO_BIN_EXE_steer-can"))
            .args(["--iface", "sim", "--fast", "monitor", "--duration-s", "0.1"])
            .args(["--sim-inject", &spec])
            .stdin(Stdio::null())
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("--sim-inject time"),
            "{spec}: {err}"
        );
    }
}

//! steer-can's README command summary against the program's own `--help`: every option the
//! README shows must be one the program documents for that very subcommand, so a team that
//! copies a line from the README is not told it is unknown. The checker is shared with
//! host-sim's `readme_help` test. And the front page's one-minute tour is a command the program
//! takes.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "../../tests/support/readme_summary.rs"]
mod readme_summary;

use readme_summary::{block, check};
use std::process::Command;

fn read(path: &str) -> String {
    std::fs::read_to_string(format!("{}/{path}", env!("CARGO_MANIFEST_DIR")))
        .unwrap_or_else(|e| panic!("{path}: {e}"))
}

#[test]
fn steer_can_options_in_the_readme_are_in_its_help() {
    let lines = block(&read("README.md"), "steer-can [--iface");
    check(env!("CARGO_BIN_EXE_steer-can"), &lines, "steer-can");
}

/// The tour on the front page (`cargo run --release -p steer-can -- --iface sim --fast
/// rehearse`): its subcommand's help lists every option the tour gives it.
#[test]
fn the_front_pages_tour_is_a_steer_can_command() {
    let front = read("../../README.md");
    let start = front
        .find("## The one-minute tour")
        .expect("the front page has no `## The one-minute tour` section");
    let tour = front[start..]
        .lines()
        .find_map(|l| {
            l.trim()
                .strip_prefix("cargo run --release -p steer-can -- ")
        })
        .expect("no `cargo run --release -p steer-can -- ...` in the tour");
    let words: Vec<&str> = tour.split_whitespace().collect();
    let subcommand: Vec<&str> = words
        .iter()
        .copied()
        .filter(|w| !w.starts_with('-') && *w != "sim")
        .collect();
    assert_eq!(subcommand, ["rehearse"], "{tour}");
    let help = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["rehearse", "--help"])
        .output()
        .unwrap();
    assert!(help.status.success(), "steer-can rehearse --help failed");
    let help = String::from_utf8(help.stdout).unwrap();
    let options: Vec<&&str> = words.iter().filter(|w| w.starts_with("--")).collect();
    assert_eq!(options.len(), 2, "{tour}");
    for option in options {
        assert!(
            help.contains(&format!("{option} ")) || help.contains(&format!("{option}\n")),
            "the tour gives `rehearse` `{option}`, its `--help` does not have it:\n{help}"
        );
    }
}

//! The READMEs' commands against the programs: the command summary of `host-sim gap` in
//! host-sim's README against the program's own `--help` (every option the README shows must be
//! one the program documents for that very subcommand, so a newcomer who copies a line is not
//! told it is unknown), and the front page's two commands against CI's test command and
//! `host-sim`'s help. (steer-can's summary is checked in steer-can's own `tests/readme_help.rs`,
//! with the same checker.)
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/readme_summary.rs"]
mod readme_summary;

use readme_summary::{block, check};
use std::process::Command;

fn read(path: &str) -> String {
    std::fs::read_to_string(format!("{}/{path}", env!("CARGO_MANIFEST_DIR")))
        .unwrap_or_else(|e| panic!("{path}: {e}"))
}

#[test]
fn gap_options_in_the_readme_are_in_its_help() {
    let lines = block(&read("README.md"), "host-sim gap LOG");
    check(env!("CARGO_BIN_EXE_host-sim"), &lines, "host-sim");
}

/// The commands of the front page's "Two commands" block, comments left out.
fn two_commands() -> Vec<String> {
    let front = read("../README.md");
    let start = front
        .find("## Two commands")
        .expect("the front page has no `## Two commands` section");
    let body = &front[start..];
    let open = body
        .find("```sh\n")
        .expect("no sh block under `## Two commands`")
        + 6;
    body[open..]
        .lines()
        .take_while(|l| !l.starts_with("```"))
        .map(str::trim)
        .filter(|l| !l.is_empty() && !l.starts_with('#'))
        .map(str::to_string)
        .collect()
}

/// The front page's test command is the one CI runs (`TEST_CMD` in `.ci/run`, which says to
/// keep the two in sync), and its first command's subcommand and options are `host-sim`'s.
#[test]
fn the_front_pages_two_commands_are_cis_and_host_sims() {
    let commands = two_commands();
    assert_eq!(commands.len(), 2, "{commands:?}");

    let ci = read("../.ci/run");
    let test_cmd = ci
        .lines()
        .find_map(|l| l.strip_prefix("TEST_CMD=\""))
        .and_then(|l| l.strip_suffix('"'))
        .expect(".ci/run has no TEST_CMD=\"...\" line");
    assert_eq!(
        commands[1], test_cmd,
        "the front page's test command is not CI's"
    );

    let run = commands[0]
        .strip_prefix("cargo run --release -p host-sim -- ")
        .unwrap_or_else(|| panic!("not a host-sim run: {}", commands[0]));
    let words: Vec<&str> = run.split_whitespace().collect();
    let subcommand = words[0];
    let help = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args([subcommand, "--help"])
        .output()
        .unwrap();
    assert!(help.status.success(), "host-sim {subcommand} --help failed");
    let help = String::from_utf8(help.stdout).unwrap();
    let options: Vec<&&str> = words.iter().filter(|w| w.starts_with("--")).collect();
    assert!(!options.is_empty(), "{run}");
    for option in options {
        assert!(
            help.contains(&format!("{option} ")) || help.contains(&format!("{option}\n")),
            "the front page runs `host-sim {subcommand} {option}`, its `--help` does not have \
             it:\n{help}"
        );
    }
}

//! The README's command summary for `steer-can` against the program's own `--help`: every
//! option the README shows must be one the program documents for that very subcommand, so a
//! team that copies a line from the README is not told it is unknown. The checker is shared
//! with host-sim's `readme_help` test.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "../../tests/support/readme_summary.rs"]
mod readme_summary;

use readme_summary::{block, check};

fn readme() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../../README.md")).unwrap()
}

#[test]
fn steer_can_options_in_the_readme_are_in_its_help() {
    let lines = block(&readme(), "steer-can [--iface");
    check(env!("CARGO_BIN_EXE_steer-can"), &lines, "steer-can");
}

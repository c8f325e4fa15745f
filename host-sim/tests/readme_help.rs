//! The README's command summary for `host-sim gap` against the program's own `--help`: every
//! option the README shows must be one the program documents for that very subcommand, so a
//! newcomer who copies a line from the README is not told it is unknown. (steer-can's summary
//! is checked in steer-can's own `tests/readme_help.rs`, with the same checker.)
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

#[path = "support/readme_summary.rs"]
mod readme_summary;

use readme_summary::{block, check};

fn readme() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md")).unwrap()
}

#[test]
fn gap_options_in_the_readme_are_in_its_help() {
    let lines = block(&readme(), "host-sim gap LOG");
    check(env!("CARGO_BIN_EXE_host-sim"), &lines, "host-sim");
}

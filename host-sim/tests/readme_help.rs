//! The README's command summaries against the programs' own `--help`: every option the README
//! shows for `steer-can` and `host-sim gap` must be one the program documents for that very
//! subcommand, so a newcomer who copies a line from the README is not told it is unknown.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use std::process::Command;

fn readme() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../README.md")).unwrap()
}

/// The fenced block of the README whose first line starts with `first`.
fn block(text: &str, first: &str) -> Vec<String> {
    let start = text
        .find(&format!("```\n{first}"))
        .unwrap_or_else(|| panic!("no README block starting with `{first}`"));
    text[start + 4..]
        .lines()
        .take_while(|l| !l.starts_with("```"))
        .map(str::to_string)
        .collect()
}

/// The subcommand words at the start of a summary line (`campaign sweep|track --out` ->
/// `campaign sweep`), and the `--options` anywhere on it.
fn words_and_options(line: &str) -> (Vec<String>, Vec<String>) {
    let mut words = Vec::new();
    for w in line.split_whitespace() {
        if w.starts_with('-') || w.starts_with('[') || w.starts_with('<') || w.starts_with('#') {
            break;
        }
        let first = w.split('|').next().unwrap();
        if !first.chars().all(|c| c.is_ascii_lowercase() || c == '-') {
            break;
        }
        words.push(first.to_string());
    }
    let options = line
        .split(|c: char| c.is_whitespace() || c == '[' || c == ']')
        .filter(|t| t.starts_with("--"))
        .map(|t| {
            t.trim_end_matches(|c: char| !c.is_ascii_alphanumeric())
                .to_string()
        })
        .collect();
    (words, options)
}

fn help(exe: &str, words: &[String]) -> String {
    let o = Command::new(exe)
        .args(words)
        .arg("--help")
        .output()
        .unwrap();
    assert!(o.status.success(), "{words:?} --help failed");
    String::from_utf8(o.stdout).unwrap()
}

fn check(exe: &str, lines: &[String], program: &str) {
    let mut checked = 0;
    let mut current: Vec<String> = Vec::new();
    for line in lines {
        let line = line.trim_start();
        let line = line.strip_prefix(program).unwrap_or(line).trim_start();
        // Comment columns start after two or more spaces and are not options.
        let line = line.split("  ").next().unwrap_or("");
        let (words, options) = words_and_options(line);
        if !words.is_empty() {
            current = words;
        }
        if options.is_empty() {
            continue;
        }
        let text = help(exe, &current);
        for option in options {
            assert!(
                text.contains(&format!("{option} ")) || text.contains(&format!("{option}\n")),
                "README shows `{program} {} {option}`, `--help` does not:\n{text}",
                current.join(" ")
            );
            checked += 1;
        }
    }
    assert!(
        checked >= 5,
        "only {checked} options found in the README block"
    );
}

#[test]
fn steer_can_options_in_the_readme_are_in_its_help() {
    let lines = block(&readme(), "steer-can [--iface");
    check(env!("CARGO_BIN_EXE_steer-can"), &lines, "steer-can");
}

#[test]
fn gap_options_in_the_readme_are_in_its_help() {
    let lines = block(&readme(), "host-sim gap LOG");
    check(env!("CARGO_BIN_EXE_host-sim"), &lines, "host-sim");
}

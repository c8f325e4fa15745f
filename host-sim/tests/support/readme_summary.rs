//! Shared by host-sim's and steer-can's `readme_help` tests (each package's test can run only
//! its own binaries): a README command summary checked against the program's `--help`, every
//! option on a summary line looked up in the help of that line's subcommand.

use std::process::Command;

/// The fenced block of the README whose first line starts with `first`.
pub fn block(text: &str, first: &str) -> Vec<String> {
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

pub fn check(exe: &str, lines: &[String], program: &str) {
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

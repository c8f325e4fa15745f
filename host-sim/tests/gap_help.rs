//! `host-sim gap selftest --help` shows the selftest's own options, and
//! `gap --help` still shows the diagnosis's.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use std::process::Command;

fn help(args: &[&str]) -> String {
    let o = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(args)
        .output()
        .unwrap();
    assert!(
        o.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

#[test]
fn gap_selftest_help_shows_the_selftest_options_only() {
    for args in [
        ["gap", "selftest", "--help"],
        ["gap", "--help", "selftest"],
        ["gap", "selftest", "-h"],
    ] {
        let text = help(&args);
        assert!(text.contains("host-sim gap selftest [OPTIONS]"), "{text}");
        for option in [
            "--cases",
            "--seed",
            "--duration-s",
            "--model-world",
            "--threads",
        ] {
            assert!(text.contains(option), "{option} missing: {text}");
        }
        for option in [
            "--validate",
            "--rig",
            "--refit-linear",
            "--plots",
            "--effects",
        ] {
            assert!(
                !text.contains(option),
                "{option} is not the selftest's: {text}"
            );
        }
    }
}

#[test]
fn gap_help_shows_the_diagnosis_options_and_a_missing_log_is_an_error() {
    let text = help(&["gap", "--help"]);
    assert!(text.contains("host-sim gap [OPTIONS] <LOG>"), "{text}");
    for option in ["--validate", "--rig", "--effects", "--cases"] {
        assert!(text.contains(option), "{option} missing: {text}");
    }
    let o = Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .arg("gap")
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("<LOG>"));
}

//! Shared by host-sim's and steer-can's `bad_input` tests (each package's test can run only its
//! own binaries): what "refused" means for the bad-input table, and the small file
//! helpers both use to make bad files.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use std::io::Write;
use std::path::Path;
use std::process::Output;

pub fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

pub fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

pub fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// Refused: a failure exit (not the 101 of a panic), no panic message, and
/// every piece of `expected` in the error.
pub fn assert_refused(o: &Output, expected: &[&str]) {
    let err = stderr(o);
    assert!(!o.status.success(), "accepted: {}\n{err}", stdout(o));
    assert_ne!(o.status.code(), Some(101), "panicked: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for piece in expected {
        assert!(err.contains(piece), "`{piece}` not in: {err}");
    }
}

pub fn write_lines(path: &Path, lines: &[String]) {
    std::fs::write(path, lines.join("\n") + "\n").unwrap();
}

pub fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut gz = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::default());
    gz.write_all(bytes).unwrap();
    gz.finish().unwrap()
}

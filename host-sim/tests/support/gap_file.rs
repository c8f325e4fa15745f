//! Shared by the gap tests that diagnose a log file as `host-sim gap FILE` does (host-sim's
//! and steer-can's): the file read by the paper rig's reader, the car given as far as
//! `drive` and `controller` say (as `--drive` and `--controller`), the rest from the header
//! lines or fitted, and the candidates the command fits on that rig.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use host_sim::gap::drive::{self, CarChoice};
use host_sim::gap::rig::{CarDrive, Rig};
use host_sim::gap::{Diagnosis, EffectKind, Options, VerdictKind, diagnose};
use host_sim::sim::Controller;
use std::path::Path;

pub fn diagnose_file(
    path: &Path,
    drive: Option<CarDrive>,
    controller: Option<Controller>,
) -> (Diagnosis, CarChoice) {
    let rig = Rig::paper();
    let loaded = rig.load_log(path).unwrap();
    let header = drive::LogHeader::parse(&loaded.comments).unwrap();
    let opts = Options {
        effects: EffectKind::for_rig(&rig),
        threads: 2,
        ..Options::default()
    };
    let (rig, rec, choice) =
        drive::choose_for_log(&rig, &loaded, &header, drive, controller, &opts);
    let d = diagnose(&rig, &rec, None, &opts);
    let choice = choice.unwrap().on_the_clock_of(&d);
    println!("{}\n{}", choice.describe(), d.summary());
    (d, choice)
}

/// [`diagnose_file`] with the car fitted, asserted `none` (`what` names the log in the
/// message); the diagnosis and the car, for what a test checks beside.
#[allow(dead_code)] // each test binary takes what it needs
pub fn assert_none(path: &Path, what: &str) -> (Diagnosis, CarChoice) {
    let (d, choice) = diagnose_file(path, None, None);
    assert_eq!(
        d.verdict.kind,
        VerdictKind::None,
        "{what}: {:?}: {}",
        d.verdict.effects,
        choice.describe()
    );
    (d, choice)
}

/// One of the reader's `notes` says `said`.
#[allow(dead_code)] // each test binary takes what it needs
pub fn assert_noted(notes: &[String], said: &str) {
    assert!(
        notes.iter().any(|n| n.contains(said)),
        "no note says {said:?}: {notes:?}"
    );
}

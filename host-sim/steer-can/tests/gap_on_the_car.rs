//! The gap diagnosis on the car's own logs: the simulated car (the firmware's tasks, the
//! simulated EPOS4 or the ECU's own bridge, the paper plant, exactly Table 4, no effect) runs
//! a campaign, the recording becomes a log as `steer-can convert` makes it, and the log is
//! diagnosed as `host-sim gap` diagnoses it: the car from the log's header and the fit of the
//! rest, then the verdict. An effect-free car must be `none`, its nominal model at >= 95 %.
#![cfg(feature = "sim")]
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use host_io::scenario::Sweep;
use host_sim::gap::drive::{self, LogHeader, Source};
use host_sim::gap::rig::{CarDrive, Rig};
use host_sim::gap::{Options, diagnose};
use host_sim::sim_ecu::{SimCar, SimDrive, SimEcu};
use std::sync::Arc;
use std::sync::atomic::AtomicBool;
use steer_can::campaign::{self, Campaign};
use steer_can::decode::Decoder;
use steer_can::profile::{self, Profile};
use steering_ecu::as_state::AsState;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::epos4::PositionScale;
use steering_ecu::controller::ControllerKind;

fn decoder() -> Decoder {
    Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(84).unwrap())
}

/// The campaign's log, saved and loaded back as `gap` reads it; the car's figures.
fn diagnosed(car: SimCar, profile: Profile) -> (host_sim::gap::Diagnosis, drive::CarChoice) {
    let mut sim = SimEcu::new(car);
    let dec = decoder();
    let ready = campaign::ready_check(&mut sim, &dec).unwrap();
    let c = Campaign {
        profile,
        as_state: AsState::Driving,
        stop: Arc::new(AtomicBool::new(false)),
    };
    let run = c.run(&mut sim, &dec, &ready, |_| {}).unwrap();
    assert_eq!(run.aborted, None);
    drop(sim);
    let built = run.log(&dec).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("car.csv.gz");
    campaign::save_log(&built.log, &path).unwrap();

    let rig = Rig::paper();
    let loaded = rig.load_log(&path).unwrap();
    let rec = loaded.record;
    let header = LogHeader::parse(&loaded.comments).unwrap();
    let want = match car.drive {
        SimDrive::Epos4 => CarDrive::Epos4,
        SimDrive::Direct => CarDrive::Direct,
    };
    assert_eq!(header.drive, Some(want), "the log's header names the drive");
    let says = drive::LogSays {
        reference_stated: header.reference.is_some(),
        timing: loaded.timing,
    };
    let (rig, rec, choice) = drive::choose(
        &rig,
        &rec,
        header.drive.map(|d| (d, Source::Header)),
        header.controller.map(|c| (c, Source::Header)),
        says,
        2,
    );
    let choice = choice.unwrap();
    println!("{}", choice.describe());
    let d = diagnose(
        &rig,
        &rec,
        None,
        &Options {
            threads: 2,
            ..Options::default()
        },
    );
    println!("{}", d.summary());
    (d, choice)
}

fn epos4(controller: ControllerKind) -> SimCar {
    SimCar {
        column_deg: 0.0,
        controller,
        drive: SimDrive::Epos4,
    }
}

fn assert_none_at_95(d: &host_sim::gap::Diagnosis) {
    assert!(
        d.verdict.effects.is_empty() && d.verdict.kind == host_sim::gap::VerdictKind::None,
        "{:?}: {}",
        d.verdict.kind,
        d.verdict.reason
    );
    assert!(
        d.baseline_gof >= 0.95,
        "nominal GoF {:.1} %",
        100.0 * d.baseline_gof
    );
}

#[test]
fn the_default_epos4_car_on_a_sweep_is_none_against_its_own_chain() {
    let (d, choice) = diagnosed(
        epos4(ControllerKind::Paper),
        profile::sweep(Sweep::PAPER).unwrap(),
    );
    assert_eq!(choice.drive, CarDrive::Epos4);
    assert_eq!(choice.controller, host_sim::sim::Controller::Paper);
    assert_none_at_95(&d);
}

#[test]
fn the_epos4_car_under_the_ecu_controller_on_a_sweep_is_none() {
    let (d, choice) = diagnosed(
        epos4(ControllerKind::Ecu),
        profile::sweep(Sweep::PAPER).unwrap(),
    );
    assert_eq!(choice.drive, CarDrive::Epos4);
    // The bus does not say which controller the ECU runs: the log does.
    assert_eq!(choice.controller_from, Source::Fitted);
    assert_eq!(choice.controller, host_sim::sim::Controller::Ecu);
    assert_none_at_95(&d);
}

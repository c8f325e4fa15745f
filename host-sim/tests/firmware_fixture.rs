//! The fixture the task tests and the simulated car run on (`host_sim::firmware_fixture`):
//! what an ECU reset keeps and loses, and the watchdog's log. Own test binary: the mock clock
//! is global to the process.
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use host_sim::canbus::RandomFaults;
use host_sim::effect_plant::PlantEffects;
use host_sim::firmware_fixture::{CarPlant, FirmwareFixture, FixtureBuild, STEP_US, SimDrive};
use steering_ecu::canopen::epos4::Phase;
use steering_ecu::canopen::nmt::NmtState;
use steering_ecu::controller::ControllerKind;
use steering_ecu::watchdog::FEED_PERIOD_US;

fn build(drive: SimDrive, watchdog: bool) -> FixtureBuild {
    FixtureBuild {
        controller: ControllerKind::Paper,
        drive,
        column_rad: 0.0,
        epos4_effects: PlantEffects::NONE,
        direct_plant: CarPlant::new(PlantEffects::NONE, STEP_US as f64 * 1e-6),
        bus_faults: RandomFaults::default(),
        bus_seed: 1,
        watchdog,
        reference_delay_us: 0,
    }
}

/// One step in the simulated car's order.
fn step(fixture: &mut FirmwareFixture) {
    let _ = fixture.deliver();
    fixture.poll_tasks();
    let _ = fixture.tx_to_bus();
    fixture.advance_epos();
    fixture.fast_loop();
    fixture.end_step();
}

fn run_to(fixture: &mut FirmwareFixture, t_us: u64) {
    while fixture.now_us() < t_us {
        step(fixture);
    }
}

/// The link brings the simulated EPOS4 up; a reset then loses what the dead ECU had queued and
/// starts a fresh ECU whose link starts over, while the drive stays as it was.
#[test]
fn a_reset_starts_a_fresh_link_and_keeps_the_drive() {
    let mut fixture = FirmwareFixture::new(build(SimDrive::Epos4, false));
    run_to(&mut fixture, 1_000_000);
    assert_eq!(fixture.epos().nmt_state(), NmtState::Operational);
    let phase = |f: &FirmwareFixture| f.with_ecu(|e| e.link().map(|l| l.phase()));
    assert_eq!(
        phase(&fixture),
        Some(Phase::Standby),
        "brought up, unpowered"
    );
    // The status task's frames of this step wait in the transmit queue ...
    let _ = fixture.deliver();
    fixture.poll_tasks();
    fixture.reset_ecu();
    // ... and die with the ECU.
    assert!(fixture.take_tx().is_empty());
    assert_ne!(phase(&fixture), Some(Phase::Standby), "a fresh link");
    assert_eq!(fixture.epos().nmt_state(), NmtState::Operational);
    assert_eq!(fixture.now_us(), 1_000_000, "at the same instant");
    // The fresh link brings the drive up again.
    run_to(&mut fixture, 2_000_000);
    assert_eq!(phase(&fixture), Some(Phase::Standby));
    assert!(fixture.output().faults.is_empty());
}

/// With the watchdog task, its feeds are logged once per feed period while the tasks and the
/// fast loop run; without it, none.
#[test]
fn the_watchdog_task_runs_only_when_asked_and_its_feeds_are_logged() {
    for watchdog in [true, false] {
        let mut fixture = FirmwareFixture::new(build(SimDrive::Direct, watchdog));
        run_to(&mut fixture, 200_000);
        let feeds = fixture.feeds_us();
        if watchdog {
            assert!(feeds.len() >= 15, "{feeds:?}");
            assert!(
                feeds
                    .windows(2)
                    .all(|w| w[1] - w[0] >= u64::from(FEED_PERIOD_US)),
                "{feeds:?}"
            );
        } else {
            assert!(feeds.is_empty(), "{feeds:?}");
        }
    }
}

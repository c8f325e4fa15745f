//! What the link watches once the drive is configured, and how it reacts: the heartbeats
//! both ways (the drive's, which it watches; the ECU's, which it produces for the drive to
//! watch), the SYNC grid, EMCYs, the statusword of each TPDO1, garbage answering its SDO
//! requests, and its best-effort "disable voltage" after a failure.

use super::*;
use crate::canopen::NodeId;

fn node() -> NodeId {
    NodeId::new(1).unwrap()
}

/// A link with power wanted, put in `phase` at 0 with no SDO transfer open (the
/// configuration script is not walked: only what the link does from that phase is checked
/// here).
fn link_in(phase: Phase) -> Epos4Link {
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let _ = link.set_power(true, 0);
    assert!(link.power_wanted());
    link.phase = phase;
    link
}

fn heartbeat(state: NmtState) -> Frame {
    nmt::heartbeat_frame(node(), state).unwrap()
}

/// Once the drive is started, a heartbeat in any state but Operational (pre-operational,
/// stopped, or a boot-up: the drive reset itself) means it no longer runs the PDOs the link
/// relies on: the link fails, naming the state; an Operational heartbeat changes nothing.
#[test]
fn a_started_drive_leaving_operational_fails_the_link() {
    for phase in [
        Phase::Enabling,
        Phase::Cyclic,
        Phase::Disabling,
        Phase::Standby,
    ] {
        let mut link = link_in(phase);
        let _ = link.on_frame(&heartbeat(NmtState::Operational), 1_000);
        assert_eq!(link.phase(), phase);
        assert_eq!(link.error(), None);
        for state in [
            NmtState::PreOperational,
            NmtState::Stopped,
            NmtState::BootUp,
        ] {
            let mut link = link_in(phase);
            let _ = link.on_frame(&heartbeat(state), 1_000);
            assert_eq!(
                link.error(),
                Some(LinkError::NodeLeftOperational { state }),
                "{phase:?} then {state:?}"
            );
        }
    }
}

/// While the NMT start is out, the drive may still announce its own boot-up (it was reset
/// with the ECU): that is no failure, and its Operational heartbeat then starts the enable
/// walk.
#[test]
fn a_boot_up_while_the_start_is_out_is_no_failure() {
    let mut link = link_in(Phase::Starting);
    let _ = link.on_frame(&heartbeat(NmtState::BootUp), 1_000);
    assert_eq!(link.error(), None);
    assert_eq!(link.phase(), Phase::Starting);
    let _ = link.on_frame(&heartbeat(NmtState::Operational), 2_000);
    assert_eq!(link.phase(), Phase::Enabling);
}

/// After a failure nothing confirms a frame, so the link sends one "disable voltage" on the
/// first "off" and none on the calls after it (the ECU asks for off every tick); a new
/// failure after a fault reset sends one again.
#[test]
fn a_failed_link_sends_one_disable_per_failure() {
    let disable = disable_voltage_frame(node()).unwrap();
    let mut link = link_in(Phase::Cyclic);
    let emcy = emcy::Emcy {
        error_code: 0x3210,
        error_register: 0x04,
        vendor: [0; 5],
    };
    let _ = link.on_frame(&emcy.to_frame(node()).unwrap(), 1_000);
    assert!(matches!(
        link.phase(),
        Phase::Failed(LinkError::Emcy { .. })
    ));
    let first = link.set_power(false, 1_000);
    assert_eq!(first.as_slice(), &[disable]);
    for t in [2_000, 3_000, 50_000] {
        assert!(link.set_power(false, t).is_empty(), "at {t} us");
    }
    // Power wanted again, then off: still the same failure, nothing more to send.
    let _ = link.set_power(true, 60_000);
    assert!(link.set_power(false, 61_000).is_empty());

    let _ = link.request_fault_reset(70_000);
    assert_eq!(link.phase(), Phase::Enabling);
    let _ = link.set_power(true, 70_000);
    let _ = link.on_frame(&emcy.to_frame(node()).unwrap(), 80_000);
    let again = link.set_power(false, 80_000);
    assert_eq!(again.as_slice(), &[disable]);
}

/// The ECU's own heartbeat (node 127, every 10 ms by default) goes out on the 10 ms grid
/// whatever the phase; after a stall of the caller one goes out at once and the grid resumes
/// from there, with no burst of the ones missed.
#[test]
fn the_ecu_heartbeat_keeps_its_period_and_resumes_after_a_stall() {
    let ecu = EcuHeartbeat::DEFAULT;
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let ecu_heartbeat = nmt::heartbeat_frame(ecu.node, NmtState::Operational).unwrap();
    let mut sent_at = Vec::new();
    let poll = |link: &mut Epos4Link, t: u64, sent_at: &mut Vec<u64>| {
        let n = link.poll(t).iter().filter(|f| **f == ecu_heartbeat).count();
        sent_at.extend(std::iter::repeat_n(t, n));
    };
    for t in (0..=100_000).step_by(1_000) {
        poll(&mut link, t, &mut sent_at);
    }
    let grid: Vec<u64> = (0..=10).map(|k| k * 10_000).collect();
    assert_eq!(sent_at, grid);
    // Nobody polled from 100 to 155 ms.
    sent_at.clear();
    for t in (155_000..=185_000).step_by(1_000) {
        poll(&mut link, t, &mut sent_at);
    }
    assert_eq!(sent_at, [155_000, 165_000, 175_000, 185_000]);
}

/// A started drive whose heartbeat stops for longer than the heartbeat timeout (100 ms)
/// fails the link, the timeout itself allowed; a heartbeat resets the count.
#[test]
fn a_silent_started_drive_fails_the_link_after_the_heartbeat_timeout() {
    let mut link = link_in(Phase::Cyclic);
    let _ = link.on_frame(&heartbeat(NmtState::Operational), 50_000);
    let _ = link.poll(150_000);
    assert_eq!(link.error(), None);
    let _ = link.poll(150_001);
    assert_eq!(
        link.error(),
        Some(LinkError::HeartbeatLost { silent_us: 100_001 })
    );
}

/// While the NMT start is out, a drive that has not spoken yet is not failed for its
/// silence: the start is sent again once more than a heartbeat timeout has passed since the
/// last one, three times in all, then the link
/// fails with NodeDidNotStart. A drive that has spoken (a pre-operational heartbeat) and
/// falls silent is a lost heartbeat.
#[test]
fn a_drive_silent_from_the_start_gets_three_starts_and_one_that_spoke_is_watched() {
    let start = nmt::command_frame(NmtCommand::Start, NmtTarget::Node(node())).unwrap();
    let mut link = link_in(Phase::Starting);
    // The first start went out at 0: exactly one heartbeat timeout later it is not due yet.
    assert!(!link.poll(100_000).contains(&start));
    for attempt in 1..=3u64 {
        let t = attempt * 100_001;
        let out = link.poll(t);
        assert_eq!(link.error(), None, "attempt {attempt}");
        assert!(out.contains(&start), "attempt {attempt}: {out:?}");
    }
    let _ = link.poll(4 * 100_001);
    assert_eq!(
        link.error(),
        Some(LinkError::NodeDidNotStart { attempts: 3 })
    );

    let mut link = link_in(Phase::Starting);
    let _ = link.on_frame(&heartbeat(NmtState::PreOperational), 10_000);
    assert_eq!(
        link.error(),
        None,
        "not started yet: pre-operational is expected"
    );
    let _ = link.poll(110_001);
    assert_eq!(
        link.error(),
        Some(LinkError::HeartbeatLost { silent_us: 100_001 })
    );
}

/// The SYNC of the cyclic exchange keeps its 10 ms grid; after a stall of the caller one
/// SYNC goes out at once and the grid resumes from there, with no burst of the missed ones.
#[test]
fn the_sync_keeps_its_period_and_resumes_after_a_stall() {
    let sync = nmt::sync_frame().unwrap();
    // Operation enabled, position 0: the drive's answer to each SYNC.
    let tpdo1 = Frame::new(StandardId::new(0x181).unwrap(), &[0x27, 0x00, 0, 0, 0, 0]).unwrap();
    let mut link = link_in(Phase::Cyclic);
    let mut synced_at = Vec::new();
    let times = (0..=20_000)
        .step_by(1_000)
        .chain((55_000..=75_000).step_by(1_000));
    for t in times {
        if link.poll(t).contains(&sync) {
            synced_at.push(t);
            let _ = link.on_frame(&tpdo1, t + 500);
        }
    }
    assert_eq!(link.error(), None);
    assert_eq!(synced_at, [0, 10_000, 20_000, 55_000, 65_000, 75_000]);
}

/// An EMCY "error reset" (code 0, sent when the drive clears a fault) is no failure; an EMCY
/// while the link has already failed keeps the first error, the root cause.
#[test]
fn an_emcy_reset_is_no_failure_and_a_later_emcy_keeps_the_first_error() {
    let emcy = |code: u16| {
        let e = emcy::Emcy {
            error_code: code,
            error_register: if code == 0 { 0 } else { 0x01 },
            vendor: [0; 5],
        };
        e.to_frame(node()).unwrap()
    };
    let mut link = link_in(Phase::Cyclic);
    let _ = link.on_frame(&emcy(0x0000), 1_000);
    assert_eq!(link.error(), None);
    assert_eq!(link.phase(), Phase::Cyclic);
    let _ = link.on_frame(&emcy(0x8611), 2_000);
    let _ = link.on_frame(&emcy(0x3210), 3_000);
    assert_eq!(
        link.error(),
        Some(LinkError::Emcy {
            error_code: 0x8611,
            error_register: 0x01
        })
    );
}

/// TPDO1 with this statusword and position 0.
fn tpdo1(statusword: u16) -> Frame {
    let [lo, hi] = statusword.to_le_bytes();
    Frame::new(StandardId::new(0x181).unwrap(), &[lo, hi, 0, 0, 0, 0]).unwrap()
}

/// Each TPDO1's statusword is watched: the fault bit fails the link with DriveFault in
/// Cyclic, Disabling and Standby (a faulted drive is reported even with the motor free);
/// leaving Operation enabled without a fault fails it with LeftOperationEnabled in Cyclic
/// only (in Disabling and Standby that is where the drive is going or is).
#[test]
fn the_statusword_of_each_tpdo1_is_watched() {
    let fault = 0x0008;
    let switched_on = 0x0023;
    for phase in [Phase::Cyclic, Phase::Disabling, Phase::Standby] {
        let mut link = link_in(phase);
        let _ = link.on_frame(&tpdo1(fault), 1_000);
        assert_eq!(
            link.error(),
            Some(LinkError::DriveFault { statusword: fault }),
            "{phase:?}"
        );
        let mut link = link_in(phase);
        let _ = link.on_frame(&tpdo1(switched_on), 1_000);
        let expected = (phase == Phase::Cyclic).then_some(LinkError::LeftOperationEnabled {
            statusword: switched_on,
        });
        assert_eq!(link.error(), expected, "{phase:?}");
    }
}

/// An answer the link cannot use for its request (here an upload answer to the first
/// download, "disable voltage") is retried like a time-out, within the three attempts: the
/// request goes out again twice, and the third such answer fails the link naming it.
#[test]
fn garbage_answering_a_request_is_retried_within_the_attempt_budget() {
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let first = link.start(0);
    assert_eq!(first.as_slice(), &[disable_voltage_frame(node()).unwrap()]);
    let upload_answer = Frame::new(
        StandardId::new(0x581).unwrap(),
        &[0x4B, 0x40, 0x60, 0x00, 0, 0, 0, 0],
    )
    .unwrap();
    for k in 1..=2u64 {
        let out = link.on_frame(&upload_answer, k * 1_000);
        assert_eq!(out.as_slice(), first.as_slice(), "answer {k}");
        assert_eq!(link.error(), None, "answer {k}");
    }
    let out = link.on_frame(&upload_answer, 3_000);
    assert!(out.is_empty());
    assert_eq!(
        link.error(),
        Some(LinkError::SdoUnexpected {
            object: od::CONTROLWORD,
            command: 0x4B
        })
    );
}

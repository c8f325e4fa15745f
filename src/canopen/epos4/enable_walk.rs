//! The CiA 402 walk to Operation enabled as the drive answers it: a drive found enabled, a
//! drive found faulted with and without a fault reset asked, a quick stop left on the way, a
//! drive whose answers never let the walk advance.

use super::super::sdo::{self, ServerRequest};
use super::*;
use crate::canopen::NodeId;

fn node() -> NodeId {
    NodeId::new(1).unwrap()
}

/// A link with power wanted whose walk has just begun (`reset`: with a fault reset), the
/// statusword read out.
fn walking(reset: bool) -> Epos4Link {
    let mut link = Epos4Link::new(Epos4Config::paper(node()), 0).unwrap();
    let _ = link.set_power(true, 0);
    let mut out = Outbox::new();
    link.enter_enabling(reset, 0, &mut out);
    assert_eq!(
        request_in(&out),
        Some(ServerRequest::Upload {
            object: od::STATUSWORD
        })
    );
    link
}

fn request_in(out: &Outbox) -> Option<ServerRequest> {
    out.iter().find_map(|f| sdo::parse_request(f, node()))
}

/// The controlword the link writes in `out`, if it writes one.
fn controlword_in(out: &Outbox) -> Option<u16> {
    match request_in(out) {
        Some(ServerRequest::Download { object, value, .. }) if object == od::CONTROLWORD => {
            Some(value as u16)
        }
        _ => None,
    }
}

/// The drive answers the statusword read with `statusword`.
fn status(link: &mut Epos4Link, statusword: u16, now_us: u64) -> Outbox {
    let answer =
        sdo::upload_response_frame(node(), od::STATUSWORD, u32::from(statusword), Width::U16)
            .unwrap();
    link.on_frame(&answer, now_us)
}

/// The drive confirms the controlword write.
fn controlword_written(link: &mut Epos4Link, now_us: u64) -> Outbox {
    let answer = sdo::download_response_frame(node(), od::CONTROLWORD).unwrap();
    link.on_frame(&answer, now_us)
}

/// A drive already in Operation enabled when the walk begins (it kept its state through a
/// link restart) is taken back to Switched on first, so the software position limits are
/// written and read back before it is enabled again: never straight to the cyclic exchange.
#[test]
fn a_drive_found_enabled_is_disabled_first_to_write_the_limits() {
    let mut link = walking(false);
    let out = status(&mut link, 0x0027, 1_000);
    assert_eq!(
        controlword_in(&out),
        Some(Command::DisableOperation.controlword())
    );
    assert_eq!(link.phase(), Phase::Enabling);
}

/// A faulted drive with a fault reset asked: "disable voltage", then the fault reset (the
/// rising edge of bit 7), then the statusword again. Without a reset asked it fails the link.
#[test]
fn a_faulted_drive_is_reset_only_when_a_reset_was_asked() {
    let mut link = walking(true);
    let out = status(&mut link, 0x0008, 1_000);
    assert_eq!(
        controlword_in(&out),
        Some(Command::DisableVoltage.controlword())
    );
    let out = controlword_written(&mut link, 2_000);
    assert_eq!(
        controlword_in(&out),
        Some(Command::FaultReset.controlword())
    );
    let out = controlword_written(&mut link, 3_000);
    assert_eq!(
        request_in(&out),
        Some(ServerRequest::Upload {
            object: od::STATUSWORD
        })
    );

    let mut link = walking(false);
    let _ = status(&mut link, 0x0008, 1_000);
    assert_eq!(
        link.error(),
        Some(LinkError::DriveFault { statusword: 0x0008 })
    );
}

/// A "disable voltage" on the way (leaving Quick stop active) is followed by a fresh read of
/// the statusword, not by a fault reset nobody asked for.
#[test]
fn a_disable_voltage_on_the_way_is_followed_by_a_status_read_not_a_fault_reset() {
    let mut link = walking(false);
    let out = status(&mut link, 0x0007, 1_000);
    assert_eq!(
        controlword_in(&out),
        Some(Command::DisableVoltage.controlword())
    );
    let out = controlword_written(&mut link, 2_000);
    assert_eq!(
        request_in(&out),
        Some(ServerRequest::Upload {
            object: od::STATUSWORD
        })
    );
}

/// A drive that keeps answering a statusword no CiA 402 state has is read again, 40 steps in
/// all; the 41st fails the link with Cia402Stuck and the last statusword.
#[test]
fn a_walk_that_does_not_advance_fails_after_40_steps() {
    let garbage = 0x0001;
    assert_eq!(State::from_statusword(garbage), None);
    let mut link = walking(false);
    for k in 1..=40u64 {
        let out = status(&mut link, garbage, k * 1_000);
        assert_eq!(link.error(), None, "step {k}");
        assert_eq!(
            request_in(&out),
            Some(ServerRequest::Upload {
                object: od::STATUSWORD
            }),
            "step {k}"
        );
    }
    let _ = status(&mut link, garbage, 41_000);
    assert_eq!(
        link.error(),
        Some(LinkError::Cia402Stuck {
            statusword: garbage
        })
    );
}

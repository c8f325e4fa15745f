//! Where a new sender's reference counter starts: one above the counter the ECU's E2E check
//! last saw. The ECU puts that counter in every motor frame (0x102, `MOT_RefCounter`), so a
//! `send` or a campaign started after another sender (a second `steer-can` process on `can0`,
//! a second call on a shared simulated car) listens for one before its first frame and
//! continues from it; counting from its own 0 instead, its first frame would be dropped by the
//! ECU as a counter jump. A reference frame on the bus after the ECU's report (another sender
//! still running) is newer, and is taken instead.

use super::decode::Decoded;
use super::{BringupError, Stamped, Transport, pump};
use canlink::reference::ReferenceSender;
use steering_ecu::protocol::{AliveCounter, PERIOD_US};

/// How long a sender listens for the ECU's counter before its first frame, µs: the motor
/// frame comes every status period, so three periods hold one even if a period's frame is
/// lost or held back.
pub const LISTEN_US: u64 = 3 * PERIOD_US as u64;

/// What the listening heard last: where the next reference's counter comes from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LastCounter {
    /// The ECU's motor frame: the counter of the last reference frame it authenticated (0
    /// before the first, when it accepts any).
    Ecu(AliveCounter),
    /// A reference frame of another sender on the bus.
    Bus(AliveCounter),
}

impl LastCounter {
    pub fn counter(self) -> AliveCounter {
        match self {
            LastCounter::Ecu(c) | LastCounter::Bus(c) => c,
        }
    }

    /// Takes what a frame says about the counter, if anything; the newer frame wins.
    pub fn update(last: &mut Option<LastCounter>, decoded: &Decoded) {
        match decoded {
            Decoded::Motor(Ok(m)) => *last = Some(LastCounter::Ecu(m.reference_counter)),
            Decoded::Reference(Ok(r)) => *last = Some(LastCounter::Bus(r.counter)),
            _ => {}
        }
    }

    /// The line on stderr that says where the counter continues from.
    pub fn words(self) -> String {
        let c = self.counter().raw();
        let next = self.counter().next().raw();
        match self {
            LastCounter::Ecu(_) => format!(
                "reference counter: continuing after {c}, the last the ECU saw (motor frame \
                 0x102), from {next}"
            ),
            LastCounter::Bus(_) => format!(
                "reference counter: continuing after {c}, the last reference frame on the bus, \
                 from {next}"
            ),
        }
    }
}

/// Listens up to [`LISTEN_US`] for the ECU's motor frame, handing every frame to `on_frame`
/// (which decodes it, a [`super::monitor::Monitor`] or the caller's own decoder). `None`
/// when neither a motor frame nor a reference frame came.
pub fn listen(
    transport: &mut dyn Transport,
    mut on_frame: impl FnMut(&Stamped) -> Decoded,
) -> Result<Option<LastCounter>, BringupError> {
    let deadline = transport.now_us().saturating_add(LISTEN_US);
    let mut last = None;
    pump(transport, deadline, |rx| {
        let decoded = on_frame(rx);
        LastCounter::update(&mut last, &decoded);
        !matches!(last, Some(LastCounter::Ecu(_)))
    })?;
    Ok(last)
}

/// What a sender says when nothing told it the counter: it counts on from its own, `next`.
pub fn not_heard_warning(next: AliveCounter) -> String {
    format!(
        "steer-can: warning: no motor frame (0x102) from the ECU within {} ms, so the \
         reference counter the ECU last saw is unknown: counting from {} (the ECU drops the \
         first frame as a counter jump if another sender came before)",
        LISTEN_US / 1000,
        next.raw()
    )
}

/// Sets `sender` to continue after what was heard, and says so on stderr; without anything
/// heard, warns and leaves the sender's own count.
pub fn continue_sender(sender: &mut ReferenceSender, heard: Option<LastCounter>) {
    match heard {
        Some(last) => {
            sender.continue_after(last.counter());
            eprintln!("{}", last.words());
        }
        None => eprintln!("{}", not_heard_warning(sender.last().next())),
    }
}

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

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;
    use crate::decode::Decoder;
    use crate::{Clock, LinkError};
    use std::collections::VecDeque;
    use steering_ecu::as_state::AsState;
    use steering_ecu::can::Frame;
    use steering_ecu::canopen::NodeId;
    use steering_ecu::canopen::epos4::PositionScale;
    use steering_ecu::protocol::{MotorStatus, ProtocolConfig, Reference};
    use steering_ecu::units::{Amps, MotorRad, SteeringDeg};

    /// A bus that delivers `frames` (time, frame) and otherwise stays silent.
    struct Bus {
        now_us: u64,
        frames: VecDeque<Stamped>,
    }

    impl Clock for Bus {
        fn now_us(&self) -> u64 {
            self.now_us
        }
    }

    impl Transport for Bus {
        fn send(&mut self, _: &Frame) -> Result<(), LinkError> {
            Ok(())
        }
        fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
            match self.frames.front() {
                Some(f) if f.t_us <= deadline_us => {
                    self.now_us = f.t_us;
                    Ok(self.frames.pop_front())
                }
                _ => {
                    self.now_us = self.now_us.max(deadline_us);
                    Ok(None)
                }
            }
        }
        fn name(&self) -> &str {
            "test"
        }
        fn epoch_s(&self) -> f64 {
            0.0
        }
    }

    fn decoder() -> Decoder {
        Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(4096).unwrap())
    }

    fn motor(t_us: u64, reference_counter: u8) -> Stamped {
        Stamped {
            t_us,
            frame: ProtocolConfig::DEFAULT.encode_motor(&MotorStatus {
                angle: MotorRad(0.0),
                current_mean: Amps(0.0),
                counter: AliveCounter::wrapping(0),
                reference_counter: AliveCounter::wrapping(reference_counter),
            }),
        }
    }

    fn reference(t_us: u64, counter: u8) -> Stamped {
        Stamped {
            t_us,
            frame: ProtocolConfig::DEFAULT.encode_reference(&Reference {
                angle: SteeringDeg(0.0),
                as_state: AsState::Off,
                counter: AliveCounter::wrapping(counter),
                clear_faults: false,
            }),
        }
    }

    /// A silent bus: the sender listens the whole bound, hears nothing, and keeps its own
    /// count (the first frame carries 1, as before).
    #[test]
    fn nothing_heard_leaves_the_senders_own_count_after_the_bound() {
        let mut bus = Bus {
            now_us: 5_000,
            frames: VecDeque::new(),
        };
        let dec = decoder();
        assert_eq!(listen(&mut bus, |rx| dec.decode(&rx.frame)).unwrap(), None);
        assert_eq!(bus.now_us, 5_000 + LISTEN_US);
        let mut sender = ReferenceSender::default();
        continue_sender(&mut sender, None);
        let first = sender.frame(0.0, AsState::Off, false);
        let r = ProtocolConfig::DEFAULT.decode_reference(&first).unwrap();
        assert_eq!(r.counter.raw(), 1);
        assert!(not_heard_warning(AliveCounter::wrapping(1)).contains("counting from 1"));
    }

    /// The ECU's motor frame ends the listening at once; a reference frame before it (another
    /// sender) is older than the ECU's word and gives way to it.
    #[test]
    fn the_ecus_motor_frame_ends_the_listening_and_sets_the_count() {
        let mut bus = Bus {
            now_us: 0,
            frames: [reference(1_000, 4), motor(3_000, 9), motor(13_000, 2)].into(),
        };
        let dec = decoder();
        let heard = listen(&mut bus, |rx| dec.decode(&rx.frame)).unwrap();
        assert_eq!(heard, Some(LastCounter::Ecu(AliveCounter::wrapping(9))));
        assert_eq!(bus.now_us, 3_000, "stopped at the motor frame");
        let mut sender = ReferenceSender::default();
        continue_sender(&mut sender, heard);
        let first = sender.frame(0.0, AsState::Off, false);
        let r = ProtocolConfig::DEFAULT.decode_reference(&first).unwrap();
        assert_eq!(r.counter.raw(), 10);
    }

    /// Only another sender's frame came: the sender continues after it.
    #[test]
    fn a_reference_frame_alone_sets_the_count() {
        let mut bus = Bus {
            now_us: 0,
            frames: [reference(1_000, 15)].into(),
        };
        let dec = decoder();
        let heard = listen(&mut bus, |rx| dec.decode(&rx.frame)).unwrap();
        assert_eq!(heard, Some(LastCounter::Bus(AliveCounter::wrapping(15))));
        assert_eq!(heard.unwrap().counter().next().raw(), 0, "wraps");
        assert!(heard.unwrap().words().contains("from 0"));
    }
}

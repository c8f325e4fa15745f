//! The firmware's tasks, written against the [`crate::ports`] traits and embassy's time and
//! channels, so the STM32 and host-sim run the same code. A task reads a port, calls a pure
//! `step` of the core, writes a port.

use crate::can::Frame;
use crate::ecu::Ecu;
use crate::ports::{BusError, CanRx, ColumnEncoderPort, EncoderError};
use crate::sensors::ColumnEncoder;
use crate::units::SteeringDeg;
use core::cell::RefCell;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::channel::{Channel, Receiver, Sender};
use embassy_time::{Duration, Instant, Ticker, with_deadline, with_timeout};

/// The ECU state shared by the tasks and the fast-loop interrupts: each takes the lock for one
/// pure method call, so the longest hold is one state-machine step.
pub type SharedEcu = Mutex<CriticalSectionRawMutex, RefCell<Ecu>>;

/// Reference period, and the status frame's period (protocol::PERIOD_US).
pub const REFERENCE_PERIOD: Duration = Duration::from_millis(10);
/// The state machine is ticked at least this often when no frame comes, so a timeout is
/// seen within 2 ms of its deadline.
pub const TICK_PERIOD: Duration = Duration::from_millis(2);
/// Column encoder sampling period (500 Hz).
pub const ENCODER_PERIOD: Duration = Duration::from_millis(2);

/// Default identifier of the vehicle computer's reference frame (see the DBC).
pub const VEHICLE_REFERENCE_ID: u16 = 0x100;

/// Frames waiting for one consumer; 8 covers the 2.5 frames per reference period the vehicle
/// and the EPOS4 send to each consumer with room for a late task.
pub const QUEUE_DEPTH: usize = 8;

pub type FrameQueue = Channel<CriticalSectionRawMutex, Frame, QUEUE_DEPTH>;
pub type FrameSender<'a> = Sender<'a, CriticalSectionRawMutex, Frame, QUEUE_DEPTH>;
pub type FrameReceiver<'a> = Receiver<'a, CriticalSectionRawMutex, Frame, QUEUE_DEPTH>;

fn now_us() -> u64 {
    Instant::now().as_micros()
}

/// The 100 Hz reference receiver: every frame through the E2E check into the state machine;
/// without frames the state machine is still ticked, so the 30 ms timeout is seen on time.
pub async fn reference_task(frames: FrameReceiver<'_>, ecu: &SharedEcu) -> ! {
    loop {
        let received = with_timeout(TICK_PERIOD, frames.receive()).await;
        let now = now_us();
        ecu.lock(|e| {
            let mut e = e.borrow_mut();
            let _ = match received {
                Ok(frame) => e.on_reference_frame(now, &frame),
                Err(_) => e.tick(now),
            };
        });
    }
}

/// The diagnostic page goes out only while at least this many transmit slots are free, so it
/// never takes the room the EPOS4 link's SYNC, RPDO or disable needs in the same period.
pub const DIAGNOSTIC_FREE_SLOTS: usize = QUEUE_DEPTH / 2;

/// The 100 Hz status sender: the status frame, then the motor frame, then one page of the
/// diagnostic frame (0x103, [`Ecu::diagnostic_frame`]), so a reader has every counter and
/// every fault record within 22 periods (220 ms) without asking: a request frame would be
/// one more input to check, and a logger started after the fault still sees it. A full transmit
/// queue drops this period's frame (the counter shows the gap to the vehicle computer) rather
/// than delaying the next one; the diagnostic page, the least urgent, waits for a period with
/// [`DIAGNOSTIC_FREE_SLOTS`] free (its page is not used up, so no page is skipped).
pub async fn status_task(tx: FrameSender<'_>, ecu: &SharedEcu) -> ! {
    let mut ticker = Ticker::every(REFERENCE_PERIOD);
    loop {
        ticker.next().await;
        let frame = ecu.lock(|e| e.borrow_mut().status_frame());
        let _ = tx.try_send(frame);
        let motor = ecu.lock(|e| e.borrow_mut().motor_frame());
        let _ = tx.try_send(motor);
        if tx.free_capacity() >= DIAGNOSTIC_FREE_SLOTS {
            let diagnostic = ecu.lock(|e| e.borrow_mut().diagnostic_frame(now_us()));
            let _ = tx.try_send(diagnostic);
        }
    }
}

/// The column-encoder reader: every sample to the plausibility checks of the state machine.
pub async fn encoder_task(
    port: &mut impl ColumnEncoderPort,
    zero: ColumnEncoder,
    ecu: &SharedEcu,
) -> ! {
    let mut ticker = Ticker::every(ENCODER_PERIOD);
    loop {
        ticker.next().await;
        let reading = port.read().await;
        let now = now_us();
        ecu.lock(|e| {
            let mut e = e.borrow_mut();
            let _ = match reading {
                Ok(raw) => e.on_encoder(now, SteeringDeg::from(zero.angle(raw))),
                Err(EncoderError::NoResponse) => e.on_encoder_error(now, 1),
                Err(EncoderError::InvalidReading) => e.on_encoder_error(now, 2),
            };
        });
    }
}

/// How often the drive task polls the EPOS4 link: the bound on SYNC jitter and on the time a
/// disable waits before it goes on the bus.
pub const DRIVE_POLL_PERIOD: Duration = Duration::from_millis(1);

/// The EPOS4 link (EPOS4 mode): the drive's frames in, SYNC, RPDO and SDO requests out, and
/// the link polled every [`DRIVE_POLL_PERIOD`] even while frames keep coming. A full transmit
/// queue drops the frame rather than stalling the link; the link's SDO retries and TPDO
/// supervision notice a lost one. In direct mode the ECU returns no frames and the task only
/// idles.
pub async fn drive_task(frames: FrameReceiver<'_>, tx: FrameSender<'_>, ecu: &SharedEcu) -> ! {
    let start = ecu.lock(|e| e.borrow_mut().drive_start(now_us()));
    for f in start {
        let _ = tx.try_send(f);
    }
    let mut next_poll = Instant::now();
    loop {
        let received = with_deadline(next_poll, frames.receive()).await;
        let now = Instant::now();
        let out = ecu.lock(|e| {
            let mut e = e.borrow_mut();
            let mut out: heapless::Vec<Frame, 16> = heapless::Vec::new();
            // 16 holds both calls' frames (8 each at most); `extend_from_slice` refuses
            // rather than panics.
            if let Ok(frame) = received {
                let _ = out.extend_from_slice(&e.on_drive_frame(now.as_micros(), &frame));
            }
            if now >= next_poll {
                let _ = out.extend_from_slice(&e.drive_poll(now.as_micros()));
            }
            out
        });
        if now >= next_poll {
            // `Instant + Duration` panics past u64 microseconds; saturate instead.
            next_poll = next_poll.saturating_add(DRIVE_POLL_PERIOD);
            if next_poll <= now {
                next_poll = now.saturating_add(DRIVE_POLL_PERIOD);
            }
        }
        for f in out {
            let _ = tx.try_send(f);
        }
    }
}

/// How often [`watchdog_task`] asks the feed gate ([`crate::watchdog::FEED_PERIOD_US`]).
pub const WATCHDOG_FEED_PERIOD: Duration =
    Duration::from_micros(crate::watchdog::FEED_PERIOD_US as u64);

/// The watchdog feeder: every [`WATCHDOG_FEED_PERIOD`] it reads the ECU's progress counts and
/// calls `feed` (the firmware: `IndependentWatchdog::pet`) only when the feed gate says both
/// the supervisor tasks and the fast loop ran since the last feed. It runs on the supervisor's
/// executor, so a stalled executor stops the feeding too.
pub async fn watchdog_task(ecu: &SharedEcu, mut feed: impl FnMut()) -> ! {
    let mut gate = crate::watchdog::FeedGate::new();
    let mut ticker = Ticker::every(WATCHDOG_FEED_PERIOD);
    loop {
        ticker.next().await;
        let progress = ecu.lock(|e| e.borrow().progress());
        if gate.check(progress) {
            feed();
        }
    }
}

/// Which consumer a received frame belongs to.
pub trait Route {
    /// `Some(i)` for the i-th consumer, `None` to drop the frame (not ours).
    fn route(&self, frame: &Frame) -> Option<usize>;
}

/// The firmware's routing (`main.rs`), kept here so the simulated car routes as the chip does:
/// the vehicle's reference to consumer 0 (the reference task), the EPOS4's EMCY (0x081..),
/// TPDOs (0x181..0x4FF), SDO answers (0x581..) and heartbeat (0x701..) to consumer 1 (the drive
/// link).
#[derive(Debug, Clone, Copy)]
pub struct FirmwareRoutes;

impl Route for FirmwareRoutes {
    fn route(&self, frame: &Frame) -> Option<usize> {
        match frame.id().raw() {
            VEHICLE_REFERENCE_ID => Some(0),
            0x081..=0x0FF | 0x181..=0x4FF | 0x581..=0x5FF | 0x701..=0x77F => Some(1),
            _ => None,
        }
    }
}

/// What the router saw that the state machine must know.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct RouterCounters {
    pub routed: u32,
    pub unrouted: u32,
    /// A consumer's queue was full: the frame was dropped (counted, never blocks the bus).
    pub queue_full: u32,
    pub bus_errors: u32,
}

/// Receive frames forever and hand each to its consumer's queue. A full queue drops the frame
/// (the consumer's own checks notice the gap) rather than stalling reception for everyone.
/// Returns only when the controller reports bus-off, so the caller latches that fault.
pub async fn route_frames<R: Route>(
    rx: &mut impl CanRx,
    routes: &R,
    queues: &[FrameSender<'_>],
    counters: &mut RouterCounters,
) -> BusError {
    loop {
        match rx.receive().await {
            Ok(frame) => match routes.route(&frame).and_then(|i| queues.get(i)) {
                Some(queue) => {
                    if queue.try_send(frame).is_ok() {
                        counters.routed = counters.routed.saturating_add(1);
                    } else {
                        counters.queue_full = counters.queue_full.saturating_add(1);
                    }
                }
                None => counters.unrouted = counters.unrouted.saturating_add(1),
            },
            Err(BusError::BusOff) => return BusError::BusOff,
            Err(_) => counters.bus_errors = counters.bus_errors.saturating_add(1),
        }
    }
}

/// The receive side of the bus: [`route_frames`] until the controller reports bus-off, then
/// the bus-off fault into the state machine (`tec`: the transmit error counter, if the
/// caller's peripheral gives one). Returns so the caller can keep the bus down.
pub async fn receive_task<R: Route>(
    rx: &mut impl CanRx,
    routes: &R,
    queues: &[FrameSender<'_>],
    counters: &mut RouterCounters,
    ecu: &SharedEcu,
    tec: impl FnOnce() -> u8,
) -> BusError {
    let end = route_frames(rx, routes, queues, counters).await;
    let now = now_us();
    let tec = tec();
    ecu.lock(|e| {
        let _ = e.borrow_mut().on_bus_off(now, tec);
    });
    end
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::StandardId;

    struct Script(std::vec::IntoIter<Result<Frame, BusError>>);
    impl CanRx for Script {
        async fn receive(&mut self) -> Result<Frame, BusError> {
            self.0.next().unwrap_or(Err(BusError::BusOff))
        }
    }

    struct ById;
    impl Route for ById {
        fn route(&self, frame: &Frame) -> Option<usize> {
            match frame.id().raw() {
                0x100 => Some(0),
                0x181..=0x1FF | 0x701..=0x77F => Some(1),
                _ => None,
            }
        }
    }

    fn frame(id: u16) -> Frame {
        Frame::new(StandardId::new(id).unwrap(), &[id as u8]).unwrap()
    }

    #[test]
    fn frames_go_to_their_consumer_and_bus_off_ends_routing() {
        let reference = FrameQueue::new();
        let drive = FrameQueue::new();
        let mut rx = Script(
            vec![
                Ok(frame(0x100)),
                Ok(frame(0x181)),
                Err(BusError::Overrun),
                Ok(frame(0x555)),
                Ok(frame(0x701)),
            ]
            .into_iter(),
        );
        let mut counters = RouterCounters::default();
        let end = embassy_futures::block_on(route_frames(
            &mut rx,
            &ById,
            &[reference.sender(), drive.sender()],
            &mut counters,
        ));
        assert_eq!(end, BusError::BusOff);
        assert_eq!(reference.try_receive().map(|f| f.id().raw()), Ok(0x100));
        assert_eq!(drive.try_receive().map(|f| f.id().raw()), Ok(0x181));
        assert_eq!(drive.try_receive().map(|f| f.id().raw()), Ok(0x701));
        assert_eq!(counters.routed, 3);
        assert_eq!(counters.unrouted, 1);
        assert_eq!(counters.bus_errors, 1);
    }

    #[test]
    fn a_full_queue_drops_and_counts_instead_of_blocking() {
        let reference = FrameQueue::new();
        let frames: Vec<_> = (0..QUEUE_DEPTH + 3).map(|_| Ok(frame(0x100))).collect();
        let mut rx = Script(frames.into_iter());
        let mut counters = RouterCounters::default();
        embassy_futures::block_on(route_frames(
            &mut rx,
            &ById,
            &[reference.sender()],
            &mut counters,
        ));
        assert_eq!(counters.routed as usize, QUEUE_DEPTH);
        assert_eq!(counters.queue_full, 3);
    }
}

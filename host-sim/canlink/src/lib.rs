//! canlink: how a host node sits on the ECU's CAN bus, shared by the simulated car (host-sim)
//! and the bring-up tool (steer-can) without either depending on the other.
//!
//! - [`Transport`] (with its [`Clock`]): send a frame, receive until a deadline. The tool is
//!   written against it alone; SocketCAN on the car, the simulated car in the tests.
//! - [`canbus`]: the in-memory bus the simulated car's nodes share, with faults on purpose.
//! - [`reference`](mod@reference): the vehicle side's reference frames (counter, CRC, AS state), sent by the
//!   tool on the car and by the simulated vehicle computer alike.
//!
//! Nothing here does numerics, so the laptop build of steer-can stays small.

pub mod canbus;
pub mod reference;

use std::fmt;
use steering_ecu::can::Frame;

/// A frame with the time it was seen (received, or sent by this node), µs on the transport's
/// clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Stamped {
    pub t_us: u64,
    pub frame: Frame,
}

/// Where time comes from: wall clock on the car, virtual time in the simulation.
pub trait Clock {
    /// Monotonic time, µs, from an arbitrary origin.
    fn now_us(&self) -> u64;
}

/// One CAN interface, blocking.
pub trait Transport: Clock {
    /// Put one frame on the bus.
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError>;
    /// The next received frame, or `None` once `deadline_us` has passed without one. A
    /// deadline in the past still returns frames already waiting.
    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError>;
    /// Interface name for messages ("can0", "sim").
    fn name(&self) -> &str;
    /// Wall-clock time of `now_us() == 0`, s since the Unix epoch, for candump timestamps.
    fn epoch_s(&self) -> f64;
}

/// Why a transport could not open, send or receive; each names what to check.
#[derive(Debug)]
pub enum LinkError {
    /// The CAN interface does not exist or is down (or the simulated car is not there).
    NoInterface { iface: String, detail: String },
    /// A read or write on the interface failed.
    Io {
        context: String,
        source: std::io::Error,
    },
}

impl fmt::Display for LinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            LinkError::NoInterface { iface, detail } => write!(
                f,
                "{iface}: no such interface, or it is down ({detail}) — bring it up with \
                 `sudo ip link set {iface} up type can bitrate 1000000`"
            ),
            LinkError::Io { context, source } => write!(f, "{context}: {source}"),
        }
    }
}

impl std::error::Error for LinkError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            LinkError::Io { source, .. } => Some(source),
            LinkError::NoInterface { .. } => None,
        }
    }
}

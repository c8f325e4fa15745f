//! `steer-can`, the CAN bring-up tool: what a team runs on a laptop with a USB-CAN adapter the
//! first day the ECU is on the car. It speaks the ECU's vehicle protocol (`src/protocol`, the
//! DBC) and CANopen towards the EPOS4, drives the test campaign and records logs in the
//! project's log format, ready for `host-sim gap`.
//!
//! Theory of operation:
//!
//! ```text
//!   steer-can <command> --iface can0|sim|sim:PATH
//!        |
//!        v
//!   Transport (send a frame, receive until a deadline, now_us)   <- the only I/O, `canlink`
//!        |-- SocketCan (Linux, wall clock; thin)                  `socketcan.rs`
//!        |-- SimEcu (the firmware's tasks + plant + EPOS4 sim,     `host_sim::sim_ecu`
//!        |           in-memory bus, virtual time; WallPaced holds it to the wall clock)
//!        '-- SimSocket (a SimEcu that `sim-car` serves to many calls) `simsock.rs`
//!   decode   frame -> Decoded (reference, status, motor, EPOS4 PDO/SDO/EMCY/heartbeat, NMT)
//!   monitor  Decoded stream -> counters, CRC errors, counter gaps, last values
//!   profile  step / sine / sweep / track samples at 100 Hz, limited to the ECU's 400 deg/s
//!   resume   before a sender's first frame: the reference counter the ECU last saw (0x102)
//!   campaign ready check -> confirmation -> lead-in -> profile -> settle -> AS Off;
//!            aborts on a fault bit, an EMCY, a silent ECU or Ctrl-C, always ending in AS Off
//!   record   every frame with its time -> candump `-l` file        `candump.rs`
//!   logbuild reference + status + motor frames -> log rows (t, ref_sw_deg, sw_deg, ...)
//!   rehearse the README's first-day list, read from the README, on one SimEcu   `rehearse.rs`
//! ```
//!
//! Every command takes its time from the transport, so a campaign against the simulated ECU
//! runs in virtual time (held to the wall clock unless `--fast`), and one on the car in
//! wall-clock time.
//!
//! The simulated car (`--iface sim`, `sim-car`, `rehearse`) is host-sim's, behind the default
//! feature `sim`; without it (`--no-default-features`, the laptop on the car) the tool builds
//! without the simulator's numerics and says so when asked for the simulated car.

pub mod args;
pub mod bounds;
pub mod campaign;
pub mod candump;
pub mod cli;
pub mod commands;
pub mod decode;
pub mod epos;
pub mod liveplot;
pub mod logbuild;
pub mod monitor;
pub mod profile;
#[cfg(feature = "sim")]
pub mod rehearse;
pub mod resume;
pub mod simcar;
#[cfg(all(unix, feature = "sim"))]
pub mod simsock;
#[cfg(target_os = "linux")]
pub mod socketcan;

pub use canlink::{Clock, LinkError, Stamped, Transport};
use std::fmt;
use std::path::PathBuf;
use steering_ecu::can::Frame;

/// Everything the tool reports as an error; each names what to check.
#[derive(Debug)]
pub enum BringupError {
    /// The CAN interface is missing or down, or a send or receive on it failed.
    Link(LinkError),
    /// A read or write on a file failed.
    Io {
        context: String,
        source: std::io::Error,
    },
    /// No status frame within `waited_ms`.
    EcuSilent { waited_ms: u64 },
    /// The ECU is there but not ready for a campaign.
    EcuNotReady { reason: String },
    /// A candump line that is not `(seconds) iface id#data`.
    Candump {
        path: PathBuf,
        line: usize,
        message: String,
    },
    /// A profile that cannot be sent (range, empty, bad file).
    Profile { reason: String },
    /// The EPOS4 did not answer or refused an SDO read.
    Epos { reason: String },
    /// The log could not be built or written.
    Log { reason: String },
    /// The operator said no at the confirmation prompt.
    NotConfirmed,
    /// A command line the tool cannot act on (an option that does not fit, a bad value).
    Usage { reason: String },
    /// The simulated car was asked for (`asked`: `--iface sim`, `rehearse`, `sim-car`) in a
    /// build without it (`--no-default-features`).
    NoSimCar { asked: String },
}

impl fmt::Display for BringupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            BringupError::Link(e) => write!(f, "{e}"),
            BringupError::Io { context, source } => write!(f, "{context}: {source}"),
            BringupError::EcuSilent { waited_ms } => write!(
                f,
                "no status frame from the ECU (0x101) within {:.1} s — is it powered, is the bit \
                 rate 1 Mbit/s?",
                *waited_ms as f64 / 1000.0
            ),
            BringupError::EcuNotReady { reason } => write!(f, "the ECU is not ready: {reason}"),
            BringupError::Candump {
                path,
                line,
                message,
            } => write!(f, "{}:{line}: {message}", path.display()),
            BringupError::Profile { reason } => write!(f, "profile: {reason}"),
            BringupError::Epos { reason } => write!(f, "EPOS4: {reason}"),
            BringupError::Log { reason } => write!(f, "log: {reason}"),
            BringupError::Usage { reason } => write!(f, "{reason}"),
            BringupError::NoSimCar { asked } => write!(
                f,
                "{asked}: this steer-can was built without the simulated car (no `sim` \
                 feature); a build with it: `cargo install --path host-sim/steer-can` or \
                 `cargo run -p steer-can -- ...` (the default features)"
            ),
            BringupError::NotConfirmed => write!(
                f,
                "not confirmed; nothing was sent (answer `yes`, or pass --yes in a script)"
            ),
        }
    }
}

impl std::error::Error for BringupError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            BringupError::Io { source, .. } => Some(source),
            BringupError::Link(e) => e.source(),
            _ => None,
        }
    }
}

impl From<LinkError> for BringupError {
    fn from(e: LinkError) -> Self {
        BringupError::Link(e)
    }
}

/// Receive until `deadline_us`, handing each frame to `on_frame`; stops early when it returns
/// `false`. Returns whether it was stopped early.
pub fn pump(
    transport: &mut dyn Transport,
    deadline_us: u64,
    mut on_frame: impl FnMut(&Stamped) -> bool,
) -> Result<bool, BringupError> {
    while let Some(rx) = transport.recv_until(deadline_us)? {
        if !on_frame(&rx) {
            return Ok(true);
        }
    }
    Ok(false)
}

/// A simulated transport held to the wall clock: its virtual time never runs more than
/// [`WallPaced::LEAD_US`] ahead of the time since it was opened, so `steer-can --iface sim`
/// behaves like the car in time (a `record` or `monitor` without `--duration-s` runs for as
/// long as it is left running, not as fast as the CPU allows). `--fast` leaves it out.
#[derive(Debug)]
pub struct WallPaced<T> {
    inner: T,
    opened: std::time::Instant,
}

impl<T: Transport> WallPaced<T> {
    /// How far virtual time may run ahead of the wall clock: one status period, so frames come
    /// out in 10 ms bursts at most.
    pub const LEAD_US: u64 = 10_000;

    pub fn new(inner: T) -> Self {
        WallPaced {
            inner,
            opened: std::time::Instant::now(),
        }
    }

    /// The paced transport itself (to script the simulated car between commands).
    pub fn inner_mut(&mut self) -> &mut T {
        &mut self.inner
    }

    fn wall_us(&self) -> u64 {
        u64::try_from(self.opened.elapsed().as_micros()).unwrap_or(u64::MAX)
    }
}

impl<T: Transport> Clock for WallPaced<T> {
    fn now_us(&self) -> u64 {
        self.inner.now_us()
    }
}

impl<T: Transport> Transport for WallPaced<T> {
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError> {
        self.inner.send(frame)
    }

    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
        loop {
            let horizon = self.wall_us().saturating_add(Self::LEAD_US);
            if let Some(rx) = self.inner.recv_until(deadline_us.min(horizon))? {
                return Ok(Some(rx));
            }
            let now = self.inner.now_us();
            if now >= deadline_us {
                return Ok(None);
            }
            // Ahead of the wall clock: wait for it, in steps short enough for Ctrl-C.
            let ahead = now.saturating_sub(self.wall_us());
            std::thread::sleep(std::time::Duration::from_micros(ahead.clamp(100, 20_000)));
        }
    }

    fn name(&self) -> &str {
        self.inner.name()
    }

    fn epoch_s(&self) -> f64 {
        self.inner.epoch_s()
    }
}

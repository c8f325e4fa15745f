//! The car's bus through Linux SocketCAN (a USB-CAN adapter as `can0`): the thin edge of the
//! tool. Wall-clock time since the socket was opened; classic 11-bit data frames only (others
//! are not this bus's protocol and are skipped).

use super::{Clock, LinkError, Stamped, Transport};
use socketcan::{CanFrame, CanSocket, EmbeddedFrame, Id, Socket, StandardId as ScStandardId};
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};
use steering_ecu::can::{Frame, StandardId};

/// An open SocketCAN interface.
#[derive(Debug)]
pub struct SocketCan {
    socket: CanSocket,
    iface: String,
    opened: Instant,
    epoch_s: f64,
}

impl SocketCan {
    /// Opens `iface`; a missing or down interface names the command that brings it up.
    pub fn open(iface: &str) -> Result<SocketCan, LinkError> {
        let socket = CanSocket::open(iface).map_err(|e| LinkError::NoInterface {
            iface: iface.to_string(),
            detail: e.to_string(),
        })?;
        let epoch_s = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .map(|d| d.as_secs_f64())
            .unwrap_or(0.0);
        Ok(SocketCan {
            socket,
            iface: iface.to_string(),
            opened: Instant::now(),
            epoch_s,
        })
    }

    fn io(&self, what: &str, source: std::io::Error) -> LinkError {
        if source.kind() == std::io::ErrorKind::NetworkDown {
            return LinkError::NoInterface {
                iface: self.iface.clone(),
                detail: source.to_string(),
            };
        }
        LinkError::Io {
            context: format!("{}: {what}", self.iface),
            source,
        }
    }
}

impl Clock for SocketCan {
    fn now_us(&self) -> u64 {
        self.opened.elapsed().as_micros() as u64
    }
}

impl Transport for SocketCan {
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError> {
        let id = ScStandardId::new(frame.id().raw()).ok_or_else(|| LinkError::Io {
            context: format!("{}: send", self.iface),
            source: std::io::Error::other("identifier above 0x7FF"),
        })?;
        let out = CanFrame::new(id, frame.data()).ok_or_else(|| LinkError::Io {
            context: format!("{}: send", self.iface),
            source: std::io::Error::other("more than 8 data bytes"),
        })?;
        self.socket.write_frame(&out).map_err(|e| {
            self.io(
                "send failed (is the bus terminated, is anyone acknowledging?)",
                e,
            )
        })
    }

    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
        loop {
            let now = self.now_us();
            // Frames already waiting are taken even past the deadline.
            let wait = Duration::from_micros(deadline_us.saturating_sub(now).max(1));
            match self.socket.read_frame_timeout(wait) {
                Ok(CanFrame::Data(f)) => {
                    let t_us = self.now_us();
                    let Id::Standard(id) = f.id() else { continue };
                    let Some(frame) =
                        StandardId::new(id.as_raw()).and_then(|id| Frame::new(id, f.data()))
                    else {
                        continue;
                    };
                    return Ok(Some(Stamped { t_us, frame }));
                }
                Ok(_) => continue, // remote and error frames: not this protocol
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                    ) =>
                {
                    if self.now_us() >= deadline_us {
                        return Ok(None);
                    }
                }
                Err(e) => return Err(self.io("receive failed", e)),
            }
        }
    }

    fn name(&self) -> &str {
        &self.iface
    }

    fn epoch_s(&self) -> f64 {
        self.epoch_s
    }
}

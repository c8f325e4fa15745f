//! Expedited SDO client (CiA 301 7.2.4): upload and download of objects up to 4 bytes, the
//! abort codes by name, and a one-transfer-at-a-time client with time-outs.
//!
//! Every object this ECU touches on the EPOS4 is at most 32 bit, so segmented and block
//! transfers are not implemented; a server answering with one is reported as
//! [`SdoResponse::Unsupported`] rather than misread.
//!
//! Theory of operation of [`SdoClient`]:
//!
//! ```text
//!            start(req) -> request frame
//!   Idle ---------------------------------> Waiting(req, sent_at)
//!    ^                                         |  on_frame(matching response) -> Done/Aborted
//!    +-----------------------------------------+  poll(now > sent_at + timeout) -> TimedOut
//! ```
//!
//! A response counts only if it comes from the addressed node's SDO server (0x580 + node),
//! is 8 bytes long (CiA 301 requires it) and names the object of the pending request; anything
//! else is ignored, so a corrupted or stray frame ends as a time-out, never as a wrong value
//! attributed to the wrong object.

use super::{NodeId, ObjectAddress, cob_id, frame, function, node_of};
use crate::can::Frame;

/// Size of an expedited value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Width {
    U8 = 1,
    U16 = 2,
    U32 = 4,
}

impl Width {
    pub fn bytes(self) -> usize {
        self as usize
    }

    /// The bytes of an expedited transfer's 4-byte data field that this width leaves unused
    /// (the command byte's n field).
    fn unused_bytes(self) -> u8 {
        match self {
            Width::U8 => 3,
            Width::U16 => 2,
            Width::U32 => 0,
        }
    }

    /// The value kept to this width (higher bytes cleared).
    pub fn truncate(self, value: u32) -> u32 {
        match self {
            Width::U8 => value & 0xFF,
            Width::U16 => value & 0xFFFF,
            Width::U32 => value,
        }
    }
}

/// A value to write: raw bits little-endian on the wire, `width` bytes of them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SdoWrite {
    pub object: ObjectAddress,
    pub value: u32,
    pub width: Width,
}

/// One transfer the client can run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SdoRequest {
    Download(SdoWrite),
    Upload(ObjectAddress),
}

impl SdoRequest {
    pub fn object(&self) -> ObjectAddress {
        match self {
            SdoRequest::Download(w) => w.object,
            SdoRequest::Upload(o) => *o,
        }
    }
}

/// An SDO abort code (CiA 301 7.2.4.3.17).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct AbortCode(pub u32);

impl AbortCode {
    pub const TOGGLE_BIT: AbortCode = AbortCode(0x0503_0000);
    pub const TIMED_OUT: AbortCode = AbortCode(0x0504_0000);
    pub const INVALID_COMMAND: AbortCode = AbortCode(0x0504_0001);
    pub const UNSUPPORTED_ACCESS: AbortCode = AbortCode(0x0601_0000);
    pub const WRITE_ONLY: AbortCode = AbortCode(0x0601_0001);
    pub const READ_ONLY: AbortCode = AbortCode(0x0601_0002);
    pub const NO_OBJECT: AbortCode = AbortCode(0x0602_0000);
    pub const NOT_MAPPABLE: AbortCode = AbortCode(0x0604_0041);
    pub const PDO_TOO_LONG: AbortCode = AbortCode(0x0604_0042);
    pub const LENGTH_MISMATCH: AbortCode = AbortCode(0x0607_0010);
    pub const NO_SUB_INDEX: AbortCode = AbortCode(0x0609_0011);
    pub const VALUE_RANGE: AbortCode = AbortCode(0x0609_0030);
    pub const VALUE_TOO_HIGH: AbortCode = AbortCode(0x0609_0031);
    pub const VALUE_TOO_LOW: AbortCode = AbortCode(0x0609_0032);
    pub const GENERAL: AbortCode = AbortCode(0x0800_0000);
    pub const DEVICE_STATE: AbortCode = AbortCode(0x0800_0022);

    /// The CiA 301 name, or "unknown abort code".
    pub fn name(self) -> &'static str {
        match self.0 {
            0x0503_0000 => "toggle bit not alternated",
            0x0504_0000 => "SDO protocol timed out",
            0x0504_0001 => "client/server command specifier not valid or unknown",
            0x0504_0002 => "invalid block size",
            0x0504_0003 => "invalid sequence number",
            0x0504_0004 => "CRC error",
            0x0504_0005 => "out of memory",
            0x0601_0000 => "unsupported access to an object",
            0x0601_0001 => "attempt to read a write only object",
            0x0601_0002 => "attempt to write a read only object",
            0x0602_0000 => "object does not exist in the object dictionary",
            0x0604_0041 => "object cannot be mapped to the PDO",
            0x0604_0042 => "number and length of objects to be mapped would exceed PDO length",
            0x0604_0043 => "general parameter incompatibility",
            0x0604_0047 => "general internal incompatibility in the device",
            0x0606_0000 => "access failed due to a hardware error",
            0x0607_0010 => "data type does not match, length of service parameter does not match",
            0x0607_0012 => "data type does not match, length of service parameter too high",
            0x0607_0013 => "data type does not match, length of service parameter too low",
            0x0609_0011 => "sub-index does not exist",
            0x0609_0030 => "invalid value for parameter",
            0x0609_0031 => "value of parameter written too high",
            0x0609_0032 => "value of parameter written too low",
            0x0609_0036 => "maximum value is less than minimum value",
            0x060A_0023 => "resource not available: SDO connection",
            0x0800_0000 => "general error",
            0x0800_0020 => "data cannot be transferred or stored to the application",
            0x0800_0021 => "data cannot be transferred or stored because of local control",
            0x0800_0022 => "data cannot be transferred or stored because of the device state",
            0x0800_0023 => "object dictionary dynamic generation fails or no OD present",
            0x0800_0024 => "no data available",
            _ => "unknown abort code",
        }
    }
}

impl core::fmt::Display for AbortCode {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "0x{:08X} ({})", self.0, self.name())
    }
}

fn address_bytes(object: ObjectAddress) -> [u8; 3] {
    let [lo, hi] = object.index.to_le_bytes();
    [lo, hi, object.sub]
}

/// Client request frame (0x600 + node).
pub fn request_frame(node: NodeId, request: &SdoRequest) -> Option<Frame> {
    let mut data = [0u8; 8];
    match request {
        SdoRequest::Download(w) => {
            // ccs = 1, e = 1, s = 1, n = 4 - width
            data[0] = 0x23 | (w.width.unused_bytes() << 2);
            data[1..4].copy_from_slice(&address_bytes(w.object));
            data[4..8].copy_from_slice(&w.width.truncate(w.value).to_le_bytes());
        }
        SdoRequest::Upload(object) => {
            data[0] = 0x40;
            data[1..4].copy_from_slice(&address_bytes(*object));
        }
    }
    frame(cob_id(function::SDO_RX, node), &data)
}

/// What an SDO server answered.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SdoResponse {
    /// Download confirmed (scs = 3).
    Downloaded { object: ObjectAddress },
    /// Expedited upload (scs = 2, e = 1); `bytes` is `None` when the size was not indicated.
    Uploaded {
        object: ObjectAddress,
        value: u32,
        bytes: Option<u8>,
    },
    /// Transfer aborted by the server.
    Aborted {
        object: ObjectAddress,
        code: AbortCode,
    },
    /// A valid-looking SDO frame this client does not handle (segmented upload, block
    /// transfer, a client command echoed back ...).
    Unsupported { object: ObjectAddress, command: u8 },
}

impl SdoResponse {
    pub fn object(&self) -> ObjectAddress {
        match *self {
            SdoResponse::Downloaded { object }
            | SdoResponse::Uploaded { object, .. }
            | SdoResponse::Aborted { object, .. }
            | SdoResponse::Unsupported { object, .. } => object,
        }
    }
}

/// An 8-byte SDO frame of `node` on the channel `base` (request or response) as its command
/// byte, the object it names and the 4-byte payload.
fn split(frame: &Frame, node: NodeId, base: u16) -> Option<(u8, ObjectAddress, u32)> {
    if node_of(frame.id(), base) != Some(node) {
        return None;
    }
    let d: [u8; 8] = frame.data().try_into().ok()?;
    let object = ObjectAddress::new(u16::from_le_bytes([d[1], d[2]]), d[3]);
    Some((d[0], object, u32::from_le_bytes([d[4], d[5], d[6], d[7]])))
}

/// The value of an expedited transfer and its size in bytes if the command byte indicates it
/// (s bit set: the n field counts the unused bytes); bytes beyond the size are masked off.
fn expedited(cs: u8, payload: u32) -> (u32, Option<u8>) {
    if cs & 0x01 == 0 {
        return (payload, None);
    }
    let (mask, bytes) = match (cs >> 2) & 0x03 {
        0 => (u32::MAX, 4),
        1 => (0x00FF_FFFF, 3),
        2 => (0x0000_FFFF, 2),
        _ => (0x0000_00FF, 1),
    };
    (payload & mask, Some(bytes))
}

/// The server's response in `frame`, if it is an 8-byte frame from `node`'s SDO server.
pub fn parse_response(frame: &Frame, node: NodeId) -> Option<SdoResponse> {
    let (cs, object, payload) = split(frame, node, function::SDO_TX)?;
    Some(match cs >> 5 {
        3 => SdoResponse::Downloaded { object },
        2 if cs & 0x02 != 0 => {
            let (value, bytes) = expedited(cs, payload);
            SdoResponse::Uploaded {
                object,
                value,
                bytes,
            }
        }
        4 => SdoResponse::Aborted {
            object,
            code: AbortCode(payload),
        },
        _ => SdoResponse::Unsupported {
            object,
            command: cs,
        },
    })
}

/// Server side, for simulators and tests: a download request (ccs = 1, expedited) as
/// (object, value, size in bytes if indicated), or an upload request (ccs = 2) as the object.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ServerRequest {
    Download {
        object: ObjectAddress,
        value: u32,
        bytes: Option<u8>,
    },
    Upload {
        object: ObjectAddress,
    },
    Unsupported {
        object: ObjectAddress,
        command: u8,
    },
}

/// The client request in `frame`, if it is an 8-byte frame to `node`'s SDO server.
pub fn parse_request(frame: &Frame, node: NodeId) -> Option<ServerRequest> {
    let (cs, object, payload) = split(frame, node, function::SDO_RX)?;
    Some(match cs >> 5 {
        1 if cs & 0x02 != 0 => {
            let (value, bytes) = expedited(cs, payload);
            ServerRequest::Download {
                object,
                value,
                bytes,
            }
        }
        2 => ServerRequest::Upload { object },
        _ => ServerRequest::Unsupported {
            object,
            command: cs,
        },
    })
}

/// Server response frames (0x580 + node), for simulators and tests.
pub fn download_response_frame(node: NodeId, object: ObjectAddress) -> Option<Frame> {
    let mut d = [0u8; 8];
    d[0] = 0x60;
    d[1..4].copy_from_slice(&address_bytes(object));
    frame(cob_id(function::SDO_TX, node), &d)
}

pub fn upload_response_frame(
    node: NodeId,
    object: ObjectAddress,
    value: u32,
    width: Width,
) -> Option<Frame> {
    let mut d = [0u8; 8];
    d[0] = 0x43 | (width.unused_bytes() << 2);
    d[1..4].copy_from_slice(&address_bytes(object));
    d[4..8].copy_from_slice(&width.truncate(value).to_le_bytes());
    frame(cob_id(function::SDO_TX, node), &d)
}

pub fn abort_frame(node: NodeId, object: ObjectAddress, code: AbortCode) -> Option<Frame> {
    let mut d = [0u8; 8];
    d[0] = 0x80;
    d[1..4].copy_from_slice(&address_bytes(object));
    d[4..8].copy_from_slice(&code.0.to_le_bytes());
    frame(cob_id(function::SDO_TX, node), &d)
}

/// How a transfer ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SdoOutcome {
    Written {
        object: ObjectAddress,
    },
    Read {
        object: ObjectAddress,
        value: u32,
    },
    Aborted {
        object: ObjectAddress,
        code: AbortCode,
    },
    /// No answer within the time-out. The caller decides whether to retry.
    TimedOut {
        request: SdoRequest,
    },
    /// The server answered with something this client cannot use for this request
    /// (a segmented upload, an upload answer to a download, ...).
    Unexpected {
        object: ObjectAddress,
        command: u8,
    },
}

/// Why [`SdoClient::start`] refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SdoError {
    /// A transfer is still pending (one at a time, CiA 301 7.2.4.1).
    Busy,
}

/// One SDO channel to one server.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SdoClient {
    node: NodeId,
    timeout_us: u64,
    pending: Option<(SdoRequest, u64)>,
}

impl SdoClient {
    pub fn new(node: NodeId, timeout_us: u64) -> Self {
        SdoClient {
            node,
            timeout_us,
            pending: None,
        }
    }

    pub fn is_idle(&self) -> bool {
        self.pending.is_none()
    }

    pub fn pending(&self) -> Option<SdoRequest> {
        self.pending.map(|(r, _)| r)
    }

    /// Begin a transfer; the frame to send.
    pub fn start(&mut self, request: SdoRequest, now_us: u64) -> Result<Option<Frame>, SdoError> {
        if self.pending.is_some() {
            return Err(SdoError::Busy);
        }
        self.pending = Some((request, now_us));
        Ok(request_frame(self.node, &request))
    }

    /// Drop the pending transfer without an outcome (e.g. the link gave up).
    pub fn cancel(&mut self) {
        self.pending = None;
    }

    /// Feed a received frame; the outcome if it answers the pending transfer.
    pub fn on_frame(&mut self, frame: &Frame) -> Option<SdoOutcome> {
        let (request, _) = self.pending?;
        let response = parse_response(frame, self.node)?;
        if response.object() != request.object() {
            return None;
        }
        let outcome = match (request, response) {
            (_, SdoResponse::Aborted { object, code }) => SdoOutcome::Aborted { object, code },
            (SdoRequest::Download(_), SdoResponse::Downloaded { object }) => {
                SdoOutcome::Written { object }
            }
            (SdoRequest::Upload(_), SdoResponse::Uploaded { object, value, .. }) => {
                SdoOutcome::Read { object, value }
            }
            (_, other) => SdoOutcome::Unexpected {
                object: other.object(),
                command: frame.data().first().copied().unwrap_or(0),
            },
        };
        self.pending = None;
        Some(outcome)
    }

    /// Check the time-out.
    pub fn poll(&mut self, now_us: u64) -> Option<SdoOutcome> {
        let (request, sent_at) = self.pending?;
        if now_us.saturating_sub(sent_at) > self.timeout_us {
            self.pending = None;
            return Some(SdoOutcome::TimedOut { request });
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node() -> NodeId {
        NodeId::new(1).unwrap()
    }

    const GAIN: ObjectAddress = ObjectAddress::new(0x30A1, 0x01);

    #[test]
    fn download_of_32_bit_uses_command_0x23() {
        let req = SdoRequest::Download(SdoWrite {
            object: GAIN,
            value: 4_390_000,
            width: Width::U32,
        });
        let f = request_frame(node(), &req).unwrap();
        assert_eq!(f.id().raw(), 0x601);
        assert_eq!(f.data()[..4], [0x23, 0xA1, 0x30, 0x01]);
        assert_eq!(f.data()[4..], 4_390_000u32.to_le_bytes());
        assert_eq!(
            parse_request(&f, node()),
            Some(ServerRequest::Download {
                object: GAIN,
                value: 4_390_000,
                bytes: Some(4)
            })
        );
    }

    #[test]
    fn download_of_one_and_two_bytes_sets_n() {
        for (width, cs) in [(Width::U8, 0x2F), (Width::U16, 0x2B)] {
            let req = SdoRequest::Download(SdoWrite {
                object: GAIN,
                value: 0xFFFF_FFFF,
                width,
            });
            let f = request_frame(node(), &req).unwrap();
            assert_eq!(f.data()[0], cs);
            let ServerRequest::Download { value, bytes, .. } = parse_request(&f, node()).unwrap()
            else {
                panic!()
            };
            assert_eq!(Some(width.bytes() as u8), bytes);
            assert_eq!(value, width.truncate(0xFFFF_FFFF));
        }
    }

    #[test]
    fn upload_round_trip_through_the_client() {
        let mut c = SdoClient::new(node(), 1_000);
        let f = c.start(SdoRequest::Upload(GAIN), 0).unwrap().unwrap();
        assert_eq!(f.data()[0], 0x40);
        assert_eq!(c.start(SdoRequest::Upload(GAIN), 0), Err(SdoError::Busy));
        let resp = upload_response_frame(node(), GAIN, 0x1234_5678, Width::U32).unwrap();
        assert_eq!(
            c.on_frame(&resp),
            Some(SdoOutcome::Read {
                object: GAIN,
                value: 0x1234_5678
            })
        );
        assert!(c.is_idle());
    }

    #[test]
    fn a_response_for_another_object_is_ignored_then_times_out() {
        let mut c = SdoClient::new(node(), 1_000);
        c.start(SdoRequest::Upload(GAIN), 0).unwrap();
        let other = download_response_frame(node(), ObjectAddress::new(0x30A1, 2)).unwrap();
        assert_eq!(c.on_frame(&other), None);
        assert_eq!(c.poll(1_000), None);
        assert_eq!(
            c.poll(1_001),
            Some(SdoOutcome::TimedOut {
                request: SdoRequest::Upload(GAIN)
            })
        );
    }

    #[test]
    fn abort_codes_have_names() {
        let f = abort_frame(node(), GAIN, AbortCode::READ_ONLY).unwrap();
        let r = parse_response(&f, node()).unwrap();
        assert_eq!(
            r,
            SdoResponse::Aborted {
                object: GAIN,
                code: AbortCode::READ_ONLY
            }
        );
        assert_eq!(
            AbortCode::READ_ONLY.name(),
            "attempt to write a read only object"
        );
        assert_eq!(AbortCode(1).name(), "unknown abort code");
    }

    #[test]
    fn segmented_upload_is_reported_not_misread() {
        let mut c = SdoClient::new(node(), 1_000);
        c.start(SdoRequest::Upload(GAIN), 0).unwrap();
        let mut d = [0u8; 8];
        d[0] = 0x41; // initiate segmented upload
        d[1] = 0xA1;
        d[2] = 0x30;
        d[3] = 0x01;
        let f = Frame::new(cob_id(function::SDO_TX, node()), &d).unwrap();
        assert_eq!(
            c.on_frame(&f),
            Some(SdoOutcome::Unexpected {
                object: GAIN,
                command: 0x41
            })
        );
    }

    #[test]
    fn short_frames_are_not_sdo_responses() {
        let f = Frame::new(cob_id(function::SDO_TX, node()), &[0x60, 0xA1, 0x30, 1]).unwrap();
        assert_eq!(parse_response(&f, node()), None);
    }
}

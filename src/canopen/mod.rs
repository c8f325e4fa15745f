//! CANopen (CiA 301) and the CiA 402 drive profile, as far as the ECU needs them to run a
//! maxon EPOS4 in cyclic synchronous position mode: pure codecs and state machines, no HAL,
//! no heap, no async. Every decoder takes an arbitrary [`Frame`] and never panics.
//!
//! Layers, bottom up:
//! - [`nmt`]: NMT commands (0x000), SYNC (0x080), heartbeat / boot-up (0x700 + node).
//! - [`sdo`]: expedited SDO client (0x600 + node / 0x580 + node) with abort codes by name.
//! - [`pdo`]: PDO communication and mapping parameters as SDO writes; the PDO payloads.
//! - [`emcy`]: emergency frames (0x080 + node).
//! - [`cia402`]: controlword / statusword and the drive state machine as seen by a master.
//! - [`epos4`]: the EPOS4 object dictionary entries used here (checked against maxon's EDS),
//!   unit conversions, and [`epos4::Epos4Link`], the bring-up and cyclic exchange.
//! - `epos4_model` (tests and the `epos4-model` feature only): the drive's side of the same
//!   protocol, the EPOS4 the tests run the link against.

pub mod cia402;
pub mod emcy;
pub mod epos4;
#[cfg(any(test, feature = "epos4-model"))]
pub mod epos4_model;
pub mod nmt;
pub mod pdo;
pub mod sdo;

use crate::can::{Frame, StandardId};

/// A CANopen node-ID, 1..=127 (CiA 301: 0 is "all nodes" in NMT and never a node's own id).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct NodeId(u8);

impl NodeId {
    pub const fn new(raw: u8) -> Option<Self> {
        if raw >= 1 && raw <= 127 {
            Some(NodeId(raw))
        } else {
            None
        }
    }

    pub const fn raw(self) -> u8 {
        self.0
    }
}

/// An object dictionary address: index and sub-index.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ObjectAddress {
    pub index: u16,
    pub sub: u8,
}

impl ObjectAddress {
    pub const fn new(index: u16, sub: u8) -> Self {
        ObjectAddress { index, sub }
    }
}

impl core::fmt::Display for ObjectAddress {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "0x{:04X}/{}", self.index, self.sub)
    }
}

/// Function codes of the predefined connection set (CiA 301 7.3.3): COB-ID = base + node-ID.
pub mod function {
    pub const NMT: u16 = 0x000;
    pub const SYNC: u16 = 0x080;
    pub const EMCY: u16 = 0x080;
    pub const TPDO1: u16 = 0x180;
    pub const RPDO1: u16 = 0x200;
    pub const TPDO2: u16 = 0x280;
    pub const SDO_TX: u16 = 0x580;
    pub const SDO_RX: u16 = 0x600;
    pub const HEARTBEAT: u16 = 0x700;
}

/// COB-ID 0x000, built at compile time (a `None` here would fail the build, never at run time).
pub const NMT_ID: StandardId = match StandardId::new(function::NMT) {
    Some(id) => id,
    None => panic!("0x000 is an 11-bit identifier"),
};

/// COB-ID 0x080 (SYNC), built at compile time.
pub const SYNC_ID: StandardId = match StandardId::new(function::SYNC) {
    Some(id) => id,
    None => panic!("0x080 is an 11-bit identifier"),
};

/// The COB-ID `base + node`. Every base above is at most 0x700 and a node at most 127, so the
/// sum fits 11 bits; the masked fallback only keeps the function total.
pub fn cob_id(base: u16, node: NodeId) -> StandardId {
    StandardId::new(base.wrapping_add(node.0 as u16) & StandardId::MAX).unwrap_or(NMT_ID)
}

/// The node a COB-ID of function `base` belongs to, if it is one.
pub fn node_of(id: StandardId, base: u16) -> Option<NodeId> {
    let raw = id.raw().checked_sub(base)?;
    u8::try_from(raw).ok().and_then(NodeId::new)
}

/// An 8-byte frame. `Frame::new` only refuses more than 8 bytes, so `None` cannot happen here;
/// the `Option` is kept rather than hidden behind a panic.
pub(crate) fn frame(id: StandardId, data: &[u8]) -> Option<Frame> {
    Frame::new(id, data)
}

//! Emergency objects (CiA 301 7.2.7): COB-ID 0x080 + node, 8 bytes: error code (u16), error
//! register (0x1001, u8), five manufacturer-specific bytes.

use super::{NodeId, cob_id, frame, function, node_of};
use crate::can::Frame;

/// One EMCY message.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Emcy {
    /// CiA 301 Table 21 / EPOS4 firmware specification error code; 0x0000 = "error reset or
    /// no error" (sent when a fault was cleared).
    pub error_code: u16,
    /// Error register, object 0x1001.
    pub error_register: u8,
    pub vendor: [u8; 5],
}

impl Emcy {
    /// True for the "error reset / no error" message.
    pub fn is_reset(&self) -> bool {
        self.error_code == 0
    }

    pub fn to_frame(&self, node: NodeId) -> Option<Frame> {
        let mut d = [0u8; 8];
        d[..2].copy_from_slice(&self.error_code.to_le_bytes());
        d[2] = self.error_register;
        d[3..].copy_from_slice(&self.vendor);
        frame(cob_id(function::EMCY, node), &d)
    }
}

/// The EMCY in `frame`, if it is an 8-byte EMCY of `node`.
pub fn parse(frame: &Frame, node: NodeId) -> Option<Emcy> {
    if node_of(frame.id(), function::EMCY) != Some(node) {
        return None;
    }
    let [c0, c1, reg, v0, v1, v2, v3, v4] = *frame.data() else {
        return None;
    };
    Some(Emcy {
        error_code: u16::from_le_bytes([c0, c1]),
        error_register: reg,
        vendor: [v0, v1, v2, v3, v4],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn emcy_round_trips_and_checks_node_and_length() {
        let n = NodeId::new(3).unwrap();
        let e = Emcy {
            error_code: 0x2310,
            error_register: 0x03,
            vendor: [1, 2, 3, 4, 5],
        };
        let f = e.to_frame(n).unwrap();
        assert_eq!(f.id().raw(), 0x083);
        assert_eq!(parse(&f, n), Some(e));
        assert_eq!(parse(&f, NodeId::new(4).unwrap()), None);
        let short = Frame::new(f.id(), &f.data()[..7]).unwrap();
        assert_eq!(parse(&short, n), None);
    }

    #[test]
    fn sync_is_not_an_emcy() {
        let sync = crate::canopen::nmt::sync_frame().unwrap();
        assert_eq!(parse(&sync, NodeId::new(1).unwrap()), None);
    }
}

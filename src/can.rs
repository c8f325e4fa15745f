//! Classic CAN frames as the core sees them: an 11-bit identifier and up to 8 data bytes.
//! The firmware converts to and from embassy-stm32's bxCAN frames at the edge; host-sim's
//! in-memory bus carries these directly.

/// An 11-bit standard identifier; `None` for values above 0x7FF.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct StandardId(u16);

impl StandardId {
    pub const MAX: u16 = 0x7FF;

    pub const fn new(raw: u16) -> Option<Self> {
        if raw <= Self::MAX {
            Some(StandardId(raw))
        } else {
            None
        }
    }

    pub const fn raw(self) -> u16 {
        self.0
    }
}

/// A data frame (remote frames are not used on this bus).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Frame {
    id: StandardId,
    len: u8,
    data: [u8; 8],
}

impl Frame {
    /// `None` if `data` is longer than 8 bytes.
    pub fn new(id: StandardId, data: &[u8]) -> Option<Self> {
        let mut buf = [0u8; 8];
        // `get_mut` is the length check: `None` beyond 8 bytes.
        buf.get_mut(..data.len())?.copy_from_slice(data);
        Some(Frame {
            id,
            len: data.len() as u8,
            data: buf,
        })
    }

    /// A full 8-byte frame: cannot fail, so encoders need no error path.
    pub const fn from_bytes(id: StandardId, data: [u8; 8]) -> Self {
        Frame { id, len: 8, data }
    }

    pub fn id(&self) -> StandardId {
        self.id
    }

    /// The payload, 0 to 8 bytes.
    pub fn data(&self) -> &[u8] {
        // `len` <= 8 by construction (`new`); the fallback is never taken.
        self.data.get(..usize::from(self.len)).unwrap_or(&[])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn identifiers_above_11_bits_are_unrepresentable() {
        assert!(StandardId::new(0x7FF).is_some());
        assert!(StandardId::new(0x800).is_none());
    }

    #[test]
    fn frames_hold_up_to_8_bytes() {
        let id = StandardId::new(0x123).unwrap();
        assert_eq!(Frame::new(id, &[1, 2, 3]).unwrap().data(), &[1, 2, 3]);
        assert!(Frame::new(id, &[0; 9]).is_none());
        assert_eq!(Frame::new(id, &[]).unwrap().data(), &[] as &[u8]);
        assert_eq!(Frame::from_bytes(id, [7; 8]).data(), &[7; 8]);
    }
}

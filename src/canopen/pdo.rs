//! Process data objects: the communication (0x1400 / 0x1800 + n) and mapping (0x1600 / 0x1A00
//! + n) parameters written as a list of SDO downloads, and the payloads this ECU exchanges.
//!
//! The write order follows CiA 301 7.5.2.35-36: invalidate the COB-ID (bit 31), set the
//! transmission type, clear the mapping count, write the entries, set the count, and validate
//! the COB-ID again. A device may refuse mapping changes on a valid PDO, hence the order.

use super::sdo::{SdoWrite, Width};
use super::{ObjectAddress, frame};
use crate::can::{Frame, StandardId};

/// COB-ID bit 31: PDO not valid (CiA 301 Table 71/72).
pub const COB_ID_INVALID: u32 = 1 << 31;
/// COB-ID bit 30 of a TPDO: no RTR allowed on this PDO.
pub const COB_ID_NO_RTR: u32 = 1 << 30;
/// Transmission type 1: synchronous, every SYNC (CiA 301 Table 71/72).
pub const TRANSMISSION_SYNC_EVERY: u8 = 1;

/// Receive (master -> device) or transmit (device -> master), from the device's point of view.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Direction {
    Receive,
    Transmit,
}

/// One mapping entry: object and length in bits, as the 32-bit value of 0x1600/0x1A00 sub n.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MappingEntry {
    pub object: ObjectAddress,
    pub bits: u8,
}

impl MappingEntry {
    pub const fn new(object: ObjectAddress, bits: u8) -> Self {
        MappingEntry { object, bits }
    }

    pub const fn raw(&self) -> u32 {
        ((self.object.index as u32) << 16) | ((self.object.sub as u32) << 8) | self.bits as u32
    }

    pub const fn from_raw(raw: u32) -> Self {
        MappingEntry {
            object: ObjectAddress::new((raw >> 16) as u16, (raw >> 8) as u8),
            bits: raw as u8,
        }
    }
}

/// Maximum entries this layer maps into one PDO (8 bytes hold at most 8 objects; 4 suffice).
pub const MAX_ENTRIES: usize = 4;

/// Why a PDO configuration is refused.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum PdoConfigError {
    /// PDO number outside 1..=4 (the EPOS4 has four of each: EDS NrOfRXPDO / NrOfTXPDO = 4).
    Number { number: u8 },
    /// More than [`MAX_ENTRIES`] entries, or more than 64 bits in total.
    TooLong { bits: u32 },
    /// An entry of 0 bits or not a whole number of bytes.
    EntryLength { object: ObjectAddress, bits: u8 },
}

/// One PDO's configuration.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PdoConfig {
    direction: Direction,
    number: u8,
    cob_id: StandardId,
    transmission: u8,
    entries: heapless::Vec<MappingEntry, MAX_ENTRIES>,
}

impl PdoConfig {
    /// `number` is 1-based (RPDO1 = 0x1400/0x1600).
    pub fn new(
        direction: Direction,
        number: u8,
        cob_id: StandardId,
        transmission: u8,
        entries: &[MappingEntry],
    ) -> Result<Self, PdoConfigError> {
        if !(1..=4).contains(&number) {
            return Err(PdoConfigError::Number { number });
        }
        let mut bits = 0u32;
        for e in entries {
            if e.bits == 0 || e.bits % 8 != 0 {
                return Err(PdoConfigError::EntryLength {
                    object: e.object,
                    bits: e.bits,
                });
            }
            bits = bits.saturating_add(u32::from(e.bits));
        }
        let entries =
            heapless::Vec::from_slice(entries).map_err(|_| PdoConfigError::TooLong { bits })?;
        if bits > 64 {
            return Err(PdoConfigError::TooLong { bits });
        }
        Ok(PdoConfig {
            direction,
            number,
            cob_id,
            transmission,
            entries,
        })
    }

    pub fn cob_id(&self) -> StandardId {
        self.cob_id
    }

    pub fn entries(&self) -> &[MappingEntry] {
        &self.entries
    }

    /// Payload length in bytes.
    pub fn len(&self) -> usize {
        self.entries.iter().map(|e| e.bits as usize / 8).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    fn communication_index(&self) -> u16 {
        let base: u16 = match self.direction {
            Direction::Receive => 0x1400,
            Direction::Transmit => 0x1800,
        };
        // `number` is 1..=4 (checked in `new`).
        base.saturating_add(u16::from(self.number.saturating_sub(1)))
    }

    fn mapping_index(&self) -> u16 {
        self.communication_index().saturating_add(0x200)
    }

    /// The SDO writes that configure this PDO, in CiA 301 order.
    pub fn writes(&self) -> heapless::Vec<SdoWrite, { 5 + MAX_ENTRIES }> {
        let comm = self.communication_index();
        let map = self.mapping_index();
        let rtr = match self.direction {
            Direction::Receive => 0,
            Direction::Transmit => COB_ID_NO_RTR,
        };
        let cob = self.cob_id.raw() as u32 | rtr;
        let w = |index: u16, sub: u8, value: u32, width: Width| SdoWrite {
            object: ObjectAddress::new(index, sub),
            value,
            width,
        };
        let mut out = heapless::Vec::new();
        // Capacity is 5 + MAX_ENTRIES and `entries` holds at most MAX_ENTRIES: never full.
        let _ = out.push(w(comm, 1, cob | COB_ID_INVALID, Width::U32));
        let _ = out.push(w(comm, 2, self.transmission as u32, Width::U8));
        let _ = out.push(w(map, 0, 0, Width::U8));
        for (i, e) in self.entries.iter().enumerate() {
            let _ = out.push(w(map, (i as u8).saturating_add(1), e.raw(), Width::U32));
        }
        let _ = out.push(w(map, 0, self.entries.len() as u32, Width::U8));
        let _ = out.push(w(comm, 1, cob, Width::U32));
        out
    }
}

/// RPDO payload: one `i32`, little-endian (e.g. target position 0x607A).
pub fn encode_i32(cob_id: StandardId, value: i32) -> Option<Frame> {
    frame(cob_id, &value.to_le_bytes())
}

/// TPDO payload "statusword u16 + position i32" (6 bytes, in mapping order).
pub fn decode_u16_i32(data: &[u8]) -> Option<(u16, i32)> {
    let [a, b, c, d, e, f] = *data else {
        return None;
    };
    Some((u16::from_le_bytes([a, b]), i32::from_le_bytes([c, d, e, f])))
}

/// TPDO payload of one `i32` (e.g. current actual value 0x30D1, INTEGER32 in the EDS).
pub fn decode_i32(data: &[u8]) -> Option<i32> {
    let bytes: [u8; 4] = data.try_into().ok()?;
    Some(i32::from_le_bytes(bytes))
}

/// The node a PDO COB-ID belongs to is not implied by the frame; callers compare ids.
pub fn is_from(frame: &Frame, cob_id: StandardId) -> bool {
    frame.id() == cob_id
}

#[cfg(test)]
mod tests {
    use super::*;

    fn id(raw: u16) -> StandardId {
        StandardId::new(raw).unwrap()
    }

    #[test]
    fn mapping_entry_packs_index_sub_bits() {
        let e = MappingEntry::new(ObjectAddress::new(0x607A, 0), 32);
        assert_eq!(e.raw(), 0x607A_0020);
        assert_eq!(MappingEntry::from_raw(0x30D1_0220).object.sub, 2);
    }

    #[test]
    fn tpdo_writes_follow_the_cia301_order() {
        let cfg = PdoConfig::new(
            Direction::Transmit,
            1,
            id(0x181),
            1,
            &[
                MappingEntry::new(ObjectAddress::new(0x6041, 0), 16),
                MappingEntry::new(ObjectAddress::new(0x6064, 0), 32),
            ],
        )
        .unwrap();
        let w = cfg.writes();
        let seq: Vec<(u16, u8, u32)> = w
            .iter()
            .map(|w| (w.object.index, w.object.sub, w.value))
            .collect();
        assert_eq!(
            seq,
            vec![
                (0x1800, 1, 0xC000_0181),
                (0x1800, 2, 1),
                (0x1A00, 0, 0),
                (0x1A00, 1, 0x6041_0010),
                (0x1A00, 2, 0x6064_0020),
                (0x1A00, 0, 2),
                (0x1800, 1, 0x4000_0181),
            ]
        );
        assert_eq!(cfg.len(), 6);
    }

    #[test]
    fn more_than_8_bytes_is_refused() {
        let e = MappingEntry::new(ObjectAddress::new(0x6064, 0), 32);
        assert_eq!(
            PdoConfig::new(Direction::Transmit, 1, id(0x181), 1, &[e, e, e]),
            Err(PdoConfigError::TooLong { bits: 96 })
        );
        assert!(matches!(
            PdoConfig::new(Direction::Transmit, 5, id(0x181), 1, &[e]),
            Err(PdoConfigError::Number { number: 5 })
        ));
    }

    #[test]
    fn payloads_round_trip() {
        let f = encode_i32(id(0x201), -123_456).unwrap();
        assert_eq!(decode_i32(f.data()), Some(-123_456));
        let mut d = [0u8; 6];
        d[..2].copy_from_slice(&0x0637u16.to_le_bytes());
        d[2..].copy_from_slice(&(-5i32).to_le_bytes());
        assert_eq!(decode_u16_i32(&d), Some((0x0637, -5)));
        assert_eq!(decode_u16_i32(&d[..5]), None);
    }
}

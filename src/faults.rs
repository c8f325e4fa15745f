//! The steering ECU's faults: what can go wrong ([`Fault`]), the latched set as it goes into the
//! CAN status frame ([`FaultSet`]), and a fixed-size ring of fault records ([`FaultLog`]) that
//! keeps the detail of each (the code, the value that tripped it) for the defmt log, the
//! debugger and the diagnostic frame 0x103, which pages through every record with its age and
//! whether a clear has acknowledged it ([`crate::protocol::Diagnostic`]).
//!
//! Detection, latching and clearing live in [`crate::steering`]; this module only names the
//! faults and stores them. The bit positions below are the wire format of the status frame's
//! fault bits: they never move, a new fault takes a free bit.
//!
//! A panic is not in the list: the firmware's panic handler turns the drive off (EPOS4
//! "disable voltage", PWM outputs low) and halts the MCU, so no code of this crate runs after
//! it (see `src/firmware/safety.rs`).

use heapless::Deque;

/// One kind of fault. The discriminant is the bit position in [`FaultSet`] and the status
/// frame; it never changes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(u8)]
pub enum Fault {
    /// Bit 0. No valid reference frame for the reference timeout plus the hold time
    /// (30 + 100 ms by default) while the AS state allows power. Detail: age of the last
    /// valid frame, ms (saturated to `i32::MAX`).
    ReferenceTimeout = 0,
    /// Bit 1. End-to-end protection: the protocol layer saw too many invalid reference frames
    /// in a row (CRC, alive counter, length). Detail: the count it reports.
    InvalidFrames = 1,
    /// Bit 2. The column encoder or the motor angle is unusable: the sensor reported an error,
    /// a value is not finite, or no sample came within the encoder timeout while the AS state
    /// allows power. Detail: see [`EncoderFaultDetail`].
    Encoder = 2,
    /// Bit 3. The column encoder moved further between two samples than the column can.
    /// Detail: the jump, centi-degrees at the wheel.
    EncoderJump = 3,
    /// Bit 4. Column encoder and motor angle x gear ratio disagree beyond the window for longer
    /// than the persistence time. Detail: the difference, centi-degrees at the wheel.
    EncoderMotorDisagreement = 4,
    /// Bit 5. Measured |I| above the over-current threshold for N samples in a row.
    /// Detail: the last sample, mA (`i32::MIN` if it was not a number).
    OverCurrent = 5,
    /// Bit 6. The EPOS4 reported a fault (statusword fault bit or an EMCY). Detail: the
    /// CANopen error code (0x603F / EMCY code).
    EposFault = 6,
    /// Bit 7. The EPOS4's heartbeat stopped (CANopen consumer heartbeat time elapsed).
    HeartbeatLost = 7,
    /// Bit 8. The CAN controller went bus-off. Detail: the transmit error counter if known.
    BusOff = 8,
    /// Bit 9. The column is further from the reference than the tracking window for longer
    /// than its persistence time while the drive is on: the actuator does not do what it is
    /// told (a current-sense offset, a wrong commutation, a jammed or slipping mechanism).
    /// Detail: the error, centi-degrees at the wheel.
    TrackingError = 9,
    /// Bit 10. The motor origin is not trustworthy: at an enable, the column samples of the
    /// last 16 ms did not agree on it (detail: their spread, centi-degrees at the wheel), or,
    /// while the drive rests on, column and motor angle / gear ratio differ by more than a
    /// wrong origin's bound (detail: the difference, centi-degrees, plus 1 000 000).
    Origin = 10,
}

impl Fault {
    /// Every fault, in bit order.
    pub const ALL: [Fault; 11] = [
        Fault::ReferenceTimeout,
        Fault::InvalidFrames,
        Fault::Encoder,
        Fault::EncoderJump,
        Fault::EncoderMotorDisagreement,
        Fault::OverCurrent,
        Fault::EposFault,
        Fault::HeartbeatLost,
        Fault::BusOff,
        Fault::TrackingError,
        Fault::Origin,
    ];

    /// Bit position in [`FaultSet`] and in the status frame.
    pub const fn bit(self) -> u8 {
        self as u8
    }

    /// The fault at a bit position; `None` for a free bit.
    pub const fn from_bit(bit: u8) -> Option<Fault> {
        match bit {
            0 => Some(Fault::ReferenceTimeout),
            1 => Some(Fault::InvalidFrames),
            2 => Some(Fault::Encoder),
            3 => Some(Fault::EncoderJump),
            4 => Some(Fault::EncoderMotorDisagreement),
            5 => Some(Fault::OverCurrent),
            6 => Some(Fault::EposFault),
            7 => Some(Fault::HeartbeatLost),
            8 => Some(Fault::BusOff),
            9 => Some(Fault::TrackingError),
            10 => Some(Fault::Origin),
            _ => None,
        }
    }
}

/// Detail codes of [`Fault::Encoder`].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[repr(i32)]
pub enum EncoderFaultDetail {
    /// The column-encoder reading was NaN or infinite.
    ColumnNotFinite = 1,
    /// The motor angle was NaN or infinite.
    MotorNotFinite = 2,
    /// No encoder sample within the encoder timeout while the AS state allows power.
    Stale = 3,
    /// The sensor itself reported an error; the firmware's code is added to this base
    /// (`0x1_0000 + code`).
    SensorReported = 0x1_0000,
}

/// A set of faults as a `u16` bitset; bit `n` is the fault with [`Fault::bit`] `n`. Bits 11 to
/// 15 are free and always zero.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultSet(u16);

impl FaultSet {
    pub const EMPTY: FaultSet = FaultSet(0);
    /// The bits that name a fault.
    pub const VALID_BITS: u16 = (1 << Fault::ALL.len()) - 1;

    /// The set from status-frame bits; free bits are dropped.
    pub const fn from_bits(bits: u16) -> FaultSet {
        FaultSet(bits & Self::VALID_BITS)
    }

    /// The status-frame bits.
    pub const fn bits(self) -> u16 {
        self.0
    }

    pub const fn is_empty(self) -> bool {
        self.0 == 0
    }

    pub const fn contains(self, fault: Fault) -> bool {
        self.0 & (1 << fault.bit()) != 0
    }

    /// Adds `fault`; true if it was not in the set before.
    pub fn insert(&mut self, fault: Fault) -> bool {
        let new = !self.contains(fault);
        self.0 |= 1 << fault.bit();
        new
    }

    pub fn remove(&mut self, fault: Fault) {
        self.0 &= !(1 << fault.bit());
    }

    pub const fn union(self, other: FaultSet) -> FaultSet {
        FaultSet(self.0 | other.0)
    }

    pub const fn intersection(self, other: FaultSet) -> FaultSet {
        FaultSet(self.0 & other.0)
    }

    /// The faults in the set, in bit order.
    pub fn iter(self) -> impl Iterator<Item = Fault> {
        Fault::ALL.into_iter().filter(move |f| self.contains(*f))
    }
}

impl From<Fault> for FaultSet {
    fn from(fault: Fault) -> Self {
        FaultSet(1 << fault.bit())
    }
}

/// One fault as it was latched.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct FaultRecord {
    pub fault: Fault,
    /// Time of detection, µs on the caller's clock.
    pub at_us: u64,
    /// Fault-specific value, documented on each [`Fault`] variant.
    pub detail: i32,
}

/// Records the ring holds; the oldest is dropped when a new one does not fit.
pub const FAULT_LOG_CAPACITY: usize = 16;

/// Fixed-size ring of the newest [`FAULT_LOG_CAPACITY`] fault records, oldest first, with a
/// count of the records dropped to make room. No heap; pushing never fails.
#[derive(Debug, Clone, Default)]
pub struct FaultLog {
    records: Deque<FaultRecord, FAULT_LOG_CAPACITY>,
    dropped: u32,
    /// The oldest this many records are acknowledged ([`FaultLog::acknowledge_all`]).
    acknowledged: usize,
}

impl FaultLog {
    pub const fn new() -> Self {
        FaultLog {
            records: Deque::new(),
            dropped: 0,
            acknowledged: 0,
        }
    }

    /// Marks every record held as acknowledged: the latch its fault set was cleared on request.
    /// Records pushed later are not.
    pub fn acknowledge_all(&mut self) {
        self.acknowledged = self.records.len();
    }

    /// Whether the `index`-th record (0 = oldest held) is acknowledged; false past the end.
    pub fn is_acknowledged(&self, index: usize) -> bool {
        index < self.acknowledged.min(self.records.len())
    }

    /// Records held that no clear has acknowledged.
    pub fn unacknowledged(&self) -> usize {
        self.records.len().saturating_sub(self.acknowledged)
    }

    /// Appends a record, dropping the oldest if the ring is full.
    pub fn push(&mut self, record: FaultRecord) {
        if self.records.is_full() && self.records.pop_front().is_some() {
            // Saturates: after 4 billion drops the exact count no longer matters.
            self.dropped = self.dropped.saturating_add(1);
            self.acknowledged = self.acknowledged.saturating_sub(1);
        }
        // Cannot fail: there is room now (capacity is not zero).
        let _ = self.records.push_back(record);
    }

    /// Records held, at most [`FAULT_LOG_CAPACITY`].
    pub fn len(&self) -> usize {
        self.records.len()
    }

    pub fn is_empty(&self) -> bool {
        self.records.is_empty()
    }

    /// Records dropped (oldest first) since start-up or the last [`FaultLog::clear`].
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// The `index`-th record, 0 = oldest held.
    pub fn get(&self, index: usize) -> Option<&FaultRecord> {
        self.records.get(index)
    }

    /// Oldest first.
    pub fn iter(&self) -> impl Iterator<Item = &FaultRecord> {
        self.records.iter()
    }

    /// Removes and returns the oldest record (for a read-out that consumes the log).
    pub fn pop_oldest(&mut self) -> Option<FaultRecord> {
        let oldest = self.records.pop_front();
        if oldest.is_some() {
            self.acknowledged = self.acknowledged.saturating_sub(1);
        }
        oldest
    }

    /// Empties the ring and zeroes the drop count.
    pub fn clear(&mut self) {
        self.records.clear();
        self.dropped = 0;
        self.acknowledged = 0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bit_positions_are_stable() {
        // The status frame's wire format: changing any of these breaks the DBC.
        let expected = [
            (Fault::ReferenceTimeout, 0),
            (Fault::InvalidFrames, 1),
            (Fault::Encoder, 2),
            (Fault::EncoderJump, 3),
            (Fault::EncoderMotorDisagreement, 4),
            (Fault::OverCurrent, 5),
            (Fault::EposFault, 6),
            (Fault::HeartbeatLost, 7),
            (Fault::BusOff, 8),
            (Fault::TrackingError, 9),
            (Fault::Origin, 10),
        ];
        for (fault, bit) in expected {
            assert_eq!(fault.bit(), bit);
            assert_eq!(Fault::from_bit(bit), Some(fault));
            assert_eq!(FaultSet::from(fault).bits(), 1 << bit);
        }
        for bit in 11..=255u8 {
            assert_eq!(Fault::from_bit(bit), None);
        }
        assert_eq!(FaultSet::VALID_BITS, 0x07FF);
    }

    #[test]
    fn fault_set_drops_free_bits_and_iterates_in_bit_order() {
        let set = FaultSet::from_bits(0xFFFF);
        assert_eq!(set.bits(), 0x07FF);
        assert_eq!(set.iter().count(), 11);
        let mut s = FaultSet::EMPTY;
        assert!(s.insert(Fault::BusOff));
        assert!(!s.insert(Fault::BusOff), "second insert is not new");
        assert!(s.insert(Fault::InvalidFrames));
        let v: Vec<Fault> = s.iter().collect();
        assert_eq!(v, [Fault::InvalidFrames, Fault::BusOff]);
        s.remove(Fault::BusOff);
        assert_eq!(s, FaultSet::from(Fault::InvalidFrames));
        assert!(!s.is_empty());
    }

    #[test]
    fn fault_ring_keeps_the_newest() {
        let mut log = FaultLog::new();
        let n = FAULT_LOG_CAPACITY as u64 + 5;
        for i in 0..n {
            log.push(FaultRecord {
                fault: Fault::OverCurrent,
                at_us: i,
                detail: i as i32,
            });
        }
        assert_eq!(log.len(), FAULT_LOG_CAPACITY);
        assert_eq!(log.dropped(), 5);
        assert_eq!(log.get(0).map(|r| r.at_us), Some(5), "oldest kept");
        assert_eq!(log.iter().last().map(|r| r.at_us), Some(n - 1), "newest");
        let times: Vec<u64> = log.iter().map(|r| r.at_us).collect();
        assert!(times.windows(2).all(|w| w[0] < w[1]), "oldest first");
        assert_eq!(log.pop_oldest().map(|r| r.at_us), Some(5));
        log.clear();
        assert!(log.is_empty());
        assert_eq!(log.dropped(), 0);
    }
}

#[cfg(test)]
mod acknowledge_tests {
    use super::*;

    fn record(at_us: u64) -> FaultRecord {
        FaultRecord {
            fault: Fault::Encoder,
            at_us,
            detail: 0,
        }
    }

    #[test]
    fn an_acknowledge_covers_the_records_held_then_and_follows_them_out_of_the_ring() {
        let mut log = FaultLog::new();
        log.push(record(0));
        log.push(record(1));
        log.acknowledge_all();
        log.push(record(2));
        assert_eq!(
            (0..4).map(|i| log.is_acknowledged(i)).collect::<Vec<_>>(),
            [true, true, false, false]
        );
        assert_eq!(log.unacknowledged(), 1);
        // Filling the ring pushes the two acknowledged ones out, oldest first.
        for t in 3..=FAULT_LOG_CAPACITY as u64 {
            log.push(record(t));
        }
        assert_eq!(log.get(0).map(|r| r.at_us), Some(1));
        assert!(log.is_acknowledged(0) && !log.is_acknowledged(1));
        log.push(record(100));
        assert!(!log.is_acknowledged(0));
        assert_eq!(log.unacknowledged(), FAULT_LOG_CAPACITY);
        log.acknowledge_all();
        assert_eq!(log.pop_oldest().map(|r| r.at_us), Some(2));
        assert_eq!(log.unacknowledged(), 0);
        log.clear();
        log.push(record(7));
        assert!(!log.is_acknowledged(0));
    }
}

/// A union that adds nothing new, and a log's emptiness as records come and go.
#[cfg(test)]
mod set_and_log_queries {
    use super::*;

    #[test]
    fn a_union_keeps_the_faults_both_sets_share() {
        let both = FaultSet::from(Fault::BusOff).union(Fault::Encoder.into());
        let u = both.union(Fault::BusOff.into());
        assert!(u.contains(Fault::BusOff) && u.contains(Fault::Encoder));
        assert_eq!(u, both);
    }

    #[test]
    fn a_log_with_a_record_is_not_empty() {
        let mut log = FaultLog::new();
        assert!(log.is_empty());
        log.push(FaultRecord {
            fault: Fault::BusOff,
            at_us: 1,
            detail: 0,
        });
        assert!(!log.is_empty());
        log.clear();
        assert!(log.is_empty());
    }
}

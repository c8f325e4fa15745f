//! Golden vectors of the control core: what host-sim records on the host and what the emulated
//! Cortex-M4F must reproduce, bit for bit.
//!
//! Two kinds:
//! - [`loops`]: closed-loop runs recorded from host-sim (a window of the sweep and of the track).
//!   The file holds every input the cascade got (reference samples, Hall counts, measured
//!   currents) and every output it gave (current set-points, voltages, statuses); a replay feeds
//!   the same inputs to a fresh [`steering_ecu::paper_mode::Cascade`] and compares the outputs.
//! - [`cases`]: the reference/status codec, the E2E check, the CANopen parsers, the CiA 402
//!   rules, the ECU state machine and the cascade under arbitrary bit patterns. Their inputs
//!   come from a seeded generator that both sides run; each case's outputs are written with
//!   `Debug` (which prints an `f32` so that it reads back to the same bits) into a 64-bit
//!   FNV-1a hash, and the file holds one hash per case.
//!
//! Everything is little-endian. No heap, no std: this crate runs on the target.
#![no_std]

pub mod cases;
pub mod loops;

/// FNV-1a, 64 bit: the per-case digest. Not cryptographic; it only has to change when a case's
/// output text changes.
#[derive(Debug, Clone, Copy)]
pub struct Fnv(u64);

impl Fnv {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    pub const fn new() -> Self {
        Fnv(Self::OFFSET)
    }

    pub fn bytes(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0 ^ u64::from(b)).wrapping_mul(Self::PRIME);
        }
    }

    pub const fn finish(&self) -> u64 {
        self.0
    }
}

impl Default for Fnv {
    fn default() -> Self {
        Self::new()
    }
}

/// Little-endian reader over a golden file; every read past the end is `None`.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Reader<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Reader { bytes, at: 0 }
    }

    pub fn offset(&self) -> usize {
        self.at
    }

    pub fn is_empty(&self) -> bool {
        self.at >= self.bytes.len()
    }

    pub fn take<const N: usize>(&mut self) -> Option<[u8; N]> {
        let end = self.at.checked_add(N)?;
        let out = self.bytes.get(self.at..end)?.try_into().ok()?;
        self.at = end;
        Some(out)
    }

    pub fn u8(&mut self) -> Option<u8> {
        self.take::<1>().map(|[b]| b)
    }

    pub fn u32(&mut self) -> Option<u32> {
        self.take().map(u32::from_le_bytes)
    }

    pub fn u64(&mut self) -> Option<u64> {
        self.take().map(u64::from_le_bytes)
    }
}

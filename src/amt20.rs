//! The column encoder: a CUI Devices AMT20-series absolute encoder (AMT203-V), 12 bit per
//! turn over SPI. Chosen because it is common, cheap, mounts on a shaft with a sleeve and is
//! absolute, so the column angle is known at power-up without homing.
//!
//! Reading the position is a byte-by-byte exchange (SPI mode 0, <= 1 MHz, chip select
//! released and >= 20 us between bytes, per the AMT20 datasheet):
//!
//! ```text
//! host sends  0x10 (rd_pos)   0x00      ...  0x00     0x00        0x00
//! encoder     (anything)      0xA5 wait ...  0x10 echo  MSB (0000xxxx)  LSB
//! ```
//!
//! This module is that exchange as a pure state machine, so the SPI port (firmware) and the
//! tests drive the same logic. Any unexpected byte, an MSB with its upper nibble set, or more
//! than [`MAX_WAIT_POLLS`] wait bytes fails the read; the encoder task reports the failure to
//! the state machine, which counts it as an encoder fault.

use crate::ports::EncoderError;

/// Command: read position.
pub const RD_POS: u8 = 0x10;
/// No operation; the encoder answers 0xA5 while idle or busy.
pub const NOP_A5: u8 = 0x00;
/// The encoder's "nothing to say yet" byte.
pub const WAIT: u8 = 0xA5;
/// Wait bytes tolerated before the read fails. The datasheet's worst case is a few tens of
/// microseconds of processing; at >= 20 us per byte, 16 polls is ample.
pub const MAX_WAIT_POLLS: u8 = 16;

/// What to do next in a read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Next {
    /// Send this byte (chip select asserted for it alone) and report the byte received.
    Transfer(u8),
    /// The 12-bit position, 0..=4095.
    Position(u16),
    Failed(EncoderError),
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Phase {
    Command,
    Waiting { polls: u8 },
    Msb,
    Lsb { msb: u8 },
    Done,
}

/// One position read. Start it, send [`Read::first_byte`], then feed each received byte to
/// [`Read::on_received`] until it answers `Position` or `Failed`.
#[derive(Debug, Clone)]
pub struct Read {
    phase: Phase,
}

impl Default for Read {
    fn default() -> Self {
        Self::new()
    }
}

impl Read {
    pub fn new() -> Self {
        Read {
            phase: Phase::Command,
        }
    }

    pub fn first_byte(&self) -> u8 {
        RD_POS
    }

    /// The byte received during the last transfer.
    pub fn on_received(&mut self, byte: u8) -> Next {
        let (phase, next) = match self.phase {
            // The answer to the command byte itself carries no information.
            Phase::Command => (Phase::Waiting { polls: 0 }, Next::Transfer(NOP_A5)),
            Phase::Waiting { polls } => match byte {
                RD_POS => (Phase::Msb, Next::Transfer(NOP_A5)),
                WAIT if polls < MAX_WAIT_POLLS => {
                    (Phase::Waiting { polls: polls + 1 }, Next::Transfer(NOP_A5))
                }
                WAIT => (Phase::Done, Next::Failed(EncoderError::NoResponse)),
                _ => (Phase::Done, Next::Failed(EncoderError::InvalidReading)),
            },
            Phase::Msb if byte & 0xF0 != 0 => {
                (Phase::Done, Next::Failed(EncoderError::InvalidReading))
            }
            Phase::Msb => (Phase::Lsb { msb: byte }, Next::Transfer(NOP_A5)),
            Phase::Lsb { msb } => (
                Phase::Done,
                Next::Position((u16::from(msb) << 8) | u16::from(byte)),
            ),
            Phase::Done => (Phase::Done, Next::Failed(EncoderError::InvalidReading)),
        };
        self.phase = phase;
        next
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Plays the encoder's side: `busy` wait bytes, then the echo and the position.
    fn exchange(busy: usize, position: u16, msb_garbage: u8) -> Next {
        let mut answers = vec![0xFFu8]; // reply to the command byte: meaningless
        answers.extend(std::iter::repeat_n(WAIT, busy));
        answers.push(RD_POS);
        answers.push(((position >> 8) as u8) | msb_garbage);
        answers.push(position as u8);
        let mut read = Read::new();
        assert_eq!(read.first_byte(), RD_POS);
        for a in answers {
            match read.on_received(a) {
                Next::Transfer(b) => assert_eq!(b, NOP_A5),
                done => return done,
            }
        }
        Next::Failed(EncoderError::NoResponse)
    }

    #[test]
    fn reads_a_12_bit_position_after_wait_bytes() {
        assert_eq!(exchange(0, 0, 0), Next::Position(0));
        assert_eq!(exchange(3, 4095, 0), Next::Position(4095));
        assert_eq!(exchange(1, 0x5A3, 0), Next::Position(0x5A3));
    }

    #[test]
    fn a_silent_encoder_fails_the_read() {
        assert_eq!(
            exchange(MAX_WAIT_POLLS as usize + 1, 100, 0),
            Next::Failed(EncoderError::NoResponse)
        );
    }

    #[test]
    fn garbage_fails_the_read_instead_of_giving_an_angle() {
        assert_eq!(
            exchange(0, 100, 0x30),
            Next::Failed(EncoderError::InvalidReading)
        );
        let mut read = Read::new();
        read.on_received(0);
        assert_eq!(
            read.on_received(0x42),
            Next::Failed(EncoderError::InvalidReading)
        );
        assert_eq!(
            read.on_received(0x10),
            Next::Failed(EncoderError::InvalidReading)
        );
    }

    #[test]
    fn any_byte_stream_ends_in_a_defined_result() {
        for seed in 0u32..2000 {
            let mut x = seed.wrapping_mul(2_654_435_761).max(1);
            let mut read = Read::new();
            let mut done = false;
            for _ in 0..40 {
                x ^= x << 13;
                x ^= x >> 17;
                x ^= x << 5;
                match read.on_received(x as u8) {
                    Next::Transfer(_) => {}
                    Next::Position(p) => {
                        assert!(p <= 4095);
                        done = true;
                        break;
                    }
                    Next::Failed(_) => {
                        done = true;
                        break;
                    }
                }
            }
            assert!(done, "seed {seed}: a read ends within 40 bytes");
        }
    }
}

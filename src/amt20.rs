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
//! tests drive the same logic. [`Amt20`] runs it over any SPI device of the embedded-hal-async
//! `SpiDevice` trait, for a board or HAL other than ours. Any unexpected byte, an MSB with its upper nibble set, or more
//! than [`MAX_WAIT_POLLS`] wait bytes fails the read; the encoder task reports the failure to
//! the state machine, which counts it as an encoder fault.

use crate::ports::{ColumnEncoderPort, EncoderError};
use embedded_hal_async::delay::DelayNs;
use embedded_hal_async::spi::{MODE_0, Mode, SpiDevice};

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
                WAIT if polls < MAX_WAIT_POLLS => (
                    Phase::Waiting {
                        polls: polls.saturating_add(1),
                    },
                    Next::Transfer(NOP_A5),
                ),
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

/// The SPI mode the AMT20 speaks (datasheet): configure the bus with it.
pub const SPI_MODE: Mode = MODE_0;
/// The AMT20's least time between two bytes, µs (datasheet).
pub const MIN_BYTE_GAP_US: u32 = 20;

/// The AMT20 on any SPI device of the embedded-hal-async trait. Each byte is its own
/// transaction, so the device releases chip select between bytes as the encoder needs, and
/// `delay` waits the byte gap after each. The bus must run in [`SPI_MODE`] at 1 MHz or less.
#[derive(Debug)]
pub struct Amt20<S, D> {
    spi: S,
    delay: D,
    byte_gap_us: u32,
}

impl<S: SpiDevice, D: DelayNs> Amt20<S, D> {
    /// `byte_gap_us` below the datasheet's [`MIN_BYTE_GAP_US`] is raised to it.
    pub fn new(spi: S, delay: D, byte_gap_us: u32) -> Self {
        Amt20 {
            spi,
            delay,
            byte_gap_us: byte_gap_us.max(MIN_BYTE_GAP_US),
        }
    }

    /// The SPI device and the delay back.
    pub fn release(self) -> (S, D) {
        (self.spi, self.delay)
    }

    /// One position read: the raw 12-bit word. An SPI error is `NoResponse`, as a silent
    /// encoder is: either way no reading came.
    pub async fn read_position(&mut self) -> Result<u16, EncoderError> {
        let mut read = Read::new();
        let mut byte = read.first_byte();
        loop {
            let mut buf = [byte];
            let sent = self.spi.transfer_in_place(&mut buf).await;
            self.delay.delay_us(self.byte_gap_us).await;
            sent.map_err(|_| EncoderError::NoResponse)?;
            match read.on_received(buf[0]) {
                Next::Transfer(next) => byte = next,
                Next::Position(raw) => return Ok(raw),
                Next::Failed(e) => return Err(e),
            }
        }
    }
}

impl<S: SpiDevice, D: DelayNs> ColumnEncoderPort for Amt20<S, D> {
    async fn read(&mut self) -> Result<u16, EncoderError> {
        self.read_position().await
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

    /// A stand-in AMT20 behind the embedded-hal-async `SpiDevice` trait: it answers from a
    /// script, and records every transaction (one chip-select assertion each) and the time
    /// between them, as the real encoder would notice it.
    mod mock {
        use super::super::*;
        use embedded_hal_async::spi::{ErrorKind, ErrorType, Operation};
        use std::cell::{Cell, RefCell};
        use std::rc::Rc;

        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        pub struct BusError;
        impl embedded_hal_async::spi::Error for BusError {
            fn kind(&self) -> ErrorKind {
                ErrorKind::Other
            }
        }

        /// Time as the delay advances it, µs, shared by the bus and the delay.
        pub type Clock = Rc<Cell<u64>>;

        #[derive(Debug)]
        pub struct Encoder {
            pub answers: Vec<u8>,
            /// Fail the transfer with this index.
            pub fail_at: Option<usize>,
            pub sent: Vec<u8>,
            /// (time, bytes in the transaction) per chip-select assertion.
            pub transactions: Rc<RefCell<Vec<(u64, usize)>>>,
            pub clock: Clock,
        }

        impl ErrorType for Encoder {
            type Error = BusError;
        }

        impl SpiDevice for Encoder {
            async fn transaction(
                &mut self,
                operations: &mut [Operation<'_, u8>],
            ) -> Result<(), BusError> {
                let mut bytes = 0;
                for op in operations {
                    let Operation::TransferInPlace(buf) = op else {
                        panic!("the driver only exchanges bytes in place");
                    };
                    for b in buf.iter_mut() {
                        let index = self.sent.len();
                        self.sent.push(*b);
                        if self.fail_at == Some(index) {
                            return Err(BusError);
                        }
                        *b = self.answers.get(index).copied().unwrap_or(WAIT);
                        bytes += 1;
                    }
                }
                self.transactions
                    .borrow_mut()
                    .push((self.clock.get(), bytes));
                Ok(())
            }
        }

        #[derive(Debug)]
        pub struct Delay(pub Clock);

        impl DelayNs for Delay {
            async fn delay_ns(&mut self, ns: u32) {
                self.0.set(self.0.get() + u64::from(ns.div_ceil(1000)));
            }
        }

        pub fn pair(answers: Vec<u8>, fail_at: Option<usize>) -> (Encoder, Delay) {
            let clock: Clock = Rc::new(Cell::new(0));
            (
                Encoder {
                    answers,
                    fail_at,
                    sent: Vec::new(),
                    transactions: Rc::new(RefCell::new(Vec::new())),
                    clock: clock.clone(),
                },
                Delay(clock),
            )
        }
    }

    #[test]
    fn the_generic_driver_reads_through_any_spi_device_one_byte_per_select() {
        let answers = vec![0xFF, WAIT, WAIT, RD_POS, 0x05, 0xA3];
        let (spi, delay) = mock::pair(answers, None);
        let transactions = spi.transactions.clone();
        let mut encoder = Amt20::new(spi, delay, 5);
        // Through the firmware's port trait, as the encoder task would call it.
        let position = embassy_futures::block_on(ColumnEncoderPort::read(&mut encoder));
        assert_eq!(position, Ok(0x5A3));
        let (spi, _) = encoder.release();
        assert_eq!(spi.sent, [RD_POS, NOP_A5, NOP_A5, NOP_A5, NOP_A5, NOP_A5]);
        let t = transactions.borrow();
        assert!(t.iter().all(|&(_, bytes)| bytes == 1), "{t:?}");
        // The 5 µs asked for is raised to the datasheet's 20 µs between selects.
        for w in t.windows(2) {
            assert!(w[1].0 - w[0].0 >= u64::from(MIN_BYTE_GAP_US), "{t:?}");
        }
    }

    #[test]
    fn the_generic_driver_turns_bus_errors_and_garbage_into_encoder_errors() {
        let (spi, delay) = mock::pair(vec![0xFF, RD_POS, 0x05, 0xA3], Some(2));
        let mut encoder = Amt20::new(spi, delay, 25);
        assert_eq!(
            embassy_futures::block_on(encoder.read_position()),
            Err(EncoderError::NoResponse)
        );
        let (spi, delay) = mock::pair(vec![0xFF, RD_POS, 0x35, 0xA3], None);
        let mut encoder = Amt20::new(spi, delay, 25);
        assert_eq!(
            embassy_futures::block_on(encoder.read_position()),
            Err(EncoderError::InvalidReading)
        );
        // A silent encoder (wait bytes for ever) ends the read too.
        let (spi, delay) = mock::pair(vec![0xFF], None);
        let mut encoder = Amt20::new(spi, delay, 25);
        assert_eq!(
            embassy_futures::block_on(encoder.read_position()),
            Err(EncoderError::NoResponse)
        );
    }
}

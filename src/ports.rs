//! The hardware the firmware's tasks touch, as traits: the STM32 implements them in
//! `main.rs`, host-sim implements them over the simulated plant and an in-memory CAN bus, so
//! the tasks themselves are the same code in both places.
//!
//! Async methods: the firmware runs one thread-mode executor (plus interrupts for the fast
//! loops), so no `Send` bound is needed on the futures.
#![allow(async_fn_in_trait)]

use crate::can::Frame;

/// Why the CAN peripheral could not deliver or take a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BusError {
    /// The controller went bus-off (transmit error counter > 255): a latched fault.
    BusOff,
    /// Frames were lost in the receive FIFO.
    Overrun,
    /// Any other controller error (stuff, form, ack, CRC) reported by the peripheral.
    Other,
}

/// Receiving half of the CAN peripheral.
pub trait CanRx {
    async fn receive(&mut self) -> Result<Frame, BusError>;
}

/// Transmitting half of the CAN peripheral.
pub trait CanTx {
    async fn transmit(&mut self, frame: &Frame) -> Result<(), BusError>;
}

/// The absolute encoder on the steering column: a raw 12-bit single-turn word.
pub trait ColumnEncoderPort {
    async fn read(&mut self) -> Result<u16, EncoderError>;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncoderError {
    /// No answer or a bus error on SPI.
    NoResponse,
    /// The encoder answered but flagged its reading invalid (or the framing was wrong).
    InvalidReading,
}

//! The hardware the firmware's tasks touch, as traits: the STM32 implements them in
//! `main.rs`, host-sim implements them over the simulated plant and an in-memory CAN bus, so
//! the tasks themselves are the same code in both places.
//!
//! The clock is embassy-time's (`Instant`, `Timer`, `Ticker`): the firmware's time driver on
//! the chip, the mock driver in host-sim.
//!
//! Async methods: the firmware runs one thread-mode executor (plus interrupts for the fast
//! loops), so no `Send` bound is needed on the futures.
#![allow(async_fn_in_trait)]

use crate::can::Frame;
use crate::commutation::BridgeCommand;
use crate::units::Amps;

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

/// The three Hall sensors of the motor, sampled together: bits H3 H2 H1 (see
/// [`crate::commutation`]). Read in the current-loop interrupt, so not async.
pub trait HallInputs {
    fn read(&mut self) -> u8;
}

/// The phase-current sensing, sampled synchronously with the PWM (the ADC conversion is
/// triggered by the PWM timer at the centre of the on-time): phases A, B, C, positive into
/// the motor. A failed conversion reads NaN, which the over-current check counts.
pub trait CurrentSense {
    fn phase_currents(&mut self) -> [Amps; 3];
}

/// The three-phase bridge: complementary PWM with hardware dead time.
pub trait Bridge {
    /// Apply the legs from the next PWM period on.
    fn apply(&mut self, command: &BridgeCommand);
}

//! The firmware's glue to the STM32's peripherals that is worth sharing: built only for the
//! chip (`thumbv7em-none-eabihf`), so the board suite (`hil-tests/tests/board.rs`) runs the
//! firmware's own register code instead of a copy. Host builds never see it.

pub mod bridge;
pub mod can;
pub mod fault;

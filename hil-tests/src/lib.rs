//! On-target tests of the steering ECU. The board suite is `tests/board.rs`, the emulated suite
//! the `emulated` package, the golden vectors' format and replay the `golden-vectors` package
//! (see `README.md`). This library is empty; it exists so `cargo build` here builds for the chip.
#![no_std]

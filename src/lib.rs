//! Hardware-free control core of the steering ECU, shared by the firmware and host-sim.
//!
//! Nothing here touches a peripheral: the firmware's tasks and host-sim's simulated ports read
//! their inputs, call the pure `step` functions below and write the outputs. All arithmetic is
//! `f32` (the Cortex-M4F has a single-precision FPU), no heap, and no input can make it panic:
//! every non-finite or out-of-range value has a documented outcome (see each module).
//!
//! Map:
//! - [`units`]: typed angles, currents and voltages; the gear chain wheel <-> motor ([`gearing`]).
//! - [`sensors`]: Hall counts and the 12-bit column encoder as angles.
//! - [`gains`]: the EPOS4 gains of the paper's Table 3, converted once to SI.
//! - [`reference`](mod@reference): the 100 Hz reference, interpolated with one sample of lag.
//! - [`control`]: position PID + feedforward, PI current loop, their anti-windup.
//! - [`paper_mode`]: the cascade at the paper's rates, as the firmware and host-sim both run it.
//! - `chip` (built for the chip only): the bridge's PWM set-up and force-off and the CAN set-up,
//!   shared by the firmware and the board suite.
//!
//! The rest of this page is the firmware's theory of operation (`src/FIRMWARE.md`).
#![doc = include_str!("FIRMWARE.md")]
#![cfg_attr(not(test), no_std)]
#![forbid(unsafe_code)]
// No input may make the firmware panic: the sites where a panic could hide (an index out of
// range, an integer overflow, an unwrap) are flagged, and each one that stays says why it
// cannot fire. Not for the tests, where a panic is the failure report.
#![cfg_attr(
    not(test),
    warn(
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects,
        clippy::expect_used,
        clippy::unwrap_used,
        clippy::panic
    )
)]

pub mod amt20;
pub mod as_state;
pub mod can;
pub mod canopen;
#[cfg(all(target_arch = "arm", target_os = "none"))]
pub mod chip;
pub mod commutation;
pub mod control;
pub mod controller;
pub mod direct;
pub mod ecu;
pub mod ecu_mode;
pub mod enable_ramp;
pub mod faults;
pub mod gains;
pub mod gearing;
pub mod paper_mode;
pub mod ports;
pub mod protocol;
pub mod reference;
pub mod sensors;
pub mod stack;
pub mod steering;
pub mod tasks;
pub mod units;
pub mod watchdog;

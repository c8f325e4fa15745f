//! bxCAN1's set-up for the vehicle bus, shared by the firmware and the board suite: one
//! bitrate and one filter, so the suite's loopback runs at what the car runs.

use embassy_stm32::can::Can;
use embassy_stm32::can::Fifo;
use embassy_stm32::can::filter::Mask32;

/// CAN bit rate, bit/s. 1 Mbit/s is the EPOS4's default and what the paper's car ran; the
/// bxCAN timing is derived from APB1 at start-up (45 MHz on the F446: 3 x 15 time quanta).
pub const BITRATE: u32 = 1_000_000;

/// Every frame into FIFO 0 (the router, `tasks::FirmwareRoutes`, sorts them) at [`BITRATE`].
/// Call before `enable`; test modes (loopback, silent) go on top.
pub fn configure(can: &mut Can<'_>) {
    can.modify_filters()
        .enable_bank(0, Fifo::Fifo0, Mask32::accept_all());
    can.modify_config().set_bitrate(BITRATE);
}

//! What the firmware does when its own code fails: a panic or a HardFault (a stack overflow
//! included) turns the drive's power stage off before anything else, then stops the MCU where
//! a probe can see why.
//!
//! - Direct drive: TIM1's main output enable (MOE) is cleared, which forces all six gate
//!   signals to their idle level (low = every switch off; OSSI is set at start-up so the
//!   outputs are driven, not floating), and the gate driver's enable pin is pulled low.
//! - EPOS4: the controlword "disable voltage" SDO request is written straight into a free
//!   bxCAN transmit mailbox (the async driver may be what failed) and given up to 1 ms to go.
//!
//! The handlers do not reset the MCU: a panic is a bug, and a reset would power the actuator
//! again as soon as the vehicle's reference frames come back. The status frames stop, which
//! the vehicle computer treats as a lost steering ECU (AS Emergency). The independent watchdog
//! (`steering_ecu::watchdog`, started in `main.rs`) cannot be stopped once running, so with no
//! more feeds it does reset the MCU 68..188 ms later; the firmware then starts as at power-up,
//! drive off, in Idle until the vehicle computer's frames allow power (the fault log, in RAM,
//! is lost). Both handlers need no state and no lock, so they work whatever was held when the
//! fault hit.

#[cfg(feature = "drive-epos4")]
use steering_ecu::canopen::NodeId;
#[cfg(feature = "drive-epos4")]
use steering_ecu::canopen::epos4::{Epos4Config, disable_voltage_frame};

/// The EPOS4's CANopen node ID (its DIP switches; 1 on the paper's car).
#[cfg(feature = "drive-epos4")]
pub const EPOS4_NODE: NodeId = match NodeId::new(1) {
    Some(node) => node,
    None => panic!("a node ID is 1..=127"), // evaluated at compile time
};

/// The link's settings: the paper's (Table 3 gains, 10 ms cycle) at [`EPOS4_NODE`].
#[cfg(feature = "drive-epos4")]
pub fn epos4_config() -> Epos4Config {
    Epos4Config::paper(EPOS4_NODE)
}

/// Power stage off, from any context, without locks or allocation.
pub fn drive_off() {
    #[cfg(feature = "drive-direct")]
    steering_ecu::chip::bridge::force_off();
    #[cfg(feature = "drive-epos4")]
    send_disable_raw();
}

/// "Disable voltage" to the EPOS4 through a free CAN1 transmit mailbox, waiting up to ~1 ms
/// (busy loop: interrupts are off) for the transmission.
#[cfg(feature = "drive-epos4")]
fn send_disable_raw() {
    use embassy_stm32::pac::CAN1;
    let Some(frame) = disable_voltage_frame(EPOS4_NODE) else {
        return;
    };
    let tsr = CAN1.tsr().read();
    let Some(mailbox) = (0..3).find(|&m| tsr.tme(m)) else {
        return;
    };
    let data = frame.data();
    let mut bytes = [0u8; 8];
    for (b, d) in bytes.iter_mut().zip(data) {
        *b = *d;
    }
    let tx = CAN1.tx(mailbox);
    tx.tdtr().write(|w| w.set_dlc(data.len() as u8));
    tx.tdlr()
        .write(|w| w.0 = u32::from_le_bytes([bytes[0], bytes[1], bytes[2], bytes[3]]));
    tx.tdhr()
        .write(|w| w.0 = u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]));
    tx.tir().write(|w| {
        w.set_stid(frame.id().raw());
        w.set_txrq(true);
    });
    // About 1 ms at 180 MHz (a few cycles per iteration): one 8-byte frame takes 0.13 ms at
    // 1 Mbit/s.
    for _ in 0..60_000 {
        if CAN1.tsr().read().tme(mailbox) {
            break;
        }
        cortex_m::asm::nop();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    cortex_m::interrupt::disable();
    drive_off();
    defmt::error!("panic, drive off: {}", defmt::Display2Format(info));
    // HardFault next: the probe shows the backtrace; the handler below keeps the drive off.
    cortex_m::asm::udf()
}

// The HardFault entry moves the stack pointer back to the top of the stack before the body
// runs: after a stack overflow (flip-link: the stack ran off the RAM start) a handler that
// pushed anything first would lock the core up with the drive still on. Why and how:
// `steering_ecu::chip::fault`; the emulated suite's `stack-overflow` run tests it.
#[allow(unsafe_code)]
mod hard_fault {
    steering_ecu::hard_fault_entry!(super::on_hard_fault);
}

extern "C" fn on_hard_fault() -> ! {
    drive_off();
    loop {
        cortex_m::asm::nop();
    }
}

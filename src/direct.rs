//! Direct drive's fast loop: what the firmware's 20 kHz interrupt does each PWM period, as one
//! pure step over the [`crate::ports`] traits, so host-sim runs the same code against the
//! plant.
//!
//! ```text
//!  ADC end of conversion (20 kHz, triggered by the PWM timer mid on-time)
//!    Hall code ----------> HallDecoder ------ count --+--> every 10th tick: Ecu::position_tick
//!                            | sector                 |        (2 kHz, current set-point)
//!    phase currents ---> winding current ------------>+--> Ecu::current_tick (PI, 20 A, 24 V)
//!                                                              | voltage, or None = off
//!                            commutate(voltage, supply) <------+
//!                                 |
//!                                 v
//!                            Bridge::apply (complementary PWM, dead time in hardware)
//! ```
//!
//! Supervisor watch: when the tasks have not called the ECU for [`SUPERVISOR_TIMEOUT_US`]
//! (a hung or starved task), the fast loop turns the bridge off by itself, without the state
//! machine, until they call again; the cascade then restarts at the measured angle.
//!
//! Hall faults: an impossible code (000, 111) or a jump of more than one sector switches the
//! bridge off for that period and keeps the last count; [`HALL_ERRORS_TO_FAULT`] in a row
//! latch [`crate::faults::Fault::Encoder`] (the motor angle is unusable) with the detail
//! `0x1_0000 + code`, code = [`HALL_INVALID_CODE`] + the Hall code, or [`HALL_JUMP`] + from x
//! 16 + to.

use crate::commutation::{BRIDGE_OFF, BridgeCommand, HallDecoder, HallError};
use crate::ecu::Ecu;
use crate::paper_mode::CURRENT_TICKS_PER_POSITION_TICK;
use crate::ports::{Bridge, CurrentSense, HallInputs};
use crate::units::{Amps, Volts};

/// Consecutive bad Hall samples (50 us each) that latch the fault.
pub const HALL_ERRORS_TO_FAULT: u8 = 3;
/// Fault code base of an impossible Hall code.
pub const HALL_INVALID_CODE: u16 = 0x100;
/// Fault code base of a Hall jump.
pub const HALL_JUMP: u16 = 0x200;
/// The fast loop turns the bridge off by itself when the supervisor (the tasks that tick the
/// state machine: reference receiver, encoder reader) has not called the ECU for this long, us
/// (5 ms). Both tasks call every 2 ms, so 5 ms is two missed calls of each plus
/// scheduling jitter; a stall longer than that is a hung or starved task, and the state
/// machine's timeouts (which need its calls) cannot act. The bridge stays off until the
/// supervisor calls again; the cascade then restarts at the measured angle.
pub const SUPERVISOR_TIMEOUT_US: u64 = 5_000;

/// The state the fast loop keeps between periods.
#[derive(Debug, Clone)]
pub struct FastLoop {
    hall: HallDecoder,
    supply: Volts,
    tick: u32,
    hall_errors: u8,
    last: BridgeCommand,
    /// The bridge is off because the supervisor stalled.
    supervisor_stalled: bool,
    supervisor_stalls: u16,
}

impl FastLoop {
    /// `phase_offset` matches the commutation table to the motor's wiring
    /// ([`HallDecoder::new`]); `supply` is the bridge's DC voltage (the duty is
    /// voltage / supply).
    pub fn new(phase_offset: u8, supply: Volts) -> Self {
        FastLoop {
            hall: HallDecoder::new(phase_offset),
            supply,
            tick: 0,
            hall_errors: 0,
            last: BRIDGE_OFF,
            supervisor_stalled: false,
            supervisor_stalls: 0,
        }
    }

    /// The measured supply voltage (e.g. from a divider, each position tick). A non-finite or
    /// non-positive value switches the bridge off until a good one comes.
    pub fn set_supply(&mut self, supply: Volts) {
        self.supply = supply;
    }

    pub fn hall(&self) -> &HallDecoder {
        &self.hall
    }

    /// How often the supervisor stalled and the fast loop turned the bridge off (saturating).
    pub fn supervisor_stalls(&self) -> u16 {
        self.supervisor_stalls
    }

    /// The bridge command of the last period.
    pub fn last_command(&self) -> BridgeCommand {
        self.last
    }

    /// One PWM period: read the Hall inputs and the phase currents, run the position loop on
    /// every 10th call and the current loop on every call, and set the bridge.
    pub fn run(
        &mut self,
        ecu: &mut Ecu,
        now_us: u64,
        hall: &mut impl HallInputs,
        sense: &mut impl CurrentSense,
        bridge: &mut impl Bridge,
    ) -> BridgeCommand {
        let command = self.step(ecu, now_us, hall.read(), sense.phase_currents());
        bridge.apply(&command);
        command
    }

    /// [`FastLoop::run`] on sampled values.
    pub fn step(
        &mut self,
        ecu: &mut Ecu,
        now_us: u64,
        hall_code: u8,
        phases: [Amps; 3],
    ) -> BridgeCommand {
        // Progress for the watchdog first: a period that ends early (a Hall error, a stalled
        // supervisor) is still the fast loop running, and those have their own outcomes.
        ecu.fast_loop_ran();
        let position_tick = self.tick.is_multiple_of(CURRENT_TICKS_PER_POSITION_TICK);
        self.tick = self.tick.wrapping_add(1);
        if let Err(e) = self.hall.update(hall_code) {
            self.hall_errors = self.hall_errors.saturating_add(1);
            if self.hall_errors >= HALL_ERRORS_TO_FAULT {
                let code = match e {
                    HallError::InvalidCode { code } => HALL_INVALID_CODE + u16::from(code),
                    HallError::Jump { from, to } => {
                        HALL_JUMP.saturating_add(u16::from(from) << 4 | u16::from(to))
                    }
                };
                let _ = ecu.on_hall_fault(now_us, code);
            }
            self.last = BRIDGE_OFF;
            return BRIDGE_OFF;
        }
        self.hall_errors = 0;
        let stale = ecu
            .supervisor_seen_us()
            .is_none_or(|t| now_us.saturating_sub(t) > SUPERVISOR_TIMEOUT_US);
        if stale {
            if !self.supervisor_stalled {
                self.supervisor_stalled = true;
                self.supervisor_stalls = self.supervisor_stalls.saturating_add(1);
            }
            self.last = BRIDGE_OFF;
            return BRIDGE_OFF;
        }
        if self.supervisor_stalled {
            self.supervisor_stalled = false;
            ecu.resync_cascade();
        }
        if position_tick {
            let _ = ecu.position_tick(self.hall.count());
        }
        let current = self
            .hall
            .winding_current([phases[0].0, phases[1].0, phases[2].0])
            .unwrap_or(f32::NAN);
        self.last = match ecu.current_tick(now_us, Amps(current)) {
            Some(voltage) => self.hall.commutate(voltage.0, self.supply.0),
            None => BRIDGE_OFF,
        };
        self.last
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::as_state::AsState;
    use crate::commutation::code_of;
    use crate::faults::Fault;
    use crate::protocol::{AliveCounter, ProtocolConfig, Reference};
    use crate::steering::DriveDemand;
    use crate::units::SteeringDeg;

    /// An ECU tracking 5 deg: AS Driving, a fresh reference and encoder sample; two frames,
    /// 10 ms apart, so the enable ramp (which starts at the column) has moved toward 5 deg.
    fn tracking_ecu(now_us: u64) -> Ecu {
        let mut ecu = Ecu::paper().unwrap();
        for k in 0..2u8 {
            let t = now_us.saturating_sub(10_000 * u64::from(1 - k));
            let frame = ProtocolConfig::default().encode_reference(&Reference {
                angle: SteeringDeg(5.0),
                as_state: AsState::Driving,
                counter: AliveCounter::wrapping(1 + k),
                clear_faults: false,
            });
            let _ = ecu.on_encoder(t, SteeringDeg(0.0));
            let out = ecu.on_reference_frame(t, &frame);
            assert_eq!(out.demand, DriveDemand::Track);
            // The position ticks of the period, as the fast loop takes them.
            for _ in 0..20 {
                let _ = ecu.position_tick(0);
            }
        }
        ecu
    }

    #[test]
    fn a_tracking_ecu_drives_two_legs_toward_the_reference() {
        let mut ecu = tracking_ecu(1_000);
        let mut fast = FastLoop::new(0, Volts(24.0));
        let mut driven = None;
        for i in 0..400u64 {
            let cmd = fast.step(&mut ecu, 1_000 + i * 50, code_of(0), [Amps::ZERO; 3]);
            if cmd != BRIDGE_OFF {
                driven = Some(cmd);
            }
        }
        let cmd = driven.expect("the bridge was driven");
        let v = fast.hall().terminal_voltage(&cmd, 24.0).unwrap();
        assert!(v > 0.0, "positive torque toward +5 deg, got {v} V");
    }

    #[test]
    fn bad_hall_samples_switch_off_at_once_and_latch_after_three() {
        let mut ecu = tracking_ecu(1_000);
        let mut fast = FastLoop::new(0, Volts(24.0));
        let _ = fast.step(&mut ecu, 1_050, code_of(0), [Amps::ZERO; 3]);
        for (i, code) in [0b000u8, 0b111].into_iter().enumerate() {
            let cmd = fast.step(&mut ecu, 1_100 + i as u64 * 50, code, [Amps::ZERO; 3]);
            assert_eq!(cmd, BRIDGE_OFF, "off on the bad sample itself");
            assert!(
                ecu.output().faults.is_empty(),
                "not latched before the third"
            );
        }
        // Jump of two sectors: the third bad sample in a row.
        let cmd = fast.step(&mut ecu, 1_200, code_of(2), [Amps::ZERO; 3]);
        assert_eq!(cmd, BRIDGE_OFF);
        let out = ecu.output();
        assert!(out.faults.contains(Fault::Encoder), "{:?}", out.faults);
        assert_eq!(out.demand, DriveDemand::Disabled);
        for i in 0..20u64 {
            let cmd = fast.step(&mut ecu, 1_250 + i * 50, code_of(0), [Amps::ZERO; 3]);
            assert_eq!(cmd, BRIDGE_OFF, "latched: stays off with good samples");
        }
    }

    #[test]
    fn a_bad_supply_or_current_never_drives() {
        let mut ecu = tracking_ecu(1_000);
        let mut fast = FastLoop::new(0, Volts(f32::NAN));
        for i in 0..40u64 {
            let cmd = fast.step(&mut ecu, 1_050 + i * 50, code_of(0), [Amps(f32::NAN); 3]);
            assert_eq!(cmd, BRIDGE_OFF);
        }
    }

    #[test]
    fn the_fast_loop_turns_the_bridge_off_when_the_supervisor_stops() {
        // Tracking 5 deg, the bridge driven; then the tasks stop (no tick, no frame, no
        // encoder sample) while the ADC interrupt keeps running.
        let mut ecu = tracking_ecu(1_000);
        let mut fast = FastLoop::new(0, Volts(24.0));
        let mut last_driven = None;
        for i in 0..400u64 {
            let now = 1_000 + i * 50;
            if fast.step(&mut ecu, now, code_of(0), [Amps::ZERO; 3]) != BRIDGE_OFF {
                last_driven = Some(now);
            }
        }
        let last = last_driven.expect("the bridge was driven");
        assert!(
            last <= 1_000 + SUPERVISOR_TIMEOUT_US,
            "driven {} us after the supervisor's last call",
            last - 1_000
        );
        // The supervisor ticks again: the bridge is driven again.
        let _ = ecu.tick(21_000);
        let driven = (0..40u64).any(|i| {
            fast.step(&mut ecu, 21_000 + i * 50, code_of(0), [Amps::ZERO; 3]) != BRIDGE_OFF
        });
        assert!(driven);
    }
}

//! The direct drive's three-phase bridge on TIM1: its PWM set-up with every switch off, and
//! [`force_off`], which the firmware's panic and HardFault handlers and the board suite call.
//!
//! Off means: the main output enable (MOE) cleared, the off-state selection for idle (OSSI)
//! set so the outputs drive their idle level instead of floating, every idle level low (all
//! six gates off), and the gate driver's enable pin (PC9) low.

use embassy_stm32::Peri;
use embassy_stm32::gpio::OutputType;
use embassy_stm32::pac;
use embassy_stm32::peripherals::{PA8, PA9, PA10, PB13, PB14, PB15, TIM1};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::Channel;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin, Ossi, Ossr};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::simple_pwm::PwmPin;

/// Dead time between a leg's high and low switch, TIM1 clock ticks: 90 at 180 MHz = 500 ns,
/// for gate drivers and MOSFETs of the 20 A class; check your bridge's datasheet.
pub const DEAD_TIME_TICKS: u16 = 90;

/// The bridge's timer and outputs (the wiring table of `src/FIRMWARE.md`): TIM1 CH1..3 on PA8, PA9,
/// PA10 (high sides), CH1N..3N on PB13, PB14, PB15 (low sides).
#[derive(Debug)]
pub struct Pins {
    pub tim: Peri<'static, TIM1>,
    pub ch1: Peri<'static, PA8>,
    pub ch1n: Peri<'static, PB13>,
    pub ch2: Peri<'static, PA9>,
    pub ch2n: Peri<'static, PB14>,
    pub ch3: Peri<'static, PA10>,
    pub ch3n: Peri<'static, PB15>,
}

/// TIM1 as the bridge at `frequency`, centre-aligned, with [`DEAD_TIME_TICKS`] and every
/// switch off: `ComplementaryPwm::new` sets MOE, which is cleared again here before any
/// channel is enabled; channels 1..3 at duty 0 and disabled. The caller enables what it drives
/// and sets MOE when its interrupt is armed.
pub fn pwm(pins: Pins, frequency: Hertz) -> ComplementaryPwm<'static, TIM1> {
    let mut pwm = ComplementaryPwm::new(
        pins.tim,
        Some(PwmPin::new(pins.ch1, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(pins.ch1n, OutputType::PushPull)),
        Some(PwmPin::new(pins.ch2, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(pins.ch2n, OutputType::PushPull)),
        Some(PwmPin::new(pins.ch3, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(pins.ch3n, OutputType::PushPull)),
        None,
        None,
        frequency,
        CountingMode::CenterAlignedDownInterrupts,
    );
    force_off();
    pwm.set_off_state_selection_idle(Ossi::IDLE_LEVEL);
    pwm.set_off_state_selection_run(Ossr::IDLE_LEVEL);
    pwm.set_dead_time(DEAD_TIME_TICKS);
    for ch in [Channel::Ch1, Channel::Ch2, Channel::Ch3] {
        pwm.set_duty(ch, 0);
        pwm.disable(ch);
    }
    pwm
}

/// Every switch off at once, from any context: idle levels low, OSSI, MOE cleared, gate
/// driver disabled. Register writes only (no lock, no state): callable from the panic and
/// HardFault handlers whatever was held when they hit, and before [`pwm`] ran.
pub fn force_off() {
    pac::TIM1.cr2().modify(|w| {
        for ch in 0..3 {
            w.set_ois(ch, false);
            w.set_oisn(ch, false);
        }
    });
    pac::TIM1.bdtr().modify(|w| {
        w.set_ossi(pac::timer::vals::Ossi::IDLE_LEVEL);
        w.set_moe(false);
    });
    // PC9 low through the set/reset register: a single write, whatever else GPIOC does.
    pac::GPIOC.bsrr().write(|w| w.set_br(9, true));
}

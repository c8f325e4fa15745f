//! Direct drive on the chip (feature `drive-direct`): the three-phase bridge on TIM1, the phase
//! currents on ADC1 triggered by TIM1, the Hall sensors on GPIOC, and the 20 kHz fast loop in
//! the ADC interrupt at the highest priority. The loop itself is the lib's
//! [`steering_ecu::direct::FastLoop`] (tested in host-sim); this file only moves bits.
//!
//! Timing of one 50 us PWM period (TIM1 centre-aligned, counting 0 -> ARR -> 0):
//!
//! ```text
//!  CNT   0 ......... ARR ......... 0
//!  high  ON    (CNT < CCRx)   ON        PWM mode 1: the high side conducts around CNT = 0
//!  low      ---ON around ARR---          and the low side (complementary, dead time) around
//!  CC4          ^ CNT = ARR - 1 counting down: ADC1 injected trigger (3 phase currents)
//!  ADC IRQ         ^ JEOC: Hall code + currents -> FastLoop -> CCR1..3 and CCER for the next period
//! ```
//!
//! The low-side shunts carry the phase currents only while the low switches conduct, so the
//! duty is capped at [`MAX_DUTY`] to keep that window wider than the three conversions.
//!
//! Outputs come up off: the TIM1 set-up and the off-state are the lib's
//! [`steering_ecu::chip::bridge`] (shared with the board suite, which checks them on the chip);
//! the gate driver's enable pin starts low and goes high only once the interrupt is armed. The
//! panic and HardFault handlers call the lib's `force_off`.

use core::cell::RefCell;
use embassy_stm32::Peri;
use embassy_stm32::adc::{Adc, AdcChannel, Exten, SampleTime};
use embassy_stm32::gpio::{Input, Level, Output, Pull, Speed};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use embassy_stm32::pac;
use embassy_stm32::peripherals::{ADC1, PA0, PA1, PA4, PC6, PC7, PC8, PC9, TIM1};
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::Channel;
use embassy_stm32::timer::complementary_pwm::ComplementaryPwm;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::Instant;
use static_cell::StaticCell;
use steering_ecu::chip::bridge::{self as tim1_bridge, DEAD_TIME_TICKS};
use steering_ecu::commutation::{BRIDGE_OFF, BridgeCommand, Leg};
use steering_ecu::direct::FastLoop;
use steering_ecu::paper_mode::CURRENT_LOOP_HZ;
use steering_ecu::ports::{Bridge, CurrentSense, HallInputs};
use steering_ecu::tasks::SharedEcu;
use steering_ecu::units::{Amps, Volts};

/// Bridge supply, V (Table 2: 24 V). A measured value would go to `FastLoop::set_supply`.
const SUPPLY_V: f32 = 24.0;
/// Duty cap that leaves the low-side shunts a sampling window (3 x 1.2 us conversions at
/// 22.5 MHz ADC clock, 15-cycle sampling) in every 50 us period: 0.92 x 24 V = 22 V at most.
const MAX_DUTY: f32 = 0.92;
/// Rotates the commutation table to the motor's wiring (see `steering_ecu::commutation`).
const HALL_PHASE_OFFSET: u8 = 0;
/// Current sense: bidirectional amplifiers centred at half of the 3.3 V ADC range; full scale
/// +-25 A (e.g. a 2 mOhm shunt with a gain of 33). Adjust to the board.
const CURRENT_ZERO_COUNTS: f32 = 2048.0;
const AMPS_PER_COUNT: f32 = 25.0 / 2048.0;

/// The pins and peripherals of the direct drive (the wiring table of `src/FIRMWARE.md`).
pub struct Pins {
    /// TIM1 and its six outputs.
    pub bridge: tim1_bridge::Pins,
    /// Gate-driver enable, active high.
    pub enable: Peri<'static, PC9>,
    /// Hall sensors H1, H2, H3 (open collector: pulled up here).
    pub hall: (Peri<'static, PC6>, Peri<'static, PC7>, Peri<'static, PC8>),
    pub adc: Peri<'static, ADC1>,
    /// Phase currents A, B, C (ADC1 IN0, IN1, IN4; Arduino A0, A1, A2).
    pub sense: (Peri<'static, PA0>, Peri<'static, PA1>, Peri<'static, PA4>),
}

/// What the interrupt needs: the fast loop's state and the ECU.
static FAST: Mutex<CriticalSectionRawMutex, RefCell<Option<(FastLoop, &'static SharedEcu)>>> =
    Mutex::new(RefCell::new(None));
/// Drivers kept alive for ever (dropping them would reconfigure the pins).
static PWM: StaticCell<ComplementaryPwm<'static, TIM1>> = StaticCell::new();
static HALLS: StaticCell<[Input<'static>; 3]> = StaticCell::new();
static ENABLE: StaticCell<Output<'static>> = StaticCell::new();

/// Sets the bridge up with every switch off, arms the ADC interrupt and enables the gate
/// driver. From here the interrupt runs the loops; the state machine's demand decides whether
/// any leg switches.
pub fn start(ecu: &'static SharedEcu, pins: Pins) {
    let enable = ENABLE.init(Output::new(pins.enable, Level::Low, Speed::Low));
    let pwm = PWM.init(tim1_bridge::pwm(pins.bridge, Hertz(CURRENT_LOOP_HZ)));
    // CC4 just below the top, counting down: the centre of the low-side on-time.
    let max = pwm.get_max_duty();
    pwm.set_duty(Channel::Ch4, max.saturating_sub(1));

    HALLS.init([
        Input::new(pins.hall.0, Pull::Up),
        Input::new(pins.hall.1, Pull::Up),
        Input::new(pins.hall.2, Pull::Up),
    ]);

    let adc = Adc::new(pins.adc);
    let injected = adc.setup_injected_conversions(
        [
            (pins.sense.0.degrade_adc(), SampleTime::CYCLES15),
            (pins.sense.1.degrade_adc(), SampleTime::CYCLES15),
            (pins.sense.2.degrade_adc(), SampleTime::CYCLES15),
        ],
        embassy_stm32::triggers::TIM1_CH4,
        Exten::RISING_EDGE,
        true,
    );
    // Dropping it would stop the conversions.
    core::mem::forget(injected);

    FAST.lock(|f| {
        f.replace(Some((
            FastLoop::new(HALL_PHASE_OFFSET, Volts(SUPPLY_V)),
            ecu,
        )))
    });
    interrupt::ADC.set_priority(Priority::P0);
    // SAFETY: the handler below uses only FAST (initialised above), the ECU behind its
    // critical-section mutex and the TIM1/ADC1/GPIOC registers this module owns.
    #[allow(unsafe_code)]
    unsafe {
        interrupt::ADC.enable()
    };
    pwm.set_master_output_enable(true);
    enable.set_high();
    defmt::info!(
        "bridge: {=u32} Hz PWM, ARR {=u32}, dead time {=u16} ticks, max duty {=f32}",
        CURRENT_LOOP_HZ,
        max,
        DEAD_TIME_TICKS,
        MAX_DUTY
    );
}

/// The Hall code H3 H2 H1 from PC8, PC7, PC6.
struct Halls;
impl HallInputs for Halls {
    fn read(&mut self) -> u8 {
        let idr = pac::GPIOC.idr().read();
        let bit = |n: usize| u8::from(idr.idr(n) == pac::gpio::vals::Idr::HIGH);
        bit(6) | bit(7) << 1 | bit(8) << 2
    }
}

/// The injected conversions of this period, in amps.
struct Sense([u16; 3]);
impl CurrentSense for Sense {
    fn phase_currents(&mut self) -> [Amps; 3] {
        self.0
            .map(|raw| Amps((f32::from(raw) - CURRENT_ZERO_COUNTS) * AMPS_PER_COUNT))
    }
}

/// TIM1 channels 1..3 as the bridge legs A, B, C.
struct Tim1;
impl Bridge for Tim1 {
    fn apply(&mut self, command: &BridgeCommand) {
        let tim = pac::TIM1;
        let top = f32::from(tim.arr().read().arr());
        let mut ccer = tim.ccer().read();
        for (i, leg) in command.iter().enumerate() {
            let (ccr, on) = match *leg {
                // `as` saturates; NaN -> 0 (the lib never sends one).
                Leg::Pwm(duty) => ((duty.clamp(0.0, MAX_DUTY) * top) as u16, true),
                // CCR = 0: the high side never conducts, the complementary low side always.
                Leg::Low => (0, true),
                Leg::Off => (0, false),
            };
            tim.ccr(i).write(|w| w.set_ccr(ccr));
            ccer.set_cce(i, on);
            ccer.set_ccne(i, on);
        }
        tim.ccer().write_value(ccer);
    }
}

#[interrupt]
fn ADC() {
    let adc = pac::ADC1;
    if !adc.sr().read().jeoc() {
        return;
    }
    let raw = [
        adc.jdr(0).read().jdata(),
        adc.jdr(1).read().jdata(),
        adc.jdr(2).read().jdata(),
    ];
    adc.sr().modify(|w| {
        w.set_jeoc(false);
        w.set_jstrt(false);
    });
    let now_us = Instant::now().as_micros();
    let mut ran = false;
    FAST.lock(|f| {
        let Ok(mut slot) = f.try_borrow_mut() else {
            return;
        };
        let Some((fast, ecu)) = slot.as_mut() else {
            return;
        };
        ecu.lock(|e| {
            // Thread-mode code borrows the ECU only inside this same critical section, so
            // the borrow cannot be taken here; if it ever were, this period stays off.
            if let Ok(mut e) = e.try_borrow_mut() {
                fast.run(&mut e, now_us, &mut Halls, &mut Sense(raw), &mut Tim1);
                ran = true;
            }
        });
    });
    if !ran {
        Tim1.apply(&BRIDGE_OFF);
    }
}

//! Firmware entry: the one file that names the chip. It sets the clocks, logs over defmt-rtt and
//! spawns the tasks; the control logic lives in the hardware-free lib.
//!
//! Built for `thumbv7em-none-eabihf` only (`cargo fw`). The HAL, executor and logger are
//! target-only dependencies, so on the host this file compiles to a stub that says how to build
//! the firmware, and `cargo test` never sees Embassy.
#![cfg_attr(target_os = "none", no_std, no_main)]

#[cfg(not(target_os = "none"))]
fn main() {
    println!(
        "steering-ecu {}: this is the host stub. The firmware is built with \
         `cargo build --release --target thumbv7em-none-eabihf --bin steering-ecu` (alias: `cargo fw`).",
        env!("CARGO_PKG_VERSION")
    );
}

#[cfg(target_os = "none")]
mod firmware {
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_time::{Duration, Ticker};
    use panic_probe as _;

    /// Rate of the loop that will run the control step (the later issue hangs CAN and the EPOS4
    /// off it).
    const CONTROL_RATE_HZ: u64 = 100;
    /// Control ticks between two heartbeat log lines: one per second.
    const TICKS_PER_HEARTBEAT: u32 = 100;

    #[cfg(feature = "stm32f446re")]
    const CHIP: &str = "STM32F446RE";
    #[cfg(feature = "stm32f405rg")]
    const CHIP: &str = "STM32F405RG";
    #[cfg(feature = "stm32f407vg")]
    const CHIP: &str = "STM32F407VG";

    /// NUCLEO-F446RE: the ST-LINK's MCO feeds 8 MHz into OSC_IN (HSE bypass; the board's default
    /// solder bridges), PLL to the F446's 180 MHz maximum. embassy-stm32 switches on the
    /// over-drive that 180 MHz needs and sets five flash wait states.
    #[cfg(feature = "stm32f446re")]
    fn clock_config() -> embassy_stm32::Config {
        use embassy_stm32::rcc::{
            AHBPrescaler, APBPrescaler, Hse, HseMode, Pll, PllMul, PllPDiv, PllPreDiv, PllSource,
            Sysclk,
        };
        use embassy_stm32::time::Hertz;

        let mut config = embassy_stm32::Config::default();
        config.rcc.hse = Some(Hse {
            freq: Hertz::mhz(8),
            mode: HseMode::Bypass,
        });
        config.rcc.pll_src = PllSource::HSE;
        config.rcc.pll = Some(Pll {
            // 2 MHz into the PLL: the low-jitter end of the 1-2 MHz input range (RM0390 6.3.2).
            prediv: PllPreDiv::DIV4,
            // 360 MHz VCO, inside 100-432 MHz.
            mul: PllMul::MUL180,
            divp: Some(PllPDiv::DIV2),
            // 360 MHz has no integer divisor to USB's 48 MHz; the F446 would take it from PLLSAI.
            divq: None,
            divr: None,
        });
        config.rcc.sys = Sysclk::PLL1_P;
        config.rcc.ahb_pre = AHBPrescaler::DIV1;
        // APB1 at its 45 MHz maximum; bxCAN is clocked from it (1 Mbit/s = 3 x 15 tq).
        config.rcc.apb1_pre = APBPrescaler::DIV4;
        // APB2 at its 90 MHz maximum.
        config.rcc.apb2_pre = APBPrescaler::DIV2;
        config
    }

    /// F405/F407: clocked from the internal 16 MHz HSI, because the board (and whether its HSE is
    /// a crystal or a bypassed clock) is not fixed yet; PLL to the F40x's 168 MHz maximum. The
    /// HSI drifts by percents over temperature, more than CAN's bit timing tolerates: move to the
    /// board's HSE before CAN runs on these parts.
    #[cfg(any(feature = "stm32f405rg", feature = "stm32f407vg"))]
    fn clock_config() -> embassy_stm32::Config {
        use embassy_stm32::rcc::{
            AHBPrescaler, APBPrescaler, Pll, PllMul, PllPDiv, PllPreDiv, PllQDiv, PllSource, Sysclk,
        };

        let mut config = embassy_stm32::Config::default();
        config.rcc.pll_src = PllSource::HSI;
        config.rcc.pll = Some(Pll {
            // 2 MHz into the PLL (RM0090 6.3.2), 336 MHz VCO.
            prediv: PllPreDiv::DIV8,
            mul: PllMul::MUL168,
            divp: Some(PllPDiv::DIV2),
            // 48 MHz for USB OTG FS, SDIO and the RNG.
            divq: Some(PllQDiv::DIV7),
            divr: None,
        });
        config.rcc.sys = Sysclk::PLL1_P;
        config.rcc.ahb_pre = AHBPrescaler::DIV1;
        // APB1 at its 42 MHz maximum (bxCAN), APB2 at its 84 MHz maximum.
        config.rcc.apb1_pre = APBPrescaler::DIV4;
        config.rcc.apb2_pre = APBPrescaler::DIV2;
        config
    }

    // No `allow(unsafe_code)` needed: the macro's own `unsafe` (cortex-m-rt's `#[entry]`, the
    // executor made `'static`) comes from an external crate, which the lint does not look into.
    #[embassy_executor::main]
    async fn main(spawner: Spawner) {
        let peripherals = embassy_stm32::init(clock_config());
        let clocks = embassy_stm32::rcc::clocks(&peripherals.RCC);
        defmt::info!(
            "steering-ecu {=str} on {=str}: sysclk {}, pclk1 {}",
            env!("CARGO_PKG_VERSION"),
            CHIP,
            clocks.sys.to_hertz(),
            clocks.pclk1.to_hertz(),
        );

        // The pool holds exactly one heartbeat task, so this fails only if spawned twice.
        spawner.spawn(defmt::unwrap!(heartbeat()));
    }

    /// Ticks at the control rate and logs once per second. The `Ticker` schedules each tick from
    /// the previous deadline, not from when the task woke, so a late poll does not shift the rate.
    #[embassy_executor::task]
    async fn heartbeat() {
        let mut ticker = Ticker::every(Duration::from_hz(CONTROL_RATE_HZ));
        let mut ticks: u32 = 0;
        let mut seconds: u32 = 0;
        loop {
            ticker.next().await;
            ticks += 1;
            if ticks == TICKS_PER_HEARTBEAT {
                ticks = 0;
                seconds = seconds.wrapping_add(1);
                defmt::info!("heartbeat: {=u32} s", seconds);
            }
        }
    }
}

//! The NUCLEO-F446RE's clock tree, shared by the firmware (`src/main.rs`) and the board suite
//! (`hil-tests/tests/board.rs`, which includes this file by path), so the cycle budgets the
//! suite checks are measured at the clocks the firmware runs.

/// NUCLEO-F446RE: the ST-LINK's MCO feeds 8 MHz into OSC_IN (HSE bypass; the board's default
/// solder bridges), PLL to the F446's 180 MHz maximum. embassy-stm32 switches on the
/// over-drive that 180 MHz needs and sets five flash wait states.
pub fn clock_config() -> embassy_stm32::Config {
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

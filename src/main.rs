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

#[cfg(all(
    target_os = "none",
    not(any(feature = "drive-epos4", feature = "drive-direct"))
))]
compile_error!("pick the drive mode: feature `drive-epos4` (default) or `drive-direct`");
#[cfg(all(target_os = "none", feature = "drive-epos4", feature = "drive-direct"))]
compile_error!(
    "features `drive-epos4` and `drive-direct` exclude each other: build the direct mode with \
     `--no-default-features --features stm32f446re,drive-direct`"
);

#[cfg(target_os = "none")]
mod firmware {
    use core::cell::RefCell;
    use defmt_rtt as _;
    use embassy_executor::Spawner;
    use embassy_futures::select::{Either, select};
    use embassy_stm32::can::{
        self, Can, Id, Rx0InterruptHandler, Rx1InterruptHandler, SceInterruptHandler,
        TxInterruptHandler,
    };
    use embassy_stm32::gpio::{Level, Output, Speed};
    use embassy_stm32::mode::Blocking;
    use embassy_stm32::peripherals::CAN1;
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use embassy_stm32::wdg::IndependentWatchdog;
    use embassy_time::{Duration, Ticker, Timer};
    use static_cell::StaticCell;
    use steering_ecu::amt20;
    use steering_ecu::can::{Frame, StandardId};
    use steering_ecu::controller::ControllerKind;
    use steering_ecu::ecu::{DriveChoice, Ecu, EcuBuild};
    use steering_ecu::ports::{BusError, CanRx, CanTx, ColumnEncoderPort, EncoderError};
    use steering_ecu::sensors::ColumnEncoder;
    use steering_ecu::tasks::{self, FirmwareRoutes, FrameQueue, RouterCounters, SharedEcu};

    #[cfg(feature = "drive-direct")]
    mod bridge;
    mod safety;
    mod stack;

    /// The ECU's shared state, made once at start-up.
    static ECU: StaticCell<SharedEcu> = StaticCell::new();
    /// The steering controller: `Paper` (the paper's EPOS4 cascade, Table 3) or `Ecu` (the
    /// ECU's own, `steering_ecu::ecu_mode`: about twice the bandwidth on the paper's plant; see
    /// host-sim/README.md, "ECU mode"). In EPOS4 mode `Ecu` also writes the model feedforward.
    const CONTROLLER: ControllerKind = ControllerKind::Paper;
    /// Raw column-encoder word at straight ahead; set at bring-up (the bring-up list, host-sim/steer-can/README.md).
    const COLUMN_ZERO_RAW: u16 = 0;
    /// AMT20 SPI clock: the datasheet allows up to 1 MHz; 500 kHz leaves margin for the cable
    /// along the column.
    const ENCODER_SPI_HZ: u32 = 500_000;
    /// Chip select released between bytes for at least this long (AMT20 datasheet: 20 us).
    const ENCODER_BYTE_GAP_US: u64 = 25;

    /// How often a silent bus is checked for bus-off, ms. A bus-off controller receives
    /// nothing, so the check cannot wait for a frame.
    const BUS_OFF_POLL_MS: u64 = 5;

    embassy_stm32::bind_interrupts!(struct CanIrqs {
        CAN1_RX0 => Rx0InterruptHandler<CAN1>;
        CAN1_RX1 => Rx1InterruptHandler<CAN1>;
        CAN1_SCE => SceInterruptHandler<CAN1>;
        CAN1_TX => TxInterruptHandler<CAN1>;
    });

    /// Frames for the reference task (the vehicle computer's frames).
    static REFERENCE_FRAMES: FrameQueue = FrameQueue::new();
    /// Frames for the EPOS4 link (PDOs, SDO responses, heartbeat, EMCY).
    static DRIVE_FRAMES: FrameQueue = FrameQueue::new();
    /// Frames the tasks want on the bus.
    static TX_FRAMES: FrameQueue = FrameQueue::new();

    /// The bxCAN receive half as the core's [`CanRx`]: standard data frames only (extended
    /// frames are not part of this bus's protocol and are skipped).
    struct BxRx<'d>(can::CanRx<'d>);

    impl CanRx for BxRx<'_> {
        async fn receive(&mut self) -> Result<Frame, BusError> {
            loop {
                // Automatic bus-off recovery is off (bxCAN default), so the flag stays set
                // until the fault is handled: it is a latched fault of the state machine.
                if embassy_stm32::pac::CAN1.esr().read().boff() {
                    return Err(BusError::BusOff);
                }
                let timeout = Timer::after(Duration::from_millis(BUS_OFF_POLL_MS));
                match select(self.0.read(), timeout).await {
                    Either::First(Ok(envelope)) => {
                        let frame = &envelope.frame;
                        if let Id::Standard(id) = frame.id() {
                            let core = StandardId::new(id.as_raw())
                                .and_then(|id| Frame::new(id, frame.data()));
                            if let Some(core) = core {
                                return Ok(core);
                            }
                        }
                    }
                    Either::First(Err(_)) => return Err(BusError::Other),
                    Either::Second(()) => {}
                }
            }
        }
    }

    /// The bxCAN transmit half as the core's [`CanTx`].
    struct BxTx<'d>(can::CanTx<'d>);

    impl CanTx for BxTx<'_> {
        async fn transmit(&mut self, frame: &Frame) -> Result<(), BusError> {
            let hw = can::Frame::new_standard(frame.id().raw(), frame.data())
                .map_err(|_| BusError::Other)?;
            self.0.write(&hw).await;
            Ok(())
        }
    }

    /// The AMT20 on SPI1 with a GPIO chip select, one byte per select as the encoder wants.
    struct Amt20Port<'d> {
        spi: Spi<'d, Blocking, spi::mode::Master>,
        cs: Output<'d>,
    }

    impl ColumnEncoderPort for Amt20Port<'_> {
        async fn read(&mut self) -> Result<u16, EncoderError> {
            let mut read = amt20::Read::new();
            let mut byte = read.first_byte();
            loop {
                self.cs.set_low();
                let mut buf = [byte];
                let sent = self.spi.blocking_transfer_in_place(&mut buf);
                self.cs.set_high();
                sent.map_err(|_| EncoderError::NoResponse)?;
                Timer::after(Duration::from_micros(ENCODER_BYTE_GAP_US)).await;
                match read.on_received(buf[0]) {
                    amt20::Next::Transfer(next) => byte = next,
                    amt20::Next::Position(raw) => return Ok(raw),
                    amt20::Next::Failed(e) => return Err(e),
                }
            }
        }
    }

    #[embassy_executor::task]
    async fn reference_task(ecu: &'static SharedEcu) {
        tasks::reference_task(REFERENCE_FRAMES.receiver(), ecu).await
    }

    #[embassy_executor::task]
    async fn status_task(ecu: &'static SharedEcu) {
        tasks::status_task(TX_FRAMES.sender(), ecu).await
    }

    #[cfg(feature = "drive-epos4")]
    #[embassy_executor::task]
    async fn drive_task(ecu: &'static SharedEcu) {
        tasks::drive_task(DRIVE_FRAMES.receiver(), TX_FRAMES.sender(), ecu).await
    }

    /// The chip's independent watchdog, started here and fed only through the library's feed
    /// gate (`steering_ecu::watchdog`): when the supervisor tasks or the fast loop stop, the
    /// feeding stops and the IWDG resets the MCU within 68..188 ms (the LSI's spread), which
    /// comes up with the drive off.
    #[embassy_executor::task]
    async fn watchdog_task(
        mut wdg: IndependentWatchdog<'static, embassy_stm32::peripherals::IWDG>,
        ecu: &'static SharedEcu,
    ) {
        wdg.unleash();
        tasks::watchdog_task(ecu, || wdg.pet()).await
    }

    #[embassy_executor::task]
    async fn encoder_task(mut port: Amt20Port<'static>, ecu: &'static SharedEcu) {
        tasks::encoder_task(
            &mut port,
            ColumnEncoder {
                zero_raw: COLUMN_ZERO_RAW,
            },
            ecu,
        )
        .await
    }

    /// Rate of the loop that runs the control step (CAN and the EPOS4 hang off it).
    const CONTROL_RATE_HZ: u64 = 100;
    /// Control ticks between two heartbeat log lines: one per second.
    const TICKS_PER_HEARTBEAT: u32 = 100;

    #[cfg(feature = "stm32f446re")]
    const CHIP: &str = "STM32F446RE";
    #[cfg(feature = "stm32f405rg")]
    const CHIP: &str = "STM32F405RG";
    #[cfg(feature = "stm32f407vg")]
    const CHIP: &str = "STM32F407VG";

    #[cfg(feature = "stm32f446re")]
    mod clock_f446;
    #[cfg(feature = "stm32f446re")]
    use clock_f446::clock_config;

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
        // Before anything else runs deeper than here: what the stack reaches from now on is
        // what `stack_task` reports.
        stack::paint();
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

        // Start-up only: the defaults are valid by construction (tested on the host).
        #[cfg(feature = "drive-epos4")]
        let ecu: &'static SharedEcu = {
            let config = safety::epos4_config();
            let now = embassy_time::Instant::now().as_micros();
            defmt::info!(
                "drive: EPOS4 node {=u8}, CSP, controller {}",
                config.node.raw(),
                CONTROLLER
            );
            ECU.init(SharedEcu::new(RefCell::new(defmt::unwrap!(Ecu::build(
                EcuBuild::new(CONTROLLER, DriveChoice::Epos4(config)),
                now
            )))))
        };
        #[cfg(feature = "drive-direct")]
        let ecu: &'static SharedEcu = {
            defmt::info!(
                "drive: direct, three-phase bridge on TIM1, controller {}",
                CONTROLLER
            );
            ECU.init(SharedEcu::new(RefCell::new(defmt::unwrap!(Ecu::build(
                EcuBuild::new(CONTROLLER, DriveChoice::Direct),
                embassy_time::Instant::now().as_micros()
            )))))
        };
        spawner.spawn(defmt::unwrap!(reference_task(ecu)));
        spawner.spawn(defmt::unwrap!(status_task(ecu)));
        spawner.spawn(defmt::unwrap!(stack_task(ecu)));
        #[cfg(feature = "drive-epos4")]
        spawner.spawn(defmt::unwrap!(drive_task(ecu)));
        #[cfg(feature = "drive-direct")]
        bridge::start(
            ecu,
            bridge::Pins {
                bridge: steering_ecu::chip::bridge::Pins {
                    tim: peripherals.TIM1,
                    ch1: peripherals.PA8,
                    ch1n: peripherals.PB13,
                    ch2: peripherals.PA9,
                    ch2n: peripherals.PB14,
                    ch3: peripherals.PA10,
                    ch3n: peripherals.PB15,
                },
                enable: peripherals.PC9,
                hall: (peripherals.PC6, peripherals.PC7, peripherals.PC8),
                adc: peripherals.ADC1,
                sense: (peripherals.PA0, peripherals.PA1, peripherals.PA4),
            },
        );

        // AMT20 on SPI1: PA5 SCK, PA6 MISO, PA7 MOSI (Arduino D13/D12/D11), CS on PB6 (D10).
        let mut spi_config = spi::Config::default();
        spi_config.frequency = Hertz(ENCODER_SPI_HZ);
        let spi = Spi::new_blocking(
            peripherals.SPI1,
            peripherals.PA5,
            peripherals.PA7,
            peripherals.PA6,
            spi_config,
        );
        let cs = Output::new(peripherals.PB6, Level::High, Speed::VeryHigh);
        spawner.spawn(defmt::unwrap!(encoder_task(Amt20Port { spi, cs }, ecu)));

        // Last, once every half the gate watches has been started.
        let wdg = IndependentWatchdog::new(
            peripherals.IWDG,
            steering_ecu::watchdog::WATCHDOG_TIMEOUT_US,
        );
        spawner.spawn(defmt::unwrap!(watchdog_task(wdg, ecu)));
        defmt::info!(
            "IWDG: {=u32} us nominal, fed when the supervisor and the fast loop both ran",
            steering_ecu::watchdog::WATCHDOG_TIMEOUT_US
        );

        // CAN1 on PA11 (RX) / PA12 (TX): the Nucleo's morpho pins to the transceiver.
        let mut can = Can::new(
            peripherals.CAN1,
            peripherals.PA11,
            peripherals.PA12,
            CanIrqs,
        );
        steering_ecu::chip::can::configure(&mut can);
        can.enable().await;
        defmt::info!("CAN1 up at {=u32} bit/s", steering_ecu::chip::can::BITRATE);

        // `main` keeps the peripheral alive (dropping `Can` would shut it down) and runs its
        // two halves for ever.
        let (tx, rx) = can.split();
        let mut rx = BxRx(rx);
        let mut tx = BxTx(tx);
        let receive = async {
            let mut counters = RouterCounters::default();
            let queues = [REFERENCE_FRAMES.sender(), DRIVE_FRAMES.sender()];
            let end = tasks::receive_task(
                &mut rx,
                &FirmwareRoutes,
                &queues,
                &mut counters,
                ecu,
                || embassy_stm32::pac::CAN1.esr().read().tec(),
            )
            .await;
            defmt::error!("CAN receive stopped: {} (faults latched)", end);
        };
        let transmit = async {
            loop {
                let frame = TX_FRAMES.receive().await;
                if let Err(e) = tx.transmit(&frame).await {
                    defmt::warn!("CAN transmit failed: {}", e);
                }
            }
        };
        embassy_futures::join::join(receive, transmit).await;
        loop {
            // Bus-off: stay here with the bus down; the state machine has the fault.
            Timer::after(Duration::from_secs(1)).await;
        }
    }

    /// How often the stack's high-water mark is measured (a scan of the free stack).
    const STACK_CHECK_PERIOD: Duration = Duration::from_secs(1);

    /// Measures the stack's high-water mark every [`STACK_CHECK_PERIOD`] and hands it to the
    /// ECU, which reports it on the diagnostic frame (0x103, counter page 5).
    #[embassy_executor::task]
    async fn stack_task(ecu: &'static SharedEcu) {
        let mut ticker = Ticker::every(STACK_CHECK_PERIOD);
        loop {
            ticker.next().await;
            let usage = stack::usage();
            ecu.lock(|e| e.borrow_mut().set_stack_usage(usage));
        }
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

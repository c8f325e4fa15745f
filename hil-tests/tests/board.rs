//! The on-board suite: NUCLEO-F446RE at 180 MHz, flashed and run by probe-rs through
//! embedded-test (one reset per test). Wiring and the command: `../README.md`.
//!
//! | test | checks | bound |
//! |---|---|---|
//! | `can_loopback_*` | bxCAN in silent loopback: reference and status frames out and back through the codec | every frame back unchanged, round trip <= 300 us |
//! | `control_steps_*` | the golden replays (`../vectors`) on the chip, timed with DWT | bit-exact; current tick <= 450 cycles, position tick <= 4500 |
//! | `pwm_*` | TIM1 complementary outputs: off at start, off on a fault, off from the panic handler | pins low, MOE clear |
//! | `reference_timeout_*` | the ECU on the real clock after the frames stop | hold at 30 ms, fault at 130 ms, each within 1 ms |
//! | `spi_encoder_*` | the AMT20 over SPI1 | every read valid and steady; skipped when no encoder answers |
#![no_std]
#![no_main]

use defmt_rtt as _;
use embassy_stm32::peripherals::CAN1;
use embassy_stm32::{bind_interrupts, can};

bind_interrupts!(struct CanIrqs {
    CAN1_RX0 => can::Rx0InterruptHandler<CAN1>;
    CAN1_RX1 => can::Rx1InterruptHandler<CAN1>;
    CAN1_SCE => can::SceInterruptHandler<CAN1>;
    CAN1_TX => can::TxInterruptHandler<CAN1>;
});

/// The core clock the budgets are set at (the firmware's `clock_config`, src/main.rs).
const CORE_HZ: u32 = 180_000_000;

/// The firmware's clock tree on the NUCLEO-F446RE, from the firmware's own source: 8 MHz from
/// the ST-LINK (HSE bypass), PLL to 180 MHz, APB1 45 MHz (bxCAN), APB2 90 MHz (TIM1 at 180 MHz).
#[path = "../../src/firmware/clock_f446.rs"]
mod clock_f446;
use clock_f446::clock_config;

/// The bridge outputs: TIM1 CH1-3 on PA8/PA9/PA10, CH1N-3N on PB13/PB14/PB15 (morpho pins; the
/// Arduino PA7 is the encoder's MOSI). Set up and switched off by the firmware's own code
/// (`steering_ecu::chip::bridge`); this module only reads them back.
mod bridge {
    use embassy_stm32::pac;
    pub use steering_ecu::chip::bridge::force_off;

    /// Every output at its level now: (CH1, CH1N, CH2, CH2N, CH3, CH3N) as read back from the
    /// pins' input data registers.
    pub fn levels() -> [bool; 6] {
        let a = pac::GPIOA.idr().read();
        let b = pac::GPIOB.idr().read();
        let high = pac::gpio::vals::Idr::HIGH;
        [
            a.idr(8) == high,
            b.idr(13) == high,
            a.idr(9) == high,
            b.idr(14) == high,
            a.idr(10) == high,
            b.idr(15) == high,
        ]
    }

    pub fn main_output_enabled() -> bool {
        pac::TIM1.bdtr().read().moe()
    }

    /// All six read low for `samples` reads in a row.
    pub fn stays_low(samples: u32) -> bool {
        (0..samples).all(|_| levels() == [false; 6])
    }
}

/// The panic handler of this suite does what the firmware's does: outputs off first, with the
/// firmware's `force_off`. It then
/// checks them: off -> the panic is reported (semihosting abort), which `pwm_off_on_panic`
/// expects; still on -> a normal exit, so that `should_panic` test fails.
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    bridge::force_off();
    let off = !bridge::main_output_enabled() && bridge::stays_low(1000);
    defmt::error!(
        "panic: {} (bridge outputs {})",
        defmt::Display2Format(info),
        if off { "off" } else { "STILL ON" }
    );
    if off {
        semihosting::process::abort()
    } else {
        semihosting::process::exit(0)
    }
}

#[embedded_test::tests(default_timeout = 20)]
mod tests {
    use super::{CORE_HZ, CanIrqs, bridge, clock_config};
    use cortex_m::peripheral::DWT;
    use embassy_stm32::Peripherals;
    use embassy_stm32::can::{self, Can, Id};
    use embassy_stm32::gpio::{Level, Output, Pull, Speed};
    use embassy_stm32::spi::{self, Spi};
    use embassy_stm32::time::Hertz;
    use embassy_stm32::timer::complementary_pwm::ComplementaryPwm;
    use embassy_time::{Duration, Instant, Timer, with_timeout};
    use golden_vectors::loops::{self, Meter, Step, Verdict};
    use steering_ecu::amt20;
    use steering_ecu::as_state::AsState;
    use steering_ecu::can::{Frame, StandardId};
    use steering_ecu::commutation::HallDecoder;
    use steering_ecu::ecu::Ecu;
    use steering_ecu::faults::Fault;
    use steering_ecu::ports::EncoderError;
    use steering_ecu::protocol::{AliveCounter, ProtocolConfig, Reference, Status};
    use steering_ecu::steering::{DriveDemand, EcuState};
    use steering_ecu::units::{Amps, SteeringDeg};

    static SWEEP: &[u8] = include_bytes!("../vectors/sweep.bin");
    static TRACK: &[u8] = include_bytes!("../vectors/track.bin");

    /// Round trip of one 8-byte frame in loopback, us: 135 bit times at 1 Mbit/s worst case
    /// with stuffing, plus the interrupt and the executor's wake-up; 300 us is two frame times.
    const CAN_ROUND_TRIP_US: u32 = 300;
    /// 5 % of the 20 kHz period, and of the 2 kHz period, at 180 MHz: what the control steps may
    /// take of the core, leaving the rest to the tasks and the CAN traffic.
    const CURRENT_BUDGET_CYCLES: u32 = CORE_HZ / 20_000 / 20;
    const POSITION_BUDGET_CYCLES: u32 = CORE_HZ / 2_000 / 20;

    #[init]
    fn init() -> Peripherals {
        let p = embassy_stm32::init(clock_config());
        if let Some(mut core) = cortex_m::Peripherals::take() {
            core.DCB.enable_trace();
            core.DWT.enable_cycle_counter();
        }
        p
    }

    fn cycles() -> u32 {
        DWT::cycle_count()
    }

    async fn loopback_can(p: Peripherals) -> Can<'static> {
        let mut can = Can::new(p.CAN1, p.PA11, p.PA12, CanIrqs);
        // The firmware's filter and bit rate, then loopback on top.
        steering_ecu::chip::can::configure(&mut can);
        can.modify_config().set_loopback(true).set_silent(true);
        can.enable().await;
        can
    }

    /// Out through bxCAN and back; the frame received and the round trip in cycles.
    async fn round_trip(can: &mut Can<'static>, frame: &Frame) -> (Frame, u32) {
        let hw = defmt::unwrap!(can::Frame::new_standard(frame.id().raw(), frame.data()).ok());
        let start = cycles();
        can.write(&hw).await;
        let envelope = defmt::unwrap!(
            with_timeout(Duration::from_millis(10), can.read())
                .await
                .ok(),
            "no frame back within 10 ms"
        );
        let end = cycles();
        let envelope = defmt::unwrap!(envelope.ok(), "bus error in loopback");
        let back = &envelope.frame;
        let Id::Standard(id) = back.id() else {
            defmt::panic!("extended id back")
        };
        let core = StandardId::new(id.as_raw()).and_then(|id| Frame::new(id, back.data()));
        (defmt::unwrap!(core), end.wrapping_sub(start))
    }

    fn us(cycles: u32) -> u32 {
        cycles / (CORE_HZ / 1_000_000)
    }

    #[test]
    async fn can_loopback_carries_reference_and_status_frames(p: Peripherals) {
        let mut can = loopback_can(p).await;
        let cfg = ProtocolConfig::DEFAULT;
        let mut worst = 0;
        let mut counter = AliveCounter::wrapping(0);
        for k in 0..200u32 {
            counter = counter.next();
            let reference = Reference {
                angle: SteeringDeg((k as f32 - 100.0) * 0.85),
                as_state: if k % 2 == 0 {
                    AsState::Driving
                } else {
                    AsState::Ready
                },
                counter,
                clear_faults: k % 50 == 0,
            };
            let (back, t) = round_trip(&mut can, &cfg.encode_reference(&reference)).await;
            assert_eq!(cfg.decode_reference(&back), Ok(reference));
            worst = worst.max(t);

            let status = Status {
                angle: SteeringDeg(k as f32 * 0.25 - 20.0),
                current: Amps(k as f32 * 0.2 - 20.0),
                ecu_state: (k % 6) as u8,
                faults: k as u16,
                counter,
            };
            let (back, t) = round_trip(&mut can, &cfg.encode_status(&status)).await;
            assert_eq!(cfg.decode_status(&back), Ok(status));
            worst = worst.max(t);
        }
        let esr = embassy_stm32::pac::CAN1.esr().read();
        defmt::info!(
            "CAN loopback: 400 frames back unchanged, worst round trip {} us (bound {} us), TEC {} REC {}",
            us(worst),
            CAN_ROUND_TRIP_US,
            esr.tec(),
            esr.rec()
        );
        assert!(us(worst) <= CAN_ROUND_TRIP_US);
        assert_eq!((esr.tec(), esr.rec()), (0, 0));
    }

    /// Times each replayed step with DWT. The current step's window also holds what the
    /// firmware's 20 kHz interrupt does around it: the current-sense conversion before and the
    /// Hall decoding and six-step commutation after.
    struct CycleMeter {
        current_max: u32,
        position_max: u32,
        current_sum: u64,
        current_steps: u32,
        hall: HallDecoder,
        hall_code: u8,
    }

    /// Current sense: 12-bit ADC around mid-scale, 3.3 V reference, 66 mV/A (an ACS-type
    /// sensor, until the board's own front end is known). The work, not the scale, is timed.
    fn amps_from_adc(raw: u16) -> Amps {
        Amps((f32::from(raw & 0x0FFF) - 2048.0) * (3.3 / 4096.0 / 0.066))
    }

    impl Meter for CycleMeter {
        fn measure<R>(&mut self, step: Step, f: impl FnOnce() -> R) -> R {
            let start = cycles();
            let out = match step {
                Step::Current => {
                    let sensed = core::hint::black_box(amps_from_adc(2100));
                    let out = core::hint::black_box(f());
                    // The Hall code walks the six valid codes, as a turning motor's would.
                    const CODES: [u8; 6] = [0b001, 0b011, 0b010, 0b110, 0b100, 0b101];
                    self.hall_code = (self.hall_code + 1) % 6;
                    let _ = self.hall.update(CODES[self.hall_code as usize]);
                    core::hint::black_box(self.hall.commutate(sensed.0, 24.0));
                    out
                }
                Step::Position => core::hint::black_box(f()),
            };
            let n = cycles().wrapping_sub(start);
            match step {
                Step::Current => {
                    self.current_max = self.current_max.max(n);
                    self.current_sum += u64::from(n);
                    self.current_steps += 1;
                }
                Step::Position => self.position_max = self.position_max.max(n),
            }
            out
        }
    }

    #[test]
    fn control_steps_are_bit_exact_and_within_budget(_p: Peripherals) {
        let mut meter = CycleMeter {
            current_max: 0,
            position_max: 0,
            current_sum: 0,
            current_steps: 0,
            hall: HallDecoder::new(0),
            hall_code: 0,
        };
        for (name, bytes) in [("sweep.bin", SWEEP), ("track.bin", TRACK)] {
            let report = defmt::unwrap!(loops::replay(bytes, &mut meter, None).ok());
            defmt::info!(
                "{}: {} outputs, {} differing, {} within tolerance",
                name,
                report.compared,
                report.differing,
                report.within_tolerance
            );
            assert!(report.verdict() == Verdict::BitExact);
        }
        defmt::info!(
            "cycles at {} MHz: current tick max {} mean {} (budget {}), position step max {} (budget {})",
            CORE_HZ / 1_000_000,
            meter.current_max,
            meter.current_sum / u64::from(meter.current_steps.max(1)),
            CURRENT_BUDGET_CYCLES,
            meter.position_max,
            POSITION_BUDGET_CYCLES
        );
        assert!(meter.current_max <= CURRENT_BUDGET_CYCLES);
        assert!(meter.position_max <= POSITION_BUDGET_CYCLES);
    }

    /// TIM1 as the three-phase bridge at 20 kHz, set up by the firmware's own code (off, with
    /// its dead time), then each phase at 50 % duty with its channels enabled and MOE still
    /// clear.
    fn bridge_pwm(p: Peripherals) -> ComplementaryPwm<'static, embassy_stm32::peripherals::TIM1> {
        let mut pwm = steering_ecu::chip::bridge::pwm(
            steering_ecu::chip::bridge::Pins {
                tim: p.TIM1,
                ch1: p.PA8,
                ch1n: p.PB13,
                ch2: p.PA9,
                ch2n: p.PB14,
                ch3: p.PA10,
                ch3n: p.PB15,
            },
            Hertz::khz(20),
        );
        for ch in [
            embassy_stm32::timer::Channel::Ch1,
            embassy_stm32::timer::Channel::Ch2,
            embassy_stm32::timer::Channel::Ch3,
        ] {
            pwm.set_duty(ch, pwm.get_max_duty() / 2);
            pwm.enable(ch);
        }
        pwm
    }

    #[test]
    fn pwm_outputs_come_up_off(p: Peripherals) {
        let _pwm = bridge_pwm(p);
        assert!(!bridge::main_output_enabled());
        // 2000 reads over several 50 us periods: no edge gets through.
        assert!(bridge::stays_low(2000));
    }

    /// Outputs switching: the high side of phase A seen high and low within a few periods.
    fn switching() -> bool {
        let (mut high, mut low) = (false, false);
        for _ in 0..20_000 {
            let l = bridge::levels();
            high |= l[0];
            low |= !l[0];
        }
        high && low
    }

    #[test]
    fn pwm_goes_off_on_a_fault(p: Peripherals) {
        let mut pwm = bridge_pwm(p);
        let mut ecu = defmt::unwrap!(Ecu::paper());
        pwm.set_master_output_enable(true);
        assert!(switching(), "the bridge must switch before the fault");

        // A latched fault (bus-off) disables the drive in the same call; the 20 kHz tick then
        // gets `None` and switches the outputs off.
        let start = cycles();
        let out = ecu.on_bus_off(Instant::now().as_micros(), 255);
        if ecu
            .current_tick(Instant::now().as_micros(), Amps(0.0))
            .is_none()
        {
            bridge::force_off();
        }
        let took = cycles().wrapping_sub(start);
        assert_eq!(out.demand, DriveDemand::Disabled);
        assert!(bridge::stays_low(2000));
        defmt::info!(
            "fault to outputs off: {} cycles (one 20 kHz period: 9000)",
            took
        );
        assert!(took < CORE_HZ / 20_000);

        // The hardware path too: a break (here the software break) clears MOE by itself.
        pwm.set_master_output_enable(true);
        assert!(switching());
        pwm.trigger_software_break(0);
        assert!(!bridge::main_output_enabled());
        assert!(bridge::stays_low(2000));
    }

    #[test]
    #[should_panic]
    fn pwm_goes_off_on_a_panic(p: Peripherals) {
        let mut pwm = bridge_pwm(p);
        pwm.set_master_output_enable(true);
        assert!(switching());
        // The suite's panic handler must leave the outputs off; it reports the panic only if
        // they are.
        defmt::panic!("deliberate panic with the bridge switching");
    }

    #[test]
    async fn reference_timeout_holds_then_faults(p: Peripherals) {
        let mut can = loopback_can(p).await;
        let cfg = ProtocolConfig::DEFAULT;
        let mut ecu = defmt::unwrap!(Ecu::paper());
        let mut counter = AliveCounter::wrapping(0);
        let mut last_frame_at = 0;
        // 200 ms of frames at 100 Hz through the real bus, the encoder fresh every tick.
        for _ in 0..20 {
            counter = counter.next();
            let reference = Reference {
                angle: SteeringDeg(0.0),
                as_state: AsState::Driving,
                counter,
                clear_faults: false,
            };
            let (back, _) = round_trip(&mut can, &cfg.encode_reference(&reference)).await;
            last_frame_at = Instant::now().as_micros();
            let _ = ecu.on_reference_frame(last_frame_at, &back);
            for _ in 0..20 {
                let now = Instant::now().as_micros();
                let _ = ecu.on_encoder(now, SteeringDeg(0.0));
                let _ = ecu.tick(now);
                Timer::after(Duration::from_micros(500)).await;
            }
        }
        assert_eq!(ecu.output().state, EcuState::Tracking);
        // The frames stop; the encoder keeps going. Tick at 2 kHz and note the transitions.
        let (mut hold_at, mut fault_at) = (None, None);
        while fault_at.is_none() {
            let now = Instant::now().as_micros();
            let _ = ecu.on_encoder(now, SteeringDeg(0.0));
            let out = ecu.tick(now);
            let since = now - last_frame_at;
            if out.demand == DriveDemand::Hold && hold_at.is_none() {
                hold_at = Some(since);
            }
            if out.demand == DriveDemand::Disabled {
                assert!(out.faults.contains(Fault::ReferenceTimeout));
                fault_at = Some(since);
            }
            assert!(
                since < 200_000,
                "no timeout fault 200 ms after the last frame"
            );
            Timer::after(Duration::from_micros(500)).await;
        }
        let (hold, fault) = (defmt::unwrap!(hold_at), defmt::unwrap!(fault_at));
        defmt::info!(
            "hold after {} us (30 000), fault after {} us (130 000)",
            hold,
            fault
        );
        assert!((30_000..=31_000).contains(&hold));
        assert!((130_000..=131_000).contains(&fault));
    }

    #[test]
    async fn spi_encoder_reads_are_valid_and_steady(p: Peripherals) {
        // The firmware's wiring: SPI1 PA5 SCK, PA6 MISO, PA7 MOSI, PB6 chip select; 500 kHz.
        let mut config = spi::Config::default();
        config.frequency = Hertz(500_000);
        // Pulled down: an unwired MISO reads 0x00, which no AMT20 answer starts with.
        config.miso_pull = Pull::Down;
        let mut spi = Spi::new_blocking(p.SPI1, p.PA5, p.PA7, p.PA6, config);
        let mut cs = Output::new(p.PB6, Level::High, Speed::VeryHigh);
        let mut read = async || -> Result<u16, (EncoderError, bool)> {
            let mut r = amt20::Read::new();
            let mut byte = r.first_byte();
            let mut all_zero = true;
            loop {
                cs.set_low();
                let mut buf = [byte];
                let sent = spi.blocking_transfer_in_place(&mut buf);
                cs.set_high();
                if sent.is_err() {
                    return Err((EncoderError::NoResponse, all_zero));
                }
                all_zero &= buf[0] == 0;
                Timer::after(Duration::from_micros(25)).await;
                match r.on_received(buf[0]) {
                    amt20::Next::Transfer(next) => byte = next,
                    amt20::Next::Position(raw) => return Ok(raw),
                    amt20::Next::Failed(e) => return Err((e, all_zero)),
                }
            }
        };
        let first = match read().await {
            Ok(raw) => raw,
            Err((_, true)) => {
                defmt::warn!(
                    "SKIPPED spi_encoder: no encoder wired (MISO read 0x00 throughout); wire an AMT20 to SPI1 to run this test"
                );
                return;
            }
            Err((e, false)) => defmt::panic!("encoder answered but the read failed: {}", e),
        };
        // The column stands still on the bench: 100 reads within +-2 counts of the first.
        for _ in 0..100 {
            let raw = match read().await {
                Ok(raw) => raw,
                Err((e, _)) => defmt::panic!("read failed: {}", e),
            };
            assert!(raw <= 4095);
            let diff = (i32::from(raw) - i32::from(first)).rem_euclid(4096);
            assert!(diff <= 2 || diff >= 4094, "{} then {}", first, raw);
            Timer::after(Duration::from_millis(1)).await;
        }
        defmt::info!("spi encoder: 101 reads valid and steady at raw {}", first);
    }
}

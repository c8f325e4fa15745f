//! The control core on an emulated Cortex-M4F: QEMU's `netduinoplus2` (an STM32F405, the same
//! flash and RAM layout as our `memory.x`) runs this with semihosting. It replays the golden
//! vectors that host-sim wrote (`../vectors`, see `host-sim/src/golden.rs`), says for each
//! whether the target reproduced it bit for bit, within the stated tolerance, or not at all, and
//! counts the instructions of every `Cascade::current_step` and `Cascade::position_step` of the
//! replay. Any difference beyond the tolerance, or a step above its budget, exits non-zero.
//!
//! Counting: QEMU runs with `-icount shift=0`, so its virtual clock advances exactly 1 ns per
//! executed instruction, and its model of TIM2 counts that clock at 1 GHz with no prescaler.
//! The difference of two reads of TIM2's counter is therefore the number of instructions in
//! between, the same on every run and every machine. (SysTick is no use here: QEMU clocks it
//! from the 168 MHz system clock, so it counts 0.168 per instruction.) `embassy_stm32::init`
//! is never called: QEMU has no model of the STM32 clock tree and it would hang.
//!
//! Stack: each part of the work is run on freshly painted stack ([`stack`]), and the fast
//! loop's step is then run in a real exception (SysTick, pended by software) the same way; the
//! deepest work plus the interrupt on top of it is the deepest path, reported against the
//! stack size. With the feature `stack-overflow`, main first recurses until the stack runs off
//! the RAM start (flip-link's layout): the run must end in the firmware's HardFault entry
//! (`steering_ecu::hard_fault_entry!`) with the statics intact.
#![no_std]
#![no_main]

mod stack;

use core::cell::RefCell;
use core::sync::atomic::{AtomicU32, Ordering, compiler_fence};
use cortex_m::interrupt::Mutex;
use cortex_m::peripheral::SCB;
use cortex_m_rt::{entry, exception};
use cortex_m_semihosting::{debug, hprintln};
use embassy_stm32::pac;
use golden_vectors::cases::{self, CaseWriter, Group, GroupReport};
use golden_vectors::loops::{self, Meter, Report, Step, Tamper, Verdict};
use steering_ecu::as_state::AsState;
use steering_ecu::commutation::code_of;
use steering_ecu::direct::FastLoop;
use steering_ecu::ecu::Ecu;
use steering_ecu::paper_mode::CURRENT_TICKS_PER_POSITION_TICK;
use steering_ecu::protocol::{AliveCounter, ProtocolConfig, Reference};
use steering_ecu::steering::DriveDemand;
use steering_ecu::units::{Amps, SteeringDeg, Volts};

static SWEEP: &[u8] = include_bytes!("../../vectors/sweep.bin");
static TRACK: &[u8] = include_bytes!("../../vectors/track.bin");
static CASES: &[u8] = include_bytes!("../../vectors/cases.bin");
static ECU_SWEEP: &[u8] = include_bytes!("../../vectors/ecu_sweep.bin");
static ECU_TRACK: &[u8] = include_bytes!("../../vectors/ecu_track.bin");

/// Budgets: 5 % of the period at the F446's 180 MHz (the rest is the tasks'). They are cycle
/// budgets; an instruction takes at least one cycle on the Cortex-M4, so an instruction count
/// above the budget is a cycle count above it too (the converse needs the board:
/// hil-tests/tests/board.rs).
const CORE_HZ: u32 = 180_000_000;
const CURRENT_BUDGET: u32 = CORE_HZ / steering_ecu::paper_mode::CURRENT_LOOP_HZ / 20;
const POSITION_BUDGET: u32 = CORE_HZ / steering_ecu::paper_mode::POSITION_LOOP_HZ / 20;

/// Per-step instruction counts: a histogram (for the median; counts above 1023 share the last
/// bin, far above every budget that matters here) and the extremes. 4 KiB each: several live
/// on the stack at once.
struct Counts {
    bins: [u32; 1024],
    steps: u32,
    min: u32,
    max: u32,
    sum: u64,
}

impl Counts {
    const fn new() -> Self {
        Counts {
            bins: [0; 1024],
            steps: 0,
            min: u32::MAX,
            max: 0,
            sum: 0,
        }
    }

    fn add(&mut self, n: u32) {
        let bin = (n as usize).min(self.bins.len() - 1);
        self.bins[bin] += 1;
        self.steps += 1;
        self.min = self.min.min(n);
        self.max = self.max.max(n);
        self.sum += u64::from(n);
    }

    fn median(&self) -> u32 {
        let mut seen = 0;
        for (n, &count) in self.bins.iter().enumerate() {
            seen += count;
            if seen * 2 >= self.steps {
                return n as u32;
            }
        }
        self.max
    }
}

/// Counts instructions through QEMU's TIM2 (see the module comment).
struct InstructionMeter {
    /// Instructions of an empty measurement (the two counter reads), subtracted.
    overhead: u32,
    current: Counts,
    position: Counts,
}

fn instructions_now() -> u32 {
    compiler_fence(Ordering::SeqCst);
    let n = pac::TIM2.cnt().read();
    compiler_fence(Ordering::SeqCst);
    n
}

impl InstructionMeter {
    fn new() -> Self {
        let mut meter = InstructionMeter {
            overhead: 0,
            current: Counts::new(),
            position: Counts::new(),
        };
        meter.overhead = meter.count(|| ()).1;
        meter
    }

    #[inline(always)]
    fn count<R>(&self, f: impl FnOnce() -> R) -> (R, u32) {
        count_instructions(self.overhead, f)
    }
}

/// The result of `f` and the instructions it executed, `overhead` (the reads') subtracted.
#[inline(always)]
fn count_instructions<R>(overhead: u32, f: impl FnOnce() -> R) -> (R, u32) {
    let start = instructions_now();
    let out = core::hint::black_box(f());
    let end = instructions_now();
    (out, end.wrapping_sub(start).saturating_sub(overhead))
}

impl Meter for InstructionMeter {
    fn measure<R>(&mut self, step: Step, f: impl FnOnce() -> R) -> R {
        let (out, n) = self.count(f);
        match step {
            Step::Current => self.current.add(n),
            Step::Position => self.position.add(n),
        }
        out
    }
}

fn verdict_text(v: Verdict) -> &'static str {
    match v {
        Verdict::BitExact => "bit-exact",
        Verdict::WithinTolerance => "WITHIN TOLERANCE (not bit-exact; passes)",
        Verdict::Differs => "DIFFERS",
    }
}

/// Replays one closed-loop file; `true` if it passes.
fn check_loop(
    name: &str,
    bytes: &[u8],
    meter: &mut InstructionMeter,
    tamper: Option<Tamper>,
) -> bool {
    match loops::replay(bytes, meter, tamper) {
        Ok(r) => {
            print_loop(name, &r);
            r.verdict() != Verdict::Differs
        }
        Err(e) => {
            hprintln!(
                "  {}: unreadable: {:?} (regenerate: see hil-tests/README.md)",
                name,
                e
            );
            false
        }
    }
}

fn print_loop(name: &str, r: &Report) {
    hprintln!(
        "  {}: {} periods, {} position + {} current steps, {} outputs: {}",
        name,
        r.periods,
        r.position_steps,
        r.current_steps,
        r.compared,
        verdict_text(r.verdict())
    );
    if r.within_tolerance > 0 {
        hprintln!(
            "    {} outputs within tolerance: max |diff| {} A, {} V (tolerance {} A, {} V)",
            r.within_tolerance,
            r.max_abs_diff_a,
            r.max_abs_diff_v,
            loops::TOLERANCE_A,
            loops::TOLERANCE_V
        );
    }
    if let Some(d) = r.first_difference {
        hprintln!(
            "    {} differ; first: period {} tick {} current step {:?}: {} expected {:#010x} ({}), got {:#010x} ({})",
            r.differing,
            d.period,
            d.tick,
            d.current_step,
            d.what,
            d.expected,
            f32::from_bits(d.expected),
            d.got,
            f32::from_bits(d.got)
        );
    }
}

fn print_group(group: Group, r: &GroupReport, first: Option<&CaseWriter>) {
    let verdict = if r.differing == 0 {
        Verdict::BitExact
    } else {
        Verdict::Differs
    };
    hprintln!(
        "  cases.bin {}: {} cases: {}",
        group.name(),
        r.cases,
        verdict_text(verdict)
    );
    if let (Some(i), Some(w)) = (r.first_differing, first) {
        hprintln!(
            "    {} differ; first: case {}, output now begins: {}",
            r.differing,
            i,
            w.head()
        );
    }
}

fn print_counts(name: &str, c: &Counts, budget: u32, hz: u32) -> bool {
    let ok = c.max <= budget;
    hprintln!(
        "  {:<14} median {:>4}  max {:>4}  min {:>4}  mean {:>4}  over {} steps | budget {} cycles (5 % of {} Hz at 180 MHz): {}",
        name,
        c.median(),
        c.max,
        c.min,
        c.sum / u64::from(c.steps.max(1)),
        c.steps,
        budget,
        hz,
        if ok { "within" } else { "OVER" }
    );
    ok
}

/// The direct drive's fast loop and the ECU it steps, owned by the SysTick exception as the
/// firmware's ADC interrupt owns them; the main loop, as the firmware's tasks, reaches the ECU
/// inside a critical section.
struct Tracking {
    fast: FastLoop,
    ecu: Ecu,
    period: u32,
}

static IN_INTERRUPT: Mutex<RefCell<Option<Tracking>>> = Mutex::new(RefCell::new(None));
/// The read pair's instructions, subtracted from each count.
static OVERHEAD: AtomicU32 = AtomicU32::new(0);
/// The last period's instruction count; `NOT_RUN` until the exception ran one.
static LAST_COUNT: AtomicU32 = AtomicU32::new(NOT_RUN);
const NOT_RUN: u32 = u32::MAX;

/// The sampled inputs of a fast-loop period: its time, the Hall code of a motor turning one
/// sector every 2 ms (40 periods), and a winding current of 4 A.
fn fast_loop_inputs(period: u32) -> (u64, u8, [Amps; 3]) {
    let now_us = 1_000 + 50 * u64::from(period);
    let code = code_of(((period / 40) % 6) as u8);
    (now_us, code, [Amps(4.0), Amps(-4.0), Amps(0.0)])
}

/// The firmware's 20 kHz interrupt: one period of the fast loop, its instructions counted.
#[exception]
fn SysTick() {
    let overhead = OVERHEAD.load(Ordering::Relaxed);
    cortex_m::interrupt::free(|cs| {
        if let Some(t) = IN_INTERRUPT.borrow(cs).borrow_mut().as_mut() {
            let (now_us, code, phases) = fast_loop_inputs(t.period);
            let (_, n) =
                count_instructions(overhead, || t.fast.step(&mut t.ecu, now_us, code, phases));
            t.period += 1;
            LAST_COUNT.store(n, Ordering::Relaxed);
        }
    });
}

/// Pends the interrupt and returns the instructions of the period it ran, if it ran one.
fn interrupt_period() -> Option<u32> {
    LAST_COUNT.store(NOT_RUN, Ordering::Relaxed);
    SCB::set_pendst();
    // The exception is taken here, before the next instruction.
    cortex_m::asm::isb();
    Some(LAST_COUNT.load(Ordering::Relaxed)).filter(|&n| n != NOT_RUN)
}

/// Whether the interrupt's ECU is tracking (driving the bridge).
fn interrupt_tracks() -> bool {
    cortex_m::interrupt::free(|cs| {
        IN_INTERRUPT
            .borrow(cs)
            .borrow()
            .as_ref()
            .is_some_and(|t| t.ecu.output().demand == DriveDemand::Track)
    })
}

/// Instructions of the direct drive's whole interrupt, `FastLoop::step` (Hall decoding, the
/// winding current from the three phase currents, the state machine's over-current check, the
/// PI current loop, six-step commutation, and on every 10th period the position loop), run in
/// the SysTick exception on an ECU tracking a reference while the motor turns one sector every
/// 2 ms. Fills the counts of the current-only periods and of the periods that also ran the
/// position loop; `false` if the ECU did not track (the counts would be of an idle path).
fn count_fast_loop(meter: &InstructionMeter, current: &mut Counts, position: &mut Counts) -> bool {
    let protocol = ProtocolConfig::default();
    let Some(ecu) = Ecu::paper() else {
        return false;
    };
    let tracking = Tracking {
        fast: FastLoop::new(0, Volts(24.0)),
        ecu,
        period: 0,
    };
    OVERHEAD.store(meter.overhead, Ordering::Relaxed);
    cortex_m::interrupt::free(|cs| IN_INTERRUPT.borrow(cs).replace(Some(tracking)));
    let mut counter = AliveCounter::wrapping(0);
    for k in 0..4_000u32 {
        let now_us = fast_loop_inputs(k).0;
        // Outside the measurement, at the firmware's rates: a column sample every 2 ms (the
        // encoder task, which also keeps the fast loop's supervisor watchdog fed; at 10 ms the
        // fast loop would switch the bridge off half the time and count its idle path) and
        // the 100 Hz reference.
        let frame = (k % 200 == 0).then(|| {
            counter = counter.next();
            protocol.encode_reference(&Reference {
                angle: SteeringDeg(10.0),
                as_state: AsState::Driving,
                counter,
                clear_faults: false,
            })
        });
        cortex_m::interrupt::free(|cs| {
            if let Some(t) = IN_INTERRUPT.borrow(cs).borrow_mut().as_mut() {
                if k % 40 == 0 {
                    let _ = t
                        .ecu
                        .on_encoder(now_us, SteeringDeg(0.02 * (k / 40) as f32));
                }
                if let Some(frame) = &frame {
                    let _ = t.ecu.on_reference_frame(now_us, frame);
                }
            }
        });
        let Some(n) = interrupt_period() else {
            return false;
        };
        if k % CURRENT_TICKS_PER_POSITION_TICK == 0 {
            position.add(n);
        } else {
            current.add(n);
        }
    }
    // The run must have driven the bridge, or the counts are of an idle path.
    interrupt_tracks()
}

/// Periods the interrupt runs for the stack measurement: two position-loop periods' worth.
const INTERRUPT_RUNS: u32 = 2 * CURRENT_TICKS_PER_POSITION_TICK;

/// The stack of the fast loop's interrupt (frame stacking included), measured after
/// [`count_fast_loop`], on top of the deepest work measured before (`work_depth`), against the
/// stack size; `false` if the interrupt did not run or its ECU stopped tracking.
fn report_stack(work_depth: usize) -> bool {
    let (ran, interrupt_depth) = stack::depth_of(|| {
        (0..INTERRUPT_RUNS)
            .filter(|_| interrupt_period().is_some())
            .count()
    });
    let tracked = interrupt_tracks();
    let (bottom, top) = stack::bounds();
    let size = top - bottom;
    let main_frame = top - stack::pointer();
    let path = work_depth + interrupt_depth;
    hprintln!(
        "stack (painted; {:#010x}..{:#010x}, {} B below the statics):",
        bottom,
        top,
        size
    );
    hprintln!(
        "  deepest work (replays, cases, fast-loop run) {} B; the fast-loop interrupt (SysTick, {} periods, frame included) {} B",
        work_depth,
        ran,
        interrupt_depth
    );
    let ok = ran == INTERRUPT_RUNS as usize && tracked && main_frame + path < size;
    hprintln!(
        "  deepest path: {} B, the interrupt on top of the deepest work ({} B with this suite's own {} B main frame) of {} B: {}",
        path,
        main_frame + path,
        main_frame,
        size,
        if ok {
            "within"
        } else {
            "OVER, or the interrupt did not run or track"
        }
    );
    ok
}

#[entry]
fn main() -> ! {
    let tamper = cfg!(feature = "corrupt-one-vector").then_some(Tamper {
        current_step: 5_000,
    });
    hprintln!(
        "emulated suite: control core on a Cortex-M4F (QEMU netduinoplus2), thumbv7em-none-eabihf"
    );
    if tamper.is_some() {
        hprintln!(
            "feature corrupt-one-vector: sweep.bin current step 5000 is expected 1 V off; this run must FAIL"
        );
    }
    if cfg!(feature = "stack-overflow") {
        hprintln!("feature stack-overflow: recursing until the stack runs off the RAM start");
        hprintln!("emulated suite: recursed {} levels", recurse(0));
    }
    hprintln!("golden vectors (written by `host-sim golden`):");
    let mut meter = InstructionMeter::new();
    // The stack each part of the work takes below main's frame; the deepest is kept.
    let mut work_depth = 0;
    let mut deepest = |(ok, depth): (bool, usize)| {
        work_depth = work_depth.max(depth);
        ok
    };
    let mut pass = deepest(stack::depth_of(|| {
        check_loop(
            "sweep.bin (paper sweep 6.0-6.6 s)",
            SWEEP,
            &mut meter,
            tamper,
        )
    }));
    pass &= deepest(stack::depth_of(|| {
        check_loop(
            "track.bin (built-in track 110.0-110.5 s)",
            TRACK,
            &mut meter,
            None,
        )
    }));
    // ECU mode on its own meter, so each controller's counts are its own.
    let mut ecu_meter = InstructionMeter::new();
    pass &= deepest(stack::depth_of(|| {
        check_loop(
            "ecu_sweep.bin (ECU mode, paper sweep 6.0-6.3 s)",
            ECU_SWEEP,
            &mut ecu_meter,
            None,
        )
    }));
    pass &= deepest(stack::depth_of(|| {
        check_loop(
            "ecu_track.bin (ECU mode, built-in track 110.0-110.25 s)",
            ECU_TRACK,
            &mut ecu_meter,
            None,
        )
    }));
    pass &= deepest(stack::depth_of(|| {
        match cases::check(CASES, &mut print_group) {
            Ok(differing) => differing == 0,
            Err(e) => {
                hprintln!(
                    "  cases.bin: unreadable: {:?} (regenerate: see hil-tests/README.md)",
                    e
                );
                false
            }
        }
    }));
    hprintln!(
        "instructions per step (QEMU -icount shift=0: exact instruction counts, not cycles; {} subtracted per read pair):",
        meter.overhead
    );
    pass &= print_counts(
        "current_step",
        &meter.current,
        CURRENT_BUDGET,
        steering_ecu::paper_mode::CURRENT_LOOP_HZ,
    );
    pass &= print_counts(
        "position_step",
        &meter.position,
        POSITION_BUDGET,
        steering_ecu::paper_mode::POSITION_LOOP_HZ,
    );
    hprintln!("ECU mode (`--controller ecu`):");
    pass &= print_counts(
        "current_step",
        &ecu_meter.current,
        CURRENT_BUDGET,
        steering_ecu::paper_mode::CURRENT_LOOP_HZ,
    );
    pass &= print_counts(
        "position_step",
        &ecu_meter.position,
        POSITION_BUDGET,
        steering_ecu::paper_mode::POSITION_LOOP_HZ,
    );
    let (mut current, mut position) = (Counts::new(), Counts::new());
    let (tracked, depth) = stack::depth_of(|| count_fast_loop(&meter, &mut current, &mut position));
    work_depth = work_depth.max(depth);
    if tracked {
        hprintln!(
            "direct drive's 20 kHz interrupt (FastLoop::step: Hall, current sense, commutation, ECU checks):"
        );
        pass &= print_counts(
            "current period",
            &current,
            CURRENT_BUDGET,
            steering_ecu::paper_mode::CURRENT_LOOP_HZ,
        );
        pass &= print_counts(
            "with position",
            &position,
            POSITION_BUDGET,
            steering_ecu::paper_mode::POSITION_LOOP_HZ,
        );
        pass &= report_stack(work_depth);
    } else {
        hprintln!("  FastLoop: the ECU did not track, so the count is of an idle path");
        pass = false;
    }
    if pass {
        hprintln!("emulated suite: PASS");
        debug::exit(debug::EXIT_SUCCESS);
    } else {
        hprintln!("emulated suite: FAIL");
        debug::exit(debug::EXIT_FAILURE);
    }
    loop {
        cortex_m::asm::wfi();
    }
}

/// Recurses for ever (`stack-overflow` feature), each level with a 256-byte frame the compiler
/// cannot drop.
#[allow(unconditional_recursion)]
fn recurse(depth: u32) -> u32 {
    let frame = core::hint::black_box([depth; 64]);
    recurse(depth + 1).wrapping_add(frame[0])
}

/// Initialised static (`.data`), checked in the HardFault handler: flip-link keeps the statics
/// above the stack, so an overflow must leave it as it was.
static CANARY: AtomicU32 = AtomicU32::new(0x5AFE_C0DE);

// The firmware's HardFault entry (it resets the stack pointer before anything uses the stack).
#[allow(unsafe_code)]
mod hard_fault {
    steering_ecu::hard_fault_entry!(super::on_hard_fault);
}

extern "C" fn on_hard_fault() -> ! {
    let canary = CANARY.load(Ordering::Relaxed);
    hprintln!(
        "emulated suite: HardFault, statics {}",
        if canary == 0x5AFE_C0DE {
            "intact"
        } else {
            "OVERWRITTEN"
        }
    );
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    hprintln!("emulated suite: panic: {}", info);
    debug::exit(debug::EXIT_FAILURE);
    loop {
        cortex_m::asm::wfi();
    }
}

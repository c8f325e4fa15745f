//! Closed-loop golden vectors: the cascade's inputs and outputs over a recorded run, and their
//! replay on a fresh cascade.
//!
//! File layout (little-endian; `f32` as its bit pattern):
//!
//! ```text
//! header   "GLV2", periods u32, hall0 i32, belt f32, tau_bs f32, tau_p f32, ra f32, la f32,
//!          supply_v f32, controller u32 (0 paper mode, 1 ECU mode)
//! period   reference_deg f32, push result u8 (0 ok, 1 not finite, 2 out of range),
//!          20 x tick
//! tick     hall i32, column rad f32, current set-point f32, position status u8,
//!          10 x (measured current f32, voltage f32, current status u8)
//! ```
//!
//! The controller is built as host-sim's `sim::run` builds it: the Table 3 gains (ECU mode: with
//! `EcuTuning::PAPER`), the gearing and winding of the header, conditional integration, the
//! supply as voltage limit, reset to `hall0`. Paper mode ignores the column.
//! The host-side test replays every freshly recorded file too, so a difference between this
//! construction and host-sim's would fail on the host before it reaches the target.

use crate::Reader;
use steering_ecu::control::AntiWindup;
use steering_ecu::control::current::{CurrentOutput, CurrentStatus};
use steering_ecu::control::position::{PositionOutput, PositionStatus};
use steering_ecu::controller::{ControllerKind, SteeringController};
use steering_ecu::ecu_mode::{ColumnCascade, EcuTuning};
use steering_ecu::gains::EposGains;
use steering_ecu::gearing::Gearing;
use steering_ecu::paper_mode::{
    CURRENT_TICKS_PER_POSITION_TICK, Cascade, POSITION_TICKS_PER_REFERENCE,
};
use steering_ecu::reference::ReferenceError;
use steering_ecu::units::{Amps, SteeringDeg, SteeringRad, Volts};

pub const MAGIC: [u8; 4] = *b"GLV2";
/// Bytes per position tick: hall, column, set-point, status, then ten current ticks of 9 bytes.
pub const TICK_BYTES: usize = 13 + 9 * CURRENT_TICKS_PER_POSITION_TICK as usize;
pub const PERIOD_BYTES: usize = 5 + TICK_BYTES * POSITION_TICKS_PER_REFERENCE as usize;
pub const HEADER_BYTES: usize = 40;

/// Where Rust's `f32` code could differ between host and target (an FMA contraction, a
/// different libm), an output within this much still passes, reported as "within tolerance".
/// Rust does not contract `a * b + c` and the cascade calls no libm function, so the expected
/// verdict is "bit-exact". 0.1 mV / 0.1 mA: about 50 ulp at the 24 V / 20 A limits, far below
/// a quantisation step of the sensors (one Hall count is 0.075 rad).
pub const TOLERANCE_V: f32 = 1e-4;
pub const TOLERANCE_A: f32 = 1e-4;

/// What the cascade is built from (host-sim's `RunConfig`, as `f32`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Header {
    pub periods: u32,
    pub hall0: i32,
    pub belt_reduction: f32,
    pub tau_bs: f32,
    pub tau_p: f32,
    pub ra_ohm: f32,
    pub la_h: f32,
    pub supply_v: f32,
    pub controller: ControllerKind,
}

fn controller_code(kind: ControllerKind) -> u32 {
    match kind {
        ControllerKind::Paper => 0,
        ControllerKind::Ecu => 1,
    }
}

impl Header {
    pub fn to_bytes(&self) -> [u8; HEADER_BYTES] {
        let mut out = [0u8; HEADER_BYTES];
        out[..4].copy_from_slice(&MAGIC);
        let words = [
            self.periods,
            self.hall0 as u32,
            self.belt_reduction.to_bits(),
            self.tau_bs.to_bits(),
            self.tau_p.to_bits(),
            self.ra_ohm.to_bits(),
            self.la_h.to_bits(),
            self.supply_v.to_bits(),
            controller_code(self.controller),
        ];
        for (chunk, word) in out[4..].chunks_exact_mut(4).zip(words) {
            chunk.copy_from_slice(&word.to_le_bytes());
        }
        out
    }

    fn read(r: &mut Reader<'_>) -> Option<Self> {
        if r.take::<4>()? != MAGIC {
            return None;
        }
        let mut f = || r.u32();
        Some(Header {
            periods: f()?,
            hall0: f()? as i32,
            belt_reduction: f32::from_bits(f()?),
            tau_bs: f32::from_bits(f()?),
            tau_p: f32::from_bits(f()?),
            ra_ohm: f32::from_bits(f()?),
            la_h: f32::from_bits(f()?),
            supply_v: f32::from_bits(f()?),
            controller: match f()? {
                0 => ControllerKind::Paper,
                1 => ControllerKind::Ecu,
                _ => return None,
            },
        })
    }

    /// The controller as host-sim builds it for this run; `None` if the header's gearing is
    /// invalid.
    pub fn cascade(&self) -> Option<SteeringController> {
        let gains = EposGains::PAPER.to_si().ok()?;
        let gearing = Gearing::new(self.belt_reduction, self.tau_bs, self.tau_p)?;
        let mut cascade: SteeringController = match self.controller {
            ControllerKind::Paper => Cascade::new(&gains, gearing).into(),
            ControllerKind::Ecu => ColumnCascade::new(&gains, gearing, EcuTuning::PAPER).into(),
        };
        cascade.set_anti_windup(AntiWindup::ConditionalIntegration);
        cascade.set_winding(self.ra_ohm, self.la_h);
        cascade.set_voltage_limit(Volts(self.supply_v));
        cascade.reset(self.hall0);
        Some(cascade)
    }
}

pub fn reference_code(result: Result<(), ReferenceError>) -> u8 {
    match result {
        Ok(()) => 0,
        Err(ReferenceError::NotFinite) => 1,
        Err(ReferenceError::OutOfRange) => 2,
    }
}

pub fn position_code(status: PositionStatus) -> u8 {
    match status {
        PositionStatus::Linear => 0,
        PositionStatus::Saturated => 1,
        PositionStatus::InputNotFinite => 2,
    }
}

pub fn current_code(status: CurrentStatus) -> u8 {
    match status {
        CurrentStatus::Linear => 0,
        CurrentStatus::Saturated => 1,
        CurrentStatus::CurrentLimited => 2,
        CurrentStatus::InputNotFinite => 3,
    }
}

/// The record of one reference sample (the recorder's side).
pub fn reference_record(deg: f32, result: Result<(), ReferenceError>) -> [u8; 5] {
    let b = deg.to_bits().to_le_bytes();
    [b[0], b[1], b[2], b[3], reference_code(result)]
}

/// The record of one position step (the column as the controller got it, NaN for none); ten
/// current records follow it.
pub fn position_record(hall: i32, column_rad: f32, out: &PositionOutput) -> [u8; 13] {
    let mut rec = [0u8; 13];
    rec[..4].copy_from_slice(&hall.to_le_bytes());
    rec[4..].copy_from_slice(&two_words_and_code(
        column_rad.to_bits(),
        out.current.0.to_bits(),
        position_code(out.status),
    ));
    rec
}

/// The record of one current step.
pub fn current_record(measured: Amps, out: &CurrentOutput) -> [u8; 9] {
    two_words_and_code(
        measured.0.to_bits(),
        out.voltage.0.to_bits(),
        current_code(out.status),
    )
}

fn two_words_and_code(a: u32, b: u32, code: u8) -> [u8; 9] {
    let mut out = [0u8; 9];
    out[..4].copy_from_slice(&a.to_le_bytes());
    out[4..8].copy_from_slice(&b.to_le_bytes());
    out[8] = code;
    out
}

/// Which step a [`Meter`] is timing.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Step {
    Position,
    Current,
}

/// Wraps each cascade step of a replay: the emulated suite counts instructions here.
pub trait Meter {
    fn measure<R>(&mut self, step: Step, f: impl FnOnce() -> R) -> R;
}

/// No measurement (the host).
#[derive(Debug, Clone, Copy, Default)]
pub struct NoMeter;

impl Meter for NoMeter {
    fn measure<R>(&mut self, _step: Step, f: impl FnOnce() -> R) -> R {
        f()
    }
}

/// The first output that was not bit-identical.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Difference {
    pub period: u32,
    pub tick: u32,
    /// `None` for the position step, `Some(k)` for the k-th current step of the tick.
    pub current_step: Option<u32>,
    pub what: &'static str,
    pub expected: u32,
    pub got: u32,
}

/// How a replay compared.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Report {
    pub periods: u32,
    pub position_steps: u32,
    pub current_steps: u32,
    /// Outputs compared (reference results, set-points, voltages and statuses).
    pub compared: u32,
    /// Outputs not bit-identical but within [`TOLERANCE_V`] / [`TOLERANCE_A`].
    pub within_tolerance: u32,
    /// Outputs beyond the tolerance, and status codes that differ.
    pub differing: u32,
    pub max_abs_diff_a: f32,
    pub max_abs_diff_v: f32,
    pub first_difference: Option<Difference>,
}

/// The verdict the suite prints.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Verdict {
    BitExact,
    WithinTolerance,
    Differs,
}

impl Report {
    pub fn verdict(&self) -> Verdict {
        if self.differing > 0 {
            Verdict::Differs
        } else if self.within_tolerance > 0 {
            Verdict::WithinTolerance
        } else {
            Verdict::BitExact
        }
    }

    fn note(&mut self, at: Difference, tolerance: Option<f32>) {
        self.compared += 1;
        if at.expected == at.got {
            return;
        }
        let (e, g) = (f32::from_bits(at.expected), f32::from_bits(at.got));
        let diff = (e - g).abs();
        match tolerance {
            Some(tol) if diff <= tol => {
                self.within_tolerance += 1;
                if tol == TOLERANCE_V {
                    self.max_abs_diff_v = self.max_abs_diff_v.max(diff);
                } else {
                    self.max_abs_diff_a = self.max_abs_diff_a.max(diff);
                }
            }
            _ => self.differing += 1,
        }
        if self.first_difference.is_none() {
            self.first_difference = Some(at);
        }
    }
}

/// Why a file could not be replayed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FormatError {
    Header,
    Truncated { offset: usize },
    TrailingBytes { offset: usize },
    Gearing,
}

/// A deliberate corruption of the expected outputs, to show that the check can fail: the
/// expected voltage of the `current_step`-th current step (counted over the run) is taken 1 V
/// higher than recorded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Tamper {
    pub current_step: u32,
}

/// Feed the recorded inputs to a fresh cascade and compare every output with the record.
pub fn replay(
    bytes: &[u8],
    meter: &mut impl Meter,
    tamper: Option<Tamper>,
) -> Result<Report, FormatError> {
    let mut r = Reader::new(bytes);
    let header = Header::read(&mut r).ok_or(FormatError::Header)?;
    let mut cascade = header.cascade().ok_or(FormatError::Gearing)?;
    let mut report = Report::default();
    let truncated = |r: &Reader<'_>| FormatError::Truncated { offset: r.offset() };
    for period in 0..header.periods {
        let deg = f32::from_bits(r.u32().ok_or_else(|| truncated(&r))?);
        let expected = r.u8().ok_or_else(|| truncated(&r))?;
        let got = reference_code(cascade.push_reference(SteeringDeg(deg)));
        let at = |what, expected, got| Difference {
            period,
            tick: 0,
            current_step: None,
            what,
            expected,
            got,
        };
        report.note(at("reference result", expected.into(), got.into()), None);
        for tick in 0..POSITION_TICKS_PER_REFERENCE {
            let hall = r.u32().ok_or_else(|| truncated(&r))? as i32;
            let column = f32::from_bits(r.u32().ok_or_else(|| truncated(&r))?);
            let column = column.is_finite().then_some(SteeringRad(column));
            let expected_a = r.u32().ok_or_else(|| truncated(&r))?;
            let expected_status = r.u8().ok_or_else(|| truncated(&r))?;
            let out = meter.measure(Step::Position, || cascade.position_step(hall, column));
            let at = |what, expected, got, step| Difference {
                period,
                tick,
                current_step: step,
                what,
                expected,
                got,
            };
            report.position_steps += 1;
            report.note(
                at(
                    "current set-point",
                    expected_a,
                    out.current.0.to_bits(),
                    None,
                ),
                Some(TOLERANCE_A),
            );
            report.note(
                at(
                    "position status",
                    expected_status.into(),
                    position_code(out.status).into(),
                    None,
                ),
                None,
            );
            for k in 0..CURRENT_TICKS_PER_POSITION_TICK {
                let measured = f32::from_bits(r.u32().ok_or_else(|| truncated(&r))?);
                let mut expected_v = r.u32().ok_or_else(|| truncated(&r))?;
                let expected_status = r.u8().ok_or_else(|| truncated(&r))?;
                if tamper.is_some_and(|t| t.current_step == report.current_steps) {
                    expected_v = (f32::from_bits(expected_v) + 1.0).to_bits();
                }
                let out = meter.measure(Step::Current, || cascade.current_step(Amps(measured)));
                report.current_steps += 1;
                report.note(
                    at("voltage", expected_v, out.voltage.0.to_bits(), Some(k)),
                    Some(TOLERANCE_V),
                );
                report.note(
                    at(
                        "current status",
                        expected_status.into(),
                        current_code(out.status).into(),
                        Some(k),
                    ),
                    None,
                );
            }
        }
        report.periods += 1;
    }
    if !r.is_empty() {
        return Err(FormatError::TrailingBytes { offset: r.offset() });
    }
    Ok(report)
}

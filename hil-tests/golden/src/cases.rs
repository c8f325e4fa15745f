//! Seeded cases for the codecs, the CANopen parsers, the CiA 402 rules, the ECU state machine
//! and the cascade under arbitrary inputs. Both sides generate the same inputs from the same
//! seeds; a case's outputs go into a [`CaseWriter`] with `Debug`, and the golden file holds one
//! FNV-1a hash per case:
//!
//! ```text
//! file     "GLC1", groups u32, then per group: group id u32, cases u32, cases x hash u64
//! ```

use crate::{Fnv, Reader};
use core::fmt::Write;
use steering_ecu::as_state::AsState;
use steering_ecu::can::{Frame, StandardId};
use steering_ecu::canopen::cia402::{self, State, Target};
use steering_ecu::canopen::{NodeId, emcy, nmt, pdo, sdo};
use steering_ecu::controller::ControllerKind;
use steering_ecu::ecu::{DriveChoice, Ecu, EcuBuild};
use steering_ecu::gains::EposGains;
use steering_ecu::paper_mode::Cascade;
use steering_ecu::protocol::{AliveCounter, E2eChecker, ProtocolConfig, Reference, Status};
use steering_ecu::units::{Amps, MotorRad, SteeringDeg};

pub const MAGIC: [u8; 4] = *b"GLC1";

/// The cases' generator: xorshift64*, the same on the host and the target.
pub use det_rng::XorShift64Star as Rng;

/// Hashes what a case writes, and keeps its first bytes to show when the case differs.
#[derive(Debug, Clone)]
pub struct CaseWriter {
    hash: Fnv,
    head: [u8; 192],
    head_len: usize,
}

impl CaseWriter {
    pub const fn new() -> Self {
        CaseWriter {
            hash: Fnv::new(),
            head: [0; 192],
            head_len: 0,
        }
    }

    pub fn hash(&self) -> u64 {
        self.hash.finish()
    }

    /// The start of the case's text (whole characters only).
    pub fn head(&self) -> &str {
        let bytes = &self.head[..self.head_len];
        match core::str::from_utf8(bytes) {
            Ok(s) => s,
            Err(e) => core::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or(""),
        }
    }
}

impl Default for CaseWriter {
    fn default() -> Self {
        Self::new()
    }
}

impl Write for CaseWriter {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        self.hash.bytes(s.as_bytes());
        let room = self.head.len() - self.head_len;
        let n = room.min(s.len());
        self.head[self.head_len..self.head_len + n].copy_from_slice(&s.as_bytes()[..n]);
        self.head_len += n;
        Ok(())
    }
}

/// The case groups, in file order.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Group {
    ReferenceCodec,
    StatusCodec,
    E2e,
    Canopen,
    Cia402,
    Ecu,
    ArbitraryCascade,
}

pub const GROUPS: [Group; 7] = [
    Group::ReferenceCodec,
    Group::StatusCodec,
    Group::E2e,
    Group::Canopen,
    Group::Cia402,
    Group::Ecu,
    Group::ArbitraryCascade,
];

/// Writes `Debug` of each value, `;`-separated. A write to a `CaseWriter` cannot fail.
macro_rules! out {
    ($w:expr, $($v:expr),+) => {
        {
            $( let _ = write!($w, "{:?};", $v); )+
        }
    };
}

impl Group {
    pub fn id(self) -> u32 {
        self as u32
    }

    pub fn from_id(id: u32) -> Option<Self> {
        GROUPS.iter().copied().find(|g| g.id() == id)
    }

    pub fn name(self) -> &'static str {
        match self {
            Group::ReferenceCodec => "reference codec",
            Group::StatusCodec => "status codec",
            Group::E2e => "E2E check",
            Group::Canopen => "CANopen parsers",
            Group::Cia402 => "CiA 402 rules",
            Group::Ecu => "ECU state machine (10 ms per case)",
            Group::ArbitraryCascade => "cascade, arbitrary inputs",
        }
    }

    pub fn cases(self) -> u32 {
        match self {
            Group::ReferenceCodec | Group::StatusCodec | Group::Canopen => 400,
            Group::E2e => 600,
            Group::Cia402 => 300,
            Group::Ecu => 300,
            Group::ArbitraryCascade => 200,
        }
    }

    /// Run every case; `done(index, writer)` is called after each.
    pub fn run(self, done: &mut impl FnMut(u32, &CaseWriter)) {
        // The low bit set keeps the state off xorshift's fixed point 0; the stored vectors were
        // made with this seeding.
        let seed = 0x9E37_79B9_7F4A_7C15 ^ u64::from(self.id()).wrapping_mul(0x100);
        let mut rng = Rng::from_state(seed | 1);
        match self {
            Group::ReferenceCodec => per_case(self, &mut rng, done, reference_case),
            Group::StatusCodec => per_case(self, &mut rng, done, status_case),
            Group::Canopen => per_case(self, &mut rng, done, canopen_case),
            Group::Cia402 => per_case(self, &mut rng, done, cia402_case),
            Group::E2e => e2e_cases(self.cases(), &mut rng, done),
            Group::Ecu => ecu_cases(self.cases(), &mut rng, done),
            Group::ArbitraryCascade => arbitrary_cascade_cases(self.cases(), &mut rng, done),
        }
    }
}

fn per_case(
    group: Group,
    rng: &mut Rng,
    done: &mut impl FnMut(u32, &CaseWriter),
    case: fn(&mut Rng, &mut CaseWriter),
) {
    for i in 0..group.cases() {
        let mut w = CaseWriter::new();
        case(rng, &mut w);
        done(i, &w);
    }
}

fn id(raw: u32) -> StandardId {
    StandardId::new((raw & 0x7FF) as u16).unwrap_or(steering_ecu::protocol::REFERENCE_ID)
}

fn as_state(code: u32) -> AsState {
    AsState::from_code(code as u8).unwrap_or(AsState::Off)
}

/// A frame with an arbitrary length and payload, on `id`.
fn arbitrary_frame(rng: &mut Rng, id: StandardId) -> Frame {
    let data = rng.bytes();
    let len = if rng.below(4) == 0 { rng.below(9) } else { 8 } as usize;
    Frame::new(id, &data[..len]).unwrap_or(Frame::from_bytes(id, data))
}

/// A third each: an encoded message, any payload on the codec's own ID, anything on any ID.
fn codec_frame(rng: &mut Rng, own_id: StandardId, encode: fn(&mut Rng) -> Frame) -> Frame {
    match rng.below(3) {
        0 => encode(rng),
        1 => arbitrary_frame(rng, own_id),
        _ => {
            let raw = rng.below(0x800);
            arbitrary_frame(rng, id(raw))
        }
    }
}

fn reference_case(rng: &mut Rng, w: &mut CaseWriter) {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = codec_frame(rng, cfg.reference_id, |rng| {
        ProtocolConfig::DEFAULT.encode_reference(&Reference {
            angle: SteeringDeg(rng.any_f32(200.0)),
            as_state: as_state(rng.below(8)),
            counter: AliveCounter::wrapping(rng.below(256) as u8),
            clear_faults: rng.below(2) == 1,
        })
    });
    out!(w, frame, cfg.decode_reference(&frame));
}

fn status_case(rng: &mut Rng, w: &mut CaseWriter) {
    let cfg = ProtocolConfig::DEFAULT;
    let frame = codec_frame(rng, cfg.status_id, |rng| {
        ProtocolConfig::DEFAULT.encode_status(&Status {
            angle: SteeringDeg(rng.any_f32(400.0)),
            current: Amps(rng.any_f32(60.0)),
            ecu_state: rng.below(256) as u8,
            faults: rng.below(0x1_0000) as u16,
            counter: AliveCounter::wrapping(rng.below(256) as u8),
        })
    });
    out!(w, frame, cfg.decode_status(&frame));
}

fn canopen_case(rng: &mut Rng, w: &mut CaseWriter) {
    let Some(node) = NodeId::new(1 + rng.below(127) as u8) else {
        return;
    };
    let bases = [0x000, 0x080, 0x180, 0x280, 0x580, 0x600, 0x700];
    let base = bases[rng.below(bases.len() as u32) as usize];
    let node_part = if base == 0 { 0 } else { u32::from(node.raw()) };
    let offset = rng.below(2);
    let frame = arbitrary_frame(rng, id(base + node_part + offset));
    out!(
        w,
        frame,
        sdo::parse_response(&frame, node),
        sdo::parse_request(&frame, node),
        emcy::parse(&frame, node),
        nmt::parse_command(&frame),
        nmt::parse_heartbeat(&frame, node),
        pdo::decode_i32(frame.data()),
        pdo::decode_u16_i32(frame.data())
    );
}

fn cia402_case(rng: &mut Rng, w: &mut CaseWriter) {
    let word = rng.below(0x1_0000) as u16;
    let state = State::from_statusword(word);
    out!(w, word, state);
    if let Some(state) = state {
        for target in [
            Target::SwitchOnDisabled,
            Target::ReadyToSwitchOn,
            Target::SwitchedOn,
            Target::OperationEnabled,
        ] {
            out!(w, cia402::next_command(state, target));
        }
    }
}

/// A reference stream at 10 ms with jitter, gaps, repeats, skips, corrupt bytes and jumps.
fn e2e_cases(cases: u32, rng: &mut Rng, done: &mut impl FnMut(u32, &CaseWriter)) {
    let cfg = ProtocolConfig::DEFAULT;
    let Ok(mut checker) = E2eChecker::new(cfg) else {
        return;
    };
    let mut now: u64 = 0;
    let mut counter = AliveCounter::wrapping(0);
    let mut angle = 0.0f32;
    for i in 0..cases {
        now += 10_000 + u64::from(rng.below(2_000));
        if rng.below(20) == 0 {
            now += u64::from(rng.below(80_000));
        }
        match rng.below(12) {
            0 => {}
            1 => counter = counter.next().next(),
            _ => counter = counter.next(),
        }
        angle += if rng.below(15) == 0 {
            rng.any_f32(30.0)
        } else {
            rng.below(600) as f32 * 0.01 - 3.0
        };
        let reference = Reference {
            angle: SteeringDeg(angle),
            as_state: as_state(rng.below(7)),
            counter,
            clear_faults: false,
        };
        let mut frame = cfg.encode_reference(&reference);
        if rng.below(15) == 0 {
            let mut data = [0u8; 8];
            data.copy_from_slice(frame.data());
            data[rng.below(8) as usize] ^= 1 << rng.below(8);
            frame = Frame::from_bytes(frame.id(), data);
        }
        let mut w = CaseWriter::new();
        out!(
            w,
            now,
            frame,
            checker.check(&frame, now),
            checker.timed_out(now),
            checker.invalid_in_row(),
            checker.in_fault()
        );
        done(i, &w);
        if !angle.is_finite() || angle.abs() > 200.0 {
            angle = 0.0;
        }
    }
    let mut w = CaseWriter::new();
    out!(w, checker.drops());
    done(cases, &w);
}

/// The ECU at 2 kHz / 20 kHz through an AS sequence Off -> Ready -> Driving, a reference gap
/// long enough for the timeout fault, Off and a clear request, Driving again, and an
/// over-current. One case per 10 ms reference period.
fn ecu_cases(cases: u32, rng: &mut Rng, done: &mut impl FnMut(u32, &CaseWriter)) {
    let build = EcuBuild::new(ControllerKind::Paper, DriveChoice::Direct);
    let Some(mut ecu) = Ecu::build(build, 0) else {
        return;
    };
    let cfg = ProtocolConfig::DEFAULT;
    let mut counter = AliveCounter::wrapping(0);
    let mut hall: i32 = 0;
    for period in 0..cases {
        let mut w = CaseWriter::new();
        let t0 = u64::from(period) * 10_000;
        let as_state = match period {
            0..20 => AsState::Off,
            20..40 => AsState::Ready,
            40..150 => AsState::Driving,
            150..200 => AsState::Off,
            _ => AsState::Driving,
        };
        // Frames stop for 150 ms in Driving: hold, then the timeout fault.
        let silent = (100..115).contains(&period);
        if !silent {
            counter = counter.next();
            // A 1 s triangle of +-20 deg (no libm on the target), with a little noise.
            let phase = (period % 100) as f32 * 0.01;
            let triangle = 1.0 - 4.0 * (phase - 0.5).abs();
            let angle = 20.0 * triangle + 0.5 * (rng.below(100) as f32 * 0.01);
            let reference = Reference {
                angle: SteeringDeg(angle),
                as_state,
                counter,
                clear_faults: period == 180,
            };
            let frame = cfg.encode_reference(&reference);
            out!(w, ecu.on_reference_frame(t0, &frame));
        }
        for tick in 0..20u64 {
            let now = t0 + tick * 500;
            out!(w, ecu.tick(now));
            if tick % 2 == 0 {
                let column = SteeringDeg(hall as f32 * 0.075 * 57.3 / 85.45);
                out!(w, ecu.on_encoder(now, column));
            }
            hall += rng.below(3) as i32 - 1;
            out!(w, ecu.position_tick(hall).0.to_bits());
            for k in 0..10u64 {
                let over = (250..255).contains(&period);
                let measured = if over { 25.0 } else { rng.any_f32(5.0) };
                let measured = if measured.is_finite() { measured } else { 0.0 };
                let v = ecu.current_tick(now + k * 50, Amps(measured));
                out!(w, v.map(|v| v.0.to_bits()));
            }
        }
        out!(w, ecu.status_frame(), ecu.output(), ecu.clear_refusals());
        done(period, &w);
    }
}

/// The cascade fed arbitrary bit patterns (NaN, infinities, subnormals) and plausible values,
/// 1000 operations per case.
fn arbitrary_cascade_cases(cases: u32, rng: &mut Rng, done: &mut impl FnMut(u32, &CaseWriter)) {
    let mut c = Cascade::paper();
    for i in 0..cases {
        let mut w = CaseWriter::new();
        for k in 0..1000u32 {
            match rng.next_u64() % 8 {
                0 => out!(w, c.push_reference(SteeringDeg(rng.any_f32(120.0)))),
                1 => out!(w, c.position_step(rng.next_u64() as i32)),
                2 => out!(w, c.position_step_at(MotorRad(rng.any_f32(200.0)))),
                3 if k % 500 == 3 => c.reset(rng.next_u64() as i32),
                4 if k % 500 == 4 => {
                    let mut g = EposGains::PAPER;
                    g.position_kd_ma_s_per_rad = rng.any_f32(1000.0);
                    out!(w, c.set_gains(&g));
                }
                5 if k % 500 == 5 => c.set_winding(rng.any_f32(1.0), rng.any_f32(1e-3)),
                _ => out!(w, c.current_step(Amps(rng.any_f32(40.0)))),
            }
        }
        done(i, &w);
    }
}

/// Cases in one group that did not match.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct GroupReport {
    pub cases: u32,
    pub differing: u32,
    pub first_differing: Option<u32>,
}

/// Why a cases file could not be read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FormatError {
    Header,
    UnknownGroup { id: u32 },
    Truncated { offset: usize },
    CaseCount { group: Group, file: u32, code: u32 },
}

/// Check every group of a cases file: `report(group, result, head)` is called per group, with
/// the text head of the first differing case. Returns the number of differing cases.
pub fn check(
    bytes: &[u8],
    report: &mut impl FnMut(Group, &GroupReport, Option<&CaseWriter>),
) -> Result<u32, FormatError> {
    let mut r = Reader::new(bytes);
    if r.take::<4>() != Some(MAGIC) {
        return Err(FormatError::Header);
    }
    let groups = r.u32().ok_or(FormatError::Header)?;
    let mut differing = 0;
    for _ in 0..groups {
        let gid = r
            .u32()
            .ok_or(FormatError::Truncated { offset: r.offset() })?;
        let group = Group::from_id(gid).ok_or(FormatError::UnknownGroup { id: gid })?;
        let file_cases = r
            .u32()
            .ok_or(FormatError::Truncated { offset: r.offset() })?;
        let mut result = GroupReport::default();
        let mut first: Option<CaseWriter> = None;
        let mut truncated = None;
        group.run(&mut |i, w| {
            result.cases += 1;
            let Some(expected) = r.u64() else {
                truncated = Some(r.offset());
                return;
            };
            if expected != w.hash() {
                result.differing += 1;
                if first.is_none() {
                    result.first_differing = Some(i);
                    first = Some(w.clone());
                }
            }
        });
        if let Some(offset) = truncated {
            return Err(FormatError::Truncated { offset });
        }
        if result.cases != file_cases {
            return Err(FormatError::CaseCount {
                group,
                file: file_cases,
                code: result.cases,
            });
        }
        differing += result.differing;
        report(group, &result, first.as_ref());
    }
    Ok(differing)
}

/// Write a cases file (the generator's side): `put` receives the bytes in order.
pub fn write(put: &mut impl FnMut(&[u8])) {
    put(&MAGIC);
    put(&(GROUPS.len() as u32).to_le_bytes());
    for group in GROUPS {
        let mut hashes_done = 0u32;
        // The count is known only after the run (E2E adds a summary case): run twice.
        group.run(&mut |_, _| hashes_done += 1);
        put(&group.id().to_le_bytes());
        put(&hashes_done.to_le_bytes());
        group.run(&mut |_, w| put(&w.hash().to_le_bytes()));
    }
}

//! A model of a maxon EPOS4's CANopen side for tests: the object dictionary subset the ECU
//! uses (index, sub-index, type and access as in maxon's EDS, see [`super::epos4`]), the SDO
//! server, NMT (PDOs only when Operational), the heartbeat producer and consumer, EMCY on
//! faults, and a CiA 402 state machine driven by the controlword that refuses illegal
//! transitions. The library's EPOS4-mode tests and host-sim's simulated drive run this one
//! model; what turns the motor (nothing, or host-sim's cascade and plant) sits behind
//! [`Motor`].
//!
//! Stricter than the drive where that helps tests: read-only objects refuse writes with the
//! CiA 301 abort code, writes of the wrong size are aborted, PDO mappings can only change
//! while the PDO is invalid and its count is 0, TPDOs go out only when configured synchronous,
//! and every refused controlword is recorded.
//!
//! Timing: [`Epos4Model::advance`] runs the drive in steps of one current-loop period
//! ([`TICK_US`]); an RPDO configured synchronous is latched and applied at the next SYNC,
//! where its target position (inc) goes to [`Motor::target`].
//!
//! Not in the firmware: compiled for the library's tests and with the `epos4-model` feature.
//! No heap: the dictionary, the frames it sends and the refusals are bounded buffers.
// Not in the firmware, so the firmware's no-panic rule for sums is relaxed here: the sums are
// the dictionary's small constants (PDO number 0..4, node 1..127), counters and µs times from
// 0, none near its type's range in a test; an overflow would panic as the test's failure.
#![allow(clippy::arithmetic_side_effects)]

use crate::can::{Frame, StandardId};
use crate::canopen::cia402::{State, status};
use crate::canopen::emcy::Emcy;
use crate::canopen::epos4::od;
use crate::canopen::nmt::{self, NmtCommand, NmtState};
use crate::canopen::pdo::{COB_ID_INVALID, MappingEntry};
use crate::canopen::sdo::{self, AbortCode, ServerRequest, Width};
use crate::canopen::{NodeId, ObjectAddress};
use crate::gains::EposGains;
use crate::paper_mode::CURRENT_LOOP_HZ;

/// One step of [`Epos4Model::advance`]: the drive's current-loop period, µs.
pub const TICK_US: u64 = 1_000_000 / CURRENT_LOOP_HZ as u64;
/// Entries of the error history 0x1003.
const ERROR_HISTORY_LEN: u8 = 5;
/// Objects in the dictionary (174 are defined).
const OD_CAPACITY: usize = 192;
/// Frames one call can produce: an SDO answer, four TPDOs, a heartbeat, an EMCY, a boot-up.
const OUT_CAPACITY: usize = 16;
/// Refused controlwords kept (the first ones).
const REFUSALS_KEPT: usize = 16;

/// The frames one [`Epos4Model::on_frame`] call answers with.
pub type Frames = heapless::Vec<Frame, OUT_CAPACITY>;

/// What moves behind the drive's power stage. The model asks it for the live values it
/// reports (position actual, currents) and tells it when the power stage runs and where to go.
pub trait Motor {
    /// One current-loop period ([`TICK_US`]); `running`: Operation enabled in CSP, the
    /// drive's loops run; otherwise the power stage is off.
    fn tick(&mut self, running: bool);
    /// The drive enters Operation enabled with these gains (0x30A0, 0x30A1 in their units).
    fn enable(&mut self, gains: &EposGains);
    /// A target position the interpolator takes, inc from the drive's power-up (within the
    /// software position limits).
    fn target(&mut self, inc: i32);
    /// Position actual value (0x6064), inc from the drive's power-up.
    fn position_inc(&self) -> i32;
    /// Current actual value averaged (0x30D1 sub 1), mA.
    fn current_averaged_ma(&self) -> i32;
    /// Current actual value (0x30D1 sub 2), mA.
    fn current_actual_ma(&self) -> i32;
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Access {
    Ro,
    Rw,
    Const,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Entry {
    value: u32,
    width: Width,
    access: Access,
}

/// A controlword the drive did not act on, and the state it was in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Refusal {
    pub state: State,
    pub controlword: u16,
}

/// Device-side reading of a controlword (CiA 402-2 Table 31).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum DeviceCommand {
    Shutdown,
    SwitchOn,
    EnableOperation,
    DisableVoltage,
    QuickStop,
    FaultReset,
}

fn decode_controlword(cw: u16, previous: u16) -> Option<DeviceCommand> {
    if cw & 0x80 != 0 {
        return (previous & 0x80 == 0).then_some(DeviceCommand::FaultReset);
    }
    if cw & 0x02 == 0 {
        Some(DeviceCommand::DisableVoltage)
    } else if cw & 0x06 == 0x02 {
        Some(DeviceCommand::QuickStop)
    } else if cw & 0x07 == 0x06 {
        Some(DeviceCommand::Shutdown)
    } else if cw & 0x0F == 0x07 {
        Some(DeviceCommand::SwitchOn)
    } else if cw & 0x0F == 0x0F {
        Some(DeviceCommand::EnableOperation)
    } else {
        None
    }
}

/// The drive's protocol side; the motor behind it is passed to each call.
#[derive(Debug)]
pub struct Epos4Model {
    node: NodeId,
    /// Sorted by address.
    od: heapless::Vec<(ObjectAddress, Entry), OD_CAPACITY>,
    nmt: NmtState,
    state: State,
    last_controlword: u16,
    refusals: heapless::Vec<Refusal, REFUSALS_KEPT>,
    now_us: u64,
    booted: bool,
    next_heartbeat_us: u64,
    pending_rpdo: Option<heapless::Vec<u8, 8>>,
    gain_limit: Option<(ObjectAddress, u32)>,
    quick_stop_until_us: u64,
    limited_targets: u64,
    pdo_length_errors: u64,
    out: Frames,
    /// Consumer heartbeat (0x1016 sub 1): when the watched node's heartbeat last came; the
    /// watch starts with the first one (CiA 301).
    consumer_last_us: Option<u64>,
}

impl Epos4Model {
    /// A drive at node `node`, powered up at t = 0; it sends its boot-up message on the
    /// first [`Epos4Model::advance`] and ignores frames until then.
    pub fn new(node: NodeId) -> Epos4Model {
        let mut model = Epos4Model {
            node,
            od: heapless::Vec::new(),
            nmt: NmtState::BootUp,
            state: State::NotReadyToSwitchOn,
            last_controlword: 0,
            refusals: heapless::Vec::new(),
            now_us: 0,
            booted: false,
            next_heartbeat_us: u64::MAX,
            pending_rpdo: None,
            gain_limit: None,
            quick_stop_until_us: 0,
            limited_targets: 0,
            pdo_length_errors: 0,
            out: Frames::new(),
            consumer_last_us: None,
        };
        model.load_defaults();
        model
    }

    fn define(&mut self, object: ObjectAddress, entry: Entry) {
        match self.od.binary_search_by_key(&object, |(a, _)| *a) {
            Ok(at) => {
                if let Some((_, slot)) = self.od.get_mut(at) {
                    *slot = entry;
                }
            }
            // A full dictionary drops the object: it then reads as missing.
            Err(at) => {
                let _ = self.od.insert(at, (object, entry));
            }
        }
    }

    fn entry(&self, object: ObjectAddress) -> Option<&Entry> {
        self.od
            .binary_search_by_key(&object, |(a, _)| *a)
            .ok()
            .and_then(|at| self.od.get(at))
            .map(|(_, e)| e)
    }

    /// EDS default values (see the module docs of [`super::epos4`]).
    fn load_defaults(&mut self) {
        use Access::*;
        use Width::*;
        let n = self.node.raw() as u32;
        let mut e = |index: u16, sub: u8, width: Width, access: Access, value: u32| {
            self.define(
                ObjectAddress::new(index, sub),
                Entry {
                    value,
                    width,
                    access,
                },
            );
        };
        e(0x1001, 0, U8, Ro, 0);
        // Error history (CiA 301 0x1003): sub 0 = number of entries (write 0 to clear),
        // subs 1..=5 newest first, as the EPOS4 keeps five.
        e(0x1003, 0, U8, Rw, 0);
        for s in 1..=ERROR_HISTORY_LEN {
            e(0x1003, s, U32, Ro, 0);
        }
        e(0x1005, 0, U32, Const, 0x80);
        e(0x1014, 0, U32, Ro, 0x80 + n);
        // Consumer heartbeat time: bits 16..23 the node watched, bits 0..15 the time, ms.
        e(0x1016, 0, U8, Ro, 2);
        e(0x1016, 1, U32, Rw, 0);
        e(0x1016, 2, U32, Rw, 0);
        e(0x1017, 0, U16, Rw, 0);
        for p in 0..4u16 {
            // RPDO1 and TPDO1 valid at power-up, the others not; TPDOs without RTR (bit 30).
            let (rx_flags, tx_flags) = if p == 0 {
                (0, 0x4000_0000)
            } else {
                (COB_ID_INVALID, 0xC000_0000)
            };
            let cob = |base: u32| base + 0x100 * p as u32 + n;
            e(0x1400 + p, 0, U8, Ro, 2);
            e(0x1400 + p, 1, U32, Rw, rx_flags | cob(0x200));
            e(0x1400 + p, 2, U8, Rw, 255);
            e(0x1600 + p, 0, U8, Rw, 1);
            e(0x1800 + p, 0, U8, Ro, 3);
            e(0x1800 + p, 1, U32, Rw, tx_flags | cob(0x180));
            e(0x1800 + p, 2, U8, Rw, 255);
            e(0x1800 + p, 3, U16, Rw, 10);
            e(0x1A00 + p, 0, U8, Rw, 1);
            for s in 1..=12u8 {
                e(0x1600 + p, s, U32, Rw, if s == 1 { 0x6040_0010 } else { 0 });
                e(0x1A00 + p, s, U32, Rw, if s == 1 { 0x6041_0010 } else { 0 });
            }
        }
        e(0x30A0, 0, U8, Ro, 2);
        e(0x30A0, 1, U32, Rw, 1_171_880);
        e(0x30A0, 2, U32, Rw, 3_906_250);
        e(0x30A1, 0, U8, Ro, 9);
        e(0x30A1, 1, U32, Rw, 1_500_000);
        e(0x30A1, 2, U32, Rw, 780_000);
        e(0x30A1, 3, U32, Rw, 16_000);
        e(0x30A1, 4, U32, Rw, 0);
        e(0x30A1, 5, U32, Rw, 0);
        e(0x30D1, 0, U8, Ro, 2);
        e(0x30D1, 1, U32, Ro, 0);
        e(0x30D1, 2, U32, Ro, 0);
        e(0x603F, 0, U16, Ro, 0);
        e(0x6040, 0, U16, Rw, 0);
        e(0x6041, 0, U16, Ro, 0);
        // Limits the ECU writes at bring-up (values here are the model's power-up ones,
        // chosen unlike the ECU's so a missing write shows; not the EDS defaults).
        e(0x3001, 0, U8, Ro, 5);
        e(0x3001, 2, U32, Rw, 5_000);
        e(0x6065, 0, U32, Rw, 2_000);
        e(0x607F, 0, U32, Rw, 25_000);
        // Software position limits (INTEGER32, inc): the widest range, as if never set.
        e(0x607D, 0, U8, Ro, 2);
        e(0x607D, 1, U32, Rw, i32::MIN as u32);
        e(0x607D, 2, U32, Rw, i32::MAX as u32);
        e(0x6060, 0, U8, Rw, 1);
        e(0x6061, 0, U8, Ro, 1);
        e(0x6064, 0, U32, Ro, 0);
        e(0x607A, 0, U32, Rw, 0);
        e(0x60C2, 0, U8, Const, 2);
        e(0x60C2, 1, U8, Rw, 0);
        e(0x60C2, 2, U8, Rw, (-3i8) as u8 as u32);
    }

    // ----- test hooks -------------------------------------------------------------------

    /// Make the drive keep at most `max` in `object` (a firmware limit the ECU does not
    /// know about): the write is confirmed, the read-back differs.
    pub fn limit_gain(&mut self, object: ObjectAddress, max: u32) {
        self.gain_limit = Some((object, max));
    }

    /// A drive error: Fault state, 0x603F = `code`, EMCY sent (with the next call's frames).
    pub fn inject_fault<M: Motor + ?Sized>(&mut self, code: u16, motor: &mut M) {
        self.set_raw(
            od::CONTROLWORD.index,
            0,
            self.get_raw(od::CONTROLWORD.index, 0),
        );
        self.set_raw(0x603F, 0, code as u32);
        self.set_raw(0x1001, 0, 0x01);
        self.push_error_history(code);
        self.enter(State::Fault, motor);
        self.emit_emcy(code, 0x01);
    }

    fn push_error_history(&mut self, code: u16) {
        for s in (2..=ERROR_HISTORY_LEN).rev() {
            let older = self.get_raw(0x1003, s - 1);
            self.set_raw(0x1003, s, older);
        }
        self.set_raw(0x1003, 1, u32::from(code));
        let n = (self.get_raw(0x1003, 0) + 1).min(u32::from(ERROR_HISTORY_LEN));
        self.set_raw(0x1003, 0, n);
    }

    /// Controlwords the drive refused, in order (the first 16).
    pub fn refusals(&self) -> &[Refusal] {
        &self.refusals
    }

    pub fn cia402_state(&self) -> State {
        self.state
    }

    pub fn nmt_state(&self) -> NmtState {
        self.nmt
    }

    /// Raw value of an object.
    pub fn object(&self, object: ObjectAddress) -> Option<u32> {
        self.entry(object).map(|e| e.value)
    }

    /// Targets beyond the software position limits (0x607D), held at the limit as CiA 402
    /// has the drive do.
    pub fn limited_targets(&self) -> u64 {
        self.limited_targets
    }

    /// RPDOs shorter than their mapping, ignored.
    pub fn pdo_length_errors(&self) -> u64 {
        self.pdo_length_errors
    }

    // ----- bus side ---------------------------------------------------------------------

    /// Run the drive and `motor` up to `now_us` in steps of [`TICK_US`]; the frames it
    /// produced (boot-up, heartbeats, EMCY) go to `sent` in order.
    pub fn advance<M: Motor + ?Sized>(
        &mut self,
        now_us: u64,
        motor: &mut M,
        mut sent: impl FnMut(Frame),
    ) {
        if !self.booted {
            self.boot(motor);
        }
        while self.now_us + TICK_US <= now_us {
            self.drain(&mut sent);
            self.now_us += TICK_US;
            self.current_tick(motor);
            if self.now_us >= self.next_heartbeat_us {
                self.emit_heartbeat();
            }
            self.check_consumer_heartbeat(motor);
        }
        self.drain(&mut sent);
    }

    fn drain(&mut self, sent: &mut impl FnMut(Frame)) {
        for f in core::mem::take(&mut self.out) {
            sent(f);
        }
    }

    /// The consumer heartbeat's (node, time in µs), if 0x1016 sub 1 is set.
    fn consumer(&self) -> Option<(u8, u64)> {
        let raw = self.get_raw(0x1016, 1);
        let (node, ms) = (((raw >> 16) & 0xFF) as u8, u64::from(raw & 0xFFFF));
        (node != 0 && ms != 0).then_some((node, ms * 1000))
    }

    /// A heartbeat consumer that timed out is a communication error: the drive faults (EMCY
    /// 0x8130, "life guard or heartbeat error"), which switches the power stage off.
    fn check_consumer_heartbeat<M: Motor + ?Sized>(&mut self, motor: &mut M) {
        let (Some((_, time_us)), Some(last)) = (self.consumer(), self.consumer_last_us) else {
            return;
        };
        if self.now_us.saturating_sub(last) > time_us && self.state != State::Fault {
            self.consumer_last_us = None;
            self.inject_fault(0x8130, motor);
        }
    }

    /// Handle one received frame; the frames the drive answers with (and any left from a
    /// hook called since the last call).
    pub fn on_frame<M: Motor + ?Sized>(&mut self, frame: &Frame, motor: &mut M) -> Frames {
        if !self.booted {
            return Frames::new();
        }
        if let Some((watched, _)) = self.consumer()
            && let Some(node) = NodeId::new(watched)
            && nmt::parse_heartbeat(frame, node).is_some()
        {
            self.consumer_last_us = Some(self.now_us);
            return Frames::new();
        }
        if let Some((cmd, target)) = nmt::parse_command(frame) {
            if target.includes(self.node) {
                self.on_nmt(cmd, motor);
            }
        } else if nmt::is_sync(frame) {
            self.on_sync(motor);
        } else if let Some(req) = sdo::parse_request(frame, self.node) {
            if self.nmt != NmtState::Stopped {
                self.on_sdo(req, motor);
            }
        } else if self.nmt == NmtState::Operational {
            self.on_rpdo(frame, motor);
        }
        core::mem::take(&mut self.out)
    }

    fn send(&mut self, frame: Option<Frame>) {
        // The buffer holds more than one call produces; a frame beyond it would be lost.
        if let Some(f) = frame {
            let _ = self.out.push(f);
        }
    }

    fn boot<M: Motor + ?Sized>(&mut self, motor: &mut M) {
        self.booted = true;
        self.nmt = NmtState::PreOperational;
        self.state = State::SwitchOnDisabled;
        self.refresh_live(motor);
        self.send(nmt::heartbeat_frame(self.node, NmtState::BootUp));
        self.schedule_heartbeat();
    }

    fn schedule_heartbeat(&mut self) {
        let ms = self.get_raw(0x1017, 0) as u64;
        self.next_heartbeat_us = if ms == 0 {
            u64::MAX
        } else {
            self.now_us + ms * 1000
        };
    }

    fn emit_heartbeat(&mut self) {
        self.send(nmt::heartbeat_frame(self.node, self.nmt));
        self.schedule_heartbeat();
    }

    fn emit_emcy(&mut self, code: u16, register: u8) {
        let e = Emcy {
            error_code: code,
            error_register: register,
            vendor: [0; 5],
        };
        self.send(e.to_frame(self.node));
    }

    fn on_nmt<M: Motor + ?Sized>(&mut self, cmd: NmtCommand, motor: &mut M) {
        match cmd {
            NmtCommand::Start => self.nmt = NmtState::Operational,
            NmtCommand::Stop => self.nmt = NmtState::Stopped,
            NmtCommand::EnterPreOperational => self.nmt = NmtState::PreOperational,
            NmtCommand::ResetNode | NmtCommand::ResetCommunication => {
                if cmd == NmtCommand::ResetNode {
                    self.od.clear();
                    self.load_defaults();
                    self.enter(State::SwitchOnDisabled, motor);
                }
                self.booted = false;
                self.boot(motor);
            }
        }
    }

    fn get_raw(&self, index: u16, sub: u8) -> u32 {
        self.entry(ObjectAddress::new(index, sub))
            .map_or(0, |e| e.value)
    }

    fn set_raw(&mut self, index: u16, sub: u8, value: u32) {
        let object = ObjectAddress::new(index, sub);
        if let Ok(at) = self.od.binary_search_by_key(&object, |(a, _)| *a)
            && let Some((_, e)) = self.od.get_mut(at)
        {
            e.value = match e.width {
                Width::U8 => value & 0xFF,
                Width::U16 => value & 0xFFFF,
                Width::U32 => value,
            };
        }
    }

    fn on_sdo<M: Motor + ?Sized>(&mut self, req: ServerRequest, motor: &mut M) {
        self.refresh_live(motor);
        let reply = match req {
            ServerRequest::Upload { object } => match self.entry(object) {
                Some(e) => sdo::upload_response_frame(self.node, object, e.value, e.width),
                None => sdo::abort_frame(self.node, object, self.missing(object)),
            },
            ServerRequest::Download {
                object,
                value,
                bytes,
            } => match self.write(object, value, bytes, motor) {
                Ok(()) => sdo::download_response_frame(self.node, object),
                Err(code) => sdo::abort_frame(self.node, object, code),
            },
            ServerRequest::Unsupported { object, .. } => {
                sdo::abort_frame(self.node, object, AbortCode::INVALID_COMMAND)
            }
        };
        self.send(reply);
    }

    fn missing(&self, object: ObjectAddress) -> AbortCode {
        if self.od.iter().any(|(k, _)| k.index == object.index) {
            AbortCode::NO_SUB_INDEX
        } else {
            AbortCode::NO_OBJECT
        }
    }

    fn write<M: Motor + ?Sized>(
        &mut self,
        object: ObjectAddress,
        value: u32,
        bytes: Option<u8>,
        motor: &mut M,
    ) -> Result<(), AbortCode> {
        let entry = *self.entry(object).ok_or_else(|| self.missing(object))?;
        if entry.access != Access::Rw {
            return Err(AbortCode::READ_ONLY);
        }
        if let Some(n) = bytes
            && n as usize != entry.width.bytes()
        {
            return Err(AbortCode::LENGTH_MISMATCH);
        }
        let mut value = value;
        match (object.index, object.sub) {
            (0x60C2, 1) if value > od::INTERPOLATION_PERIOD_MAX as u32 => {
                return Err(AbortCode::VALUE_TOO_HIGH);
            }
            (0x6060, 0) if ![1u32, 3, 6, 8, 9, 10].contains(&value) => {
                return Err(AbortCode::VALUE_RANGE);
            }
            (0x1600..=0x1603 | 0x1A00..=0x1A03, sub) => {
                let comm = object.index - 0x200;
                if self.get_raw(comm, 1) & COB_ID_INVALID == 0 {
                    return Err(AbortCode::DEVICE_STATE);
                }
                if sub == 0 {
                    self.check_mapping(object.index, value)?;
                } else if self.get_raw(object.index, 0) != 0 {
                    return Err(AbortCode::DEVICE_STATE);
                }
            }
            _ => {}
        }
        if let Some((limited, max)) = self.gain_limit
            && limited == object
        {
            value = value.min(max);
        }
        self.set_raw(object.index, object.sub, value);
        match (object.index, object.sub) {
            (0x6040, 0) => self.on_controlword(value as u16, motor),
            (0x1017, 0) => self.schedule_heartbeat(),
            _ => {}
        }
        Ok(())
    }

    fn check_mapping(&self, index: u16, count: u32) -> Result<(), AbortCode> {
        if count > 12 {
            return Err(AbortCode::VALUE_TOO_HIGH);
        }
        let mut bits = 0u32;
        for s in 1..=count as u8 {
            let m = MappingEntry::from_raw(self.get_raw(index, s));
            if self.entry(m.object).is_none() {
                return Err(AbortCode::NOT_MAPPABLE);
            }
            bits += m.bits as u32;
        }
        if bits > 64 {
            return Err(AbortCode::PDO_TOO_LONG);
        }
        Ok(())
    }

    fn enter<M: Motor + ?Sized>(&mut self, state: State, motor: &mut M) {
        if state == State::OperationEnabled && self.state != State::OperationEnabled {
            motor.enable(&self.gains());
            // Hold where the target says: the ECU sets 0x607A to the actual position first.
            let target = self.get_raw(0x607A, 0) as i32;
            self.push_target(target, motor);
        }
        if state == State::QuickStopActive {
            self.quick_stop_until_us = self.now_us + 10_000;
        }
        self.state = state;
        self.refresh_live(motor);
    }

    /// The gains in 0x30A0 / 0x30A1 (micro-units in the dictionary).
    fn gains(&self) -> EposGains {
        let g = |index: u16, sub: u8| self.get_raw(index, sub) as f32 * 1e-3;
        EposGains {
            current_kp_mv_per_a: g(0x30A0, 1),
            current_ki_mv_per_a_ms: g(0x30A0, 2),
            position_kp_ma_per_rad: g(0x30A1, 1),
            position_ki_ma_per_rad_s: g(0x30A1, 2),
            position_kd_ma_s_per_rad: g(0x30A1, 3),
            ff_velocity_ma_s_per_rad: g(0x30A1, 4),
            ff_acceleration_ma_s2_per_rad: g(0x30A1, 5),
        }
    }

    fn on_controlword<M: Motor + ?Sized>(&mut self, cw: u16, motor: &mut M) {
        let previous = self.last_controlword;
        self.last_controlword = cw;
        use DeviceCommand as C;
        use State as S;
        let Some(cmd) = decode_controlword(cw, previous) else {
            return;
        };
        let next = match (self.state, cmd) {
            (S::Fault, C::FaultReset) => {
                self.set_raw(0x603F, 0, 0);
                self.set_raw(0x1001, 0, 0);
                self.emit_emcy(0, 0);
                Some(S::SwitchOnDisabled)
            }
            // In Fault everything but a reset is ignored, as the drive does; not a refusal.
            (S::Fault | S::FaultReactionActive, _) => return,
            (_, C::FaultReset) => None,
            (S::SwitchOnDisabled, C::Shutdown) => Some(S::ReadyToSwitchOn),
            (S::SwitchOnDisabled, C::DisableVoltage | C::QuickStop) => None,
            (S::ReadyToSwitchOn, C::SwitchOn) => Some(S::SwitchedOn),
            // EPOS4: "switch on + enable operation" from Ready to switch on (3 then 4).
            (S::ReadyToSwitchOn, C::EnableOperation) => Some(S::OperationEnabled),
            (S::ReadyToSwitchOn, C::DisableVoltage | C::QuickStop) => Some(S::SwitchOnDisabled),
            (S::ReadyToSwitchOn, C::Shutdown) => None,
            (S::SwitchedOn, C::EnableOperation) => Some(S::OperationEnabled),
            (S::SwitchedOn, C::Shutdown) => Some(S::ReadyToSwitchOn),
            (S::SwitchedOn, C::DisableVoltage | C::QuickStop) => Some(S::SwitchOnDisabled),
            (S::SwitchedOn, C::SwitchOn) => None,
            (S::OperationEnabled, C::SwitchOn) => Some(S::SwitchedOn),
            (S::OperationEnabled, C::Shutdown) => Some(S::ReadyToSwitchOn),
            (S::OperationEnabled, C::DisableVoltage) => Some(S::SwitchOnDisabled),
            (S::OperationEnabled, C::QuickStop) => Some(S::QuickStopActive),
            (S::OperationEnabled, C::EnableOperation) => None,
            (S::QuickStopActive, C::DisableVoltage) => Some(S::SwitchOnDisabled),
            (S::QuickStopActive, C::QuickStop) => None,
            (state, _) => {
                let _ = self.refusals.push(Refusal {
                    state,
                    controlword: cw,
                });
                return;
            }
        };
        if let Some(next) = next {
            self.enter(next, motor);
        }
    }

    /// The statusword, mode display, position and currents from the state and `motor`.
    fn refresh_live<M: Motor + ?Sized>(&mut self, motor: &M) {
        let mut sw = self.state.statusword_bits() | status::REMOTE;
        if self.state == State::OperationEnabled && self.csp() {
            sw |= status::FOLLOWS_TARGET;
        }
        if self.state != State::SwitchOnDisabled && self.state != State::NotReadyToSwitchOn {
            sw |= status::VOLTAGE_ENABLED;
        }
        self.set_raw(0x6041, 0, sw as u32);
        let mode = self.get_raw(0x6060, 0);
        self.set_raw(0x6061, 0, mode);
        self.set_raw(0x6064, 0, motor.position_inc() as u32);
        self.set_raw(0x30D1, 1, motor.current_averaged_ma() as u32);
        self.set_raw(0x30D1, 2, motor.current_actual_ma() as u32);
    }

    fn csp(&self) -> bool {
        self.get_raw(0x6060, 0) as u8 as i8 == od::MODE_CSP
    }

    fn push_target<M: Motor + ?Sized>(&mut self, inc: i32, motor: &mut M) {
        // The software position limits hold the target within them (min above max: as the
        // drive would, the limits are refused and the target is held at the actual position).
        let (min, max) = (
            self.get_raw(0x607D, 1) as i32,
            self.get_raw(0x607D, 2) as i32,
        );
        let inc = if min > max {
            self.limited_targets += 1;
            self.get_raw(0x6064, 0) as i32
        } else if !(min..=max).contains(&inc) {
            self.limited_targets += 1;
            inc.clamp(min, max)
        } else {
            inc
        };
        motor.target(inc);
    }

    fn on_sync<M: Motor + ?Sized>(&mut self, motor: &mut M) {
        if self.nmt != NmtState::Operational {
            return;
        }
        if let Some(data) = self.pending_rpdo.take() {
            self.apply_rpdo(&data, motor);
        }
        self.refresh_live(motor);
        for p in 0..4u16 {
            let comm = 0x1800 + p;
            let cob = self.get_raw(comm, 1);
            let kind = self.get_raw(comm, 2);
            if cob & COB_ID_INVALID != 0 || !(1..=240).contains(&kind) {
                continue;
            }
            // A mapping longer than a frame sends nothing (the mapping check keeps it within).
            let mut data = heapless::Vec::<u8, 8>::new();
            let mut fits = true;
            for s in 1..=self.get_raw(0x1A00 + p, 0) as u8 {
                let m = MappingEntry::from_raw(self.get_raw(0x1A00 + p, s));
                let v = self.get_raw(m.object.index, m.object.sub).to_le_bytes();
                for b in v.iter().take(m.bits as usize / 8) {
                    fits &= data.push(*b).is_ok();
                }
            }
            let id = StandardId::new((cob & 0x7FF) as u16);
            if fits {
                self.send(id.and_then(|id| Frame::new(id, &data)));
            }
        }
    }

    fn on_rpdo<M: Motor + ?Sized>(&mut self, frame: &Frame, motor: &mut M) {
        for p in 0..4u16 {
            let cob = self.get_raw(0x1400 + p, 1);
            if cob & COB_ID_INVALID != 0 || (cob & 0x7FF) as u16 != frame.id().raw() {
                continue;
            }
            let kind = self.get_raw(0x1400 + p, 2);
            let want: usize = (1..=self.get_raw(0x1600 + p, 0) as u8)
                .map(|s| MappingEntry::from_raw(self.get_raw(0x1600 + p, s)).bits as usize / 8)
                .sum();
            if frame.data().len() < want {
                self.pdo_length_errors += 1;
                return;
            }
            if (0..=240).contains(&kind) {
                self.pending_rpdo = heapless::Vec::from_slice(frame.data()).ok();
            } else {
                self.apply_rpdo(frame.data(), motor);
            }
            return;
        }
    }

    /// RPDO1's mapping applied (the only RPDO this ECU configures).
    fn apply_rpdo<M: Motor + ?Sized>(&mut self, data: &[u8], motor: &mut M) {
        let mut at = 0;
        for s in 1..=self.get_raw(0x1600, 0) as u8 {
            let m = MappingEntry::from_raw(self.get_raw(0x1600, s));
            let n = m.bits as usize / 8;
            let Some(bytes) = data.get(at..at + n) else {
                return;
            };
            at += n;
            let mut raw = [0u8; 4];
            for (r, b) in raw.iter_mut().zip(bytes) {
                *r = *b;
            }
            let value = u32::from_le_bytes(raw);
            self.set_raw(m.object.index, m.object.sub, value);
            if m.object == od::TARGET_POSITION && self.state == State::OperationEnabled {
                self.push_target(value as i32, motor);
            } else if m.object == od::CONTROLWORD {
                self.on_controlword(value as u16, motor);
            }
        }
    }

    fn current_tick<M: Motor + ?Sized>(&mut self, motor: &mut M) {
        if self.state == State::QuickStopActive && self.now_us >= self.quick_stop_until_us {
            self.enter(State::SwitchOnDisabled, motor);
        }
        let running = self.state == State::OperationEnabled && self.csp();
        motor.tick(running);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canopen::cia402::Command;
    use crate::canopen::sdo::{SdoRequest, SdoWrite};
    use std::vec::Vec;

    fn node() -> NodeId {
        NodeId::new(1).unwrap()
    }

    /// A motor that stands at 0 inc with no current.
    struct Still;

    impl Motor for Still {
        fn tick(&mut self, _running: bool) {}
        fn enable(&mut self, _gains: &EposGains) {}
        fn target(&mut self, _inc: i32) {}
        fn position_inc(&self) -> i32 {
            0
        }
        fn current_averaged_ma(&self) -> i32 {
            0
        }
        fn current_actual_ma(&self) -> i32 {
            0
        }
    }

    /// The model and its motor, called as host-sim calls its drive.
    struct Bench {
        model: Epos4Model,
        motor: Still,
    }

    impl Bench {
        fn new() -> Bench {
            Bench {
                model: Epos4Model::new(node()),
                motor: Still,
            }
        }

        fn advance(&mut self, now_us: u64) -> Vec<Frame> {
            let mut out = Vec::new();
            self.model.advance(now_us, &mut self.motor, |f| out.push(f));
            out
        }

        fn on_frame(&mut self, f: &Frame) -> Vec<Frame> {
            self.model.on_frame(f, &mut self.motor).to_vec()
        }

        fn cia402_state(&self) -> State {
            self.model.cia402_state()
        }

        fn refusals(&self) -> &[Refusal] {
            self.model.refusals()
        }
    }

    fn write_cw(sim: &mut Bench, cw: u16) -> Vec<Frame> {
        let req = SdoRequest::Download(SdoWrite {
            object: od::CONTROLWORD,
            value: cw as u32,
            width: Width::U16,
        });
        let f = sdo::request_frame(node(), &req).unwrap();
        sim.on_frame(&f)
    }

    #[test]
    fn enable_operation_from_switch_on_disabled_is_refused() {
        let mut sim = Bench::new();
        sim.advance(100);
        assert_eq!(sim.cia402_state(), State::SwitchOnDisabled);
        write_cw(&mut sim, Command::EnableOperation.controlword());
        assert_eq!(sim.cia402_state(), State::SwitchOnDisabled);
        assert_eq!(
            sim.refusals(),
            &[Refusal {
                state: State::SwitchOnDisabled,
                controlword: 0x000F
            }]
        );
        // The legal walk works.
        for cw in [0x06, 0x07, 0x0F] {
            write_cw(&mut sim, cw);
        }
        assert_eq!(sim.cia402_state(), State::OperationEnabled);
    }

    #[test]
    fn read_only_objects_refuse_writes_with_the_cia301_code() {
        let mut sim = Bench::new();
        sim.advance(100);
        let req = SdoRequest::Download(SdoWrite {
            object: od::STATUSWORD,
            value: 0,
            width: Width::U16,
        });
        let out = sim.on_frame(&sdo::request_frame(node(), &req).unwrap());
        assert_eq!(
            sdo::parse_response(&out[0], node()),
            Some(sdo::SdoResponse::Aborted {
                object: od::STATUSWORD,
                code: AbortCode::READ_ONLY
            })
        );
        let req = SdoRequest::Upload(ObjectAddress::new(0x30A1, 0x30));
        let out = sim.on_frame(&sdo::request_frame(node(), &req).unwrap());
        assert!(matches!(
            sdo::parse_response(&out[0], node()),
            Some(sdo::SdoResponse::Aborted {
                code: AbortCode::NO_SUB_INDEX,
                ..
            })
        ));
    }

    #[test]
    fn pdos_flow_only_in_operational() {
        let mut sim = Bench::new();
        sim.advance(100);
        let sync = nmt::sync_frame().unwrap();
        // Default TPDO1 is event-driven (type 255) and the node is pre-operational: nothing.
        assert!(sim.on_frame(&sync).is_empty());
        let start = nmt::command_frame(NmtCommand::Start, nmt::NmtTarget::Node(node())).unwrap();
        sim.on_frame(&start);
        assert!(
            sim.on_frame(&sync).is_empty(),
            "type 255 is not synchronous"
        );
    }

    /// The bounded buffers: every default object fits the dictionary, and refusals past the
    /// kept ones are dropped, not a panic.
    #[test]
    fn the_dictionary_holds_every_default_and_refusals_are_bounded() {
        let mut sim = Bench::new();
        assert!(sim.model.od.len() < OD_CAPACITY, "{}", sim.model.od.len());
        assert_eq!(sim.model.object(ObjectAddress::new(0x60C2, 2)), Some(0xFD));
        assert_eq!(sim.model.object(ObjectAddress::new(0x1A03, 12)), Some(0));
        assert_eq!(sim.advance(100).len(), 1, "the boot-up");
        for _ in 0..2 * REFUSALS_KEPT {
            write_cw(&mut sim, Command::EnableOperation.controlword());
        }
        assert_eq!(sim.refusals().len(), REFUSALS_KEPT);
        assert_eq!(sim.cia402_state(), State::SwitchOnDisabled);
    }
}

//! What one frame on the car's bus is, per the DBC (reference 0x100, status 0x101, motor 0x102,
//! diagnostics 0x103) and CANopen's predefined connection set for the EPOS4 node (TPDO1/2, RPDO1, SDO, EMCY,
//! heartbeat) plus NMT and SYNC; and the fault bits and state codes in words.

use steering_ecu::as_state::AsState;
use steering_ecu::can::Frame;
use steering_ecu::canopen::epos4::{EcuHeartbeat, PositionScale, amps_from_ma};
use steering_ecu::canopen::nmt::{self, NmtState};
use steering_ecu::canopen::{NodeId, emcy, function, node_of};
use steering_ecu::ecu::link_fault_name;
use steering_ecu::faults::{EncoderFaultDetail, Fault, FaultSet};
use steering_ecu::protocol::{
    DIAGNOSTIC_ID, Diagnostic, FrameError, MOTOR_ID, MotorStatus, ProtocolConfig, REFERENCE_ID,
    Reference, STATUS_ID, Status,
};
use steering_ecu::steering::{EcuState, ORIGIN_RESTING_DETAIL};

/// One frame, decoded.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Decoded {
    Reference(Result<Reference, FrameError>),
    Status(Result<Status, FrameError>),
    Motor(Result<MotorStatus, FrameError>),
    /// One page of the ECU's diagnostic frame.
    Diagnostic(Result<Diagnostic, FrameError>),
    /// EPOS4 TPDO1 (0x6041 statusword, 0x6064 position actual), position in rad at the motor.
    EposTpdo1 {
        statusword: u16,
        motor_rad: f64,
    },
    /// EPOS4 TPDO2 (0x30D1 current actual), A.
    EposTpdo2 {
        current_a: f64,
    },
    /// RPDO1 to the EPOS4 (0x607A target position), rad at the motor.
    EposRpdo1 {
        target_rad: f64,
    },
    /// A PDO of the node with an unexpected length.
    EposPdoLength {
        cob: u16,
        len: usize,
    },
    Emcy {
        error_code: u16,
        error_register: u8,
    },
    Heartbeat(NmtState),
    /// The ECU's own heartbeat (node [`EcuHeartbeat::DEFAULT`], 127), which the EPOS4 watches.
    EcuHeartbeat(NmtState),
    SdoRequest,
    SdoResponse,
    Nmt,
    Sync,
    Unknown,
}

impl Decoded {
    /// A short name for counters, stable for scripts.
    pub fn kind(&self) -> &'static str {
        match self {
            Decoded::Reference(_) => "reference 0x100",
            Decoded::Status(_) => "status 0x101",
            Decoded::Motor(_) => "motor 0x102",
            Decoded::Diagnostic(_) => "diagnostics 0x103",
            Decoded::EposTpdo1 { .. } => "EPOS4 TPDO1",
            Decoded::EposTpdo2 { .. } => "EPOS4 TPDO2",
            Decoded::EposRpdo1 { .. } => "EPOS4 RPDO1",
            Decoded::EposPdoLength { .. } => "EPOS4 PDO (bad length)",
            Decoded::Emcy { .. } => "EPOS4 EMCY",
            Decoded::Heartbeat(_) => "EPOS4 heartbeat",
            Decoded::EcuHeartbeat(_) => "ECU heartbeat",
            Decoded::SdoRequest => "SDO request",
            Decoded::SdoResponse => "SDO response",
            Decoded::Nmt => "NMT",
            Decoded::Sync => "SYNC",
            Decoded::Unknown => "other",
        }
    }
}

/// Decodes frames of one bus: the ECU's protocol and one EPOS4 node.
#[derive(Debug, Clone, Copy)]
pub struct Decoder {
    pub protocol: ProtocolConfig,
    pub node: NodeId,
    pub scale: PositionScale,
}

impl Decoder {
    pub fn new(node: NodeId, scale: PositionScale) -> Self {
        Decoder {
            protocol: ProtocolConfig::DEFAULT,
            node,
            scale,
        }
    }

    pub fn decode(&self, frame: &Frame) -> Decoded {
        let id = frame.id();
        let data = frame.data();
        if id == REFERENCE_ID {
            return Decoded::Reference(self.protocol.decode_reference(frame));
        }
        if id == STATUS_ID {
            return Decoded::Status(self.protocol.decode_status(frame));
        }
        if id == MOTOR_ID {
            return Decoded::Motor(self.protocol.decode_motor(frame));
        }
        if id == DIAGNOSTIC_ID {
            return Decoded::Diagnostic(self.protocol.decode_diagnostic(frame));
        }
        if nmt::is_sync(frame) {
            return Decoded::Sync;
        }
        if nmt::parse_command(frame).is_some() {
            return Decoded::Nmt;
        }
        let ours = |base: u16| node_of(id, base) == Some(self.node);
        if ours(function::TPDO1) {
            if data.len() != 6 {
                return Decoded::EposPdoLength {
                    cob: id.raw(),
                    len: data.len(),
                };
            }
            let statusword = u16::from_le_bytes([data[0], data[1]]);
            let inc = i32::from_le_bytes([data[2], data[3], data[4], data[5]]);
            return Decoded::EposTpdo1 {
                statusword,
                motor_rad: f64::from(self.scale.motor_from_inc(inc).0),
            };
        }
        if ours(function::TPDO2) {
            if data.len() != 4 {
                return Decoded::EposPdoLength {
                    cob: id.raw(),
                    len: data.len(),
                };
            }
            let ma = i32::from_le_bytes([data[0], data[1], data[2], data[3]]);
            return Decoded::EposTpdo2 {
                current_a: f64::from(amps_from_ma(ma).0),
            };
        }
        if ours(function::RPDO1) {
            if data.len() != 4 {
                return Decoded::EposPdoLength {
                    cob: id.raw(),
                    len: data.len(),
                };
            }
            let inc = i32::from_le_bytes([data[0], data[1], data[2], data[3]]);
            return Decoded::EposRpdo1 {
                target_rad: f64::from(self.scale.motor_from_inc(inc).0),
            };
        }
        if let Some(e) = emcy::parse(frame, self.node) {
            return Decoded::Emcy {
                error_code: e.error_code,
                error_register: e.error_register,
            };
        }
        if let Some(state) = nmt::parse_heartbeat(frame, self.node) {
            return Decoded::Heartbeat(state);
        }
        if let Some(state) = nmt::parse_heartbeat(frame, EcuHeartbeat::DEFAULT.node) {
            return Decoded::EcuHeartbeat(state);
        }
        if ours(function::SDO_RX) {
            return Decoded::SdoRequest;
        }
        if ours(function::SDO_TX) {
            return Decoded::SdoResponse;
        }
        Decoded::Unknown
    }
}

/// A fault in words, as on the status frame's fault bits.
pub fn fault_words(fault: Fault) -> &'static str {
    match fault {
        Fault::ReferenceTimeout => "reference timeout",
        Fault::InvalidFrames => "invalid reference frames",
        Fault::Encoder => "column encoder",
        Fault::EncoderJump => "column encoder jump",
        Fault::EncoderMotorDisagreement => "encoder/motor disagreement",
        Fault::OverCurrent => "over-current",
        Fault::EposFault => "EPOS4 fault",
        Fault::HeartbeatLost => "EPOS4 heartbeat lost",
        Fault::BusOff => "CAN bus-off",
        Fault::TrackingError => "tracking error",
        Fault::Origin => "motor origin",
    }
}

/// A fault record's detail in words, per the units each [`Fault`] documents for it.
pub fn fault_detail_words(fault: Fault, detail: i32) -> String {
    let centideg = |d: i32| f64::from(d) / 100.0;
    match fault {
        Fault::ReferenceTimeout => format!("no valid reference for {detail} ms"),
        Fault::InvalidFrames => format!("invalid-frame score {detail}"),
        Fault::Encoder => encoder_detail_words(detail),
        Fault::EncoderJump => format!("jumped {:+.2} deg", centideg(detail)),
        Fault::EncoderMotorDisagreement => {
            format!("encoder and motor {:+.2} deg apart", centideg(detail))
        }
        Fault::OverCurrent if detail == i32::MIN => "current not a number".into(),
        Fault::OverCurrent => format!("{:+.3} A", f64::from(detail) / 1000.0),
        Fault::EposFault => epos_code_words(detail),
        Fault::HeartbeatLost => "no heartbeat within the consumer time".into(),
        Fault::BusOff => format!("transmit error counter {detail}"),
        Fault::TrackingError => format!("{:+.2} deg from the reference", centideg(detail)),
        Fault::Origin if detail >= ORIGIN_RESTING_DETAIL => format!(
            "column and motor {:+.2} deg apart at rest",
            centideg(detail - ORIGIN_RESTING_DETAIL)
        ),
        Fault::Origin if detail <= -ORIGIN_RESTING_DETAIL => format!(
            "column and motor {:+.2} deg apart at rest",
            centideg(detail + ORIGIN_RESTING_DETAIL)
        ),
        Fault::Origin => format!(
            "column samples at the enable {:.2} deg apart",
            centideg(detail)
        ),
    }
}

fn encoder_detail_words(detail: i32) -> String {
    const SENSOR: i32 = EncoderFaultDetail::SensorReported as i32;
    match detail {
        d if d == EncoderFaultDetail::ColumnNotFinite as i32 => {
            "column reading not a number".into()
        }
        d if d == EncoderFaultDetail::MotorNotFinite as i32 => "motor angle not a number".into(),
        d if d == EncoderFaultDetail::Stale as i32 => "no sample within the timeout".into(),
        // The codes the firmware's encoder task reports (`tasks::encoder_task`).
        d if d == SENSOR + 1 => "sensor did not answer".into(),
        d if d == SENSOR + 2 => "sensor gave an invalid reading".into(),
        d if d > SENSOR => format!("sensor error {}", d - SENSOR),
        d => format!("unknown encoder detail {d}"),
    }
}

/// An EPOS4 fault's code: the link's own failures by name, else the drive's EMCY error code
/// or statusword as the drive gave it.
fn epos_code_words(detail: i32) -> String {
    match u16::try_from(detail).ok().and_then(link_fault_name) {
        Some(name) => format!("link: {name}"),
        None => format!("drive error code/statusword 0x{detail:04X}"),
    }
}

/// The fault bits in words, "none" for zero; unknown bits are named by number.
pub fn faults_in_words(bits: u16) -> String {
    if bits == 0 {
        return "none".into();
    }
    let set = FaultSet::from_bits(bits);
    let mut words: Vec<String> = set.iter().map(|f| fault_words(f).to_string()).collect();
    let known = set.iter().fold(0u16, |acc, f| acc | (1 << f.bit()));
    for bit in 0..16 {
        if bits & !known & (1 << bit) != 0 {
            words.push(format!("unknown bit {bit}"));
        }
    }
    words.join(", ")
}

/// The status frame's ECU state in words.
pub fn ecu_state_words(code: u8) -> String {
    match EcuState::from_code(code) {
        Some(EcuState::Idle) => "idle".into(),
        Some(EcuState::Standby) => "standby".into(),
        Some(EcuState::Tracking) => "tracking".into(),
        Some(EcuState::Holding) => "holding".into(),
        Some(EcuState::Emergency) => "emergency".into(),
        Some(EcuState::Faulted) => "faulted".into(),
        Some(EcuState::Arming) => "arming (drive being enabled)".into(),
        None => format!("unknown state {code}"),
    }
}

/// The AS state in words.
pub fn as_state_words(s: AsState) -> &'static str {
    match s {
        AsState::Off => "Off",
        AsState::Ready => "Ready",
        AsState::Driving => "Driving",
        AsState::Emergency => "Emergency",
        AsState::Finished => "Finished",
        AsState::Manual => "Manual",
    }
}

/// A CANopen NMT state in words.
pub fn nmt_words(s: NmtState) -> &'static str {
    match s {
        NmtState::BootUp => "boot-up",
        NmtState::Stopped => "stopped",
        NmtState::Operational => "operational",
        NmtState::PreOperational => "pre-operational",
    }
}

/// Why a frame failed its checks, in words.
pub fn frame_error_words(e: &FrameError) -> String {
    match e {
        FrameError::WrongId { id } => format!("wrong ID 0x{:03X}", id.raw()),
        FrameError::WrongLength { len } => format!("length {len}, expected 8"),
        FrameError::Crc { expected, found } => {
            format!("CRC error (byte 0 is 0x{found:02X}, CRC is 0x{expected:02X})")
        }
        FrameError::UnknownAsState { code } => format!("unknown AS state {code}"),
        other => format!("{other:?}"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ecus_own_heartbeat_is_named_not_other() {
        // The EPOS4 link produces the ECU's heartbeat on node 127 for the drive to watch; the
        // monitor listed it as "other" until it was decoded.
        let decoder = Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(84).unwrap());
        let ecu = nmt::heartbeat_frame(EcuHeartbeat::DEFAULT.node, NmtState::Operational).unwrap();
        let decoded = decoder.decode(&ecu);
        assert_eq!(decoded, Decoded::EcuHeartbeat(NmtState::Operational));
        assert_eq!(decoded.kind(), "ECU heartbeat");
        let drive = nmt::heartbeat_frame(decoder.node, NmtState::Operational).unwrap();
        assert_eq!(decoder.decode(&drive).kind(), "EPOS4 heartbeat");
    }
}

//! `epos check`: what the EPOS4 says about itself, by SDO reads only (nothing is written):
//! NMT state (heartbeat), CiA 402 state, mode of operation, the gains in 0x30A0/0x30A1 against
//! ours (Table 3 as `gain_words` writes them), the drive's limits against ours (current,
//! following error window, max velocity, and the software position limits' span around the
//! origin the ECU wrote them at), the error register, the error code and the error history.

use super::decode::nmt_words;
use super::{BringupError, Transport, pump};
use steering_ecu::canopen::cia402::State;
use steering_ecu::canopen::epos4::{DriveLimits, Epos4Config, gain_words, od};
use steering_ecu::canopen::nmt::{self, NmtState};
use steering_ecu::canopen::sdo::{SdoClient, SdoOutcome, SdoRequest};
use steering_ecu::canopen::{NodeId, ObjectAddress};
use steering_ecu::gains::EposGains;

/// How long one SDO read may take, µs, and how often it is tried.
const SDO_TIMEOUT_US: u64 = 100_000;
const SDO_ATTEMPTS: u32 = 3;
/// How long to listen for a heartbeat, µs (the firmware asks for 20 ms; 0x1017 may be off).
const HEARTBEAT_LISTEN_US: u64 = 300_000;

const ERROR_REGISTER: ObjectAddress = ObjectAddress::new(0x1001, 0);
const ERROR_HISTORY_COUNT: ObjectAddress = ObjectAddress::new(0x1003, 0);
const ERROR_CODE: ObjectAddress = ObjectAddress::new(0x603F, 0);

/// One gain, read back and compared.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct GainCheck {
    pub object: ObjectAddress,
    pub name: &'static str,
    pub ours: u32,
    pub drive: u32,
}

/// The software position limits (0x607D) as the drive holds them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PositionLimitsCheck {
    /// Ours: inc either side of the origin ([`DriveLimits::position_limit_inc`]).
    pub ours_span: u32,
    pub drive_min: i32,
    pub drive_max: i32,
}

impl PositionLimitsCheck {
    /// The drive still has the widest range: no enable has written them since it powered up.
    pub fn unwritten(&self) -> bool {
        self.drive_min == i32::MIN && self.drive_max == i32::MAX
    }

    /// Half the drive's range, as ours is given (the origin is the ECU's, from the column).
    pub fn drive_span(&self) -> i64 {
        (i64::from(self.drive_max) - i64::from(self.drive_min)) / 2
    }

    pub fn matches(&self) -> bool {
        !self.unwritten() && self.drive_span() == i64::from(self.ours_span)
    }
}

/// Everything `epos check` found.
#[derive(Debug, Clone, PartialEq)]
pub struct EposReport {
    pub node: NodeId,
    /// From the heartbeat; `None` if no heartbeat came while listening.
    pub nmt: Option<NmtState>,
    pub heartbeat_ms: u32,
    pub statusword: u16,
    pub mode: i8,
    pub gains: Vec<GainCheck>,
    /// Current limit, following error window, max velocity: ours beside the drive's.
    pub limits: Vec<GainCheck>,
    pub position_limits: PositionLimitsCheck,
    pub error_register: u8,
    pub error_code: u16,
    /// Newest first.
    pub error_history: Vec<u32>,
}

impl EposReport {
    pub fn gain_mismatches(&self) -> usize {
        self.gains.iter().filter(|g| g.ours != g.drive).count()
    }

    pub fn limit_mismatches(&self) -> usize {
        self.limits.iter().filter(|g| g.ours != g.drive).count()
    }

    /// Fine for a campaign on the EPOS4: no error, gains and limits as ours, CSP. The software
    /// position limits are written at each enable, so a drive not enabled since power-up is
    /// not refused for lacking them (the text says so); written ones must have our span.
    pub fn is_ok(&self) -> bool {
        self.gain_mismatches() == 0
            && self.limit_mismatches() == 0
            && (self.position_limits.unwritten() || self.position_limits.matches())
            && self.error_register == 0
            && self.error_code == 0
    }

    pub fn text(&self) -> String {
        let mut out = format!("EPOS4 node {}\n", self.node.raw());
        out.push_str(&match self.nmt {
            Some(s) => format!("  NMT state        {} (heartbeat)\n", nmt_words(s)),
            None => format!(
                "  NMT state        no heartbeat in {} ms (0x1017 = {} ms); SDO answers, so \
                 pre-operational or operational\n",
                HEARTBEAT_LISTEN_US / 1000,
                self.heartbeat_ms
            ),
        });
        let state = State::from_statusword(self.statusword)
            .map(|s| format!("{s:?}"))
            .unwrap_or_else(|| "unknown".into());
        out.push_str(&format!(
            "  CiA 402 state    {state} (statusword 0x{:04X})\n",
            self.statusword
        ));
        out.push_str(&format!(
            "  mode             {} ({})\n",
            self.mode,
            mode_words(self.mode)
        ));
        for (title, rows) in [("gains ", &self.gains), ("limits", &self.limits)] {
            out.push_str(&format!(
                "  {title}           object    ours        drive\n"
            ));
            for g in rows {
                out.push_str(&format!(
                    "    {:<26} {}  {:>10}  {:>10}  {}\n",
                    g.name,
                    g.object,
                    g.ours,
                    g.drive,
                    if g.ours == g.drive { "ok" } else { "DIFFERS" }
                ));
            }
        }
        let p = &self.position_limits;
        out.push_str(&format!(
            "    {:<26} 0x607D    +-{:>8}  {}\n",
            "software position, inc",
            p.ours_span,
            if p.unwritten() {
                "not written (the ECU writes them at each enable)".to_string()
            } else {
                format!(
                    "{}..{} = +-{} around {}  {}",
                    p.drive_min,
                    p.drive_max,
                    p.drive_span(),
                    (i64::from(p.drive_min) + i64::from(p.drive_max)) / 2,
                    if p.matches() { "ok" } else { "DIFFERS" }
                )
            }
        ));
        out.push_str(&format!(
            "  error register   0x{:02X}{}\n",
            self.error_register,
            if self.error_register == 0 {
                " (no error)"
            } else {
                ""
            }
        ));
        out.push_str(&format!("  error code       0x{:04X}\n", self.error_code));
        if self.error_history.is_empty() {
            out.push_str("  error history    empty\n");
        } else {
            for (i, e) in self.error_history.iter().enumerate() {
                out.push_str(&format!(
                    "  error history {}  0x{:04X} (vendor 0x{:04X})\n",
                    i + 1,
                    e & 0xFFFF,
                    e >> 16
                ));
            }
        }
        out.push_str(&format!(
            "  verdict          {}\n",
            if self.is_ok() {
                "ok".to_string()
            } else {
                format!(
                    "{} gain(s) and {} limit(s) differ from ours, error register 0x{:02X}",
                    self.gain_mismatches(),
                    self.limit_mismatches() + usize::from(!p.unwritten() && !p.matches()),
                    self.error_register
                )
            }
        ));
        out
    }
}

/// CiA 402 modes of operation in words.
pub fn mode_words(mode: i8) -> &'static str {
    match mode {
        1 => "profile position",
        3 => "profile velocity",
        6 => "homing",
        8 => "cyclic synchronous position (what the ECU uses)",
        9 => "cyclic synchronous velocity",
        10 => "cyclic synchronous torque",
        0 => "none",
        _ => "other",
    }
}

/// One SDO upload, retried; the error names the object.
pub fn read(
    transport: &mut dyn Transport,
    node: NodeId,
    object: ObjectAddress,
) -> Result<u32, BringupError> {
    let mut client = SdoClient::new(node, SDO_TIMEOUT_US);
    for _ in 0..SDO_ATTEMPTS {
        let now = transport.now_us();
        let frame = client
            .start(SdoRequest::Upload(object), now)
            .ok()
            .flatten()
            .ok_or_else(|| BringupError::Epos {
                reason: format!("cannot build an SDO request for {object}"),
            })?;
        transport.send(&frame)?;
        let mut outcome = None;
        pump(transport, now + SDO_TIMEOUT_US, |rx| {
            outcome = client.on_frame(&rx.frame);
            outcome.is_none()
        })?;
        client.cancel();
        match outcome {
            Some(SdoOutcome::Read { value, .. }) => return Ok(value),
            Some(SdoOutcome::Aborted { code, .. }) => {
                return Err(BringupError::Epos {
                    reason: format!(
                        "read of {object} aborted: 0x{:08X} ({})",
                        code.0,
                        code.name()
                    ),
                });
            }
            Some(other) => {
                return Err(BringupError::Epos {
                    reason: format!("read of {object}: unexpected answer {other:?}"),
                });
            }
            None => continue,
        }
    }
    Err(BringupError::Epos {
        reason: format!(
            "node {} does not answer SDO reads of {object} (0x{:03X} -> 0x{:03X}) within {} ms, \
             {SDO_ATTEMPTS} tries — is it powered, is --node right, is the bit rate 1 Mbit/s?",
            node.raw(),
            0x600 + u16::from(node.raw()),
            0x580 + u16::from(node.raw()),
            SDO_TIMEOUT_US / 1000
        ),
    })
}

/// The whole check.
pub fn check(transport: &mut dyn Transport, node: NodeId) -> Result<EposReport, BringupError> {
    let mut nmt_state = None;
    let start = transport.now_us();
    pump(transport, start + HEARTBEAT_LISTEN_US, |rx| {
        // A boot-up message is a heartbeat too; keep listening for a state after it.
        if let Some(s) = nmt::parse_heartbeat(&rx.frame, node) {
            nmt_state = Some(s);
        }
        !matches!(nmt_state, Some(s) if s != NmtState::BootUp)
    })?;
    let heartbeat_ms = read(transport, node, od::PRODUCER_HEARTBEAT)?;
    let statusword = read(transport, node, od::STATUSWORD)? as u16;
    let mode = read(transport, node, od::MODES_OF_OPERATION_DISPLAY)? as u8 as i8;
    let ours = gain_words(&EposGains::PAPER).map_err(|e| BringupError::Epos {
        reason: format!("our gains cannot be written as EPOS4 words: {e:?}"),
    })?;
    let mut gains = Vec::with_capacity(ours.len());
    for (object, word) in ours {
        gains.push(GainCheck {
            object,
            name: gain_name(object),
            ours: word,
            drive: read(transport, node, object)?,
        });
    }
    let ours: DriveLimits = Epos4Config::paper(node).limits;
    let mut limits = Vec::with_capacity(3);
    for (object, name, word) in [
        (
            od::OUTPUT_CURRENT_LIMIT,
            "current limit, mA",
            ours.current_ma,
        ),
        (
            od::FOLLOWING_ERROR_WINDOW,
            "following error window, inc",
            ours.following_error_inc,
        ),
        (
            od::MAX_PROFILE_VELOCITY,
            "max profile velocity, rpm",
            ours.max_velocity_rpm,
        ),
    ] {
        limits.push(GainCheck {
            object,
            name,
            ours: word,
            drive: read(transport, node, object)?,
        });
    }
    let position_limits = PositionLimitsCheck {
        ours_span: ours.position_limit_inc,
        drive_min: read(transport, node, od::MIN_POSITION_LIMIT)? as i32,
        drive_max: read(transport, node, od::MAX_POSITION_LIMIT)? as i32,
    };
    let error_register = read(transport, node, ERROR_REGISTER)? as u8;
    let error_code = read(transport, node, ERROR_CODE)? as u16;
    let n = read(transport, node, ERROR_HISTORY_COUNT)?.min(8) as u8;
    let mut error_history = Vec::with_capacity(n as usize);
    for sub in 1..=n {
        error_history.push(read(transport, node, ObjectAddress::new(0x1003, sub))?);
    }
    Ok(EposReport {
        node,
        nmt: nmt_state,
        heartbeat_ms,
        statusword,
        mode,
        gains,
        limits,
        position_limits,
        error_register,
        error_code,
        error_history,
    })
}

fn gain_name(object: ObjectAddress) -> &'static str {
    match object {
        od::CURRENT_P => "current P, uV/A",
        od::CURRENT_I => "current I, uV/(A ms)",
        od::POSITION_P => "position P, uA/rad",
        od::POSITION_I => "position I, uA/(rad s)",
        od::POSITION_D => "position D, uA s/rad",
        od::POSITION_FF_VELOCITY => "velocity FF, uA s/rad",
        od::POSITION_FF_ACCELERATION => "acceleration FF, uA s2/rad",
        _ => "gain",
    }
}

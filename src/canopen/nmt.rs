//! Network management (CiA 301 7.2.8): NMT node control (COB-ID 0x000), the SYNC producer
//! (0x080) and the heartbeat consumer (0x700 + node).

use super::{NMT_ID, NodeId, SYNC_ID, cob_id, frame, function, node_of};
use crate::can::Frame;

/// NMT node-control command specifiers (CiA 301 7.2.8.3.1).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NmtCommand {
    Start = 0x01,
    Stop = 0x02,
    EnterPreOperational = 0x80,
    ResetNode = 0x81,
    ResetCommunication = 0x82,
}

impl NmtCommand {
    pub fn from_u8(cs: u8) -> Option<Self> {
        match cs {
            0x01 => Some(NmtCommand::Start),
            0x02 => Some(NmtCommand::Stop),
            0x80 => Some(NmtCommand::EnterPreOperational),
            0x81 => Some(NmtCommand::ResetNode),
            0x82 => Some(NmtCommand::ResetCommunication),
            _ => None,
        }
    }
}

/// Which nodes an NMT command addresses.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NmtTarget {
    All,
    Node(NodeId),
}

impl NmtTarget {
    pub fn includes(self, node: NodeId) -> bool {
        match self {
            NmtTarget::All => true,
            NmtTarget::Node(n) => n == node,
        }
    }
}

/// The NMT command frame: 0x000, [command, node-ID or 0].
pub fn command_frame(command: NmtCommand, target: NmtTarget) -> Option<Frame> {
    let node = match target {
        NmtTarget::All => 0,
        NmtTarget::Node(n) => n.raw(),
    };
    frame(NMT_ID, &[command as u8, node])
}

/// An NMT command frame, if `frame` is one (id 0x000, exactly 2 bytes, known command, node-ID
/// 0 or 1..=127).
pub fn parse_command(frame: &Frame) -> Option<(NmtCommand, NmtTarget)> {
    if frame.id() != NMT_ID {
        return None;
    }
    let [cs, node] = *frame.data() else {
        return None;
    };
    let command = NmtCommand::from_u8(cs)?;
    let target = match node {
        0 => NmtTarget::All,
        n => NmtTarget::Node(NodeId::new(n)?),
    };
    Some((command, target))
}

/// The SYNC frame without counter (0x080, no data): the EPOS4's 0x1005 is const 0x00000080.
pub fn sync_frame() -> Option<Frame> {
    frame(SYNC_ID, &[])
}

/// True for a SYNC frame (0x080, 0 bytes, or 1 byte with the optional counter).
pub fn is_sync(frame: &Frame) -> bool {
    frame.id() == SYNC_ID && frame.data().len() <= 1
}

/// NMT states as a heartbeat reports them (CiA 301 7.2.8.3.2.1, toggle bit masked off).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum NmtState {
    BootUp = 0x00,
    Stopped = 0x04,
    Operational = 0x05,
    PreOperational = 0x7F,
}

impl NmtState {
    pub fn from_u8(raw: u8) -> Option<Self> {
        match raw & 0x7F {
            0x00 => Some(NmtState::BootUp),
            0x04 => Some(NmtState::Stopped),
            0x05 => Some(NmtState::Operational),
            0x7F => Some(NmtState::PreOperational),
            _ => None,
        }
    }
}

/// A heartbeat (or boot-up) frame of `node`: 0x700 + node, 1 byte.
pub fn heartbeat_frame(node: NodeId, state: NmtState) -> Option<Frame> {
    frame(cob_id(function::HEARTBEAT, node), &[state as u8])
}

/// The state in a heartbeat from `node`; `None` for any other frame or a malformed one.
pub fn parse_heartbeat(frame: &Frame, node: NodeId) -> Option<NmtState> {
    if node_of(frame.id(), function::HEARTBEAT) != Some(node) {
        return None;
    }
    match *frame.data() {
        [state] => NmtState::from_u8(state),
        _ => None,
    }
}

/// Heartbeat consumer: the producer is lost when nothing arrived for `timeout_us`.
///
/// The clock is whatever `now_us` the caller passes (monotonic µs); a clock that steps back is
/// treated as "no time passed", never as an underflow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HeartbeatMonitor {
    timeout_us: u64,
    last_us: u64,
    last_state: Option<NmtState>,
}

impl HeartbeatMonitor {
    /// Armed at `now_us`: the first heartbeat is due within `timeout_us`.
    pub fn new(timeout_us: u64, now_us: u64) -> Self {
        HeartbeatMonitor {
            timeout_us,
            last_us: now_us,
            last_state: None,
        }
    }

    pub fn rearm(&mut self, now_us: u64) {
        self.last_us = now_us;
    }

    pub fn on_heartbeat(&mut self, state: NmtState, now_us: u64) {
        self.last_us = now_us;
        self.last_state = Some(state);
    }

    pub fn last_state(&self) -> Option<NmtState> {
        self.last_state
    }

    /// µs since the last heartbeat.
    pub fn silent_us(&self, now_us: u64) -> u64 {
        now_us.saturating_sub(self.last_us)
    }

    pub fn expired(&self, now_us: u64) -> bool {
        self.silent_us(now_us) > self.timeout_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::can::StandardId;

    fn node(n: u8) -> NodeId {
        NodeId::new(n).unwrap()
    }

    #[test]
    fn start_command_addresses_one_node() {
        let f = command_frame(NmtCommand::Start, NmtTarget::Node(node(1))).unwrap();
        assert_eq!(f.id().raw(), 0x000);
        assert_eq!(f.data(), &[0x01, 0x01]);
        assert_eq!(
            parse_command(&f),
            Some((NmtCommand::Start, NmtTarget::Node(node(1))))
        );
    }

    #[test]
    fn node_id_zero_and_above_127_are_unrepresentable() {
        assert!(NodeId::new(0).is_none());
        assert!(NodeId::new(128).is_none());
        assert!(NodeId::new(127).is_some());
    }

    #[test]
    fn heartbeat_masks_the_toggle_bit_and_checks_the_node() {
        let f = Frame::new(StandardId::new(0x701).unwrap(), &[0x85]).unwrap();
        assert_eq!(parse_heartbeat(&f, node(1)), Some(NmtState::Operational));
        assert_eq!(parse_heartbeat(&f, node(2)), None);
        let boot = Frame::new(StandardId::new(0x701).unwrap(), &[0x00]).unwrap();
        assert_eq!(parse_heartbeat(&boot, node(1)), Some(NmtState::BootUp));
        let long = Frame::new(StandardId::new(0x701).unwrap(), &[0x05, 0]).unwrap();
        assert_eq!(parse_heartbeat(&long, node(1)), None);
    }

    #[test]
    fn heartbeat_monitor_expires_after_the_timeout_and_survives_a_clock_step_back() {
        let mut m = HeartbeatMonitor::new(100, 1_000);
        assert!(!m.expired(1_100));
        assert!(m.expired(1_101));
        m.on_heartbeat(NmtState::Operational, 1_050);
        assert!(!m.expired(1_101));
        assert!(!m.expired(0));
    }

    #[test]
    fn sync_is_0x080_without_data() {
        let f = sync_frame().unwrap();
        assert_eq!(f.id().raw(), 0x080);
        assert!(f.data().is_empty());
        assert!(is_sync(&f));
    }
}

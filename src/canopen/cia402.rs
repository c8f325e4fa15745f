//! CiA 402 drive profile, master side: the controlword commands (0x6040), the statusword
//! (0x6041) decoded into the power state machine, and the next command toward a target state.
//!
//! Theory of operation (CiA 402-2 Figure 6; transition numbers in brackets):
//!
//! ```text
//!  Not ready to switch on --(1, automatic)--> Switch on disabled <------------------+
//!                                              |  ^ (7) disable voltage             |
//!                                  shutdown (2)v  |                                 |
//!                                         Ready to switch on                       (9,10,12)
//!                                              |  ^ (6) shutdown                    |
//!                                 switch on (3)v  |                                 |
//!                                           Switched on ----------------------------+
//!                                              |  ^ (5) disable operation
//!                          enable operation (4)v  |
//!                                       Operation enabled --(11) quick stop--> Quick stop active
//!  any --(13, error)--> Fault reaction active --(14, automatic)--> Fault
//!  Fault --(15, fault reset: rising edge of bit 7)--> Switch on disabled
//! ```
//!
//! [`next_command`] walks one transition at a time and never skips a state (the EPOS4 would
//! accept "switch on + enable operation" from Ready to switch on, but a strict walk makes each
//! step visible in the statusword and works with every CiA 402 drive).

/// Controlword commands (CiA 402-2 Table 31; bits 0-3 and 7).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Command {
    /// Transitions 2, 6, 8: 0b0xxx_x110.
    Shutdown,
    /// Transition 3: 0b0xxx_0111.
    SwitchOn,
    /// Transition 5: same bits as switch on, from Operation enabled.
    DisableOperation,
    /// Transition 4 (and 16): 0b0xxx_1111.
    EnableOperation,
    /// Transitions 7, 9, 10, 12: 0b0xxx_xx0x.
    DisableVoltage,
    /// Transitions 7, 10, 11: 0b0xxx_x01x.
    QuickStop,
    /// Transition 15 on the rising edge of bit 7; send [`Command::DisableVoltage`] (bit 7 low)
    /// first if the previous controlword had bit 7 set.
    FaultReset,
}

impl Command {
    pub const fn controlword(self) -> u16 {
        match self {
            Command::Shutdown => 0x0006,
            Command::SwitchOn | Command::DisableOperation => 0x0007,
            Command::EnableOperation => 0x000F,
            Command::DisableVoltage => 0x0000,
            Command::QuickStop => 0x0002,
            Command::FaultReset => 0x0080,
        }
    }
}

/// Statusword bits (CiA 402-2 Table 30).
pub mod status {
    pub const READY_TO_SWITCH_ON: u16 = 1 << 0;
    pub const SWITCHED_ON: u16 = 1 << 1;
    pub const OPERATION_ENABLED: u16 = 1 << 2;
    pub const FAULT: u16 = 1 << 3;
    pub const VOLTAGE_ENABLED: u16 = 1 << 4;
    pub const QUICK_STOP: u16 = 1 << 5;
    pub const SWITCH_ON_DISABLED: u16 = 1 << 6;
    pub const WARNING: u16 = 1 << 7;
    pub const REMOTE: u16 = 1 << 9;
    pub const TARGET_REACHED: u16 = 1 << 10;
    pub const INTERNAL_LIMIT: u16 = 1 << 11;
    /// In CSP: the drive follows the target (bit 12, "drive follows command value").
    pub const FOLLOWS_TARGET: u16 = 1 << 12;
    pub const FOLLOWING_ERROR: u16 = 1 << 13;
}

/// The power state machine's states.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum State {
    NotReadyToSwitchOn,
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
    QuickStopActive,
    FaultReactionActive,
    Fault,
}

impl State {
    /// Decode with the CiA 402-2 Table 30 masks; `None` for bit patterns no state has.
    pub fn from_statusword(sw: u16) -> Option<State> {
        match (sw & 0x004F, sw & 0x006F) {
            (0x0000, _) => Some(State::NotReadyToSwitchOn),
            (0x0040, _) => Some(State::SwitchOnDisabled),
            (_, 0x0021) => Some(State::ReadyToSwitchOn),
            (_, 0x0023) => Some(State::SwitchedOn),
            (_, 0x0027) => Some(State::OperationEnabled),
            (_, 0x0007) => Some(State::QuickStopActive),
            (0x000F, _) => Some(State::FaultReactionActive),
            (0x0008, _) => Some(State::Fault),
            _ => None,
        }
    }

    /// A statusword showing this state (the state bits only), for simulators and tests.
    pub const fn statusword_bits(self) -> u16 {
        match self {
            State::NotReadyToSwitchOn => 0x0000,
            State::SwitchOnDisabled => 0x0040,
            State::ReadyToSwitchOn => 0x0021,
            State::SwitchedOn => 0x0023,
            State::OperationEnabled => 0x0027,
            State::QuickStopActive => 0x0007,
            State::FaultReactionActive => 0x000F,
            State::Fault => 0x0008,
        }
    }
}

/// Where the master wants the drive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Target {
    SwitchOnDisabled,
    ReadyToSwitchOn,
    SwitchedOn,
    OperationEnabled,
}

fn rank(state: State) -> Option<u8> {
    match state {
        State::SwitchOnDisabled => Some(0),
        State::ReadyToSwitchOn => Some(1),
        State::SwitchedOn => Some(2),
        State::OperationEnabled => Some(3),
        _ => None,
    }
}

fn target_rank(target: Target) -> u8 {
    match target {
        Target::SwitchOnDisabled => 0,
        Target::ReadyToSwitchOn => 1,
        Target::SwitchedOn => 2,
        Target::OperationEnabled => 3,
    }
}

/// The one command that moves `current` a step toward `target`; `None` when there already, when
/// the drive moves on its own (Not ready to switch on, Fault reaction active), or in Fault
/// (leaving Fault needs an explicit [`Command::FaultReset`], a decision for the caller).
pub fn next_command(current: State, target: Target) -> Option<Command> {
    let want = target_rank(target);
    match current {
        State::NotReadyToSwitchOn | State::FaultReactionActive | State::Fault => None,
        // Quick stop active only leaves through Switch on disabled (12).
        State::QuickStopActive => Some(Command::DisableVoltage),
        _ => {
            let have = rank(current)?;
            if have == want {
                None
            } else if have < want {
                Some(match current {
                    State::SwitchOnDisabled => Command::Shutdown,
                    State::ReadyToSwitchOn => Command::SwitchOn,
                    _ => Command::EnableOperation,
                })
            } else {
                Some(match (current, target) {
                    (_, Target::SwitchOnDisabled) => Command::DisableVoltage,
                    (_, Target::ReadyToSwitchOn) => Command::Shutdown,
                    _ => Command::DisableOperation,
                })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn statusword_masks_ignore_the_other_bits() {
        // EPOS4 typical values: 0x0140 switch on disabled (remote), 0x0637 / 0x1637 enabled.
        assert_eq!(
            State::from_statusword(0x0140),
            Some(State::SwitchOnDisabled)
        );
        assert_eq!(State::from_statusword(0x0121), Some(State::ReadyToSwitchOn));
        assert_eq!(State::from_statusword(0x0123), Some(State::SwitchedOn));
        assert_eq!(
            State::from_statusword(0x1637),
            Some(State::OperationEnabled)
        );
        assert_eq!(State::from_statusword(0x0117), Some(State::QuickStopActive));
        assert_eq!(
            State::from_statusword(0x011F),
            Some(State::FaultReactionActive)
        );
        assert_eq!(State::from_statusword(0x0108), Some(State::Fault));
        assert_eq!(
            State::from_statusword(0x0000),
            Some(State::NotReadyToSwitchOn)
        );
        assert_eq!(State::from_statusword(0x0001), None);
    }

    #[test]
    fn every_state_round_trips_through_its_bits() {
        for s in [
            State::NotReadyToSwitchOn,
            State::SwitchOnDisabled,
            State::ReadyToSwitchOn,
            State::SwitchedOn,
            State::OperationEnabled,
            State::QuickStopActive,
            State::FaultReactionActive,
            State::Fault,
        ] {
            assert_eq!(State::from_statusword(s.statusword_bits()), Some(s));
        }
    }

    #[test]
    fn walk_to_operation_enabled_is_shutdown_switch_on_enable() {
        let mut s = State::SwitchOnDisabled;
        let mut cmds = Vec::new();
        while let Some(c) = next_command(s, Target::OperationEnabled) {
            cmds.push(c.controlword());
            s = match s {
                State::SwitchOnDisabled => State::ReadyToSwitchOn,
                State::ReadyToSwitchOn => State::SwitchedOn,
                State::SwitchedOn => State::OperationEnabled,
                other => other,
            };
        }
        assert_eq!(cmds, vec![0x06, 0x07, 0x0F]);
    }

    #[test]
    fn fault_waits_for_an_explicit_reset() {
        assert_eq!(next_command(State::Fault, Target::OperationEnabled), None);
        assert_eq!(Command::FaultReset.controlword(), 0x80);
        assert_eq!(
            next_command(State::OperationEnabled, Target::SwitchOnDisabled),
            Some(Command::DisableVoltage)
        );
        assert_eq!(
            next_command(State::OperationEnabled, Target::SwitchedOn),
            Some(Command::DisableOperation)
        );
    }
}

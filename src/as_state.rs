//! The autonomous-system (AS) states of the Formula Student Driverless rules, as the vehicle
//! computer reports them in every reference frame.
//!
//! The steering actuator may be powered only in AS Ready and AS Driving; in every other state
//! the drive is disabled so the reversible ball screw lets the driver steer (rule DT.2), and
//! in AS Emergency it is disabled at once.

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum AsState {
    /// Manual driving: a driver steers, the autonomous system is not involved.
    Manual,
    Off,
    Ready,
    Driving,
    Emergency,
    Finished,
}

impl AsState {
    /// The wire code (reference frame, DBC value table).
    pub const fn code(self) -> u8 {
        match self {
            AsState::Off => 0,
            AsState::Ready => 1,
            AsState::Driving => 2,
            AsState::Emergency => 3,
            AsState::Finished => 4,
            AsState::Manual => 5,
        }
    }

    /// `None` for codes the rules do not define; the frame carrying it is invalid.
    pub const fn from_code(code: u8) -> Option<Self> {
        match code {
            0 => Some(AsState::Off),
            1 => Some(AsState::Ready),
            2 => Some(AsState::Driving),
            3 => Some(AsState::Emergency),
            4 => Some(AsState::Finished),
            5 => Some(AsState::Manual),
            _ => None,
        }
    }

    /// May the actuator be powered in this state under the FS rules (the default
    /// [`Actuation::ReadyOrDriving`])? See [`Actuation::allows`] for the configured rule.
    pub const fn actuator_may_be_powered(self) -> bool {
        Actuation::ReadyOrDriving.allows(self)
    }
}

/// Which AS states may power the steering actuator: the rule books differ.
///
/// - [`Actuation::ReadyOrDriving`] (the default): Formula Student Germany's rules allow the
///   steering actuator to be active in AS Ready (the car stands with the brakes applied; the
///   autonomous system may move the wheels to its start angle) and AS Driving.
/// - [`Actuation::DrivingOnly`]: the FSAE Driverless supplement (DT.2.1.2) allows actuation
///   only once the car is ready to drive, i.e. AS Driving; in AS Ready the drive stays off.
///
/// Every other state (Off, Manual, Finished, Emergency) powers nothing under either rule.
/// Chosen with [`crate::steering::Config::with_actuation`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Actuation {
    #[default]
    ReadyOrDriving,
    DrivingOnly,
}

impl Actuation {
    /// Does this rule let `state` power the actuator?
    pub const fn allows(self, state: AsState) -> bool {
        match self {
            Actuation::ReadyOrDriving => matches!(state, AsState::Ready | AsState::Driving),
            Actuation::DrivingOnly => matches!(state, AsState::Driving),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn codes_round_trip_and_unknown_codes_are_refused() {
        for code in 0..=255u8 {
            match AsState::from_code(code) {
                Some(s) => assert_eq!(s.code(), code),
                None => assert!(code > 5),
            }
        }
    }

    #[test]
    fn only_ready_and_driving_power_the_actuator() {
        assert!(AsState::Ready.actuator_may_be_powered());
        assert!(AsState::Driving.actuator_may_be_powered());
        for s in [
            AsState::Manual,
            AsState::Off,
            AsState::Emergency,
            AsState::Finished,
        ] {
            assert!(!s.actuator_may_be_powered());
        }
    }
}

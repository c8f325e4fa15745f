//! The steering controller the ECU runs in direct drive: paper mode (the paper's EPOS4 cascade,
//! bit-exact) or ECU mode (the ECU's own, [`crate::ecu_mode`]), behind one call pattern so the
//! firmware, host-sim and the golden vectors drive either the same way.
//!
//! Call order per position tick: [`SteeringController::push_reference`] when a sample arrives,
//! then [`SteeringController::position_step`], then ten [`SteeringController::current_step`].

use crate::control::AntiWindup;
use crate::control::current::CurrentOutput;
use crate::control::position::PositionOutput;
use crate::ecu_mode::ColumnCascade;
use crate::paper_mode::Cascade;
use crate::reference::{ReferenceError, Setpoint};
use crate::units::{Amps, SteeringDeg, SteeringRad, Volts};

/// Which controller, as a configuration value (CLI, firmware constant).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ControllerKind {
    /// The paper's cascade on the motor angle (Table 3).
    #[default]
    Paper,
    /// The ECU's own controller on the column.
    Ecu,
}

#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant)]
pub enum SteeringController {
    Paper(Cascade),
    Ecu(ColumnCascade),
}

impl SteeringController {
    pub fn kind(&self) -> ControllerKind {
        match self {
            SteeringController::Paper(_) => ControllerKind::Paper,
            SteeringController::Ecu(_) => ControllerKind::Ecu,
        }
    }

    pub fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        match self {
            SteeringController::Paper(c) => c.push_reference(angle),
            SteeringController::Ecu(c) => c.push_reference(angle),
        }
    }

    /// A sample the ECU made itself (the enable ramp): ECU mode takes it without its inverse
    /// belt model ([`crate::ecu_mode::ColumnShaper::push_unshaped`]); both take it within the
    /// drive's limits ([`crate::paper_mode::RAMP_RANGE_DEG`]), beyond the vehicle's +-90 deg.
    pub fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        match self {
            SteeringController::Paper(c) => c.push_unshaped(angle),
            SteeringController::Ecu(c) => c.push_unshaped(angle),
        }
    }

    /// One position tick. Paper mode ignores the column (its loop sees only the motor).
    pub fn position_step(
        &mut self,
        hall_count: i32,
        column: Option<SteeringRad>,
    ) -> PositionOutput {
        match self {
            SteeringController::Paper(c) => c.position_step(hall_count),
            SteeringController::Ecu(c) => c.position_step(hall_count, column),
        }
    }

    pub fn current_step(&mut self, measured: Amps) -> CurrentOutput {
        match self {
            SteeringController::Paper(c) => c.current_step(measured),
            SteeringController::Ecu(c) => c.current_step(measured),
        }
    }

    pub fn setpoint(&self) -> Setpoint {
        match self {
            SteeringController::Paper(c) => c.setpoint(),
            SteeringController::Ecu(c) => c.setpoint(),
        }
    }

    pub fn current_setpoint(&self) -> Amps {
        match self {
            SteeringController::Paper(c) => c.current_setpoint(),
            SteeringController::Ecu(c) => c.current_setpoint(),
        }
    }

    pub fn reset(&mut self, hall_count: i32) {
        match self {
            SteeringController::Paper(c) => c.reset(hall_count),
            SteeringController::Ecu(c) => c.reset(hall_count),
        }
    }

    pub fn set_anti_windup(&mut self, mode: AntiWindup) {
        match self {
            SteeringController::Paper(c) => c.set_anti_windup(mode),
            SteeringController::Ecu(c) => c.set_anti_windup(mode),
        }
    }

    /// The winding the current guard models (ohm, H); invalid values turn the guard off.
    pub fn set_winding(&mut self, ra_ohm: f32, la_h: f32) {
        match self {
            SteeringController::Paper(c) => c.set_winding(ra_ohm, la_h),
            SteeringController::Ecu(c) => c.set_winding(ra_ohm, la_h),
        }
    }

    pub fn set_voltage_limit(&mut self, limit: Volts) {
        match self {
            SteeringController::Paper(c) => c.set_voltage_limit(limit),
            SteeringController::Ecu(c) => c.set_voltage_limit(limit),
        }
    }
}

impl From<Cascade> for SteeringController {
    fn from(c: Cascade) -> Self {
        SteeringController::Paper(c)
    }
}

impl From<ColumnCascade> for SteeringController {
    fn from(c: ColumnCascade) -> Self {
        SteeringController::Ecu(c)
    }
}

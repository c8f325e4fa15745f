//! The steering controller the ECU runs in direct drive: paper mode (the paper's EPOS4 cascade,
//! bit-exact) or ECU mode (the ECU's own, [`crate::ecu_mode`]), behind one call pattern so the
//! firmware, host-sim and the golden vectors drive either the same way.
//!
//! Call order per position tick: [`Controller::push_reference`] when a sample arrives,
//! then [`Controller::position_step`], then ten [`Controller::current_step`].

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

/// What the ECU asks of a direct-drive controller, in the call order of the module docs.
/// Paper mode and ECU mode each implement it; [`SteeringController`] holds the one chosen and
/// hands it out as this interface, so no caller matches on the mode.
pub trait Controller {
    fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError>;
    /// A sample the ECU made itself (the enable ramp): ECU mode takes it without its inverse
    /// belt model ([`crate::ecu_mode::ColumnShaper::push_unshaped`]); both take it within the
    /// drive's limits ([`crate::paper_mode::RAMP_RANGE_DEG`]), beyond the vehicle's +-90 deg.
    fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError>;
    /// One position tick. Paper mode ignores the column (its loop sees only the motor).
    fn position_step(&mut self, hall_count: i32, column: Option<SteeringRad>) -> PositionOutput;
    fn current_step(&mut self, measured: Amps) -> CurrentOutput;
    fn setpoint(&self) -> Setpoint;
    fn current_setpoint(&self) -> Amps;
    fn reset(&mut self, hall_count: i32);
    fn set_anti_windup(&mut self, mode: AntiWindup);
    /// The winding the current guard models (ohm, H); invalid values turn the guard off.
    fn set_winding(&mut self, ra_ohm: f32, la_h: f32);
    fn set_voltage_limit(&mut self, limit: Volts);
}

impl Controller for Cascade {
    fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        Cascade::push_reference(self, angle)
    }
    fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        Cascade::push_unshaped(self, angle)
    }
    fn position_step(&mut self, hall_count: i32, _column: Option<SteeringRad>) -> PositionOutput {
        Cascade::position_step(self, hall_count)
    }
    fn current_step(&mut self, measured: Amps) -> CurrentOutput {
        Cascade::current_step(self, measured)
    }
    fn setpoint(&self) -> Setpoint {
        Cascade::setpoint(self)
    }
    fn current_setpoint(&self) -> Amps {
        Cascade::current_setpoint(self)
    }
    fn reset(&mut self, hall_count: i32) {
        Cascade::reset(self, hall_count)
    }
    fn set_anti_windup(&mut self, mode: AntiWindup) {
        Cascade::set_anti_windup(self, mode)
    }
    fn set_winding(&mut self, ra_ohm: f32, la_h: f32) {
        Cascade::set_winding(self, ra_ohm, la_h)
    }
    fn set_voltage_limit(&mut self, limit: Volts) {
        Cascade::set_voltage_limit(self, limit)
    }
}

impl Controller for ColumnCascade {
    fn push_reference(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        ColumnCascade::push_reference(self, angle)
    }
    fn push_unshaped(&mut self, angle: SteeringDeg) -> Result<(), ReferenceError> {
        ColumnCascade::push_unshaped(self, angle)
    }
    fn position_step(&mut self, hall_count: i32, column: Option<SteeringRad>) -> PositionOutput {
        ColumnCascade::position_step(self, hall_count, column)
    }
    fn current_step(&mut self, measured: Amps) -> CurrentOutput {
        ColumnCascade::current_step(self, measured)
    }
    fn setpoint(&self) -> Setpoint {
        ColumnCascade::setpoint(self)
    }
    fn current_setpoint(&self) -> Amps {
        ColumnCascade::current_setpoint(self)
    }
    fn reset(&mut self, hall_count: i32) {
        ColumnCascade::reset(self, hall_count)
    }
    fn set_anti_windup(&mut self, mode: AntiWindup) {
        ColumnCascade::set_anti_windup(self, mode)
    }
    fn set_winding(&mut self, ra_ohm: f32, la_h: f32) {
        ColumnCascade::set_winding(self, ra_ohm, la_h)
    }
    fn set_voltage_limit(&mut self, limit: Volts) {
        ColumnCascade::set_voltage_limit(self, limit)
    }
}

/// The controller a direct-drive ECU runs, held by value (no heap); used through
/// [`Controller`], which it dereferences to.
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
}

impl core::ops::Deref for SteeringController {
    type Target = dyn Controller;
    fn deref(&self) -> &Self::Target {
        match self {
            SteeringController::Paper(c) => c,
            SteeringController::Ecu(c) => c,
        }
    }
}

impl core::ops::DerefMut for SteeringController {
    fn deref_mut(&mut self) -> &mut Self::Target {
        match self {
            SteeringController::Paper(c) => c,
            SteeringController::Ecu(c) => c,
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

//! The two drives the ECU can command, each with its own state: [`DirectDrive`] (the ECU's own
//! bridge, the controller's cascade run here) and [`Epos4Drive`] (the EPOS4 over CANopen: the
//! link, ECU mode's column shaper and the frames a demand change leaves for the drive task).
//! [`Drive`] holds the one the firmware was built for; the ECU asks it, never the variant.

use crate::can::Frame;
use crate::canopen::epos4::{Epos4Link, LinkError, Phase};
use crate::controller::SteeringController;
use crate::ecu_mode::ColumnShaper;
use crate::gearing::Gearing;
use crate::sensors::{HALL_COUNTS_PER_REV, hall_from_motor, motor_from_hall};
use crate::units::{Amps, MotorRad, SteeringDeg, SteeringRad};

/// Frames a demand change left for the drive task; a disable is one frame, so 4 is room for
/// several changes within one drive-task period.
pub(super) const PENDING_DEPTH: usize = 4;

/// The ECU's own bridge: the controller runs here at the fast loop's rates.
#[derive(Debug, Clone)]
pub struct DirectDrive {
    controller: SteeringController,
    /// Position ticks since the last reference sample was pushed, saturating: the rate
    /// limit's time base.
    ticks_since_push: u32,
}

/// An EPOS4 in cyclic synchronous position mode, which runs the loops itself.
#[derive(Debug, Clone)]
pub struct Epos4Drive {
    link: Epos4Link,
    /// ECU mode: the column side of the controller, which makes the CSP target. `None` in
    /// paper mode.
    shaper: Option<ColumnShaper>,
    /// Frames from demand changes, for the next drive call.
    pending: heapless::Vec<Frame, PENDING_DEPTH>,
    /// The link was up (Standby, Disabling or Cyclic) at the last supervision.
    link_up: bool,
    link_error: Option<LinkError>,
    last_link_reset_us: Option<u64>,
    current_seen_us: u64,
    /// The reference sample the drive's target came from at the last SYNC, and when that
    /// SYNC and the one before it went out: the rate limit's anchor and time base.
    synced_reference: Option<SteeringDeg>,
    last_sync_us: Option<u64>,
    sync_interval_us: u64,
}

/// How the motor is driven; see the module docs of [`crate::ecu`].
#[derive(Debug, Clone)]
// One per ECU, made once: the size difference does not matter.
#[allow(clippy::large_enum_variant)]
pub enum Drive {
    /// The ECU runs the cascade on its own bridge: paper mode or ECU mode.
    Direct(DirectDrive),
    /// An EPOS4 in cyclic synchronous position mode runs the loops.
    Epos4(Epos4Drive),
}

impl DirectDrive {
    pub(super) fn new(controller: SteeringController) -> Self {
        DirectDrive {
            controller,
            ticks_since_push: u32::MAX,
        }
    }

    /// The controller the ECU runs.
    pub fn controller(&self) -> &SteeringController {
        &self.controller
    }

    pub(super) fn controller_mut(&mut self) -> &mut SteeringController {
        &mut self.controller
    }

    /// One position tick passed (the rate limit's time base).
    pub(super) fn ticked(&mut self) {
        self.ticks_since_push = self.ticks_since_push.saturating_add(1);
    }
}

impl Epos4Drive {
    pub(super) fn new(link: Epos4Link, shaper: Option<ColumnShaper>, period_us: u32) -> Self {
        Epos4Drive {
            link,
            shaper,
            pending: heapless::Vec::new(),
            link_up: false,
            link_error: None,
            last_link_reset_us: None,
            current_seen_us: 0,
            synced_reference: None,
            last_sync_us: None,
            sync_interval_us: u64::from(period_us),
        }
    }

    pub fn link(&self) -> &Epos4Link {
        &self.link
    }

    pub(super) fn link_mut(&mut self) -> &mut Epos4Link {
        &mut self.link
    }

    /// Whether an automatic reset of a failed link is due at `now_us` (at most once per
    /// `interval_us`); if so, it is taken as done now.
    pub(super) fn take_reset_due(&mut self, now_us: u64, interval_us: u64) -> bool {
        let due = self
            .last_link_reset_us
            .is_none_or(|t| now_us.saturating_sub(t) >= interval_us);
        if due {
            self.last_link_reset_us = Some(now_us);
        }
        due
    }

    /// A new drive-current sample since the last call, if the link has one.
    pub(super) fn new_current(&mut self) -> Option<Amps> {
        let updated = self.link.feedback().current_updated_us;
        if updated == self.current_seen_us {
            return None;
        }
        self.current_seen_us = updated;
        Some(self.link.motor_current())
    }

    /// The link's error if it changed since the last call.
    pub(super) fn error_change(&mut self) -> Option<Option<LinkError>> {
        let error = self.link.error();
        if error == self.link_error {
            return None;
        }
        self.link_error = error;
        Some(error)
    }

    /// Whether the link came up (Standby, Disabling or Cyclic) since the last call.
    pub(super) fn came_up(&mut self) -> bool {
        let up = matches!(
            self.link.phase(),
            Phase::Standby | Phase::Disabling | Phase::Cyclic
        );
        let came_up = up && !self.link_up;
        self.link_up = up;
        came_up
    }

    /// A SYNC went out at `now_us` carrying the target of `reference`.
    pub(super) fn synced(&mut self, now_us: u64, reference: Option<SteeringDeg>) {
        self.synced_reference = reference;
        if let Some(t) = self.last_sync_us.replace(now_us) {
            self.sync_interval_us = now_us.saturating_sub(t);
        }
    }
}

impl Drive {
    /// The EPOS4 link, in EPOS4 mode.
    pub fn link(&self) -> Option<&Epos4Link> {
        match self {
            Drive::Epos4(d) => Some(&d.link),
            Drive::Direct(_) => None,
        }
    }

    /// The EPOS4 drive, in EPOS4 mode.
    pub(super) fn epos4_mut(&mut self) -> Option<&mut Epos4Drive> {
        match self {
            Drive::Epos4(d) => Some(d),
            Drive::Direct(_) => None,
        }
    }

    /// The ECU's own bridge, in direct mode.
    pub(super) fn direct_mut(&mut self) -> Option<&mut DirectDrive> {
        match self {
            Drive::Direct(d) => Some(d),
            Drive::Epos4(_) => None,
        }
    }

    /// The demand changed or stands (`on`: the drive may be powered), `just_enabled` if it
    /// left Disabled now. Direct: an enable restarts the cascade at the motor's aligned count
    /// `aligned`, with empty integrators. EPOS4: an enable starts ECU mode's shaper from rest
    /// at the column (`column_motor`); the power stage follows the demand, its frames queued
    /// for the next drive call. Returns the frames that did not fit the queue.
    pub(super) fn on_demand(
        &mut self,
        now_us: u64,
        on: bool,
        just_enabled: bool,
        aligned: i32,
        column_motor: MotorRad,
    ) -> u16 {
        match self {
            Drive::Direct(d) => {
                if just_enabled {
                    d.ticks_since_push = u32::MAX;
                    d.controller.reset(aligned);
                }
                0
            }
            Drive::Epos4(d) => {
                if just_enabled {
                    d.synced_reference = None;
                    if let Some(shaper) = &mut d.shaper {
                        shaper.reset(column_motor);
                    }
                }
                let mut lost = 0u16;
                for f in d.link.set_power(on, now_us) {
                    if d.pending.push(f).is_err() {
                        lost = lost.saturating_add(1);
                    }
                }
                lost
            }
        }
    }

    /// The rate limit's anchor and the time the controller takes to get there from it, s:
    /// direct, the last sample pushed (`last_pushed`) and the position ticks taken since (at
    /// most one period); EPOS4, the sample of the last SYNC and the SYNC interval (at most
    /// `period_s`).
    pub(super) fn rate_anchor(
        &self,
        last_pushed: Option<SteeringDeg>,
        period_s: f32,
    ) -> (Option<SteeringDeg>, f32) {
        match self {
            Drive::Direct(d) => {
                let ticks = d
                    .ticks_since_push
                    .min(crate::paper_mode::POSITION_TICKS_PER_REFERENCE);
                (
                    last_pushed,
                    ticks as f32 / crate::paper_mode::POSITION_LOOP_HZ as f32,
                )
            }
            Drive::Epos4(d) => (
                d.synced_reference,
                (d.sync_interval_us as f32 * 1e-6).min(period_s),
            ),
        }
    }

    /// A reference sample for the drive (`ramping`: the enable ramp's own, not shaped). The
    /// E2E check already bounds the angle to the cascade's range; a refusal keeps the ramp
    /// in progress, which is the documented outcome.
    pub(super) fn push(
        &mut self,
        gearing: Gearing,
        angle: SteeringDeg,
        ramping: bool,
        column: SteeringDeg,
        origin: Option<i32>,
    ) {
        match self {
            Drive::Direct(d) => {
                d.ticks_since_push = 0;
                let _ = if ramping {
                    d.controller.push_unshaped(angle)
                } else {
                    d.controller.push_reference(angle)
                };
            }
            Drive::Epos4(d) => Self::push_epos4_target(d, gearing, angle, ramping, column, origin),
        }
    }

    /// Direct mode: restart the cascade at the aligned count `aligned` with empty
    /// integrators. Nothing in EPOS4 mode.
    pub(super) fn resync(&mut self, aligned: i32) {
        if let Drive::Direct(d) = self {
            d.controller.reset(aligned);
        }
    }

    /// The frames demand changes left for the drive task, emptied (none in direct mode).
    pub(super) fn take_pending(&mut self) -> heapless::Vec<Frame, PENDING_DEPTH> {
        match self {
            Drive::Epos4(d) => core::mem::take(&mut d.pending),
            Drive::Direct(_) => heapless::Vec::new(),
        }
    }

    /// The motor sensor's raw count: the Hall count `hall_count` (it starts at 0 wherever the
    /// motor stands at power-up), or the EPOS4's position actual once the drive has reported
    /// one.
    pub(super) fn motor_counts(&self, hall_count: i32) -> Option<i32> {
        match self {
            Drive::Direct(_) => Some(hall_count),
            Drive::Epos4(d) => d
                .link
                .position_known()
                .then_some(d.link.feedback().position_inc),
        }
    }

    /// The nearest count of a motor angle, in the drive's unit; `None` if not finite.
    pub(super) fn counts_from_motor(&self, motor: MotorRad) -> Option<i32> {
        match self {
            Drive::Direct(_) => motor.is_finite().then(|| {
                // `hall_from_motor` floors: half a count more rounds to the nearest.
                let half_count = core::f64::consts::PI / f64::from(HALL_COUNTS_PER_REV);
                hall_from_motor(f64::from(motor.0) + half_count)
            }),
            Drive::Epos4(d) => d.link.scale().inc_from_motor(motor),
        }
    }

    pub(super) fn motor_from_counts(&self, counts: i32) -> MotorRad {
        match self {
            Drive::Direct(_) => motor_from_hall(counts),
            Drive::Epos4(d) => d.link.scale().motor_from_inc(counts),
        }
    }

    /// The motor origin, also to the EPOS4 link: the drive's software position limits are
    /// written around it at each enable.
    pub(super) fn set_origin(&mut self, origin: Option<i32>) {
        if let Drive::Epos4(d) = self {
            d.link.set_position_origin(origin);
        }
    }

    /// What pushes the motor: the position loop's current set-point (direct), the drive's
    /// measured current `measured` (EPOS4: its set-point is not on the bus).
    pub(super) fn effort(&self, measured: Amps) -> Amps {
        match self {
            Drive::Direct(d) => d.controller.current_setpoint(),
            Drive::Epos4(_) => measured,
        }
    }

    /// Whether power demanded is not yet power delivered: the EPOS4 is not in Operation
    /// enabled (the link walks CiA 402 for a few SDO round trips).
    pub(super) fn arming(&self) -> bool {
        match self {
            Drive::Direct(_) => false,
            Drive::Epos4(d) => d.link.phase() != Phase::Cyclic,
        }
    }

    /// The drive's target for the reference sample `angle` (EPOS4): ECU mode's shaped target
    /// with the column terms (`ramping`: the enable ramp's own sample, not shaped), plus the
    /// origin, since the drive counts from where it powered up. Not finite, or no origin
    /// yet: the target stays (the link keeps it at the drive's actual position until it is
    /// enabled).
    fn push_epos4_target(
        d: &mut Epos4Drive,
        gearing: Gearing,
        angle: SteeringDeg,
        ramping: bool,
        column: SteeringDeg,
        origin: Option<i32>,
    ) {
        let mut motor = gearing.motor_from_steering(SteeringRad::from(angle));
        if let Some(shaper) = &mut d.shaper {
            // A refused sample keeps the shaper's last target.
            let _ = if ramping {
                shaper.push_unshaped(angle)
            } else {
                shaper.push_reference(angle)
            };
            let column = Some(SteeringRad::from(column)).filter(|c| c.is_finite());
            motor = shaper.next_target(column);
        }
        if let (Some(inc), Some(origin)) = (d.link.scale().inc_from_motor(motor), origin) {
            d.link.set_target_inc(inc.saturating_add(origin));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::canopen::NodeId;
    use crate::canopen::epos4::Epos4Config;

    /// In EPOS4 mode the rate limit's time base is the interval between the last two SYNCs,
    /// at most a reference period: a SYNC sent early (the link enters Cyclic and syncs at
    /// once, 3 ms after Standby's last) lets the target move only 3 ms' worth, and a late one
    /// no more than a period's.
    #[test]
    fn the_epos4_rate_anchor_spans_the_sync_interval_at_most_a_period() {
        let node = NodeId::new(1).unwrap();
        let link = Epos4Link::new(Epos4Config::paper(node), 0).unwrap();
        let mut drive = Drive::Epos4(Epos4Drive::new(link, None, 10_000));
        let Drive::Epos4(d) = &mut drive else {
            unreachable!()
        };
        d.synced(0, Some(SteeringDeg(4.0)));
        d.synced(3_000, Some(SteeringDeg(5.0)));
        let (anchor, span_s) = drive.rate_anchor(None, 0.01);
        assert_eq!(anchor, Some(SteeringDeg(5.0)));
        assert!((span_s - 0.003).abs() < 1e-7, "{span_s} s");

        let Drive::Epos4(d) = &mut drive else {
            unreachable!()
        };
        d.synced(28_000, Some(SteeringDeg(6.0)));
        assert_eq!(
            drive.rate_anchor(None, 0.01),
            (Some(SteeringDeg(6.0)), 0.01)
        );
    }

    /// In EPOS4 mode what pushes the motor, for the runaway check, is the drive's measured
    /// current as given (its own set-point is not on the bus), either sign.
    #[test]
    fn the_epos4_effort_is_the_measured_current() {
        let node = NodeId::new(1).unwrap();
        let link = Epos4Link::new(Epos4Config::paper(node), 0).unwrap();
        let drive = Drive::Epos4(Epos4Drive::new(link, None, 10_000));
        assert_eq!(drive.effort(Amps(18.5)), Amps(18.5));
        assert_eq!(drive.effort(Amps(-7.25)), Amps(-7.25));
    }
}

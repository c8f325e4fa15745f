//! A current column that holds instantaneous samples of a current loop's chatter.
//!
//! Our loggers write each row's current as the mean over the row's interval (the 0x102
//! frame, host-sim's logs) or, on the EPOS4 car, the drive's sample at the SYNC. A team's
//! logger of the direct drive may instead write the ECU's last current sample at each row:
//! an instant of the cascade's chatter, where the position loop's new current set-point every
//! 0.5 ms on 84-count Hall feedback moves the winding current by amperes. At 100 Hz those
//! samples scatter about the interval mean by 4-7 A on the independent world's sweeps (the
//! mean's own row-to-row scatter is 0.4-0.7 A), and no model repeats that chatter sample for
//! sample: it is noise to the diagnosis.
//!
//! The likelihood the diagnosis fits weighs each signal by its own noise and takes that in
//! its stride. The car's fits do not: they compare the cars by the GoF (eq. 11), where such a
//! current outweighs the column and chooses the reference convention, the drive or the
//! reference tick by its chatter (a 90 ms mean still leaves 2 A of it against 3-6 A of
//! signal). So where the header says the current is instantaneous, or where the log's current
//! scatters row to row [`CHATTER_RATIO`] times more than the current of any car our loggers
//! record (the direct drive's interval mean under either controller, the EPOS4's SYNC
//! sample), the car is fitted on the column and the motor angle
//! ([`super::Record::current_chatter`]): the motor answers the reference through the position
//! loop, ahead of the belt, the rack and the tyre. Where the scatter found it and the log
//! does not say which drive wrote it, the EPOS4 is left out: its current is one sample a
//! SYNC of a 25 kHz loop on a fine encoder, and the largest scatter of [`read`]'s cars is its
//! own (1.2-1.5 A on the independent world's sweeps, as the world's EPOS4 logs show it); the
//! direct drive's instantaneous samples at 100 Hz scatter 2.9-5.5 times that. Where the
//! log's reference convention is fitted, the two conventions' best cars are told apart by
//! their candidates, as two drives are. The diagnosis's likelihood then
//! takes the current's whole scatter about the nominal model for its noise (the median third
//! difference it reads off other logs takes a chatter's heavy tails for less than they are),
//! and its GoF too pairs the column with the motor angle.

use super::Record;
use super::drive::{SYNC_SEARCH_S, head, with_car};
use super::model::Effects;
use super::rig::{CarDrive, Rig, RigModel};
use super::score::{Scorer, white_sigma};
use crate::sim::Controller;

/// How many times more than any car's logged current a log's current must scatter row to row
/// (the white part: the median third difference) to be taken for instantaneous samples of
/// the loop's chatter. The largest car's is the EPOS4's SYNC sample, and the world's EPOS4
/// logs scatter as much as its model (1.30 A against 1.32 A, 1.39 against 1.40 on two
/// sweeps); the direct drive's instantaneous samples at 100 Hz scatter 2.9-5.5 times the
/// largest car's on the first 20 cars' logs: twice lies between, about a factor of two from
/// the EPOS4's and from the lowest of them.
pub const CHATTER_RATIO: f64 = 2.0;

/// What the log's current column was read as, and why.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct CurrentChatter {
    /// The header says so (`# current: instantaneous`); else found from the log.
    pub stated: bool,
    /// The white part of the log's current on the grid (row-to-row scatter, the median third
    /// difference), A, on the log's first 10 s.
    pub log_white_a: f64,
    /// The largest white part of a car's current as our loggers record it, on the same
    /// reference (the cars' nominal models), A.
    pub cars_white_a: f64,
    /// The drive was the log's to say and the EPOS4 was left out: its current, one sample
    /// at each SYNC of a 25 kHz loop on a fine encoder, does not chatter so; the direct
    /// drive's instantaneous current does.
    pub epos4_left_out: bool,
}

impl CurrentChatter {
    /// One clause for the report's car line.
    pub fn describe(&self) -> String {
        let why = if self.stated {
            "the header says so".to_string()
        } else {
            format!(
                "its row-to-row scatter {:.2} A, {:.1} times the {:.2} A of any car's logged \
                 current",
                self.log_white_a,
                self.log_white_a / self.cars_white_a.max(1e-12),
                self.cars_white_a
            )
        };
        format!(
            "the current column read as instantaneous samples of the loop's chatter ({why}): \
             GoF of the column and the motor angle, the current weighed as noise{}",
            if self.epos4_left_out {
                ", the EPOS4 left out (its current does not chatter so)"
            } else {
                ""
            }
        )
    }
}

/// Reads the log's current column on the paper rig: `stated` is the header's `# current:`
/// line (`Some(true)` for `instantaneous`, `Some(false)` for any other kind, `None` without
/// the line). `None` where the current is compared as logged.
pub fn read(rig: &Rig, rec: &Record, stated: Option<bool>) -> Option<CurrentChatter> {
    if !matches!(rig.model, RigModel::Paper(_)) || stated == Some(false) {
        return None;
    }
    let on = head(rec, SYNC_SEARCH_S);
    let skip = Scorer::new(rig, &on).skip();
    let log_white_a = white_sigma(&on.effort[skip..]);
    let cars = [
        (CarDrive::Direct, Controller::Paper, 0.0),
        (CarDrive::Direct, Controller::Ecu, 0.0),
        (CarDrive::Epos4, Controller::Paper, 0.005),
    ];
    let cars_white_a = cars
        .iter()
        .map(|&(d, c, phase)| {
            let sim = super::simulate(&with_car(rig, d, c, phase), &on, &Effects::nominal());
            let n = sim.effort.len().min(on.len());
            white_sigma(&sim.effort[skip.min(n)..n])
        })
        .filter(|w| w.is_finite())
        .fold(0.0, f64::max);
    let found = log_white_a.is_finite() && log_white_a > CHATTER_RATIO * cars_white_a;
    (stated == Some(true) || found).then_some(CurrentChatter {
        stated: stated == Some(true),
        log_white_a,
        cars_white_a,
        epos4_left_out: false,
    })
}

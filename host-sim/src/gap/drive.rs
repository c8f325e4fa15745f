//! Which car wrote a log: its drive (an EPOS4 in CSP, or the ECU's own bridge), the ECU's
//! controller, and on an EPOS4 car where the drive's SYNC falls after each reference sample.
//!
//! The nominal model must be the car's own chain: an EPOS4 latches the ECU's target at a SYNC
//! and reports its position and current as sampled there, which a model of the direct drive
//! reads as parameters off the table. The header lines `steer-can convert` and host-sim write
//! say which car it was (`# drive: epos4`, `# controller: paper`); a log without them (a
//! team's own logger) is run through every car the header leaves open, and the one whose
//! nominal model leaves the least of the log (eq. 11) is taken, with the margin printed;
//! where the other drive's nominal model comes close, the two drives are told apart by their
//! best candidates, alone or beside a late reference ([`DriveScreen`]). The SYNC's phase is
//! not in any header: the ECU's SYNC grid runs on its own clock, so it is searched on every
//! EPOS4 log.

use super::drive_clock::{self, ClockRefit};
use super::model::{Effects, MAX_SYNC_DRIFT};
use super::reference_window::{self, ReferenceWindow};
use super::rig::{CarDrive, Epos4Readout, Rig, RigModel};
use super::{CurrentSamples, Fit, Record, ReferenceConvention, Scorer, parallel_map, simulate};
use crate::sim::Controller;

/// What a log's comment lines before its header say of the car and the logger.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize)]
pub struct LogHeader {
    pub drive: Option<CarDrive>,
    pub controller: Option<Controller>,
    /// `# current: ...`: what the current column holds.
    pub current: Option<CurrentSamples>,
    /// `# reference: ...`: which reference a row at a reference instant holds.
    pub reference: Option<ReferenceConvention>,
    /// `# sync-drift: +35.2 ppm`: how fast the EPOS4 car's SYNC grid walks against the
    /// reference frames, s per s, as `steer-can convert` reads it off the bus.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sync_drift: Option<f64>,
    /// `# column-sampled: 2.31 ms before each row's end`: where the status frames' column
    /// samples sit against the rows at the log's start, s (convert reads the column at each
    /// row's end off a line between them; the ECU's clock places them).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub column_sampled_s: Option<f64>,
}

/// The period a status frame's column sample may sit before a row's end, ms.
const COLUMN_SAMPLED_MAX_MS: f64 = 10.0;

impl LogHeader {
    /// The `key: value` comment lines (without their `#`); other comments are ignored, and a
    /// value this reader does not know is an error, not a guess.
    pub fn parse(comments: &[String]) -> Result<LogHeader, String> {
        let mut h = LogHeader::default();
        for c in comments {
            let Some((k, v)) = c.split_once(':') else {
                continue;
            };
            let (k, v) = (k.trim(), v.trim());
            match k {
                "drive" => {
                    h.drive = Some(CarDrive::from_name(v).ok_or_else(|| {
                        format!("header `# drive: {v}`: expected `epos4` or `direct`")
                    })?)
                }
                "controller" => {
                    h.controller = Some(controller_from_name(v).ok_or_else(|| {
                        format!("header `# controller: {v}`: expected `paper` or `ecu`")
                    })?)
                }
                "current" => {
                    h.current = Some(CurrentSamples::from_name(v).ok_or_else(|| {
                        format!(
                            "header `# current: {v}`: expected `interval-mean`, `sync-sample` \
                             or `instantaneous`"
                        )
                    })?)
                }
                "reference" => {
                    h.reference = Some(ReferenceConvention::from_name(v).ok_or_else(|| {
                        format!(
                            "header `# reference: {v}`: expected `period-ending` (each row holds \
                             the reference of the period that ends there) or `period-starting` \
                             (the one that starts there)"
                        )
                    })?)
                }
                "sync-drift" => {
                    h.sync_drift = Some(
                        v.strip_suffix("ppm")
                            .and_then(|n| n.trim().parse::<f64>().ok())
                            .filter(|d| d.is_finite() && d.abs() <= 1e6 * MAX_SYNC_DRIFT)
                            .map(|d| d / 1e6)
                            .ok_or_else(|| {
                                format!(
                                    "header `# sync-drift: {v}`: expected parts per million \
                                     within +-{:.0}, e.g. `+35.2 ppm`",
                                    1e6 * MAX_SYNC_DRIFT
                                )
                            })?,
                    )
                }
                "column-sampled" => {
                    h.column_sampled_s = Some(
                        v.strip_suffix("ms before each row's end")
                            .and_then(|n| n.trim().parse::<f64>().ok())
                            .filter(|a| a.is_finite() && (0.0..=COLUMN_SAMPLED_MAX_MS).contains(a))
                            .map(|a| a * 1e-3)
                            .ok_or_else(|| {
                                format!(
                                    "header `# column-sampled: {v}`: expected milliseconds \
                                     within 0-{COLUMN_SAMPLED_MAX_MS:.0}, e.g. `2.31 ms before \
                                     each row's end`"
                                )
                            })?,
                    )
                }
                _ => {}
            }
        }
        Ok(h)
    }

    /// The header lines of a log of this car (for the writers).
    pub fn lines(drive: CarDrive, controller: Controller) -> Vec<String> {
        crate::car::header_lines(drive, controller)
    }
}

pub use crate::car::{controller_from_name, controller_name};

/// How the car was chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    /// Given on the command line.
    Option,
    /// Read from the log's header lines.
    Header,
    /// Fitted: the nominal model the log supports best.
    Fitted,
}

/// One car tried on the log.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Tried {
    pub drive: CarDrive,
    pub controller: Controller,
    /// EPOS4 only: the SYNC after each reference sample, s.
    pub sync_after_push_s: Option<f64>,
    /// Direct drive only: how far into its period the ECU takes each reference sample, s
    /// (whole position-loop ticks, [`super::rig::PaperModel::push_tick`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub push_after_s: Option<f64>,
    /// EPOS4 only: the drift of the SYNC grid its model runs, s per s, where the header gives
    /// one and it fits the log better than one SYNC phase; `sync_after_push_s` is then the
    /// phase at the log's start.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sync_drift: Option<f64>,
    /// Rows the reference column was moved later by: 1 when the logger writes at each row
    /// the reference that starts there (the ECU uses it from that instant), 0 when the one in
    /// force over the period that ends there (host-sim's and steer-can's logs).
    pub reference_shift_rows: usize,
    /// The nominal model's GoF on the log (eq. 11, combined).
    pub gof: f64,
    /// EPOS4 only: the readout fitted with the phase (on a log whose header does not say how
    /// it read the drive), or convert's with the column where its header places it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub readout: Option<Epos4Readout>,
    /// EPOS4 only: the current-loop ticks from each period's start to the drive's next
    /// position-loop tick (fitted, [`super::drive_clock`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position_phase_ticks: Option<u32>,
    /// EPOS4 under the ECU controller: when the ECU's 2 ms column-encoder task samples after
    /// each reference sample, s (fitted, [`super::drive_clock::fit_encoder_phase`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub encoder_phase_s: Option<f64>,
}

/// The chosen car run with its reference late.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct LateComparison {
    /// The delay that fits the head of the log (its first 10 s) best, s.
    pub delay_s: f64,
    /// The car's GoF on the whole log, nominal and with that delay.
    pub gof: f64,
    pub gof_late: f64,
}

/// Two drives' cars whose nominal models the log left close, told apart by the candidates
/// ([`super::screen`]): the other drive is taken where its best effect, alone or beside a
/// late reference, fits the log better than the chosen car's by more than
/// [`SCREEN_MARGIN_GOF`]. Two reference conventions are told apart by single effects. The
/// other car is screened first; where its best does not beat the chosen car's nominal model
/// by the margin, it cannot beat the chosen car's best, which is then not fitted.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct DriveScreen {
    /// The two cars differ in their reference convention, not their drive: on a current of
    /// the loop's chatter ([`super::chatter`]) the conventions are screened so.
    pub by_convention: bool,
    /// The car the nominal models ranked first, then the other drive's best.
    pub cars: [ScreenedCar; 2],
    /// The other drive's car was taken.
    pub switched: bool,
}

/// One car of a [`DriveScreen`].
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ScreenedCar {
    pub drive: CarDrive,
    pub controller: Controller,
    /// Its reference convention where fitted (see [`Tried::reference_shift_rows`]).
    pub reference_shift_rows: Option<usize>,
    /// Its nominal GoF on the whole log, and its best candidate's: `None` for the
    /// chosen car where the other car's best did not beat its nominal GoF by the margin (so
    /// could not beat its best).
    pub nominal_gof: f64,
    pub best_effect: Option<String>,
    pub best_gof: Option<f64>,
}

/// The car the diagnosis runs, and how it was chosen.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct CarChoice {
    pub drive: CarDrive,
    pub controller: Controller,
    pub drive_from: Source,
    pub controller_from: Source,
    pub sync_after_push_s: Option<f64>,
    /// Direct drive: how far into its period the ECU takes each reference sample, s (fitted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub push_after_s: Option<f64>,
    /// EPOS4: how fast its SYNC grid walks against the reference, s per s, as the model runs
    /// it: the header's, where it fits the log better than one SYNC phase
    /// (`sync_after_push_s` is then the phase at the log's start).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub sync_drift: Option<f64>,
    /// EPOS4: the drift the header states (`# sync-drift:`), run or not.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub header_sync_drift: Option<f64>,
    /// The reference convention: `None` when the header states it, else the rows the
    /// reference column was moved by (see [`Tried::reference_shift_rows`]).
    pub reference_shift_rows: Option<usize>,
    /// A delay this log's timing can explain, s: `delay` is named only beyond it.
    pub timing_bound_s: f64,
    /// Where a late reference lifted a car's fit, the cars were compared with it: the chosen
    /// car's figures. The diagnosis still starts from the nominal model (the delay is for its
    /// candidates to find).
    pub compared_late: Option<LateComparison>,
    /// The best of each car tried (one entry when the car was given), best first.
    pub tried: Vec<Tried>,
    /// An EPOS4 car: how the log reads the drive ([`Epos4Readout`]): fitted where the header
    /// does not say; where it does (`steer-can convert`'s), convert's, with the column where
    /// the header's `# column-sampled:` line places it.
    pub readout: Option<Epos4Readout>,
    /// An EPOS4 car: the current-loop ticks (50 us) from each period's start to the drive's
    /// next position-loop tick (fitted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub position_phase_ticks: Option<u32>,
    /// An EPOS4 car under the ECU controller: when the ECU's column-encoder task samples after
    /// each reference sample, s (fitted).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub encoder_phase_s: Option<f64>,
    /// An EPOS4 car whose drive clock the diagnosis fitted again with its best candidate in
    /// the model, and moved ([`super::drive_clock::with_best`]); `sync_after_push_s` and
    /// `position_phase_ticks` are then the moved clock ([`CarChoice::on_the_clock_of`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub clock_refitted: Option<ClockRefit>,
    /// An EPOS4 car logged a row per SYNC: the stretches where the reference column is a row
    /// off what the drive latched, the SYNC walking through the frames on a clock of its own
    /// ([`super::reference_window`]); the record the diagnosis runs has them moved.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reference_windows: Vec<ReferenceWindow>,
    /// The drive fitted where the two drives' nominal models came within
    /// [`DRIVE_SCREEN_GOF`]: how their candidates told them apart.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub screened: Option<DriveScreen>,
    /// The current column read as instantaneous samples of the loop's chatter: the GoF pairs
    /// the column with the motor angle, and the likelihood weighs the current as noise
    /// ([`super::chatter`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub current_chatter: Option<super::chatter::CurrentChatter>,
    /// How the diagnosis reads the log's columns against the nominal model's: a column the
    /// logger wrote with the other sign read negated, a motor angle in another unit left out
    /// ([`super::columns`]).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub columns: Option<super::columns::ColumnSigns>,
}

impl CarChoice {
    /// Whether a log of this car can hold stretches where its reference column is a row off
    /// the drive's latch ([`super::reference_window`]): an EPOS4 car at the reference rate
    /// whose reference convention no header states (so was fitted), as a team's row-per-SYNC
    /// logger writes it.
    pub fn may_lead_the_latch(&self) -> bool {
        self.drive == CarDrive::Epos4 && self.reference_shift_rows.is_some()
    }

    /// This car on the clock `d` was diagnosed on, where the diagnosis moved it.
    pub fn on_the_clock_of(mut self, d: &super::Diagnosis) -> CarChoice {
        if let Some(r) = &d.clock_refit {
            self.sync_after_push_s = Some(r.sync_after_push_s);
            self.position_phase_ticks = Some(r.position_phase_ticks);
            self.clock_refitted = Some(r.clone());
        }
        self
    }

    /// Where the frames of a late reference can have reached the ECU, ms after each reference
    /// sample (lowest excluded), where the diagnosis `d` named a delay on an EPOS4 car: the
    /// drive latches a frame at the first SYNC after it arrives, so the log fixes the latch
    /// (the SYNC phase plus the fitted delay, `sync_after_push_s` on the clock `d` ran), and
    /// every arrival within the SYNC period before it gives the same log (gap/NOTES.md, "A
    /// late reference and the SYNC are one thing to the model"). `None` otherwise: a direct
    /// drive takes each frame at the position tick it lands on, and its delay is the fit's.
    pub fn late_reference_window_ms(&self, d: &super::Diagnosis) -> Option<(f64, f64)> {
        if self.drive != CarDrive::Epos4 || !d.verdict.effects.iter().any(|e| e == "delay") {
            return None;
        }
        let sync_ms = 1e3 * self.sync_after_push_s?;
        let named = d.verdict.effects.join("+");
        let delay_ms = d
            .ranking
            .iter()
            .find(|c| c.effect == named)?
            .params
            .iter()
            .find(|(k, _)| k.ends_with("delay_ms"))
            .map(|(_, v)| *v)?;
        let latch_ms = sync_ms + delay_ms;
        let period_ms = 1e3 / steering_ecu::paper_mode::REFERENCE_HZ as f64;
        latch_ms
            .is_finite()
            .then_some(((latch_ms - period_ms).max(0.0), latch_ms))
    }

    /// One line for the report.
    pub fn describe(&self) -> String {
        let from = |s: Source| match s {
            Source::Option => "given",
            Source::Header => "from the header of the log",
            Source::Fitted => "fitted",
        };
        let mut line = format!(
            "car: {} drive ({}), {} controller ({})",
            self.drive.name(),
            from(self.drive_from),
            controller_name(self.controller),
            from(self.controller_from),
        );
        if let Some(s) = self.sync_after_push_s {
            line.push_str(&format!(
                "; SYNC {:.2} ms after each reference sample (fitted)",
                1e3 * s
            ));
        }
        if let Some(p) = self.position_phase_ticks {
            line.push_str(&format!(
                "; the drive's position loop {:.2} ms into each period (fitted)",
                1e3 * f64::from(p) * SYNC_FINE_STEP_S
            ));
        }
        if let Some(e) = self.encoder_phase_s {
            let from = match self.readout.and_then(|r| drive_clock::encoder_phase_of(&r)) {
                Some(_) => "the header's column line",
                None => "fitted",
            };
            line.push_str(&format!(
                "; the ECU's column encoder sampled {:.2} ms after each reference sample ({from})",
                1e3 * e
            ));
        }
        if let Some(r) = &self.clock_refitted {
            line.push_str(&format!(
                " (both fitted again with {} in the model; on the nominal model: SYNC {:.2} ms, \
                 position loop {:.2} ms)",
                r.with_effect,
                1e3 * r.nominal_sync_after_push_s,
                1e3 * f64::from(r.nominal_position_phase_ticks) * SYNC_FINE_STEP_S
            ));
        }
        match (self.sync_drift, self.header_sync_drift) {
            (Some(d), _) => line.push_str(&format!(
                "; the SYNC grid walking {:+.1} ppm against the reference (the ECU's clock \
                 against the vehicle computer's, from the header of the log)",
                1e6 * d
            )),
            (None, Some(d)) if d != 0.0 => line.push_str(&format!(
                "; the header's SYNC drift of {:+.1} ppm not run: one SYNC phase fits the log \
                 better",
                1e6 * d
            )),
            _ => {}
        }
        if let Some(s) = self.push_after_s {
            line.push_str(&format!(
                "; each reference sample taken {:.1} ms into its period (fitted)",
                1e3 * s
            ));
        }
        if let Some(r) = self.readout.filter(|r| r.column_interpolated) {
            line.push_str(&if r.column_age_s > 0.0 {
                format!(
                    "; the column read as steer-can convert reads it, off a line between the \
                     status frames' samples {:.2} ms before each row's end (the header's)",
                    1e3 * r.column_age_s
                )
            } else {
                "; the column at each row's end (the header does not say where the status \
                 frames sampled it)"
                    .to_string()
            });
        } else if let Some(r) = &self.readout {
            line.push_str(&format!(
                "; the drive's samples read as {}, the column {:.2} ms old (fitted; the header \
                 does not say)",
                if r.rows_per_sync() {
                    "a row per SYNC (the current at the row's end)"
                } else {
                    "steer-can convert reads them (the current at the row's middle)"
                },
                1e3 * r.column_age_s
            ));
        }
        if let Some(c) = &self.current_chatter {
            line.push_str(&format!("; {}", c.describe()));
        }
        if let Some(c) = self.columns.map(|c| c.describe()).filter(|c| !c.is_empty()) {
            line.push_str(&format!("; {c}"));
        }
        match self.reference_shift_rows {
            Some(0) => line.push_str(
                "; reference column: the period ending at each row (fitted; the header does not say)",
            ),
            Some(n) => line.push_str(&format!(
                "; reference column: the period starting at each row (fitted, {n} row later; the \
                 header does not say)"
            )),
            None => {}
        }
        for w in &self.reference_windows {
            line.push_str(&format!("; {}", w.describe()));
        }
        if let Some(l) = &self.compared_late {
            line.push_str(&format!(
                "; the cars compared with the reference late (it lifts this car's GoF from \
                 {:.1} % to {:.1} % at {:.1} ms, the delay its first {:.0} s fit best)",
                100.0 * l.gof,
                100.0 * l.gof_late,
                1e3 * l.delay_s,
                SYNC_SEARCH_S
            ));
        }
        if let Some(sc) = &self.screened {
            let car = |c: &ScreenedCar| {
                let best = match c.best_gof {
                    Some(g) => format!(
                        "with {} {:.1} %",
                        c.best_effect.as_deref().unwrap_or("no candidate"),
                        100.0 * g
                    ),
                    None => "its candidates not fitted".to_string(),
                };
                let convention = match (sc.by_convention, c.reference_shift_rows) {
                    (true, Some(rows)) => convention_clause(rows),
                    _ => "",
                };
                format!(
                    "{} + {}{convention} nominal {:.1} %, {best}",
                    c.drive.name(),
                    controller_name(c.controller),
                    100.0 * c.nominal_gof,
                )
            };
            line.push_str(&format!(
                "; the {}' nominal models within {:.0} points, so told apart by their best \
                 {} ({}; {}): {}",
                if sc.by_convention {
                    "reference conventions"
                } else {
                    "drives"
                },
                100.0 * DRIVE_SCREEN_GOF,
                if sc.by_convention {
                    "single candidates"
                } else {
                    "candidates, alone or beside a late reference"
                },
                car(&sc.cars[0]),
                car(&sc.cars[1]),
                if sc.by_convention {
                    format!(
                        "the reference {} at each row {}",
                        if sc.cars[usize::from(sc.switched)].reference_shift_rows == Some(0) {
                            "ending"
                        } else {
                            "starting"
                        },
                        if sc.switched {
                            "taken, its candidates fitting the log better"
                        } else {
                            "kept"
                        }
                    )
                } else if sc.switched {
                    format!(
                        "the {} drive taken, its candidates fitting the log more than {:.0} \
                         points better",
                        sc.cars[1].drive.name(),
                        100.0 * SCREEN_MARGIN_GOF
                    )
                } else {
                    format!("the {} drive kept", sc.cars[0].drive.name())
                }
            ));
        }
        line.push_str(&format!(
            "; a delay is named only beyond {:.1} ms (what the timing of the log can explain)",
            1e3 * self.timing_bound_s.max(0.010)
        ));
        let others: Vec<String> = self
            .tried
            .iter()
            .skip(1)
            .map(|t| {
                format!(
                    "{} + {}{}: nominal GoF {:.1} %",
                    t.drive.name(),
                    controller_name(t.controller),
                    if self.reference_shift_rows.is_some() {
                        convention_clause(t.reference_shift_rows)
                    } else {
                        ""
                    },
                    100.0 * t.gof
                )
            })
            .collect();
        if let Some(best) = self.tried.first()
            && !others.is_empty()
        {
            // Ranked with the reference late, the chosen car's nominal GoF may be the lower.
            line.push_str(&format!(
                "; {}nominal GoF {:.1} % against {}",
                if self.compared_late.is_some() {
                    "ranked with the reference late, not by these: "
                } else {
                    ""
                },
                100.0 * best.gof,
                others.join(", ")
            ));
        }
        line
    }
}

/// SYNC phases tried on an EPOS4 log, s after each reference sample: every millisecond of the
/// 10 ms period, then every current-loop tick (50 us) within half a millisecond of the best:
/// the drive samples its current at the SYNC, and where that falls within the position
/// loop's 0.5 ms cycle shows in the current it reports.
const SYNC_COARSE_S: [f64; 10] = [
    0.001, 0.002, 0.003, 0.004, 0.005, 0.006, 0.007, 0.008, 0.009, 0.010,
];
const SYNC_FINE_STEP_S: f64 = 1.0 / steering_ecu::paper_mode::CURRENT_LOOP_HZ as f64;
const SYNC_FINE_STEPS: i32 = 10;
/// The phase is searched on at most this much of the log, s (it is one number for the log).
pub(super) const SYNC_SEARCH_S: f64 = 10.0;
/// An EPOS4 car whose best coarse phase leaves the log this far (GoF, combined) below the best
/// car's is not refined: a phase moves the GoF by less.
const PRUNE_GOF: f64 = 0.15;

/// An EPOS4 car under the ECU controller whose head GoF at its best column-encoder phase on
/// the head is this far below the best car's keeps that phase: the phase is fitted on the
/// whole log ([`super::drive_clock::fit_encoder_phase`], eight runs of it) only for a car that
/// may come first. (The head's best phase bounds the car's head GoF at any phase; the cars are
/// ranked on the whole log: on the simulated car's sweep logged without a header, the head
/// chose 1.25 ms and the whole log 1.5 ms, 0.04 points apart there.)
const ENCODER_REACH_GOF: f64 = 0.02;

/// The position-loop ticks into its period at which a direct-drive car may take each reference
/// sample: the frame's time on the bus (0.1-0.3 ms at 500 kbit/s - 1 Mbit/s) and the wait for
/// the next tick of the free-running 2 kHz loop (up to 0.5 ms) put it 0-2 ticks after the
/// vehicle computer sent it.
const MAX_PUSH_TICK: u32 = 2;
const PUSH_TICKS: [u32; MAX_PUSH_TICK as usize + 1] = [0, 1, MAX_PUSH_TICK];
const POSITION_TICK_S: f64 = 1.0 / steering_ecu::paper_mode::POSITION_LOOP_HZ as f64;

/// How the report names a car's reference convention, from the rows its reference column
/// was moved by ([`Tried::reference_shift_rows`]).
fn convention_clause(shift_rows: usize) -> &'static str {
    if shift_rows == 0 {
        " (reference ending at the row)"
    } else {
        " (reference starting at the row)"
    }
}

/// `rig` as the car `drive` + `controller`, its reference timed by `phase` (s after each
/// reference sample): an EPOS4's SYNC, or the direct drive's position tick that takes it.
pub(super) fn with_car(rig: &Rig, drive: CarDrive, controller: Controller, phase: f64) -> Rig {
    let mut r = rig.clone();
    if let RigModel::Paper(m) = &mut r.model {
        m.drive = drive;
        m.controller = controller;
        match drive {
            CarDrive::Epos4 => m.epos4.sync_after_push_s = phase,
            // A whole number of ticks, 0 to 2: the `as` takes a negative or NaN phase to 0,
            // the `min` holds a larger one (or an infinite one) to 2.
            CarDrive::Direct => {
                m.push_tick = ((phase / POSITION_TICK_S).round() as u32).min(MAX_PUSH_TICK)
            }
        }
    }
    r
}

/// Reference delays each car is run with before the cars are compared, s: every 10 ms to
/// 80 ms (the delay candidate's range), then 5 and 2.5 ms either side of the best.
const LATE_COARSE_S: [f64; 8] = [0.01, 0.02, 0.03, 0.04, 0.05, 0.06, 0.07, 0.08];
const LATE_REFINE_S: [f64; 2] = [0.005, 0.0025];
/// A late reference shows in a log when a car with it (the delay its head fits best) fits the
/// log better than any car's nominal model by more than this (combined GoF): effect-free cars
/// of either drive gain nothing from a delay; a reference 20 ms late costs the nominal model
/// 10 points or more.
const LATE_MARGIN_GOF: f64 = 0.03;

/// Where the drive is fitted, no late reference ranked the cars, and the other drive's best
/// car's nominal GoF on the whole log comes this close to the chosen one's, both are
/// screened by the candidates ([`super::screen`]): a car with an effect can look, to
/// the nominal models, more like the other drive than like its own (friction at the rack,
/// or play and a late reference, on the direct drive look like the EPOS4's latch and
/// interpolation), and an effect's fit lifts a log's GoF by more than a few points.
pub const DRIVE_SCREEN_GOF: f64 = 0.15;

/// The other drive is taken where its best candidate fits the log better than the
/// chosen car's by more than this (GoF on the whole log): more than the spread of two
/// candidates' fits of one effect on one car.
pub const SCREEN_MARGIN_GOF: f64 = 0.02;

/// The best reference delay for the car of `rig` on `rec`, and its GoF.
fn best_late(rig: &Rig, rec: &Record) -> (f64, f64) {
    let gof_at = |d: f64| {
        let fx = Effects {
            delay_s: d,
            ..Effects::nominal()
        };
        fit_with(rig, rec, &fx).gof
    };
    let mut best =
        LATE_COARSE_S
            .iter()
            .map(|&d| (d, gof_at(d)))
            .fold(
                (0.0, f64::NEG_INFINITY),
                |b, x| if x.1 > b.1 { x } else { b },
            );
    for step in LATE_REFINE_S {
        let centre = best.0;
        for d in [centre - step, centre + step] {
            if d > 0.0 {
                let g = gof_at(d);
                if g > best.1 {
                    best = (d, g);
                }
            }
        }
    }
    best
}

/// The fit of the car of `rig` with `fx` on `rec`; a GoF that is not finite (a run that blew
/// up) ranks last.
fn fit_with(rig: &Rig, rec: &Record, fx: &Effects) -> Fit {
    let sim = simulate(rig, rec, fx);
    let fit = Scorer::new(rig, rec).fit(rec, &sim);
    Fit {
        gof: if fit.gof.is_finite() {
            fit.gof
        } else {
            f64::NEG_INFINITY
        },
        ..fit
    }
}

/// The nominal model of `rig` on `rec`, a run that blew up ranking last.
pub(super) fn nominal_fit(rig: &Rig, rec: &Record) -> Fit {
    fit_with(rig, rec, &Effects::nominal())
}

/// The record with its reference column moved `rows` later (the first sample held).
pub fn shifted_reference(rec: &Record, rows: usize) -> Record {
    if rows == 0 || rec.is_empty() {
        return rec.clone();
    }
    Record {
        reference: super::model::held_later(&rec.reference, rows),
        ..rec.clone()
    }
}

/// The first `seconds` of a record.
pub(super) fn head(rec: &Record, seconds: f64) -> Record {
    let n = ((seconds / rec.dt).round() as usize).min(rec.len());
    if n >= rec.len() {
        return rec.clone();
    }
    Record {
        dt: rec.dt,
        reference: rec.reference[..n].to_vec(),
        output: rec.output[..n].to_vec(),
        effort: rec.effort[..n].to_vec(),
        motor: rec.motor.as_ref().map(|m| m[..n].to_vec()),
        disturbance: rec.disturbance.as_ref().map(|d| d[..n].to_vec()),
        supply_v: rec.supply_v.as_ref().map(|s| s[..n].to_vec()),
        powered_from: rec.powered_from.min(n),
        current_chatter: rec.current_chatter,
    }
}

/// What the log's file says of its timing, for [`choose`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LogSays {
    /// The reference convention the header states (`# reference: ...`); `None`: fitted.
    pub reference: Option<ReferenceConvention>,
    /// What the header says the current column holds (`# current: ...`), and so how an
    /// EPOS4 car's samples were read into the rows (`steer-can convert`'s way where it says
    /// anything).
    pub current: Option<CurrentSamples>,
    pub timing: super::LogTiming,
    /// How fast an EPOS4 car's SYNC grid walks against the reference frames, s per s, where
    /// the header says (`# sync-drift:`); the model runs it
    /// ([`super::rig::Epos4Timing::sync_drift`]) where it fits the log better than one phase.
    pub sync_drift: Option<f64>,
    /// Where convert's header says the status frames sampled the column, s before each row's
    /// end (`# column-sampled:`); `None`: the column at the row's end.
    pub column_sampled_s: Option<f64>,
}

/// The car for a log on the paper rig: `drive` and `controller` where given (the command line
/// or the header), the rest fitted; and, for a log whose header does not say how its
/// reference column is timed, that convention: at the reference rate, and at several rows a
/// period where the loader read the log both ways (`by_convention`). Where the drive is
/// fitted and the two drives' nominal models come close, their candidates tell them apart
/// ([`DriveScreen`], fitted with `opts`' candidates and threads). Returns the rig with that
/// car in its model and the record as the diagnosis must read it. Other rigs are returned as
/// they are, with `None`.
pub fn choose(
    rig: &Rig,
    rec: &Record,
    by_convention: Option<&[Record; 2]>,
    drive: Option<(CarDrive, Source)>,
    controller: Option<(Controller, Source)>,
    says: LogSays,
    opts: &super::Options,
) -> (Rig, Record, Option<CarChoice>) {
    let threads = opts.threads;
    if !matches!(rig.model, RigModel::Paper(_)) {
        return (rig.clone(), rec.clone(), None);
    }
    // Convert's column: a line between the status frames' samples, where its header places
    // them (else the column at the row's end, as a log from before that line was written).
    let mut with_column = rig.clone();
    let mut stated = Epos4Readout::CONVERT;
    if let RigModel::Paper(m) = &mut with_column.model {
        m.epos4.readout.column_age_s = says.column_sampled_s.unwrap_or(0.0);
        stated = m.epos4.readout;
        // The same line places the ECU's encoder task, whose samples ECU mode's column terms
        // take: every car tried runs it there (the paper controller does not read it).
        m.epos4.encoder_phase_s = drive_clock::encoder_phase_of(&stated).unwrap_or(0.0);
    }
    let rig = &with_column;
    // A current of instantaneous samples of the loop's chatter: the car is fitted on the
    // column and the motor angle, and the diagnosis weighs the current as noise (the record
    // returned carries it).
    let mut chatter = super::chatter::read(
        rig,
        rec,
        says.current.map(|c| c == CurrentSamples::Instantaneous),
    );
    let mut by_angles = rec.clone();
    by_angles.current_chatter = chatter.is_some();
    let rec = &by_angles;
    let drives: Vec<CarDrive> = match (drive, &mut chatter) {
        (Some((d, _)), _) => vec![d],
        // Found by its scatter, the current is no EPOS4's; a header's word that the samples
        // are instants says nothing of how much they chatter.
        (None, Some(c)) if !c.stated => {
            c.epos4_left_out = true;
            vec![CarDrive::Direct]
        }
        (None, _) => vec![CarDrive::Epos4, CarDrive::Direct],
    };
    let controllers: Vec<Controller> = match controller {
        Some((c, _)) => vec![c],
        None => vec![Controller::Paper, Controller::Ecu],
    };
    // At the reference rate the two conventions are one row apart; at 200 Hz and faster the
    // rows resolve the reference's steps and the binning places them.
    let row_dt = says.timing.row_dt_s;
    let at_reference_rate = row_dt > 0.75 * rec.dt && row_dt < 1.5 * rec.dt;
    // A convention the header states is taken; a row holding the reference that starts there
    // is the next period's, one row later than ours.
    // Faster, rows on the periods' boundaries leave the convention to the car too: the log
    // read each way (`by_convention`, the loader's), a row apart.
    let placed = by_convention.filter(|_| says.reference.is_none() && !at_reference_rate);
    let shifts: Vec<usize> = match (says.reference, at_reference_rate) {
        (None, true) => vec![0, 1],
        (Some(ReferenceConvention::PeriodStarting), true) => vec![1],
        _ if placed.is_some() => vec![0, 1],
        _ => vec![0],
    };
    let records: Vec<Record> = match placed {
        Some(both) => both
            .iter()
            .map(|r| Record {
                current_chatter: rec.current_chatter,
                ..r.clone()
            })
            .collect(),
        None => shifts.iter().map(|&k| shifted_reference(rec, k)).collect(),
    };
    let shorts: Vec<Record> = records.iter().map(|r| head(r, SYNC_SEARCH_S)).collect();
    type Job = (CarDrive, Controller, f64, usize);
    let mut jobs: Vec<Job> = Vec::new();
    for &d in &drives {
        for &c in &controllers {
            for &k in &shifts {
                match d {
                    CarDrive::Direct => jobs.extend(
                        PUSH_TICKS
                            .iter()
                            .map(|&t| (d, c, f64::from(t) * POSITION_TICK_S, k)),
                    ),
                    CarDrive::Epos4 => jobs.extend(SYNC_COARSE_S.iter().map(|&s| (d, c, s, k))),
                }
            }
        }
    }
    let index_of = |k: usize| shifts.iter().position(|x| *x == k).unwrap_or(0);
    let run = |jobs: &[Job], on: &[Record]| -> Vec<Tried> {
        parallel_map(jobs, threads, |&(d, c, s, k)| {
            let fit = nominal_fit(&with_car(rig, d, c, s), &on[index_of(k)]);
            Tried {
                drive: d,
                controller: c,
                sync_after_push_s: (d == CarDrive::Epos4).then_some(s),
                push_after_s: (d == CarDrive::Direct).then_some(s),
                sync_drift: None,
                reference_shift_rows: k,
                gof: fit.gof,
                readout: None,
                position_phase_ticks: None,
                encoder_phase_s: None,
            }
        })
    };
    let coarse = run(&jobs, &shorts);
    let best_coarse = coarse
        .iter()
        .map(|t| t.gof)
        .fold(f64::NEG_INFINITY, f64::max);
    let rig_of = |t: &Tried| {
        let mut r = with_car(
            rig,
            t.drive,
            t.controller,
            t.sync_after_push_s.or(t.push_after_s).unwrap_or(0.0),
        );
        if let RigModel::Paper(m) = &mut r.model {
            if let Some(readout) = t.readout {
                m.epos4.readout = readout;
            }
            m.epos4.position_phase_ticks = t.position_phase_ticks.unwrap_or(0);
            if let Some(e) = t.encoder_phase_s {
                m.epos4.encoder_phase_s = e;
            }
            m.epos4.sync_drift = t.sync_drift.unwrap_or(0.0);
            m.epos4.clock_from_nominal =
                t.position_phase_ticks.is_some() && m.epos4.sync_drift == 0.0;
        }
        r
    };
    // The best phase of each EPOS4 car, refined around its best millisecond.
    let mut best_of_car: Vec<Tried> = Vec::new();
    for &d in &drives {
        for &c in &controllers {
            for &k in &shifts {
                let Some(best) = coarse
                    .iter()
                    .filter(|t| t.drive == d && t.controller == c && t.reference_shift_rows == k)
                    .max_by(|a, b| a.gof.total_cmp(&b.gof))
                    .copied()
                else {
                    continue;
                };
                // Only an EPOS4 car is pruned (its phase's refinement is what costs): a
                // direct-drive car far below is still compared with its reference late.
                if best.sync_after_push_s.is_some() && best.gof < best_coarse - PRUNE_GOF {
                    continue;
                }
                let best = match best.sync_after_push_s {
                    Some(s) => {
                        let fine: Vec<Job> = (-SYNC_FINE_STEPS..=SYNC_FINE_STEPS)
                            .filter(|j| *j != 0)
                            .map(|j| s + f64::from(j) * SYNC_FINE_STEP_S)
                            .filter(|x| *x > 0.0 && *x <= 0.010 + 1e-9)
                            .map(|x| (d, c, x, k))
                            .collect();
                        run(&fine, &shorts)
                            .into_iter()
                            .chain(std::iter::once(best))
                            .max_by(|a, b| a.gof.total_cmp(&b.gof))
                            .unwrap_or(best)
                    }
                    None => best,
                };
                // A log that does not say how it read an EPOS4 car's samples: the readout,
                // fitted with the phase, before the cars are compared (a stale column read as
                // convert's looks like a late reference, which the direct drive then fits).
                let best = match best.sync_after_push_s {
                    Some(s) if says.current.is_none() => {
                        let (fitted, readout) =
                            fit_readout(&with_car(rig, d, c, s), &shorts[index_of(k)], threads);
                        Tried {
                            sync_after_push_s: Some(sync_of(&fitted)),
                            readout: Some(readout),
                            ..best
                        }
                    }
                    _ => best,
                };
                // The drive's own clock on convert's log: where its position loop ticks
                // against the SYNC. (On a log whose readout was fitted, see `gap/NOTES.md`.)
                let readout = best.readout.unwrap_or(stated);
                let best = match best.sync_after_push_s {
                    Some(s) if readout.column_interpolated => {
                        let car = with_readout(&with_car(rig, d, c, s), s, readout);
                        // Under the ECU controller, its encoder's phase: convert's header says.
                        let encoder = drive_clock::encoder_phase_of(&readout)
                            .filter(|_| c == Controller::Ecu);
                        match drive_clock::fit(
                            &car,
                            &shorts[index_of(k)],
                            s,
                            &Effects::nominal(),
                            threads,
                        ) {
                            Some(f) => Tried {
                                sync_after_push_s: Some(f.sync_after_push_s),
                                position_phase_ticks: Some(f.position_phase_ticks),
                                encoder_phase_s: encoder,
                                readout: Some(readout),
                                gof: f.gof,
                                ..best
                            },
                            None => best,
                        }
                    }
                    _ => best,
                };
                best_of_car.push(best);
            }
        }
    }
    // ECU mode's column terms read the ECU's newest encoder sample: when its task samples is
    // the car's too. Where the header does not say, fitted on the whole log at the clock found
    // (a track's first 10 s chose the phase unreliably: on the simulated car's track 0 ms, on
    // the whole log 1.25 ms). Its phases are tried on the head first: the best of them bounds
    // the car's head GoF at any phase, and a car that stays ENCODER_REACH_GOF below the best
    // car's there keeps the head's phase.
    let best_head = best_of_car
        .iter()
        .map(|t| t.gof)
        .fold(f64::NEG_INFINITY, f64::max);
    for best in best_of_car.iter_mut() {
        if best.encoder_phase_s.is_some() {
            continue;
        }
        let k = best.reference_shift_rows;
        let car = rig_of(best);
        let Some((on_head, head_gof)) =
            drive_clock::fit_encoder_phase(&car, &shorts[index_of(k)], threads)
        else {
            continue;
        };
        let whole_log = (head_gof >= best_head - ENCODER_REACH_GOF)
            .then(|| drive_clock::fit_encoder_phase(&car, &records[index_of(k)], threads))
            .flatten()
            .map(|(phase, _)| phase);
        // The car's figure on the head as every other car's is (`best_nominal` and the late
        // reference compare them): the head's scan ran it at the head's phase.
        *best = match whole_log.filter(|&phase| phase != on_head) {
            Some(phase) => {
                let at_phase = Tried {
                    encoder_phase_s: Some(phase),
                    ..*best
                };
                Tried {
                    gof: nominal_fit(&rig_of(&at_phase), &shorts[index_of(k)]).gof,
                    ..at_phase
                }
            }
            None => Tried {
                encoder_phase_s: Some(on_head),
                gof: head_gof,
                ..*best
            },
        };
    }
    // The cars compared on the whole log; an EPOS4 car also with its SYNC grid walking as the
    // header says, where that fits the log better.
    let whole = parallel_map(&best_of_car, threads, |t| {
        let on = &records[index_of(t.reference_shift_rows)];
        let one_phase = Tried {
            gof: nominal_fit(&rig_of(t), on).gof,
            ..*t
        };
        match (says.sync_drift, t.sync_after_push_s) {
            (Some(d), Some(phase)) if t.drive == CarDrive::Epos4 && d != 0.0 => {
                let walking = drifting(one_phase, phase, d, on.len() as f64 * on.dt);
                let walking = Tried {
                    gof: nominal_fit(&rig_of(&walking), on).gof,
                    ..walking
                };
                if walking.gof > one_phase.gof {
                    walking
                } else {
                    one_phase
                }
            }
            _ => one_phase,
        }
    });
    // A reference that reaches the ECU late looks, to a car's nominal model, much like the
    // EPOS4's latch at its SYNC and its interpolation over the period: a direct-drive car 40 ms
    // late is better fitted by the EPOS4's nominal model than by its own, and the diagnosis
    // then runs the wrong car and calls the log `parameters`. So each car is also run with
    // its reference late: the delay fitted on the head of the log, the car then run with it
    // on the whole log. Where a car with it beats every car's nominal model on the whole log
    // by more than LATE_MARGIN_GOF, the log has a late reference and the cars are compared
    // with it. (The head of a track may hold little of its motion: a direct-drive car 40 ms
    // late, logged without a header, gained 1.8 points on its first 10 s and 7 on the whole
    // 120 s, where the EPOS4's nominal model fitted 11 points better than its own.)
    // With one car left (drive and controller given) there is nothing for it to rank.
    let several_cars = best_of_car
        .iter()
        .any(|t| (t.drive, t.controller) != (best_of_car[0].drive, best_of_car[0].controller));
    let late: Vec<(f64, f64)> = if several_cars {
        let cars: Vec<usize> = (0..best_of_car.len()).collect();
        parallel_map(&cars, threads, |&i| {
            let t = &best_of_car[i];
            let (delay_s, _) = best_late(&rig_of(t), &shorts[index_of(t.reference_shift_rows)]);
            let fx = Effects {
                delay_s,
                ..Effects::nominal()
            };
            let on = &records[index_of(t.reference_shift_rows)];
            (delay_s, fit_with(&rig_of(&whole[i]), on, &fx).gof)
        })
    } else {
        Vec::new()
    };
    // Shown when it fits the log better than every car's nominal model on either convention
    // (at the reference rate a reference one row late is the other convention, no late
    // reference; and a car far off the log gains from anything).
    let best_nominal = whole
        .iter()
        .map(|t| t.gof)
        .fold(f64::NEG_INFINITY, f64::max);
    let late_shows = late
        .iter()
        .any(|&(_, gof)| gof - best_nominal > LATE_MARGIN_GOF);
    let mut order: Vec<usize> = (0..whole.len()).collect();
    let key = |i: usize| if late_shows { late[i].1 } else { whole[i].gof };
    order.sort_by(|&a, &b| key(b).total_cmp(&key(a)));
    // The late reference picks the drive and the controller only. At the reference rate a
    // reference one row late is the other convention, and a delay scan fits either: the
    // convention (and an EPOS4's phase) of that car is the one its nominal model fits best.
    if let Some(&lead) = order.first() {
        let same_car = |i: usize| {
            whole[i].drive == whole[lead].drive && whole[i].controller == whole[lead].controller
        };
        if let Some(pos) = (0..order.len())
            .filter(|&p| same_car(order[p]))
            .max_by(|&a, &b| whole[order[a]].gof.total_cmp(&whole[order[b]].gof))
        {
            let pick = order.remove(pos);
            order.insert(0, pick);
        }
    }
    if order.is_empty() {
        return (rig.clone(), rec.clone(), None);
    }
    let fitted_convention = shifts.len() > 1;
    // What the log's timing can explain: three times its stamps' jitter, and one row more when
    // its reference convention is fitted rather than stated (a late reference and a logger
    // that writes it a row early are one row apart).
    let timing_bound_s = 3.0 * says.timing.jitter_s + if fitted_convention { row_dt } else { 0.0 };
    // The car `order[0]`, the others ranked after it: its rig, the record as it reads it, and
    // the choice as reported.
    let finish = |order: &[usize]| -> (Rig, Record, CarChoice) {
        let tried: Vec<Tried> = order.iter().map(|&i| whole[i]).collect();
        let best = tried[0];
        let compared_late = late_shows.then(|| LateComparison {
            delay_s: late[order[0]].0,
            gof: whole[order[0]].gof,
            gof_late: late[order[0]].1,
        });
        let choice = CarChoice {
            drive: best.drive,
            controller: best.controller,
            drive_from: drive.map_or(Source::Fitted, |(_, s)| s),
            controller_from: controller.map_or(Source::Fitted, |(_, s)| s),
            sync_after_push_s: best.sync_after_push_s,
            push_after_s: best.push_after_s,
            sync_drift: best.sync_drift,
            header_sync_drift: says.sync_drift.filter(|_| best.drive == CarDrive::Epos4),
            reference_shift_rows: fitted_convention.then_some(best.reference_shift_rows),
            timing_bound_s,
            compared_late,
            tried,
            readout: best.readout,
            position_phase_ticks: best.position_phase_ticks,
            encoder_phase_s: best.encoder_phase_s,
            clock_refitted: None,
            reference_windows: Vec::new(),
            screened: None,
            current_chatter: chatter,
            columns: None,
        };
        let mut chosen = rig_of(&best);
        if let RigModel::Paper(m) = &mut chosen.model {
            m.timing_bound_s = timing_bound_s;
        }
        let record = records[index_of(best.reference_shift_rows)].clone();
        // Where the SYNC walked through the frames, the column is a row off the drive's target
        // for a stretch.
        let (record, reference_windows) = if choice.may_lead_the_latch() {
            reference_window::fit(&chosen, &record, threads)
        } else {
            (record, Vec::new())
        };
        let choice = CarChoice {
            reference_windows,
            ..choice
        };
        (chosen, record, choice)
    };
    let first = finish(&order);
    // The other drive's best car, where the drive is the log's to say and its nominal model
    // came close. Not where a late reference ranked the cars: that comparison already ran
    // each with an effect, the one a single candidate's screen would leave out (and the
    // EPOS4's latch stands in for a late reference beside any one effect).
    // On a current of the loop's chatter (the EPOS4 left out or the drive given) the cars'
    // nominal models cannot tell a reference convention from play or a tyre that holds the
    // column back: the other convention's best car is the rival, told apart the same way.
    let by_convention = chatter.is_some() && fitted_convention;
    let rival = order
        .iter()
        .position(|&i| {
            if by_convention {
                whole[i].reference_shift_rows != whole[order[0]].reference_shift_rows
            } else {
                whole[i].drive != whole[order[0]].drive
            }
        })
        .filter(|&p| {
            (drive.is_none() || by_convention)
                && !late_shows
                && whole[order[0]].gof - whole[order[p]].gof < DRIVE_SCREEN_GOF
        });
    let Some(p) = rival else {
        return (first.0, first.1, Some(first.2));
    };
    let mut other_order = order.clone();
    let pick = other_order.remove(p);
    other_order.insert(0, pick);
    let second = finish(&other_order);
    // The other car first: where its best candidate does not beat the chosen car's nominal
    // model by the margin, it cannot beat the chosen car's best, which is not fitted.
    // Two drives' cars are screened with a late reference beside their best effect too: the
    // EPOS4's latch at a late SYNC, its column read old, stands in for a direct car's late
    // reference beside any one effect, which the direct car's single candidates cannot match.
    // Two conventions a row apart are told apart without it: it would stand in for the row.
    let late = !by_convention;
    let other = super::screen(&second.0, &second.1, opts, late);
    let nominal = nominal_fit(&first.0, &first.1).gof;
    let own = (other.gof() > nominal + SCREEN_MARGIN_GOF)
        .then(|| super::screen(&first.0, &first.1, opts, late));
    let switched = own
        .as_ref()
        .is_some_and(|s| other.gof() > s.gof() + SCREEN_MARGIN_GOF);
    let car = |c: &CarChoice, nominal_gof: f64, s: Option<&super::Screen>| ScreenedCar {
        drive: c.drive,
        controller: c.controller,
        reference_shift_rows: c.reference_shift_rows,
        nominal_gof,
        best_effect: s.and_then(|s| s.best.as_ref().map(|(e, _)| e.clone())),
        best_gof: s.map(super::Screen::gof),
    };
    let screened = DriveScreen {
        by_convention,
        cars: [
            car(&first.2, nominal, own.as_ref()),
            car(&second.2, other.nominal_gof, Some(&other)),
        ],
        switched,
    };
    let (rig, record, choice) = if switched { second } else { first };
    let choice = CarChoice {
        screened: Some(screened),
        ..choice
    };
    (rig, record, Some(choice))
}

/// `car` (an EPOS4 car whose SYNC phase `phase` was fitted on the head of the log) with its
/// SYNC grid walking `drift` s per s over a log of `duration` s: the head's phase holds at
/// the middle of the head, where it was fitted, so the phase at the log's start is that less
/// the walk to there, within a period.
fn drifting(car: Tried, phase: f64, drift: f64, duration: f64) -> Tried {
    let period = 1.0 / steering_ecu::paper_mode::REFERENCE_HZ as f64;
    let middle = 0.5 * duration.min(SYNC_SEARCH_S);
    let tick = SYNC_FINE_STEP_S;
    // Convert's column samples walk with the SYNCs, earlier against each row's end: the
    // header's place (read over the same head) at the log's start.
    let readout = car.readout.map(|r| Epos4Readout {
        column_age_s: if r.column_interpolated && r.column_age_s > 0.0 {
            (r.column_age_s + drift * middle).rem_euclid(period)
        } else {
            r.column_age_s
        },
        ..r
    });
    Tried {
        sync_after_push_s: Some((phase - drift * middle - tick).rem_euclid(period) + tick),
        sync_drift: Some(drift),
        readout,
        ..car
    }
}

fn sync_of(rig: &Rig) -> f64 {
    match &rig.model {
        RigModel::Paper(m) => m.epos4.sync_after_push_s,
        _ => 0.0,
    }
}

/// Column ages tried on an EPOS4 log that does not say how it read the drive, s: every
/// millisecond up to a period and an encoder tick (a logger that holds the ECU's last status
/// frame), then every quarter millisecond within a millisecond of the best.
const COLUMN_AGE_COARSE_S: f64 = 1e-3;
const COLUMN_AGE_MAX_S: f64 = 0.012;
const COLUMN_AGE_FINE_S: f64 = 2.5e-4;
/// Where in the row the current is read: the middle of its period (convert's interpolation)
/// or its end (a row per TPDO, the current the drive sampled at that SYNC).
const CURRENT_AT_ROW: [f64; 2] = [0.5, 1.0];

/// How much older the log's column is than its motor angle, s, read from the motor ->
/// steering segment alone (the nominal chain driven by the logged motor angle,
/// [`super::model::replay_downstream`]): where the column moves, the logged column against the
/// replayed one as `column = replay - a w + h sgn(w) + c`. A stale column trails by `a w`;
/// play in the belt, or the stretch a load puts in it, sits `h` to either side whatever the
/// speed, and a sweep's or a track's speeds tell the two apart. The closed loop's fit cannot:
/// there an effect that lags the column (play) is soaked up by the age. `None` without a
/// motor angle or where the fit is singular; within `[0, COLUMN_AGE_MAX_S]`.
fn column_age_from_motor(rig: &Rig, rec: &Record) -> Option<f64> {
    let RigModel::Paper(m) = &rig.model else {
        return None;
    };
    let replay = super::model::replay_downstream(m, rec, &Effects::nominal())?;
    let n = replay.len().min(rec.output.len());
    if n < 20 {
        return None;
    }
    let w: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (replay[b] - replay[a]) / ((b - a).max(1) as f64 * rec.dt)
        })
        .collect();
    let mut speeds: Vec<f64> = w
        .iter()
        .map(|v| v.abs())
        .filter(|v| v.is_finite())
        .collect();
    speeds.sort_by(f64::total_cmp);
    let fast = 0.2 * speeds.get(speeds.len() * 9 / 10).copied()?;
    let rows: Vec<usize> = (1..n - 1)
        .filter(|&k| w[k].abs() > fast && rec.output[k].is_finite() && replay[k].is_finite())
        .collect();
    if rows.len() < 10 {
        return None;
    }
    let acc: Vec<f64> = (0..n)
        .map(|k| {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            (w[b] - w[a]) / ((b - a).max(1) as f64 * rec.dt)
        })
        .collect();
    let x = nalgebra::DMatrix::from_fn(rows.len(), 5, |i, j| {
        let k = rows[i];
        match j {
            0 => -w[k],
            1 => w[k].signum(),
            2 => replay[k],
            3 => acc[k],
            _ => 1.0,
        }
    });
    let y = nalgebra::DVector::from_fn(rows.len(), |i, _| rec.output[rows[i]] - replay[rows[i]]);
    let coef = (x.transpose() * &x).try_inverse()? * x.transpose() * y;
    let age = coef[0];
    age.is_finite().then(|| age.clamp(0.0, COLUMN_AGE_MAX_S))
}

/// The readout of an EPOS4 log whose header does not state it ([`Epos4Readout`]), fitted on
/// `head`: the column's age from the motor -> steering segment ([`column_age_from_motor`]),
/// and the current's place in the row with the nominal model jointly with the SYNC phase
/// (the phase was first fitted under convert's readout, and a current read at the row's end
/// with the SYNC late in the period looks much like one read at its middle with the SYNC
/// earlier): every millisecond of phase, each with both places (one run of the model serves
/// them all), then every tick near the best. A log without a motor angle has the age fitted
/// in the loop too, every millisecond and then every quarter near the best.
fn fit_readout(rig: &Rig, head: &Record, threads: usize) -> (Rig, Epos4Readout) {
    let RigModel::Paper(model) = &rig.model else {
        return (rig.clone(), Epos4Readout::CONVERT);
    };
    let ages = |from: f64, to: f64, step: f64| -> Vec<f64> {
        let n = ((to - from) / step).round().max(0.0) as usize;
        (0..=n)
            .map(|i| from + i as f64 * step)
            .filter(|a| *a >= 0.0 && *a <= COLUMN_AGE_MAX_S + 1e-9)
            .collect()
    };
    // The column's age from the motor -> steering segment where the log has a motor angle;
    // else every millisecond of it in the closed loop's fit.
    let age = column_age_from_motor(rig, head);
    let coarse_ages = match age {
        Some(a) => vec![a],
        None => ages(0.0, COLUMN_AGE_MAX_S, COLUMN_AGE_COARSE_S),
    };
    let coarse: Vec<Epos4Readout> = CURRENT_AT_ROW
        .iter()
        .flat_map(|&c| {
            coarse_ages.iter().map(move |&a| Epos4Readout {
                current_at_row: c,
                column_age_s: a,
                column_interpolated: false,
            })
        })
        .collect();
    let scorer = Scorer::new(rig, head);
    // The best of `readouts` with the SYNC at `sync`, and its GoF.
    let best_at = |sync: f64, readouts: &[Epos4Readout]| -> (f64, Epos4Readout, f64) {
        let mut m = model.clone();
        m.epos4.sync_after_push_s = sync;
        let samples = super::model::epos4_samples(&m, head, &Effects::nominal());
        readouts
            .iter()
            .map(|&r| {
                let g = scorer.fit(head, &samples.read(r)).gof;
                (sync, r, if g.is_finite() { g } else { f64::NEG_INFINITY })
            })
            .max_by(|a, b| a.2.total_cmp(&b.2))
            .unwrap_or((sync, Epos4Readout::CONVERT, f64::NEG_INFINITY))
    };
    let best_of = |found: Vec<(f64, Epos4Readout, f64)>| {
        found
            .into_iter()
            .max_by(|a, b| a.2.total_cmp(&b.2))
            .unwrap_or((
                model.epos4.sync_after_push_s,
                Epos4Readout::CONVERT,
                f64::NEG_INFINITY,
            ))
    };
    let (sync, _, _) = best_of(parallel_map(&SYNC_COARSE_S, threads, |&s| {
        best_at(s, &coarse)
    }));
    let fine: Vec<f64> = (-SYNC_FINE_STEPS..=SYNC_FINE_STEPS)
        .map(|j| sync + f64::from(j) * SYNC_FINE_STEP_S)
        .filter(|x| *x > 0.0 && *x <= 0.010 + 1e-9)
        .collect();
    let (sync, r, _) = best_of(parallel_map(&fine, threads, |&s| best_at(s, &coarse)));
    // The segment's reading stands: refined in the closed loop, even within 1.5 ms, the age
    // ran to where play or a tyre lags the column (1.5 deg of play then read as a tyre).
    // Without it, the age to a quarter millisecond near the best millisecond.
    if age.is_some() {
        return (with_readout(rig, sync, r), r);
    }
    let ages_fine: Vec<Epos4Readout> = ages(
        r.column_age_s - COLUMN_AGE_COARSE_S,
        r.column_age_s + COLUMN_AGE_COARSE_S,
        COLUMN_AGE_FINE_S,
    )
    .into_iter()
    .map(|a| Epos4Readout {
        column_age_s: a,
        ..r
    })
    .collect();
    let (sync, r, _) = best_at(sync, &ages_fine);
    (with_readout(rig, sync, r), r)
}

/// `rig` with its EPOS4 model's SYNC phase at `sync` (s) and its readout `readout`.
fn with_readout(rig: &Rig, sync: f64, readout: Epos4Readout) -> Rig {
    let mut chosen = rig.clone();
    if let RigModel::Paper(m) = &mut chosen.model {
        m.epos4.sync_after_push_s = sync;
        m.epos4.readout = readout;
    }
    chosen
}

/// The car for a log as `host-sim gap` takes it: a `drive` or `controller` given (the command
/// line) wins over the log's header lines; what neither says, and the reference convention a
/// header does not state, is fitted ([`choose`]).
pub fn choose_for_log(
    rig: &Rig,
    loaded: &super::rig::LoadedLog,
    header: &LogHeader,
    drive: Option<CarDrive>,
    controller: Option<Controller>,
    opts: &super::Options,
) -> (Rig, Record, Option<CarChoice>) {
    let drive = match drive {
        Some(d) => Some((d, Source::Option)),
        None => header.drive.map(|d| (d, Source::Header)),
    };
    let controller = match controller {
        Some(c) => Some((c, Source::Option)),
        None => header.controller.map(|c| (c, Source::Header)),
    };
    let (rec, by_convention) = (&loaded.record, loaded.by_convention.as_ref());
    let says = LogSays {
        reference: header.reference,
        current: header.current,
        timing: loaded.timing,
        sync_drift: header.sync_drift,
        column_sampled_s: header.column_sampled_s,
    };
    // A column the logger wrote with the other sign: read as the car has it, before the car
    // is fitted on it.
    let Some(signs) = super::columns::read(rig, rec) else {
        return choose(rig, rec, by_convention, drive, controller, says, opts);
    };
    let read = signs.any().then(|| signs.apply(rec));
    let placed = by_convention
        .filter(|_| signs.any())
        .map(|both| both.each_ref().map(|r| signs.apply(r)));
    match choose(
        rig,
        read.as_ref().unwrap_or(rec),
        placed.as_ref().or(by_convention),
        drive,
        controller,
        says,
        opts,
    ) {
        (rig, rec, Some(choice)) => (
            rig,
            rec,
            Some(CarChoice {
                columns: Some(signs),
                ..choice
            }),
        ),
        // No car to report it on: the log as logged, as `choose` leaves it.
        (rig, _, None) => (rig, rec.clone(), None),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn push_tick_of(phase: f64) -> u32 {
        match with_car(&Rig::paper(), CarDrive::Direct, Controller::Ecu, phase).model {
            RigModel::Paper(m) => m.push_tick,
            _ => unreachable!("the paper rig"),
        }
    }

    #[test]
    fn a_direct_cars_phase_is_a_whole_position_tick_within_the_fitted_range() {
        assert_eq!(push_tick_of(0.0), 0);
        assert_eq!(push_tick_of(0.0005), 1);
        assert_eq!(push_tick_of(0.0007), 1);
        assert_eq!(push_tick_of(0.001), 2);
        // Beyond the range, or no number: the nearest end.
        assert_eq!(push_tick_of(0.004), 2);
        assert_eq!(push_tick_of(-0.001), 0);
        assert_eq!(push_tick_of(f64::NAN), 0);
        assert_eq!(push_tick_of(f64::INFINITY), 2);
    }

    fn header(line: &str) -> Result<LogHeader, String> {
        LogHeader::parse(&[line.to_string()])
    }

    #[test]
    fn a_headers_sync_drift_is_read_in_parts_per_million() {
        let d = header("sync-drift: +35.2 ppm").unwrap().sync_drift.unwrap();
        assert!((d - 35.2e-6).abs() < 1e-12, "{d}");
        let d = header("sync-drift: -91ppm").unwrap().sync_drift.unwrap();
        assert!((d + 91e-6).abs() < 1e-12, "{d}");
        assert_eq!(header("drive: epos4").unwrap().sync_drift, None);
    }

    #[test]
    fn where_convert_sampled_the_column_is_read_in_milliseconds_and_a_bad_value_refused() {
        let at = header("column-sampled: 2.31 ms before each row's end")
            .unwrap()
            .column_sampled_s
            .unwrap();
        assert!((at - 2.31e-3).abs() < 1e-12, "{at}");
        assert_eq!(header("drive: epos4").unwrap().column_sampled_s, None);
        assert_refused(
            &[
                "column-sampled: 2.31",
                "column-sampled: soon ms before each row's end",
                "column-sampled: -0.5 ms before each row's end",
                "column-sampled: 10.5 ms before each row's end",
                "column-sampled: nan ms before each row's end",
                "column-sampled: inf ms before each row's end",
            ],
            "milliseconds",
        );
    }

    /// Each of `bad` is refused with a message that names `expected`.
    fn assert_refused(bad: &[&str], expected: &str) {
        for line in bad {
            let e = header(line).unwrap_err();
            assert!(e.contains(expected), "{line}: {e}");
        }
    }

    #[test]
    fn a_current_or_a_reference_convention_the_reader_does_not_know_is_refused() {
        for kind in CurrentSamples::ALL {
            let h = header(&format!("current: {}", kind.name())).unwrap();
            assert_eq!(h.current, Some(kind));
        }
        for convention in ReferenceConvention::ALL {
            let h = header(&format!("reference: {}", convention.name())).unwrap();
            assert_eq!(h.reference, Some(convention));
        }
        assert_refused(
            &["current: peak", "current: mean", "current: "],
            "expected `interval-mean`, `sync-sample` or `instantaneous`",
        );
        assert_refused(
            &["reference: sideways", "reference: starting", "reference: "],
            "expected `period-ending`",
        );
    }

    #[test]
    fn a_sync_drift_that_is_no_number_or_beyond_one_percent_is_refused() {
        assert_refused(
            &[
                "sync-drift: fast",
                "sync-drift: 35.2",
                "sync-drift: nan ppm",
                "sync-drift: inf ppm",
                "sync-drift: 20000 ppm",
                "sync-drift:  ppm",
            ],
            "parts per million",
        );
    }

    #[test]
    fn an_epos4_cars_phase_is_its_sync_and_leaves_the_push_tick() {
        let r = with_car(&Rig::paper(), CarDrive::Epos4, Controller::Paper, 0.004);
        let RigModel::Paper(m) = r.model else {
            unreachable!("the paper rig")
        };
        assert_eq!(m.epos4.sync_after_push_s, 0.004);
        assert_eq!(m.push_tick, 0);
    }
}

//! An EPOS4 car's own clock against a log that `steer-can convert` wrote, fitted on the head of
//! the log once its SYNC phase is: where the drive's 2 kHz position loop ticks against the
//! SYNC. (Where the ECU's status frames sampled the column, which convert reads the column
//! off, is the log's header's: `# column-sampled:`.) A log whose readout is fitted
//! (a team's logger without a header) is left as it was: there the readout's own fit already
//! trades against the SYNC, and the phase fitted beside it lost verdicts on the world's EPOS4
//! car (a row per TPDO 36 -> 34 of the first 40, on a drifting clock 34 -> 31; gap/NOTES.md,
//! "Two leads measured and dropped").
//!
//! Both are the car's, not the model's: the drive runs its loops on its own clock, so a target
//! latched at a SYNC first moves the motor at the drive's next position tick, anywhere up to
//! 0.5 ms later; and the ECU's status frames (one a period, each with the column the encoder
//! read one encoder period before) sit wherever the ECU's clock put them against the
//! reference, while convert reads the column at each row's end off a line between them. On
//! the simulated EPOS4 car's effect-free sweep, a model that took neither (the position loop
//! on the row grid, the column at the row's end) left 1.1 % of GoF against 0.2 % that the car
//! does not repeat itself by (gap/NOTES.md, "The EPOS4 car's clock and convert's column").
//!
//! The clock is fitted when the car is chosen, before any effect; [`with_best`] fits it again
//! with the diagnosis's best single candidate in the model, where that candidate is large.

use super::drive::{SYNC_SEARCH_S, head};
use super::model::{Effects, simulate_epos4};
use super::rig::{CarDrive, Rig, RigModel};
use super::{Candidate, Record, Scorer, parallel_map};
use crate::sim::Controller;
use steering_ecu::paper_mode::{CURRENT_LOOP_HZ, CURRENT_TICKS_PER_POSITION_TICK, REFERENCE_HZ};

/// One current-loop tick, s: the grid of the SYNC, the position loop and the column's samples.
const TICK_S: f64 = 1.0 / CURRENT_LOOP_HZ as f64;
/// The SYNC is refined again with the position loop's phase, this many ticks either side.
const SYNC_STEPS: i32 = 10;

/// What [`fit`] found: the SYNC phase, the position loop's phase (ticks) and the GoF on the
/// head.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DriveClock {
    pub sync_after_push_s: f64,
    pub position_phase_ticks: u32,
    pub gof: f64,
    /// The simulations the fit ran.
    pub simulations: usize,
}

/// The drive's clock of the EPOS4 car `rig` (its readout as the log states it) with the
/// effects `fx` on `head`, from its SYNC phase `sync`: every position-loop phase at that SYNC,
/// then the SYNC again, every tick within half a millisecond, at the best phase. `None` on
/// another rig.
pub fn fit(
    rig: &Rig,
    head: &Record,
    sync: f64,
    fx: &Effects,
    threads: usize,
) -> Option<DriveClock> {
    let RigModel::Paper(model) = &rig.model else {
        return None;
    };
    let scorer = Scorer::new(rig, head);
    let period = 1.0 / REFERENCE_HZ as f64;
    let run = |sync: f64, phase: u32| -> DriveClock {
        let mut m = model.clone();
        m.epos4.sync_after_push_s = sync;
        m.epos4.position_phase_ticks = phase;
        let g = scorer.fit(head, &simulate_epos4(&m, head, fx)).gof;
        DriveClock {
            sync_after_push_s: sync,
            position_phase_ticks: phase,
            gof: if g.is_finite() { g } else { f64::NEG_INFINITY },
            simulations: 0,
        }
    };
    let best = |found: Vec<DriveClock>| found.into_iter().max_by(|a, b| a.gof.total_cmp(&b.gof));
    // The phase is searched as the ticks from the SYNC to the drive's next position tick, and
    // moves with the SYNC when that is refined: what the log shows of the two is the SYNC's
    // instant (the current's sample) and how long a latched target waits for the loop.
    let per = CURRENT_TICKS_PER_POSITION_TICK;
    let phase_after = |sync: f64, wait: u32| -> u32 {
        // `as` saturates a negative or NaN phase to tick 0.
        let tick = (sync / TICK_S).round() as u64;
        ((tick + u64::from(wait)) % u64::from(per)) as u32
    };
    let waits: Vec<u32> = (0..per).collect();
    let scan_waits = |sync: f64| {
        parallel_map(&waits, threads, |&w| (run(sync, phase_after(sync, w)), w))
            .into_iter()
            .max_by(|a, b| a.0.gof.total_cmp(&b.0.gof))
    };
    let (at_phase, wait) = scan_waits(sync)?;
    let syncs: Vec<f64> = (-SYNC_STEPS..=SYNC_STEPS)
        .filter(|j| *j != 0)
        .map(|j| sync + f64::from(j) * TICK_S)
        .filter(|s| *s > 0.0 && *s <= period + 1e-9)
        .collect();
    let refined = best(parallel_map(&syncs, threads, |&s| {
        run(s, phase_after(s, wait))
    }));
    let at_sync = match refined {
        Some(r) if r.gof > at_phase.gof => r,
        _ => at_phase,
    };
    // The wait once more at the refined SYNC.
    let refined = scan_waits(at_sync.sync_after_push_s).map(|(c, _)| c);
    let found = match refined {
        Some(r) if r.gof > at_sync.gof => r,
        _ => at_sync,
    };
    Some(DriveClock {
        simulations: 2 * waits.len() + syncs.len(),
        ..found
    })
}

/// The ECU's column-encoder task's phases tried against each reference sample, s: its 2 ms
/// period (`tasks::ENCODER_PERIOD`) in steps of a quarter millisecond.
const ENCODER_PHASE_STEP_S: f64 = 0.000_25;
/// The phases in the task's 2 ms period.
const ENCODER_STEPS: u32 = 8;

/// Where the ECU's 2 ms column-encoder task samples against each reference sample, fitted on
/// `rec` with the car `rig` (an EPOS4 car under the ECU controller, its SYNC and readout
/// fitted), and the nominal GoF there; `None` on another car. For a log that does not say
/// (convert's does: [`encoder_phase_of`]).
///
/// ECU mode's column terms take the newest encoder sample at each SYNC, so which sample that
/// is, up to 2 ms old, is the car's own timing, like the SYNC's: its proportional term and
/// integral act on it. A model that took it at the reference sample's instant left the
/// simulated EPOS4 car's effect-free sweep at 97.3 % and its track at 91.8 % (gap/NOTES.md,
/// "The ECU's column-encoder phase"). The paper controller reads no column, and is left
/// alone.
pub fn fit_encoder_phase(rig: &Rig, rec: &Record, threads: usize) -> Option<(f64, f64)> {
    let RigModel::Paper(model) = &rig.model else {
        return None;
    };
    if model.drive != CarDrive::Epos4 || model.controller != Controller::Ecu {
        return None;
    }
    let phases: Vec<f64> = (0..ENCODER_STEPS)
        .map(|k| f64::from(k) * ENCODER_PHASE_STEP_S)
        .collect();
    let scorer = Scorer::new(rig, rec);
    parallel_map(&phases, threads.max(1), |&phase| {
        let mut m = model.clone();
        m.epos4.encoder_phase_s = phase;
        let g = scorer
            .fit(rec, &simulate_epos4(&m, rec, &Effects::nominal()))
            .gof;
        (phase, if g.is_finite() { g } else { f64::NEG_INFINITY })
    })
    .into_iter()
    .max_by(|a, b| a.1.total_cmp(&b.1))
}

/// Where the ECU's column-encoder task samples after each reference sample, s, read off
/// convert's `# column-sampled:` line (`column_age_s` before each row's end, the row ending a
/// reference period after the sample): each status frame carries one of the task's samples,
/// so the task samples at that instant, modulo its period. On the simulated car 2.31 ms
/// before the row's end: 1.69 ms after the reference. `None` without that line.
pub fn encoder_phase_of(readout: &super::rig::Epos4Readout) -> Option<f64> {
    let age = readout.column_age_s;
    // A NaN age is no place either.
    if !readout.column_interpolated || age.is_nan() || age <= 0.0 {
        return None;
    }
    let period = 1.0 / REFERENCE_HZ as f64;
    let task = steering_ecu::tasks::ENCODER_PERIOD.as_micros() as f64 * 1e-6;
    Some((period - age).rem_euclid(task))
}

/// The share of the nominal model's cost the best single candidate must remove before the
/// drive's clock is fitted again with it in the model ([`with_best`]). An effect that large
/// moved the clock fitted without it: on the simulated EPOS4 car's sweep with 100 and 300 N
/// at the rack (the best candidate removing 92 % and 97 %), the position loop's phase came out
/// 4 and 2 ticks against the car's 5, and the friction fitted on that clock 88 and 278 N.
const CLOCK_WITH_EFFECT_SHARE: f64 = 0.5;

/// The drive clock a diagnosis moved: fitted again with `with_effect` in the model, where it
/// had been fitted on the nominal model when the car was chosen.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct ClockRefit {
    pub with_effect: String,
    pub sync_after_push_s: f64,
    pub position_phase_ticks: u32,
    pub nominal_sync_after_push_s: f64,
    pub nominal_position_phase_ticks: u32,
    /// The simulations the clock's fit ran.
    pub simulations: usize,
}

impl ClockRefit {
    /// `rig` on this clock.
    pub fn apply(&self, rig: &mut Rig) {
        if let RigModel::Paper(m) = &mut rig.model {
            m.epos4.sync_after_push_s = self.sync_after_push_s;
            m.epos4.position_phase_ticks = self.position_phase_ticks;
            m.epos4.clock_from_nominal = false;
        }
    }
}

/// The EPOS4 car `rig` on the clock fitted again on the head of `rec` with `best` (the
/// diagnosis's best single candidate) in the model, where the car's clock was fitted on the
/// nominal model (`clock_from_nominal`), `best` removes at least half of the nominal cost
/// (`CLOCK_WITH_EFFECT_SHARE`) and the clock moves; `None` otherwise.
///
/// The car is chosen before any effect, so an effect in the log pulls the clock towards what
/// makes up for it, and the effect fitted on that clock comes out short (gap/NOTES.md, "The
/// drive's clock with the effect in the model"). The returned rig's clock is no longer the
/// nominal model's, so a diagnosis on it does not move it again.
pub fn with_best(
    rig: &Rig,
    rec: &Record,
    best: &Candidate,
    threads: usize,
) -> Option<(Rig, ClockRefit)> {
    let RigModel::Paper(m) = &rig.model else {
        return None;
    };
    if m.drive != CarDrive::Epos4
        || !m.epos4.clock_from_nominal
        || best.improvement < CLOCK_WITH_EFFECT_SHARE
    {
        return None;
    }
    let (sync, phase) = (m.epos4.sync_after_push_s, m.epos4.position_phase_ticks);
    let fx = best.effects_on(rig);
    let clock = fit(rig, &head(rec, SYNC_SEARCH_S), sync, &fx, threads.max(1))?;
    if (clock.sync_after_push_s, clock.position_phase_ticks) == (sync, phase) {
        return None;
    }
    let simulations = clock.simulations;
    let refit = ClockRefit {
        with_effect: best.effect.clone(),
        sync_after_push_s: clock.sync_after_push_s,
        position_phase_ticks: clock.position_phase_ticks,
        nominal_sync_after_push_s: sync,
        nominal_position_phase_ticks: phase,
        simulations,
    };
    let mut moved = rig.clone();
    refit.apply(&mut moved);
    Some((moved, refit))
}

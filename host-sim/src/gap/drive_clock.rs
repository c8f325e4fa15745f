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

use super::model::{Effects, simulate_epos4};
use super::rig::{Rig, RigModel};
use super::{Record, Scorer, parallel_map};
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
}

/// The drive's clock of the EPOS4 car `rig` (its readout as the log states it) on `head`, from
/// its SYNC phase `sync`: every position-loop phase at that SYNC, then the SYNC again, every
/// tick within half a millisecond, at the best phase. `None` on another rig.
pub fn fit(rig: &Rig, head: &Record, sync: f64, threads: usize) -> Option<DriveClock> {
    let RigModel::Paper(model) = &rig.model else {
        return None;
    };
    let scorer = Scorer::new(rig, head);
    let period = 1.0 / REFERENCE_HZ as f64;
    let run = |sync: f64, phase: u32| -> DriveClock {
        let mut m = model.clone();
        m.epos4.sync_after_push_s = sync;
        m.epos4.position_phase_ticks = phase;
        let g = scorer
            .fit(head, &simulate_epos4(&m, head, &Effects::nominal()))
            .gof;
        DriveClock {
            sync_after_push_s: sync,
            position_phase_ticks: phase,
            gof: if g.is_finite() { g } else { f64::NEG_INFINITY },
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
    Some(match refined {
        Some(r) if r.gof > at_sync.gof => r,
        _ => at_sync,
    })
}

//! A row per SYNC on two clocks: the stretch of a log where its reference column is a row off
//! the target the drive latched.
//!
//! A team's logger that writes a row as each TPDO arrives holds, in its reference column, the
//! reference frame it saw last; the drive latched at that SYNC the target that had reached it,
//! through the ECU, before the SYNC. On one clock the SYNC keeps its place against the
//! frames, so the two agree throughout or differ by one row throughout (the convention
//! [`super::drive::choose`] fits). The ECU sends its SYNC on its own crystal, 20-100 ppm off
//! the vehicle computer's: over a 120 s log the SYNC walks 2-12 ms against the frames, and
//! where it walks through the gap between what the logger has seen and what has reached the
//! drive (about half a millisecond in the independent world, 5-25 s of rows) the column
//! holds the next frame's sample while the drive still runs the previous one.
//!
//! The logger's own crossing is in the log: on a moving reference the column repeats a sample
//! (the SYNC walking earlier against the frames) or leaves one out (walking later)
//! ([`crossings`]). The drive's crossing is not, so the stretch between the two is fitted
//! ([`fit`]): the nominal model run with the column moved a row over a stretch that ends or
//! starts at the logger's crossing, its length searched on each side. Where neither side
//! lifts the nominal GoF by [`MIN_RESIDUAL_SHARE`] of its residual, the column stays as
//! logged.

use super::rig::Rig;
use super::{Record, parallel_map};

/// What the column does at a logger's crossing.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Crossing {
    /// The row holds the sample of the row before (the SYNC walking earlier).
    Repeat,
    /// The row holds the sample after the one the row before should be followed by (later).
    Skip,
}

/// A stretch of rows whose reference the model takes from the row before or after.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct ReferenceWindow {
    /// Where the logger's column repeats or skips a sample (row index).
    pub crossing_row: usize,
    pub crossing: Crossing,
    /// The rows moved: `start_row..end_row`.
    pub start_row: usize,
    pub end_row: usize,
    /// The same in seconds from the log's first row.
    pub crossing_s: f64,
    pub start_s: f64,
    pub end_s: f64,
    /// +1: each row takes the sample of the row before (the drive a row behind the column);
    /// -1: of the row after (the drive a row ahead).
    pub rows_later: i8,
    /// The nominal model's GoF on the whole log (eq. 11, combined), without the stretch and
    /// with it.
    pub gof_before: f64,
    pub gof_after: f64,
}

impl ReferenceWindow {
    /// One clause for the car line of the report.
    pub fn describe(&self) -> String {
        format!(
            "the reference column a row {} the drive's target over {:.2}-{:.2} s (rows {}-{}; \
             the logger's column {} a sample at {:.2} s, the SYNC walking through the frames \
             on a clock of its own; fitted, nominal GoF {:.1} -> {:.1} %)",
            if self.rows_later > 0 {
                "ahead of"
            } else {
                "behind"
            },
            self.start_s,
            self.end_s,
            self.start_row,
            self.end_row.saturating_sub(1),
            match self.crossing {
                Crossing::Repeat => "repeats",
                Crossing::Skip => "leaves out",
            },
            self.crossing_s,
            100.0 * self.gof_before,
            100.0 * self.gof_after
        )
    }
}

/// A crossing's stretch is kept when it takes at least this share off the nominal model's
/// residual (1 - GoF, eq. 11). On the independent world's drifting row-per-TPDO
/// tracks the stretch takes 1.1-40 % off (least where an effect leaves most of the residual:
/// 1.1 % on rack friction at a nominal 70 %, 0.6 % on a tyre at 65 %, not kept).
pub const MIN_RESIDUAL_SHARE: f64 = 0.01;
/// Rows either side of a row that [`crossings`] fits its cubics to.
pub const HALF_SPAN: usize = 4;
/// A crossing's cubic leaves at most this share of the plain cubic's residual (RMS): the
/// independent world's drifting logger's crossings leave 0.05-8 %.
pub const CROSSING_RESIDUAL_SHARE: f64 = 0.25;
/// The plain cubic's residual (RMS) must be at least this many of the column's resolution.
pub const MIN_RESIDUAL_QUANTA: f64 = 2.0;
/// More crossings than this is a column that moves in its own way (a reference that holds
/// samples), not a SYNC walking: none is fitted.
const MAX_CROSSINGS: usize = 6;
/// Stretch lengths tried first, as shares of the room on the side, and the shorter ones under
/// the first share ([`coarse_lengths`]).
const COARSE_SHARES: usize = 8;
const SHORT_HALVINGS: i32 = 5;

/// Where a column on the move repeats a sample or leaves one out, sorted by row. Around each
/// row a cubic in the sample's index is fitted to [`HALF_SPAN`] rows either side three ways:
/// every row its own sample; the row repeating the sample before it; the row leaving a sample
/// out. A crossing is where one of the last two leaves at most [`CROSSING_RESIDUAL_SHARE`] of
/// the first's residual, and the first's is [`MIN_RESIDUAL_QUANTA`] or more of the column's
/// written resolution (a slow column written to a few decimals repeats and doubles its steps
/// by itself). A repeat at a reversal, where the steps around it nearly vanish, shows in this
/// where the steps alone do not.
pub fn crossings(reference: &[f64]) -> Vec<(usize, Crossing)> {
    if reference.iter().any(|v| !v.is_finite()) {
        return Vec::new();
    }
    let quantum = resolution(reference);
    let h = HALF_SPAN as i32;
    let plain: Vec<f64> = (-h..=h).map(f64::from).collect();
    let repeat: Vec<f64> = (-h..=h)
        .map(|i| f64::from(if i < 0 { i } else { i - 1 }))
        .collect();
    let skip: Vec<f64> = (-h..=h)
        .map(|i| f64::from(if i < 0 { i } else { i + 1 }))
        .collect();
    let mut found: Vec<(usize, Crossing, f64)> = Vec::new();
    for k in HALF_SPAN..reference.len().saturating_sub(HALF_SPAN) {
        let y: Vec<f64> = reference[k - HALF_SPAN..=k + HALF_SPAN]
            .iter()
            .map(|v| v - reference[k])
            .collect();
        let none = cubic_rss(&plain, &y);
        if none < (MIN_RESIDUAL_QUANTA * quantum).powi(2) * y.len() as f64 {
            continue;
        }
        let (r, s) = (cubic_rss(&repeat, &y), cubic_rss(&skip, &y));
        let share = r.min(s) / none;
        if share > CROSSING_RESIDUAL_SHARE.powi(2) {
            continue;
        }
        let here = (
            k,
            if r <= s {
                Crossing::Repeat
            } else {
                Crossing::Skip
            },
            share,
        );
        // One crossing read from two rows side by side (each row's cubic spans the other):
        // the row whose crossing fits better.
        match found.last_mut() {
            Some(last) if k - last.0 <= HALF_SPAN => {
                if share < last.2 {
                    *last = here;
                }
            }
            _ => found.push(here),
        }
    }
    found.into_iter().map(|(k, c, _)| (k, c)).collect()
}

/// The residual sum of squares of the least-squares cubic through `(x, y)`.
fn cubic_rss(x: &[f64], y: &[f64]) -> f64 {
    let a = nalgebra::DMatrix::from_fn(x.len(), 4, |i, j| x[i].powi(j as i32));
    let b = nalgebra::DVector::from_column_slice(y);
    let fit = a.clone().svd(true, true).solve(&b, 1e-12);
    match fit {
        Ok(c) => (a * c - b).norm_squared(),
        Err(_) => f64::INFINITY,
    }
}

/// The step the column's values are written in: the largest power of ten, down to 1e-9, that
/// every value is a whole multiple of (a logger's decimals, or a frame's resolution written
/// out); else a billionth of the column's range.
fn resolution(values: &[f64]) -> f64 {
    let whole = |q: f64| {
        values.iter().all(|v| {
            let n = v / q;
            (n - n.round()).abs() < 1e-6
        })
    };
    if let Some(q) = (0..=9).map(|p| 10f64.powi(-p)).find(|&q| whole(q)) {
        return q;
    }
    let (lo, hi) = values
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(*v), h.max(*v))
        });
    (1e-9 * (hi - lo)).max(1e-12)
}

/// `reference` with rows `start..end` taken from the row `rows_later` before (after, when
/// negative), held at the column's ends.
fn moved(reference: &[f64], start: usize, end: usize, rows_later: i8) -> Vec<f64> {
    let mut out = reference.to_vec();
    let last = reference.len().saturating_sub(1);
    for (k, v) in out.iter_mut().enumerate().take(end).skip(start) {
        let j = if rows_later > 0 {
            k.saturating_sub(1)
        } else {
            (k + 1).min(last)
        };
        *v = reference[j];
    }
    out
}

/// The nominal model's GoF on `rec` with its reference `reference` (a run that blew up ranks
/// last, as the cars do).
fn gof_with(rig: &Rig, rec: &Record, reference: Vec<f64>) -> f64 {
    let rec = Record {
        reference,
        ..rec.clone()
    };
    super::drive::nominal_fit(rig, &rec).gof
}

/// One side of a crossing: the stretch's rows for a length `w`, and the way it moves.
#[derive(Clone, Copy)]
struct Side {
    crossing_row: usize,
    before: bool,
    rows_later: i8,
    /// Rows there is room for.
    room: usize,
}

impl Side {
    fn rows(&self, w: usize) -> (usize, usize) {
        let w = w.min(self.room);
        if self.before {
            (self.crossing_row - w, self.crossing_row)
        } else {
            (self.crossing_row, self.crossing_row + w)
        }
    }
}

/// Stretch lengths tried first on `side`: shares of its room, and shorter ones under the
/// first share.
fn coarse_lengths(side: &Side) -> Vec<usize> {
    let first = side.room as f64 / COARSE_SHARES as f64;
    let mut lengths: Vec<usize> = (1..=COARSE_SHARES)
        .map(|j| (side.room * j).div_ceil(COARSE_SHARES))
        .chain((1..=SHORT_HALVINGS).map(|i| (first * 2f64.powi(-i)).round() as usize))
        .filter(|w| *w >= 1)
        .collect();
    lengths.sort_unstable();
    lengths.dedup();
    lengths
}

/// The best stretch at a crossing: each side's [`coarse_lengths`] run at once, then the best
/// refined on its side by golden section between its neighbours, to a row or a fiftieth of
/// its length. The side, the length and the nominal GoF it gives.
fn best_stretch(
    rig: &Rig,
    rec: &Record,
    reference: &[f64],
    sides: &[Side],
    threads: usize,
) -> Option<(Side, usize, f64)> {
    let at = |side: &Side, w: usize| {
        let (s, e) = side.rows(w);
        gof_with(rig, rec, moved(reference, s, e, side.rows_later))
    };
    let jobs: Vec<(usize, usize)> = sides
        .iter()
        .enumerate()
        .filter(|(_, s)| s.room > 0)
        .flat_map(|(i, s)| coarse_lengths(s).into_iter().map(move |w| (i, w)))
        .collect();
    let gofs = parallel_map(&jobs, threads, |&(i, w)| at(&sides[i], w));
    let (best_job, _) = gofs.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1))?;
    let (i, w0) = jobs[best_job];
    let side = sides[i];
    // Every length run on this side, so the section's points that fall on one run before
    // are not run again.
    let mut tried: Vec<(usize, f64)> = jobs
        .iter()
        .zip(&gofs)
        .filter(|((j, _), _)| *j == i)
        .map(|((_, w), g)| (*w, *g))
        .collect();
    let pos = tried.iter().position(|(w, _)| *w == w0)?;
    let mut lo = if pos == 0 { 1 } else { tried[pos - 1].0 };
    let mut hi = tried.get(pos + 1).map_or(w0, |t| t.0);
    let mut best = (w0, gofs[best_job]);
    let mut eval = |w: usize, best: &mut (usize, f64)| {
        let g = match tried.iter().find(|(x, _)| *x == w) {
            Some(&(_, g)) => g,
            None => {
                let g = at(&side, w);
                tried.push((w, g));
                g
            }
        };
        if g > best.1 {
            *best = (w, g);
        }
        g
    };
    let phi = 0.5 * (5f64.sqrt() - 1.0);
    while hi > lo + 2.max(best.0 / 50) {
        let span = (hi - lo) as f64;
        let a = lo + (span * (1.0 - phi)).round() as usize;
        let b = (lo + (span * phi).round() as usize).max(a + 1);
        if eval(a, &mut best) >= eval(b, &mut best) {
            hi = b;
        } else {
            lo = a;
        }
    }
    Some((side, best.0, best.1))
}

/// The stretches of a row-per-SYNC log whose reference column the nominal model of `rig` fits
/// better a row moved, each at one of the logger's [`crossings`]; and the record with them
/// moved. A record without crossings (one clock) comes back as it is.
pub fn fit(rig: &Rig, rec: &Record, threads: usize) -> (Record, Vec<ReferenceWindow>) {
    let found = crossings(&rec.reference);
    if found.is_empty() || found.len() > MAX_CROSSINGS {
        return (rec.clone(), Vec::new());
    }
    let mut reference = rec.reference.clone();
    let mut windows: Vec<ReferenceWindow> = Vec::new();
    let mut gof = gof_with(rig, rec, reference.clone());
    for (j, &(row, crossing)) in found.iter().enumerate() {
        // Room up to the neighbouring crossings (or the log's ends).
        let lower = if j == 0 { 0 } else { found[j - 1].0 };
        let upper = found.get(j + 1).map_or(reference.len(), |c| c.0);
        let later_before = match crossing {
            Crossing::Repeat => 1,
            Crossing::Skip => -1,
        };
        let sides = [
            Side {
                crossing_row: row,
                before: true,
                rows_later: later_before,
                room: row - lower,
            },
            Side {
                crossing_row: row,
                before: false,
                rows_later: -later_before,
                room: upper - row,
            },
        ];
        let Some((side, w, g)) = best_stretch(rig, rec, &reference, &sides, threads) else {
            continue;
        };
        if 1.0 - g > (1.0 - MIN_RESIDUAL_SHARE) * (1.0 - gof) {
            continue;
        }
        let (start_row, end_row) = side.rows(w);
        reference = moved(&reference, start_row, end_row, side.rows_later);
        windows.push(ReferenceWindow {
            crossing_row: row,
            crossing,
            start_row,
            end_row,
            crossing_s: row as f64 * rec.dt,
            start_s: start_row as f64 * rec.dt,
            end_s: end_row as f64 * rec.dt,
            rows_later: side.rows_later,
            gof_before: gof,
            gof_after: g,
        });
        gof = g;
    }
    (
        Record {
            reference,
            ..rec.clone()
        },
        windows,
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A sine at four decimals, 100 samples a period, whose row `k` holds sample `sample(k)`.
    fn column(n: usize, sample: impl Fn(usize) -> usize) -> Vec<f64> {
        (0..n)
            .map(|k| (3.0 * (0.0628 * sample(k) as f64).sin() * 1e4).round() / 1e4)
            .collect()
    }

    #[test]
    fn a_repeated_and_a_left_out_sample_on_a_moving_column_are_found() {
        // Row 20 repeats row 19's sample; row 35 leaves sample 34 out.
        let r = column(50, |k| if (20..35).contains(&k) { k - 1 } else { k });
        assert_eq!(
            crossings(&r),
            vec![(20, Crossing::Repeat), (35, Crossing::Skip)]
        );
        // The same on a column of f32 values: no decimals, the range's billionth.
        let f: Vec<f64> = r.iter().map(|v| f64::from(*v as f32 + 0.012_345)).collect();
        assert_eq!(crossings(&f), crossings(&r));
        // A repeat at the sine's crest (sample 25), where the steps around it nearly vanish.
        let crest = column(50, |k| if k >= 25 { k - 1 } else { k });
        assert_eq!(crossings(&crest), vec![(25, Crossing::Repeat)]);
    }

    #[test]
    fn a_column_that_stands_or_turns_has_no_crossing() {
        // Standing, starting to move, turning back: no neighbours that agree around a gap.
        let mut r = vec![1.0; 10];
        r.extend((1..20).map(|k| 1.0 + 0.05 * f64::from(k)));
        r.extend((1..20).map(|k| 1.95 - 0.05 * f64::from(k)));
        assert!(crossings(&r).is_empty(), "{:?}", crossings(&r));
        // A sine at 100 Hz rows, four decimals: smooth everywhere.
        let s: Vec<f64> = (0..2000)
            .map(|k| ((10.0 * (0.02 * k as f64).sin()) * 1e4).round() / 1e4)
            .collect();
        assert!(crossings(&s).is_empty(), "{:?}", crossings(&s));
        // Too short to have neighbours, empty, one value, not numbers.
        assert!(crossings(&[0.0, 1.0, 1.0]).is_empty());
        assert!(crossings(&[]).is_empty());
        assert!(crossings(&[2.0; 100]).is_empty());
        assert!(crossings(&[f64::NAN; 10]).is_empty());
    }

    #[test]
    fn a_stretch_moves_its_rows_a_row_later_or_earlier_held_at_the_ends() {
        let r = vec![0.0, 1.0, 2.0, 3.0, 4.0];
        assert_eq!(moved(&r, 1, 3, 1), vec![0.0, 0.0, 1.0, 3.0, 4.0]);
        assert_eq!(moved(&r, 3, 5, -1), vec![0.0, 1.0, 2.0, 4.0, 4.0]);
        assert_eq!(moved(&r, 0, 1, 1), r);
    }
}

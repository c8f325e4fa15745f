//! A logger that writes rows faster than the car's frames arrive.
//!
//! The car reports its column, motor and current in frames at the reference rate (100 Hz).
//! A team's logger on the vehicle computer may still write a row every millisecond, each
//! holding the last frame it received: the column then stands for ten rows and jumps, up to a
//! period stale, and a row's current is a frame's interval mean, not the row's. Binned as a
//! log of 1 kHz samples, the effect-free car of the independent world read 77.6 % nominal
//! GoF (92.6 % from a logger of true 1 kHz samples) and was named `parameters`.
//!
//! Such a log holds its frames on rows where nothing changes. Where most rows repeat the row
//! before in every car column and the rows where something changes come about one period
//! apart, the log is read at those rows alone, as a logger of the frames writes it: each
//! frame at the row before its first row (the logger's last row before it came: its stamp
//! and its reference), a frame whose row before was lost left out. Two frames (the angles'
//! and the current's) that land on rows closer than a quarter period are one arrival, at the
//! later row, which holds both.
//!
//! A recording's decoded frames exported row by row hold the same: a row for each frame, the
//! other frames' cells left empty. Where a quarter of the rows leave a column empty
//! ([`blank_share`]) the paper rig's reader holds each empty cell at its column's last value
//! and reads the log here, with one row a period holding the car's columns enough.

/// Fewest rows that must repeat the row before in every car column for the log to be read
/// as held frames: a logger at twice the frames' rate repeats half its rows, and a logger of
/// real samples almost none (a current's noise changes it every row).
pub const HELD_SHARE: f64 = 0.4;

/// [`HELD_SHARE`] for a log known to hold a row for each CAN frame (its other frames' cells
/// empty): each period's reference frame has a row that holds the car's columns, so with the
/// car's columns in two frames of their own a third of the rows hold them.
pub const FRAMES_HELD_SHARE: f64 = 0.2;

/// From this share of rows leaving the reference or a column of the car empty, a log is read
/// as a row for each CAN frame, each empty sample holding its column's last: a sensor's
/// dropouts leave a few rows so, a log of two frames half of them.
pub const FRAMES_BLANK_SHARE: f64 = 0.25;

/// The arrivals' median spacing, as a share of the frames' period, that held frames show
/// (frames lost, or two at once, move it little).
const ARRIVAL_SPACING: std::ops::RangeInclusive<f64> = 0.75..=1.5;

/// Arrivals closer than this share of a period are one frame's rows.
const ONE_ARRIVAL: f64 = 0.25;

/// The rows of a log (`t` increasing, `columns` the car's columns, each as long as `t`) at
/// which a new frame arrived, where the log holds frames of period `period_s` on rows that
/// come faster, at least `held_share` of its rows holding the row before ([`HELD_SHARE`],
/// [`FRAMES_HELD_SHARE`]); `None` for a log of samples (each row its own), or one whose rows
/// come no faster than its frames.
pub fn arrivals(
    t: &[f64],
    columns: &[&[f64]],
    period_s: f64,
    held_share: f64,
) -> Option<Vec<usize>> {
    let n = t.len();
    if n < 20 || columns.is_empty() || columns.iter().any(|c| c.len() != n) {
        return None;
    }
    let row_s = host_io::grid::median_gap(t);
    if !(row_s > 0.0 && row_s < 0.75 * period_s) {
        return None;
    }
    let changed = |k: usize| columns.iter().any(|c| c[k] != c[k - 1]);
    let held = (1..n).filter(|&k| !changed(k)).count();
    if (held as f64) < held_share * (n - 1) as f64 {
        return None;
    }
    // The rows where a frame arrived; the first row holds the first frame seen.
    let mut rows: Vec<usize> = vec![0];
    for k in (1..n).filter(|&k| changed(k)) {
        match rows.last_mut() {
            Some(last) if *last != 0 && t[k] - t[*last] < ONE_ARRIVAL * period_s => *last = k,
            _ => rows.push(k),
        }
    }
    let spacing = host_io::grid::median_gap(&at(t, &rows));
    (rows.len() > 20 && ARRIVAL_SPACING.contains(&(spacing / period_s))).then_some(rows)
}

/// `rows` (a frame's first rows, [`arrivals`]) less those whose row before lies more than a
/// row spacing and the stamps' jitter (`jitter_s`, RMS) earlier: a row was lost between
/// them, so the frame came anywhere in two rows' time (a 200 Hz logger's 10 ms). Such a
/// frame is left out, as a row a logger of the frames lost.
pub fn unambiguous(t: &[f64], rows: &[usize], jitter_s: f64) -> Vec<usize> {
    let spacing = host_io::grid::median_gap(t);
    let limit = spacing + (0.5 * spacing).max(4.0 * jitter_s);
    rows.iter()
        .copied()
        .filter(|&k| k == 0 || t[k] - t[k - 1] <= limit)
        .collect()
}

/// The share of a log's rows, from the first by which each of `columns` (each as long as the
/// log) has a sample, that leave one of them empty (`nan`); 0 where one never has a sample.
pub fn blank_share(columns: &[&[f64]]) -> f64 {
    let Some(start) = columns
        .iter()
        .map(|v| v.iter().position(|x| !x.is_nan()))
        .collect::<Option<Vec<usize>>>()
        .and_then(|firsts| firsts.into_iter().max())
    else {
        return 0.0;
    };
    let rows = columns.iter().map(|v| v.len()).min().unwrap_or(0);
    if rows <= start {
        return 0.0;
    }
    let blank = (start..rows)
        .filter(|&j| columns.iter().any(|v| v[j].is_nan()))
        .count();
    blank as f64 / (rows - start) as f64
}

/// `values` at `rows`.
pub fn at(values: &[f64], rows: &[usize]) -> Vec<f64> {
    rows.iter().map(|&k| values[k]).collect()
}

/// The row before each of `rows` (the log's first row, with none before it, itself): the
/// logger's last row before the frame came, whose stamp and reference the frame takes, as a
/// logger of the frames stamps each when it comes. Where the rows divide the period (200 Hz,
/// 500 Hz, 1 kHz) that row sits at one phase of the period; where they do not (250 Hz,
/// 400 Hz) its phase walks, and the frames' with it (gap/NOTES.md).
pub fn before(rows: &[usize]) -> Vec<usize> {
    rows.iter().map(|&k| k.saturating_sub(1)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 1 kHz log of `seconds` holding frames that arrive every 10 ms, 4.3 ms into each
    /// period, frame `f` holding `sin(0.37 f)`.
    fn held_log(seconds: f64) -> (Vec<f64>, Vec<f64>) {
        let n = (seconds * 1000.0) as usize;
        let t: Vec<f64> = (0..n).map(|k| 0.001 * (k + 1) as f64).collect();
        let v: Vec<f64> = t
            .iter()
            .map(|s| {
                let frame = ((s - 0.0043) / 0.01).floor();
                (0.37 * frame).sin()
            })
            .collect();
        (t, v)
    }

    #[test]
    fn held_frames_are_read_where_they_arrive() {
        let (t, v) = held_log(2.0);
        let rows = arrivals(&t, &[&v], 0.01, HELD_SHARE).expect("held");
        // 200 periods: an arrival in each, the first row besides.
        assert!((199..=201).contains(&rows.len()), "{}", rows.len());
        for w in rows[1..].windows(2) {
            assert!((t[w[1]] - t[w[0]] - 0.01).abs() < 1.5e-3, "{w:?}");
        }
        // Each arrival row holds a new value, and the row before it the old one.
        for &k in &rows[1..] {
            assert_ne!(v[k], v[k - 1]);
        }
    }

    #[test]
    fn two_frames_a_row_apart_are_one_arrival() {
        let (t, v) = held_log(2.0);
        // The current's frame lands a row after the angles'.
        let w: Vec<f64> = (0..v.len()).map(|k| v[k.saturating_sub(1)]).collect();
        let rows = arrivals(&t, &[&v, &w], 0.01, HELD_SHARE).expect("held");
        assert!((199..=201).contains(&rows.len()), "{}", rows.len());
        for &k in &rows[1..] {
            assert_ne!(w[k], w[k - 1], "the later row of the two holds both");
        }
    }

    #[test]
    fn a_frame_whose_row_before_was_lost_is_left_out() {
        // 200 Hz rows, frames first held on every other row; the row before the arrival at
        // row 41 lost, and the arrival row 60 itself.
        let t: Vec<f64> = (0..200)
            .filter(|k| *k != 40 && *k != 60)
            .map(|k| 0.005 * k as f64)
            .collect();
        let first = |k: usize| t.iter().position(|x| (x - 0.005 * k as f64).abs() < 1e-9);
        let rows: Vec<usize> = (1..100)
            .filter_map(|f| first(2 * f + 1).or(first(2 * f + 2)))
            .collect();
        let kept = unambiguous(&t, &rows, 0.0);
        assert_eq!(rows.len() - kept.len(), 2, "{rows:?}");
        assert!(!kept.contains(&first(41).unwrap()) && !kept.contains(&first(61).unwrap()));
        // Read with the stamps' jitter at 0.6 ms RMS (+-1 ms), the same two.
        assert_eq!(unambiguous(&t, &rows, 0.6e-3).len(), rows.len() - 2);
    }

    #[test]
    fn empty_cells_are_counted_from_the_row_every_column_has_begun() {
        let nan = f64::NAN;
        // A reference frame's row, then the car's; the car's first frame comes on row 1.
        let reference = [0.1, nan, 0.2, nan, 0.3, nan];
        let column = [nan, 1.0, nan, 2.0, nan, 3.0];
        assert_eq!(blank_share(&[&reference, &column]), 1.0);
        // A dropout of one row in five, after the car began on row 2.
        let full = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 7.0];
        let dropout = [nan, nan, 3.0, nan, 5.0, 6.0, 7.0];
        assert!((blank_share(&[&full, &dropout]) - 0.2).abs() < 1e-12);
        assert_eq!(blank_share(&[&full, &[nan; 7]]), 0.0);
        assert_eq!(blank_share(&[]), 0.0);
    }

    #[test]
    fn a_log_of_samples_or_at_the_frames_rate_is_read_as_it_is() {
        let t: Vec<f64> = (0..2000).map(|k| 0.001 * k as f64).collect();
        let samples: Vec<f64> = t.iter().map(|s| (7.0 * s).sin()).collect();
        assert_eq!(arrivals(&t, &[&samples], 0.01, HELD_SHARE), None);
        // 100 Hz rows: nothing held.
        let t100: Vec<f64> = (0..500).map(|k| 0.01 * k as f64).collect();
        let v100: Vec<f64> = t100.iter().map(|s| (7.0 * s).sin()).collect();
        assert_eq!(arrivals(&t100, &[&v100], 0.01, HELD_SHARE), None);
        // A car at rest for most of a log of samples: its rows repeat, but no frames arrive
        // a period apart.
        let mut rest = samples.clone();
        for x in rest.iter_mut().skip(100) {
            *x = 0.0;
        }
        assert_eq!(arrivals(&t, &[&rest], 0.01, HELD_SHARE), None);
    }
}

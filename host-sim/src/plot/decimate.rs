//! Long series reduced to what the pixel columns can show.

use super::MAX_UNSORTED_POINTS;
use super::scale::Scale;

/// A series reduced to what `columns` pixel columns can show: runs of samples `(x, y)`, a new
/// run after every NaN gap. Plotters would otherwise write every sample of a 120 s log.
pub(super) fn decimate(
    x: &[f64],
    y: &[f64],
    x_scale: &Scale,
    columns: i64,
) -> Vec<Vec<(f64, f64)>> {
    let sorted = x.iter().filter(|v| !v.is_nan()).is_sorted();
    if !sorted {
        return thin_unsorted(x, y, x_scale);
    }
    let mut out = Decimator::default();
    for (&xv, &yv) in x.iter().zip(y) {
        let Some(f) = x_scale.fraction(xv) else {
            out.gap();
            continue;
        };
        // Everything left of the plot shares one column, everything right another: enough
        // to draw the clipped line into the edge.
        let column = ((f * columns as f64).floor() as i64).clamp(-1, columns + 1);
        out.enter_column(column);
        if yv.is_finite() {
            out.point(xv, yv);
        } else {
            out.gap();
        }
    }
    out.finish()
}

/// Per-column reduction to first, min, max and last sample (the "M4" scheme): the line looks
/// the same as with every sample, single-sample spikes included.
#[derive(Default)]
pub(super) struct Decimator {
    runs: Vec<Vec<(f64, f64)>>,
    current: Vec<(f64, f64)>,
    column: Option<i64>,
    /// (sample count in column, x, y) of first, lowest, highest, last finite sample.
    first: Option<(usize, f64, f64)>,
    min: (usize, f64, f64),
    max: (usize, f64, f64),
    last: (usize, f64, f64),
    count: usize,
    /// The line must break before the next column's first point.
    break_pending: bool,
    /// A NaN came after the last finite point of this column.
    gap_after: bool,
}

impl Decimator {
    fn enter_column(&mut self, column: i64) {
        if self.column != Some(column) {
            self.flush();
            self.column = Some(column);
        }
    }

    fn point(&mut self, x: f64, y: f64) {
        // A gap with finite points on both sides inside one pixel column is invisible; it
        // would only multiply path pieces on a signal that drops out at a high rate.
        self.gap_after = false;
        self.count += 1;
        let p = (self.count, x, y);
        if self.first.is_none() {
            self.first = Some(p);
            self.min = p;
            self.max = p;
        }
        if y < self.min.2 {
            self.min = p;
        }
        if y > self.max.2 {
            self.max = p;
        }
        self.last = p;
    }

    fn gap(&mut self) {
        if self.first.is_some() {
            self.gap_after = true;
        } else {
            self.break_pending = true;
        }
    }

    fn flush(&mut self) {
        let Some(first) = self.first.take() else {
            return;
        };
        if self.break_pending && !self.current.is_empty() {
            self.runs.push(std::mem::take(&mut self.current));
        }
        let mut points = [first, self.min, self.max, self.last];
        points.sort_by_key(|p| p.0);
        let mut previous = None;
        for (k, x, y) in points {
            if previous != Some(k) {
                self.current.push((x, y));
                previous = Some(k);
            }
        }
        self.break_pending = self.gap_after;
        self.gap_after = false;
        self.count = 0;
    }

    fn finish(mut self) -> Vec<Vec<(f64, f64)>> {
        self.flush();
        if !self.current.is_empty() {
            self.runs.push(self.current);
        }
        self.runs
    }
}

/// Fallback for x that is not sorted (no pixel columns to reduce over): every n-th sample.
pub(super) fn thin_unsorted(x: &[f64], y: &[f64], x_scale: &Scale) -> Vec<Vec<(f64, f64)>> {
    let stride = x.len().div_ceil(MAX_UNSORTED_POINTS).max(1);
    let mut runs = Vec::new();
    let mut current = Vec::new();
    for (&xv, &yv) in x.iter().zip(y).step_by(stride) {
        if x_scale.transform(xv).is_some() && yv.is_finite() {
            current.push((xv, yv));
        } else if !current.is_empty() {
            runs.push(std::mem::take(&mut current));
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs
}

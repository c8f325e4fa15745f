//! One axis as plotters draws it ([`Scale`]), and the data ranges the axes span.

use super::ticks::{log_tick_label, tick_label};
use super::{Frame, MAX_OVERSHOOT, Panel, XScale};
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};
use std::ops::Range;

/// One axis: its data range, linear or decades, and the ticks we chose for it. It is the
/// coordinate type plotters draws with, so the grid, the tick labels, the decimator's pixel
/// columns and the clipping all use one mapping.
#[derive(Debug, Clone)]
pub(super) struct Scale {
    pub(super) lo: f64,
    pub(super) hi: f64,
    pub(super) log: bool,
    /// Labelled ticks (plotters' bold mesh lines) and unlabelled ones (its light lines).
    pub(super) major: Vec<f64>,
    pub(super) minor: Vec<f64>,
    /// Spacing of the labelled ticks on a linear axis: how many decimals a label needs.
    pub(super) step: f64,
}

impl Scale {
    pub(super) fn new(lo: f64, hi: f64, log: bool) -> Self {
        Self {
            lo,
            hi,
            log,
            major: Vec::new(),
            minor: Vec::new(),
            step: 1.0,
        }
    }

    pub(super) fn ticks(mut self, major: Vec<f64>, minor: Vec<f64>) -> Self {
        self.step = major.windows(2).map(|w| w[1] - w[0]).next().unwrap_or(1.0);
        self.major = major;
        self.minor = minor;
        self
    }

    /// The value along the axis' own straight line: itself, or its log10 on a decade axis.
    /// `None` for NaN, infinities and, on a log axis, `v <= 0`.
    pub(super) fn transform(&self, v: f64) -> Option<f64> {
        let t = if self.log {
            if v > 0.0 { v.log10() } else { return None }
        } else {
            v
        };
        t.is_finite().then_some(t)
    }

    pub(super) fn inverse(&self, t: f64) -> f64 {
        if self.log { 10f64.powf(t) } else { t }
    }

    /// Where `v` lies along the axis: 0 at `lo`, 1 at `hi`.
    pub(super) fn fraction(&self, v: f64) -> Option<f64> {
        let (t, t_lo, t_hi) = (
            self.transform(v)?,
            self.transform(self.lo)?,
            self.transform(self.hi)?,
        );
        Some((t - t_lo) / (t_hi - t_lo)).filter(|f| f.is_finite())
    }

    pub(super) fn contains(&self, v: f64) -> bool {
        self.transform(v).is_some() && v >= self.lo && v <= self.hi
    }
}

impl Ranged for Scale {
    type FormatOption = NoDefaultFormatting;
    type ValueType = f64;

    fn map(&self, value: &f64, limit: (i32, i32)) -> i32 {
        // Only clipped data reaches here; the clamp keeps a stray value from writing an absurd
        // coordinate into the file.
        let f = self
            .fraction(*value)
            .unwrap_or(0.0)
            .clamp(-MAX_OVERSHOOT, 1.0 + MAX_OVERSHOOT);
        (f64::from(limit.0) + f * f64::from(limit.1 - limit.0)).round() as i32
    }

    fn key_points<Hint: KeyPointHint>(&self, hint: Hint) -> Vec<f64> {
        if hint.weight().allow_light_points() {
            self.minor.clone()
        } else {
            self.major.clone()
        }
    }

    fn range(&self) -> Range<f64> {
        self.lo..self.hi
    }
}

impl ValueFormatter<f64> for Scale {
    fn format(value: &f64) -> String {
        format!("{value}")
    }

    fn format_ext(&self, value: &f64) -> String {
        if self.log {
            log_tick_label(*value)
        } else {
            tick_label(*value, self.step)
        }
    }
}

pub(super) fn valid_range(range: Option<(f64, f64)>, log: bool) -> Option<(f64, f64)> {
    range.filter(|&(lo, hi)| lo.is_finite() && hi.is_finite() && lo < hi && (!log || lo > 0.0))
}

pub(super) fn resolve_x_range(frame: &Frame, panels: &[&Panel]) -> (f64, f64) {
    let log = frame.x_scale == XScale::Log;
    if let Some(range) = valid_range(frame.x_range, log) {
        return range;
    }
    let usable = |x: &f64| x.is_finite() && (!log || *x > 0.0);
    let (lo, hi) = panels
        .iter()
        .flat_map(|p| &p.series)
        .flat_map(|s| s.x.iter().copied().filter(usable))
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        });
    let no_data = lo > hi;
    match (lo < hi, no_data, log) {
        (true, _, _) => (lo, hi),
        // A single x value: a range around it.
        (false, false, true) => (lo / 2.0, hi * 2.0),
        (false, false, false) => (lo - 0.5, hi + 0.5),
        (false, true, true) => (1.0, 10.0),
        (false, true, false) => (0.0, 1.0),
    }
}

/// The panel's fixed range, else its visible data and limit lines with 5 % headroom.
pub(super) fn resolve_y_range(panel: &Panel, x_scale: &Scale) -> (f64, f64) {
    if let Some(range) = valid_range(panel.y_range, false) {
        return range;
    }
    let visible = panel
        .series
        .iter()
        .flat_map(|s| s.x.iter().zip(&s.y))
        .filter(|&(&x, y)| y.is_finite() && x_scale.contains(x))
        .map(|(_, &y)| y);
    let lines = panel.hlines.iter().map(|h| h.y).filter(|y| y.is_finite());
    let (lo, hi) = visible
        .chain(lines)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), y| {
            (lo.min(y), hi.max(y))
        });
    if lo > hi {
        return (0.0, 1.0);
    }
    if lo < hi {
        let pad = 0.05 * (hi - lo);
        return (lo - pad, hi + pad);
    }
    // A constant signal: a range around it.
    let d = if lo == 0.0 { 1.0 } else { lo.abs() * 0.1 };
    (lo - d, hi + d)
}

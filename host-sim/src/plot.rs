//! SVG line charts for the README and the reports, written by hand so that host-sim needs no
//! plotting crate: stacked time plots ([`TimePlot`]) and Bode plots ([`BodePlot`]).
//!
//! # Theory of operation
//!
//! A figure is a column of panels sharing one x axis; tick labels appear under the bottom panel
//! only. Each panel has its own y axis, legend strip, grid, limit lines and shaded intervals:
//!
//! ```text
//!           title
//!   ── series a  ── series b          <- legend strip
//!  ┌──────────────────────────────┐
//!  │ ░░░ shade ░░      - - limit -│   <- panel 1 (y label on the left, rotated)
//!  └──────────────────────────────┘
//!  ┌──────────────────────────────┐
//!  │                              │   <- panel 2
//!  └──────────────────────────────┘
//!    0     2     4     6     8        <- x ticks, then the x label
//! ```
//!
//! Series are copied in and drawn when [`TimePlot::to_svg`] runs. Before drawing, a series is
//! decimated to at most four points per pixel column (first, min, max, last: the line looks the
//! same as with every sample, spikes included), so a 240 000-sample trace costs a few tens of
//! kilobytes. A NaN sample (sensor dropout) lifts the pen: the line breaks there. Points outside
//! the axes are clipped, not dropped, so lines run to the edge. Colours come from the Okabe-Ito
//! palette, which stays distinguishable with the common colour-vision deficiencies; the
//! background is white so the picture also reads on GitHub's dark theme.
use std::fmt::{self, Write as _};
use std::fs;
use std::io;
use std::path::Path;

const DEFAULT_WIDTH: f64 = 900.0;
const DEFAULT_PANEL_HEIGHT: f64 = 190.0;
const MARGIN_LEFT: f64 = 76.0;
const MARGIN_RIGHT: f64 = 28.0;
const TITLE_HEIGHT: f64 = 38.0;
const NO_TITLE_HEIGHT: f64 = 10.0;
const LEGEND_HEIGHT: f64 = 24.0;
/// Space above a panel that has no legend strip.
const PANEL_GAP: f64 = 12.0;
const BOTTOM_HEIGHT: f64 = 50.0;
/// Markers are drawn only on sparse series; on dense ones they would merge into a smear.
const MAX_MARKERS: usize = 400;
/// Cap for series whose x is not sorted, which the per-column decimation cannot handle.
const MAX_UNSORTED_POINTS: usize = 20_000;
/// How far outside the plot a coordinate may land; beyond, it is pulled in so the file holds no
/// absurd numbers. Far enough that the clipped line's visible part does not change.
const MAX_OVERSHOOT_PX: f64 = 10_000.0;

const TEXT: &str = "#222222";
const TEXT_SOFT: &str = "#555555";
const GRID: &str = "#e3e3e3";
const GRID_MINOR: &str = "#f1f1f1";
const GRID_ZERO: &str = "#c4c4c4";
const FRAME: &str = "#444444";
const SHADE_FILLS: [&str; 6] = [
    "#ececec", "#fde9d2", "#d9efe5", "#e9e0f1", "#fff3c4", "#dceaf6",
];

/// An sRGB colour, written as `#rrggbb`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Color(pub u8, pub u8, pub u8);

impl Color {
    pub const BLUE: Color = Color(0x00, 0x72, 0xB2);
    pub const VERMILLION: Color = Color(0xD5, 0x5E, 0x00);
    pub const GREEN: Color = Color(0x00, 0x9E, 0x73);
    pub const PURPLE: Color = Color(0xCC, 0x79, 0xA7);
    pub const ORANGE: Color = Color(0xE6, 0x9F, 0x00);
    pub const SKY: Color = Color(0x56, 0xB4, 0xE9);
    pub const BLACK: Color = Color(0x00, 0x00, 0x00);
    pub const GRAY: Color = Color(0x66, 0x66, 0x66);
}

impl fmt::Display for Color {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "#{:02x}{:02x}{:02x}", self.0, self.1, self.2)
    }
}

/// Series colours in the order they are handed out (Okabe-Ito without its yellow, which is too
/// faint on white).
pub const PALETTE: [Color; 6] = [
    Color::BLUE,
    Color::VERMILLION,
    Color::GREEN,
    Color::PURPLE,
    Color::ORANGE,
    Color::SKY,
];

/// How a series is drawn. The default is a solid line in the next palette colour.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Style {
    /// `None`: the next palette colour.
    pub color: Option<Color>,
    pub dashed: bool,
    /// A dot on every sample; skipped on series with more than a few hundred visible samples.
    pub markers: bool,
}

impl Style {
    pub fn new() -> Self {
        Self::default()
    }

    pub fn color(self, color: Color) -> Self {
        Self {
            color: Some(color),
            ..self
        }
    }

    pub fn dashed(self) -> Self {
        Self {
            dashed: true,
            ..self
        }
    }

    pub fn markers(self) -> Self {
        Self {
            markers: true,
            ..self
        }
    }
}

/// Linear or logarithmic (decades) x axis.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum XScale {
    #[default]
    Linear,
    Log,
}

#[derive(Debug, Clone)]
struct Series {
    name: String,
    x: Vec<f64>,
    y: Vec<f64>,
    color: Color,
    dashed: bool,
    markers: bool,
}

#[derive(Debug, Clone)]
struct HLine {
    y: f64,
    label: String,
}

#[derive(Debug, Clone)]
struct VLine {
    x: f64,
    label: String,
    color: Color,
    /// Label near the bottom, left of the line: where a low-pass magnitude leaves room.
    label_at_bottom: bool,
}

#[derive(Debug, Clone)]
struct Shade {
    x0: f64,
    x1: f64,
    label: String,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum YTicks {
    Decimal,
    Degrees,
}

/// One panel of a figure: a y axis with its label, series, limit lines and shaded intervals.
#[derive(Debug, Clone)]
pub struct Panel {
    y_label: String,
    height: f64,
    series: Vec<Series>,
    hlines: Vec<HLine>,
    vlines: Vec<VLine>,
    shades: Vec<Shade>,
    y_range: Option<(f64, f64)>,
    y_ticks: YTicks,
    legend: bool,
    auto_colors: usize,
}

impl Panel {
    /// An empty panel; give the unit in the label, e.g. `"motor current (A)"`.
    pub fn new(y_label: &str) -> Self {
        Self {
            y_label: y_label.to_string(),
            height: DEFAULT_PANEL_HEIGHT,
            series: Vec::new(),
            hlines: Vec::new(),
            vlines: Vec::new(),
            shades: Vec::new(),
            y_range: None,
            y_ticks: YTicks::Decimal,
            legend: true,
            auto_colors: 0,
        }
    }

    /// Adds a solid line in the next palette colour. `x` and `y` pair up sample by sample; if
    /// their lengths differ, the extra samples of the longer one are not drawn.
    pub fn series(self, name: &str, x: &[f64], y: &[f64]) -> Self {
        self.series_styled(name, x, y, Style::new())
    }

    /// Adds a line drawn as `style` says.
    pub fn series_styled(mut self, name: &str, x: &[f64], y: &[f64], style: Style) -> Self {
        let color = style.color.unwrap_or_else(|| {
            self.auto_colors += 1;
            PALETTE[(self.auto_colors - 1) % PALETTE.len()]
        });
        self.push_series(name, x, y, color, style);
        self
    }

    /// A dashed horizontal line, e.g. a limit: `.hline(20.0, "+20 A limit")`. The label (may be
    /// empty) sits at its right end. The auto y range includes it.
    pub fn hline(mut self, y: f64, label: &str) -> Self {
        self.hlines.push(HLine {
            y,
            label: label.to_string(),
        });
        self
    }

    /// A dashed vertical marker with a label near its top.
    pub fn vline(mut self, x: f64, label: &str) -> Self {
        self.vlines.push(VLine {
            x,
            label: label.to_string(),
            color: Color::GRAY,
            label_at_bottom: false,
        });
        self
    }

    /// Shades the x interval `x0..x1`; intervals with the same label get the same tint.
    pub fn shade(mut self, x0: f64, x1: f64, label: &str) -> Self {
        self.shades.push(Shade {
            x0,
            x1,
            label: label.to_string(),
        });
        self
    }

    /// A fixed y range instead of the data's (ignored unless finite with `lo < hi`).
    pub fn y_range(mut self, lo: f64, hi: f64) -> Self {
        self.y_range = Some((lo, hi));
        self
    }

    /// Ticks on multiples of 15, 30, 45 or 90 instead of 1-2-5 steps: for angles in degrees.
    pub fn degree_ticks(mut self) -> Self {
        self.y_ticks = YTicks::Degrees;
        self
    }

    /// Height of the plotting area in pixels (default 190).
    pub fn height(mut self, px: f64) -> Self {
        if px.is_finite() && px >= 40.0 {
            self.height = px;
        }
        self
    }

    /// No legend strip above this panel (e.g. a single series the y label already names).
    pub fn hide_legend(mut self) -> Self {
        self.legend = false;
        self
    }

    fn push_series(&mut self, name: &str, x: &[f64], y: &[f64], color: Color, style: Style) {
        let n = x.len().min(y.len());
        self.series.push(Series {
            name: name.to_string(),
            x: x[..n].to_vec(),
            y: y[..n].to_vec(),
            color,
            dashed: style.dashed,
            markers: style.markers,
        });
    }

    fn shows_legend(&self) -> bool {
        self.legend && self.series.iter().any(|s| !s.name.is_empty())
    }

    fn top_pad(&self) -> f64 {
        if self.shows_legend() {
            LEGEND_HEIGHT
        } else {
            PANEL_GAP
        }
    }
}

/// Stacked panels over a shared time axis.
///
/// ```no_run
/// # use host_sim::plot::{Panel, Style, Color, TimePlot};
/// # let (t, r, y, i) = (vec![0.0, 1.0], vec![0.0, 1.0], vec![0.0, 0.9], vec![0.0, 3.0]);
/// TimePlot::new("Step, 10 deg at the wheel")
///     .panel(
///         Panel::new("steering wheel (deg)")
///             .series_styled("reference", &t, &r, Style::new().color(Color::BLACK).dashed())
///             .series("column encoder", &t, &y),
///     )
///     .panel(Panel::new("motor current (A)").series("current", &t, &i).hline(20.0, "+20 A limit"))
///     .save(std::path::Path::new("target/plots/step.svg"))?;
/// # Ok::<(), std::io::Error>(())
/// ```
#[derive(Debug, Clone)]
pub struct TimePlot {
    title: String,
    x_label: String,
    x_range: Option<(f64, f64)>,
    width: f64,
    panels: Vec<Panel>,
    shades: Vec<Shade>,
}

impl TimePlot {
    /// An empty figure; the x label is `"time (s)"` until [`TimePlot::x_label`] changes it.
    pub fn new(title: &str) -> Self {
        Self {
            title: title.to_string(),
            x_label: "time (s)".to_string(),
            x_range: None,
            width: DEFAULT_WIDTH,
            panels: Vec::new(),
            shades: Vec::new(),
        }
    }

    /// Adds a panel below the ones already there.
    pub fn panel(mut self, panel: Panel) -> Self {
        self.panels.push(panel);
        self
    }

    /// Shades `x0..x1` in every panel, labelled in the top one (e.g. a regime of the run).
    pub fn shade(mut self, x0: f64, x1: f64, label: &str) -> Self {
        self.shades.push(Shade {
            x0,
            x1,
            label: label.to_string(),
        });
        self
    }

    pub fn x_label(mut self, label: &str) -> Self {
        self.x_label = label.to_string();
        self
    }

    /// Shows only `lo..hi` of the x axis instead of all data (ignored unless `lo < hi`).
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    /// Total width in pixels (default 900).
    pub fn width(mut self, px: f64) -> Self {
        if px.is_finite() && px >= 200.0 {
            self.width = px;
        }
        self
    }

    pub fn to_svg(&self) -> String {
        let frame = Frame {
            title: &self.title,
            x_label: &self.x_label,
            x_scale: XScale::Linear,
            x_range: self.x_range,
            width: self.width,
            shared_shades: &self.shades,
            shared_vlines: &[],
        };
        let panels: Vec<&Panel> = self.panels.iter().collect();
        render(&frame, &panels)
    }

    /// Writes the SVG to `path`, creating missing parent directories.
    pub fn save(&self, path: &Path) -> io::Result<()> {
        save_svg(path, &self.to_svg())
    }
}

/// Magnitude (dB) and phase (deg) against frequency (Hz), optionally coherence, with the -3 dB
/// bandwidth marked.
///
/// A series keeps its colour in every panel; a coherence series named like a Bode series takes
/// that series' colour.
#[derive(Debug, Clone)]
pub struct BodePlot {
    title: String,
    x_scale: XScale,
    x_range: Option<(f64, f64)>,
    width: f64,
    magnitude: Panel,
    phase: Panel,
    coherence: Option<Panel>,
    markers: Vec<VLine>,
    colors: Vec<(String, Color)>,
}

impl BodePlot {
    /// An empty Bode plot with a logarithmic frequency axis.
    pub fn new(title: &str) -> Self {
        Self {
            title: title.to_string(),
            x_scale: XScale::Log,
            x_range: None,
            width: DEFAULT_WIDTH,
            magnitude: Panel::new("magnitude (dB)").height(220.0),
            phase: Panel::new("phase (deg)")
                .height(170.0)
                .degree_ticks()
                .hide_legend(),
            coherence: None,
            markers: Vec::new(),
            colors: Vec::new(),
        }
    }

    pub fn x_scale(mut self, scale: XScale) -> Self {
        self.x_scale = scale;
        self
    }

    /// Shows only `lo..hi` Hz (ignored unless `lo < hi`, and `lo > 0` on a log axis).
    pub fn x_range(mut self, lo: f64, hi: f64) -> Self {
        self.x_range = Some((lo, hi));
        self
    }

    pub fn magnitude_range(mut self, lo_db: f64, hi_db: f64) -> Self {
        self.magnitude = self.magnitude.y_range(lo_db, hi_db);
        self
    }

    pub fn phase_range(mut self, lo_deg: f64, hi_deg: f64) -> Self {
        self.phase = self.phase.y_range(lo_deg, hi_deg);
        self
    }

    /// Total width in pixels (default 900).
    pub fn width(mut self, px: f64) -> Self {
        if px.is_finite() && px >= 200.0 {
            self.width = px;
        }
        self
    }

    /// Adds a frequency response in the next palette colour. Phase is drawn as given: unwrap it
    /// first if it crosses ±180 deg.
    pub fn series(self, name: &str, f_hz: &[f64], magnitude_db: &[f64], phase_deg: &[f64]) -> Self {
        self.series_styled(name, f_hz, magnitude_db, phase_deg, Style::new())
    }

    /// Adds a frequency response drawn as `style` says (e.g. dashed for a model).
    pub fn series_styled(
        mut self,
        name: &str,
        f_hz: &[f64],
        magnitude_db: &[f64],
        phase_deg: &[f64],
        style: Style,
    ) -> Self {
        let color = style.color.unwrap_or_else(|| self.next_color());
        self.colors.push((name.to_string(), color));
        self.magnitude
            .push_series(name, f_hz, magnitude_db, color, style);
        self.phase.push_series(name, f_hz, phase_deg, color, style);
        self
    }

    /// Adds a coherence panel (0..1) below the phase, or a series to it.
    pub fn coherence(mut self, name: &str, f_hz: &[f64], coherence: &[f64]) -> Self {
        let known = self.colors.iter().find(|(n, _)| n == name).map(|&(_, c)| c);
        let color = known.unwrap_or_else(|| self.next_color());
        let panel = self.coherence.get_or_insert_with(|| {
            Panel::new("coherence")
                .height(110.0)
                .y_range(-0.03, 1.03)
                .hide_legend()
        });
        panel.push_series(name, f_hz, coherence, color, Style::new());
        // Names the magnitude legend does not already show need a legend of their own.
        if known.is_none() {
            panel.legend = true;
        }
        self
    }

    /// Marks the -3 dB bandwidth: a dashed -3 dB line on the magnitude and a vertical line at
    /// `f_hz` labelled "-3 dB at 5.1 Hz". Ignored unless `f_hz` is finite and positive, so an
    /// analysis that found no crossing can pass its NaN straight in.
    pub fn bandwidth(self, f_hz: f64) -> Self {
        let label = format!("-3 dB at {} Hz", format_hz(f_hz));
        self.add_bandwidth(f_hz, label, Color::GRAY)
    }

    /// As [`BodePlot::bandwidth`], for one of several series: the marker takes the series'
    /// colour and the label its name, "simulated: -3 dB at 5.1 Hz".
    pub fn bandwidth_of(self, series: &str, f_hz: f64) -> Self {
        let color = self
            .colors
            .iter()
            .find(|(n, _)| n == series)
            .map_or(Color::GRAY, |&(_, c)| c);
        let label = format!("{series}: -3 dB at {} Hz", format_hz(f_hz));
        self.add_bandwidth(f_hz, label, color)
    }

    pub fn to_svg(&self) -> String {
        let frame = Frame {
            title: &self.title,
            x_label: "frequency (Hz)",
            x_scale: self.x_scale,
            x_range: self.x_range,
            width: self.width,
            shared_shades: &[],
            shared_vlines: &self.markers,
        };
        let mut panels = vec![&self.magnitude, &self.phase];
        panels.extend(self.coherence.as_ref());
        render(&frame, &panels)
    }

    /// Writes the SVG to `path`, creating missing parent directories.
    pub fn save(&self, path: &Path) -> io::Result<()> {
        save_svg(path, &self.to_svg())
    }

    fn next_color(&self) -> Color {
        let auto = self
            .colors
            .iter()
            .filter(|(_, c)| PALETTE.contains(c))
            .count();
        PALETTE[auto % PALETTE.len()]
    }

    fn add_bandwidth(mut self, f_hz: f64, label: String, color: Color) -> Self {
        if !(f_hz.is_finite() && f_hz > 0.0) {
            return self;
        }
        if !self.magnitude.hlines.iter().any(|h| h.label == "-3 dB") {
            self.magnitude = self.magnitude.hline(-3.0, "-3 dB");
        }
        self.markers.push(VLine {
            x: f_hz,
            label,
            color,
            label_at_bottom: true,
        });
        self
    }
}

/// Tick positions at 1-2-5 steps (times a power of ten) inside `lo..=hi`, as many as fit within
/// `max_count` intervals. Empty if the range is not finite or empty.
///
/// `nice_ticks(0.0, 9.7, 5)` is `[0, 2, 4, 6, 8]`.
pub fn nice_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Vec::new();
    }
    let raw = (hi - lo) / max_count.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .find(|&s| s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * magnitude);
    ticks_with_step(lo, hi, step)
}

/// Ticks for a logarithmic axis: `(labelled, unlabelled)`. Labelled are the decades, or 1-2-5
/// (then 1..9) times a decade when the range holds too few decades to read it.
pub fn log_ticks(lo: f64, hi: f64) -> (Vec<f64>, Vec<f64>) {
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi) {
        return (Vec::new(), Vec::new());
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    let candidates: Vec<(u32, f64)> = (first..=last)
        .flat_map(|k| (1..=9u32).map(move |m| (m, f64::from(m) * 10f64.powi(k))))
        .filter(|&(_, v)| inside(v))
        .collect();
    for mantissas in [&[1u32][..], &[1, 2, 5], &[1, 2, 3, 4, 5, 6, 7, 8, 9]] {
        let (major, minor): (Vec<_>, Vec<_>) =
            candidates.iter().partition(|(m, _)| mantissas.contains(m));
        if major.len() >= 2 || mantissas.len() == 9 {
            return (
                major.iter().map(|&(_, v)| v).collect(),
                minor.iter().map(|&(_, v)| v).collect(),
            );
        }
    }
    (Vec::new(), Vec::new())
}

fn degree_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    let span = hi - lo;
    match [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0, 360.0]
        .into_iter()
        .find(|&s| span / s <= max_count.max(1) as f64)
    {
        Some(step) => ticks_with_step(lo, hi, step),
        None => nice_ticks(lo, hi, max_count),
    }
}

fn ticks_with_step(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    // Multiples of the step rather than repeated addition, so 0.1-steps do not drift.
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A tick label with as many decimals as the step needs, never "-0".
fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10() - 1e-9).ceil().max(0.0) as usize
    };
    let text = format!("{v:.decimals$}");
    if text.starts_with('-') && text[1..].bytes().all(|b| b == b'0' || b == b'.') {
        text[1..].to_string()
    } else {
        text
    }
}

fn log_tick_label(v: f64) -> String {
    let decade = (v.log10() + 1e-9).floor();
    tick_label(v, 10f64.powf(decade))
}

fn format_hz(f: f64) -> String {
    match f {
        f if f >= 100.0 => format!("{f:.0}"),
        f if f >= 1.0 => format!("{f:.1}"),
        f if f >= 0.1 => format!("{f:.2}"),
        f => format!("{f:.3}"),
    }
}

fn save_svg(path: &Path, svg: &str) -> io::Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        fs::create_dir_all(dir)?;
    }
    fs::write(path, svg)
}

/// What every figure type hands to [`render`].
struct Frame<'a> {
    title: &'a str,
    x_label: &'a str,
    x_scale: XScale,
    x_range: Option<(f64, f64)>,
    width: f64,
    /// Drawn in every panel, labelled in the top one.
    shared_shades: &'a [Shade],
    shared_vlines: &'a [VLine],
}

/// Maps data values to pixels along one direction.
#[derive(Debug, Clone, Copy)]
struct Axis {
    lo: f64,
    hi: f64,
    log: bool,
    px_lo: f64,
    px_hi: f64,
}

impl Axis {
    fn new(lo: f64, hi: f64, log: bool, px_lo: f64, px_hi: f64) -> Self {
        Self {
            lo,
            hi,
            log,
            px_lo,
            px_hi,
        }
    }

    fn transform(&self, v: f64) -> Option<f64> {
        let t = if self.log {
            if v > 0.0 { v.log10() } else { return None }
        } else {
            v
        };
        t.is_finite().then_some(t)
    }

    /// Pixel coordinate of `v`; `None` for NaN, infinities and, on a log axis, `v <= 0`.
    fn px(self, v: f64) -> Option<f64> {
        let t = self.transform(v)?;
        let (t_lo, t_hi) = (self.transform(self.lo)?, self.transform(self.hi)?);
        let px = self.px_lo + (t - t_lo) / (t_hi - t_lo) * (self.px_hi - self.px_lo);
        let (min, max) = (self.px_lo.min(self.px_hi), self.px_lo.max(self.px_hi));
        Some(px.clamp(min - MAX_OVERSHOOT_PX, max + MAX_OVERSHOOT_PX))
    }

    fn contains(&self, v: f64) -> bool {
        self.transform(v).is_some() && v >= self.lo && v <= self.hi
    }
}

fn valid_range(range: Option<(f64, f64)>, log: bool) -> Option<(f64, f64)> {
    range.filter(|&(lo, hi)| lo.is_finite() && hi.is_finite() && lo < hi && (!log || lo > 0.0))
}

fn resolve_x_range(frame: &Frame, panels: &[&Panel]) -> (f64, f64) {
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
fn resolve_y_range(panel: &Panel, x_axis: &Axis) -> (f64, f64) {
    if let Some(range) = valid_range(panel.y_range, false) {
        return range;
    }
    let visible = panel
        .series
        .iter()
        .flat_map(|s| s.x.iter().zip(&s.y))
        .filter(|&(&x, y)| y.is_finite() && x_axis.contains(x))
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

/// A series reduced to what one pixel column can show: runs of pixel points, a new run after
/// every NaN gap.
fn decimate(x: &[f64], y: &[f64], x_axis: &Axis, y_axis: &Axis) -> Vec<Vec<(f64, f64)>> {
    let sorted = x.iter().filter(|v| !v.is_nan()).is_sorted();
    if !sorted {
        return thin_unsorted(x, y, x_axis, y_axis);
    }
    let columns = (x_axis.px_hi - x_axis.px_lo).ceil() as i64;
    let mut out = Decimator::default();
    for (&xv, &yv) in x.iter().zip(y) {
        let Some(px) = x_axis.px(xv) else {
            out.gap();
            continue;
        };
        // Everything left of the plot shares one column, everything right another: enough
        // to draw the clipped line into the edge.
        let column = ((px - x_axis.px_lo).floor() as i64).clamp(-1, columns + 1);
        out.enter_column(column);
        match y_axis.px(yv) {
            Some(py) => out.point(px, py),
            None => out.gap(),
        }
    }
    out.finish()
}

/// Per-column reduction to first, min, max and last point (the "M4" scheme).
#[derive(Default)]
struct Decimator {
    runs: Vec<Vec<(f64, f64)>>,
    current: Vec<(f64, f64)>,
    column: Option<i64>,
    /// (sample count in column, px, py) of first, lowest, highest, last finite point.
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

    fn point(&mut self, px: f64, py: f64) {
        // A gap with finite points on both sides inside one pixel column is invisible; it
        // would only multiply path pieces on a signal that drops out at a high rate.
        self.gap_after = false;
        self.count += 1;
        let p = (self.count, px, py);
        if self.first.is_none() {
            self.first = Some(p);
            self.min = p;
            self.max = p;
        }
        // Pixel y grows downwards; "min" and "max" here are just the two extremes.
        if py < self.min.2 {
            self.min = p;
        }
        if py > self.max.2 {
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
        for (k, px, py) in points {
            if previous != Some(k) {
                self.current.push((px, py));
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
fn thin_unsorted(x: &[f64], y: &[f64], x_axis: &Axis, y_axis: &Axis) -> Vec<Vec<(f64, f64)>> {
    let stride = x.len().div_ceil(MAX_UNSORTED_POINTS).max(1);
    let mut runs = Vec::new();
    let mut current = Vec::new();
    for (&xv, &yv) in x.iter().zip(y).step_by(stride) {
        match (x_axis.px(xv), y_axis.px(yv)) {
            (Some(px), Some(py)) => current.push((px, py)),
            _ if !current.is_empty() => runs.push(std::mem::take(&mut current)),
            _ => {}
        }
    }
    if !current.is_empty() {
        runs.push(current);
    }
    runs
}

/// The SVG text being built. Writing to a `String` cannot fail, so results are discarded.
struct Svg {
    out: String,
}

impl Svg {
    fn new(width: f64, height: f64) -> Self {
        let mut svg = Self {
            out: String::with_capacity(64 * 1024),
        };
        svg.raw(format_args!(
            "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width:.0}\" height=\"{height:.0}\" \
             viewBox=\"0 0 {width:.0} {height:.0}\" font-family=\"sans-serif\">\n"
        ));
        svg
    }

    fn raw(&mut self, args: fmt::Arguments) {
        let _ = self.out.write_fmt(args);
    }

    fn line(&mut self, (x1, y1): (f64, f64), (x2, y2): (f64, f64), stroke: &str, extra: &str) {
        self.raw(format_args!(
            "<line x1=\"{x1:.1}\" y1=\"{y1:.1}\" x2=\"{x2:.1}\" y2=\"{y2:.1}\" stroke=\"{stroke}\"{extra}/>\n"
        ));
    }

    /// Text; `extra` carries further attributes, already escaped.
    fn text(
        &mut self,
        (x, y): (f64, f64),
        size: f64,
        anchor: &str,
        fill: &str,
        extra: &str,
        content: &str,
    ) {
        self.raw(format_args!(
            "<text x=\"{x:.1}\" y=\"{y:.1}\" font-size=\"{size}\" text-anchor=\"{anchor}\" \
             fill=\"{fill}\"{extra}>{}</text>\n",
            Escaped(content)
        ));
    }

    /// Text over data, on a pale box so it stays readable where lines cross it. (A text halo
    /// through `paint-order` would be lighter, but not every SVG renderer supports it.)
    fn label(&mut self, label: &Label) {
        let Label {
            at: (x, y),
            anchor,
            size,
            ..
        } = *label;
        let width = text_width(&label.text, size) + 4.0;
        let left = match anchor {
            "end" => x - width + 2.0,
            "middle" => x - width / 2.0,
            _ => x - 2.0,
        };
        self.raw(format_args!(
            "<rect x=\"{left:.1}\" y=\"{:.1}\" width=\"{width:.1}\" height=\"{:.1}\" \
             fill=\"#ffffff\" fill-opacity=\"0.8\" rx=\"2\"/>\n",
            y - size * 0.95,
            size * 1.3
        ));
        self.text((x, y), size, anchor, &label.color, "", &label.text);
    }

    fn finish(mut self) -> String {
        self.out.push_str("</svg>\n");
        self.out
    }
}

/// Text escaped for XML content and attribute values.
struct Escaped<'a>(&'a str);

impl fmt::Display for Escaped<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for c in self.0.chars() {
            match c {
                '&' => f.write_str("&amp;")?,
                '<' => f.write_str("&lt;")?,
                '>' => f.write_str("&gt;")?,
                '"' => f.write_str("&quot;")?,
                '\'' => f.write_str("&apos;")?,
                // Control characters are not allowed in XML 1.0 at all.
                c if c.is_control() => f.write_char(' ')?,
                c => f.write_char(c)?,
            }
        }
        Ok(())
    }
}

/// Annotation text, drawn after the data and the frame so nothing covers it.
struct Label {
    at: (f64, f64),
    anchor: &'static str,
    size: f64,
    color: String,
    text: String,
}

/// Rough width of a label: no font metrics here, and sans-serif averages about 0.56 em.
fn text_width(text: &str, size: f64) -> f64 {
    text.chars().count() as f64 * size * 0.56
}

/// A 1 px line on a pixel centre, so it is drawn sharp instead of smeared over two pixels.
fn crisp(v: f64) -> f64 {
    v.floor() + 0.5
}

fn dash_attr(dashed: bool) -> &'static str {
    if dashed {
        " stroke-dasharray=\"7 4\""
    } else {
        ""
    }
}

fn render(frame: &Frame, panels: &[&Panel]) -> String {
    let log = frame.x_scale == XScale::Log;
    let (plot_left, plot_right) = (MARGIN_LEFT, frame.width - MARGIN_RIGHT);
    let (x_lo, x_hi) = resolve_x_range(frame, panels);
    let x_axis = Axis::new(x_lo, x_hi, log, plot_left, plot_right);
    let (x_major, x_minor) = if log {
        log_ticks(x_lo, x_hi)
    } else {
        let max_ticks = ((plot_right - plot_left) / 85.0).max(2.0) as usize;
        (nice_ticks(x_lo, x_hi, max_ticks), Vec::new())
    };
    let x_step = x_major
        .windows(2)
        .map(|w| w[1] - w[0])
        .next()
        .unwrap_or(1.0);

    let title_height = if frame.title.is_empty() {
        NO_TITLE_HEIGHT
    } else {
        TITLE_HEIGHT
    };
    let height =
        title_height + panels.iter().map(|p| p.top_pad() + p.height).sum::<f64>() + BOTTOM_HEIGHT;
    let mut svg = Svg::new(frame.width, height);
    svg.raw(format_args!(
        "<rect width=\"{:.0}\" height=\"{height:.0}\" fill=\"#ffffff\"/>\n",
        frame.width
    ));
    if !frame.title.is_empty() {
        svg.text(
            (frame.width / 2.0, 25.0),
            16.0,
            "middle",
            TEXT,
            " font-weight=\"600\"",
            frame.title,
        );
    }

    // Tints by label, in order of first appearance, so a regime has one colour everywhere.
    let mut shade_labels: Vec<&str> = Vec::new();
    for shade in frame
        .shared_shades
        .iter()
        .chain(panels.iter().flat_map(|p| &p.shades))
    {
        if !shade_labels.contains(&shade.label.as_str()) {
            shade_labels.push(&shade.label);
        }
    }
    let tint = |label: &str| {
        let k = shade_labels.iter().position(|l| *l == label).unwrap_or(0);
        SHADE_FILLS[k % SHADE_FILLS.len()]
    };

    let mut top = title_height;
    for (index, panel) in panels.iter().enumerate() {
        top += panel.top_pad();
        let bottom = top + panel.height;
        let (y_lo, y_hi) = resolve_y_range(panel, &x_axis);
        let y_axis = Axis::new(y_lo, y_hi, false, bottom, top);
        let max_y_ticks = (panel.height / 34.0).max(2.0) as usize;
        let y_ticks = match panel.y_ticks {
            YTicks::Decimal => nice_ticks(y_lo, y_hi, max_y_ticks),
            YTicks::Degrees => degree_ticks(y_lo, y_hi, max_y_ticks),
        };
        let y_step = y_ticks
            .windows(2)
            .map(|w| w[1] - w[0])
            .next()
            .unwrap_or(1.0);
        let is_top = index == 0;

        svg.raw(format_args!(
            "<clipPath id=\"clip{index}\"><rect x=\"{plot_left:.1}\" y=\"{top:.1}\" \
             width=\"{:.1}\" height=\"{:.1}\"/></clipPath>\n",
            plot_right - plot_left,
            panel.height
        ));

        let mut labels = Vec::new();

        // Shaded intervals, under everything else.
        let shared = frame.shared_shades.iter().map(|s| (s, is_top));
        let own = panel.shades.iter().map(|s| (s, true));
        for (shade, labelled) in shared.chain(own) {
            let ends = (x_axis.px(shade.x0), x_axis.px(shade.x1));
            let (Some(a), Some(b)) = ends else { continue };
            let (a, b) = (a.min(b).max(plot_left), a.max(b).min(plot_right));
            if b <= a {
                continue;
            }
            svg.raw(format_args!(
                "<rect x=\"{a:.1}\" y=\"{top:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"{}\"/>\n",
                b - a,
                panel.height,
                tint(&shade.label)
            ));
            if labelled && !shade.label.is_empty() && text_width(&shade.label, 10.0) + 6.0 < b - a {
                labels.push(Label {
                    at: (a + 4.0, top + 13.0),
                    anchor: "start",
                    size: 10.0,
                    color: TEXT_SOFT.to_string(),
                    text: shade.label.clone(),
                });
            }
        }

        // Grid.
        svg.raw(format_args!(
            "<g shape-rendering=\"crispEdges\" stroke-width=\"1\">\n"
        ));
        for &x in &x_minor {
            if let Some(px) = x_axis.px(x) {
                svg.line((crisp(px), top), (crisp(px), bottom), GRID_MINOR, "");
            }
        }
        for &x in &x_major {
            if let Some(px) = x_axis.px(x) {
                svg.line((crisp(px), top), (crisp(px), bottom), GRID, "");
            }
        }
        for &y in &y_ticks {
            if let Some(py) = y_axis.px(y) {
                let color = if y.abs() < y_step * 1e-6 {
                    GRID_ZERO
                } else {
                    GRID
                };
                svg.line((plot_left, crisp(py)), (plot_right, crisp(py)), color, "");
            }
        }
        svg.raw(format_args!("</g>\n"));

        // Series, clipped to the plotting area.
        svg.raw(format_args!(
            "<g clip-path=\"url(#clip{index})\" fill=\"none\" stroke-width=\"1.6\" \
             stroke-linejoin=\"round\" stroke-linecap=\"round\">\n"
        ));
        for series in &panel.series {
            draw_series(&mut svg, series, &x_axis, &y_axis);
        }
        svg.raw(format_args!("</g>\n"));

        // Limit lines and markers over the data: they are what the reader compares against.
        for h in &panel.hlines {
            let Some(py) = y_axis.px(h.y).filter(|py| (top..=bottom).contains(py)) else {
                continue;
            };
            svg.line(
                (plot_left, py),
                (plot_right, py),
                "#555555",
                " stroke-width=\"1.2\" stroke-dasharray=\"5 4\"",
            );
            if !h.label.is_empty() {
                // Below the line when above it would leave the panel.
                let ty = if py - top < 16.0 { py + 13.0 } else { py - 4.0 };
                labels.push(Label {
                    at: (plot_right - 4.0, ty),
                    anchor: "end",
                    size: 11.0,
                    color: TEXT_SOFT.to_string(),
                    text: h.label.clone(),
                });
            }
        }
        let shared = frame.shared_vlines.iter().map(|v| (v, is_top));
        let own = panel.vlines.iter().map(|v| (v, true));
        let mut stacked = 0.0;
        for (v, labelled) in shared.chain(own) {
            let Some(px) = x_axis
                .px(v.x)
                .filter(|px| (plot_left..=plot_right).contains(px))
            else {
                continue;
            };
            let color = v.color.to_string();
            svg.line(
                (px, top),
                (px, bottom),
                &color,
                " stroke-width=\"1.2\" stroke-dasharray=\"5 4\"",
            );
            if labelled && !v.label.is_empty() {
                let width = text_width(&v.label, 11.0);
                let (ty, prefer_left) = if v.label_at_bottom {
                    (bottom - 8.0 - stacked * 16.0, true)
                } else {
                    (top + 15.0 + stacked * 16.0, false)
                };
                stacked += 1.0;
                let fits_left = px - 5.0 - width > plot_left;
                let fits_right = px + 5.0 + width < plot_right;
                let (tx, anchor) = if (prefer_left && fits_left) || !fits_right {
                    (px - 5.0, "end")
                } else {
                    (px + 5.0, "start")
                };
                labels.push(Label {
                    at: (tx, ty),
                    anchor,
                    size: 11.0,
                    color: color.clone(),
                    text: v.label.clone(),
                });
            }
        }

        svg.raw(format_args!(
            "<rect x=\"{:.1}\" y=\"{:.1}\" width=\"{:.1}\" height=\"{:.1}\" fill=\"none\" \
             stroke=\"{FRAME}\" stroke-width=\"1\" shape-rendering=\"crispEdges\"/>\n",
            crisp(plot_left),
            crisp(top),
            (plot_right - plot_left).round(),
            panel.height.round()
        ));
        for label in &labels {
            svg.label(label);
        }

        for &y in &y_ticks {
            if let Some(py) = y_axis.px(y) {
                svg.text(
                    (plot_left - 7.0, py + 4.0),
                    11.0,
                    "end",
                    TEXT_SOFT,
                    "",
                    &tick_label(y, y_step),
                );
            }
        }
        let mid = (top + bottom) / 2.0;
        svg.raw(format_args!(
            "<text transform=\"translate(18,{mid:.1}) rotate(-90)\" font-size=\"13\" \
             text-anchor=\"middle\" fill=\"{TEXT}\">{}</text>\n",
            Escaped(&panel.y_label)
        ));

        if panel.shows_legend() {
            draw_legend(&mut svg, panel, plot_left, top - 8.0);
        }
        top = bottom;
    }

    // Shared x axis under the bottom panel.
    for &x in &x_major {
        if let Some(px) = x_axis.px(x) {
            svg.line(
                (crisp(px), top),
                (crisp(px), top + 4.0),
                FRAME,
                " shape-rendering=\"crispEdges\"",
            );
            let label = if log {
                log_tick_label(x)
            } else {
                tick_label(x, x_step)
            };
            svg.text((px, top + 17.0), 11.0, "middle", TEXT_SOFT, "", &label);
        }
    }
    svg.text(
        ((plot_left + plot_right) / 2.0, top + 38.0),
        13.0,
        "middle",
        TEXT,
        "",
        frame.x_label,
    );
    svg.finish()
}

fn draw_series(svg: &mut Svg, series: &Series, x_axis: &Axis, y_axis: &Axis) {
    let runs = decimate(&series.x, &series.y, x_axis, y_axis);
    if runs.is_empty() {
        return;
    }
    svg.raw(format_args!(
        "<path stroke=\"{}\"{} d=\"",
        series.color,
        dash_attr(series.dashed)
    ));
    for run in &runs {
        for (k, (x, y)) in run.iter().enumerate() {
            let command = match k {
                0 => "M",
                1 => "L",
                _ => " ",
            };
            svg.raw(format_args!("{command}{x:.1},{y:.1}"));
        }
        if run.len() == 1 {
            // A lone sample between dropouts: a zero-length segment that the round cap turns
            // into a dot.
            svg.raw(format_args!("h0"));
        }
    }
    svg.raw(format_args!("\"/>\n"));

    if series.markers {
        let visible: Vec<(f64, f64)> = series
            .x
            .iter()
            .zip(&series.y)
            .filter(|&(&x, _)| x_axis.contains(x))
            .filter_map(|(&x, &y)| Some((x_axis.px(x)?, y_axis.px(y)?)))
            .collect();
        if visible.len() <= MAX_MARKERS {
            svg.raw(format_args!(
                "<g fill=\"{}\" stroke=\"none\">",
                series.color
            ));
            for (x, y) in visible {
                svg.raw(format_args!(
                    "<circle cx=\"{x:.1}\" cy=\"{y:.1}\" r=\"2.6\"/>"
                ));
            }
            svg.raw(format_args!("</g>\n"));
        }
    }
}

fn draw_legend(svg: &mut Svg, panel: &Panel, left: f64, baseline: f64) {
    let mut x = left;
    for series in panel.series.iter().filter(|s| !s.name.is_empty()) {
        let color = series.color.to_string();
        let attrs = format!(" stroke-width=\"2\"{}", dash_attr(series.dashed));
        svg.line(
            (x, baseline - 4.0),
            (x + 24.0, baseline - 4.0),
            &color,
            &attrs,
        );
        if series.markers {
            svg.raw(format_args!(
                "<circle cx=\"{:.1}\" cy=\"{:.1}\" r=\"2.6\" fill=\"{color}\"/>\n",
                x + 12.0,
                baseline - 4.0
            ));
        }
        svg.text((x + 30.0, baseline), 12.0, "start", TEXT, "", &series.name);
        x += 30.0 + text_width(&series.name, 12.0) + 18.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Checks what a renderer needs from XML: one root `<svg>`, tags that nest and close,
    /// quotes that pair up, entities only where escaping put them.
    fn assert_well_formed(svg: &str) {
        assert!(svg.starts_with("<svg "), "must start with <svg");
        assert!(svg.trim_end().ends_with("</svg>"), "must end with </svg>");
        let mut stack: Vec<&str> = Vec::new();
        let mut rest = svg;
        let mut roots = 0;
        while let Some(start) = rest.find('<') {
            assert!(
                !rest[..start].contains('>'),
                "stray '>' in text: {}",
                &rest[..start]
            );
            let end = start + rest[start..].find('>').expect("tag not closed");
            let tag = &rest[start + 1..end];
            assert!(!tag.contains('<'), "'<' inside tag: {tag}");
            assert_eq!(tag.matches('"').count() % 2, 0, "unpaired quote in: {tag}");
            if let Some(name) = tag.strip_prefix('/') {
                assert_eq!(stack.pop(), Some(name.trim()), "closing tag mismatch");
            } else {
                if stack.is_empty() {
                    roots += 1;
                }
                if !tag.ends_with('/') {
                    stack.push(tag.split_whitespace().next().expect("tag name"));
                }
            }
            rest = &rest[end + 1..];
        }
        assert!(stack.is_empty(), "unclosed tags: {stack:?}");
        assert_eq!(roots, 1, "exactly one root element");
        for (i, _) in svg.match_indices('&') {
            let entity = &svg[i..svg[i..].find(';').map_or(svg.len(), |e| i + e + 1)];
            assert!(
                ["&amp;", "&lt;", "&gt;", "&quot;", "&apos;"].contains(&entity),
                "bad entity {entity}"
            );
        }
    }

    fn step_response(n: usize) -> (Vec<f64>, Vec<f64>, Vec<f64>, Vec<f64>) {
        let dt = 120.0 / n as f64;
        let t: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
        let r: Vec<f64> = t
            .iter()
            .map(|&t| if (t % 4.0) < 2.0 { 10.0 } else { -10.0 })
            .collect();
        let y: Vec<f64> = t
            .iter()
            .map(|&t| 10.0 * (t * 0.8).sin() + 0.3 * (t * 340.0).sin())
            .collect();
        let i: Vec<f64> = t.iter().map(|&t| 22.0 * (t * 3.1).cos()).collect();
        (t, r, y, i)
    }

    fn time_plot(n: usize) -> TimePlot {
        let (t, r, y, i) = step_response(n);
        TimePlot::new("Square wave <10 deg> & current")
            .panel(
                Panel::new("steering wheel (deg)")
                    .series_styled(
                        "reference",
                        &t,
                        &r,
                        Style::new().color(Color::BLACK).dashed(),
                    )
                    .series("column encoder", &t, &y),
            )
            .panel(
                Panel::new("motor current (A)")
                    .series("current", &t, &i)
                    .hline(20.0, "+20 A limit")
                    .hline(-20.0, "-20 A limit")
                    .hide_legend(),
            )
            .shade(10.0, 30.0, "saturated")
            .shade(50.0, 60.0, "saturated")
            .shade(70.0, 80.0, "dead band")
    }

    fn bode(n: usize) -> BodePlot {
        let f: Vec<f64> = (0..n)
            .map(|k| 0.1 * 10f64.powf(3.0 * k as f64 / (n - 1) as f64))
            .collect();
        let response = |wn: f64| -> (Vec<f64>, Vec<f64>) {
            f.iter()
                .map(|&f| {
                    let u = f / wn;
                    let (re, im) = (1.0 - u * u, 2.0 * 0.6 * u);
                    (
                        -10.0 * (re * re + im * im).log10(),
                        -im.atan2(re).to_degrees(),
                    )
                })
                .unzip()
        };
        let (m1, p1) = response(5.1);
        let (m2, p2) = response(4.8);
        let coherence: Vec<f64> = f
            .iter()
            .map(|&f| 1.0 / (1.0 + (f / 30.0).powi(2)))
            .collect();
        BodePlot::new("Closed loop, 10 deg sweep")
            .series("simulated", &f, &m1, &p1)
            .series_styled("paper model", &f, &m2, &p2, Style::new().dashed())
            .coherence("simulated", &f, &coherence)
            .bandwidth_of("simulated", 5.1)
            .bandwidth_of("paper model", 4.8)
    }

    #[test]
    fn time_plot_is_well_formed_and_escapes_text() {
        let svg = time_plot(5_000).to_svg();
        assert_well_formed(&svg);
        assert!(svg.contains("Square wave &lt;10 deg&gt; &amp; current"));
        assert!(svg.contains("+20 A limit") && svg.contains("saturated"));
        assert!(svg.contains("font-family=\"sans-serif\""));
    }

    #[test]
    fn bode_plot_is_well_formed_and_labels_the_bandwidth() {
        let svg = bode(400).to_svg();
        assert_well_formed(&svg);
        assert!(svg.contains("simulated: -3 dB at 5.1 Hz"), "{svg}");
        assert!(svg.contains(">-3 dB<"));
        assert!(svg.contains("coherence"));
        let linear = bode(50).x_scale(XScale::Linear).bandwidth(5.1).to_svg();
        assert_well_formed(&linear);
        assert!(linear.contains(">-3 dB at 5.1 Hz<"));
    }

    #[test]
    fn long_series_are_decimated_to_a_small_file() {
        let svg = time_plot(240_000).to_svg();
        assert_well_formed(&svg);
        // Three series of 240 000 samples; undecimated they would take several megabytes.
        assert!(svg.len() < 150_000, "{} bytes", svg.len());
    }

    #[test]
    fn decimation_keeps_a_single_sample_spike() {
        let n = 240_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let mut y = vec![0.0; n];
        y[123_457] = 100.0;
        let x_axis = Axis::new(0.0, n as f64, false, 0.0, 800.0);
        let y_axis = Axis::new(0.0, 100.0, false, 200.0, 0.0);
        let runs = decimate(&x, &y, &x_axis, &y_axis);
        assert_eq!(runs.len(), 1);
        assert!(runs[0].len() <= 4 * 802, "{} points", runs[0].len());
        let top = runs[0].iter().map(|p| p.1).fold(f64::INFINITY, f64::min);
        assert!(top.abs() < 1e-9, "spike drawn at y = {top}");
    }

    #[test]
    fn nan_samples_break_the_line_and_never_reach_the_file() {
        let t: Vec<f64> = (0..1000).map(|i| i as f64 * 0.01).collect();
        let mut y: Vec<f64> = t.iter().map(|t| t.sin()).collect();
        for v in &mut y[300..400] {
            *v = f64::NAN;
        }
        y[500] = f64::INFINITY;
        y[700] = f64::NAN;
        y[702] = f64::NAN;
        let mut t_bad = t.clone();
        t_bad[10] = f64::NAN;
        let svg = TimePlot::new("dropouts")
            .panel(
                Panel::new("angle (deg)")
                    .series("with gaps", &t, &y)
                    .series("all missing", &t, &vec![f64::NAN; t.len()])
                    .series("bad time", &t_bad, &t)
                    .series_styled("markers", &t[..50], &y[..50], Style::new().markers()),
            )
            .to_svg();
        assert_well_formed(&svg);
        let lower = svg.to_lowercase();
        assert!(
            !lower.contains("nan") && !lower.contains("inf"),
            "non-finite value in SVG"
        );

        let x_axis = Axis::new(0.0, 10.0, false, 0.0, 800.0);
        let y_axis = Axis::new(-1.0, 1.0, false, 200.0, 0.0);
        let runs = decimate(&t, &y, &x_axis, &y_axis);
        // Gaps at 300..400, 500, 700 and 702; the lone sample 701 is a run of its own.
        assert_eq!(
            runs.len(),
            5,
            "{:?}",
            runs.iter().map(Vec::len).collect::<Vec<_>>()
        );
        assert!(runs.iter().any(|r| r.len() == 1));
    }

    #[test]
    fn empty_figures_still_render() {
        assert_well_formed(&TimePlot::new("").to_svg());
        assert_well_formed(&TimePlot::new("no data").panel(Panel::new("x")).to_svg());
        assert_well_formed(&BodePlot::new("no data").bandwidth(f64::NAN).to_svg());
        let constant =
            TimePlot::new("flat").panel(Panel::new("y").series("c", &[0.0, 1.0], &[3.0, 3.0]));
        assert_well_formed(&constant.to_svg());
    }

    #[test]
    fn unsorted_x_is_thinned_not_bucketed() {
        let x: Vec<f64> = (0..100_000).map(|i| ((i * 7919) % 1000) as f64).collect();
        let svg = TimePlot::new("xy")
            .panel(Panel::new("y").series("s", &x, &x))
            .to_svg();
        assert_well_formed(&svg);
        assert!(svg.len() < 400_000, "{} bytes", svg.len());
    }

    fn assert_ticks(got: &[f64], expected: &[f64]) {
        assert_eq!(got.len(), expected.len(), "{got:?} vs {expected:?}");
        for (g, e) in got.iter().zip(expected) {
            assert!((g - e).abs() < 1e-9, "{got:?} vs {expected:?}");
        }
    }

    #[test]
    fn ticks_use_one_two_five_steps() {
        assert_ticks(&nice_ticks(0.0, 9.7, 5), &[0.0, 2.0, 4.0, 6.0, 8.0]);
        assert_ticks(
            &nice_ticks(-21.0, 21.0, 5),
            &[-20.0, -10.0, 0.0, 10.0, 20.0],
        );
        assert_ticks(&nice_ticks(0.0, 0.3, 3), &[0.0, 0.1, 0.2, 0.3]);
        assert_ticks(
            &nice_ticks(0.0, 120.0, 10),
            &[0.0, 20.0, 40.0, 60.0, 80.0, 100.0, 120.0],
        );
        assert_ticks(&nice_ticks(0.013, 0.048, 4), &[0.02, 0.03, 0.04]);
        assert!(nice_ticks(1.0, 1.0, 5).is_empty());
        assert!(nice_ticks(f64::NAN, 1.0, 5).is_empty());
    }

    #[test]
    fn tick_labels_have_the_decimals_of_the_step() {
        assert_eq!(tick_label(0.30000000000000004, 0.1), "0.3");
        assert_eq!(tick_label(-1e-17, 0.1), "0.0");
        assert_eq!(tick_label(20.0, 10.0), "20");
        assert_eq!(tick_label(0.05, 0.05), "0.05");
        assert_eq!(log_tick_label(0.1), "0.1");
        assert_eq!(log_tick_label(100.0), "100");
    }

    #[test]
    fn degree_ticks_fall_on_multiples_of_45() {
        assert_ticks(
            &degree_ticks(-190.0, 5.0, 5),
            &[-180.0, -135.0, -90.0, -45.0, 0.0],
        );
    }

    #[test]
    fn log_ticks_label_decades_or_one_two_five() {
        let (major, minor) = log_ticks(0.1, 100.0);
        assert_ticks(&major, &[0.1, 1.0, 10.0, 100.0]);
        assert_eq!(minor.len(), 8 * 3);
        let (major, _) = log_ticks(2.0, 30.0);
        assert_ticks(&major, &[2.0, 5.0, 10.0, 20.0]);
        let (major, _) = log_ticks(2.5, 4.5);
        assert_ticks(&major, &[3.0, 4.0]);
    }

    #[test]
    fn save_creates_parent_directories() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("plots/sub/bode.svg");
        bode(100).save(&path).expect("save");
        let text = fs::read_to_string(&path).expect("read back");
        assert_well_formed(&text);
    }
}

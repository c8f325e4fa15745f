//! Line charts for the README and the reports, drawn with plotters' SVG backend: stacked time
//! plots ([`TimePlot`]) and Bode plots ([`BodePlot`]). Plotters draws the frame, grid, tick
//! labels, lines and text; this module owns the layout, the ticks (1-2-5 steps, decades,
//! multiples of 45 deg), the decimation of long logs, the clipping and the palette.
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
//! Series are copied in and drawn when [`TimePlot::to_svg`] runs, in the order they were added
//! (a later series lies over an earlier one). Before drawing, a series is decimated to at most
//! four samples per pixel column (first, min, max, last: the line looks the same as with every
//! sample, spikes included), so a 240 000-sample trace costs a few tens of kilobytes. A NaN
//! sample (sensor dropout) lifts the pen: the line breaks there. Lines are cut at the edge of the
//! plotting area (plotters itself would draw across the axes). Colours come from the Okabe-Ito
//! palette, which stays distinguishable with the common colour-vision deficiencies; the
//! background is white so the picture also reads on GitHub's dark theme. Without plotters' font
//! features the SVG backend writes plain `<text>` elements with a sans-serif family and
//! estimates text widths itself, so nothing here needs fonts or system libraries.
use plotters::coord::Shift;
use plotters::coord::ranged1d::{KeyPointHint, NoDefaultFormatting, Ranged, ValueFormatter};
use plotters::element::DashedPathElement;
use plotters::prelude::{
    Cartesian2d, ChartBuilder, ChartContext, Circle, DrawingArea, DrawingAreaErrorKind, FontDesc,
    FontFamily, FontStyle, IntoDrawingArea, LabelAreaPosition, PathElement, RGBColor, Rectangle,
    SVGBackend, ShapeStyle, TextStyle, WHITE,
};
use plotters::style::Color as _;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::fmt;
use std::fs;
use std::io;
use std::ops::Range;
use std::path::Path;

const DEFAULT_WIDTH: f64 = 900.0;
const DEFAULT_PANEL_HEIGHT: u32 = 190;
const MARGIN_LEFT: u32 = 76;
const MARGIN_RIGHT: u32 = 28;
/// Room left of the rotated y label, and below the x label.
const Y_LABEL_INSET: u32 = 8;
const X_LABEL_INSET: u32 = 9;
const TITLE_HEIGHT: u32 = 38;
const NO_TITLE_HEIGHT: u32 = 10;
const LEGEND_HEIGHT: u32 = 24;
/// Space above a panel that has no legend strip.
const PANEL_GAP: u32 = 12;
const BOTTOM_HEIGHT: u32 = 50;
/// Stroke width of data lines in pixels (plotters' SVG backend takes whole pixels).
const LINE_WIDTH: u32 = 2;
const MARKER_RADIUS: u32 = 3;
/// Dash and gap of a dashed series in pixels. The SVG backend has no dash pattern: plotters
/// writes every dash as an element of its own, so short dashes on a long, busy trace (a square
/// wave over 120 s) would cost a hundred kilobytes.
const DASH: (u32, u32) = (12, 6);
/// Markers are drawn only on sparse series; on dense ones they would merge into a smear.
const MAX_MARKERS: usize = 400;
/// Cap for series whose x is not sorted, which the per-column decimation cannot handle.
const MAX_UNSORTED_POINTS: usize = 20_000;
/// How far outside the plot (in plot widths) a coordinate may land; beyond, it is pulled in so
/// the file holds no absurd numbers.
const MAX_OVERSHOOT: f64 = 10.0;

const TEXT: u32 = 0x222222;
const TEXT_SOFT: u32 = 0x555555;
const GRID: u32 = 0xe3e3e3;
const GRID_MINOR: u32 = 0xf1f1f1;
const GRID_ZERO: u32 = 0xc4c4c4;
const FRAME: u32 = 0x444444;
const LIMIT: u32 = 0x555555;
const SHADE_FILLS: [u32; 6] = [0xececec, 0xfde9d2, 0xd9efe5, 0xe9e0f1, 0xfff3c4, 0xdceaf6];

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
    /// `None`: opaque. Lets a series drawn over another show what lies under it.
    pub opacity: Option<f64>,
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

    /// Drawn with this opacity (0 transparent .. 1 opaque; other values are ignored).
    pub fn opacity(self, opacity: f64) -> Self {
        Self {
            opacity: (0.0..=1.0).contains(&opacity).then_some(opacity),
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
    opacity: f64,
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
    height: u32,
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
            self.height = px.min(10_000.0).round() as u32;
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
            opacity: style.opacity.unwrap_or(1.0),
        });
    }

    fn shows_legend(&self) -> bool {
        self.legend && self.series.iter().any(|s| !s.name.is_empty())
    }

    fn top_pad(&self) -> u32 {
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
            self.width = px.min(10_000.0);
        }
        self
    }

    pub fn to_svg(&self) -> String {
        let panels: Vec<&Panel> = self.panels.iter().collect();
        render(&self.frame(), &panels)
    }

    fn try_svg(&self) -> Result<String, String> {
        let panels: Vec<&Panel> = self.panels.iter().collect();
        try_render(&self.frame(), &panels)
    }

    fn frame(&self) -> Frame<'_> {
        Frame {
            title: &self.title,
            x_label: &self.x_label,
            x_scale: XScale::Linear,
            x_range: self.x_range,
            width: self.width,
            shared_shades: &self.shades,
            shared_vlines: &[],
        }
    }

    /// Writes the SVG to `path`, creating missing parent directories.
    pub fn save(&self, path: &Path) -> io::Result<()> {
        save_svg(path, self.try_svg())
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
    wrap_phase: bool,
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
            wrap_phase: false,
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
            self.width = px.min(10_000.0);
        }
        self
    }

    /// Draws the phase wrapped into (-180, 180] deg on a fixed -180..180 axis (unless
    /// [`BodePlot::phase_range`] sets another), the line broken where it wraps. For estimates
    /// whose unwrapped phase runs off through bins of noise and would flatten the band that
    /// matters.
    pub fn wrap_phase(mut self) -> Self {
        self.wrap_phase = true;
        self
    }

    /// Adds a frequency response in the next palette colour. Phase is drawn as given (unwrap it
    /// first if it crosses ±180 deg), or wrapped with [`BodePlot::wrap_phase`].
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
        let phase = self.phase_panel();
        render(&self.frame(), &self.panels(&phase))
    }

    fn try_svg(&self) -> Result<String, String> {
        let phase = self.phase_panel();
        try_render(&self.frame(), &self.panels(&phase))
    }

    /// The phase panel as drawn: as given, or wrapped.
    fn phase_panel(&self) -> std::borrow::Cow<'_, Panel> {
        if !self.wrap_phase {
            return std::borrow::Cow::Borrowed(&self.phase);
        }
        let mut panel = self.phase.clone();
        for series in &mut panel.series {
            (series.x, series.y) = wrapped_phase(&series.x, &series.y);
        }
        if panel.y_range.is_none() {
            panel.y_range = Some((-180.0, 180.0));
        }
        std::borrow::Cow::Owned(panel)
    }

    fn frame(&self) -> Frame<'_> {
        Frame {
            title: &self.title,
            x_label: "frequency (Hz)",
            x_scale: self.x_scale,
            x_range: self.x_range,
            width: self.width,
            shared_shades: &[],
            shared_vlines: &self.markers,
        }
    }

    fn panels<'a>(&'a self, phase: &'a Panel) -> Vec<&'a Panel> {
        let mut panels = vec![&self.magnitude, phase];
        panels.extend(self.coherence.as_ref());
        panels
    }

    /// Writes the SVG to `path`, creating missing parent directories.
    pub fn save(&self, path: &Path) -> io::Result<()> {
        save_svg(path, self.try_svg())
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

/// Phase in degrees wrapped into (-180, 180], with a NaN sample (a break in the line) between
/// two neighbours whose wrapped values lie more than 180 deg apart: there the curve crossed
/// ±180 deg, and a line joining them would run straight across the panel.
fn wrapped_phase(x: &[f64], phase_deg: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let wrap = |p: f64| p - 360.0 * ((p - 180.0) / 360.0).ceil();
    let mut out_x = Vec::with_capacity(x.len());
    let mut out_y = Vec::with_capacity(phase_deg.len());
    let mut previous: Option<(f64, f64)> = None;
    for (&xv, &p) in x.iter().zip(phase_deg) {
        let w = wrap(p);
        if let Some((px, pw)) = previous
            && (w - pw).abs() > 180.0
        {
            out_x.push(0.5 * (px + xv));
            out_y.push(f64::NAN);
        }
        previous = w.is_finite().then_some((xv, w));
        out_x.push(xv);
        out_y.push(w);
    }
    (out_x, out_y)
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

/// Ticks for a logarithmic axis: `(labelled, unlabelled)`. Labelled are 1-2-5 times a decade
/// (what a reader needs to read off a bandwidth such as 2.3 Hz), or only the decades when 1-2-5
/// would give more than `max_count` labels, or 1..9 times a decade when the range is too short
/// for two 1-2-5 labels.
pub fn log_ticks(lo: f64, hi: f64, max_count: usize) -> (Vec<f64>, Vec<f64>) {
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
    let split = |mantissas: &[u32]| -> (Vec<f64>, Vec<f64>) {
        let (major, minor): (Vec<_>, Vec<_>) =
            candidates.iter().partition(|(m, _)| mantissas.contains(m));
        (
            major.iter().map(|&(_, v)| v).collect(),
            minor.iter().map(|&(_, v)| v).collect(),
        )
    };
    let one_two_five = split(&[1, 2, 5]);
    let labels = one_two_five.0.len();
    if (2..=max_count.max(2)).contains(&labels) {
        return one_two_five;
    }
    let decades = split(&[1]);
    if labels > max_count && decades.0.len() >= 2 {
        return decades;
    }
    if labels >= 2 {
        return one_two_five;
    }
    split(&[1, 2, 3, 4, 5, 6, 7, 8, 9])
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

/// Writes a drawn figure; one plotters could not draw is an error, not a file.
fn save_svg(path: &Path, svg: Result<String, String>) -> io::Result<()> {
    let svg = svg.map_err(|e| io::Error::other(format!("figure not drawn: {e}")))?;
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

/// One axis: its data range, linear or decades, and the ticks we chose for it. It is the
/// coordinate type plotters draws with, so the grid, the tick labels, the decimator's pixel
/// columns and the clipping all use one mapping.
#[derive(Debug, Clone)]
struct Scale {
    lo: f64,
    hi: f64,
    log: bool,
    /// Labelled ticks (plotters' bold mesh lines) and unlabelled ones (its light lines).
    major: Vec<f64>,
    minor: Vec<f64>,
    /// Spacing of the labelled ticks on a linear axis: how many decimals a label needs.
    step: f64,
}

impl Scale {
    fn new(lo: f64, hi: f64, log: bool) -> Self {
        Self {
            lo,
            hi,
            log,
            major: Vec::new(),
            minor: Vec::new(),
            step: 1.0,
        }
    }

    fn ticks(mut self, major: Vec<f64>, minor: Vec<f64>) -> Self {
        self.step = major.windows(2).map(|w| w[1] - w[0]).next().unwrap_or(1.0);
        self.major = major;
        self.minor = minor;
        self
    }

    /// The value along the axis' own straight line: itself, or its log10 on a decade axis.
    /// `None` for NaN, infinities and, on a log axis, `v <= 0`.
    fn transform(&self, v: f64) -> Option<f64> {
        let t = if self.log {
            if v > 0.0 { v.log10() } else { return None }
        } else {
            v
        };
        t.is_finite().then_some(t)
    }

    fn inverse(&self, t: f64) -> f64 {
        if self.log { 10f64.powf(t) } else { t }
    }

    /// Where `v` lies along the axis: 0 at `lo`, 1 at `hi`.
    fn fraction(&self, v: f64) -> Option<f64> {
        let (t, t_lo, t_hi) = (
            self.transform(v)?,
            self.transform(self.lo)?,
            self.transform(self.hi)?,
        );
        Some((t - t_lo) / (t_hi - t_lo)).filter(|f| f.is_finite())
    }

    fn contains(&self, v: f64) -> bool {
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
fn resolve_y_range(panel: &Panel, x_scale: &Scale) -> (f64, f64) {
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

/// A series reduced to what `columns` pixel columns can show: runs of samples `(x, y)`, a new
/// run after every NaN gap. Plotters would otherwise write every sample of a 120 s log.
fn decimate(x: &[f64], y: &[f64], x_scale: &Scale, columns: i64) -> Vec<Vec<(f64, f64)>> {
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
struct Decimator {
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
fn thin_unsorted(x: &[f64], y: &[f64], x_scale: &Scale) -> Vec<Vec<(f64, f64)>> {
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

/// Cuts runs to the plotting box (plotters draws wherever it is told, also over the axes): a
/// line leaving the box ends on its edge, one coming back starts a new run there. Straight in
/// the axis' own coordinates, so on a log axis it is cut in decades, as it is drawn.
fn clip(runs: Vec<Vec<(f64, f64)>>, x: &Scale, y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let (Some(x_lo), Some(x_hi)) = (x.transform(x.lo), x.transform(x.hi)) else {
        return Vec::new();
    };
    let bounds = [x_lo, x_hi, y.0, y.1];
    let inside = |(tx, ty): (f64, f64)| (x_lo..=x_hi).contains(&tx) && (y.0..=y.1).contains(&ty);
    let mut out = Vec::new();
    for run in runs {
        let points: Vec<(f64, f64)> = run
            .iter()
            .filter_map(|&(px, py)| Some((x.transform(px)?, py)))
            .collect();
        let mut current: Vec<(f64, f64)> = Vec::new();
        if let [only] = points[..] {
            if inside(only) {
                out.push(vec![(x.inverse(only.0), only.1)]);
            }
            continue;
        }
        for pair in points.windows(2) {
            let Some((a, b, cut_end)) = clip_segment(pair[0], pair[1], bounds) else {
                if !current.is_empty() {
                    out.push(std::mem::take(&mut current));
                }
                continue;
            };
            if current.is_empty() {
                current.push((x.inverse(a.0), a.1));
            }
            current.push((x.inverse(b.0), b.1));
            if cut_end {
                out.push(std::mem::take(&mut current));
            }
        }
        if !current.is_empty() {
            out.push(current);
        }
    }
    out
}

type Point = (f64, f64);

/// Liang-Barsky: the part of `p0..p1` inside `[x_lo, x_hi, y_lo, y_hi]`, and whether the end
/// was cut off.
fn clip_segment(
    p0: (f64, f64),
    p1: (f64, f64),
    [x_lo, x_hi, y_lo, y_hi]: [f64; 4],
) -> Option<(Point, Point, bool)> {
    let (dx, dy) = (p1.0 - p0.0, p1.1 - p0.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, p0.0 - x_lo),
        (dx, x_hi - p0.0),
        (-dy, p0.1 - y_lo),
        (dy, y_hi - p0.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| (p0.0 + t * dx, p0.1 + t * dy);
    Some((at(t0), at(t1), t1 < 1.0))
}

type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
type DrawResult = Result<(), DrawingAreaErrorKind<io::Error>>;

fn rgb(hex: u32) -> RGBColor {
    RGBColor((hex >> 16) as u8, (hex >> 8) as u8, hex as u8)
}

impl From<Color> for RGBColor {
    fn from(c: Color) -> Self {
        RGBColor(c.0, c.1, c.2)
    }
}

/// Text of `px` pixels as the SVG shows it: plotters' SVG backend writes a font size of
/// `size / 1.24`.
fn font(px: f64, color: RGBColor, h: HPos, v: VPos) -> TextStyle<'static> {
    font_styled(px, FontStyle::Normal, color, h, v)
}

fn font_styled(px: f64, style: FontStyle, color: RGBColor, h: HPos, v: VPos) -> TextStyle<'static> {
    FontDesc::new(FontFamily::SansSerif, px * 1.24, style)
        .color(&color)
        .pos(Pos::new(h, v))
}

/// Text as XML 1.0 allows it: plotters escapes markup but passes control characters, which
/// no XML parser accepts.
fn clean(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// Rough width of a label: sans-serif averages about 0.56 em (plotters' own estimate for the
/// SVG backend, which has no font metrics either).
fn text_width(text: &str, size: f64) -> i32 {
    (text.chars().count() as f64 * size * 0.56).round() as i32
}

/// Annotation text over data, drawn after the data and the frame so nothing covers it.
struct Label {
    /// Anchor point: the text's vertical centre.
    at: (i32, i32),
    anchor: HPos,
    size: f64,
    color: RGBColor,
    text: String,
}

impl Label {
    /// On a pale box so it stays readable where lines cross it.
    fn draw(&self, root: &Area) -> DrawResult {
        let width = text_width(&self.text, self.size) + 4;
        let (x, y) = self.at;
        let left = match self.anchor {
            HPos::Right => x - width + 2,
            HPos::Center => x - width / 2,
            HPos::Left => x - 2,
        };
        let half = (self.size * 0.65).round() as i32;
        root.draw(&Rectangle::new(
            [(left, y - half), (left + width, y + half)],
            WHITE.mix(0.8).filled(),
        ))?;
        root.draw_text(
            &clean(&self.text),
            &font(self.size, self.color, self.anchor, VPos::Center),
            self.at,
        )
    }
}

/// The SVG text of a figure. Plotters draws into a `String`, and that backend has no
/// operation that can fail; should a future version fail anyway, the figure says so in
/// place of the picture instead of looking like an empty plot.
fn render(frame: &Frame, panels: &[&Panel]) -> String {
    try_render(frame, panels).unwrap_or_else(|error| {
        let mut out = String::new();
        let root = SVGBackend::with_string(&mut out, (frame.width as u32, 40)).into_drawing_area();
        let text = format!("{}: figure not drawn ({error})", clean(frame.title));
        let style = font(13.0, rgb(TEXT), HPos::Left, VPos::Center);
        // Nothing is left to report a second failure to; the text is in the buffer or not.
        let _ = root.fill(&WHITE);
        let _ = root.draw_text(&text, &style, (10, 20));
        let _ = root.present();
        drop(root);
        out
    })
}

fn try_render(frame: &Frame, panels: &[&Panel]) -> Result<String, String> {
    let mut out = String::with_capacity(64 * 1024);
    draw_figure(&mut out, frame, panels).map_err(|e| e.to_string())?;
    Ok(out)
}

fn draw_figure(out: &mut String, frame: &Frame, panels: &[&Panel]) -> DrawResult {
    let width = frame.width.round() as u32;
    let title_height = if frame.title.is_empty() {
        NO_TITLE_HEIGHT
    } else {
        TITLE_HEIGHT
    };
    let heights: Vec<u32> = panels
        .iter()
        .enumerate()
        .map(|(k, p)| {
            let axis = if k + 1 == panels.len() {
                BOTTOM_HEIGHT
            } else {
                0
            };
            p.top_pad() + p.height + axis
        })
        .collect();
    let height = title_height + heights.iter().sum::<u32>().max(BOTTOM_HEIGHT);
    let root = SVGBackend::with_string(out, (width, height)).into_drawing_area();
    root.fill(&WHITE)?;
    if !frame.title.is_empty() {
        let style = font_styled(16.0, FontStyle::Bold, rgb(TEXT), HPos::Center, VPos::Center);
        root.draw_text(&clean(frame.title), &style, (width as i32 / 2, 21))?;
    }

    let log = frame.x_scale == XScale::Log;
    let (x_lo, x_hi) = resolve_x_range(frame, panels);
    let plot_width = width.saturating_sub(MARGIN_LEFT + MARGIN_RIGHT);
    let (x_major, x_minor) = if log {
        log_ticks(x_lo, x_hi, (plot_width / 60).max(2) as usize)
    } else {
        (
            nice_ticks(x_lo, x_hi, (plot_width / 85).max(2) as usize),
            Vec::new(),
        )
    };
    let x_scale = Scale::new(x_lo, x_hi, log).ticks(x_major, x_minor);

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
        rgb(SHADE_FILLS[k % SHADE_FILLS.len()])
    };

    let (_, mut rest) = root.split_vertically(title_height);
    for (index, (panel, &panel_height)) in panels.iter().zip(&heights).enumerate() {
        let (area, below) = rest.split_vertically(panel_height);
        rest = below;
        let (_, chart_area) = area.split_vertically(panel.top_pad());
        let place = Place {
            is_top: index == 0,
            is_bottom: index + 1 == panels.len(),
        };
        draw_panel(&root, &chart_area, frame, panel, &x_scale, place, &tint)?;
    }
    root.present()
}

#[derive(Clone, Copy)]
struct Place {
    is_top: bool,
    is_bottom: bool,
}

fn draw_panel(
    root: &Area,
    area: &Area,
    frame: &Frame,
    panel: &Panel,
    x_scale: &Scale,
    place: Place,
    tint: &dyn Fn(&str) -> RGBColor,
) -> DrawResult {
    let (y_lo, y_hi) = resolve_y_range(panel, x_scale);
    let max_y_ticks = (panel.height / 34).max(2) as usize;
    let y_ticks = match panel.y_ticks {
        YTicks::Decimal => nice_ticks(y_lo, y_hi, max_y_ticks),
        YTicks::Degrees => degree_ticks(y_lo, y_hi, max_y_ticks),
    };
    let y_scale = Scale::new(y_lo, y_hi, false).ticks(y_ticks, Vec::new());
    let (x_lo, x_hi) = (x_scale.lo, x_scale.hi);
    let mut chart = ChartBuilder::on(area)
        .margin_left(Y_LABEL_INSET)
        .margin_right(MARGIN_RIGHT)
        .margin_bottom(if place.is_bottom { X_LABEL_INSET } else { 0 })
        .set_label_area_size(LabelAreaPosition::Left, MARGIN_LEFT - Y_LABEL_INSET)
        .set_label_area_size(
            LabelAreaPosition::Bottom,
            if place.is_bottom {
                BOTTOM_HEIGHT - X_LABEL_INSET
            } else {
                0
            },
        )
        .build_cartesian_2d(x_scale.clone(), y_scale.clone())?;
    let (x_px, y_px) = chart.plotting_area().get_pixel_range();
    let (plot_left, plot_right, top, bottom) = (x_px.start, x_px.end, y_px.start, y_px.end);
    let mut labels = Vec::new();

    // Shaded intervals, under everything else.
    let shared = frame.shared_shades.iter().map(|s| (s, place.is_top));
    let own = panel.shades.iter().map(|s| (s, true));
    for (shade, labelled) in shared.chain(own) {
        let (a, b) = (shade.x0.min(shade.x1), shade.x0.max(shade.x1));
        let (a, b) = (a.max(x_lo), b.min(x_hi));
        if !(b > a && x_scale.contains(a) && x_scale.contains(b)) {
            continue;
        }
        chart.plotting_area().draw(&Rectangle::new(
            [(a, y_hi), (b, y_lo)],
            tint(&shade.label).filled(),
        ))?;
        let (pa, pb) = (
            chart.backend_coord(&(a, y_lo)).0,
            chart.backend_coord(&(b, y_lo)).0,
        );
        if labelled && !shade.label.is_empty() && text_width(&shade.label, 10.0) + 6 < pb - pa {
            labels.push(Label {
                at: (pa + 4, top + 9),
                anchor: HPos::Left,
                size: 10.0,
                color: rgb(TEXT_SOFT),
                text: shade.label.clone(),
            });
        }
    }

    let mut mesh = chart.configure_mesh();
    mesh.bold_line_style(rgb(GRID).stroke_width(1))
        .light_line_style(rgb(GRID_MINOR).stroke_width(1))
        .axis_style(rgb(FRAME).stroke_width(1))
        .set_all_tick_mark_size(4)
        .label_style(font(11.0, rgb(TEXT_SOFT), HPos::Center, VPos::Center))
        .axis_desc_style(font(13.0, rgb(TEXT), HPos::Center, VPos::Center))
        .y_desc(clean(&panel.y_label));
    if place.is_bottom {
        mesh.x_desc(clean(frame.x_label));
    }
    mesh.draw()?;
    // Zero drawn a shade darker than the grid: the reference level of most panels.
    if y_scale.major.iter().any(|y| y.abs() < y_scale.step * 1e-6) {
        chart.plotting_area().draw(&PathElement::new(
            vec![(x_lo, 0.0), (x_hi, 0.0)],
            rgb(GRID_ZERO).stroke_width(1),
        ))?;
    }

    // Series in the order they were added: a later one is drawn over an earlier one.
    let columns = i64::from(plot_right - plot_left + 1);
    for series in &panel.series {
        draw_series(&chart, series, x_scale, (y_lo, y_hi), columns)?;
    }

    // Limit lines and markers over the data: they are what the reader compares against.
    let limit_style = rgb(LIMIT).stroke_width(1);
    for h in &panel.hlines {
        if !(h.y.is_finite() && (y_lo..=y_hi).contains(&h.y)) {
            continue;
        }
        chart.plotting_area().draw(&DashedPathElement::new(
            vec![(x_lo, h.y), (x_hi, h.y)],
            5,
            4,
            limit_style,
        ))?;
        if !h.label.is_empty() {
            let py = chart.backend_coord(&(x_lo, h.y)).1;
            // Below the line when above it would leave the panel.
            let ty = if py - top < 16 { py + 9 } else { py - 8 };
            labels.push(Label {
                at: (plot_right - 4, ty),
                anchor: HPos::Right,
                size: 11.0,
                color: rgb(TEXT_SOFT),
                text: h.label.clone(),
            });
        }
    }
    let shared = frame.shared_vlines.iter().map(|v| (v, place.is_top));
    let own = panel.vlines.iter().map(|v| (v, true));
    let mut stacked = 0;
    for (v, labelled) in shared.chain(own) {
        if !x_scale.contains(v.x) {
            continue;
        }
        let color = RGBColor::from(v.color);
        chart.plotting_area().draw(&DashedPathElement::new(
            vec![(v.x, y_lo), (v.x, y_hi)],
            5,
            4,
            color.stroke_width(1),
        ))?;
        if labelled && !v.label.is_empty() {
            let px = chart.backend_coord(&(v.x, y_lo)).0;
            let width = text_width(&v.label, 11.0);
            let (ty, prefer_left) = if v.label_at_bottom {
                (bottom - 12 - stacked * 16, true)
            } else {
                (top + 11 + stacked * 16, false)
            };
            stacked += 1;
            let fits_left = px - 5 - width > plot_left;
            let fits_right = px + 5 + width < plot_right;
            let (tx, anchor) = if (prefer_left && fits_left) || !fits_right {
                (px - 5, HPos::Right)
            } else {
                (px + 5, HPos::Left)
            };
            labels.push(Label {
                at: (tx, ty),
                anchor,
                size: 11.0,
                color,
                text: v.label.clone(),
            });
        }
    }

    // On the pixels of plotters' axis lines (left of and below the plotting area), so the
    // frame is one line wide all round.
    root.draw(&Rectangle::new(
        [(plot_left - 1, top), (plot_right - 1, bottom)],
        rgb(FRAME).stroke_width(1),
    ))?;
    for label in &labels {
        label.draw(root)?;
    }
    if panel.shows_legend() {
        draw_legend(root, panel, plot_left, top - 12)?;
    }
    Ok(())
}

fn series_style(series: &Series) -> ShapeStyle {
    RGBColor::from(series.color)
        .mix(series.opacity)
        .stroke_width(LINE_WIDTH)
}

fn draw_series(
    chart: &ChartContext<SVGBackend, Cartesian2d<Scale, Scale>>,
    series: &Series,
    x_scale: &Scale,
    y_range: (f64, f64),
    columns: i64,
) -> DrawResult {
    let area = chart.plotting_area();
    let style = series_style(series);
    let runs = clip(
        decimate(&series.x, &series.y, x_scale, columns),
        x_scale,
        y_range,
    );
    for run in runs {
        match run[..] {
            // A lone sample between dropouts: a dot, where a line has nothing to join.
            [only] => area.draw(&Circle::new(only, LINE_WIDTH, style.filled()))?,
            _ if series.dashed => area.draw(&DashedPathElement::new(run, DASH.0, DASH.1, style))?,
            _ => area.draw(&PathElement::new(run, style))?,
        }
    }
    if series.markers {
        let visible: Vec<(f64, f64)> = series
            .x
            .iter()
            .zip(&series.y)
            .filter(|&(&x, &y)| x_scale.contains(x) && y.is_finite())
            .filter(|&(_, &y)| (y_range.0..=y_range.1).contains(&y))
            .map(|(&x, &y)| (x, y))
            .collect();
        // On dense series the dots would merge into a smear.
        if visible.len() <= MAX_MARKERS {
            for p in visible {
                area.draw(&Circle::new(p, MARKER_RADIUS, style.filled()))?;
            }
        }
    }
    Ok(())
}

/// One row above the panel: a line sample and the name of each named series.
fn draw_legend(root: &Area, panel: &Panel, left: i32, y: i32) -> DrawResult {
    let mut x = left;
    for series in panel.series.iter().filter(|s| !s.name.is_empty()) {
        let style = series_style(series);
        let sample = vec![(x, y), (x + 24, y)];
        if series.dashed {
            root.draw(&DashedPathElement::new(sample, DASH.0, DASH.1, style))?;
        } else {
            root.draw(&PathElement::new(sample, style))?;
        }
        if series.markers {
            root.draw(&Circle::new((x + 12, y), MARKER_RADIUS, style.filled()))?;
        }
        let name = clean(&series.name);
        root.draw_text(
            &name,
            &font(12.0, rgb(TEXT), HPos::Left, VPos::Center),
            (x + 30, y),
        )?;
        x += 30 + text_width(&name, 12.0) + 18;
    }
    Ok(())
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

    /// Every `<text>` element: its attributes and its content (plotters puts the content on a
    /// line of its own).
    fn texts(svg: &str) -> Vec<(&str, &str)> {
        svg.split("<text ")
            .skip(1)
            .filter_map(|rest| {
                let (attrs, rest) = rest.split_once('>')?;
                let (content, _) = rest.split_once("</text>")?;
                Some((attrs, content.trim()))
            })
            .collect()
    }

    fn has_text(svg: &str, wanted: &str) -> bool {
        texts(svg).iter().any(|&(_, t)| t == wanted)
    }

    /// A `<polyline>`: its position in the document, its stroke colour, its points.
    type Polyline = (usize, String, Vec<(i32, i32)>);

    /// Every `<polyline>` of the document.
    fn polylines(svg: &str) -> Vec<Polyline> {
        svg.match_indices("<polyline ")
            .map(|(at, _)| {
                let tag = &svg[at..at + svg[at..].find("/>").expect("closed")];
                let attr = |name: &str| {
                    let start = tag.find(&format!(" {name}=\"")).expect(name) + name.len() + 3;
                    tag[start..start + tag[start..].find('"').expect("quote")].to_string()
                };
                let points = attr("points")
                    .split_whitespace()
                    .map(|p| {
                        let (x, y) = p.split_once(',').expect("x,y");
                        (x.parse().expect("x"), y.parse().expect("y"))
                    })
                    .collect();
                (at, attr("stroke").to_lowercase(), points)
            })
            .collect()
    }

    #[test]
    fn time_plot_is_well_formed_and_escapes_text() {
        let svg = time_plot(5_000).to_svg();
        assert_well_formed(&svg);
        assert!(has_text(&svg, "Square wave &lt;10 deg&gt; &amp; current"));
        assert!(has_text(&svg, "+20 A limit") && has_text(&svg, "saturated"));
        assert!(has_text(&svg, "steering wheel (deg)") && has_text(&svg, "time (s)"));
        // Plain text in a generic family: no font file is needed to draw or to view it.
        let all = texts(&svg);
        assert!(all.len() > 10);
        assert!(
            all.iter()
                .all(|(attrs, _)| attrs.contains("font-family=\"sans-serif\""))
        );
    }

    #[test]
    fn control_characters_never_reach_the_file() {
        let svg = TimePlot::new("a\u{1}b")
            .panel(Panel::new("y\u{7f}").series("s\u{0}", &[0.0, 1.0], &[0.0, 1.0]))
            .to_svg();
        assert_well_formed(&svg);
        assert!(!svg.chars().any(|c| c.is_control() && c != '\n'));
        assert!(has_text(&svg, "a b"));
    }

    #[test]
    fn bode_plot_is_well_formed_and_labels_the_bandwidth_and_coherence() {
        let svg = bode(400).to_svg();
        assert_well_formed(&svg);
        assert!(has_text(&svg, "simulated: -3 dB at 5.1 Hz"), "{svg}");
        assert!(has_text(&svg, "-3 dB"));
        // The coherence panel's y label, rotated like the others.
        let label = texts(&svg)
            .into_iter()
            .find(|&(_, t)| t == "coherence")
            .expect("coherence label");
        assert!(label.0.contains("rotate(270"), "{}", label.0);
        assert!(has_text(&svg, "magnitude (dB)") && has_text(&svg, "phase (deg)"));
        let linear = bode(50).x_scale(XScale::Linear).bandwidth(5.1).to_svg();
        assert_well_formed(&linear);
        assert!(has_text(&linear, "-3 dB at 5.1 Hz"));
    }

    /// The numeric labels under the frequency axis (centred; the y labels are right-aligned).
    fn frequency_labels(svg: &str) -> Vec<f64> {
        texts(svg)
            .into_iter()
            .filter(|(attrs, _)| attrs.contains("text-anchor=\"middle\""))
            .filter_map(|(_, t)| t.parse().ok())
            .collect()
    }

    #[test]
    fn bode_frequency_axis_is_labelled_at_one_two_five() {
        let labels = frequency_labels(&bode(400).to_svg());
        assert_ticks(
            &labels,
            &[0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0],
        );
        let labels = frequency_labels(&bode(400).x_range(2.0, 30.0).to_svg());
        assert_ticks(&labels, &[2.0, 5.0, 10.0, 20.0]);
        // Six decades on a narrow figure: only the decades fit.
        let f: Vec<f64> = (0..200)
            .map(|k| 10f64.powf(-2.0 + 6.0 * k as f64 / 199.0))
            .collect();
        let flat = vec![0.0; f.len()];
        let wide = BodePlot::new("wide")
            .width(400.0)
            .series("s", &f, &flat, &flat)
            .to_svg();
        let labels = frequency_labels(&wide);
        assert_ticks(&labels, &[0.01, 0.1, 1.0, 10.0, 100.0, 1000.0, 10000.0]);
    }

    #[test]
    fn later_series_are_drawn_over_earlier_ones() {
        let t: Vec<f64> = (0..2000).map(|k| k as f64 * 1e-3).collect();
        let measured: Vec<f64> = t.iter().map(|t| 8.0 * (t * 30.0).sin()).collect();
        let setpoint: Vec<f64> = t
            .iter()
            .map(|t| 20.0 * (t * 300.0).sin().signum())
            .collect();
        let svg = TimePlot::new("current")
            .panel(
                Panel::new("motor current, A")
                    .series("measured", &t, &measured)
                    .series_styled(
                        "set-point",
                        &t,
                        &setpoint,
                        Style::new().color(Color::GRAY).opacity(0.6),
                    ),
            )
            .to_svg();
        let lines = polylines(&svg);
        let position = |stroke: &str| -> Vec<usize> {
            lines
                .iter()
                .filter(|(_, s, p)| s == stroke && p.len() > 2)
                .map(|&(at, _, _)| at)
                .collect()
        };
        let (blue, gray) = (position("#0072b2"), position("#666666"));
        assert!(!blue.is_empty() && !gray.is_empty());
        assert!(blue.iter().max() < gray.iter().min(), "{blue:?} {gray:?}");
        assert!(svg.contains("opacity=\"0.6\""));
    }

    #[test]
    fn palette_colours_are_handed_out_in_order() {
        let t = [0.0, 1.0, 2.0];
        let panel = (0..4).fold(Panel::new("y"), |p, k| {
            p.series(&format!("s{k}"), &t, &[k as f64, 1.0, 0.0])
        });
        let svg = TimePlot::new("palette").panel(panel).to_svg();
        let mut seen: Vec<String> = Vec::new();
        for (_, stroke, _) in polylines(&svg) {
            if PALETTE.iter().any(|c| c.to_string() == stroke) && !seen.contains(&stroke) {
                seen.push(stroke);
            }
        }
        let expected: Vec<String> = PALETTE[..4].iter().map(Color::to_string).collect();
        assert_eq!(seen, expected);
    }

    #[test]
    fn lines_are_cut_at_the_edge_of_the_plot() {
        let t: Vec<f64> = (0..1000).map(|k| k as f64 * 0.01).collect();
        let y: Vec<f64> = t.iter().map(|t| 5.0 * (t * 3.0).sin()).collect();
        let svg = TimePlot::new("clipped")
            .x_range(2.0, 8.0)
            .panel(
                Panel::new("y")
                    .series("s", &t, &y)
                    .y_range(-1.0, 1.0)
                    .hide_legend(),
            )
            .to_svg();
        // The series' lines only: plotters draws the grid and tick marks as polylines too.
        let points: Vec<(i32, i32)> = polylines(&svg)
            .into_iter()
            .filter(|(_, stroke, _)| *stroke == PALETTE[0].to_string())
            .flat_map(|(_, _, p)| p)
            .collect();
        assert!(points.len() > 20);
        let (xs, ys): (Vec<i32>, Vec<i32>) = points.into_iter().unzip();
        let left = MARGIN_LEFT as i32;
        let right = (DEFAULT_WIDTH as u32 - MARGIN_RIGHT) as i32;
        let top = (TITLE_HEIGHT + PANEL_GAP) as i32;
        let bottom = top + DEFAULT_PANEL_HEIGHT as i32;
        assert!(xs.iter().all(|x| (left..=right).contains(x)), "{xs:?}");
        assert!(ys.iter().all(|y| (top..=bottom).contains(y)), "{ys:?}");

        // A peak above the box: the line ends on the edge and starts again where it comes back.
        let runs = clip(
            vec![vec![(0.0, 0.0), (2.0, 2.0), (4.0, 0.0)]],
            &Scale::new(0.0, 4.0, false),
            (-1.0, 1.0),
        );
        assert_eq!(
            runs,
            vec![vec![(0.0, 0.0), (1.0, 1.0)], vec![(3.0, 1.0), (4.0, 0.0)]]
        );
        // On a decade axis the cut is straight in decades: 1 -> 100 crosses 10 halfway.
        let runs = clip(
            vec![vec![(1.0, 0.0), (100.0, 2.0)]],
            &Scale::new(0.5, 10.0, true),
            (-5.0, 5.0),
        );
        assert_eq!(runs.len(), 1);
        let end = runs[0][1];
        assert!(
            (end.0 - 10.0).abs() < 1e-9 && (end.1 - 1.0).abs() < 1e-9,
            "{end:?}"
        );
    }

    #[test]
    fn long_series_are_decimated_to_a_small_file() {
        let svg = time_plot(240_000).to_svg();
        assert_well_formed(&svg);
        // Three series of 240 000 samples; undecimated they would take several megabytes.
        assert!(svg.len() < 150_000, "{} bytes", svg.len());
    }

    #[test]
    fn decimation_keeps_min_max_and_a_single_sample_spike() {
        let n = 240_000;
        let x: Vec<f64> = (0..n).map(|i| i as f64).collect();
        let mut y = vec![0.0; n];
        y[123_457] = 100.0;
        y[7] = -3.0;
        let scale = Scale::new(0.0, n as f64, false);
        let runs = decimate(&x, &y, &scale, 800);
        assert_eq!(runs.len(), 1);
        assert!(runs[0].len() <= 4 * 802, "{} points", runs[0].len());
        assert!(runs[0].contains(&(123_457.0, 100.0)));
        assert!(runs[0].contains(&(7.0, -3.0)));
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
        // The lone sample 701 is a dot; the markers are 50 more.
        assert_eq!(
            svg.matches("<circle").count(),
            51 + 1,
            "legend marker included"
        );

        let scale = Scale::new(0.0, 10.0, false);
        let runs = decimate(&t, &y, &scale, 800);
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
            assert!(
                (g - e).abs() < 1e-9 * e.abs().max(1.0),
                "{got:?} vs {expected:?}"
            );
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
        assert_eq!(log_tick_label(0.2), "0.2");
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
    fn log_ticks_label_one_two_five_or_decades() {
        let (major, minor) = log_ticks(0.1, 100.0, 12);
        assert_ticks(
            &major,
            &[0.1, 0.2, 0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0],
        );
        assert_eq!(minor.len(), 6 * 3);
        let (major, minor) = log_ticks(0.1, 100.0, 5);
        assert_ticks(&major, &[0.1, 1.0, 10.0, 100.0]);
        assert_eq!(minor.len(), 8 * 3);
        let (major, _) = log_ticks(2.0, 30.0, 12);
        assert_ticks(&major, &[2.0, 5.0, 10.0, 20.0]);
        let (major, _) = log_ticks(2.5, 4.5, 12);
        assert_ticks(&major, &[3.0, 4.0]);
        assert_eq!(log_ticks(0.0, 1.0, 12), (Vec::new(), Vec::new()));
    }

    #[test]
    fn save_creates_parent_directories() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("plots/sub/bode.svg");
        bode(100).save(&path).expect("save");
        let text = fs::read_to_string(&path).expect("read back");
        assert_well_formed(&text);
        assert_eq!(text, bode(100).to_svg());
    }

    #[test]
    fn wrapped_phase_stays_in_half_open_circle_and_breaks_at_the_wrap() {
        let x = [1.0, 2.0, 3.0, 4.0, 5.0];
        let (wx, wy) = wrapped_phase(&x, &[-170.0, -190.0, -540.0, 180.0, f64::NAN]);
        // -190 wraps to 170: a jump of 340 deg, so a break (NaN) sits between 1 and 2 Hz.
        assert_eq!(wx, vec![1.0, 1.5, 2.0, 3.0, 4.0, 5.0]);
        assert_eq!(wy[0], -170.0);
        assert!(wy[1].is_nan());
        assert_eq!(&wy[2..5], &[170.0, 180.0, 180.0]);
        assert!(wy[5].is_nan());
        let svg = BodePlot::new("wrapped")
            .wrap_phase()
            .series("h", &x, &[0.0; 5], &[-170.0, -190.0, -540.0, -3400.0, 10.0])
            .to_svg();
        assert_well_formed(&svg);
        assert!(!svg.contains(">\n-3400") && !svg.contains(">\n-3000"));
    }
}

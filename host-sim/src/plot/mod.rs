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
mod clip;
mod decimate;
mod render;
mod scale;
mod ticks;

pub use ticks::{log_ticks, nice_ticks};

use render::{render, try_render};
use std::fmt;
use std::fs;
use std::io;
use std::path::Path;
use ticks::format_hz;

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

#[cfg(test)]
mod tests;

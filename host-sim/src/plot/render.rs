//! Drawing a figure with plotters: the layout of title, panels, legends and labels, the
//! mesh, the series, limit lines and markers.

use super::clip::clip;
use super::decimate::decimate;
use super::scale::{Scale, resolve_x_range, resolve_y_range};
use super::ticks::{degree_ticks, log_ticks, nice_ticks};
use super::*;
use plotters::coord::Shift;
use plotters::element::DashedPathElement;
use plotters::prelude::{
    Cartesian2d, ChartBuilder, ChartContext, Circle, DrawingArea, DrawingAreaErrorKind, FontDesc,
    FontFamily, FontStyle, IntoDrawingArea, LabelAreaPosition, PathElement, RGBColor, Rectangle,
    SVGBackend, ShapeStyle, TextStyle, WHITE,
};
use plotters::style::Color as _;
use plotters::style::text_anchor::{HPos, Pos, VPos};
use std::io;

pub(super) type Area<'a> = DrawingArea<SVGBackend<'a>, Shift>;
pub(super) type DrawResult = Result<(), DrawingAreaErrorKind<io::Error>>;

pub(super) fn rgb(hex: u32) -> RGBColor {
    RGBColor((hex >> 16) as u8, (hex >> 8) as u8, hex as u8)
}

impl From<Color> for RGBColor {
    fn from(c: Color) -> Self {
        RGBColor(c.0, c.1, c.2)
    }
}

/// Text of `px` pixels as the SVG shows it: plotters' SVG backend writes a font size of
/// `size / 1.24`.
pub(super) fn font(px: f64, color: RGBColor, h: HPos, v: VPos) -> TextStyle<'static> {
    font_styled(px, FontStyle::Normal, color, h, v)
}

pub(super) fn font_styled(
    px: f64,
    style: FontStyle,
    color: RGBColor,
    h: HPos,
    v: VPos,
) -> TextStyle<'static> {
    FontDesc::new(FontFamily::SansSerif, px * 1.24, style)
        .color(&color)
        .pos(Pos::new(h, v))
}

/// Text as XML 1.0 allows it: plotters escapes markup but passes control characters, which
/// no XML parser accepts.
pub(super) fn clean(text: &str) -> String {
    text.chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect()
}

/// Rough width of a label: sans-serif averages about 0.56 em (plotters' own estimate for the
/// SVG backend, which has no font metrics either).
pub(super) fn text_width(text: &str, size: f64) -> i32 {
    (text.chars().count() as f64 * size * 0.56).round() as i32
}

/// Annotation text over data, drawn after the data and the frame so nothing covers it.
pub(super) struct Label {
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
pub(super) fn render(frame: &Frame, panels: &[&Panel]) -> String {
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

pub(super) fn try_render(frame: &Frame, panels: &[&Panel]) -> Result<String, String> {
    let mut out = String::with_capacity(64 * 1024);
    draw_figure(&mut out, frame, panels).map_err(|e| e.to_string())?;
    Ok(out)
}

pub(super) fn draw_figure(out: &mut String, frame: &Frame, panels: &[&Panel]) -> DrawResult {
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
pub(super) struct Place {
    is_top: bool,
    is_bottom: bool,
}

pub(super) fn draw_panel(
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

pub(super) fn series_style(series: &Series) -> ShapeStyle {
    RGBColor::from(series.color)
        .mix(series.opacity)
        .stroke_width(LINE_WIDTH)
}

pub(super) fn draw_series(
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
pub(super) fn draw_legend(root: &Area, panel: &Panel, left: i32, y: i32) -> DrawResult {
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

use super::clip::clip;
use super::decimate::decimate;
use super::scale::Scale;
use super::ticks::{degree_ticks, log_tick_label, tick_label};
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

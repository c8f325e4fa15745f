//! The diagnosis pictures: residual over time with the regimes shaded, the Bode plot of
//! measured, nominal and nominal-plus-verdict, and the segment replay.

use super::locate::Frequency;
use super::model::Effects;
use super::rig::{Rig, RigModel};
use super::{Diagnosis, EffectKind, Record, simulate};
use crate::plot::{BodePlot, Color, Panel, Style, TimePlot};
use std::path::{Path, PathBuf};

/// Contiguous runs of `true` in a mask, as (start, end) times.
fn runs(mask: &[bool], dt: f64) -> Vec<(f64, f64)> {
    let mut out = Vec::new();
    let mut start = None;
    for (k, m) in mask.iter().enumerate() {
        match (m, start) {
            (true, None) => start = Some(k),
            (false, Some(s)) => {
                out.push((s as f64 * dt, k as f64 * dt));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s as f64 * dt, mask.len() as f64 * dt));
    }
    out
}

fn verdict_effects(rig: &Rig, d: &Diagnosis) -> Effects {
    let kinds: Vec<EffectKind> = d
        .verdict
        .effects
        .iter()
        .filter_map(|n| EffectKind::from_name(n))
        .collect();
    let key = kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+");
    d.ranking
        .iter()
        .find(|c| c.effect == key)
        .map_or(Effects::nominal(), |c| c.effects_on(rig))
}

/// One of the diagnosis's pictures: its file name under `--plots`, what it shows, the SVG.
#[derive(Debug)]
pub struct Picture {
    pub file: &'static str,
    pub caption: &'static str,
    pub svg: String,
}

/// Write `gap_residual.svg`, `gap_bode.svg` and (with a motor angle) `gap_segments.svg`.
pub fn write_all(
    rig: &Rig,
    rec: &Record,
    d: &Diagnosis,
    dir: &Path,
) -> Result<Vec<PathBuf>, Box<dyn std::error::Error>> {
    let mut files = Vec::new();
    for picture in pictures(rig, rec, d) {
        let p = dir.join(picture.file);
        std::fs::write(&p, picture.svg).map_err(|e| format!("{}: {e}", p.display()))?;
        files.push(p);
    }
    Ok(files)
}

/// The pictures [`write_all`] writes, as SVG text (the HTML report inlines them).
pub fn pictures(rig: &Rig, rec: &Record, d: &Diagnosis) -> Vec<Picture> {
    let (out_unit, eff_unit) = match rig.model {
        RigModel::Paper(_) => ("deg", "A"),
        RigModel::Emps(_) => ("m", "V"),
        RigModel::Bam(_) => ("rad", "duty"),
    };
    let sim0 = simulate(rig, rec, &Effects::nominal());
    let fx = verdict_effects(rig, d);
    let sim1 = simulate(rig, rec, &fx);
    let n = rec.len().min(sim0.output.len()).min(sim1.output.len());
    let t: Vec<f64> = (0..n).map(|k| k as f64 * rec.dt).collect();
    let after_name = if d.verdict.effects.is_empty() {
        "nominal (verdict: none)".to_string()
    } else {
        format!("nominal + {}", d.verdict.effects.join(" + "))
    };
    let res = |sim: &[f64], y: &[f64]| -> Vec<f64> { (0..n).map(|k| sim[k] - y[k]).collect() };
    let mut plot = TimePlot::new(&format!(
        "Residual over time, rig {} (GoF {:.1} % -> {:.1} %)",
        rig.name,
        100.0 * d.baseline_gof,
        100.0 * d.verdict.gof_after
    ))
    .panel(
        Panel::new(&format!("output, {out_unit}"))
            .series("reference", &t, &rec.reference[..n])
            .series("measured", &t, &rec.output[..n])
            .series_styled("nominal", &t, &sim0.output[..n], Style::new().dashed()),
    )
    .panel(
        Panel::new(&format!("output residual, {out_unit}"))
            .series("nominal - measured", &t, &res(&sim0.output, &rec.output))
            .series(&after_name, &t, &res(&sim1.output, &rec.output)),
    )
    .panel(
        Panel::new(&format!("effort residual, {eff_unit}"))
            .series("nominal - measured", &t, &res(&sim0.effort, &rec.effort))
            .series(&after_name, &t, &res(&sim1.effort, &rec.effort)),
    )
    .x_label("time, s");
    // Shade the two regimes that localise effects best; at most 200 intervals each.
    for r in &d.where_.regimes {
        if r.name == "velocity_reversal" || r.name == "current_limit" {
            for (a, b) in runs(&r.mask, rec.dt).into_iter().take(200) {
                plot = plot.shade(a, b, &r.name);
            }
        }
    }
    let mut pictures = vec![Picture {
        file: "gap_residual.svg",
        caption: "Residual over time, nominal and with the verdict's effects",
        svg: plot.to_svg(),
    }];

    let f = &d.where_.frequency;
    if !f.measured.freq_hz.is_empty() {
        pictures.push(Picture {
            file: "gap_bode.svg",
            caption: "Reference to output: measured, nominal and with the verdict's effects",
            svg: bode_plot(&rig.name, f, &after_name).to_svg(),
        });
    }

    let downstream = match &rig.model {
        RigModel::Paper(pm) => super::model::replay_downstream(pm, rec, &Effects::nominal()),
        RigModel::Emps(_) | RigModel::Bam(_) => None,
    };
    if let (Some(m), Some(replay)) = (&rec.motor, &downstream) {
        let n = n.min(replay.len());
        let residual = |a: &[f64], b: &[f64]| (0..n).map(|k| a[k] - b[k]).collect::<Vec<_>>();
        let seg = segments_plot(
            &t[..n],
            [&m[..n], &sim0.motor[..n], &residual(&sim0.motor, m)],
            [
                &rec.output[..n],
                &replay[..n],
                &residual(&rec.output, replay),
            ],
        );
        pictures.push(Picture {
            file: "gap_segments.svg",
            caption: "Segment replay: where in the chain the residual arises",
            svg: seg.to_svg(),
        });
    }
    pictures
}

/// Coherence below which a bin of the frequency response is greyed: where the reference no
/// longer excites the rig (above a sweep's last frequency) the output there is noise, and its
/// magnitude and phase say nothing about the rig.
const MIN_COHERENCE: f64 = 0.5;

/// Fewest neighbouring bins above [`MIN_COHERENCE`] that count as a band: among bins of noise
/// the estimate crosses 0.5 now and then by chance, one or two bins at a time.
const MIN_COHERENT_BINS: usize = 3;

/// `mask` with its runs of `true` shorter than `min_run` cleared.
fn drop_short_runs(mut mask: Vec<bool>, min_run: usize) -> Vec<bool> {
    let mut k = 0;
    while k < mask.len() {
        let run = mask[k..].iter().take_while(|&&ok| ok).count();
        if run > 0 && run < min_run {
            mask[k..k + run].iter_mut().for_each(|ok| *ok = false);
        }
        k += run.max(1);
    }
    mask
}

/// The Bode plot of the measured, nominal and verdict responses: in colour where the
/// measurement's coherence holds, grey elsewhere; the magnitude axis spans the coloured part,
/// the phase is wrapped.
fn bode_plot(rig_name: &str, f: &Frequency, after_name: &str) -> BodePlot {
    let m = &f.measured;
    // All three come from the same reference, so they share its bins; a bin the measurement
    // lacks takes the coherence of the nearest one it has.
    let coherent = |freq: f64| {
        let nearest = m
            .freq_hz
            .iter()
            .zip(&m.coherence)
            .min_by(|a, b| (a.0 - freq).abs().total_cmp(&(b.0 - freq).abs()));
        nearest.is_some_and(|(_, &c)| c >= MIN_COHERENCE)
    };
    let responses = [
        ("measured", m, Style::new()),
        ("nominal", &f.nominal, Style::new().dashed()),
        (after_name, &f.after, Style::new()),
    ];
    let masks: Vec<Vec<bool>> = responses
        .iter()
        .map(|(_, r, _)| {
            let mask = r.freq_hz.iter().map(|&x| coherent(x)).collect();
            drop_short_runs(mask, MIN_COHERENT_BINS)
        })
        .collect();
    let mut bode = BodePlot::new(&format!("Reference -> output, rig {rig_name}")).wrap_phase();
    let mut magnitude_range = (f64::INFINITY, f64::NEG_INFINITY);
    for ((name, r, style), mask) in responses.iter().zip(&masks) {
        let keep = |v: &[f64]| -> Vec<f64> {
            v.iter()
                .zip(mask)
                .map(|(&v, &ok)| if ok { v } else { f64::NAN })
                .collect()
        };
        for (&db, _) in r
            .magnitude_db
            .iter()
            .zip(mask)
            .filter(|(v, ok)| **ok && v.is_finite())
        {
            magnitude_range = (magnitude_range.0.min(db), magnitude_range.1.max(db));
        }
        bode = bode.series_styled(
            name,
            &r.freq_hz,
            &keep(&r.magnitude_db),
            &keep(&r.phase_deg),
            *style,
        );
    }
    // The grey part after the coloured, each run joined to its coloured neighbours so the line
    // stays whole; one legend entry says what grey means.
    let mut legend = Some(format!("coherence < {MIN_COHERENCE}"));
    for ((_, r, style), mask) in responses.iter().zip(&masks) {
        let grey = |v: &[f64]| -> Vec<f64> {
            (0..v.len())
                .map(|k| {
                    let near = |j: Option<usize>| j.and_then(|j| mask.get(j)) == Some(&false);
                    if !mask[k] || near(k.checked_sub(1)) || near(Some(k + 1)) {
                        v[k]
                    } else {
                        f64::NAN
                    }
                })
                .collect()
        };
        if mask.iter().all(|&ok| ok) {
            continue;
        }
        bode = bode.series_styled(
            &legend.take().unwrap_or_default(),
            &r.freq_hz,
            &grey(&r.magnitude_db),
            &grey(&r.phase_deg),
            style.color(Color::GRAY).opacity(0.6),
        );
    }
    if magnitude_range.0 < magnitude_range.1 {
        let pad = 0.05 * (magnitude_range.1 - magnitude_range.0);
        bode = bode.magnitude_range(magnitude_range.0 - pad, magnitude_range.1 + pad);
    }
    bode.coherence("measured", &m.freq_hz, &m.coherence)
}

/// Where in the chain the residual arises: `[measured, simulated, residual]` of the motor
/// (reference -> motor, closed loop) and of the column (motor -> column, the nominal chain
/// driven by the measured motor), in degrees at the wheel.
fn segments_plot(t: &[f64], motor: [&[f64]; 3], column: [&[f64]; 3]) -> TimePlot {
    // One colour per role in both panels: measured blue, simulated vermillion (dashed),
    // residual green.
    let panel = |label: &str, names: [&str; 3], y: [&[f64]; 3]| {
        Panel::new(label)
            .series_styled(names[0], t, y[0], Style::new().color(Color::BLUE))
            .series_styled(
                names[1],
                t,
                y[1],
                Style::new().color(Color::VERMILLION).dashed(),
            )
            .series_styled(names[2], t, y[2], Style::new().color(Color::GREEN))
    };
    TimePlot::new("Segment replay: where in the chain the residual arises")
        .panel(panel(
            "reference -> motor, deg",
            ["measured motor", "closed loop, nominal", "residual"],
            motor,
        ))
        .panel(panel(
            "motor -> column, deg",
            [
                "measured column",
                "nominal chain driven by the measured motor",
                "residual",
            ],
            column,
        ))
        .x_label("time, s")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::FrequencyResponse;
    use crate::plot::PALETTE;

    /// The value of `name="..."` in one SVG tag.
    fn attr<'a>(tag: &'a str, name: &str) -> Option<&'a str> {
        let start = tag.find(&format!(" {name}=\""))? + name.len() + 3;
        Some(&tag[start..start + tag[start..].find('"')?])
    }

    fn num(tag: &str, name: &str) -> f64 {
        attr(tag, name)
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no number {name} in {tag}"))
    }

    /// Every `<name ...>` tag with the text up to the next tag (a `<text>`'s content).
    fn elements<'a>(svg: &'a str, name: &str) -> Vec<(&'a str, &'a str)> {
        let open = format!("<{name} ");
        svg.match_indices(&open)
            .map(|(i, _)| {
                let end = i + svg[i..].find('>').expect("tag closes");
                let text_end = end + svg[end..].find('<').unwrap_or(0);
                (&svg[i..=end], svg[end + 1..text_end].trim())
            })
            .collect()
    }

    /// (stroke, points) of each polyline.
    fn polylines(svg: &str) -> Vec<(String, Vec<(f64, f64)>)> {
        elements(svg, "polyline")
            .into_iter()
            .map(|(tag, _)| {
                let points = attr(tag, "points")
                    .unwrap_or("")
                    .split_whitespace()
                    .map(|p| {
                        let (x, y) = p.split_once(',').expect("x,y");
                        (x.parse().expect("x"), y.parse().expect("y"))
                    })
                    .collect();
                (attr(tag, "stroke").unwrap_or("").to_lowercase(), points)
            })
            .collect()
    }

    /// The plotting areas (left, top, right, bottom) from top to bottom: the frame rectangles.
    fn frames(svg: &str) -> Vec<(f64, f64, f64, f64)> {
        elements(svg, "rect")
            .into_iter()
            .filter(|(tag, _)| attr(tag, "fill") == Some("none"))
            .map(|(tag, _)| {
                let (x, y) = (num(tag, "x"), num(tag, "y"));
                (x, y, x + num(tag, "width"), y + num(tag, "height"))
            })
            .collect()
    }

    fn is_palette(stroke: &str) -> bool {
        PALETTE
            .iter()
            .any(|c| c.to_string().eq_ignore_ascii_case(stroke))
    }

    fn response(
        freq: &[f64],
        magnitude: impl Fn(f64) -> f64,
        phase: impl Fn(f64) -> f64,
    ) -> FrequencyResponse {
        FrequencyResponse {
            freq_hz: freq.to_vec(),
            magnitude_db: freq.iter().map(|&f| magnitude(f)).collect(),
            phase_deg: freq.iter().map(|&f| phase(f)).collect(),
            coherence: freq
                .iter()
                // One bin above 0.5 by chance among the noise.
                .map(|&f| match f {
                    f if f <= 10.0 => 0.95,
                    f if (f - 30.0).abs() < 1e-9 => 0.6,
                    _ => 0.2,
                })
                .collect(),
        }
    }

    /// A sweep that stops at 10 Hz, estimated to 50 Hz: above 10 Hz the coherence is 0.2 (0.6
    /// in the one bin at 30 Hz) and the unwrapped phase runs off to -3 400 deg, as on a car's
    /// 100 Hz log.
    fn sweep_to_10_hz() -> Frequency {
        let freq: Vec<f64> = (1..=200).map(|k| 0.25 * f64::from(k)).collect();
        let phase = |f: f64| {
            if f <= 10.0 {
                -12.0 * f
            } else {
                -120.0 - 82.0 * (f - 10.0)
            }
        };
        let magnitude = |f: f64| {
            if f <= 10.0 {
                -2.0 * f
            } else {
                -45.0 + 10.0 * (f * 7.0).sin()
            }
        };
        Frequency {
            measured: response(&freq, magnitude, phase),
            nominal: response(&freq, |f| magnitude(f) - 0.5, |f| phase(f) - 3.0),
            after: response(&freq, |f| magnitude(f) - 0.2, phase),
        }
    }

    /// Linear map from pixels to values through the two outermost labelled ticks.
    fn axis(ticks: &[(f64, f64)]) -> impl Fn(f64) -> f64 + use<> {
        let lo = ticks
            .iter()
            .copied()
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("ticks");
        let hi = ticks
            .iter()
            .copied()
            .max_by(|a, b| a.0.total_cmp(&b.0))
            .expect("ticks");
        move |px: f64| lo.1 + (px - lo.0) * (hi.1 - lo.1) / (hi.0 - lo.0)
    }

    #[test]
    fn bode_draws_colour_only_where_coherent_and_phase_within_half_circle() {
        let f = sweep_to_10_hz();
        let svg = bode_plot("paper", &f, "nominal + delay").to_svg();
        let [magnitude, phase, coherence] = frames(&svg)[..] else {
            panic!("three panels expected: {:?}", frames(&svg));
        };
        let texts = elements(&svg, "text");
        // Tick labels: y ticks right-aligned left of the plots, x ticks under the bottom one.
        let y_ticks = |(left, top, _, bottom): (f64, f64, f64, f64)| -> Vec<(f64, f64)> {
            texts
                .iter()
                .filter(|(tag, _)| attr(tag, "text-anchor") == Some("end"))
                .map(|(tag, text)| (num(tag, "y"), text.parse::<f64>()))
                .filter(|&(y, _)| y >= top - 1.0 && y <= bottom + 1.0)
                .filter_map(|(y, v)| Some((y, v.ok()?)))
                .filter(|_| left > 0.0)
                .collect()
        };
        let x_ticks: Vec<(f64, f64)> = texts
            .iter()
            .filter(|(tag, _)| {
                num(tag, "y") > coherence.3 && attr(tag, "text-anchor") == Some("middle")
            })
            .filter_map(|(tag, text)| Some((num(tag, "x"), text.parse::<f64>().ok()?.log10())))
            .collect();
        assert!(x_ticks.len() >= 2, "x tick labels: {x_ticks:?}");
        let log_f = axis(&x_ticks);
        let degrees = axis(&y_ticks(phase));
        let inside = |(l, t, r, b): (f64, f64, f64, f64), (x, y): (f64, f64)| {
            x >= l - 1.0 && x <= r + 1.0 && y >= t - 1.0 && y <= b + 1.0
        };
        let coherence_at = |hz: f64| {
            let m = &f.measured;
            let k = (0..m.freq_hz.len())
                .min_by(|&a, &b| {
                    (m.freq_hz[a].ln() - hz.ln())
                        .abs()
                        .total_cmp(&(m.freq_hz[b].ln() - hz.ln()).abs())
                })
                .expect("bins");
            m.coherence[k]
        };
        let (mut coloured, mut grey, mut phase_points) = (0, 0, 0);
        // Lines, and the dots a lone sample between gaps is drawn as.
        let dots = elements(&svg, "circle").into_iter().map(|(tag, _)| {
            let colour = attr(tag, "fill").unwrap_or("").to_lowercase();
            (colour, vec![(num(tag, "cx"), num(tag, "cy"))])
        });
        for (stroke, points) in polylines(&svg).into_iter().chain(dots) {
            for &p in &points {
                let in_bode = inside(magnitude, p) || inside(phase, p);
                if !in_bode {
                    continue;
                }
                if is_palette(&stroke) {
                    coloured += 1;
                    let hz = 10f64.powf(log_f(p.0));
                    assert!(
                        coherence_at(hz) >= MIN_COHERENCE && hz <= 10.1,
                        "a {stroke} point at {hz:.2} Hz, where the coherence is {}",
                        coherence_at(hz)
                    );
                } else if stroke == Color::GRAY.to_string() {
                    grey += 1;
                }
                if inside(phase, p) && (is_palette(&stroke) || stroke == Color::GRAY.to_string()) {
                    phase_points += 1;
                    let deg = degrees(p.1);
                    assert!(
                        (-180.5..=180.5).contains(&deg),
                        "a phase point at {deg:.1} deg"
                    );
                }
            }
        }
        assert!(
            coloured > 50 && grey > 20 && phase_points > 50,
            "{coloured} {grey} {phase_points}"
        );
    }

    #[test]
    fn a_band_is_three_or_more_coherent_bins() {
        let mask = |bits: &str| bits.chars().map(|c| c == '1').collect::<Vec<_>>();
        assert_eq!(
            drop_short_runs(mask("1110100110111"), 3),
            mask("1110000000111")
        );
        assert_eq!(drop_short_runs(mask("11"), 3), mask("00"));
        assert_eq!(drop_short_runs(Vec::new(), 3), Vec::<bool>::new());
    }

    #[test]
    fn segment_replay_labels_fit_and_legend_colours_differ() {
        let t: Vec<f64> = (0..1000).map(|k| f64::from(k) * 0.01).collect();
        let wave = |a: f64| t.iter().map(|&t| a * (3.0 * t).sin()).collect::<Vec<_>>();
        let (m, s, r) = (wave(10.0), wave(9.0), wave(1.0));
        let svg = segments_plot(&t, [&m, &s, &r], [&m, &s, &r]).to_svg();
        let svg_tag = elements(&svg, "svg")[0].0;
        let (width, height) = (num(svg_tag, "width"), num(svg_tag, "height"));
        let texts = elements(&svg, "text");
        // Rotated y labels: centred on (x, y), running along y; widths as plot.rs estimates
        // them (0.56 em per character).
        let spans: Vec<(f64, f64, &str)> = texts
            .iter()
            .filter(|(tag, _)| attr(tag, "transform").is_some_and(|t| t.starts_with("rotate")))
            .map(|(tag, text)| {
                let half = 0.5 * text.chars().count() as f64 * num(tag, "font-size") * 0.56;
                let (x, y) = (num(tag, "x"), num(tag, "y"));
                assert!(
                    x >= 0.0 && x + num(tag, "font-size") <= width,
                    "{text} at x {x}"
                );
                (y - half, y + half, *text)
            })
            .collect();
        assert_eq!(spans.len(), 2, "{spans:?}");
        for &(a, b, text) in &spans {
            assert!(
                a >= 0.0 && b <= height,
                "{text} spans {a:.0}..{b:.0} of 0..{height}"
            );
        }
        assert!(
            spans[0].1 <= spans[1].0 || spans[1].1 <= spans[0].0,
            "y labels overlap: {spans:?}"
        );
        // Each legend entry: a sample line ending 6 px before its name, on the name's row.
        let lines = polylines(&svg);
        let legend: Vec<(f64, String, &str)> = texts
            .iter()
            .filter(|(tag, _)| attr(tag, "font-size") == Some("12"))
            .map(|(tag, text)| {
                let (x, y) = (num(tag, "x"), num(tag, "y"));
                let stroke = lines
                    .iter()
                    .find(|(_, p)| {
                        p.iter()
                            .all(|&(px, py)| py == y && px >= x - 31.0 && px <= x - 5.0)
                    })
                    .map(|(s, _)| s.clone())
                    .unwrap_or_else(|| panic!("no sample line for {text}"));
                (y, stroke, *text)
            })
            .collect();
        assert_eq!(legend.len(), 6, "{legend:?}");
        for (y, stroke, text) in &legend {
            let same = legend
                .iter()
                .filter(|(y2, s2, _)| y2 == y && s2 == stroke)
                .count();
            assert_eq!(
                same, 1,
                "{text} shares its colour {stroke} in its panel: {legend:?}"
            );
        }
    }
}

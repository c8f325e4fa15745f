//! The diagnosis pictures: residual over time with the regimes shaded, the Bode plot of
//! measured, nominal and nominal-plus-verdict, and the segment replay.

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
        let bode = BodePlot::new(&format!("Reference -> output, rig {}", rig.name))
            .series(
                "measured",
                &f.measured.freq_hz,
                &f.measured.magnitude_db,
                &f.measured.phase_deg,
            )
            .series_styled(
                "nominal",
                &f.nominal.freq_hz,
                &f.nominal.magnitude_db,
                &f.nominal.phase_deg,
                Style::new().dashed(),
            )
            .series(
                &after_name,
                &f.after.freq_hz,
                &f.after.magnitude_db,
                &f.after.phase_deg,
            )
            .coherence("measured", &f.measured.freq_hz, &f.measured.coherence);
        pictures.push(Picture {
            file: "gap_bode.svg",
            caption: "Reference to output: measured, nominal and with the verdict's effects",
            svg: bode.to_svg(),
        });
    }

    let downstream = match &rig.model {
        RigModel::Paper(pm) => super::model::replay_downstream(pm, rec, &Effects::nominal()),
        RigModel::Emps(_) | RigModel::Bam(_) => None,
    };
    if let (Some(m), Some(replay)) = (&rec.motor, &downstream) {
        let n = n.min(replay.len());
        let seg = TimePlot::new("Segment replay: where in the chain the residual arises")
            .panel(
                Panel::new("reference -> motor, deg at the wheel")
                    .series("measured motor", &t[..n], &m[..n])
                    .series_styled(
                        "closed loop, nominal",
                        &t[..n],
                        &sim0.motor[..n],
                        Style::new().dashed(),
                    )
                    .series(
                        "residual",
                        &t[..n],
                        &(0..n).map(|k| sim0.motor[k] - m[k]).collect::<Vec<_>>(),
                    ),
            )
            .panel(
                Panel::new("motor -> steering (nominal chain driven by the measured motor), deg")
                    .series("measured column", &t[..n], &rec.output[..n])
                    .series_styled(
                        "replayed column",
                        &t[..n],
                        &replay[..n],
                        Style::new().dashed(),
                    )
                    .series_styled(
                        "residual",
                        &t[..n],
                        &(0..n)
                            .map(|k| rec.output[k] - replay[k])
                            .collect::<Vec<_>>(),
                        Style::new().color(Color::VERMILLION),
                    ),
            )
            .x_label("time, s");
        pictures.push(Picture {
            file: "gap_segments.svg",
            caption: "Segment replay: where in the chain the residual arises",
            svg: seg.to_svg(),
        });
    }
    pictures
}

//! Where the gap lies: frequency bands, operating regimes, the segment of the chain, and the
//! signal, from the nominal model's residual (and the verdict model's, for the "after").

use super::model::{Effects, SimOut};
use super::rig::{Rig, RigModel};
use super::{Record, Scorer};
use crate::analysis::{FrequencyResponse, h1_estimate};
use rustfft::FftPlanner;
use rustfft::num_complex::Complex;

/// A regime's GoF is given only over at least this many samples.
const MIN_REGIME_SAMPLES: usize = 20;

/// Residual energy in one frequency band.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Band {
    pub lo_hz: f64,
    pub hi_hz: f64,
    /// Share of the nominal residual energy (output and effort normalised, summed).
    pub share: f64,
    pub share_output: f64,
    pub share_effort: f64,
    /// Eq. 11 on the band-limited signals, nominal and with the verdict's effects.
    pub gof_output_before: f64,
    pub gof_output_after: f64,
    pub gof_effort_before: f64,
    pub gof_effort_after: f64,
}

/// Residual against time in one operating regime.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Regime {
    pub name: String,
    pub time_share: f64,
    /// Share of the nominal residual energy that falls in the regime.
    pub residual_share: f64,
    pub residual_share_output: f64,
    pub residual_share_effort: f64,
    /// Combined GoF inside the regime, nominal and with the verdict's effects.
    pub gof_before: f64,
    pub gof_after: f64,
    /// Samples in the regime (for the shading).
    #[serde(skip)]
    pub mask: Vec<bool>,
}

/// Residual energy of each segment when replayed from its measured input.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Segment {
    pub name: String,
    /// Residual RMS in output units.
    pub rms: f64,
    pub share: f64,
}

/// Measured, nominal and verdict frequency responses reference -> output.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Frequency {
    pub measured: FrequencyResponse,
    pub nominal: FrequencyResponse,
    pub after: FrequencyResponse,
}

#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct Where {
    pub bands: Vec<Band>,
    pub regimes: Vec<Regime>,
    /// The segment holding most of the residual.
    pub segment: String,
    pub segments: Vec<Segment>,
    /// The signal whose GoF is lower under the nominal model.
    pub signal: String,
    #[serde(skip)]
    pub frequency: Frequency,
}

fn power(x: &[f64]) -> Vec<f64> {
    let n = x.len();
    if n < 4 {
        return vec![];
    }
    let mean = x.iter().sum::<f64>() / n as f64;
    let mut buf: Vec<Complex<f64>> = x.iter().map(|v| Complex::new(v - mean, 0.0)).collect();
    FftPlanner::<f64>::new()
        .plan_fft_forward(n)
        .process(&mut buf);
    buf[..n / 2 + 1].iter().map(|c| c.norm_sqr()).collect()
}

fn band_sum(p: &[f64], n: usize, fs: f64, lo: f64, hi: f64) -> f64 {
    p.iter()
        .enumerate()
        .filter(|(k, _)| {
            let f = *k as f64 * fs / n as f64;
            f >= lo && f < hi
        })
        .map(|(_, v)| v)
        .sum()
}

fn diff(y: &[f64], dt: f64) -> Vec<f64> {
    let n = y.len();
    (0..n)
        .map(|k| {
            let a = y[k.saturating_sub(1)];
            let b = y[(k + 1).min(n - 1)];
            (b - a) / (dt * ((k + 1).min(n - 1) - k.saturating_sub(1)).max(1) as f64)
        })
        .collect()
}

pub fn locate(rig: &Rig, rec: &Record, scorer: &Scorer, sim0: &SimOut, after: &SimOut) -> Where {
    let s = scorer.skip();
    let n = rec
        .len()
        .min(sim0.output.len())
        .min(after.output.len())
        .min(sim0.effort.len());
    if n <= s + 8 {
        return Where::default();
    }
    let fs = 1.0 / rec.dt;
    let y_o = &rec.output[s..n];
    let y_e = &rec.effort[s..n];
    let res = |sim: &[f64], y: &[f64]| -> Vec<f64> {
        sim[s..n].iter().zip(y).map(|(a, b)| a - b).collect()
    };
    let r0o = res(&sim0.output, y_o);
    let r0e = res(&sim0.effort, y_e);
    let r1o = res(&after.output, y_o);
    let r1e = res(&after.effort, y_e);
    let den = |y: &[f64]| {
        let m = y.iter().sum::<f64>() / y.len() as f64;
        y.iter().map(|v| (v - m).powi(2)).sum::<f64>().max(1e-300)
    };
    let (do_, de) = (den(y_o), den(y_e));

    // (a) bands
    let len = n - s;
    let (p_yo, p_ye) = (power(y_o), power(y_e));
    let (p0o, p0e, p1o, p1e) = (power(&r0o), power(&r0e), power(&r1o), power(&r1e));
    let tot_o: f64 = p0o.iter().sum::<f64>().max(1e-300);
    let tot_e: f64 = p0e.iter().sum::<f64>().max(1e-300);
    let tot = tot_o / do_ + tot_e / de;
    let mut edges = vec![0.0, 1.0, 2.0, 5.0, 10.0];
    edges.retain(|e| *e < fs / 2.0);
    if fs / 2.0 > 50.0 {
        edges.push(50.0);
    }
    edges.push(fs / 2.0 + 1e-9);
    let bands = edges
        .windows(2)
        .map(|w| {
            let b = |p: &[f64]| band_sum(p, len, fs, w[0], w[1]);
            let g = |r: f64, y: f64| 1.0 - (r / y.max(1e-300)).sqrt();
            Band {
                lo_hz: w[0],
                hi_hz: w[1].min(fs / 2.0),
                share: (b(&p0o) / do_ + b(&p0e) / de) / tot.max(1e-300),
                share_output: b(&p0o) / tot_o,
                share_effort: b(&p0e) / tot_e,
                gof_output_before: g(b(&p0o), b(&p_yo)),
                gof_output_after: g(b(&p1o), b(&p_yo)),
                gof_effort_before: g(b(&p0e), b(&p_ye)),
                gof_effort_after: g(b(&p1e), b(&p_ye)),
            }
        })
        .collect();

    // (b) regimes, from the reference's motion (noise-free) and the measured effort
    let r = &rec.reference[s..n];
    let v = diff(r, rec.dt);
    let a = diff(&v, rec.dt);
    let vmax = v.iter().fold(0.0f64, |m, x| m.max(x.abs())).max(1e-12);
    let mut reversal = vec![false; len];
    let half = ((0.05 / rec.dt).round() as usize).max(1);
    let mut last_sign = 0.0;
    for (k, vk) in v.iter().enumerate().take(len) {
        if vk.abs() > 0.01 * vmax {
            let sg = vk.signum();
            if last_sign != 0.0 && sg != last_sign {
                for m in reversal
                    .iter_mut()
                    .take((k + half).min(len))
                    .skip(k.saturating_sub(half))
                {
                    *m = true;
                }
            }
            last_sign = sg;
        }
    }
    let low: Vec<bool> = (0..len)
        .map(|k| v[k].abs() < 0.05 * vmax && !reversal[k])
        .collect();
    let limit = match &rig.model {
        RigModel::Paper(_) => 0.9 * steering_ecu::paper_mode::CURRENT_LIMIT.0 as f64,
        RigModel::Emps(m) => 0.9 * m.vsat,
        RigModel::Bam(_) => 0.9,
    };
    let at_limit: Vec<bool> = y_e.iter().map(|e| e.abs() >= limit).collect();
    let mut aa: Vec<f64> = a.iter().map(|x| x.abs()).collect();
    aa.sort_by(|x, y| x.total_cmp(y));
    let a90 = aa[(aa.len() * 9) / 10].max(1e-12);
    let high_acc: Vec<bool> = a.iter().map(|x| x.abs() > a90).collect();
    let regimes = [
        ("velocity_reversal", reversal),
        ("low_speed", low),
        ("current_limit", at_limit),
        ("high_acceleration", high_acc),
    ]
    .into_iter()
    .map(|(name, mask)| {
        let sum = |r: &[f64], d: f64| -> f64 {
            r.iter()
                .zip(&mask)
                .filter(|(_, m)| **m)
                .map(|(x, _)| x * x)
                .sum::<f64>()
                / d
        };
        let e0o = sum(&r0o, do_);
        let e0e = sum(&r0e, de);
        let t0o: f64 = r0o.iter().map(|x| x * x).sum::<f64>() / do_;
        let t0e: f64 = r0e.iter().map(|x| x * x).sum::<f64>() / de;
        let cnt = mask.iter().filter(|m| **m).count();
        // Regime GoF against the regime's own spread of each signal.
        let spread = |y: &[f64]| -> f64 {
            let sel: Vec<f64> = y
                .iter()
                .zip(&mask)
                .filter(|(_, m)| **m)
                .map(|(v, _)| *v)
                .collect();
            if sel.is_empty() {
                return 1e-300;
            }
            den(&sel)
        };
        let (so, se) = (spread(y_o), spread(y_e));
        // A GoF needs the regime's own signals to vary: with a handful of samples, or signals
        // nearly constant within the regime, the ratio divides by almost nothing and says
        // nothing (a BAM log's 0.2 % of low speed gave -4e150 %). Then there is no GoF.
        let varies = |own: f64, whole: f64| own / cnt.max(1) as f64 >= 0.01 * whole / len as f64;
        let measurable = cnt >= MIN_REGIME_SAMPLES && varies(so, do_) && varies(se, de);
        let g = |ro: &[f64], re: &[f64]| {
            super::combined_gof(1.0 - sum(ro, so).sqrt(), 1.0 - sum(re, se).sqrt())
        };
        let mut full = vec![false; s];
        full.extend_from_slice(&mask);
        Regime {
            name: name.into(),
            time_share: cnt as f64 / len as f64,
            residual_share: (e0o + e0e) / (t0o + t0e).max(1e-300),
            residual_share_output: e0o / t0o.max(1e-300),
            residual_share_effort: e0e / t0e.max(1e-300),
            gof_before: if measurable { g(&r0o, &r0e) } else { f64::NAN },
            gof_after: if measurable { g(&r1o, &r1e) } else { f64::NAN },
            mask: full,
        }
    })
    .collect();

    // (c) segments, each replayed from the measured signal at its input: reference -> motor
    // is the closed loop from the reference (its motor angle against the measured one);
    // motor -> steering is the nominal chain driven by the measured motor angle
    // (`model::replay_downstream`), its column against the measured one.
    let mut segments = Vec::new();
    let downstream = match &rig.model {
        RigModel::Paper(m) => super::model::replay_downstream(m, rec, &Effects::nominal()),
        RigModel::Emps(_) | RigModel::Bam(_) => None,
    };
    if let (Some(m), false, Some(replay)) = (&rec.motor, sim0.motor.is_empty(), &downstream) {
        let e1: f64 = (s..n).map(|k| (sim0.motor[k] - m[k]).powi(2)).sum();
        let e2: f64 = (s..n.min(replay.len()))
            .map(|k| (rec.output[k] - replay[k]).powi(2))
            .sum();
        let tot = (e1 + e2).max(1e-300);
        segments.push(Segment {
            name: "reference->motor".into(),
            rms: (e1 / len as f64).sqrt(),
            share: e1 / tot,
        });
        segments.push(Segment {
            name: "motor->steering".into(),
            rms: (e2 / len as f64).sqrt(),
            share: e2 / tot,
        });
    } else {
        let e: f64 = r0o.iter().map(|x| x * x).sum();
        segments.push(Segment {
            name: "reference->output".into(),
            rms: (e / len as f64).sqrt(),
            share: 1.0,
        });
    }
    let segment = segments
        .iter()
        .max_by(|a, b| a.share.total_cmp(&b.share))
        .map(|s| s.name.clone())
        .unwrap_or_default();

    // (d) the signal
    let go = 1.0 - (r0o.iter().map(|x| x * x).sum::<f64>() / do_).sqrt();
    let ge = 1.0 - (r0e.iter().map(|x| x * x).sum::<f64>() / de).sqrt();
    let signal = if go < ge { "output" } else { "effort" }.to_string();

    // Frequency responses reference -> output
    let seg_s = (len as f64 * rec.dt / 4.0).clamp(0.5, 4.0);
    let fmax = fs / 2.0;
    let frequency = Frequency {
        measured: h1_estimate(r, y_o, fs, seg_s, fmax),
        nominal: h1_estimate(r, &sim0.output[s..n], fs, seg_s, fmax),
        after: h1_estimate(r, &after.output[s..n], fs, seg_s, fmax),
    };
    Where {
        bands,
        regimes,
        segment,
        segments,
        signal,
        frequency,
    }
}

impl Where {
    pub fn summary(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        let _ = writeln!(
            s,
            "  bands (share of the nominal residual energy; GoF output/effort before -> after):"
        );
        for b in &self.bands {
            let _ = writeln!(
                s,
                "    {:>5.1}-{:<5.1} Hz  {:5.1} %   output {:6.1} -> {:6.1} %   effort {:6.1} -> {:6.1} %",
                b.lo_hz,
                b.hi_hz,
                100.0 * b.share,
                100.0 * b.gof_output_before,
                100.0 * b.gof_output_after,
                100.0 * b.gof_effort_before,
                100.0 * b.gof_effort_after
            );
        }
        let _ = writeln!(
            s,
            "  regimes (share of time / of the residual; GoF before -> after):"
        );
        for r in &self.regimes {
            let gof = if r.gof_before.is_finite() && r.gof_after.is_finite() {
                format!(
                    "{:6.1} -> {:6.1} %",
                    100.0 * r.gof_before,
                    100.0 * r.gof_after
                )
            } else {
                "no GoF: too few samples, or the signals barely vary there".to_string()
            };
            let _ = writeln!(
                s,
                "    {:<18} {:5.1} % / {:5.1} %   {gof}",
                r.name,
                100.0 * r.time_share,
                100.0 * r.residual_share,
            );
        }
        let segs: Vec<String> = self
            .segments
            .iter()
            .map(|g| format!("{} {:.0} % (RMS {:.4})", g.name, 100.0 * g.share, g.rms))
            .collect();
        let _ = writeln!(s, "  segment: {} [{}]", self.segment, segs.join(", "));
        let _ = writeln!(s, "  signal: the {} departs more", self.signal);
        s
    }
}

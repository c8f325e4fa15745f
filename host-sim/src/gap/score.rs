//! Scoring a simulation against a log: eq. 11's GoF per signal ([`Fit`]), the likelihood
//! cost the fits minimise ([`Scorer`]) and the floors it is judged against.

use super::Record;
use super::diagnosis::{
    OFFSET_MIN_SHARE, OFFSET_SIGNIFICANCE, OUTPUT_OFFSET_MIN_COUNTS, OUTPUT_OFFSET_MIN_SHARE,
    SCALE_MIN_SHARE,
};
use super::model::{self, Effects, SimOut};
use super::rig::{Rig, RigModel};

/// The model of a rig with effects, simulated on a record.
pub fn simulate(rig: &Rig, rec: &Record, fx: &Effects) -> SimOut {
    let mut out = match &rig.model {
        RigModel::Paper(m) => model::simulate_paper(m, rec, fx),
        RigModel::Emps(m) => model::simulate_emps(m, rec, fx),
        RigModel::Bam(m) => model::simulate_bam(m, rec, fx),
    };
    if fx.effort_delay_s > 0.0 {
        out.effort = model::delayed(&out.effort, fx.effort_delay_s, rec.dt);
    }
    out
}

/// Eq. 11 per signal and combined, on a record against a simulation, from `skip` on.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Fit {
    pub gof: f64,
    pub gof_output: f64,
    pub gof_effort: f64,
    pub rms_output: f64,
    pub rms_effort: f64,
    /// `100 ||y - ysim|| / ||y||` on the effort (the EMPS benchmark's figure), %.
    pub effort_rel_error_pct: f64,
}

/// The residual every fit minimises: each signal's error divided by that signal's own noise
/// (a Gaussian likelihood), so a signal is weighed by how much of it a model can predict, not
/// by its size. Before the noise is known (`identify`, a scorer without `with_noise`), each
/// signal is divided by its demeaned norm instead (eq. 11's denominator).
#[derive(Debug, Clone)]
pub struct Scorer {
    skip: usize,
    den_output: f64,
    den_effort: f64,
    noise: Option<Noise>,
}

/// The white measurement noise of each signal, in the signal's unit, estimated from the
/// nominal model's residual.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Noise {
    pub output: f64,
    pub effort: f64,
}

pub(super) fn demeaned_norm(y: &[f64]) -> f64 {
    let n = y.len().max(1) as f64;
    let mean = y.iter().sum::<f64>() / n;
    y.iter()
        .map(|v| (v - mean).powi(2))
        .sum::<f64>()
        .sqrt()
        .max(1e-12)
}

/// The standard deviation of the white part of `r`: the median absolute third difference
/// (white noise of variance s^2 gives third differences of variance 20 s^2). A model error is
/// smooth on the grid, so its third difference is small; the median keeps the few samples
/// where it is not (a reversal, a step in the reference) from counting as noise.
pub(super) fn white_sigma(r: &[f64]) -> f64 {
    if r.len() < 8 {
        return 0.0;
    }
    let mut a: Vec<f64> = r
        .windows(4)
        .map(|w| (w[3] - 3.0 * w[2] + 3.0 * w[1] - w[0]).abs())
        .collect();
    a.sort_by(|x, y| x.total_cmp(y));
    a[a.len() / 2] / 0.6745 / 20f64.sqrt()
}

impl Scorer {
    pub fn new(rig: &Rig, rec: &Record) -> Scorer {
        let skip = ((rig.skip_s / rec.dt).round() as usize).min(rec.len().saturating_sub(2));
        Scorer {
            skip,
            den_output: demeaned_norm(&rec.output[skip..]),
            den_effort: demeaned_norm(&rec.effort[skip..]),
            noise: None,
        }
    }

    /// The likelihood scorer: each signal's noise estimated from the nominal model's residual
    /// `sim0 - rec` (not from the raw signal, whose own curvature, a chirp's, is no noise).
    /// A floor of a thousandth of the signal's RMS per sample keeps a noiseless log finite.
    pub fn with_noise(mut self, rec: &Record, sim0: &SimOut) -> Scorer {
        let n = rec.len().min(sim0.output.len()).min(sim0.effort.len());
        let s = self.skip.min(n);
        let res = |a: &[f64], b: &[f64]| -> Vec<f64> {
            a[s..n].iter().zip(&b[s..n]).map(|(x, y)| x - y).collect()
        };
        let per_sample = ((n - s).max(1) as f64).sqrt();
        let sig = |r: Vec<f64>, den: f64| white_sigma(&r).max(1e-3 * den / per_sample);
        let effort = res(&sim0.effort, &rec.effort);
        // A current of instantaneous samples of the loop's chatter ([`super::chatter`]): its
        // scatter about the model is the chatter, whose median third difference takes its
        // heavy tails and the slow beat of a loop sampled at the rows' rate for less than it
        // is; its RMS about the residual's mean is its noise.
        let effort_noise = if rec.current_chatter {
            (demeaned_norm(&effort) / per_sample).max(1e-3 * self.den_effort / per_sample)
        } else {
            sig(effort, self.den_effort)
        };
        self.noise = Some(Noise {
            output: sig(res(&sim0.output, &rec.output), self.den_output),
            effort: effort_noise,
        });
        self
    }

    /// The same noise on another record of the same log (a window of it).
    pub fn on(&self, rig: &Rig, rec: &Record) -> Scorer {
        Scorer {
            noise: self.noise,
            ..Scorer::new(rig, rec)
        }
    }

    pub fn noise(&self) -> Option<Noise> {
        self.noise
    }

    pub fn skip(&self) -> usize {
        self.skip
    }

    fn scales(&self) -> (f64, f64) {
        match self.noise {
            Some(n) => (n.output, n.effort),
            None => (self.den_output, self.den_effort),
        }
    }

    pub fn residual(&self, rec: &Record, sim: &SimOut) -> Vec<f64> {
        let n = rec.len().min(sim.output.len()).min(sim.effort.len());
        if n <= self.skip {
            return vec![1e3; 2];
        }
        let (so, se) = self.scales();
        let mut r = Vec::with_capacity(2 * (n - self.skip));
        for k in self.skip..n {
            r.push((sim.output[k] - rec.output[k]) / so);
        }
        for k in self.skip..n {
            r.push((sim.effort[k] - rec.effort[k]) / se);
        }
        r
    }

    pub fn fit(&self, rec: &Record, sim: &SimOut) -> Fit {
        let n = rec.len().min(sim.output.len()).min(sim.effort.len());
        let s = self.skip.min(n);
        let sq = |a: &[f64], b: &[f64]| -> f64 {
            a[s..n]
                .iter()
                .zip(&b[s..n])
                .map(|(x, y)| (x - y).powi(2))
                .sum::<f64>()
        };
        let eo = sq(&sim.output, &rec.output);
        let ee = sq(&sim.effort, &rec.effort);
        let go = 1.0 - eo.sqrt() / self.den_output;
        let ge = 1.0 - ee.sqrt() / self.den_effort;
        let m = (n - s).max(1) as f64;
        // A current of instantaneous samples of the loop's chatter cannot tell cars apart: the
        // motor angle, which answers the reference through the position loop, stands in for
        // it ([`super::chatter`]).
        let gof = match (&rec.motor, rec.current_chatter) {
            (Some(motor), true) if motor.len() >= n && sim.motor.len() >= n => {
                let gm = 1.0 - sq(&sim.motor, motor).sqrt() / demeaned_norm(&motor[s..n]);
                combined_gof(go, gm)
            }
            (_, true) => go,
            _ => combined_gof(go, ge),
        };
        let effort_norm = rec.effort[s..n]
            .iter()
            .map(|v| v * v)
            .sum::<f64>()
            .sqrt()
            .max(1e-12);
        Fit {
            gof,
            gof_output: go,
            gof_effort: ge,
            rms_output: (eo / m).sqrt(),
            rms_effort: (ee / m).sqrt(),
            effort_rel_error_pct: 100.0 * ee.sqrt() / effort_norm,
        }
    }

    /// The cost the measurement noise alone would leave. With the likelihood scorer every
    /// residual sample is in units of its own noise, so the floor is the number of samples;
    /// without it, the white part of each raw signal, normalised like the residual.
    pub fn noise_floor_cost(&self, rec: &Record) -> f64 {
        let m = rec.len().saturating_sub(self.skip) as f64;
        if self.noise.is_some() {
            return 2.0 * m;
        }
        let floor = |y: &[f64], den: f64| -> f64 {
            let sigma = white_sigma(&y[self.skip..]);
            sigma * sigma * m / (den * den)
        };
        floor(&rec.output, self.den_output) + floor(&rec.effort, self.den_effort)
    }
}

/// How many contiguous blocks [`effort_offset`] cuts the residual into: enough that their means
/// scatter estimates the standard error of the whole mean, few enough that each block holds
/// several cycles of a sweep or a track's turns, so a zero-mean residual gives block means of
/// either sign.
pub const OFFSET_BLOCKS: usize = 16;

/// A constant part of the effort's residual (log minus model): what a current sensor's offset
/// leaves, and what none of the effects or Table 4's parameters make. Each of those is odd in
/// the motion, so a sweep or a track averages it out, but for a gain (the torque constant, a
/// transmission ratio off the table), whose residual follows the current: a track that turns
/// one way more than the other leaves it a mean. So the offset is the intercept of the residual
/// regressed on the model's effort, not the residual's plain mean. The same reading of the
/// output is a sensor's zero off (`score::output_offset`).
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct Offset {
    /// The intercept, in the signal's unit (A or deg on the paper rig).
    pub mean: f64,
    /// Its standard error, from the scatter of the intercept over `OFFSET_BLOCKS` (16)
    /// contiguous blocks (the residual is far from white: a block's mean carries its
    /// correlation).
    pub standard_error: f64,
    /// The residual's RMS about zero, in the effort's unit.
    pub residual_rms: f64,
    /// The logged signal's RMS about zero, in its unit.
    pub signal_rms: f64,
    /// The share of `signal_rms` it must reach to stand out, a fraction: `OFFSET_MIN_SHARE` for
    /// the effort, `OUTPUT_OFFSET_MIN_SHARE` for the output.
    pub min_share: f64,
    /// The size it must pass to stand out, in the signal's unit: 0 for the effort;
    /// `OUTPUT_OFFSET_MIN_COUNTS` of the rig's position sensor's count for the output (a car at
    /// rest reads the count it stands in, not where in the count it stands).
    pub min_abs: f64,
}

impl Offset {
    /// The intercept over its standard error.
    pub fn significance(&self) -> f64 {
        self.mean.abs() / self.standard_error.max(1e-12)
    }

    /// The intercept's size as a share of the logged signal's RMS, a fraction.
    pub fn share_of_signal(&self) -> f64 {
        self.mean.abs() / self.signal_rms.max(1e-12)
    }

    /// A constant no noise and no car the table describes leaves: beyond
    /// `OFFSET_SIGNIFICANCE` (6) standard errors, `min_share` of the signal and `min_abs`.
    pub fn stands_out(&self) -> bool {
        stands_out(self.significance(), self.share_of_signal(), self.min_share)
            && self.mean.abs() > self.min_abs
    }
}

/// A reading of the effort against the model's is the log's own, not noise, beyond
/// [`OFFSET_SIGNIFICANCE`] standard errors, and worth a team's look beyond `min_share`.
fn stands_out(significance: f64, share: f64, min_share: f64) -> bool {
    significance > OFFSET_SIGNIFICANCE && share > min_share
}

/// The effort's [`Offset`] of `sim` against `rec`, from `skip` on.
pub fn effort_offset(rec: &Record, sim: &SimOut, skip: usize) -> Offset {
    offset_of(&rec.effort, &sim.effort, skip, OFFSET_MIN_SHARE, 0.0)
}

/// The output's [`Offset`] of `sim` against `rec`, from `skip` on: on the paper rig, a column
/// encoder whose zero is not the rack's centre. The model's column follows its reference as
/// the car's does; where the loop closes on the motor (the paper controller), the log's column
/// then keeps the zero's error throughout.
///
/// It keeps as well where in its first count the car stood: the model starts at the count
/// the log's first row reads, the car anywhere within it, and a loop on the motor holds that
/// part of a count through the log (the simulated EPOS4 car started 0.03, 0.05 and 0.08 deg
/// above a count reads 0.028, 0.049 and 0.077 deg). So an offset stands out only beyond
/// `OUTPUT_OFFSET_MIN_COUNTS` of `count`, the position sensor's count in the output's unit.
pub fn output_offset(rec: &Record, sim: &SimOut, skip: usize, count: f64) -> Offset {
    offset_of(
        &rec.output,
        &sim.output,
        skip,
        OUTPUT_OFFSET_MIN_SHARE,
        OUTPUT_OFFSET_MIN_COUNTS * count,
    )
}

/// The intercept of `log - model` regressed on `model`, from `skip` on, to stand out beyond
/// `min_share` of the log's RMS and beyond `min_abs`.
fn offset_of(log: &[f64], model: &[f64], skip: usize, min_share: f64, min_abs: f64) -> Offset {
    let n = log.len().min(model.len());
    let s = skip.min(n);
    let model = &model[s..n];
    let log = &log[s..n];
    let r: Vec<f64> = log.iter().zip(model).map(|(y, x)| y - x).collect();
    let len = r.len() / OFFSET_BLOCKS;
    if len < 2 {
        return Offset::default();
    }
    let m = r.len() as f64;
    let model_mean = model.iter().sum::<f64>() / m;
    let r_mean = r.iter().sum::<f64>() / m;
    let (sxy, sxx) = model.iter().zip(&r).fold((0.0, 0.0), |(sxy, sxx), (x, y)| {
        let dx = x - model_mean;
        (sxy + dx * (y - r_mean), sxx + dx * dx)
    });
    let gain = if sxx > 0.0 { sxy / sxx } else { 0.0 };
    let intercepts: Vec<f64> = r
        .chunks_exact(len)
        .zip(model.chunks_exact(len))
        .take(OFFSET_BLOCKS)
        .map(|(rb, mb)| rb.iter().zip(mb).map(|(y, x)| y - gain * x).sum::<f64>() / len as f64)
        .collect();
    let k = intercepts.len() as f64;
    let mean = intercepts.iter().sum::<f64>() / k;
    let var = intercepts.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / (k - 1.0);
    let rms = |v: &[f64]| (v.iter().map(|x| x * x).sum::<f64>() / m).sqrt();
    Offset {
        mean,
        standard_error: (var / k).sqrt(),
        residual_rms: rms(&r),
        signal_rms: rms(log),
        min_share,
        min_abs,
    }
}

/// How many times the nominal model's effort the log's is, throughout: what a torque constant
/// off Table 1 leaves (the same motion takes 1/x the current), or a current scaled wrong by a
/// logger. Table 4 off by a few per cent scales the current by as little; a car off it by x1.5
/// in one parameter changes its shape more than its size.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Scale {
    /// The log's effort over the model's (1 = the same).
    pub factor: f64,
    /// Its standard error, by a jackknife over `OFFSET_BLOCKS` (16) contiguous blocks.
    pub standard_error: f64,
}

impl Scale {
    /// No reading (a log too short for its blocks, or a model effort without motion): the
    /// factor 1, nothing off, so no verdict rests on it.
    pub const UNREAD: Scale = Scale {
        factor: 1.0,
        standard_error: 0.0,
    };

    /// How far the factor stands from 1, in standard errors.
    pub fn significance(&self) -> f64 {
        (self.factor - 1.0).abs() / self.standard_error.max(1e-12)
    }

    /// A current a share off the model's throughout: beyond `OFFSET_SIGNIFICANCE` (6) standard
    /// errors and `SCALE_MIN_SHARE` (15 %) from 1.
    pub fn stands_out(&self) -> bool {
        stands_out(
            self.significance(),
            (self.factor - 1.0).abs(),
            SCALE_MIN_SHARE,
        )
    }
}

/// The span of [`effort_scale`]'s moving mean, s: longer than the current's chatter (a
/// loop's quantised feedback, which a model and a car do not share sample for sample), short
/// beside a sweep's or a track's motion.
const SCALE_SMOOTHING_S: f64 = 0.05;

/// The effort's [`Scale`] of `sim` against `rec`, from `skip` on: the least-squares slope of
/// the log's effort on the model's, with an intercept, both through the same moving mean. A
/// slope on the raw model effort would be pulled towards zero by its chatter (the ECU
/// controller over an EPOS4: 0.3 A RMS that does not repeat), the same linear mean on both
/// leaves the slope of what they share.
pub fn effort_scale(rec: &Record, sim: &SimOut, skip: usize) -> Scale {
    scale_of(rec, sim, skip, None)
}

/// The effort's [`Scale`] with a Coulomb friction's current fitted beside it: the slope on the
/// model's effort of a least-squares fit that also has the sign of the model's motion (its
/// motor, else its output) and an intercept, through the same moving mean.
///
/// A friction the model lacks adds a current of the motion's sign and a fixed size; a torque
/// constant off Table 1 scales all of the current. Read alone, the slope takes the friction's
/// share where the damping's current and the motion's sign go together (the world's friction
/// cars read x1.2-1.4 at 4-6 standard errors); beside the sign it is left with what scales.
pub fn effort_scale_beside_friction(rec: &Record, sim: &SimOut, skip: usize) -> Scale {
    let motion = if sim.motor.len() >= sim.effort.len() {
        &sim.motor
    } else {
        &sim.output
    };
    let sign: Vec<f64> = (0..sim.effort.len())
        .map(|k| {
            let v = motion.get(k).copied().unwrap_or(0.0)
                - motion.get(k.saturating_sub(1)).copied().unwrap_or(0.0);
            if v > 0.0 {
                1.0
            } else if v < 0.0 {
                -1.0
            } else {
                0.0
            }
        })
        .collect();
    scale_of(rec, sim, skip, Some(&sign))
}

/// The slope of the log's effort on the model's, with an intercept and, if given, a second
/// regressor beside it; all through a moving mean of `SCALE_SMOOTHING_S`, its standard error
/// by a jackknife over `OFFSET_BLOCKS` blocks.
fn scale_of(rec: &Record, sim: &SimOut, skip: usize, beside: Option<&[f64]>) -> Scale {
    let n = rec
        .len()
        .min(sim.effort.len())
        .min(beside.map_or(usize::MAX, <[f64]>::len));
    let s = skip.min(n);
    let w = ((SCALE_SMOOTHING_S / rec.dt.max(1e-9)).round() as usize).max(1);
    let smooth = |v: &[f64]| -> Vec<f64> {
        v.windows(w)
            .map(|c| c.iter().sum::<f64>() / w as f64)
            .collect()
    };
    let x = smooth(&sim.effort[s..n]);
    let y = smooth(&rec.effort[s..n]);
    let z = beside.map_or_else(|| vec![0.0; x.len()], |b| smooth(&b[s..n]));
    let len = x.len() / OFFSET_BLOCKS;
    if len < 2 {
        return Scale::UNREAD;
    }
    // Each block's sums [1, x, z, y, xx, xz, zz, xy, zy], so the slope without any one block
    // is cheap.
    let sums: Vec<[f64; 9]> = (0..OFFSET_BLOCKS)
        .map(|b| {
            (b * len..(b + 1) * len).fold([0.0; 9], |a, k| {
                let (x, z, y) = (x[k], z[k], y[k]);
                [
                    a[0] + 1.0,
                    a[1] + x,
                    a[2] + z,
                    a[3] + y,
                    a[4] + x * x,
                    a[5] + x * z,
                    a[6] + z * z,
                    a[7] + x * y,
                    a[8] + z * y,
                ]
            })
        })
        .collect();
    let two = beside.is_some();
    let slope = |t: [f64; 9]| {
        // Centred sums: xx, xz, zz, xy, zy.
        let c = |a: usize, b: usize, ab: usize| t[ab] - t[a] * t[b] / t[0];
        let (sxx, sxz, szz, sxy, szy) =
            (c(1, 1, 4), c(1, 2, 5), c(2, 2, 6), c(1, 3, 7), c(2, 3, 8));
        if !two {
            return if sxx > 0.0 { sxy / sxx } else { f64::NAN };
        }
        let det = sxx * szz - sxz * sxz;
        if det > 1e-12 * sxx * szz && sxx > 0.0 {
            (sxy * szz - sxz * szy) / det
        } else {
            f64::NAN
        }
    };
    let add = |a: [f64; 9], b: &[f64; 9]| std::array::from_fn(|i| a[i] + b[i]);
    let total = sums.iter().fold([0.0; 9], add);
    let factor = slope(total);
    let k = sums.len() as f64;
    let without: Vec<f64> = sums
        .iter()
        .map(|b| slope(std::array::from_fn(|i| total[i] - b[i])))
        .collect();
    let mean = without.iter().sum::<f64>() / k;
    let var = (k - 1.0) / k * without.iter().map(|v| (v - mean).powi(2)).sum::<f64>();
    if !factor.is_finite() || !var.is_finite() {
        return Scale::UNREAD;
    }
    Scale {
        factor,
        standard_error: var.sqrt(),
    }
}

/// Combined GoF of the output and the effort: `1 - sqrt(((1-go)^2 + (1-ge)^2) / 2)`.
pub fn combined_gof(go: f64, ge: f64) -> f64 {
    1.0 - (((1.0 - go).powi(2) + (1.0 - ge).powi(2)) / 2.0).sqrt()
}

pub(super) fn cost(r: &[f64]) -> f64 {
    r.iter().map(|v| v * v).sum()
}

/// How closely any model can predict `rec`: the nominal model's output `sim0` scored (with
/// the log's own denominators) against the same model run on the reference moved by a
/// ten-millionth of its largest magnitude. That change is far below any sensor's resolution;
/// a loop without a quantised feedback answers it by as little (GoF ~100 %), one that feeds
/// quantised counts back moves onto another phase of its chatter at the first rounding it
/// flips, as a car does on its noise. The steer-by-wire car's own chain, two runs 0.5 N of
/// rack friction apart, shows the same: its ECU controller over the EPOS4 changes its current
/// by 0.3 A RMS, the paper controller by 1 mA.
pub fn repeatability(rig: &Rig, rec: &Record, scorer: &Scorer, sim0: &SimOut) -> Fit {
    let span = rec.reference.iter().fold(0.0_f64, |m, v| m.max(v.abs()));
    let step = 1e-7 * span.max(f64::MIN_POSITIVE);
    let mut moved = rec.clone();
    for r in &mut moved.reference {
        *r += step;
    }
    let again = simulate(rig, &moved, &Effects::nominal());
    scorer.fit(&sim0.as_log(rec), &again)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record_and_model(effort: impl Fn(f64) -> (f64, f64)) -> (Record, SimOut) {
        let n = 4000;
        let (logged, model): (Vec<f64>, Vec<f64>) = (0..n).map(|k| effort(k as f64 * 1e-3)).unzip();
        let rec = Record {
            dt: 1e-3,
            reference: vec![0.0; n],
            output: vec![0.0; n],
            effort: logged,
            ..Record::default()
        };
        let sim = SimOut {
            output: vec![0.0; n],
            effort: model,
            motor: vec![],
        };
        (rec, sim)
    }

    #[test]
    fn an_offset_is_found_beside_a_gain_error_on_a_current_with_a_mean() {
        // A track that turns one way more: the current has a mean of 2 A, and the car's
        // torque constant is 10 % off, so the residual's plain mean is 0.2 A besides the
        // sensor's 0.3 A.
        let (rec, sim) = record_and_model(|t| {
            let i = 2.0 + 5.0 * (2.0 * std::f64::consts::PI * 1.3 * t).sin();
            (1.1 * i + 0.3, i)
        });
        let o = effort_offset(&rec, &sim, 0);
        assert!((o.mean - 0.3).abs() < 1e-9, "intercept {}", o.mean);
        assert!(o.significance() > 100.0, "{o:?}");
    }

    #[test]
    fn a_scale_is_read_through_chatter_the_model_does_not_share() {
        // The car's current is 0.75 times the model's (its torque constant x1.33) with a
        // constant beside it; the model's own current chatters by 0.5 A that the car's does
        // not, which pulls a plain slope to 0.5.
        let (rec, sim) = record_and_model(|t| {
            let i = 2.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
            let chatter = 0.5 * (2.0 * std::f64::consts::PI * 137.0 * t + 3.0 * t * t).sin();
            (0.75 * i + 0.2, i + chatter)
        });
        let sc = effort_scale(&rec, &sim, 0);
        assert!((sc.factor - 0.75).abs() < 0.02, "{sc:?}");
        assert!(sc.significance() > 20.0, "{sc:?}");
        // The same currents: a factor of 1, within its error.
        let (rec, sim) = record_and_model(|t| {
            let i = 2.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
            (i + 0.1 * (2.0 * std::f64::consts::PI * 91.0 * t).sin(), i)
        });
        let sc = effort_scale(&rec, &sim, 0);
        assert!((sc.factor - 1.0).abs() < 0.01, "{sc:?}");
    }

    /// A chirp's motion (1-4 Hz over 8 s at 1 kHz): the model's current is its inertia's and
    /// damping's, the car's `car(current, sign of the motion)`.
    fn chirp_with(car: impl Fn(f64, f64) -> f64) -> (Record, SimOut) {
        let n = 8000;
        let tau = std::f64::consts::TAU;
        let phase = |t: f64| tau * (t + 0.1875 * t * t);
        let (mut output, mut model, mut logged) = (vec![], vec![], vec![]);
        for k in 0..n {
            let t = k as f64 * 1e-3;
            let w = tau * (1.0 + 0.375 * t);
            let (p, v, a) = (phase(t).sin(), w * phase(t).cos(), -w * w * phase(t).sin());
            let i = 0.005 * a + 0.3 * v;
            output.push(p);
            model.push(i);
            logged.push(car(i, v.signum()));
        }
        let rec = Record {
            dt: 1e-3,
            reference: output.clone(),
            output: output.clone(),
            effort: logged,
            ..Record::default()
        };
        let sim = SimOut {
            output,
            effort: model,
            motor: vec![],
        };
        (rec, sim)
    }

    #[test]
    fn friction_reads_as_a_scale_alone_but_not_beside_the_motions_sign() {
        // 2 A of friction: the damping's current goes with the motion's sign, so the plain
        // slope takes a share of it.
        let (rec, sim) = chirp_with(|i, sign| i + 2.0 * sign);
        let alone = effort_scale(&rec, &sim, 0);
        assert!(alone.factor > 1.15, "{alone:?}");
        let beside = effort_scale_beside_friction(&rec, &sim, 0);
        assert!((beside.factor - 1.0).abs() < 0.03, "{beside:?}");
        assert!(!beside.stands_out(), "{beside:?}");
        // A torque constant x0.74: the current is x1.35 throughout, beside the sign or not.
        let (rec, sim) = chirp_with(|i, _| 1.35 * i);
        let beside = effort_scale_beside_friction(&rec, &sim, 0);
        assert!((beside.factor - 1.35).abs() < 0.03, "{beside:?}");
        assert!(beside.stands_out(), "{beside:?}");
        // Both: the scale is still read.
        let (rec, sim) = chirp_with(|i, sign| 1.35 * i + 2.0 * sign);
        let beside = effort_scale_beside_friction(&rec, &sim, 0);
        assert!((beside.factor - 1.35).abs() < 0.03, "{beside:?}");
    }

    #[test]
    fn a_motion_of_one_sign_gives_no_scale_beside_friction() {
        // The sign never changes: the friction and the intercept are one, nothing is read.
        let (mut rec, mut sim) = chirp_with(|i, _| 1.35 * i);
        sim.output = (0..sim.output.len()).map(|k| k as f64).collect();
        rec.output = sim.output.clone();
        assert_eq!(effort_scale_beside_friction(&rec, &sim, 0), Scale::UNREAD);
    }

    #[test]
    fn a_log_too_short_or_without_motion_has_no_scale() {
        let (rec, sim) = record_and_model(|_| (1.0, 0.0));
        let still = effort_scale(&rec, &sim, 0);
        assert_eq!(still, Scale::UNREAD);
        assert_eq!(still.significance(), 0.0);
        let (mut rec, mut sim) = record_and_model(|t| (t, t));
        rec.effort.truncate(20);
        sim.effort.truncate(20);
        assert_eq!(effort_scale(&rec, &sim, 0), Scale::UNREAD);
    }

    #[test]
    fn a_residual_without_a_constant_is_no_offset() {
        // Chatter and a gain error, no constant: the intercept scatters around zero.
        let (rec, sim) = record_and_model(|t| {
            let i = 5.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
            let chatter = 0.5 * (2.0 * std::f64::consts::PI * 37.0 * t + 3.0 * t * t).sin();
            (0.9 * i + chatter, i)
        });
        let o = effort_offset(&rec, &sim, 0);
        assert!(o.significance() < 3.0, "{o:?}");
        assert!(o.mean.abs() < 0.01 * o.signal_rms, "{o:?}");
    }

    #[test]
    fn a_log_too_short_for_its_blocks_has_no_offset() {
        let (mut rec, mut sim) = record_and_model(|_| (1.0, 0.0));
        rec.effort.truncate(2 * OFFSET_BLOCKS - 1);
        sim.effort.truncate(2 * OFFSET_BLOCKS - 1);
        assert_eq!(effort_offset(&rec, &sim, 0), Offset::default());
    }

    #[test]
    fn the_output_offset_reads_the_output_and_not_the_effort() {
        // A column that reads 0.35 deg high on a sweep whose model lags it a little, and an
        // effort with no constant: only the output keeps one.
        let (mut rec, mut sim) = record_and_model(|t| {
            let i = 5.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
            (i, i)
        });
        let angle = |t: f64| 8.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
        rec.output = (0..rec.len())
            .map(|k| angle(k as f64 * 1e-3) + 0.35)
            .collect();
        sim.output = (0..rec.len())
            .map(|k| 0.98 * angle(k as f64 * 1e-3 - 0.002))
            .collect();
        let count = 360.0 / 4096.0;
        let zero = output_offset(&rec, &sim, 0, count);
        assert!((zero.mean - 0.35).abs() < 0.01, "{zero:?}");
        assert!(zero.stands_out(), "{zero:?}");
        let effort = effort_offset(&rec, &sim, 0);
        assert!(!effort.stands_out(), "{effort:?}");
        // Without it, none.
        rec.output.iter_mut().for_each(|y| *y -= 0.35);
        assert!(!output_offset(&rec, &sim, 0, count).stands_out());
        // Nor where the car stood within its first count: 0.08 deg, under one count.
        rec.output.iter_mut().for_each(|y| *y += 0.08);
        let within = output_offset(&rec, &sim, 0, count);
        assert!((within.mean - 0.08).abs() < 0.01, "{within:?}");
        assert!(
            within.significance() > 6.0 && !within.stands_out(),
            "{within:?}"
        );
        // A track turns the column 40 deg each way (28 deg RMS): three encoder counts
        // (0.26 deg) are under 1 % of it, and still a zero off.
        let angle = |t: f64| 40.0 * (2.0 * std::f64::consts::PI * 0.7 * t).sin();
        rec.output = (0..rec.len())
            .map(|k| angle(k as f64 * 1e-3) + 3.0 * 360.0 / 4096.0)
            .collect();
        sim.output = (0..rec.len())
            .map(|k| 0.99 * angle(k as f64 * 1e-3 - 0.0002))
            .collect();
        let zero = output_offset(&rec, &sim, 0, count);
        assert!(zero.share_of_signal() < 0.01, "{zero:?}");
        assert!(zero.stands_out(), "{zero:?}");
    }
}

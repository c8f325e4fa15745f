//! The search: fitting one effect or a set of them (Levenberg-Marquardt on the model), the
//! window a long log is fitted on, and the worker pool.

use super::diagnosis::{Candidate, Options, PARAMETER_ITERATIONS, PARAMETER_TOLERANCE};
use super::effects::{apply_all, specs_of};
use super::fit::{self, FitOptions, ParamSpec};
use super::model::{Effects, SimOut};
use super::rig::{Rig, RigModel};
use super::score::simulate;
use super::{EffectKind, Fit, Record, Scorer, identify};
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};

/// A small stderr progress bar counting simulations.
#[derive(Debug)]
pub struct Progress {
    done: AtomicUsize,
    total: AtomicUsize,
    on: bool,
}

impl Progress {
    pub fn new(total: usize, on: bool) -> Progress {
        Progress {
            done: AtomicUsize::new(0),
            total: AtomicUsize::new(total.max(1)),
            on,
        }
    }
    pub fn add_total(&self, n: usize) {
        self.total.fetch_add(n, Ordering::Relaxed);
    }
    pub fn tick(&self) {
        let d = self.done.fetch_add(1, Ordering::Relaxed) + 1;
        if self.on {
            let t = self.total.load(Ordering::Relaxed).max(d);
            let w = 30;
            let f = d * w / t;
            crate::out::progress_line(format_args!(
                "fitting [{}{}] {d}/{t} simulations",
                "#".repeat(f),
                " ".repeat(w - f)
            ));
        }
    }
    pub fn finish(&self) {
        if self.on {
            crate::out::progress_end();
        }
    }
    pub fn done(&self) -> usize {
        self.done.load(Ordering::Relaxed)
    }
}

/// What one fit of a set of effects gives.
#[derive(Debug, Clone)]
pub(super) struct FitOut {
    /// The fitted parameters, in the order of the effects' specs.
    pub values: Vec<f64>,
    /// Each parameter's standard error.
    pub std_err: Vec<f64>,
    /// The cost left (see [`Scorer::residual`]).
    pub cost: f64,
    /// Simulations the fit ran.
    pub simulations: usize,
}

/// Fit a set of effects together on the nominal model, starting from `start` values (or the
/// specs' starts).
pub(super) fn fit_effects(
    rig: &Rig,
    rec: &Record,
    scorer: &Scorer,
    kinds: &[EffectKind],
    start: Option<&[f64]>,
    opts: FitOptions,
    progress: &Progress,
) -> FitOut {
    let (specs, lens) = specs_of(rig, kinds, start);
    let residual = |p: &[f64]| -> Vec<f64> {
        let mut fx = Effects::nominal();
        apply_all(kinds, &lens, p, &mut fx);
        scorer.residual(rec, &simulate(rig, rec, &fx))
    };
    let res = fit::levenberg_marquardt(&specs, opts, &residual, &|| progress.tick());
    FitOut {
        values: res.params,
        std_err: res.std_err,
        cost: res.cost,
        simulations: res.evaluations,
    }
}

/// The best single effect and the pair, each fitted again on Table 4 refitted with the single
/// effect in place: (cost of the single, cost of the pair, simulations of the refit). A second
/// effect must remove what a car within the table's tolerance cannot. `None` when the refit
/// fails or leaves the tolerance: the car is then off the table, and a refit that moves a
/// parameter that far could stand in for a real second effect (on 40 independent cases,
/// dropping this condition lost a real friction + delay pair and found no spurious one).
pub(super) fn pair_on_refitted_table(
    rig: &Rig,
    rec: &Record,
    scorer: &Scorer,
    best: &Candidate,
    pair: &Candidate,
    opts: &Options,
    progress: &Progress,
) -> Option<(f64, f64, usize)> {
    if !matches!(rig.model, RigModel::Paper(_)) {
        return None;
    }
    let best_fx = best.effects_on(rig);
    let id = identify::identify_with(rig, rec, PARAMETER_ITERATIONS, false, &best_fx).ok()?;
    if !identify::within_factor(rig, &id, PARAMETER_TOLERANCE) {
        return None;
    }
    let mut refit = rig.clone();
    identify::apply(&mut refit, &id);
    // The two fits tick `progress` themselves; the refit does not.
    let c_single = fit_effects(
        &refit,
        rec,
        scorer,
        &best.kinds,
        Some(&best.values),
        opts.fit,
        progress,
    )
    .cost;
    let c_pair = fit_effects(
        &refit,
        rec,
        scorer,
        &pair.kinds,
        Some(&pair.values),
        opts.fit,
        progress,
    )
    .cost;
    Some((c_single, c_pair, id.simulations))
}

/// The most a log's stamps may lag the instants its rows were sampled at, s: half a 10 ms
/// reference period (a logger stamps a row when it receives it).
pub(super) const LOG_LAG_MAX_S: f64 = 5e-3;

/// The best single effect fitted again with the log's stamping lag beside it (0 to
/// [`LOG_LAG_MAX_S`]): its cost and the lag, or `None` where a lag is the effect itself (a
/// delay) or the rig's logs carry no such clock (EMPS and BAM are sampled on their own).
pub(super) fn best_with_log_lag(
    rig: &Rig,
    rec: &Record,
    scorer: &Scorer,
    best: &Candidate,
    opts: &Options,
    progress: &Progress,
) -> Option<(f64, f64)> {
    if !matches!(rig.model, RigModel::Paper(_)) || best.kinds.contains(&EffectKind::Delay) {
        return None;
    }
    let (mut specs, lens) = specs_of(rig, &best.kinds, Some(&best.values));
    let n = specs.len();
    specs.push(ParamSpec {
        name: "log_lag_ms",
        lo: 0.0,
        hi: 1e3 * LOG_LAG_MAX_S,
        start: 0.0,
        step: 0.25,
    });
    let residual = |p: &[f64]| -> Vec<f64> {
        let mut fx = Effects::nominal();
        apply_all(&best.kinds, &lens, &p[..n], &mut fx);
        scorer.residual(rec, &simulate(rig, rec, &fx.with_log_lag(1e-3 * p[n])))
    };
    let res = fit::levenberg_marquardt(&specs, opts.fit, &residual, &|| progress.tick());
    Some((res.cost.min(best.cost), 1e-3 * res.params[n]))
}

/// The window of `max_s` with the largest nominal residual, as its own record; `None` when
/// the log is not longer than that.
pub(super) fn fit_window(
    rig: &Rig,
    rec: &Record,
    scorer: &Scorer,
    sim0: &SimOut,
    max_s: f64,
) -> Option<Record> {
    if max_s <= 0.0 || rec.duration_s() <= max_s * 1.2 {
        return None;
    }
    let w = (max_s / rec.dt) as usize;
    let r = scorer.residual(rec, sim0);
    let half = r.len() / 2;
    let skip = scorer.skip();
    let e: Vec<f64> = (0..half)
        .map(|k| r[k] * r[k] + r[half + k] * r[half + k])
        .collect();
    let mut csum = vec![0.0; e.len() + 1];
    for k in 0..e.len() {
        csum[k + 1] = csum[k] + e[k];
    }
    let stride = ((1.0 / rec.dt) as usize).max(1);
    let mut best = (0usize, f64::MIN);
    let mut k = 0;
    while k + w <= e.len() {
        let v = csum[k + w] - csum[k];
        if v > best.1 {
            best = (k, v);
        }
        k += stride;
    }
    let (a, b) = (best.0 + skip, (best.0 + skip + w).min(rec.len()));
    let _ = rig;
    Some(Record {
        dt: rec.dt,
        reference: rec.reference[a..b].to_vec(),
        output: rec.output[a..b].to_vec(),
        effort: rec.effort[a..b].to_vec(),
        motor: rec.motor.as_ref().map(|m| m[a..b].to_vec()),
        disturbance: rec.disturbance.as_ref().map(|d| d[a..b].to_vec()),
        supply_v: rec.supply_v.as_ref().map(|d| d[a..b].to_vec()),
        // What of the power-up the window holds; one from past it starts with the drive running.
        powered_from: rec.powered_from.saturating_sub(a).min(b - a),
        current_chatter: rec.current_chatter,
    })
}

/// The key of `owner`'s parameter `name` in a candidate of `kinds`: the name alone, or in a
/// pair `effect.name`.
pub(super) fn param_key(kinds: &[EffectKind], owner: EffectKind, name: &str) -> String {
    if kinds.len() > 1 {
        format!("{}.{name}", owner.name())
    } else {
        name.to_string()
    }
}

pub(super) fn make_candidate(
    rig: &Rig,
    rec: &Record,
    scorer: &Scorer,
    kinds: &[EffectKind],
    fitted: FitOut,
    cost0: f64,
    validation: &dyn Fn(&Effects) -> Option<Fit>,
) -> Candidate {
    let specs: Vec<(EffectKind, ParamSpec)> = kinds
        .iter()
        .flat_map(|k| k.specs(rig).into_iter().map(move |s| (*k, s)))
        .collect();
    let FitOut {
        values,
        std_err: errs,
        cost: c,
        simulations: evals,
    } = fitted;
    let mut params = BTreeMap::new();
    let mut std_err = BTreeMap::new();
    let mut significant = true;
    for (((owner, s), v), e) in specs.iter().zip(&values).zip(&errs) {
        let key = param_key(kinds, *owner, s.name);
        params.insert(key.clone(), *v);
        std_err.insert(key, *e);
        if s.lo == 0.0 && e.is_finite() && *v < 2.0 * e {
            significant = false;
        }
    }
    let mut cand = Candidate {
        effect: kinds.iter().map(|k| k.name()).collect::<Vec<_>>().join("+"),
        params,
        std_err,
        gof: 0.0,
        gof_validation: None,
        fit: Fit::default(),
        fit_validation: None,
        improvement: 1.0 - c / cost0.max(1e-300),
        significant,
        large_enough: true,
        simulations: evals,
        kinds: kinds.to_vec(),
        values,
        cost: c,
    };
    let mut i = 0;
    for k in kinds {
        cand.large_enough &= cand.values.get(i).is_some_and(|v| *v >= k.min_size(rig));
        i += k.specs(rig).len();
    }
    let fx = cand.effects_on(rig);
    cand.fit = scorer.fit(rec, &simulate(rig, rec, &fx));
    cand.gof = cand.fit.gof;
    cand.fit_validation = validation(&fx);
    cand.gof_validation = cand.fit_validation.map(|f| f.gof);
    cand
}

/// `f` over `items` on up to `threads` threads, results in the items' order. The items come
/// off a queue, not in fixed chunks: jobs differ in length, and a chunk of long ones would
/// leave a core idle. A worker that panicked fails the call: dropping its results would let
/// the caller go on as if nothing had happened.
pub(crate) fn parallel_map<T: Sync, R: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> R + Sync,
) -> Vec<R> {
    let threads = threads.clamp(1, items.len().max(1));
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut out: Vec<(usize, R)> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut done = Vec::new();
                    loop {
                        let i = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(item) = items.get(i) else {
                            break;
                        };
                        done.push((i, f(item)));
                    }
                    done
                })
            })
            .collect();
        handles
            .into_iter()
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    out.sort_by_key(|(i, _)| *i);
    out.into_iter().map(|(_, r)| r).collect()
}

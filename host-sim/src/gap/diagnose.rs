//! [`diagnose`]: the nominal model, each candidate alone, the pairs ([`super::pairs`]), the
//! Table 4 refit checks ([`super::refits`]) and the verdict, in that order.

use super::diagnosis::{
    Candidate, Diagnosis, FRICTION_FOR_SCALE_SIGNIFICANCE, MAX_FIT_S, MIN_IMPROVEMENT,
    MIN_PAIR_IMPROVEMENT, MIN_PAIR_SHARE_OF_FLOOR, MIN_SHARE_OF_REDUCIBLE, Options,
    SCALE_LEFT_BESIDE_FRICTION, SCALE_MIN_SHARE, UNEXPLAINED_BELOW_GOF, UNEXPLAINED_RATIO, Verdict,
    VerdictKind,
};
use super::finding::{self, BestSingle, Finding, OffsetOf, Shortfall};
use super::model::{Effects, SimOut};
use super::pairs;
use super::refits::{self, Refits};
use super::rig::{CarDrive, Rig, RigModel};
use super::ripple;
use super::score::{
    cost, effort_offset, effort_scale, effort_scale_beside_friction, output_offset, repeatability,
    simulate,
};
use super::search::{FitOut, Progress, fit_effects, fit_window, make_candidate, parallel_map};
use super::signature::{self, Signature};
use super::{EffectKind, Fit, Record, Scale, Scorer, identify, locate};

/// What every step of one diagnosis reads: the log and the window its fits run on, their
/// scorers, the nominal model's cost on that window and the window's noise floor.
pub(super) struct Stage<'a> {
    pub rig: &'a Rig,
    pub rec: &'a Record,
    pub scorer: &'a Scorer,
    /// The window the fits run on ([`fit_window`]), or the whole log.
    pub frec: &'a Record,
    pub fscorer: &'a Scorer,
    /// The validation log and its scorer.
    pub validation: Option<(&'a Record, Scorer)>,
    pub opts: &'a Options,
    /// Ticked by every candidate's fit.
    pub progress: Progress,
    /// What the nominal model leaves on the window.
    pub cost0: f64,
    /// The window's noise floor.
    pub floor: f64,
}

impl Stage<'_> {
    /// What the nominal model leaves above the noise floor.
    pub fn reducible(&self) -> f64 {
        (self.cost0 - self.floor).max(0.0)
    }

    /// `c` is named against `reference_cost`: it removes a share of what is above the noise
    /// floor and `share` of `reference_cost`, and it is of its minimum size. Nothing above the
    /// noise floor: nothing to explain (an effect that still lowers the cost is fitting the
    /// noise). A candidate below its minimum size is never named, however much it lowers the
    /// cost: it is then standing in for something else.
    pub fn named(&self, c: &Candidate, reference_cost: f64, share: f64) -> bool {
        let gain = reference_cost - c.cost;
        let reducible = self.reducible();
        reducible > 0.0
            && c.large_enough
            && gain > MIN_SHARE_OF_REDUCIBLE * reducible
            && gain > share * reference_cost
    }

    /// `c` alone is named against the nominal model.
    pub fn named_alone(&self, c: &Candidate) -> bool {
        self.named(c, self.cost0, MIN_IMPROVEMENT)
    }

    /// A further explanation (a second effect, parameters beyond the table's tolerance) that
    /// leaves `fuller` where the simpler one left `simpler` removes what it must: a share of
    /// it, a share of what is above the noise floor, and a share of the noise floor's own
    /// worth; otherwise it is fitting the noise (or the simpler fit's own error).
    pub fn removes_beyond(&self, simpler: f64, fuller: f64) -> bool {
        let gain = simpler - fuller;
        gain > MIN_PAIR_IMPROVEMENT * simpler
            && gain > MIN_SHARE_OF_REDUCIBLE * (simpler - self.floor).max(0.0)
            && gain > MIN_PAIR_SHARE_OF_FLOOR * self.floor
    }

    /// The fit on the validation log of the table's car with `fx`.
    pub fn on_validation(&self, fx: &Effects) -> Option<Fit> {
        self.validation
            .as_ref()
            .map(|(v, s)| s.fit(v, &simulate(self.rig, v, fx)))
    }

    /// `kinds` fitted on the window on `rig`, from `start` or their specs' starts.
    pub fn fit_on(&self, rig: &Rig, kinds: &[EffectKind], start: Option<&[f64]>) -> FitOut {
        let (frec, fscorer, fit) = (self.frec, self.fscorer, self.opts.fit);
        fit_effects(rig, frec, fscorer, kinds, start, fit, &self.progress)
    }

    /// `kinds` fitted on the window on the table's car.
    pub fn fit(&self, kinds: &[EffectKind], start: Option<&[f64]>) -> FitOut {
        self.fit_on(self.rig, kinds, start)
    }

    /// `kind` alone fitted on the window on the table's car, from its spec's start; a tyre
    /// that ends there under its minimum size is fitted again from a soft start
    /// ([`SOFT_TYRE_N_PER_MM`]) and the one that leaves less is kept. With no force the
    /// tyre's stiffness moves nothing, so a fit that starts far stiffer than the tyre, where a
    /// little force pulls the wrong way, stops at none: a 200 N/mm tyre of 1056 N on a 5 deg
    /// sweep stopped at 0 N from 600 N/mm and was found from 100-300 N/mm.
    pub fn fit_single(&self, kind: EffectKind) -> FitOut {
        let first = self.fit(&[kind], None);
        let tyre = kind.family() == EffectKind::TireGround.family()
            && matches!(self.rig.model, RigModel::Paper(_));
        if !tyre || first.values.first().copied().unwrap_or(0.0) >= kind.min_size(self.rig) {
            return first;
        }
        let soft = self.fit(&[kind], Some(&[0.0, SOFT_TYRE_N_PER_MM]));
        let simulations = first.simulations + soft.simulations;
        let mut kept = if soft.cost < first.cost { soft } else { first };
        kept.simulations = simulations;
        kept
    }

    /// A fit of `kinds` on `rig` scored on the whole log; its validation figures are the
    /// table's car's with those effects.
    pub fn candidate_on(&self, rig: &Rig, kinds: &[EffectKind], fitted: FitOut) -> Candidate {
        let validation = |fx: &Effects| self.on_validation(fx);
        make_candidate(
            rig,
            self.rec,
            self.scorer,
            kinds,
            fitted,
            self.cost0,
            &validation,
        )
    }

    /// A fit of `kinds` on the table's car scored on the whole log.
    pub fn candidate(&self, kinds: &[EffectKind], fitted: FitOut) -> Candidate {
        self.candidate_on(self.rig, kinds, fitted)
    }
}

/// Diagnose `rec` on `rig`; `validation` is checked with the parameters fitted on `rec`.
pub fn diagnose(rig: &Rig, rec: &Record, validation: Option<&Record>, opts: &Options) -> Diagnosis {
    let started = std::time::Instant::now();
    let nominal = Effects::nominal();
    let sim0 = simulate(rig, rec, &nominal);
    let scorer = Scorer::new(rig, rec).with_noise(rec, &sim0);
    let fit0 = scorer.fit(rec, &sim0);
    let repeat = repeatability(rig, rec, &scorer, &sim0);
    let offset = effort_offset(rec, &sim0, scorer.skip());
    let zero = output_offset(rec, &sim0, scorer.skip(), rig.output_count());
    let scale = effort_scale(rec, &sim0, scorer.skip());
    let scale_beside = effort_scale_beside_friction(rec, &sim0, scorer.skip());
    let ripple = match &rig.model {
        RigModel::Paper(m) => ripple::motor_ripple(
            rec,
            &sim0.effort,
            m.plant.motor_per_pinion().to_radians(),
            m.plant.kt,
            scorer.skip(),
        ),
        _ => None,
    };
    let signature = log_signature(rig, rec, &sim0, opts);
    let (effects, mut findings) = rule_out(rig, signature.as_ref(), &opts.effects);
    let window = FitWindow::of(rig, rec, &scorer, &sim0, MAX_FIT_S);
    let st = window.stage(rig, rec, &scorer, validation, opts, &effects);
    let (cost0, floor) = (st.cost0, st.floor);

    let mut ranking = singles(&st, &effects);
    // An EPOS4 car's clock fitted before any effect, and an effect that moves it: the
    // diagnosis on the clock fitted again with that effect in the model.
    if let Some(best) = ranking.first()
        && let Some((moved, refit)) = super::drive_clock::with_best(rig, rec, best, opts.threads)
    {
        // The first pass's runs: the nominal model, its repeatability, the fitting window's
        // nominal, the single candidates' fits, the clock's fit.
        let mut d = diagnose(&moved, rec, validation, opts);
        d.simulations += 3 + st.progress.done() + refit.simulations;
        d.clock_refit = Some(refit);
        d.elapsed_s = started.elapsed().as_secs_f64();
        return d;
    }
    // Simulations of Table 4 refits, which do not tick `progress`.
    let mut refit_simulations = 0usize;
    let mut verdict_candidate: Option<Candidate> = None;
    if let Some(best) = best_single(&st, &ranking, signature.as_ref(), fit0.gof, &mut findings) {
        findings.push(Finding::Named {
            effect: best.effect.clone(),
            improvement: best.improvement,
            nominal: cost0,
            left: best.cost,
            floor,
        });
        let second = pairs::second_effect(&st, &ranking, &best, &mut findings);
        refit_simulations += second.refit_simulations;
        ranking.extend(second.ranked);
        let mut chosen = second.chosen;
        if let Some(sig) = signature.as_ref().filter(|s| s.holds)
            && let Some(pair) =
                pairs::demanded_by_log(&st, sig, &chosen, &second.fits, &mut findings)
        {
            ranking.retain(|c| c.effect != pair.effect);
            ranking.push(pair.clone());
            chosen = pair;
        }
        verdict_candidate = Some(chosen);
    } else {
        findings.push(Finding::NothingNamed {
            nominal: cost0,
            floor,
            best: ranking.first().map(|c| BestSingle {
                effect: c.effect.clone(),
                improvement: c.improvement,
                large_enough: c.large_enough,
            }),
        });
    }
    st.progress.finish();
    let Refits {
        parameters,
        tolerant,
        win: mut parameters_win,
        simulations,
    } = refits::table_refits(&st, fit0.gof, &mut verdict_candidate, &mut findings);
    refit_simulations += simulations;
    let base_validation = st.on_validation(&nominal);
    // An honest verdict: an explanation that leaves the log, or the validation log, further
    // from the car than the nominal model (eq. 11) is no explanation, whatever the likelihood
    // says (a likelihood weighs each signal by its own noise; the GoF is what a team reads).
    let worse_than_nominal = |after: &Fit, validation: Option<&Fit>| -> Option<Shortfall> {
        if after.gof < fit0.gof {
            return Some(Shortfall::Log {
                after: after.gof,
                nominal: fit0.gof,
            });
        }
        match (validation, base_validation.as_ref()) {
            (Some(v), Some(b)) if v.gof < b.gof => Some(Shortfall::Validation {
                after: v.gof,
                nominal: b.gof,
            }),
            _ => None,
        }
    };
    let mut parameters_checked = None;
    if parameters_win && let Some((id, refit, _)) = &parameters {
        let fx = nominal.with_log_lag(id.log_lag_s);
        let fit_after = scorer.fit(rec, &simulate(refit, rec, &fx));
        let fit_validation = st
            .validation
            .as_ref()
            .map(|(v, s)| s.fit(v, &simulate(refit, v, &fx)));
        match worse_than_nominal(&fit_after, fit_validation.as_ref()) {
            Some(why) => {
                // Nor the effect it beat: the refit explains the log better by the likelihood,
                // so that effect is not what is left (a car off the table the model does not
                // reach stands behind both).
                findings.push(Finding::RefitWorse(why));
                verdict_candidate = None;
                parameters_win = false;
                refit_simulations += 1 + usize::from(fit_validation.is_some());
            }
            None => parameters_checked = Some((fit_after, fit_validation)),
        }
    }
    // The report, whichever way the verdict went: `simulations` are those beyond the
    // candidates' fits (which tick `progress`) and the three runs every log gets (the nominal
    // model, its repeatability, the verdict's `where`).
    let diagnosis = |verdict: Verdict,
                     where_: locate::Where,
                     parameters: Option<identify::Identified>,
                     simulations: usize| Diagnosis {
        rig: rig.name.clone(),
        duration_s: rec.duration_s(),
        baseline_gof: fit0.gof,
        baseline: fit0,
        baseline_validation: base_validation,
        baseline_cost: cost0,
        noise_floor_cost: floor,
        noise: scorer.noise(),
        repeatability: repeat,
        effort_offset: offset,
        output_offset: zero,
        effort_scale: scale,
        effort_scale_beside_friction: scale_beside,
        motor_ripple: ripple,
        signature,
        verdict,
        ranking,
        where_,
        refit_linear: None,
        parameters,
        simulations: st.progress.done() + simulations + 3,
        elapsed_s: started.elapsed().as_secs_f64(),
        clock_refit: None,
    };
    if parameters_win
        && let Some((id, refit, _)) = &parameters
        && let Some((fit_after, fit_validation)) = parameters_checked
    {
        let fx = nominal.with_log_lag(id.log_lag_s);
        let where_ = locate::locate(rig, rec, &scorer, &sim0, &simulate(refit, rec, &fx));
        let verdict = Verdict {
            kind: VerdictKind::Parameters,
            effects: vec!["parameters".into()],
            gof_after: fit_after.gof,
            gof_validation: fit_validation.map(|f| f.gof),
            fit_after,
            fit_validation,
            reason: finding::reason(&findings),
            fitted: None,
        };
        return diagnosis(
            verdict,
            where_,
            Some(id.clone()),
            refit_simulations + id.simulations,
        );
    }
    if let Some(c) = &verdict_candidate
        && let Some(why) = worse_than_nominal(&c.fit, c.fit_validation.as_ref())
    {
        findings.push(Finding::EffectWorse {
            effect: c.effect.clone(),
            why,
        });
        verdict_candidate = None;
    }
    // Friction adds a current of the motion's sign; it cannot make one a share larger in
    // every part of the log. Named while the log's current keeps such a share, it stands in
    // for a torque constant off Table 1.
    if let Some(c) = &verdict_candidate
        && c.kinds
            .iter()
            .any(|k| matches!(k, EffectKind::CoulombFriction | EffectKind::RackFriction))
        && friction_for_scale(&scale, &scale_beside)
    {
        findings.push(Finding::FrictionForScale {
            effect: c.effect.clone(),
            factor: scale.factor,
            standard_error: scale.standard_error,
        });
        verdict_candidate = None;
    }
    let parameter_simulations = parameters.as_ref().map_or(0, |(id, _, _)| id.simulations);
    // What the best explanation leaves: the nominal model, or the table refitted within its
    // tolerance (a car a few per cent off the table is no gap).
    let left = tolerant.as_ref().map_or(cost0, |(_, c)| c.min(cost0));
    let far_above_floor = verdict_candidate.is_none()
        && left > UNEXPLAINED_RATIO * floor
        && fit0.gof < UNEXPLAINED_BELOW_GOF;
    // A constant left in the effort or the output is no noise and no car the table describes,
    // whatever the GoF: a log near the nominal one with it is not `none`.
    let mut offset_left = false;
    for (signal, o) in [(OffsetOf::Effort, &offset), (OffsetOf::Output, &zero)] {
        if verdict_candidate.is_none() && o.stands_out() {
            offset_left = true;
            findings.push(Finding::Offset {
                signal,
                mean: o.mean,
                standard_error: o.standard_error,
                share_pct: 100.0 * o.share_of_signal(),
            });
        }
    }
    // So is a current the log keeps at a share off the model's throughout: a torque constant
    // off Table 1, or a current scaled wrong, which a refit of Table 4 mimics only by moving
    // every inertia, damping and stiffness together, and often does not reach.
    let scale_read = [(scale, false), (scale_beside, true)]
        .into_iter()
        .find(|(s, _)| s.stands_out());
    let scale_left = verdict_candidate.is_none() && scale_read.is_some();
    if let (true, Some((s, beside_friction))) = (scale_left, scale_read) {
        findings.push(Finding::EffortScale {
            factor: s.factor,
            standard_error: s.standard_error,
            beside_friction,
        });
    }
    // And a torque that repeats with the rotor's turn.
    let ripple_left = verdict_candidate.is_none() && ripple.is_some_and(|r| r.stands_out());
    if let (true, Some(r)) = (ripple_left, ripple) {
        findings.push(Finding::MotorRipple(r));
    }
    let unexplained = far_above_floor || offset_left || scale_left || ripple_left;
    if unexplained {
        findings.push(Finding::TryElse);
    }
    let verdict = match &verdict_candidate {
        Some(c) => Verdict {
            kind: VerdictKind::Effects,
            effects: {
                let mut v: Vec<String> = c.kinds.iter().map(|k| k.family().to_string()).collect();
                v.sort();
                v.dedup();
                v
            },
            gof_after: c.gof,
            gof_validation: c.gof_validation,
            fit_after: c.fit,
            fit_validation: c.fit_validation,
            reason: finding::reason(&findings),
            fitted: Some(c.clone()),
        },
        None => Verdict {
            kind: if unexplained {
                VerdictKind::Unexplained
            } else {
                VerdictKind::None
            },
            effects: if unexplained {
                vec!["unexplained".into()]
            } else {
                vec![]
            },
            gof_after: fit0.gof,
            gof_validation: base_validation.map(|f| f.gof),
            fit_after: fit0,
            fit_validation: base_validation,
            reason: finding::reason(&findings),
            fitted: None,
        },
    };
    let after_fx = verdict_candidate
        .as_ref()
        .map_or(nominal, |c| c.effects_on(rig));
    let sim_after = simulate(rig, rec, &after_fx);
    let where_ = locate::locate(rig, rec, &scorer, &sim0, &sim_after);
    diagnosis(
        verdict,
        where_,
        parameters.map(|(id, _, _)| id),
        refit_simulations + parameter_simulations,
    )
}

/// What the log says by itself of play in the belt and friction at the rack (its torque
/// balance, where it holds and `opts` uses it): a candidate it rules out is not fitted, so it
/// cannot stand in for another effect (fitted alone, rack friction explains much of what play
/// in the belt does, and the reverse).
///
/// An EPOS4 reports one current sample per SYNC of a drive whose current chatters: read alone
/// its balance put the belt 30-60 % stiff and -90 to -430 N of friction on cars with none. The
/// nominal model's run `sim0`, written with the same readout, reads the same bias, so on an
/// EPOS4 car the balance is the log's less the model's.
fn log_signature(rig: &Rig, rec: &Record, sim0: &SimOut, opts: &Options) -> Option<Signature> {
    let RigModel::Paper(m) = &rig.model else {
        return None;
    };
    let mut s = match m.drive {
        CarDrive::Direct => signature::signature(&m.plant, rec),
        CarDrive::Epos4 => signature::signature_against(&m.plant, rec, &sim0.as_log(rec)),
    }?;
    s.holds &= opts.torque_balance;
    Some(s)
}

/// The window a log's fits run on: where the nominal residual is largest on a log longer
/// than the window (the figures are still given on the whole log), so that the fits cost the
/// same for any log length; `None`, the whole log.
struct FitWindow {
    rec: Option<Record>,
    scorer: Option<Scorer>,
    /// What the nominal model leaves on the window.
    cost0: f64,
}

impl FitWindow {
    fn of(rig: &Rig, rec: &Record, scorer: &Scorer, sim0: &SimOut, max_s: f64) -> FitWindow {
        let window = fit_window(rig, rec, scorer, sim0, max_s);
        let wscorer = window.as_ref().map(|w| scorer.on(rig, w));
        let cost0 = match (&window, &wscorer) {
            (Some(w), Some(s)) => cost(&s.residual(w, &simulate(rig, w, &Effects::nominal()))),
            _ => cost(&scorer.residual(rec, sim0)),
        };
        FitWindow {
            rec: window,
            scorer: wscorer,
            cost0,
        }
    }

    /// The stage of a diagnosis of `rec` whose fits run on this window, with the nominal
    /// model's cost on it, its noise floor, and progress counted over `effects`' fits.
    fn stage<'a>(
        &'a self,
        rig: &'a Rig,
        rec: &'a Record,
        scorer: &'a Scorer,
        validation: Option<&'a Record>,
        opts: &'a Options,
        effects: &[EffectKind],
    ) -> Stage<'a> {
        let frec = self.rec.as_ref().unwrap_or(rec);
        let fscorer = self.scorer.as_ref().unwrap_or(scorer);
        let per_fit = |np: usize| opts.fit.scan + 1 + opts.fit.iterations * (np + 2);
        Stage {
            rig,
            rec,
            scorer,
            frec,
            fscorer,
            validation: validation.map(|v| (v, Scorer::new(rig, v))),
            opts,
            progress: Progress::new(
                effects
                    .iter()
                    .map(|k| per_fit(k.specs(rig).len()))
                    .sum::<usize>()
                    + per_fit(3),
                opts.progress,
            ),
            cost0: self.cost0,
            floor: fscorer.noise_floor_cost(frec),
        }
    }
}

/// A first look at a log on a car: the nominal model's GoF on the whole log, and the best
/// candidate alone with its GoF on the whole log. The candidates are those the log's torque
/// balance leaves, each fitted as the diagnosis first fits them but on a window of 10 s (not
/// 30) with 4 LM iterations (not 8 and a polish); the best is the one that leaves the least
/// on that window. Where asked (`late`), that best beside a late reference too (the best
/// other effect where the best is the delay), kept where it fits the whole log better. Two
/// cars whose nominal models the log leaves close are told apart by it ([`super::drive`]): a
/// car with an effect can look, to the nominal models, more like the other drive than like
/// itself.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Screen {
    pub nominal_gof: f64,
    /// The best candidate on the fits' window (or it beside a late reference), and its GoF on
    /// the whole log.
    pub best: Option<(String, f64)>,
}

impl Screen {
    /// The best GoF on the whole log: the best candidate's, or the nominal model's.
    pub fn gof(&self) -> f64 {
        self.best
            .as_ref()
            .map_or(self.nominal_gof, |(_, g)| g.max(self.nominal_gof))
    }
}

/// The longest window a [`Screen`]'s fits run on, s: a third of the diagnosis's, so that
/// screening two cars of a long log costs less than its diagnosis (the candidates' GoFs
/// are still on the whole log).
const SCREEN_FIT_S: f64 = 10.0;

/// A [`Screen`]'s fits: LM iterations after the scan (the diagnosis's take 8 and a polish),
/// enough to tell two cars apart by more than [`super::drive::SCREEN_MARGIN_GOF`].
const SCREEN_ITERATIONS: usize = 4;

/// The second start of a tyre's fit, its rest stiffness at the rack, N/mm: a quarter of the
/// spec's start (600 N/mm), a soft tyre's (the independent world draws 200-1000 N/mm).
const SOFT_TYRE_N_PER_MM: f64 = 150.0;

/// [`Screen`] of `rec` on `rig`, with a late reference beside the best where `late`.
pub fn screen(rig: &Rig, rec: &Record, opts: &Options, late: bool) -> Screen {
    let sim0 = simulate(rig, rec, &Effects::nominal());
    let scorer = Scorer::new(rig, rec).with_noise(rec, &sim0);
    let nominal_gof = scorer.fit(rec, &sim0).gof;
    let signature = log_signature(rig, rec, &sim0, opts);
    let (effects, _) = rule_out(rig, signature.as_ref(), &opts.effects);
    let window = FitWindow::of(rig, rec, &scorer, &sim0, SCREEN_FIT_S);
    let quiet = Options {
        progress: false,
        fit: super::fit::FitOptions {
            iterations: SCREEN_ITERATIONS,
            polish: 0,
            ..opts.fit
        },
        ..opts.clone()
    };
    let st = window.stage(rig, rec, &scorer, None, &quiet, &effects);
    // Each candidate fitted on the window; the one that leaves the least there, scored on the
    // whole log (a run of the whole log for each would cost more than the fits).
    let fits = parallel_map(&effects, opts.threads.max(1), |&k| (k, st.fit_single(k)));
    let least = |late: bool| {
        fits.iter()
            .filter(|(k, _)| late || *k != EffectKind::Delay)
            .min_by(|a, b| a.1.cost.total_cmp(&b.1.cost))
    };
    let Some((k, fitted)) = least(true) else {
        return Screen {
            nominal_gof,
            best: None,
        };
    };
    let single = st.candidate(&[*k], fitted.clone());
    // A late reference beside the best effect (or the best other effect beside a late
    // reference), fitted as the diagnosis fits a pair: the one fitted alone from its values,
    // the other from its spec's start. Kept where it fits the whole log better.
    let paired = late
        .then(|| least(false))
        .flatten()
        .filter(|_| effects.contains(&EffectKind::Delay))
        .map(|(other, other_fit)| {
            let (seed, seed_values, second) = if *k == EffectKind::Delay {
                (EffectKind::Delay, &fitted.values, *other)
            } else {
                (*other, &other_fit.values, EffectKind::Delay)
            };
            let kinds = [second, seed];
            let start = pairs::pair_start(rig, second, seed_values);
            st.candidate(&kinds, st.fit(&kinds, Some(&start)))
        })
        .filter(|pair| pair.gof > single.gof);
    let best = paired.unwrap_or(single);
    Screen {
        nominal_gof,
        best: Some((best.effect, best.gof)),
    }
}

/// Each candidate of `effects` fitted on its own, in parallel, best first.
fn singles(st: &Stage, effects: &[EffectKind]) -> Vec<Candidate> {
    // In the candidates' order whichever thread finished first, so equal costs (two effects
    // both fitted to nothing) rank the same on every run.
    let results: Vec<(EffectKind, FitOut)> =
        parallel_map(effects, st.opts.threads.max(1), |&k| (k, st.fit_single(k)));
    let mut ranking: Vec<Candidate> = results
        .into_iter()
        .map(|(k, fitted)| st.candidate(&[k], fitted))
        .collect();
    ranking.sort_by(|a, b| a.cost.total_cmp(&b.cost));
    ranking
}

/// The best single effect that is named: the first of the ranking of its minimum size, if it
/// removes what an effect must.
///
/// A tyre can stand in for a Coulomb force at the rack: the stiff Dahl element saturates
/// within a fraction of a millimetre, which a 10 ms row cannot tell from friction that creeps
/// (the independent world's EPOS4 cars with 321 N and 537 N of rack friction: tyres of 230 N at
/// 1346 N/mm and 469 N at 1825 N/mm left the least on the fit's window, the friction the better
/// GoF on the whole log). Where the torque balance shows the force clearly and the friction's
/// GoF on the whole log is no lower than the tyre's, the friction is the best.
///
/// A best single that leaves the log's GoF below the nominal model's (`nominal_gof`) is no
/// explanation and would be refused at the verdict. Play in the belt can hide behind one: at
/// each reversal the column stands while the motor crosses the gap, and a stiff Dahl tyre
/// that saturates there, or a friction, takes that stand for a force, which likelihood weighs
/// by the column's small noise and the GoF by the current it gets wrong (the independent
/// world's 100 Hz track with 1.36 deg of play: a 593 N tyre took 91 % off the cost and left
/// the GoF at 76.5 % of a nominal 87.9 %; the play took 86 % and left 90.3 %). Where the
/// torque balance shows play of at least its minimum size by three standard errors, which
/// the best does not make, and a play candidate is named alone and leaves the GoF no lower
/// than the nominal one, that play is the best single.
fn best_single(
    st: &Stage,
    ranking: &[Candidate],
    signature: Option<&Signature>,
    nominal_gof: f64,
    findings: &mut Vec<Finding>,
) -> Option<Candidate> {
    let best = ranking
        .iter()
        .find(|c| c.large_enough)
        .filter(|c| st.named_alone(c))?;
    if best.kinds[0].family() == EffectKind::TireGround.family()
        && let Some(sig) = signature.filter(|s| s.holds)
        && Signature::above(
            sig.rack_coulomb_n,
            sig.rack_coulomb_se_n,
            EffectKind::RackFriction.min_size(st.rig),
        )
        && let Some(friction) = ranking
            .iter()
            .find(|c| c.kinds == [EffectKind::RackFriction] && st.named_alone(c))
        && friction.gof >= best.gof
    {
        findings.push(Finding::BalanceShowsFriction {
            tyre: best.effect.clone(),
            tyre_gof: best.gof,
            friction: friction.effect.clone(),
            friction_gof: friction.gof,
            reading: sig.rack_coulomb_n,
            standard_error: sig.rack_coulomb_se_n,
        });
        return Some(friction.clone());
    }
    let is_play = |k: &EffectKind| k.family() == EffectKind::Backlash.family();
    if best.gof < nominal_gof
        && !best.kinds.iter().any(is_play)
        && let Some(sig) = signature.filter(|s| s.holds)
        && Signature::above(
            sig.belt_play_deg,
            sig.belt_play_se_deg,
            EffectKind::BeltPlay.min_size(st.rig),
        )
        && let Some(play) = ranking.iter().find(|c| {
            c.kinds.len() == 1 && is_play(&c.kinds[0]) && st.named_alone(c) && c.gof >= nominal_gof
        })
    {
        findings.push(Finding::BalanceShowsPlay {
            best: best.effect.clone(),
            best_gof: best.gof,
            play: play.effect.clone(),
            play_gof: play.gof,
            nominal_gof,
            reading: sig.belt_play_deg,
            standard_error: sig.belt_play_se_deg,
        });
        return Some(play.clone());
    }
    Some(best.clone())
}

/// The candidates of `effects` that the log's [`Signature`] leaves, and a finding for each
/// group it rules out: play in the belt, play at the encoder (a dead band that follows the
/// motor's direction, only where the belt shows none either), and Coulomb friction at the rack
/// or the motor, each where the log shows less than half the smallest size the candidate is
/// named at by three standard errors.
fn rule_out(
    rig: &Rig,
    sig: Option<&Signature>,
    effects: &[EffectKind],
) -> (Vec<EffectKind>, Vec<Finding>) {
    let (Some(s), RigModel::Paper(m)) = (sig.filter(|s| s.holds), &rig.model) else {
        return (effects.to_vec(), Vec::new());
    };
    let half = |k: EffectKind| 0.5 * k.min_size(rig);
    // The motor's friction at the rack: through the belt's reduction and the screw's lead.
    let motor_to_rack = m.plant.belt_reduction / m.plant.tau_bs;
    let play = (
        "play in the belt",
        s.belt_play_deg,
        s.belt_play_se_deg,
        "deg",
    );
    let motion = (
        "play that follows the motor's direction",
        s.motion_play_deg,
        s.motion_play_se_deg,
        "deg",
    );
    let force = (
        "Coulomb force at the rack",
        s.rack_coulomb_n,
        s.rack_coulomb_se_n,
        "N",
    );
    let no_belt_play = Signature::below(play.1, play.2, half(EffectKind::BeltPlay));
    // Each candidate, the reading that rules it out, its limit, and what else must hold.
    let groups = [
        (EffectKind::BeltPlay, play, half(EffectKind::BeltPlay), true),
        (
            EffectKind::Backlash,
            motion,
            half(EffectKind::Backlash),
            no_belt_play,
        ),
        (
            EffectKind::RackFriction,
            force,
            half(EffectKind::RackFriction),
            true,
        ),
        (
            EffectKind::CoulombFriction,
            force,
            half(EffectKind::CoulombFriction) * motor_to_rack,
            true,
        ),
    ];
    let mut kept = effects.to_vec();
    let mut findings = Vec::new();
    for (kind, (reading, value, standard_error, unit), limit, also) in groups {
        if also && kept.contains(&kind) && Signature::below(value, standard_error, limit) {
            kept.retain(|k| *k != kind);
            findings.push(Finding::RuledOutByLog {
                effect: kind.name().to_string(),
                reading,
                value,
                standard_error,
                unit,
                limit,
            });
        }
    }
    (kept, findings)
}

/// A current a share above the model's that friction does not make: more than
/// `SCALE_MIN_SHARE` (15 %) above the model's, the same share in every block of the log (at
/// [`FRICTION_FOR_SCALE_SIGNIFICANCE`] standard errors or more), and at least
/// [`SCALE_LEFT_BESIDE_FRICTION`] of it still there with a friction of the motion's sign
/// fitted beside it. A friction at the rack rides on the damping's current and changes its
/// share from one block to the next; a friction at the motor keeps a steady share, but it is
/// the motion's sign, and beside the sign almost none of it is left.
fn friction_for_scale(alone: &Scale, beside: &Scale) -> bool {
    let share = alone.factor - 1.0;
    share > SCALE_MIN_SHARE
        && alone.significance() >= FRICTION_FOR_SCALE_SIGNIFICANCE
        && beside.factor - 1.0 >= SCALE_LEFT_BESIDE_FRICTION * share
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scale(factor: f64, significance: f64) -> Scale {
        Scale {
            factor,
            standard_error: (factor - 1.0).abs() / significance,
        }
    }

    #[test]
    fn a_friction_stands_in_for_a_scale_only_where_the_share_holds_throughout() {
        // The world's torque constant x0.71 as a team's logger wrote it, and x0.74 on the
        // EPOS4 car as a row per TPDO on a drifting clock.
        assert!(friction_for_scale(&scale(1.404, 47.5), &scale(1.289, 6.3)));
        assert!(friction_for_scale(&scale(1.218, 92.9), &scale(1.148, 7.3)));
        // The world's rack friction car that reads most alike: the share is 1.43, but it
        // changes from block to block.
        assert!(!friction_for_scale(&scale(1.43, 5.9), &scale(1.25, 3.0)));
        // 0.15 Nm at the motor (gap_core's friction log): a steady share, but beside the
        // motion's sign a ninth of it is left.
        assert!(!friction_for_scale(&scale(1.622, 16.8), &scale(1.068, 2.3)));
        // A share that holds throughout but is small is a car a few per cent off the table.
        assert!(!friction_for_scale(&scale(1.06, 56.6), &scale(1.06, 9.0)));
        // A current below the model's is no friction's stand-in.
        assert!(!friction_for_scale(&scale(0.71, 150.0), &scale(0.74, 31.0)));
    }
}

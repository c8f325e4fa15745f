//! A second effect beside the best single one: which pairs are fitted ([`jobs`]), how
//! ([`fit_pairs`]), the rules a pair must pass to be named ([`second_effect`]), and the pair
//! the log's own torque balance asks for where the fits alone name one effect
//! ([`demanded_by_log`]).

use super::EffectKind;
use super::diagnose::Stage;
use super::diagnosis::{Candidate, MIN_PAIR_IMPROVEMENT, PARAMETER_TOLERANCE, UNEXPLAINED_RATIO};
use super::effects::first_param_at;
use super::finding::Finding;
use super::rig::Rig;
use super::search::{best_with_log_lag, pair_on_refitted_table};
use super::signature::Signature;

/// What the pairs made of the best single effect.
pub(super) struct Second {
    /// The verdict so far: the pair that passed every rule, else the best single.
    pub chosen: Candidate,
    /// Every pair fitted, whatever its size.
    pub fits: Vec<Candidate>,
    /// The best pair of its minimum size, for the ranking, named or not.
    pub ranked: Option<Candidate>,
    /// Simulations of Table 4 refits beside the best, which do not tick the progress.
    pub refit_simulations: usize,
}

/// Every pair worth fitting beside `best`: every candidate of another family on top of it,
/// and, when the best leaves the log far above its noise floor, further seeds each beside the
/// best place of every other family.
///
/// Jointly fitted, the new effect first, so the scan runs over its leading parameter. The best
/// single may be one effect standing in for two (an independent log: play at 3 deg for a 52 ms
/// delay and a tyre, 220 times the floor; the tyre fitted on top of the play never finds the
/// delay), so the runner-up (the best single of another family that also removes what an
/// effect must, and every other place of its family that does) seeds pairs too. A best single
/// near the floor is no stand-in, and the runner-up's pairs would cost a third more simulations
/// for nothing (`gap bench`: 1.3 times the floor). A family's places can nearly tie alone and
/// part in a pair (an independent log with rack friction and a 20 ms delay; play at 4 deg
/// removes the most alone, friction at the motor 80.4 % and at the rack 79.9 %; the delay beside
/// the motor's friction lost to the delay beside the play, beside the rack's it explains the
/// log).
fn jobs<'r>(
    st: &Stage,
    ranking: &'r [Candidate],
    best: &'r Candidate,
) -> Vec<(&'r Candidate, &'r Candidate)> {
    let other_family = |seed: &Candidate, c: &Candidate| {
        c.kinds.iter().all(|k| k.family() != seed.kinds[0].family())
    };
    let named = |c: &Candidate| st.named_alone(c);
    let mut jobs: Vec<(&Candidate, &Candidate)> = ranking
        .iter()
        .filter(|c| other_family(best, c))
        .map(|c| (best, c))
        .collect();
    let mut seeds: Vec<&Candidate> = Vec::new();
    if best.cost > UNEXPLAINED_RATIO * st.floor {
        if let Some(runner_up) = ranking.iter().find(|c| other_family(best, c) && named(c)) {
            seeds.extend(
                ranking
                    .iter()
                    .filter(|c| c.kinds[0].family() == runner_up.kinds[0].family() && named(c)),
            );
        }
        // And the best's own family's other places that remove what an effect must: the
        // same tie within a family, when the best is the family's other place (an
        // independent log with rack friction and a 20 ms delay, once the torque balance
        // ruled the play out: friction at the motor best alone, at the rack next; only the
        // rack's explains the log beside the delay).
        seeds.extend(ranking.iter().filter(|c| {
            c.kinds[0].family() == best.kinds[0].family() && c.kinds[0] != best.kinds[0] && named(c)
        }));
    }
    for seed in seeds {
        let mut families = Vec::new();
        for c in ranking.iter().filter(|c| other_family(seed, c)) {
            if !families.contains(&c.kinds[0].family()) {
                families.push(c.kinds[0].family());
                jobs.push((seed, c));
            }
        }
    }
    jobs
}

/// Each `(seed, other)` of `jobs` fitted jointly, a thread each, `other` first.
///
/// The second effect alone ran to the end of its range (it stood in for more than itself) and
/// removed at least half of the cost, and in the pair it collapsed below its minimum size, or
/// the pair removes too little to be named: the first may have grown to stand in for it. Play
/// with rack friction on a sweep: the friction at 1.5 times its size, the play at 0, 10 times
/// the floor; the play alone at its 4 deg limit. On a track: the play kept at 0.66 deg beside
/// 1550 N of friction, removing 15 % of what the friction alone left (the truth: 2.4 deg and
/// 860 N). So such a pair is fitted again from a start where they share the work (the second
/// at its size alone, the first at half its own), and the better fit counts.
fn fit_pairs(st: &Stage, jobs: &[(&Candidate, &Candidate)], best: &Candidate) -> Vec<Candidate> {
    let rig = st.rig;
    std::thread::scope(|s| {
        let handles: Vec<_> = jobs
            .iter()
            .map(|&(seed, other)| {
                s.spawn(move || {
                    let kinds = [other.kinds[0], seed.kinds[0]];
                    let start = pair_start(rig, other.kinds[0], &seed.values);
                    let mut fitted = st.fit(&kinds, Some(&start));
                    let (values, c) = (&fitted.values, fitted.cost);
                    let n_other = other.values.len();
                    let collapsed = values
                        .first()
                        .is_some_and(|v| *v < other.kinds[0].min_size(rig));
                    let stuck = collapsed || !st.removes_beyond(best.cost, c);
                    let pinned = other.kinds[0]
                        .specs(rig)
                        .first()
                        .zip(other.values.first())
                        .is_some_and(|(sp, v)| *v >= sp.hi - 1e-3 * (sp.hi - sp.lo));
                    if stuck && pinned && other.large_enough && other.improvement >= 0.5 {
                        let mut shared: Vec<f64> = other
                            .values
                            .iter()
                            .chain(seed.values.iter())
                            .copied()
                            .collect();
                        if let Some(lead) = shared.get_mut(n_other) {
                            *lead *= 0.5;
                        }
                        let again = st.fit(&kinds, Some(&shared));
                        let simulations = fitted.simulations + again.simulations;
                        if again.cost < c {
                            fitted = again;
                        }
                        fitted.simulations = simulations;
                    }
                    st.candidate(&kinds, fitted)
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    })
}

/// Where a pair's fit starts: `second` at its specs' starts, then the effect it joins at
/// `seed_values`, its values fitted alone.
pub(super) fn pair_start(rig: &Rig, second: EffectKind, seed_values: &[f64]) -> Vec<f64> {
    second
        .specs(rig)
        .iter()
        .map(|sp| sp.start)
        .chain(seed_values.iter().copied())
        .collect()
}

/// The pairs beside `best` fitted and judged; the findings say which pair was named, or why
/// none was.
///
/// The pair must remove a share of what the best left, a share of what is above the noise
/// floor, and a share of the noise floor's own worth: otherwise the second effect is fitting
/// the noise (or the first fit's own error). What it removes may be:
/// - the log's own clock: a logger stamps its rows late, which the best effect alone cannot
///   follow and a second effect can stand in for. The best again with the lag fitted beside
///   it, and the pair must still remove as much from what that leaves;
/// - no effect worth naming (Table 4 a few per cent off, the log's clock) where a second effect
///   below its minimum size explains what the best leaves better than the named one does:
///   every candidate soaks some of it up (an independent log with a 28 ms delay alone: belt
///   play at 0.58 deg beside it removed 63 % of what the delay left, rack friction at 160 N and
///   a tyre at 125 N, both under their minimum, removed 78 % and 71 %);
/// - the car's Table 4 being a few per cent off (every car is) rather than a second effect:
///   the table is refitted with the first effect in place, and the pair must still remove as
///   much from what that leaves;
/// - the fit's window: a second effect that lowers the whole log's GoF below the single's
///   (an independent EPOS4 car with a tyre alone: play of 0.75 deg beside it halved what the
///   tyre left on the window, and the GoF fell from 92.1 to 89.8 %).
///
/// The checks run in that order, each only when the ones before let the pair stand, so the
/// earlier ones say why where a later one would refuse the pair too.
pub(super) fn second_effect(
    st: &Stage,
    ranking: &[Candidate],
    best: &Candidate,
    findings: &mut Vec<Finding>,
) -> Second {
    let fits = fit_pairs(st, &jobs(st, ranking, best), best);
    let mut second = Second {
        chosen: best.clone(),
        fits: Vec::new(),
        ranked: None,
        refit_simulations: 0,
    };
    // The best pair whose effects are all of their minimum size, and the best of the
    // others (a second effect that came out below its minimum).
    let mut best_pair: Option<&Candidate> = None;
    let mut small_pair: Option<&Candidate> = None;
    for cand in &fits {
        let slot = if cand.large_enough {
            &mut best_pair
        } else {
            &mut small_pair
        };
        if slot.is_none_or(|b| cand.cost < b.cost) {
            *slot = Some(cand);
        }
    }
    if let Some(pair) = best_pair {
        let gain = best.cost - pair.cost;
        let gain_pct = 100.0 * gain / best.cost;
        let pair_removes = st.removes_beyond(best.cost, pair.cost);
        let lowers_gof = pair_removes && pair.gof < best.gof;
        let on_lag = if pair_removes {
            best_with_log_lag(st.rig, st.frec, st.fscorer, best, st.opts, &st.progress)
        } else {
            None
        };
        let lag_explains = on_lag.is_some_and(|(c_lag, _)| !st.removes_beyond(c_lag, pair.cost));
        let undersized =
            small_pair.filter(|small| pair_removes && !lag_explains && small.cost < pair.cost);
        let on_refit = if pair_removes && !lag_explains && undersized.is_none() {
            pair_on_refitted_table(
                st.rig,
                st.frec,
                st.fscorer,
                best,
                pair,
                st.opts,
                &st.progress,
            )
        } else {
            None
        };
        second.refit_simulations += on_refit.map_or(0, |(_, _, n)| n);
        if let Some((c_lag, lag_s)) = on_lag
            && lag_explains
        {
            findings.push(Finding::PairLagExplains {
                pair: pair.effect.clone(),
                gain_pct,
                best: best.effect.clone(),
                lag_ms: 1e3 * lag_s,
                with_lag: c_lag,
                pair_cost: pair.cost,
            });
        } else if let Some(small) = undersized {
            findings.push(Finding::PairSecondUndersized {
                pair: pair.effect.clone(),
                gain_pct,
                best: best.effect.clone(),
                small: small.effect.clone(),
                small_cost: small.cost,
            });
        } else if let Some((c_single, c_pair, _)) = on_refit
            && !st.removes_beyond(c_single, c_pair)
        {
            findings.push(Finding::PairNotBeyondRefit {
                pair: pair.effect.clone(),
                gain_pct,
                best: best.effect.clone(),
                tolerance: PARAMETER_TOLERANCE,
                single: c_single,
                with_pair: c_pair,
            });
        } else if lowers_gof {
            findings.push(Finding::PairLowersGof {
                pair: pair.effect.clone(),
                gain_pct,
                best: best.effect.clone(),
                pair_gof: pair.gof,
                best_gof: best.gof,
            });
        } else if pair_removes {
            // The pair may have grown from the runner-up and hold no part of the best.
            let added = pair.kinds.iter().find(|k| **k != best.kinds[0]);
            if pair.kinds.contains(&best.kinds[0])
                && let Some(added) = added
            {
                findings.push(Finding::Added {
                    added: added.name().to_string(),
                    gain_pct,
                });
            } else {
                findings.push(Finding::PairNamed {
                    pair: pair.effect.clone(),
                    gain_pct,
                    best: best.effect.clone(),
                });
            }
            second.chosen = pair.clone();
        } else if gain <= 0.0 {
            findings.push(Finding::PairLeavesMore {
                pair: pair.effect.clone(),
                best: best.effect.clone(),
                pair_cost: pair.cost,
            });
        } else {
            findings.push(Finding::PairRemovesTooLittle {
                pair: pair.effect.clone(),
                gain_pct,
                gain,
            });
        }
        second.ranked = Some(pair.clone());
    }
    second.fits = fits;
    second
}

/// The pair the log's own torque balance asks for beside a single named effect, if one fits.
///
/// The balance shows play, or a Coulomb force at the rack, beyond the smallest named by three
/// standard errors, and the verdict names no effect that makes it: the pair rules weigh what
/// the fits leave, which a single effect standing in for two can keep low (play with rack
/// friction on the independent world, named play alone with the balance reading 330 +- 16 N at
/// the rack; the pair fitted from the friction's own start left more than the play alone). The
/// pair of the named effect with one that makes it is fitted again from the balance's reading,
/// and the best such pair among it and `fits`, of its minimum size and leaving less than the
/// single, is the verdict. Where none is, a finding says what the balance showed.
pub(super) fn demanded_by_log(
    st: &Stage,
    sig: &Signature,
    chosen: &Candidate,
    fits: &[Candidate],
    findings: &mut Vec<Finding>,
) -> Option<Candidate> {
    let rig = st.rig;
    if chosen.kinds.len() != 1 {
        return None;
    }
    let need = demanded(rig, sig, chosen)?;
    let kinds = [need.kind, chosen.kinds[0]];
    // Each effect the balance reads starts at its reading (the named one alone grew to
    // stand in for the other: play at 2.37 deg for the 1.54 deg read, from which the
    // friction fell back to zero), the others where their fits start or ended.
    let read = |k: EffectKind| match k {
        EffectKind::BeltPlay => Some(sig.belt_play_deg),
        EffectKind::RackFriction => Some(sig.rack_coulomb_n),
        _ => None,
    };
    let start: Vec<f64> = kinds
        .iter()
        .flat_map(|&k| {
            let own = if k == chosen.kinds[0] {
                chosen.values.clone()
            } else {
                k.specs(rig).iter().map(|sp| sp.start).collect()
            };
            k.specs(rig)
                .into_iter()
                .zip(own)
                .enumerate()
                .map(move |(j, (sp, v))| match read(k) {
                    Some(r) if j == 0 => r.clamp(sp.lo, sp.hi),
                    _ => v,
                })
        })
        .collect();
    // A friction read from the balance creeps or not: its creep speed is started at
    // nothing and at a few mm/s (the cost is rugged in it; from nothing LM keeps it
    // there), and the better fit counts.
    let starts: Vec<Vec<f64>> = if kinds.contains(&EffectKind::RackFriction) {
        let creep = first_param_at(rig, &kinds, EffectKind::RackFriction).map_or(1, |at| at + 1);
        [0.0, 0.5, 1.0, 2.0]
            .iter()
            .map(|c| {
                let mut s = start.clone();
                if let Some(v) = s.get_mut(creep) {
                    *v = *c;
                }
                s
            })
            .collect()
    } else {
        vec![start]
    };
    let from_reading = starts
        .iter()
        .map(|start| st.candidate(&kinds, st.fit(&kinds, Some(start))))
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .expect("one start at least");
    // The pair counts when the effect named alone keeps its minimum size, the one the
    // balance shows comes out at half its own or more, and the pair leaves no more than
    // a second effect must remove to be named (the fits cannot tell it from the single
    // then, and the balance, which no model form enters, can). An independent log with
    // play and rack friction: the two at 1.63 deg and 182 N from the balance's reading
    // leave 12 % more than the play alone at 2.37 deg.
    let first = |c: &Candidate, kind: EffectKind| -> Option<f64> {
        c.values.get(first_param_at(rig, &c.kinds, kind)?).copied()
    };
    let single = chosen.kinds[0];
    let pair = fits
        .iter()
        .chain(std::iter::once(&from_reading))
        .filter(|c| {
            c.kinds.len() == 2
                && c.kinds.contains(&single)
                && c.cost <= (1.0 + MIN_PAIR_IMPROVEMENT) * chosen.cost
                && first(c, single).is_some_and(|v| v >= single.min_size(rig))
                && c.kinds.iter().any(|&k| {
                    need.families.contains(&k.family())
                        && first(c, k).is_some_and(|v| v >= 0.5 * k.min_size(rig))
                })
        })
        .min_by(|a, b| a.cost.total_cmp(&b.cost))
        .cloned();
    match &pair {
        Some(pair) => findings.push(Finding::DemandedByLog {
            pair: pair.effect.clone(),
            reading: need.what,
            value: need.reading,
            standard_error: need.standard_error,
            unit: need.unit,
            single: chosen.effect.clone(),
            more_pct: 100.0 * (pair.cost / chosen.cost - 1.0),
        }),
        None => findings.push(Finding::DemandedNotFitted {
            reading: need.what,
            value: need.reading,
            standard_error: need.standard_error,
            unit: need.unit,
            single: chosen.effect.clone(),
        }),
    }
    pair
}

/// What the log's [`Signature`] shows beside a single named effect that the effect does not
/// make: the families that would, the candidate fitted for it from the reading, and the
/// reading.
struct Need {
    families: &'static [&'static str],
    kind: EffectKind,
    what: &'static str,
    reading: f64,
    standard_error: f64,
    unit: &'static str,
}

/// Play in the belt beyond the smallest named by three standard errors beside an effect of
/// another family; else a Coulomb force at the rack so beside one that is neither a friction
/// nor a tyre (a tyre saturates into the same force).
fn demanded(rig: &Rig, s: &Signature, chosen: &Candidate) -> Option<Need> {
    let has = |family: &str| chosen.kinds.iter().any(|k| k.family() == family);
    let clearly =
        |value: f64, se: f64, kind: EffectKind| Signature::above(value, se, kind.min_size(rig));
    if !has("backlash") && clearly(s.belt_play_deg, s.belt_play_se_deg, EffectKind::BeltPlay) {
        return Some(Need {
            families: &["backlash"],
            kind: EffectKind::BeltPlay,
            what: "play in the belt",
            reading: s.belt_play_deg,
            standard_error: s.belt_play_se_deg,
            unit: "deg",
        });
    }
    if !has("coulomb_friction")
        && !has("tire_ground")
        && clearly(
            s.rack_coulomb_n,
            s.rack_coulomb_se_n,
            EffectKind::RackFriction,
        )
    {
        return Some(Need {
            families: &["coulomb_friction", "tire_ground"],
            kind: EffectKind::RackFriction,
            what: "Coulomb force at the rack",
            reading: s.rack_coulomb_n,
            standard_error: s.rack_coulomb_se_n,
            unit: "N",
        });
    }
    None
}

//! The withheld-effect check: logs from the selftest's own world ([`super::generator`]: a
//! nonlinear plant by RK4, effects in other forms and places than the candidates, Table 4 off
//! in every case, logs at 100-1000 Hz with skewed stamps) with a hidden effect, none, two, or
//! far-off parameters, diagnosed blind, and the confusion matrix of what was named against
//! what was hidden. `draw_case` and `record_of` are the diagnosis's own model with the
//! candidate forms, for the unit tests that need an exact effect.

use super::generator::{self, GenCase};
use super::model::Effects;
use super::rig::Rig;
use super::rng::{self, Rng};
use super::{EffectKind, Options, Record, diagnose};
use crate::scenario::Sweep;
use std::collections::BTreeMap;

/// What a case hides and how its log was made.
#[derive(Debug, Clone, serde::Serialize)]
pub struct Case {
    pub index: usize,
    pub scenario: String,
    /// The hidden effects, sorted by name; empty for none.
    pub hidden: Vec<String>,
    #[serde(skip)]
    pub effects: Effects,
    #[serde(skip)]
    pub reference: Vec<f64>,
}

/// The label of a set of effects: names joined by `+`, or `none`.
pub fn label(names: &[String]) -> String {
    if names.is_empty() {
        "none".into()
    } else {
        let mut v = names.to_vec();
        v.sort();
        v.join("+")
    }
}

/// Draw the hidden size of one effect.
fn draw_effect(kind: EffectKind, rng: &mut Rng, fx: &mut Effects) {
    match kind {
        EffectKind::Backlash => fx.backlash = rng.range(0.6, 2.5),
        EffectKind::CoulombFriction => fx.coulomb = rng.range(0.06, 0.25),
        EffectKind::Delay => fx.delay_s = rng.range(0.015, 0.06),
        EffectKind::CurrentDelay => fx.effort_delay_s = rng.range(0.015, 0.06),
        EffectKind::TireGround => {
            fx.tire_force_n = rng.range(300.0, 1500.0);
            fx.tire_stiffness_n_per_mm = rng.range(200.0, 1000.0);
        }
        EffectKind::SupplySag => fx.supply_v = rng.range(14.0, 20.0),
        EffectKind::RackFriction => fx.rack_coulomb_n = rng.range(400.0, 1500.0),
        EffectKind::BeltPlay => fx.belt_play = rng.range(0.6, 2.5),
        EffectKind::TireDahl => {
            fx.tire_force_n = rng.range(300.0, 1500.0);
            fx.tire_stiffness_n_per_mm = rng.range(200.0, 1000.0);
            fx.tire_dahl = true;
        }
    }
}

/// Draw case `index` of a run seeded with `seed`.
pub fn draw_case(seed: u64, index: usize, duration_s: f64) -> Case {
    let mut rng = rng::seeded(seed.wrapping_mul(1_000_003).wrapping_add(index as u64));
    let kinds = EffectKind::CORE;
    let roll = rng.unit();
    let mut hidden: Vec<EffectKind> = Vec::new();
    if roll < 0.2 {
        // none
    } else if roll < 0.8 {
        hidden.push(kinds[(rng.next_u64() % 4) as usize]);
    } else {
        let a = (rng.next_u64() % 4) as usize;
        let b = (a + 1 + (rng.next_u64() % 3) as usize) % 4;
        hidden.push(kinds[a]);
        hidden.push(kinds[b]);
    }
    let mut effects = Effects::nominal();
    for k in &hidden {
        draw_effect(*k, &mut rng, &mut effects);
    }
    let (scenario, reference) = if rng.unit() < 0.5 {
        let amp = rng.range(4.0, 10.0);
        let f1 = rng.range(3.0, 6.0);
        (
            format!("sweep {amp:.1} deg 0.2-{f1:.1} Hz"),
            Sweep {
                amplitude_deg: amp,
                f_start_hz: 0.2,
                f_end_hz: f1,
                duration_s,
            }
            .samples(),
        )
    } else {
        let track = crate::scenario::builtin_track();
        let n = (duration_s * 100.0) as usize + 1;
        let max_start = track.len().saturating_sub(n + 1).max(1);
        // The last 10 s hold the > 4 Hz burst; keep to the driving part.
        let start = (rng.next_u64() as usize) % max_start.min(9_000);
        (
            format!(
                "track {:.0}-{:.0} s",
                start as f64 / 100.0,
                (start + n) as f64 / 100.0
            ),
            track[start..start + n].to_vec(),
        )
    };
    let mut names: Vec<String> = hidden.iter().map(|k| k.name().to_string()).collect();
    names.sort();
    Case {
        index,
        scenario,
        hidden: names,
        effects,
        reference,
    }
}

/// The log of a case: the model with the hidden effects, then sensor noise and quantisation
/// (0.01 deg on the angle, 10 mA on the current, after 100 Hz averaging).
pub fn record_of(rig: &Rig, case: &Case, seed: u64) -> Record {
    let mut rec = Record {
        dt: 0.01,
        reference: case.reference.clone(),
        ..Record::default()
    };
    let sim = super::simulate(rig, &rec, &case.effects);
    let mut rng = rng::seeded(seed ^ (case.index as u64).wrapping_mul(0x1234_5678_9abc_def1));
    let q = |v: f64, step: f64| (v / step).round() * step;
    rec.output = sim
        .output
        .iter()
        .map(|v| q(v + 0.02 * rng.normal(), 0.01))
        .collect();
    rec.effort = sim
        .effort
        .iter()
        .map(|v| q(v + 0.3 * rng.normal(), 0.01))
        .collect();
    rec.motor = Some(sim.motor.clone());
    rec
}

/// One diagnosed case.
/// Which world the selftest's logs come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "snake_case")]
pub enum World {
    /// The diagnosis's own model with the candidate forms ([`draw_case`], [`record_of`]): a
    /// check of the search and the verdict rules, which cannot show a modelling error.
    Model,
    /// The independent world of [`super::generator`]: the check the README's figure is.
    Independent,
}

/// What a diagnosed case was.
#[derive(Debug, Clone, serde::Serialize)]
pub struct CaseInfo {
    pub index: usize,
    pub scenario: String,
    /// The hidden labels, sorted; empty for none.
    pub hidden: Vec<String>,
    /// The independent world's truth, when the case came from it.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub truth: Option<GenCase>,
}

/// The log of case `i` of a run in `world`.
fn case_of(world: World, seed: u64, i: usize, duration_s: f64, rig: &Rig) -> (CaseInfo, Record) {
    match world {
        World::Model => {
            let case = draw_case(seed, i, duration_s);
            let rec = record_of(rig, &case, seed);
            (
                CaseInfo {
                    index: case.index,
                    scenario: case.scenario,
                    hidden: case.hidden,
                    truth: None,
                },
                rec,
            )
        }
        World::Independent => {
            let case = generator::draw(seed, i, duration_s);
            let rec = generator::record_of(&case, seed);
            (
                CaseInfo {
                    index: case.index,
                    scenario: case.scenario.clone(),
                    hidden: case.hidden.clone(),
                    truth: Some(case),
                },
                rec,
            )
        }
    }
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct CaseResult {
    pub case: CaseInfo,
    pub named: Vec<String>,
    pub correct: bool,
    pub gof_before: f64,
    pub gof_after: f64,
    /// The verdict's reason, for the record.
    pub reason: String,
    /// Each candidate fitted alone, best first (sizes, share removed, large enough), and the
    /// Table 4 refit when one was tried: what a miss is read from.
    pub ranking: Vec<super::Candidate>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameters: Option<super::identify::Identified>,
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct SelftestReport {
    pub cases: Vec<CaseResult>,
    /// (hidden label, named label) -> count.
    pub confusion: BTreeMap<String, BTreeMap<String, usize>>,
    pub accuracy: f64,
    pub mean_gof_before: f64,
    pub mean_gof_after: f64,
}

/// Run the cases numbered `cases` (`0..N` for a run of N; one index reruns that case of the
/// seed) of `duration_s` each (the independent world's tracks are 120 s); `on_case` sees
/// every result as it comes.
pub fn run(
    world: World,
    cases: &[usize],
    seed: u64,
    duration_s: f64,
    opts: &Options,
    on_case: &(dyn Fn(&CaseResult) + Sync),
) -> SelftestReport {
    let rig = Rig::paper();
    let threads = opts.threads.max(1);
    let per_case = Options {
        threads: 1,
        progress: false,
        ..opts.clone()
    };
    let next = std::sync::atomic::AtomicUsize::new(0);
    let mut results: Vec<CaseResult> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|_| {
                s.spawn(|| {
                    let mut out = Vec::new();
                    loop {
                        let k = next.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                        let Some(&i) = cases.get(k) else {
                            break;
                        };
                        let (case, rec) = case_of(world, seed, i, duration_s, &rig);
                        let d = diagnose(&rig, &rec, None, &per_case);
                        let mut named = d.verdict.effects.clone();
                        named.sort();
                        named.dedup();
                        let r = CaseResult {
                            correct: named == case.hidden,
                            named,
                            gof_before: d.baseline_gof,
                            gof_after: d.verdict.gof_after,
                            reason: d.verdict.reason.clone(),
                            ranking: d.ranking,
                            parameters: d.parameters,
                            case,
                        };
                        on_case(&r);
                        out.push(r);
                    }
                    out
                })
            })
            .collect();
        handles
            .into_iter()
            // A case whose worker panicked fails the selftest rather than leaving the table.
            .flat_map(|h| h.join().unwrap_or_else(|e| std::panic::resume_unwind(e)))
            .collect()
    });
    results.sort_by_key(|r| r.case.index);
    let mut confusion: BTreeMap<String, BTreeMap<String, usize>> = BTreeMap::new();
    for r in &results {
        *confusion
            .entry(label(&r.case.hidden))
            .or_default()
            .entry(label(&r.named))
            .or_default() += 1;
    }
    let n = results.len().max(1) as f64;
    SelftestReport {
        accuracy: results.iter().filter(|r| r.correct).count() as f64 / n,
        mean_gof_before: results.iter().map(|r| r.gof_before).sum::<f64>() / n,
        mean_gof_after: results.iter().map(|r| r.gof_after).sum::<f64>() / n,
        confusion,
        cases: results,
    }
}

impl SelftestReport {
    /// The confusion matrix as text: hidden (rows) against named (columns).
    pub fn confusion_table(&self) -> String {
        use std::fmt::Write;
        let mut cols: Vec<String> = self
            .confusion
            .values()
            .flat_map(|m| m.keys().cloned())
            .collect();
        cols.sort();
        cols.dedup();
        let abbrev = |l: &str| -> String {
            l.split('+')
                .map(|p| match p {
                    "backlash" => "BL",
                    "coulomb_friction" => "CF",
                    "delay" => "DL",
                    "tire_ground" => "TG",
                    "supply_sag" => "SS",
                    "parameters" => "PAR",
                    "unexplained" => "UNX",
                    "none" => "none",
                    other => other,
                })
                .collect::<Vec<_>>()
                .join("+")
        };
        let mut s = String::new();
        let _ = write!(s, "{:<12}", "hidden\\named");
        for c in &cols {
            let _ = write!(s, " {:>6}", abbrev(c));
        }
        let _ = writeln!(s);
        for (row, m) in &self.confusion {
            let _ = write!(s, "{:<12}", abbrev(row));
            for c in &cols {
                let _ = write!(s, " {:>6}", m.get(c).copied().unwrap_or(0));
            }
            let _ = writeln!(s);
        }
        let _ = writeln!(
            s,
            "(BL backlash, CF coulomb_friction, DL delay, TG tire_ground, PAR parameters, UNX unexplained)\n{} of {} named right ({:.0} %); mean GoF {:.1} % -> {:.1} %",
            self.cases.iter().filter(|r| r.correct).count(),
            self.cases.len(),
            100.0 * self.accuracy,
            100.0 * self.mean_gof_before,
            100.0 * self.mean_gof_after
        );
        s
    }
}

/// The options the selftest uses by default: the paper rig's candidates, cheap fits.
pub fn default_options() -> Options {
    Options {
        effects: EffectKind::PAPER.to_vec(),
        fit: super::fit::FitOptions {
            scan: 5,
            iterations: 5,
            polish: 2,
            jacobian_threads: 1,
            hold_at_bounds: false,
        },
        ..Options::default()
    }
}

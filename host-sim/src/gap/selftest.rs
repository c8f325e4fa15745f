//! The withheld-effect check: logs from the selftest's own world ([`super::generator`]: a
//! nonlinear plant by RK4, effects in other forms and places than the candidates, Table 4 off
//! in every case, logs at 100-1000 Hz with skewed stamps) with a hidden effect, none, two, or
//! far-off parameters, diagnosed blind, and the confusion matrix of what was named against
//! what was hidden. `draw_case` and `record_of` are the diagnosis's own model with the
//! candidate forms, for the unit tests that need an exact effect. [`run_loggers`] diagnoses
//! the same cars from the files the world's loggers write ([`generator::Logger`]: either
//! reference convention, 100-1000 Hz, jitter, lost rows, no header), as `host-sim gap FILE`
//! reads a file, and counts the verdicts that changed against our logger's.

use super::drive::{CarChoice, LogHeader};
use super::generator::{self, GenCase, LoggedCar, Logger, ReferenceConvention};
use super::model::Effects;
use super::rig::{CarDrive, Rig};
use super::rng::{self, Rng};
use super::{EffectKind, LogTiming, Options, Record, diagnose, parallel_map};
use crate::scenario::Sweep;
use crate::sim::Controller;
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
    /// The independent world's cars with an effect no candidate has
    /// ([`generator::draw_unmodelled`]): right when answered `unexplained` or `parameters`.
    Unmodelled,
}

/// A verdict `named` is right for a car hiding `hidden`: the same labels, or for a car with
/// an effect no candidate has (`unmodelled`), `unexplained` or `parameters`.
pub fn right(hidden: &[String], named: &[String]) -> bool {
    match hidden {
        [h] if h == "unmodelled" => {
            matches!(named, [n] if n == "unexplained" || n == "parameters")
        }
        _ => named == hidden,
    }
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

/// Case `i` of the independent world's cars, or of its cars with an unmodelled effect.
fn world_case(world: World, seed: u64, i: usize, duration_s: f64) -> GenCase {
    match world {
        World::Unmodelled => generator::draw_unmodelled(seed, i, duration_s),
        _ => generator::draw(seed, i, duration_s),
    }
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
        World::Independent | World::Unmodelled => {
            let case = world_case(world, seed, i, duration_s);
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
    /// The constant and the scale the log's effort keeps against the nominal model's.
    pub effort_offset: super::Offset,
    /// The constant the log's output keeps against the nominal model's.
    pub output_offset: super::Offset,
    /// How many times the nominal model's effort the log's is.
    pub effort_scale: super::Scale,
    /// The same with a friction of the motion's sign fitted beside it.
    pub effort_scale_beside_friction: super::Scale,
    /// The strongest line in the effort residual against the motor's angle.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_ripple: Option<super::ripple::MotorRipple>,
    /// The log's torque balance, read without the model ([`super::signature`]): the second
    /// reading of play and rack friction beside the verdict; `None` where it cannot be read.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub signature: Option<super::signature::Signature>,
    /// The sizes the verdict's effects were fitted at, where it names effects.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub fitted: Option<super::Candidate>,
    /// The logger that wrote the case's file, in a run under several loggers.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub logger: Option<LoggedBy>,
}

/// How a case's file was written and what the diagnosis read of it.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LoggedBy {
    /// The kind asked for (`ours`, `drawn`, `starting-100-jitter-drop`, ...).
    pub kind: String,
    pub logger: Logger,
    /// The car the diagnosis took (drive, controller, reference convention, timing bound).
    pub car: Option<CarChoice>,
    pub log_timing: LogTiming,
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
    let per_case = single_threaded(opts);
    let results = parallel_map(cases, opts.threads.max(1), |&i| {
        let (case, rec) = case_of(world, seed, i, duration_s, &rig);
        let r = diagnosed(&rig, &rec, case, &per_case, None);
        on_case(&r);
        r
    });
    SelftestReport::of(results)
}

/// The options of one case's diagnosis: the run's threads go to the cases, one each.
fn single_threaded(opts: &Options) -> Options {
    Options {
        threads: 1,
        progress: false,
        ..opts.clone()
    }
}

/// The diagnosis of one case's record, scored against what it hides.
fn diagnosed(
    rig: &Rig,
    rec: &Record,
    case: CaseInfo,
    opts: &Options,
    logger: Option<LoggedBy>,
) -> CaseResult {
    let d = diagnose(rig, rec, None, opts);
    // The car on the clock the diagnosis ran, as `gap FILE` reports it.
    let logger = logger.map(|mut by| {
        by.car = by.car.map(|c| c.on_the_clock_of(&d));
        by
    });
    let mut named = d.verdict.effects.clone();
    named.sort();
    named.dedup();
    CaseResult {
        correct: right(&case.hidden, &named),
        named,
        gof_before: d.baseline_gof,
        gof_after: d.verdict.gof_after,
        reason: d.verdict.reason.clone(),
        fitted: d.verdict.fitted.clone(),
        ranking: d.ranking,
        parameters: d.parameters,
        effort_offset: d.effort_offset,
        output_offset: d.output_offset,
        effort_scale: d.effort_scale,
        effort_scale_beside_friction: d.effort_scale_beside_friction,
        motor_ripple: d.motor_ripple,
        signature: d.signature,
        case,
        logger,
    }
}

/// Which logger writes a case's file in a run under several loggers.
#[derive(Debug, Clone, PartialEq)]
pub enum LoggerKind {
    /// Ours at the case's own rate (stamps on the grid, every row, the header lines): the
    /// verdicts every other logger's are compared with.
    Ours,
    /// The team's logger drawn with the case ([`Logger::draw`]).
    Drawn,
    /// One logger for every case, without header lines.
    Fixed(Logger),
}

impl LoggerKind {
    /// `ours`, `drawn`, or `ending|starting-RATE[-jitter][-drop][-instant][-held][-negcurrent|-negref]`:
    /// a team's logger with that reference convention and rate (Hz, 100-1000, a whole number
    /// of the plant's 20 kHz ticks a row: 100, 200, 250, 400, 500, 1000, ...), stamps +-1 ms if
    /// `jitter`, 1 % of rows lost if `drop`, the current's instantaneous sample at each row if
    /// `instant`, each row holding the car's last 100 Hz status frame if `held` (above
    /// 100 Hz), the current or the reference written negated if `negcurrent` or `negref`,
    /// no header lines.
    pub fn parse(name: &str) -> Result<LoggerKind, String> {
        let name = name.trim();
        match name {
            "ours" => return Ok(LoggerKind::Ours),
            "drawn" => return Ok(LoggerKind::Drawn),
            _ => {}
        }
        let bad = || {
            format!(
                "logger {name:?}: expected `ours`, `drawn`, \
                 ending|starting-RATE[-jitter][-drop][-instant][-held][-negcurrent|-negref] with RATE \
                 in Hz, 100-1000, dividing 20000 (e.g. starting-100-jitter-drop, ending-250), \
                 or the EPOS4 car's epos4-convert[-drift]|\
                 epos4-status[-drift][-jitter][-drop][-negcurrent|-negref]"
            )
        };
        let mut parts = name.split('-');
        let mut logger = match parts.next() {
            Some("epos4") => {
                let car = match parts.next() {
                    Some("convert") => LoggedCar::Epos4Convert,
                    Some("status") => LoggedCar::Epos4StatusFrame,
                    _ => return Err(bad()),
                };
                Logger {
                    car,
                    // Convert writes its header lines; a team's logger of the TPDOs none.
                    header: car == LoggedCar::Epos4Convert,
                    ..Logger::ours(100)
                }
            }
            first => Logger {
                reference: match first {
                    Some("ending") => ReferenceConvention::PeriodEnding,
                    Some("starting") => ReferenceConvention::PeriodStarting,
                    _ => return Err(bad()),
                },
                rate_hz: match parts.next().and_then(|r| r.parse::<u32>().ok()) {
                    Some(r) if generator::logs_at(r) => r,
                    _ => return Err(bad()),
                },
                jitter_s: 0.0,
                drop_chance: 0.0,
                header: false,
                car: LoggedCar::Direct,
                drifting_clock: false,
                instant_current: false,
                negated: generator::Negated::None,
                held_frames: false,
            },
        };
        for p in parts {
            match p {
                // The EPOS4 car's ECU on a clock of its own.
                "drift" if logger.car != LoggedCar::Direct && !logger.drifting_clock => {
                    logger.drifting_clock = true
                }
                // Convert's rows are one per reference period, on its grid, every one.
                _ if logger.car == LoggedCar::Epos4Convert => return Err(bad()),
                "jitter" if logger.jitter_s == 0.0 => logger.jitter_s = generator::LOGGER_JITTER_S,
                "drop" if logger.drop_chance == 0.0 => {
                    logger.drop_chance = generator::LOGGER_DROP_CHANCE
                }
                // The current sampled at the row's instant (the direct drive's loggers).
                "instant" if logger.car == LoggedCar::Direct && !logger.instant_current => {
                    logger.instant_current = true
                }
                // A logger of the car's frames, faster than they come.
                "held"
                    if logger.car == LoggedCar::Direct
                        && logger.rate_hz > 100
                        && !logger.held_frames =>
                {
                    logger.held_frames = true
                }
                // A team's signs (not convert's, which writes the car's).
                "negcurrent" if logger.negated == generator::Negated::None => {
                    logger.negated = generator::Negated::Current
                }
                "negref" if logger.negated == generator::Negated::None => {
                    logger.negated = generator::Negated::Reference
                }
                _ => return Err(bad()),
            }
        }
        Ok(LoggerKind::Fixed(logger))
    }

    /// The name it was given by.
    pub fn name(&self) -> String {
        match self {
            LoggerKind::Ours => "ours".into(),
            LoggerKind::Drawn => "drawn".into(),
            LoggerKind::Fixed(l) => {
                let mut s = match l.car {
                    LoggedCar::Direct => format!("{}-{}", l.reference.short(), l.rate_hz),
                    LoggedCar::Epos4Convert => "epos4-convert".into(),
                    LoggedCar::Epos4StatusFrame => "epos4-status".into(),
                };
                if l.drifting_clock {
                    s.push_str("-drift");
                }
                if l.jitter_s > 0.0 {
                    s.push_str("-jitter");
                }
                if l.drop_chance > 0.0 {
                    s.push_str("-drop");
                }
                if l.instant_current {
                    s.push_str("-instant");
                }
                if l.held_frames {
                    s.push_str("-held");
                }
                match l.negated {
                    generator::Negated::None => {}
                    generator::Negated::Current => s.push_str("-negcurrent"),
                    generator::Negated::Reference => s.push_str("-negref"),
                }
                s
            }
        }
    }

    fn logger_for(&self, case: &GenCase) -> Logger {
        match self {
            LoggerKind::Ours => Logger::ours(case.log_rate_hz),
            LoggerKind::Drawn => case.logger,
            LoggerKind::Fixed(l) => *l,
        }
    }
}

/// One logger's verdicts on the run's cars.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LoggerRun {
    pub kind: String,
    /// Its cases, confusion matrix and accuracy.
    pub report: SelftestReport,
    /// The cases whose named effects differ from those named on our logger's file.
    pub changed_vs_ours: Vec<usize>,
}

/// The same cars diagnosed from the files of several loggers.
#[derive(Debug, Clone, serde::Serialize)]
pub struct LoggersReport {
    /// Ours first.
    pub loggers: Vec<LoggerRun>,
}

/// Which cars a run under several loggers diagnoses: cases `cases` of `world` on `seed`,
/// sweeps of `duration_s`.
#[derive(Debug, Clone, Copy)]
pub struct Cars<'a> {
    pub world: World,
    pub cases: &'a [usize],
    pub seed: u64,
    pub duration_s: f64,
}

/// The independent world's cases `cases`, each written by every logger of `kinds` (ours
/// always, first) into a file and diagnosed as `host-sim gap FILE` diagnoses it: the file
/// read by the rig's reader, the car (drive, controller) given in `car` as `--drive` and
/// `--controller` give it, else from the file's header lines, else fitted, and so the
/// reference convention ([`super::drive::choose_for_log`]). The files are kept in `keep_logs`
/// where given, else removed once diagnosed.
pub fn run_loggers(
    kinds: &[LoggerKind],
    car: (Option<CarDrive>, Option<Controller>),
    cars: Cars,
    opts: &Options,
    keep_logs: Option<&std::path::Path>,
    on_case: &(dyn Fn(&CaseResult) + Sync),
) -> Result<LoggersReport, String> {
    let kinds: Vec<LoggerKind> = std::iter::once(LoggerKind::Ours)
        .chain(kinds.iter().cloned())
        .fold(Vec::new(), |mut v, k| {
            if !v.contains(&k) {
                v.push(k);
            }
            v
        });
    let Cars {
        world,
        cases,
        seed,
        duration_s,
    } = cars;
    if world == World::Model {
        return Err("the loggers write the independent world's cars, not the model world's".into());
    }
    let rig = Rig::paper();
    let per_case = single_threaded(opts);
    let jobs: Vec<(usize, usize)> = cases
        .iter()
        .flat_map(|&i| (0..kinds.len()).map(move |k| (i, k)))
        .collect();
    // The files live only while their case is diagnosed, in a directory of this process;
    // or they are kept where `keep_logs` says, named by case and logger.
    let dir = match keep_logs {
        Some(d) => d.to_path_buf(),
        None => std::env::temp_dir().join(format!("host-sim-gap-loggers-{}", std::process::id())),
    };
    std::fs::create_dir_all(&dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    let results = parallel_map(&jobs, opts.threads.max(1), |&(i, k)| {
        let case = world_case(world, seed, i, duration_s);
        let logger = kinds[k].logger_for(&case);
        let path = match keep_logs {
            Some(_) => dir.join(format!("case{i}-{}.csv", kinds[k].name())),
            None => dir.join(format!("case{i}-logger{k}.csv")),
        };
        let loaded = generator::log_of(&case, seed, &logger)
            .save(&path)
            .map_err(|e| e.to_string())
            .and_then(|()| rig.load_log(&path).map_err(|e| e.to_string()))
            .and_then(|l| {
                LogHeader::parse(&l.comments)
                    .map(|h| (l, h))
                    .map_err(|e| format!("{}: {e}", path.display()))
            });
        if keep_logs.is_none() {
            let _ = std::fs::remove_file(&path);
        }
        let (loaded, header) = loaded?;
        let (car_rig, rec, car) =
            super::drive::choose_for_log(&rig, &loaded, &header, car.0, car.1, &per_case);
        let info = CaseInfo {
            index: case.index,
            scenario: case.scenario.clone(),
            hidden: case.hidden.clone(),
            truth: Some(case),
        };
        let by = LoggedBy {
            kind: kinds[k].name(),
            logger,
            car,
            log_timing: loaded.timing,
        };
        let r = diagnosed(&car_rig, &rec, info, &per_case, Some(by));
        on_case(&r);
        Ok::<_, String>((k, r))
    });
    if keep_logs.is_none() {
        let _ = std::fs::remove_dir(&dir);
    }
    let mut per_kind: Vec<Vec<CaseResult>> = vec![Vec::new(); kinds.len()];
    for r in results {
        let (k, r) = r?;
        per_kind[k].push(r);
    }
    let ours: BTreeMap<usize, Vec<String>> = per_kind[0]
        .iter()
        .map(|r| (r.case.index, r.named.clone()))
        .collect();
    let loggers = kinds
        .iter()
        .zip(per_kind)
        .map(|(kind, results)| LoggerRun {
            kind: kind.name(),
            changed_vs_ours: results
                .iter()
                .filter(|r| ours.get(&r.case.index) != Some(&r.named))
                .map(|r| r.case.index)
                .collect(),
            report: SelftestReport::of(results),
        })
        .collect();
    Ok(LoggersReport { loggers })
}

impl LoggersReport {
    /// Per logger: how many verdicts are right, how many changed against ours, and its
    /// confusion matrix.
    pub fn table(&self) -> String {
        use std::fmt::Write;
        let mut s = String::new();
        for l in &self.loggers {
            let n = l.report.cases.len();
            let right = l.report.cases.iter().filter(|r| r.correct).count();
            let read_so = |what: fn(&super::drive::CarChoice) -> bool| {
                l.report
                    .cases
                    .iter()
                    .filter(|r| {
                        r.logger
                            .as_ref()
                            .and_then(|b| b.car.as_ref())
                            .is_some_and(what)
                    })
                    .count()
            };
            let chatter = read_so(|c| c.current_chatter.is_some());
            let columns = read_so(|c| c.columns.is_some_and(|s| s.any()));
            let _ = writeln!(
                s,
                "logger {}: {right} of {n} right, {} changed against ours{}{}{}",
                l.kind,
                l.changed_vs_ours.len(),
                if l.changed_vs_ours.is_empty() {
                    String::new()
                } else {
                    format!(
                        " (cases {})",
                        l.changed_vs_ours
                            .iter()
                            .map(|i| i.to_string())
                            .collect::<Vec<_>>()
                            .join(",")
                    )
                },
                if chatter > 0 {
                    format!(
                        "; {chatter} read as instantaneous samples of the current loop's chatter"
                    )
                } else {
                    String::new()
                },
                if columns > 0 {
                    format!("; {columns} with a column read negated or left out")
                } else {
                    String::new()
                }
            );
            s.push_str(&l.report.confusion_table());
            s.push_str(&l.report.balance_summary());
            s.push('\n');
        }
        s
    }
}

impl SelftestReport {
    /// The report of these results: sorted by case, the confusion matrix and the means.
    pub fn of(mut results: Vec<CaseResult>) -> SelftestReport {
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

impl SelftestReport {
    /// What the log's torque balance read against what each car hides, over the cases whose
    /// truth is known and whose balance holds: the play on cars with play and the largest on
    /// cars without; the force at the rack on cars with rack friction and the largest on cars
    /// with neither friction nor a tyre (a saturated tyre is a force at the rack too). Empty
    /// where no case has both.
    pub fn balance_summary(&self) -> String {
        let holding: Vec<(&generator::Truth, &super::signature::Signature)> = self
            .cases
            .iter()
            .filter_map(|r| Some((&r.case.truth.as_ref()?.truth, r.signature.as_ref()?)))
            .filter(|(_, g)| g.holds)
            .collect();
        if holding.is_empty() {
            return String::new();
        }
        let against = holding.iter().filter(|(_, g)| g.against_model).count();
        let mut s = format!(
            "torque balance (no fit; {}), where it holds: {} of {} logs\n",
            if against == 0 {
                "the log alone".to_string()
            } else {
                format!("{against} read against the nominal model's")
            },
            holding.len(),
            self.cases.len()
        );
        // Each reading on the cars that hide the effect (with what they hide) and on those
        // that hide nothing it could be read as.
        let split = |has: fn(&generator::Truth) -> f64,
                     clean: fn(&generator::Truth) -> bool,
                     reading: fn(&super::signature::Signature) -> f64| {
            let with: Vec<(f64, f64)> = holding
                .iter()
                .filter(|(t, _)| has(t) > 0.0)
                .map(|(t, g)| (reading(g), has(t)))
                .collect();
            let without: Vec<f64> = holding
                .iter()
                .filter(|(t, _)| clean(t))
                .map(|(_, g)| reading(g))
                .collect();
            (with, without)
        };
        let (with_play, without_play) = split(
            |t| t.belt_play_deg,
            |t| t.belt_play_deg == 0.0,
            |g| g.belt_play_deg,
        );
        s.push_str(&balance_line(
            "play in the belt",
            "deg",
            2,
            &with_play,
            "play",
            &without_play,
            "without it",
        ));
        s.push_str(&self.play_sizes());
        let (with_friction, neither) = split(
            |t| t.rack_friction_n,
            |t| t.rack_friction_n == 0.0 && t.dahl_force_n == 0.0,
            |g| g.rack_coulomb_n,
        );
        s.push_str(&balance_line(
            "Coulomb force at the rack",
            "N",
            0,
            &with_friction,
            "rack friction",
            &neither,
            "with neither friction nor a tyre",
        ));
        s
    }

    /// The play's size two ways on the cars named right with play that hide it and whose
    /// balance holds: as the verdict fitted it and as the torque balance read it, each as a
    /// range of shares of what the car hides and a median error. Empty where no case has all.
    fn play_sizes(&self) -> String {
        let pairs: Vec<(f64, f64)> = self
            .cases
            .iter()
            .filter(|r| r.correct)
            .filter_map(|r| {
                let hidden = r.case.truth.as_ref()?.truth.belt_play_deg;
                let (_, fitted) = r.fitted.as_ref()?.play_deg()?;
                let balance = r.signature.as_ref().filter(|g| g.holds)?.belt_play_deg;
                (hidden > 0.0).then_some((fitted / hidden, balance / hidden))
            })
            .collect();
        if pairs.is_empty() {
            return String::new();
        }
        let shares = |pick: fn(&(f64, f64)) -> f64| -> String {
            let mut v: Vec<f64> = pairs.iter().map(pick).collect();
            v.sort_by(f64::total_cmp);
            let mut errors: Vec<f64> = v.iter().map(|x| (x - 1.0).abs()).collect();
            errors.sort_by(f64::total_cmp);
            format!(
                "x{:.2}-{:.2} of what they hide (median error {:.0} %)",
                v[0],
                v[v.len() - 1],
                100.0 * errors[errors.len() / 2]
            )
        };
        format!(
            "  the play's size where a car with play was named right ({} logs): as fitted {}; \
             as the balance reads it {}\n",
            pairs.len(),
            shares(|p| p.0),
            shares(|p| p.1)
        )
    }
}

/// One line of [`SelftestReport::balance_summary`]: the range read on the cars with the effect
/// (each as read and as a share of what it hides) and the largest magnitude on those without.
fn balance_line(
    what: &str,
    unit: &str,
    decimals: usize,
    with: &[(f64, f64)],
    effect: &str,
    without: &[f64],
    without_label: &str,
) -> String {
    let range = |v: &mut dyn Iterator<Item = f64>| {
        v.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), x| {
            (lo.min(x), hi.max(x))
        })
    };
    let mut s = format!("  {what}:");
    if with.is_empty() {
        s.push_str(&format!(" no car with {effect}"));
    } else {
        let (lo, hi) = range(&mut with.iter().map(|&(r, _)| r));
        let (rlo, rhi) = range(&mut with.iter().map(|&(r, h)| r / h));
        s.push_str(&format!(
            " {lo:.decimals$}-{hi:.decimals$} {unit} on the {} cars with {effect} \
             (x{rlo:.2}-{rhi:.2} of what they hide)",
            with.len()
        ));
    }
    if !without.is_empty() {
        let worst = without.iter().fold(0.0_f64, |m, x| m.max(x.abs()));
        s.push_str(&format!(
            "; at most {worst:.decimals$} {unit} from zero on the {} {without_label}",
            without.len()
        ));
    }
    s.push('\n');
    s
}

/// The options the selftest uses by default: those `host-sim gap FILE` diagnoses a log of the
/// paper rig with (its candidates, its fits), so the selftest's figures are the tool's.
pub fn default_options() -> Options {
    Options {
        effects: EffectKind::PAPER.to_vec(),
        ..Options::default()
    }
}

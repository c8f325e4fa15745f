//! The `gap` and `identify` subcommands: arguments and what they print and write.

use super::columns::ColumnSigns;
use super::drive::{CarChoice, LogHeader, controller_from_name};
use super::rig::CarDrive;
use super::rig::{LoadedLog, Rig};
use super::{EffectKind, Options, diagnose, selftest};
use crate::report_html::{HtmlReport, num};
use crate::sim::Controller;
use clap::Args;
use std::path::{Path, PathBuf};
use std::time::Instant;

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

#[derive(Args, Debug)]
#[command(disable_help_flag = true)]
pub struct GapArgs {
    /// The log (rig's CSV columns, .csv or .csv.gz, any rate with a row every reference
    /// period); or `selftest`, or `bench`.
    #[arg(value_name = "LOG", required_unless_present = "help")]
    pub log: Option<PathBuf>,
    /// Print help (`gap selftest --help`: the selftest's own options).
    #[arg(short, long)]
    pub help: bool,
    /// A second log, checked with the parameters fitted on LOG only.
    #[arg(long, value_name = "LOG2")]
    pub validate: Option<PathBuf>,
    /// Rig file (JSON, see host-sim/rigs/); `paper` (default), `emps` and `bam` are built in.
    #[arg(long, value_name = "paper|emps|bam|FILE")]
    pub rig: Option<PathBuf>,
    /// Refit Table 4 to LOG first (`identify`) and diagnose against that model.
    #[arg(long)]
    pub refit_linear: bool,
    /// Write the figures as JSON.
    #[arg(long, value_name = "PATH")]
    pub json: Option<PathBuf>,
    /// Write the pictures (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
    /// Write one self-contained HTML file: the command line, rig and log, the figures as a
    /// table and the pictures inline (nothing fetched from the network).
    #[arg(long, value_name = "HTML")]
    pub report: Option<PathBuf>,
    /// Candidate effects, comma-separated (default: every candidate of the rig).
    #[arg(long, value_delimiter = ',', value_name = "LIST")]
    pub effects: Vec<String>,
    /// Worker threads (default: all cores).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// selftest: number of cases.
    #[arg(long, default_value_t = 50)]
    pub cases: usize,
    /// selftest: run only these cases of the seed (comma-separated indices, as the run
    /// printed them), e.g. to look again at a miss.
    #[arg(long = "case", value_delimiter = ',', value_name = "I,...")]
    pub case: Vec<usize>,
    /// selftest: seed.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// selftest: seconds per sweep (the independent world's tracks are 120 s).
    #[arg(long, default_value_t = 12.0)]
    pub duration_s: f64,
    /// selftest: draw the logs from the diagnosis's own model instead of the independent
    /// world (a check of the search, not of the model).
    #[arg(long)]
    pub model_world: bool,
    /// selftest: the independent world's cars with an effect no candidate has (the torque
    /// constant x0.7-0.8 or x1.25-1.4, a current sensor offset of 0.3-0.6 A, cogging of
    /// 0.01-0.03 Nm, the column encoder's zero 0.26-0.97 deg off), each right when answered
    /// `unexplained` or `parameters`.
    #[arg(long, conflicts_with = "model_world")]
    pub unmodelled: bool,
    /// selftest: diagnose each car from the files of these loggers, as `gap FILE` reads them
    /// (ours always, first): `ours`, `drawn` (a team's logger drawn with each case), or
    /// `ending|starting-RATE[-jitter][-drop][-instant][-held][-negcurrent|-negref]` (RATE in
    /// Hz, 100-1000, dividing 20000; `-instant`: the current sampled at each row's instant,
    /// not its interval's mean; `-held`: each row holding the car's last 100 Hz status frame;
    /// `-negcurrent`, `-negref`: the current or the reference written with the other sign);
    /// or the world's EPOS4 car (its own drive at 25 kHz / 2.5 kHz) as
    /// `epos4-convert` (steer-can convert's rows and header) or
    /// `epos4-status[-jitter][-drop][-negcurrent|-negref]` (a row as each TPDO arrives, no
    /// header), either with
    /// `-drift` after `epos4-convert`/`epos4-status` (the car's ECU on a clock of its own,
    /// 20-100 ppm off the vehicle computer's: its SYNC grid walks); bare `--loggers`
    /// is `drawn`. Prints per logger the verdicts right, those changed against ours, the
    /// confusion matrix. With `--drive` / `--controller` the car is given, as to `gap FILE`.
    #[arg(long, value_delimiter = ',', num_args = 0.., default_missing_value = "drawn", value_name = "LIST")]
    pub loggers: Option<Vec<String>>,
    /// selftest with `--loggers`: keep each logger's file of each case in this directory
    /// (`case16-epos4-status-drift.csv`), to look at a miss again with `gap FILE`.
    #[arg(long, value_name = "DIR", requires = "loggers")]
    pub keep_logs: Option<PathBuf>,
    /// The car's drive (paper rig): an EPOS4 over CANopen, or the ECU's own bridge. Default:
    /// the log's `# drive:` line, else the drive whose nominal model the log supports.
    #[arg(long, value_name = "epos4|direct")]
    pub drive: Option<String>,
    /// The ECU's steering controller (paper rig). Default: the log's `# controller:` line,
    /// else the one whose nominal model the log supports.
    #[arg(long, value_name = "paper|ecu")]
    pub controller: Option<String>,
}

#[derive(Args, Debug)]
pub struct IdentifyArgs {
    /// The log (project log format, .csv or .csv.gz).
    #[arg(value_name = "LOG")]
    pub log: PathBuf,
    /// Rig file; must be a paper-type rig.
    #[arg(long, value_name = "FILE")]
    pub rig: Option<PathBuf>,
    /// LM iterations.
    #[arg(long, default_value_t = 12)]
    pub iterations: usize,
    /// Write the fitted parameters as JSON.
    #[arg(long, value_name = "PATH")]
    pub json: Option<PathBuf>,
}

/// A log on the rig's grid; what the reader had to fill in (missing samples) goes to stderr, so
/// the figures are never computed on a repaired log without a word.
fn load_log(rig: &Rig, path: &Path) -> Result<super::Record> {
    load_log_with_header(rig, path).map(|(loaded, _)| loaded.record)
}

/// [`load_log`] with what the log's header lines say of the car.
fn load_log_with_header(rig: &Rig, path: &Path) -> Result<(LoadedLog, LogHeader)> {
    let loaded = rig.load_log(path)?;
    for note in &loaded.notes {
        eprintln!("warning: {note}");
    }
    let header =
        LogHeader::parse(&loaded.comments).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok((loaded, header))
}

/// The car to diagnose against: the options, else the log's header, else fitted
/// ([`super::drive::choose`]). A header that disagrees with an option is the option's.
fn car_for(
    args: &GapArgs,
    rig: &Rig,
    loaded: &LoadedLog,
    header: &LogHeader,
    opts: &Options,
) -> Result<(Rig, super::Record, Option<CarChoice>)> {
    let rec = &loaded.record;
    let (drive, controller) = car_options(args)?;
    if !matches!(rig.model, super::rig::RigModel::Paper(_)) {
        if args.drive.is_some() || args.controller.is_some() {
            return Err(format!(
                "--drive / --controller apply to the paper rig, not `{}`",
                rig.name
            )
            .into());
        }
        return Ok((rig.clone(), rec.clone(), None));
    }
    let (rig, rec, choice) =
        super::drive::choose_for_log(rig, loaded, header, drive, controller, opts);
    refuse_columns(
        choice.as_ref().and_then(|c| c.columns.as_ref()),
        &args
            .log
            .as_deref()
            .map_or(String::new(), |p| format!("{}: ", p.display())),
    )?;
    Ok((rig, rec, choice))
}

/// A log whose columns cannot be diagnosed as logged ([`ColumnSigns::refusal`]: one in
/// another unit than its reference, a current not in amperes), refused after `named`.
fn refuse_columns(columns: Option<&ColumnSigns>, named: &str) -> Result<()> {
    match columns.and_then(ColumnSigns::refusal) {
        Some(why) => Err(format!("{named}{why}").into()),
        None => Ok(()),
    }
}

/// `--drive` and `--controller`, read.
fn car_options(args: &GapArgs) -> Result<(Option<CarDrive>, Option<Controller>)> {
    let drive = match &args.drive {
        Some(d) => Some(
            CarDrive::from_name(d)
                .ok_or_else(|| format!("--drive {d:?}: expected `epos4` or `direct`"))?,
        ),
        None => None,
    };
    let controller = match &args.controller {
        Some(c) => Some(
            controller_from_name(c)
                .ok_or_else(|| format!("--controller {c:?}: expected `paper` or `ecu`"))?,
        ),
        None => None,
    };
    Ok((drive, controller))
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(())
}

fn options(args: &GapArgs, rig: &Rig) -> Result<Options> {
    let mut opts = Options {
        effects: EffectKind::for_rig(rig),
        progress: true,
        ..Options::default()
    };
    if let Some(t) = args.threads {
        opts.threads = t.max(1);
    }
    if !args.effects.is_empty() {
        opts.effects = args
            .effects
            .iter()
            .map(|n| {
                EffectKind::from_name(n.trim()).ok_or_else(|| {
                    format!(
                        "--effects: unknown effect {n:?} (backlash, backlash_belt, coulomb_friction, coulomb_friction_rack, delay, \
                         tire_ground, tire_ground_dahl, supply_sag)"
                    )
                })
            })
            .collect::<std::result::Result<_, _>>()?;
    }
    Ok(opts)
}

/// The help of `gap`, or with LOG `selftest` the selftest's options alone (clap cannot tell a
/// positional value from a subcommand, so `gap selftest --help` is answered here).
fn print_help(selftest: bool) -> Result<()> {
    let own = [
        "cases",
        "case",
        "seed",
        "duration_s",
        "model_world",
        "unmodelled",
        "loggers",
        "keep_logs",
        "drive",
        "controller",
        "threads",
        "json",
        "help",
    ];
    let mut cmd = GapArgs::augment_args(clap::Command::new("host-sim gap"))
        .about(
            "Sim-to-real gap of a log: where it lies, which unmodelled effect causes it, how far \
             it shrinks. `gap selftest` checks the diagnosis on logs with a withheld effect \
             (`gap selftest --help`); `gap bench` times three 120 s logs (ours; a team's of the \
             EPOS4 car without a header; a team's of a direct-drive car with friction, whose two \
             drives are screened) and a 30 min log's stamps placed on their grid",
        )
        .override_usage("host-sim gap [OPTIONS] <LOG>");
    if selftest {
        cmd = cmd
            .name("host-sim gap selftest")
            .about(
                "The diagnosis checked on logs with a withheld effect; prints the confusion table",
            )
            .mut_args(|a| {
                let theirs = !own.contains(&a.get_id().as_str());
                a.hide(theirs)
            })
            .override_usage("host-sim gap selftest [OPTIONS]");
    }
    print!("{}", cmd.render_help());
    Ok(())
}

pub fn gap(args: &GapArgs) -> Result<()> {
    let Some(log) = args.log.as_deref().filter(|_| !args.help) else {
        return print_help(args.log.as_deref() == Some(Path::new("selftest")));
    };
    match log.to_str() {
        // Neither has a diagnosis of one log to report; refused rather than silently ignored.
        Some(mode @ ("selftest" | "bench")) if args.report.is_some() => {
            return Err(format!("--report: `gap {mode}` has no page; it applies to a log").into());
        }
        Some("selftest") => return selftest_cmd(args),
        Some("bench") => return bench_cmd(args),
        _ => {}
    }
    let rig = match &args.rig {
        Some(p) => Rig::load(p)?,
        None => Rig::paper(),
    };
    let (loaded, header) = load_log_with_header(&rig, log)?;
    let timing = loaded.timing;
    let val = match &args.validate {
        Some(p) => {
            let (v, _) = load_log_with_header(&rig, p)?;
            // Its columns' units by the log's rules: a current in milliamperes beside the
            // log's amperes would make every candidate fail its validation.
            refuse_columns(
                super::columns::read(&rig, &v.record).as_ref(),
                &format!("{} (--validate): ", p.display()),
            )?;
            Some(v)
        }
        None => None,
    };
    let opts = options(args, &rig)?;
    let (rig, rec, car) = car_for(args, &rig, &loaded, &header, &opts)?;
    let mut rig = rig;
    // The validation log is the same car's, written by the same logger.
    let shift = car
        .as_ref()
        .and_then(|c| c.reference_shift_rows)
        .unwrap_or(0);
    let columns = car.as_ref().and_then(|c| c.columns);
    // Its convention is the log's: at the reference rate its reference moved as the log's, at
    // several rows a period read that way where its rows leave it open.
    let val = val.map(|v| {
        let placed = car
            .as_ref()
            .and_then(|c| c.reference_shift_rows)
            .and(v.by_convention);
        let (v, shift) = match placed {
            Some(both) => (both[shift.min(1)].clone(), 0),
            None => (v.record, shift),
        };
        let v = match columns {
            Some(c) => c.apply(&v),
            None => v,
        };
        super::drive::shifted_reference(&v, shift)
    });
    // The validation log's own stretches where its column is a row off the drive's latch (its
    // crossings are its own).
    let (val, val_windows) = match (val, &car) {
        (Some(v), Some(c)) if c.may_lead_the_latch() => {
            let (v, w) = super::reference_window::fit(&rig, &v, opts.threads);
            (Some(v), w)
        }
        (v, _) => (v, Vec::new()),
    };
    // What the diagnosis took the car and the log to be: printed first, and on the page.
    let mut preamble = String::new();
    if let Some(car) = &car {
        preamble.push_str(&format!("{}\n", car.describe()));
    }
    for w in &val_windows {
        preamble.push_str(&format!("validation log: {}\n", w.describe()));
    }
    preamble.push_str(&format!(
        "log timing: {} rows {:.2} ms apart, stamp jitter {:.2} ms RMS, {} rows missing\n",
        timing.rows,
        1e3 * timing.row_dt_s,
        1e3 * timing.jitter_s,
        timing.missing_rows
    ));
    print!("{preamble}");
    let mut refit = None;
    if args.refit_linear {
        let id = super::identify::identify(&rig, &rec, 10, true)?;
        super::identify::apply(&mut rig, &id);
        refit = Some(id);
    }
    let mut d = diagnose(&rig, &rec, val.as_ref(), &opts);
    d.refit_linear = refit;
    let car = car.map(|c| c.on_the_clock_of(&d));
    if let Some(r) = &d.clock_refit {
        r.apply(&mut rig);
    }
    // The drive's clock, fitted again with the best candidate in the model, moved: the car
    // line again, so the report says which clock its figures are on.
    let mut summary = String::new();
    if let Some(car) = car.as_ref().filter(|c| c.clock_refitted.is_some()) {
        summary.push_str(&format!("{}\n", car.describe()));
    }
    summary.push_str(&d.summary());
    let window = car.as_ref().and_then(|c| c.late_reference_window_ms(&d));
    if let (Some((from, to)), Some(c)) = (window, &car) {
        summary.push_str(&format!(
            "  an EPOS4 car latches a late frame at the first SYNC after it arrives: the log fixes \
             that latch, {to:.1} ms after each reference sample (the SYNC {:.2} ms plus the \
             delay fitted), not the frames' own delay, which any arrival after {from:.1} ms and \
             up to {to:.1} ms gives alike\n",
            1e3 * c.sync_after_push_s.unwrap_or(f64::NAN)
        ));
    }
    print!("{summary}");
    let mut json = d.to_json();
    if let Some(car) = &car {
        json["car"] = serde_json::to_value(car)?;
    }
    if let Some((from, to)) = window {
        json["late_reference_window_ms"] = serde_json::json!([from, to]);
    }
    json["log_timing"] = serde_json::to_value(timing)?;
    if let Some(path) = &args.json {
        write_json(path, &json)?;
    }
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
        let files = super::plots::write_all(&rig, &rec, &d, dir)?;
        for f in files {
            println!("wrote {}", f.display());
        }
    }
    if let Some(path) = &args.report {
        let printed = format!("{preamble}{summary}");
        report_html(args, log, &rig, &rec, &d, &json, &printed).save(path)?;
        println!("report written to {}", path.display());
    }
    Ok(())
}

/// The diagnosis as one HTML page: the figures of the summary's first and last lines, the
/// ranking, the printed summary and the pictures.
fn report_html(
    args: &GapArgs,
    log: &Path,
    rig: &Rig,
    rec: &super::Record,
    d: &super::Diagnosis,
    json: &serde_json::Value,
    summary: &str,
) -> HtmlReport {
    let mut page = HtmlReport::new(&format!(
        "host-sim gap: {}, rig {}",
        log.display(),
        rig.name
    ))
    .setup("log", &log.display().to_string())
    .setup("rig", &rig.name)
    .setup(
        "model",
        if args.refit_linear {
            "Table 4 refitted to the log first (--refit-linear)"
        } else {
            "the rig's nominal model"
        },
    );
    if let Some(v) = &args.validate {
        page = page.setup("validation log", &v.display().to_string());
    }
    let ranking = d
        .ranking
        .iter()
        .map(|c| {
            vec![
                c.effect.clone(),
                format!("{:.1}", 100.0 * c.gof),
                c.gof_validation
                    .map_or("-".to_string(), |g| format!("{:.1}", 100.0 * g)),
                c.params
                    .iter()
                    .map(|(k, v)| format!("{k}={v:.4}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            ]
        })
        .collect();
    page = page
        .numbers(
            json,
            &[
                num("log length", "/duration_s", "s").decimals(1),
                num("simulations", "/simulations", "").decimals(0),
                num("nominal GoF", "/baseline_gof", "%").percent(),
                num("nominal GoF, output", "/baseline/gof_output", "%").percent(),
                num("nominal GoF, effort", "/baseline/gof_effort", "%").percent(),
                num("nominal cost", "/baseline_cost", "").decimals(3),
                num("noise-floor cost", "/noise_floor_cost", "").decimals(0),
            ],
        )
        .text("where: segment", json, "/where/segment", "-")
        .text("where: signal", json, "/where/signal", "-")
        .text("verdict", json, "/verdict/kind", "-")
        .text("verdict effects", json, "/verdict/effects", "none")
        .numbers(
            json,
            &[
                num("GoF with the verdict", "/verdict/gof_after", "%").percent(),
                num("validation GoF", "/verdict/gof_validation", "%").percent(),
            ],
        )
        .text("why", json, "/verdict/reason", "-")
        .table(
            "Candidates, ranked",
            &["effect", "GoF %", "validation GoF %", "parameters"],
            ranking,
        )
        .printed(summary);
    for picture in super::plots::pictures(rig, rec, d) {
        page = page.figure(picture.caption, &picture.svg);
    }
    page
}

fn selftest_cmd(args: &GapArgs) -> Result<()> {
    let mut opts = selftest::default_options();
    if let Some(t) = args.threads {
        opts.threads = t.max(1);
    }
    let started = Instant::now();
    let world = if args.model_world {
        selftest::World::Model
    } else if args.unmodelled {
        selftest::World::Unmodelled
    } else {
        selftest::World::Independent
    };
    let indices: Vec<usize> = if args.case.is_empty() {
        (0..args.cases).collect()
    } else {
        args.case.clone()
    };
    let print_case = |r: &selftest::CaseResult| {
        eprintln!(
            "case {:3} {:<32}{} hidden {:<28} named {:<28} {}  GoF {:5.1} -> {:5.1} %",
            r.case.index,
            r.case.scenario,
            r.logger.as_ref().map_or(String::new(), |l| format!(
                " logger {:<26}",
                l.logger.describe()
            )),
            selftest::label(&r.case.hidden),
            selftest::label(&r.named),
            if r.correct { "ok " } else { "MISS" },
            100.0 * r.gof_before,
            100.0 * r.gof_after
        );
        if !r.correct {
            eprintln!("         {}", r.reason);
        }
    };
    let (table, json) = if let Some(names) = &args.loggers {
        if args.model_world {
            return Err(
                "--loggers: the loggers write the independent world's cars, not the model world's"
                    .into(),
            );
        }
        let kinds = names
            .iter()
            .map(|n| selftest::LoggerKind::parse(n))
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let report = selftest::run_loggers(
            &kinds,
            car_options(args)?,
            selftest::Cars {
                world,
                cases: &indices,
                seed: args.seed,
                duration_s: args.duration_s,
            },
            &opts,
            args.keep_logs.as_deref(),
            &print_case,
        )?;
        (report.table(), serde_json::to_value(&report)?)
    } else {
        if args.drive.is_some() || args.controller.is_some() {
            return Err(
                "--drive / --controller: the selftest gives the car only with --loggers".into(),
            );
        }
        let report = selftest::run(
            world,
            &indices,
            args.seed,
            args.duration_s,
            &opts,
            &print_case,
        );
        (
            format!("{}{}", report.confusion_table(), report.balance_summary()),
            serde_json::to_value(&report)?,
        )
    };
    print!("{table}");
    println!("{:.1} s", started.elapsed().as_secs_f64());
    if let Some(path) = &args.json {
        write_json(path, &json)?;
    }
    Ok(())
}

fn bench_cmd(args: &GapArgs) -> Result<()> {
    let rig = Rig::paper();
    let mut fx = super::model::Effects::nominal();
    fx.coulomb = 0.12;
    let case = selftest::Case {
        index: 0,
        scenario: "built-in 120 s track, Coulomb 0.12 Nm".into(),
        hidden: vec!["coulomb_friction".into()],
        effects: fx,
        reference: crate::scenario::builtin_track(),
    };
    let rec = selftest::record_of(&rig, &case, 7);
    let mut opts = options(args, &rig)?;
    opts.progress = false;
    let started = Instant::now();
    let d = diagnose(&rig, &rec, None, &opts);
    let elapsed = started.elapsed().as_secs_f64();
    println!(
        "gap bench: {:.0} s log ({}), {} simulations, diagnosed in {:.1} s on {} thread(s); verdict {:?}",
        rec.duration_s(),
        case.scenario,
        d.simulations,
        elapsed,
        opts.threads,
        d.verdict.effects
    );
    bench_team_log(args)?;
    bench_screened_log(args)?;
    bench_long_stamps();
    Ok(())
}

/// The stamps of a 30 min log at 1 kHz as a receiver stamps them (+-1 ms, in order, 1 % of
/// rows lost at random), placed on their grid: the rows' order places them
/// (`record::places_by_order`), whose cost must grow with the rows, not the rows times
/// the rows lost.
fn bench_long_stamps() {
    let rows = 1_800_000;
    let (t, lost) = super::record::receiver_stamps(rows, 1e-3, 1e-3, 0.01, 7);
    let started = Instant::now();
    let timing = super::LogTiming::of(&t);
    println!(
        "gap bench: a 30 min log's stamps at 1 kHz (+-1 ms, {} of {rows} rows lost) placed on \
         their grid in {:.2} s: {} rows missing, {}",
        lost.len(),
        started.elapsed().as_secs_f64(),
        timing.missing_rows,
        if timing.on_grid {
            "on the grid"
        } else {
            "not placed"
        }
    );
}

/// The bench's second log, a team's file at its commonest: the independent world's EPOS4 car
/// (exact Table 4, no effect) on the same 120 s track, written a row per TPDO as a team's
/// logger of the status frames writes it (no header, stamps +-1 ms, 1 % of rows lost).
fn bench_team_log(args: &GapArgs) -> Result<()> {
    use super::generator::{GenCase, LoggedCar};
    let case = GenCase::nominal(crate::scenario::builtin_track(), 100);
    let logger = team_logger(LoggedCar::Epos4StatusFrame);
    bench_file(args, &case, &logger, "the EPOS4 car's 120 s track")
}

/// A team's 100 Hz logger of `car`: no header, stamps +-1 ms, 1 % of rows lost.
fn team_logger(car: super::generator::LoggedCar) -> super::generator::Logger {
    use super::generator::{self, Logger};
    Logger {
        car,
        header: false,
        jitter_s: generator::LOGGER_JITTER_S,
        drop_chance: generator::LOGGER_DROP_CHANCE,
        ..Logger::ours(100)
    }
}

/// The bench's third log, the slowest path a team's file takes: the independent world's
/// direct-drive car with 300 N of friction at the rack on the same track, written by a team's
/// 100 Hz logger (no header, stamps +-1 ms, 1 % of rows lost), whose two drives' nominal
/// models come close, so that both are screened by their candidates before the diagnosis.
fn bench_screened_log(args: &GapArgs) -> Result<()> {
    use super::generator::{GenCase, LoggedCar};
    let mut case = GenCase::nominal(crate::scenario::builtin_track(), 100);
    case.truth.rack_friction_n = 300.0;
    case.hidden = vec!["coulomb_friction".into()];
    let logger = team_logger(LoggedCar::Direct);
    bench_file(
        args,
        &case,
        &logger,
        "the direct drive's 120 s track, 300 N of rack friction",
    )
}

/// `case` written by `logger` to a file, and diagnosed as `host-sim gap FILE` does, the car's
/// drive fitted first; timed from reading the file to the verdict.
fn bench_file(
    args: &GapArgs,
    case: &super::generator::GenCase,
    logger: &super::generator::Logger,
    what: &str,
) -> Result<()> {
    eprintln!("gap bench: writing {what} as a team's logger writes it ...");
    let log = super::generator::log_of(case, 7, logger);
    let path = std::env::temp_dir().join(format!("gap-bench-{}.csv", std::process::id()));
    log.save(&path)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    let rig = Rig::paper();
    let mut opts = options(args, &rig)?;
    opts.progress = false;
    let started = Instant::now();
    let loaded = load_log_with_header(&rig, &path);
    // The file is the bench's own; it goes whatever the diagnosis makes of it.
    let _ = std::fs::remove_file(&path);
    let (loaded, header) = loaded?;
    let timing = loaded.timing;
    let (rig, rec, car) = car_for(args, &rig, &loaded, &header, &opts)?;
    let d = diagnose(&rig, &rec, None, &opts);
    let elapsed = started.elapsed().as_secs_f64();
    println!(
        "gap bench: {:.0} s log ({what}; {}, {} rows), read, car fitted and diagnosed in {:.1} \
         s on {} thread(s), {} simulations; {}; verdict {:?}",
        rec.duration_s(),
        logger.describe(),
        timing.rows,
        elapsed,
        opts.threads,
        d.simulations,
        car.map_or("no car".into(), |c| format!(
            "{} drive{}",
            c.drive.name(),
            if c.screened.is_some() {
                ", both drives screened"
            } else {
                ""
            }
        )),
        d.verdict.effects
    );
    Ok(())
}

pub fn identify(args: &IdentifyArgs) -> Result<()> {
    let rig = match &args.rig {
        Some(p) => Rig::load(p)?,
        None => Rig::paper(),
    };
    let rec = load_log(&rig, &args.log)?;
    // A column the logger wrote with the other sign, read as the car has it, as `gap` reads it.
    let columns = super::columns::read(&rig, &rec);
    refuse_columns(columns.as_ref(), &format!("{}: ", args.log.display()))?;
    let rec = match columns.map(|c| (c.describe(), c)) {
        Some((said, c)) if !said.is_empty() => {
            println!("columns: {said}");
            c.apply(&rec)
        }
        _ => rec,
    };
    let id = super::identify::identify(&rig, &rec, args.iterations, true)?;
    print!("{}", id.summary());
    if let Some(path) = &args.json {
        write_json(path, &serde_json::to_value(&id)?)?;
    }
    Ok(())
}

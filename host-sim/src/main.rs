//! `host-sim`: the paper's steering actuator simulated under the firmware's control code.
//!
//! Subcommands: `poles`, `limits`, `sweep`, `track`, `step`, `bench`, `gap` (sim-to-real gap
//! diagnosis of a log, `gap selftest`, `gap bench`) and `identify` (Table 4 from a log). Each prints a
//! readable summary; `--json PATH` writes its figures, `--log PATH` the run's log (CSV,
//! `.csv.gz` compressed), `--plots DIR` its pictures (SVG), `--report PATH` all of it as one
//! self-contained HTML page (`sweep`, `track`, `step`, `gap`).

use clap::{Args, Parser, Subcommand};
use host_sim::analysis::FrequencyResponse;
use host_sim::effect_plant::PlantEffects;
use host_sim::linear_model::{LimitedBy, LinearModel, MINUS_3_DB, Output, PhysicalLimit};
use host_sim::logfmt::Log;
use host_sim::plant::PlantParams;
use host_sim::plot::{BodePlot, Panel, Style, TimePlot};
use host_sim::report::{self, SweepReport, TrackReport};
use host_sim::report_html::{HtmlReport, Num, num};
use host_sim::scenario::{self, Sweep};
use host_sim::sim::{Controller, Run, RunConfig};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;
use steering_ecu::control::AntiWindup;
use steering_ecu::ecu_mode::EcuTuning;
use steering_ecu::gains::EposGains;

#[derive(Parser, Debug)]
#[command(
    name = "host-sim",
    version,
    about = "The paper's steering actuator (Manca et al. 2021) under the ECU's own control code"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Eigenvalues of the linear plant (eqs. 5-8, Tables 1, 2, 4) against the paper's, and of the
    /// paper-mode closed loop with the position loop's gain and phase margins (linear model).
    Poles {
        #[arg(long, value_name = "PATH")]
        json: Option<PathBuf>,
    },
    /// What the paper plant allows whatever the controller (issue 14): the current and voltage
    /// a sinusoidal pinion angle needs, the largest amplitude within 20 A and the supply, and
    /// the bound this puts on a sweep's -3 dB bandwidth.
    Limits {
        /// Sweep amplitude at the wheel; the table is for its -3 dB point, deg.
        #[arg(long, default_value_t = 10.0, value_name = "DEG")]
        amplitude_deg: f64,
        /// Supply (battery) voltage, the voltage limit, V.
        #[arg(long, default_value_t = 24.0, value_name = "V")]
        supply_v: f64,
        #[arg(long, value_name = "PATH")]
        json: Option<PathBuf>,
    },
    /// Sine sweep at the wheel (section 4.2: 0-10 Hz, 10 s, 10 deg): frequency response and
    /// -3 dB bandwidth.
    Sweep {
        #[arg(long, default_value_t = 10.0, value_name = "DEG")]
        amplitude_deg: f64,
        #[arg(long, default_value_t = 10.0, value_name = "HZ")]
        f_end_hz: f64,
        #[arg(long, default_value_t = 10.0, value_name = "S")]
        duration_s: f64,
        #[command(flatten)]
        common: Common,
    },
    /// A driverless track run (section 4.4): the built-in 120 s profile or a CSV `t,ref_sw_deg`.
    Track {
        /// The reference, CSV `t,ref_sw_deg` (s, deg; plain or gzip; any rate, further columns
        /// ignored, so a project log works); the built-in 120 s profile without it.
        #[arg(long, value_name = "CSV")]
        csv: Option<PathBuf>,
        #[command(flatten)]
        common: Common,
    },
    /// A step at the wheel.
    Step {
        /// Height of the step at the steering wheel, deg.
        #[arg(long, default_value_t = 20.0, value_name = "DEG")]
        amplitude_deg: f64,
        /// Length of the run, s.
        #[arg(long, default_value_t = 1.5, value_name = "S")]
        duration_s: f64,
        #[command(flatten)]
        common: Common,
    },
    /// Realtime factor of the 120 s track at full rates (20 kHz / 2 kHz / 100 Hz), one thread.
    Bench {
        /// Runs to time (each with and without the 1 kHz log); the median is reported.
        #[arg(long, default_value_t = 5)]
        repeats: u32,
        /// Write the figures as JSON.
        #[arg(long, value_name = "PATH")]
        json: Option<PathBuf>,
    },
    /// Sim-to-real gap of a log: where it lies, which unmodelled effect causes it, how far it
    /// shrinks. `gap selftest` checks the diagnosis on logs with a withheld effect; `gap bench`
    /// times a 120 s log.
    Gap(host_sim::gap::cli::GapArgs),
    /// The nine parameters of Table 4 fitted to a log by nonlinear least squares (sec. 4.3).
    Identify(host_sim::gap::cli::IdentifyArgs),
    /// Golden vectors for the emulated Cortex-M4F suite (hil-tests/emulated): a sweep and a
    /// track window of the closed loop, and the codec and state-machine cases.
    Golden {
        /// Write the files into this directory (the stored ones: hil-tests/vectors).
        #[arg(long, value_name = "DIR")]
        write: PathBuf,
    },
}

#[derive(Args, Debug)]
struct Common {
    /// Write the figures as JSON.
    #[arg(long, value_name = "PATH")]
    json: Option<PathBuf>,
    /// Write the run's log (project log format; `.csv.gz` compresses).
    #[arg(long, value_name = "PATH")]
    log: Option<PathBuf>,
    /// Write the pictures (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    plots: Option<PathBuf>,
    /// Write one self-contained HTML file: the command line, controller and plant, the figures
    /// as a table and the pictures inline (nothing fetched from the network).
    #[arg(long, value_name = "HTML")]
    report: Option<PathBuf>,
    /// Log rate, Hz (a divisor of 2000).
    #[arg(long, default_value_t = 1000, value_name = "HZ")]
    log_rate_hz: u32,
    /// Feed the position loop the exact motor angle instead of the 84-count Hall angle.
    #[arg(long)]
    ideal_sensors: bool,
    /// Supply (battery) voltage, the voltage limit of the current loop, V.
    #[arg(long, default_value_t = 24.0, value_name = "V")]
    supply_v: f64,
    /// Integrate regardless of saturation (to see what anti-windup prevents).
    #[arg(long)]
    no_anti_windup: bool,
    /// The steering controller: the paper's EPOS4 cascade on the motor, or the ECU's own
    /// (inverse belt model, model feedforward, column integral; README "ECU mode").
    #[arg(long, value_enum, default_value_t = Controller::Paper)]
    controller: Controller,
    /// A rig file (as in host-sim/rigs/) whose `model.plant` replaces the paper's plant (Tables
    /// 1, 2, 4); the controller keeps its own tuning, so this is how its robustness is checked.
    #[arg(long, value_name = "FILE")]
    plant: Option<PathBuf>,
    /// Run without the current guard, the voltage clamp that holds the current within 20 A
    /// (to see the overshoot it prevents).
    #[arg(long)]
    no_current_guard: bool,
    /// Effects the linear plant leaves out, as KEY=VALUE[,...]: backlash_deg (play in the
    /// belt/nut, deg at the wheel), column_play_deg, coulomb_n (rack friction, N),
    /// coulomb_creep_mm_s (rack speed it builds up over, tanh; 0 = sharp), motor_coulomb_nm,
    /// motor_stribeck_nm, stribeck_rad_s, tire_n with tire_n_per_mm, tire_dahl.
    /// E.g. `--plant-effects backlash_deg=1.5,coulomb_n=200`.
    #[arg(long, value_name = "LIST", default_value = "")]
    plant_effects: PlantEffects,
}

impl Common {
    fn config(&self) -> Result<RunConfig> {
        if self.ideal_sensors && self.controller == Controller::Ecu {
            return Err(
                "--ideal-sensors applies to paper mode only: ECU mode times the Hall \
                        edges, so it always runs on the Hall sensors"
                    .into(),
            );
        }
        let plant = match &self.plant {
            None => PlantParams::PAPER,
            Some(path) => match host_sim::gap::rig::Rig::load(path)?.model {
                host_sim::gap::rig::RigModel::Paper(m) => m.plant,
                _ => {
                    return Err(format!(
                        "--plant {}: not a paper-kind rig (its model has no `plant`)",
                        path.display()
                    )
                    .into());
                }
            },
        };
        Ok(RunConfig {
            plant,
            hall_feedback: !self.ideal_sensors,
            anti_windup: if self.no_anti_windup {
                AntiWindup::Disabled
            } else {
                AntiWindup::ConditionalIntegration
            },
            log_rate_hz: self.log_rate_hz,
            supply_v: self.supply_v,
            controller: self.controller,
            current_guard: !self.no_current_guard,
            effects: self.plant_effects,
            ..RunConfig::default()
        })
    }
}

/// `println!` that ends the program quietly when stdout is closed (`host-sim ... | head`)
/// instead of panicking on the broken pipe.
macro_rules! say {
    ($($arg:tt)*) => {
        host_sim::out::stdout_line("host-sim", format_args!($($arg)*))
    };
}

type Result<T> = std::result::Result<T, Box<dyn std::error::Error>>;

fn main() -> ExitCode {
    let cli = Cli::parse();
    match dispatch(cli.command) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("host-sim: error: {e}");
            ExitCode::FAILURE
        }
    }
}

fn dispatch(command: Command) -> Result<()> {
    match command {
        Command::Poles { json } => poles(json.as_deref()),
        Command::Limits {
            amplitude_deg,
            supply_v,
            json,
        } => limits_cmd(amplitude_deg, supply_v, json.as_deref()),
        Command::Sweep {
            amplitude_deg,
            f_end_hz,
            duration_s,
            common,
        } => {
            let sweep = Sweep {
                amplitude_deg,
                f_start_hz: 0.0,
                f_end_hz,
                duration_s,
            };
            check_sweep(&sweep)?;
            sweep_cmd(&sweep, &common)
        }
        Command::Track { csv, common } => {
            let reference = match &csv {
                Some(path) => scenario::track_from_csv(path)?,
                None => scenario::builtin_track(),
            };
            let name = csv
                .as_ref()
                .map_or("built-in 120 s profile".to_string(), |p| {
                    p.display().to_string()
                });
            track_cmd(&reference, &name, &common)
        }
        Command::Step {
            amplitude_deg,
            duration_s,
            common,
        } => {
            if !(amplitude_deg.is_finite() && amplitude_deg.abs() <= 90.0) {
                return Err(
                    format!("--amplitude-deg {amplitude_deg}: must be within +-90 deg").into(),
                );
            }
            if !(duration_s.is_finite() && duration_s > 0.1 && duration_s <= 600.0) {
                return Err(format!("--duration-s {duration_s}: must be in (0.1, 600] s").into());
            }
            step_cmd(amplitude_deg, duration_s, &common)
        }
        Command::Bench { repeats, json } => bench(repeats.max(1), json.as_deref()),
        Command::Gap(args) => host_sim::gap::cli::gap(&args),
        Command::Identify(args) => host_sim::gap::cli::identify(&args),
        Command::Golden { write } => {
            for v in host_sim::golden::write(&write)? {
                say!("{}: {} B", write.join(v.name).display(), v.bytes.len());
            }
            Ok(())
        }
    }
}

fn check_sweep(s: &Sweep) -> Result<()> {
    if !(s.amplitude_deg.is_finite() && s.amplitude_deg > 0.0 && s.amplitude_deg <= 90.0) {
        return Err(format!(
            "--amplitude-deg {}: must be in (0, 90] deg (the steering range)",
            s.amplitude_deg
        )
        .into());
    }
    if !(s.f_end_hz.is_finite() && s.f_end_hz > 0.0 && s.f_end_hz <= 50.0) {
        return Err(format!(
            "--f-end-hz {}: must be in (0, 50] Hz (the 100 Hz reference's Nyquist limit)",
            s.f_end_hz
        )
        .into());
    }
    if !(s.duration_s.is_finite() && s.duration_s >= 4.0 && s.duration_s <= 600.0) {
        return Err(format!("--duration-s {}: must be in [4, 600] s", s.duration_s).into());
    }
    Ok(())
}

fn write_json(path: &Path, value: &serde_json::Value) -> Result<()> {
    if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
        std::fs::create_dir_all(dir).map_err(|e| format!("{}: {e}", dir.display()))?;
    }
    let text = serde_json::to_string_pretty(value)?;
    std::fs::write(path, text + "\n").map_err(|e| format!("{}: {e}", path.display()))?;
    say!("figures written to {}", path.display());
    Ok(())
}

fn save_log(log: &Log, common: &Common) -> Result<()> {
    if let Some(path) = &common.log {
        log.save(path)?;
        say!("log written to {} ({} rows)", path.display(), log.len());
    }
    Ok(())
}

fn save_svg(
    dir: &Path,
    name: &str,
    svg_save: impl FnOnce(&Path) -> std::io::Result<()>,
) -> Result<()> {
    let path = dir.join(name);
    svg_save(&path).map_err(|e| format!("{}: {e}", path.display()))?;
    say!("picture written to {}", path.display());
    Ok(())
}

fn poles(json: Option<&Path>) -> Result<()> {
    let params = PlantParams::PAPER;
    let mech = params.mechanical_poles();
    say!("Mechanical poles of eqs. 5-8 (Tables 2, 4; belt factor 1/2, eq. 6 with (tauBS/tauP)^2):");
    say!(
        "{:>12} {:>12} {:>10} {:>8} {:>7}",
        "re rad/s",
        "im rad/s",
        "|p| rad/s",
        "Hz",
        "zeta"
    );
    for p in &mech {
        let w = p.norm();
        let zeta = if w > 0.0 { -p.re / w } else { f64::NAN };
        say!(
            "{:>12.2} {:>12.2} {:>10.2} {:>8.2} {:>7.3}",
            p.re,
            p.im,
            w,
            w / std::f64::consts::TAU,
            zeta
        );
    }
    say!(
        "Paper (section 4.3): 0, -334 rad/s real, pairs at 30.9 rad/s (4.9 Hz) and 131 rad/s (20.9 Hz)."
    );
    let em = params.electromechanical_poles();
    say!(
        "With the winding (eq. 1) the fast pole is at {:.0} rad/s.",
        em.last().map_or(f64::NAN, |p| p.norm())
    );
    let model = LinearModel::new(params, &EposGains::PAPER)?;
    let closed = model.closed_loop_poles();
    say!("");
    say!(
        "Closed loop, paper mode (Table 3 gains; linear model: 20 kHz PI, 2 kHz PID + feedforward, \
         exact sensors, no limits), s = ln(z) / 0.5 ms:"
    );
    say!(
        "{:>12} {:>12} {:>10} {:>8} {:>7} {:>8}",
        "re rad/s",
        "im rad/s",
        "|s| rad/s",
        "Hz",
        "zeta",
        "|z|"
    );
    for p in &closed {
        say!(
            "{:>12.2} {:>12.2} {:>10.2} {:>8.2} {:>7.3} {:>8.4}",
            p.re,
            p.im,
            p.wn,
            p.f_hz,
            p.zeta,
            p.z_magnitude
        );
    }
    say!(
        "  {} (|z| < 1 for all). im = +-{:.0} rad/s marks a negative real z: a mode that \
         alternates sign every position tick.",
        if model.is_stable() {
            "stable"
        } else {
            "UNSTABLE"
        },
        std::f64::consts::PI * steering_ecu::paper_mode::POSITION_LOOP_HZ as f64
    );
    let margins = model.margins();
    say!("Position-loop margins (loop broken at the current set-point, 0.01 Hz to 1 kHz):");
    match (margins.gain_margin_db, margins.phase_crossover_hz) {
        (Some(gm), Some(f)) => say!("  gain margin   {gm:6.1} dB  at {f:7.2} Hz (phase -180 deg)"),
        _ => say!("  gain margin   none: the phase never crosses -180 deg with |L| < 1"),
    }
    match (margins.phase_margin_deg, margins.gain_crossover_hz) {
        (Some(pm), Some(f)) => say!("  phase margin  {pm:6.1} deg at {f:7.2} Hz (|L| = 1)"),
        _ => say!("  phase margin  none: |L| never crosses 1"),
    }
    let ecu_margins = model.ecu_margins(&EcuTuning::PAPER);
    say!(
        "ECU mode's loop (the same PID with the column fed back, D on the motor speed; \
         `--controller ecu`):"
    );
    match (ecu_margins.gain_margin_db, ecu_margins.phase_crossover_hz) {
        (Some(gm), Some(f)) => say!("  gain margin   {gm:6.1} dB  at {f:7.2} Hz (phase -180 deg)"),
        _ => say!("  gain margin   none: the phase never crosses -180 deg with |L| < 1"),
    }
    match (ecu_margins.phase_margin_deg, ecu_margins.gain_crossover_hz) {
        (Some(pm), Some(f)) => say!("  phase margin  {pm:6.1} deg at {f:7.2} Hz (|L| = 1)"),
        _ => say!("  phase margin  none: |L| never crosses 1"),
    }
    let log_rate = RunConfig::default().log_rate_hz;
    let bandwidth = model.bandwidth_hz(0.05, 50.0, log_rate);
    match bandwidth {
        Some(bw) => say!(
            "Small-signal -3 dB bandwidth of the column (linear model, as a {log_rate} Hz log \
             sees it): {bw:.2} Hz"
        ),
        None => say!("Small-signal -3 dB bandwidth of the column: above 50 Hz"),
    }
    if let Some(path) = json {
        let poles: Vec<_> = mech
            .iter()
            .map(|p| serde_json::json!({"re": p.re, "im": p.im}))
            .collect();
        let em: Vec<_> = em
            .iter()
            .map(|p| serde_json::json!({"re": p.re, "im": p.im}))
            .collect();
        write_json(
            path,
            &serde_json::json!({
                "poles": poles,
                "electromechanical_poles": em,
                "unit": "rad/s",
                "closed_loop_poles": closed,
                "closed_loop_stable": model.is_stable(),
                "margins": margins,
                "ecu_mode_margins": ecu_margins,
                "small_signal_bandwidth_hz": bandwidth,
            }),
        )?;
    }
    Ok(())
}

/// The physical limit of issue 14 for a run's plant and supply (20 A, as the cascade's limit).
fn physical_limit(cfg: &RunConfig) -> PhysicalLimit {
    PhysicalLimit {
        params: cfg.plant,
        voltage_limit_v: cfg.supply_v,
        ..PhysicalLimit::paper()
    }
}

/// A bound on the bandwidth as `host-sim` prints it: "  3.79 Hz", or "above 50 Hz" (the
/// reference's Nyquist limit, where `bandwidth_bound_hz` stops looking).
fn bound_text(bound_hz: Option<f64>) -> String {
    bound_hz.map_or("above 50 Hz".to_string(), |b| format!("{b:6.2} Hz"))
}

/// A bandwidth as a share of its bound: "61 %", or "-" when either is missing.
fn share_of_bound(bandwidth_hz: Option<f64>, bound_hz: Option<f64>) -> String {
    match (bandwidth_hz, bound_hz) {
        (Some(bw), Some(b)) if b > 0.0 => format!("{:.0} %", 100.0 * bw / b),
        _ => "-".to_string(),
    }
}

fn limits_cmd(amplitude_deg: f64, supply_v: f64, json: Option<&Path>) -> Result<()> {
    if !(amplitude_deg.is_finite() && amplitude_deg > 0.0 && amplitude_deg <= 90.0) {
        return Err(format!("--amplitude-deg {amplitude_deg}: must be in (0, 90] deg").into());
    }
    if !(supply_v.is_finite() && supply_v > 0.0 && supply_v <= 60.0) {
        return Err(format!("--supply-v {supply_v}: must be in (0, 60] V").into());
    }
    let limit = PhysicalLimit {
        voltage_limit_v: supply_v,
        ..PhysicalLimit::paper()
    };
    let pinion = MINUS_3_DB * amplitude_deg;
    say!(
        "Steady state at the motor for a sinusoidal pinion angle (delta_P), paper plant (Tables \
         1, 2, 4; eqs. 1-8), any controller:"
    );
    say!(
        "pinion amplitude {pinion:.2} deg (-3 dB of a {amplitude_deg} deg sweep); limits {} A, \
         {supply_v} V",
        limit.current_limit_a
    );
    say!(
        "{:>6} {:>10} {:>10} {:>24}",
        "f Hz",
        "current A",
        "voltage V",
        "largest amplitude, deg"
    );
    let mut rows = Vec::new();
    for f in 1..=10 {
        let d = limit.demand(f as f64, pinion);
        say!(
            "{:>6.1} {:>10.1} {:>10.1} {:>12.2} ({}-bound)",
            d.f_hz,
            d.current_a,
            d.voltage_v,
            d.largest_amplitude_deg,
            match d.limited_by {
                LimitedBy::Current => "current",
                LimitedBy::Voltage => "voltage",
            }
        );
        rows.push(d);
    }
    say!(
        "Bound on the -3 dB bandwidth of a sweep of amplitude A (the highest f where \
         10^(-3/20) A is reachable):"
    );
    let mut amplitudes = vec![10.0, 5.0, 2.0, 1.0];
    if !amplitudes.contains(&amplitude_deg) {
        amplitudes.insert(0, amplitude_deg);
    }
    say!(
        "  (sinusoidal drive within the limits; saturated drive: a current or voltage clipped at \
         the limit has a fundamental of up to 4/pi of it, {:.1} A / {:.1} V, which a chirp's H1 \
         reads)",
        limit.saturated().current_limit_a,
        limit.saturated().voltage_limit_v
    );
    let mut bounds = Vec::new();
    for a in amplitudes {
        let b = limit.bandwidth_bound_hz(a);
        let sat = limit.saturated().bandwidth_bound_hz(a);
        say!(
            "  {a:5} deg: {} sinusoidal, {} saturated",
            bound_text(b),
            bound_text(sat)
        );
        bounds.push(serde_json::json!({
            "amplitude_deg": a,
            "bandwidth_bound_hz": b,
            "saturated_bandwidth_bound_hz": sat,
        }));
    }
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "current_limit_a": limit.current_limit_a,
                "voltage_limit_v": supply_v,
                "pinion_amplitude_deg": pinion,
                "table": rows,
                "bounds": bounds,
            }),
        )?;
    }
    Ok(())
}

fn print_limits(summary: &host_sim::sim::RunSummary, supply_v: f64) {
    say!(
        "  max |current|      {:6.2} A   (limit 20 A; set-point at the limit {:.0} % of position ticks)",
        summary.max_current_a,
        100.0 * summary.current_limited_share
    );
    say!(
        "  max |voltage|      {:6.2} V   (limit {supply_v} V; at the limit {:.0} % of current ticks)",
        summary.max_voltage_v,
        100.0 * summary.voltage_limited_share
    );
    if summary.rejected_references > 0 {
        say!(
            "  rejected reference samples: {}",
            summary.rejected_references
        );
    }
}

fn sweep_cmd(sweep: &Sweep, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let (rep, run) = report::sweep(sweep, &cfg)?;
    say!(
        "Sine sweep 0-{} Hz in {} s, {} deg at the wheel ({})",
        sweep.f_end_hz,
        sweep.duration_s,
        sweep.amplitude_deg,
        sensors_label(common)
    );
    match rep.bandwidth_hz {
        Some(bw) => say!(
            "  -3 dB bandwidth    {bw:6.2} Hz  (paper, suspended: 5 Hz; on the ground: 4.8 Hz)"
        ),
        None => say!(
            "  -3 dB bandwidth    above {} Hz (paper: 5 Hz)",
            sweep.f_end_hz
        ),
    }
    let limit = physical_limit(&cfg);
    let bound = limit.bandwidth_bound_hz(sweep.amplitude_deg);
    let saturated = limit.saturated().bandwidth_bound_hz(sweep.amplitude_deg);
    say!(
        "  physical bound     {}  ({} A / {} V sinusoidal on this plant, any controller: \
         `host-sim limits`); the bandwidth is {} of it",
        bound_text(bound),
        limit.current_limit_a,
        limit.voltage_limit_v,
        share_of_bound(rep.bandwidth_hz, bound)
    );
    say!(
        "  saturated bound    {}  (the same limits as square waves: fundamentals 4/pi higher); \
         the bandwidth is {} of it",
        bound_text(saturated),
        share_of_bound(rep.bandwidth_hz, saturated)
    );
    // The linear model of the paper cascade (exact sensors, no limits); not for other controllers.
    let analytic = match cfg.controller {
        Controller::Paper => {
            let model = LinearModel::new(cfg.plant, &cfg.gains)?;
            let grid: Vec<f64> = (1..=(sweep.f_end_hz * 20.0).round() as usize)
                .map(|k| k as f64 / 20.0)
                .collect();
            let fr = model.bode(&grid, Output::Column, cfg.log_rate_hz)?;
            let bw = model.bandwidth_hz(
                report::BANDWIDTH_SEARCH_FROM_HZ,
                sweep.f_end_hz,
                cfg.log_rate_hz,
            );
            if !model.is_stable() {
                say!(
                    "  linear model: the closed loop is UNSTABLE on this plant (`host-sim poles`)"
                );
            }
            match bw {
                Some(bw) => say!(
                    "  linear model       {bw:6.2} Hz  (small signal, exact sensors: `host-sim poles`)"
                ),
                None => say!("  linear model       above {} Hz", sweep.f_end_hz),
            }
            Some((fr, bw))
        }
        Controller::Ecu => None,
    };
    say!("  RMS error          {:6.2} deg", rep.tracking.rmse);
    print_limits(&rep.summary, common.supply_v);
    // Small-signal response for comparison: the same loop where no limit is reached.
    let small = Sweep {
        amplitude_deg: 1.0,
        ..*sweep
    };
    let (small_rep, _) = report::sweep(&small, &cfg)?;
    let json;
    let small_bound = limit.bandwidth_bound_hz(small.amplitude_deg);
    if let Some(bw) = small_rep.bandwidth_hz {
        say!(
            "  (at 1 deg, below the speed limit: {bw:.2} Hz, {} of its bound of {})",
            share_of_bound(Some(bw), small_bound),
            bound_text(small_bound).trim_start()
        );
    }
    {
        let mut v = serde_json::to_value(&rep)?;
        v["small_signal_bandwidth_hz"] = serde_json::json!(small_rep.bandwidth_hz);
        v["paper_bandwidth_hz"] = serde_json::json!(5.0);
        v["bandwidth_bound_hz"] = serde_json::json!(bound);
        v["bandwidth_share_of_bound"] =
            serde_json::json!(rep.bandwidth_hz.zip(bound).map(|(bw, b)| bw / b));
        v["saturated_bandwidth_bound_hz"] = serde_json::json!(saturated);
        v["small_signal_bandwidth_bound_hz"] = serde_json::json!(small_bound);
        v["analytic_bandwidth_hz"] = serde_json::json!(analytic.as_ref().and_then(|a| a.1));
        if let Some(path) = &common.json {
            write_json(path, &v)?;
        }
        json = v;
    }
    save_log(&run.log, common)?;
    if common.plots.is_none() && common.report.is_none() {
        return Ok(());
    }
    let bode = bode_plot(sweep, &rep, &small_rep, analytic.as_ref().map(|a| &a.0));
    let title = format!(
        "Sine sweep 0-{} Hz, {} deg at the wheel",
        sweep.f_end_hz, sweep.amplitude_deg
    );
    let time = time_plot(&plot_title(common, &title), &run, common.supply_v);
    if let Some(dir) = &common.plots {
        save_svg(dir, "sweep_bode.svg", |p| bode.save(p))?;
        save_svg(dir, "sweep_time.svg", |p| time.save(p))?;
    }
    if let Some(path) = &common.report {
        let above = format!("above {} Hz", sweep.f_end_hz);
        let page = report_setup(HtmlReport::new(&format!("host-sim sweep: {title}")), common)
            .numbers(
                &json,
                &[
                    num("-3 dB bandwidth", "/bandwidth_hz", "Hz").absent(&above),
                    num("paper's (suspended)", "/paper_bandwidth_hz", "Hz").decimals(1),
                    num("physical bound", "/bandwidth_bound_hz", "Hz").absent("none"),
                    num("bandwidth / bound", "/bandwidth_share_of_bound", "%")
                        .percent()
                        .decimals(0),
                    num("saturated bound", "/saturated_bandwidth_bound_hz", "Hz").absent("none"),
                    num("linear model", "/analytic_bandwidth_hz", "Hz"),
                    num("RMS error", "/tracking/rmse", "deg"),
                    num("bandwidth at 1 deg", "/small_signal_bandwidth_hz", "Hz").absent(&above),
                    num("bound at 1 deg", "/small_signal_bandwidth_bound_hz", "Hz").absent("none"),
                ],
            );
        summary_rows(page, &json)
            .figure(
                "Frequency response (H1 estimate) with coherence",
                &bode.to_svg(),
            )
            .figure("Time traces of the sweep", &time.to_svg())
            .save(path)?;
        say!("report written to {}", path.display());
    }
    Ok(())
}

/// The report's set-up lines: what ran, on what plant.
fn report_setup(page: HtmlReport, common: &Common) -> HtmlReport {
    let plant = match &common.plant {
        Some(path) => format!("rig file {} (its model.plant)", path.display()),
        None => "the paper's (Tables 1, 2, 4)".to_string(),
    };
    let effects = if common.plant_effects.is_none() {
        "none (linear plant)".to_string()
    } else {
        common.plant_effects.to_string()
    };
    page.setup("controller", &sensors_label(common))
        .setup("plant", &plant)
        .setup("plant effects", &effects)
        .setup("supply", &format!("{} V", common.supply_v))
        .setup(
            "current guard",
            if common.no_current_guard { "off" } else { "on" },
        )
        .setup(
            "anti-windup",
            if common.no_anti_windup { "off" } else { "on" },
        )
}

/// The limits every run prints (`print_limits`), from the report's `summary`.
fn summary_rows(page: HtmlReport, json: &serde_json::Value) -> HtmlReport {
    // Shares of ticks, 0..1 in the JSON, whole per cent as printed.
    let share = |n: Num<'static>| n.percent().decimals(0);
    page.numbers(
        json,
        &[
            num("simulated time", "/duration_s", "s"),
            num("max |current|", "/max_current_a", "A"),
            share(num(
                "at the 20 A limit",
                "/current_limited_share",
                "% of position ticks",
            )),
            num("max |voltage|", "/max_voltage_v", "V"),
            share(num(
                "at the supply limit",
                "/voltage_limited_share",
                "% of current ticks",
            )),
            num("rejected reference samples", "/rejected_references", "").decimals(0),
        ],
    )
}

/// The controller, its sensors, and the plant's added effects if any.
fn sensors_label(common: &Common) -> String {
    let loop_ = match (common.controller, common.ideal_sensors) {
        (Controller::Ecu, _) => {
            "ECU mode: Hall feedback and timing, 12-bit column encoder at 500 Hz"
        }
        (Controller::Paper, true) => "paper mode, exact motor angle fed back",
        (Controller::Paper, false) => "paper mode: Hall feedback, 12-bit column encoder",
    };
    if common.plant_effects.is_none() {
        loop_.to_string()
    } else {
        format!("{loop_}; plant effects {}", common.plant_effects)
    }
}

fn bode_plot(
    sweep: &Sweep,
    rep: &SweepReport,
    small: &SweepReport,
    analytic: Option<&FrequencyResponse>,
) -> BodePlot {
    let main = format!("{} deg", sweep.amplitude_deg);
    let add = |plot: BodePlot, name: &str, fr: &FrequencyResponse, style: Style| {
        plot.series_styled(name, &fr.freq_hz, &fr.magnitude_db, &fr.phase_deg, style)
    };
    let mut plot = BodePlot::new("Column angle / reference at the wheel (H1 estimate, simulated)");
    plot = add(plot, &main, &rep.response, Style::new());
    plot = add(
        plot,
        "1 deg (small signal)",
        &small.response,
        Style::new().dashed(),
    );
    if let Some(fr) = analytic {
        plot = add(
            plot,
            ANALYTIC_LABEL,
            fr,
            Style::new().dashed().color(host_sim::plot::Color::BLACK),
        );
    }
    plot = plot.coherence(&main, &rep.response.freq_hz, &rep.response.coherence);
    if let Some(bw) = rep.bandwidth_hz {
        plot = plot.bandwidth_of(&main, bw);
    }
    if let Some(bw) = small.bandwidth_hz {
        plot = plot.bandwidth_of("1 deg (small signal)", bw);
    }
    plot
}

/// The Bode plot's name for the linear model's curve (`linear_model.rs`).
const ANALYTIC_LABEL: &str = "analytic (linear model)";

/// A figure's title with the controller, and the plant's added effects if any.
fn plot_title(common: &Common, what: &str) -> String {
    let mode = match common.controller {
        Controller::Paper => "paper mode",
        Controller::Ecu => "ECU mode",
    };
    if common.plant_effects.is_none() {
        format!("{what} ({mode})")
    } else {
        format!("{what} ({mode}, plant with {})", common.plant_effects)
    }
}

fn time_plot(title: &str, run: &Run, supply_v: f64) -> TimePlot {
    let log = &run.log;
    let empty: Vec<f64> = Vec::new();
    let setpoint = log.extra("current_setpoint_a").unwrap_or(&empty);
    let voltage = log.extra("voltage_v").unwrap_or(&empty);
    let error: Vec<f64> = log
        .sw_deg
        .iter()
        .zip(&log.ref_sw_deg)
        .map(|(y, r)| y - r)
        .collect();
    TimePlot::new(title)
        .panel(
            Panel::new("steering angle, deg")
                .series("reference", &log.t, &log.ref_sw_deg)
                .series("column encoder", &log.t, &log.sw_deg),
        )
        .panel(Panel::new("error, deg").series("encoder - reference", &log.t, &error))
        .panel(
            // The set-point over the measured current, translucent: in paper mode it chatters
            // between the limits and would hide the current it commands.
            Panel::new("motor current, A")
                .series("measured", &log.t, &log.current_a)
                .series_styled(
                    "set-point",
                    &log.t,
                    setpoint,
                    Style::new().color(host_sim::plot::Color::GRAY).opacity(0.6),
                )
                .hline(20.0, "+20 A")
                .hline(-20.0, "-20 A"),
        )
        .panel(
            Panel::new("voltage, V")
                .series("motor terminal", &log.t, voltage)
                .hline(supply_v, &format!("+{supply_v} V"))
                .hline(-supply_v, &format!("-{supply_v} V")),
        )
        .x_label("time, s")
}

fn track_cmd(reference: &[f64], name: &str, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let (rep, run): (TrackReport, Run) = report::track(reference, &cfg)?;
    say!(
        "Track run, {} ({:.1} s, {})",
        name,
        rep.summary.duration_s,
        sensors_label(common)
    );
    say!(
        "  RMSE               {:6.2} deg (paper, section 4.4: 3 deg)",
        rep.rmse_deg
    );
    say!(
        "  max |error|        {:6.2} deg at {:.2} s (paper: 4.5 deg at 89.4 s; 15.7 deg in a burst above 4 Hz)",
        rep.max_error_deg,
        rep.max_error_at_s
    );
    print_limits(&rep.summary, common.supply_v);
    let json = serde_json::to_value(&rep)?;
    if let Some(path) = &common.json {
        write_json(path, &json)?;
    }
    save_log(&run.log, common)?;
    let title = format!("Track run: {name}");
    time_outputs(
        common,
        &run,
        &title,
        "track_time.svg",
        "host-sim track",
        |page| {
            page.setup("reference", name).numbers(
                &json,
                &[
                    num("RMSE", "/rmse_deg", "deg"),
                    num("max |error|", "/max_error_deg", "deg"),
                    num("max |error| at", "/max_error_at_s", "s"),
                ],
            )
        },
        &json,
    )
}

/// The picture (`--plots`) and report (`--report`) of a run in time: `rows` adds the command's
/// own figures to the page, then come the limits every run prints.
fn time_outputs(
    common: &Common,
    run: &Run,
    title: &str,
    file: &str,
    command: &str,
    rows: impl FnOnce(HtmlReport) -> HtmlReport,
    json: &serde_json::Value,
) -> Result<()> {
    if common.plots.is_none() && common.report.is_none() {
        return Ok(());
    }
    let plot = time_plot(&plot_title(common, title), run, common.supply_v);
    if let Some(dir) = &common.plots {
        save_svg(dir, file, |p| plot.save(p))?;
    }
    if let Some(path) = &common.report {
        let page = report_setup(HtmlReport::new(&format!("{command}: {title}")), common);
        summary_rows(rows(page), json)
            .figure(&format!("Time traces: {title}"), &plot.to_svg())
            .save(path)?;
        say!("report written to {}", path.display());
    }
    Ok(())
}

fn step_cmd(amplitude_deg: f64, duration_s: f64, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let reference = scenario::step(amplitude_deg, 0.1, duration_s);
    let (rep, run) = report::step(&reference, amplitude_deg, &cfg)?;
    say!(
        "Step of {amplitude_deg} deg at the wheel at 0.1 s ({})",
        sensors_label(common)
    );
    match rep.rise_time_s {
        Some(t) => say!("  10-90 % rise time  {:6.3} s", t),
        None => say!("  10-90 % rise time  not reached"),
    }
    say!(
        "  overshoot          {:6.2} deg ({:.1} %)",
        rep.overshoot_deg,
        rep.overshoot_pct
    );
    say!("  final error        {:6.2} deg", rep.final_error_deg);
    print_limits(&rep.summary, common.supply_v);
    let json = serde_json::to_value(&rep)?;
    if let Some(path) = &common.json {
        write_json(path, &json)?;
    }
    save_log(&run.log, common)?;
    let title = format!("Step of {amplitude_deg} deg at the wheel");
    time_outputs(
        common,
        &run,
        &title,
        "step_time.svg",
        "host-sim step",
        |page| {
            page.numbers(
                &json,
                &[
                    num("10-90 % rise time", "/rise_time_s", "s")
                        .decimals(3)
                        .absent("not reached"),
                    num("overshoot", "/overshoot_deg", "deg"),
                    num("overshoot", "/overshoot_pct", "%").decimals(1),
                    num("final error", "/final_error_deg", "deg"),
                ],
            )
        },
        &json,
    )
}

fn bench(repeats: u32, json: Option<&Path>) -> Result<()> {
    let reference = scenario::builtin_track();
    let mut factors = Vec::new();
    let mut factors_logged = Vec::new();
    say!("Track run, 120 s at 20 kHz current / 2 kHz position / 100 Hz reference, one thread:");
    let mut duration = 0.0;
    for i in 0..repeats {
        for (log_rate_hz, out) in [(0, &mut factors), (1000, &mut factors_logged)] {
            let cfg = RunConfig {
                log_rate_hz,
                ..RunConfig::default()
            };
            let start = Instant::now();
            let run = host_sim::sim::run(&reference, &cfg)?;
            let wall = start.elapsed().as_secs_f64();
            duration = run.summary.duration_s;
            out.push(duration / wall);
        }
        say!(
            "  run {}/{}: {:.0}x real time (no log), {:.0}x (1 kHz log)",
            i + 1,
            repeats,
            factors[i as usize],
            factors_logged[i as usize]
        );
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let rf = median(&mut factors);
    let rf_logged = median(&mut factors_logged);
    say!(
        "  median: {rf:.0}x real time ({:.1} ms per simulated 120 s); with the 1 kHz log {rf_logged:.0}x (target 1000x)",
        1e3 * duration / rf
    );
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "realtime_factor": rf,
                "realtime_factor_with_log": rf_logged,
                "simulated_s": duration,
                "repeats": repeats,
            }),
        )?;
    }
    Ok(())
}

//! What the simulation subcommands share: their options ([`Common`]), the run configuration
//! made from them, and the set-up, limits and time plot every run prints or draws.

use super::{Result, save_svg};
use clap::Args;
use host_sim::effect_plant::PlantEffects;
use host_sim::logfmt::Log;
use host_sim::plant::PlantParams;
use host_sim::plot::{Panel, Style, TimePlot};
use host_sim::report_html::{HtmlReport, Num, num};
use host_sim::sim::{Controller, Run, RunConfig};
use std::path::PathBuf;
use steering_ecu::control::AntiWindup;

#[derive(Args, Debug)]
pub(crate) struct Common {
    /// Write the figures as JSON.
    #[arg(long, value_name = "PATH")]
    pub(crate) json: Option<PathBuf>,
    /// Write the run's log (project log format; `.csv.gz` compresses).
    #[arg(long, value_name = "PATH")]
    pub(crate) log: Option<PathBuf>,
    /// Write the pictures (SVG) into this directory.
    #[arg(long, value_name = "DIR")]
    pub(crate) plots: Option<PathBuf>,
    /// Write one self-contained HTML file: the command line, controller and plant, the figures
    /// as a table and the pictures inline (nothing fetched from the network).
    #[arg(long, value_name = "HTML")]
    pub(crate) report: Option<PathBuf>,
    /// Log rate, Hz (a divisor of 2000).
    #[arg(long, default_value_t = 1000, value_name = "HZ")]
    pub(crate) log_rate_hz: u32,
    /// Feed the position loop the exact motor angle instead of the 84-count Hall angle.
    #[arg(long)]
    pub(crate) ideal_sensors: bool,
    /// Supply (battery) voltage, the voltage limit of the current loop, V.
    #[arg(long, default_value_t = 24.0, value_name = "V")]
    pub(crate) supply_v: f64,
    /// Integrate regardless of saturation (to see what anti-windup prevents).
    #[arg(long)]
    pub(crate) no_anti_windup: bool,
    /// The steering controller: the paper's EPOS4 cascade on the motor, or the ECU's own
    /// (inverse belt model, model feedforward, column integral; host-sim/README.md, "ECU mode").
    #[arg(long, value_enum, default_value_t = Controller::Paper)]
    pub(crate) controller: Controller,
    /// A rig file (as in host-sim/rigs/) whose `model.plant` replaces the paper's plant (Tables
    /// 1, 2, 4); the controller keeps its own tuning, so this is how its robustness is checked.
    #[arg(long, value_name = "FILE")]
    pub(crate) plant: Option<PathBuf>,
    /// Run without the current guard, the voltage clamp that holds the current within 20 A
    /// (to see the overshoot it prevents).
    #[arg(long)]
    pub(crate) no_current_guard: bool,
    /// Effects the linear plant leaves out, as KEY=VALUE[,...]: backlash_deg (play in the
    /// belt/nut, deg at the wheel), column_play_deg, coulomb_n (rack friction, N),
    /// coulomb_creep_mm_s (rack speed it builds up over, tanh; 0 = sharp), motor_coulomb_nm,
    /// motor_stribeck_nm, stribeck_rad_s, tire_n with tire_n_per_mm, tire_dahl.
    /// E.g. `--plant-effects backlash_deg=1.5,coulomb_n=200`.
    #[arg(long, value_name = "LIST", default_value = "")]
    pub(crate) plant_effects: PlantEffects,
}

impl Common {
    pub(crate) fn config(&self) -> Result<RunConfig> {
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

/// The report's set-up lines: what ran, on what plant.
pub(crate) fn report_setup(page: HtmlReport, common: &Common) -> HtmlReport {
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
pub(crate) fn summary_rows(page: HtmlReport, json: &serde_json::Value) -> HtmlReport {
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
pub(crate) fn sensors_label(common: &Common) -> String {
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

/// A figure's title with the controller, and the plant's added effects if any.
pub(crate) fn plot_title(common: &Common, what: &str) -> String {
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

pub(crate) fn time_plot(title: &str, run: &Run, supply_v: f64) -> TimePlot {
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

pub(crate) fn print_limits(summary: &host_sim::sim::RunSummary, supply_v: f64) {
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

/// The picture (`--plots`) and report (`--report`) of a run in time: `rows` adds the command's
/// own figures to the page, then come the limits every run prints.
pub(crate) fn time_outputs(
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

pub(crate) fn save_log(log: &Log, common: &Common) -> Result<()> {
    if let Some(path) = &common.log {
        log.save(path)?;
        say!("log written to {} ({} rows)", path.display(), log.len());
    }
    Ok(())
}

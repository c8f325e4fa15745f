//! `host-sim`: the paper's steering actuator simulated under the firmware's control code.
//!
//! Subcommands: `poles`, `limits`, `sweep`, `track`, `step`, `bench`, `gap` (sim-to-real gap
//! diagnosis of a log, `gap selftest`, `gap bench`) and `identify` (Table 4 from a log). Each prints a
//! readable summary; `--json PATH` writes its figures, `--log PATH` the run's log (CSV,
//! `.csv.gz` compressed), `--plots DIR` its pictures (SVG), `--report PATH` all of it as one
//! self-contained HTML page (`sweep`, `track`, `step`, `gap`).
//!
//! This file holds the arguments and the dispatch; each subcommand's body is a file of `cmd/`.

mod cmd;

use clap::{Parser, Subcommand};
use cmd::Result;
use cmd::common::Common;
use cmd::say;
use cmd::{
    bench::bench,
    limits::limits_cmd,
    poles::poles,
    step::step_cmd,
    sweep::{check_sweep, sweep_cmd},
    track::track_cmd,
};
use host_sim::scenario::{self, Sweep};
use std::path::PathBuf;
use std::process::ExitCode;

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
    /// What the paper plant allows whatever the controller: the current and voltage
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

#[cfg(test)]
mod tests {
    use super::*;
    use clap::CommandFactory;

    /// Every text `--help` can show, of `cmd` and its subcommands, with where it comes from.
    fn help_texts(cmd: &clap::Command, path: &str, out: &mut Vec<(String, String)>) {
        let texts = [cmd.get_about(), cmd.get_long_about()];
        for text in texts.into_iter().flatten() {
            out.push((path.to_string(), text.to_string()));
        }
        for arg in cmd.get_arguments() {
            for text in [arg.get_help(), arg.get_long_help()].into_iter().flatten() {
                out.push((format!("{path} --{}", arg.get_id()), text.to_string()));
            }
        }
        for sub in cmd.get_subcommands() {
            help_texts(sub, &format!("{path} {}", sub.get_name()), out);
        }
    }

    /// Help says what and why; which issue, session or selftest case a line came from is
    /// history, kept in the commits.
    #[test]
    fn help_names_no_issue_session_or_case_number() {
        let mut texts = Vec::new();
        help_texts(&Cli::command(), "host-sim", &mut texts);
        assert!(texts.len() > 50, "{} help texts", texts.len());
        for (path, text) in &texts {
            let words: Vec<String> = text
                .split_whitespace()
                .map(|w| {
                    w.trim_matches(|c: char| !c.is_alphanumeric())
                        .to_lowercase()
                })
                .collect();
            for pair in words.windows(2) {
                let numbered = pair[1].starts_with(|c: char| c.is_ascii_digit());
                assert!(
                    !(["issue", "session", "case"].contains(&pair[0].as_str()) && numbered),
                    "{path}: `{} {}` in `{text}`",
                    pair[0],
                    pair[1]
                );
            }
        }
    }
}

//! The `steer-can` command line as clap parses it: the global options ([`Cli`]), the
//! commands and their arguments, and each command's `--help` listing only the global options
//! that apply to it ([`command`]). Types only: what the commands do is `commands.rs`.

use super::profile::parse_as_state;
use clap::{Args, CommandFactory, Parser, Subcommand};
use std::path::PathBuf;
use steering_ecu::as_state::AsState;
use steering_ecu::controller::ControllerKind;

#[derive(Parser, Debug)]
#[command(
    name = "steer-can",
    version,
    about = "CAN bring-up of the steering ECU on the car: monitor, EPOS4 check, reference \
             profiles, the test campaign, recording"
)]
pub struct Cli {
    /// SocketCAN interface (`can0`); `sim` for a simulated car of this call alone; `sim:PATH`
    /// for the car `steer-can sim-car --socket PATH` serves to every call. `rehearse`: `sim`.
    #[arg(long, global = true, default_value = "can0")]
    pub iface: String,
    /// The EPOS4's CANopen node ID.
    #[arg(
        long,
        global = true,
        default_value_t = 1,
        allow_negative_numbers = true
    )]
    pub node: u8,
    /// With `--iface sim`: run as fast as the CPU allows instead of in step with the wall
    /// clock (tests, quick rehearsals).
    #[arg(long, global = true)]
    pub fast: bool,
    /// With `--iface sim`: inject a fault at a time, KIND@SECONDS (encoder, overcurrent, epos).
    #[arg(long, global = true, hide = true, value_name = "KIND@S")]
    pub sim_inject: Option<String>,
    /// With `--iface sim`: the steering angle the simulated car is powered up at, deg at the
    /// wheel (the motor's position counts from there, as on the car).
    #[arg(
        long,
        global = true,
        default_value_t = 0.0,
        value_name = "DEG",
        allow_negative_numbers = true
    )]
    pub sim_column_deg: f64,
    /// With `--iface sim`: the simulated ECU's steering controller, `paper` (the paper's
    /// cascade) or `ecu` (the ECU's own, host-sim/README.md, "ECU mode").
    #[arg(long, global = true, value_enum, default_value_t = ControllerArg::Paper)]
    pub controller: ControllerArg,
    /// With `--iface sim`: the firmware build the simulated car runs, `epos4` (the default
    /// build: the ECU's EPOS4 link, CSP, SYNC, heartbeats, PDOs) or `direct` (the ECU's own
    /// bridge, `--features drive-direct`).
    #[arg(long, global = true, value_enum, default_value_t = DriveArg::Epos4)]
    pub drive: DriveArg,
    /// With `--iface sim`: effects the simulated car has and Table 4 leaves out, KEY=VALUE,...:
    /// host-sim's `--plant-effects` keys (`backlash_deg`, `coulomb_n`, `coulomb_creep_mm_s`,
    /// `tire_n`, ...) and `reference_delay_ms`. A car with a known gap, for rehearsing
    /// `host-sim gap` on the whole chain (campaign, candump, convert).
    #[arg(long, global = true, value_name = "LIST")]
    pub plant_effects: Option<String>,
    #[command(subcommand)]
    pub command: Command,
}

/// The global options that mean nothing to a command, by command: hidden from its `--help`.
/// `convert` reads a file (only `--node` matters to it: the EPOS4's PDO IDs); `sim-car` is the
/// simulated car itself, so it has no interface to name.
const NOT_FOR: &[(&str, &[&str])] = &[
    (
        "convert",
        &[
            "iface",
            "fast",
            "sim_column_deg",
            "controller",
            "drive",
            "plant_effects",
        ],
    ),
    ("sim-car", &["iface", "fast"]),
];

/// The command line as `main` parses it: [`Cli`]'s, with each command's `--help` listing only
/// the global options that apply to it.
pub fn command() -> clap::Command {
    let mut cmd = Cli::command();
    // A subcommand that has an option of a global's name does not get the global copied into
    // it: give it a hidden copy instead, still accepted (a script that passes `--iface` to
    // every call keeps working) but not listed. Its value stays with the subcommand, which
    // does not read it.
    for (sub, hidden) in NOT_FOR {
        let copies: Vec<clap::Arg> = cmd
            .get_arguments()
            .filter(|a| hidden.contains(&a.get_id().as_str()))
            .map(|a| a.clone().global(false).hide(true))
            .collect();
        cmd = cmd.mut_subcommand(*sub, |c| c.args(copies));
    }
    cmd
}

impl Cli {
    /// The defaults that depend on the command: `rehearse` runs on the simulated car only, so
    /// there `--iface` means `sim` unless it is given.
    pub fn with_command_defaults(mut self, matches: &clap::ArgMatches) -> Cli {
        let iface_given = matches!(
            matches.value_source("iface"),
            Some(clap::parser::ValueSource::CommandLine | clap::parser::ValueSource::EnvVariable)
        ) || matches.subcommand().is_some_and(|(_, sub)| {
            sub.value_source("iface") == Some(clap::parser::ValueSource::CommandLine)
        });
        if matches!(self.command, Command::Rehearse { .. }) && !iface_given {
            self.iface = "sim".into();
        }
        self
    }
}

/// `--controller`: which steering controller the simulated ECU runs.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum ControllerArg {
    /// The paper's EPOS4 cascade on the motor angle (Table 3), bit-exact with the firmware.
    Paper,
    /// The ECU's own controller (`steering_ecu::ecu_mode`).
    Ecu,
}

impl ControllerArg {
    /// The firmware's name for it.
    pub fn kind(self) -> ControllerKind {
        match self {
            ControllerArg::Paper => ControllerKind::Paper,
            ControllerArg::Ecu => ControllerKind::Ecu,
        }
    }
}

/// `--drive`: which firmware build the simulated car runs.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum DriveArg {
    Epos4,
    Direct,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Live decode of the bus: reference, status, motor frame, EPOS4 PDOs, EMCY, heartbeat,
    /// with counters, CRC errors and the fault bits in words.
    Monitor {
        /// Stop after this long, s (default: until Ctrl-C).
        #[arg(long, value_name = "S", allow_negative_numbers = true)]
        duration_s: Option<f64>,
        /// Print every frame, decoded, besides the summary.
        #[arg(long)]
        each: bool,
        /// Summary every this many seconds.
        #[arg(
            long,
            default_value_t = 1.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        refresh_s: f64,
        /// Draw reference, column angle, motor angle and current scrolling in the terminal
        /// (the last 10 s, redrawn 10 times a second), with state, faults and counters below.
        #[arg(long, conflicts_with = "each")]
        plot: bool,
    },
    /// The EPOS4 by SDO reads: NMT state, mode, the gains and the drive's limits (current,
    /// following error, speed, software position limits) against ours, error register and
    /// history.
    Epos {
        #[command(subcommand)]
        what: EposCommand,
    },
    /// Send a reference profile at 100 Hz (counter, CRC) in the AS state you name.
    Send {
        /// The AS state the frames claim: off, ready, driving, finished, emergency, manual.
        /// Accepted before or after the profile's name.
        #[arg(long, global = true, value_parser = parse_as_state)]
        as_state: Option<AsState>,
        /// Stop sending at the end instead of 0.2 s of AS Finished (to see the timeout fault).
        #[arg(long, global = true)]
        no_finish: bool,
        #[command(subcommand)]
        profile: SendProfile,
    },
    /// The paper's test campaign: ready check, confirmation, run, abort on any fault, log.
    Campaign {
        #[command(subcommand)]
        kind: CampaignKind,
    },
    /// Record the bus to a candump file (can-utils `-l` format).
    Record {
        /// The candump file to write (a missing directory is created).
        #[arg(long, value_name = "FILE")]
        out: PathBuf,
        /// Stop after this long, s (default: until Ctrl-C).
        #[arg(long, value_name = "S", allow_negative_numbers = true)]
        duration_s: Option<f64>,
    },
    /// The README's first day on the simulated car, in one session: each `steer-can` step the
    /// README's bring-up list names, its result beside what the README expects, pass or fail
    /// (exit 1 if any step fails). On the simulated car only (the default `--iface` here);
    /// `--fast` to run it at CPU speed.
    Rehearse {
        /// Where the steps' files go (sweep.csv.gz, track.csv.gz, profile.csv, bus.candump,
        /// log.csv).
        #[arg(long, default_value = "rehearsal", value_name = "DIR")]
        dir: PathBuf,
    },
    /// Run one simulated car (as `--iface sim` builds it) for many calls: serve its bus on a
    /// Unix socket until Ctrl-C; attach with `--iface sim:PATH`.
    SimCar {
        /// The socket file to serve on.
        #[arg(long, value_name = "PATH")]
        socket: PathBuf,
    },
    /// Convert a candump log to the project's log format (for `host-sim gap`).
    Convert {
        /// The candump file (`candump -l` or `steer-can record`), at most 10000000 frames
        /// (held in memory; over 20 min of a full 1 Mbit/s bus): a longer one is refused,
        /// its parts (`split -l 10000000`) convert one by one.
        candump: PathBuf,
        /// The log to write (`.csv` or `.csv.gz`).
        #[arg(long, value_name = "LOG")]
        out: PathBuf,
        /// Keep every reference period, not only those in AS Ready or Driving.
        #[arg(long)]
        all_rows: bool,
    },
}

#[derive(Subcommand, Debug)]
pub enum EposCommand {
    /// Read and compare; nothing is written.
    Check,
}

#[derive(Subcommand, Debug, Clone)]
pub enum SendProfile {
    /// A step at the wheel (sent as a ramp at the ECU's 400 deg/s).
    Step {
        /// Height of the step at the steering wheel, deg.
        #[arg(
            long,
            default_value_t = 2.0,
            value_name = "DEG",
            allow_negative_numbers = true
        )]
        amplitude_deg: f64,
        /// When the step starts, s after the first frame.
        #[arg(
            long,
            default_value_t = 0.5,
            value_name = "S",
            allow_negative_numbers = true
        )]
        at_s: f64,
        /// Length of the whole profile, s.
        #[arg(
            long,
            default_value_t = 2.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        duration_s: f64,
    },
    /// A sine at the wheel.
    Sine {
        /// Amplitude at the steering wheel, deg.
        #[arg(
            long,
            default_value_t = 2.0,
            value_name = "DEG",
            allow_negative_numbers = true
        )]
        amplitude_deg: f64,
        /// Frequency, Hz.
        #[arg(
            long,
            default_value_t = 1.0,
            value_name = "HZ",
            allow_negative_numbers = true
        )]
        freq_hz: f64,
        /// Length of the profile, s.
        #[arg(
            long,
            default_value_t = 5.0,
            value_name = "S",
            allow_negative_numbers = true
        )]
        duration_s: f64,
    },
    /// The paper's chirp (section 4.2).
    Sweep(SweepArgs),
    /// A track profile from a CSV `t,ref_sw_deg` (the built-in 120 s one without --csv).
    Track(TrackArgs),
    /// AS Off frames with the clear-faults bit, 100 ms: clears latched faults whose cause is
    /// gone.
    ClearFaults,
}

#[derive(Args, Debug, Clone)]
pub struct SweepArgs {
    /// Amplitude of the chirp at the steering wheel, deg.
    #[arg(
        long,
        default_value_t = 10.0,
        value_name = "DEG",
        allow_negative_numbers = true
    )]
    pub amplitude_deg: f64,
    /// Frequency at the start, Hz.
    #[arg(
        long,
        default_value_t = 0.0,
        value_name = "HZ",
        allow_negative_numbers = true
    )]
    pub f_start_hz: f64,
    /// Frequency at the end, Hz.
    #[arg(
        long,
        default_value_t = 10.0,
        value_name = "HZ",
        allow_negative_numbers = true
    )]
    pub f_end_hz: f64,
    /// Length of the chirp, s.
    #[arg(
        long,
        default_value_t = 10.0,
        value_name = "S",
        allow_negative_numbers = true
    )]
    pub duration_s: f64,
}

#[derive(Args, Debug, Clone)]
pub struct TrackArgs {
    /// The profile, CSV `t,ref_sw_deg` (plain or gzip); the built-in 120 s one without it.
    #[arg(long, value_name = "CSV")]
    pub csv: Option<PathBuf>,
}

#[derive(Subcommand, Debug)]
pub enum CampaignKind {
    /// The paper's sweep: 0-10 Hz chirp at 10 deg, 10 s (section 4.2).
    Sweep {
        #[command(flatten)]
        sweep: SweepArgs,
        #[command(flatten)]
        common: CampaignArgs,
    },
    /// A track run (section 4.4): CSV `t,ref_sw_deg` or the built-in 120 s profile.
    Track {
        #[command(flatten)]
        track: TrackArgs,
        #[command(flatten)]
        common: CampaignArgs,
    },
}

#[derive(Args, Debug)]
pub struct CampaignArgs {
    /// The log to write (`.csv` or `.csv.gz`), ready for `host-sim gap`.
    #[arg(long, value_name = "LOG")]
    pub out: PathBuf,
    /// The candump recording of the whole run (default: the log's name + `.candump`).
    #[arg(long, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// The AS state claimed while the profile runs.
    #[arg(long, default_value = "driving", value_parser = parse_as_state)]
    pub as_state: AsState,
    /// Do not ask for confirmation.
    #[arg(long)]
    pub yes: bool,
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every option and argument of every subcommand says what it is in `--help`.
    #[test]
    fn every_option_has_help_text() {
        fn walk(cmd: &clap::Command, path: &str, missing: &mut Vec<String>) {
            for arg in cmd.get_arguments() {
                let builtin = matches!(arg.get_id().as_str(), "help" | "version");
                if !builtin && !arg.is_hide_set() && arg.get_help().is_none() {
                    missing.push(format!("{path} --{}", arg.get_id()));
                }
            }
            for sub in cmd.get_subcommands() {
                walk(sub, &format!("{path} {}", sub.get_name()), missing);
            }
        }
        let mut missing = Vec::new();
        walk(&Cli::command(), "steer-can", &mut missing);
        assert!(missing.is_empty(), "no help text: {missing:?}");
    }

    /// The global options and the AS state are accepted before or after the subcommand.
    #[test]
    fn global_options_are_accepted_anywhere() {
        let parse = |args: &[&str]| Cli::try_parse_from(args).map_err(|e| e.to_string());
        let late = parse(&[
            "steer-can",
            "send",
            "step",
            "--as-state",
            "driving",
            "--iface",
            "sim",
            "--node",
            "3",
        ])
        .unwrap();
        let early = parse(&[
            "steer-can",
            "--iface",
            "sim",
            "--node",
            "3",
            "send",
            "--as-state",
            "driving",
            "step",
        ])
        .unwrap();
        for cli in [late, early] {
            assert_eq!((cli.iface.as_str(), cli.node), ("sim", 3));
            match cli.command {
                Command::Send { as_state, .. } => assert_eq!(as_state, Some(AsState::Driving)),
                other => panic!("{other:?}"),
            }
        }
        let epos = parse(&["steer-can", "epos", "check", "--iface", "sim"]).unwrap();
        assert_eq!(epos.iface, "sim");
    }
}

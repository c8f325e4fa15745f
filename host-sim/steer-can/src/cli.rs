//! The `steer-can` command line: argument parsing, the confirmation prompt, Ctrl-C, progress
//! on stderr, results on stdout. `--iface sim` runs every command against the simulated car
//! (`host_sim::sim_ecu` through `simcar`, the default firmware unless `--drive direct`), held to the wall clock
//! unless `--fast`: the tests use it, and a team can rehearse the bring-up on a laptop before
//! the car is there (`rehearse`, `sim-car`). Each command returns what it found
//! ([`Outcome`]) besides printing it, so `rehearse` judges values, not text.

use super::campaign::{self, Campaign, Live};
use super::decode::{Decoded, Decoder, faults_in_words};
use super::liveplot::{self, LivePlot};
use super::logbuild::{self, Rows};
use super::monitor::Monitor;
use super::profile::{self, Profile, parse_as_state};
use super::simcar;
use super::{BringupError, Transport, candump, epos, pump};
use canlink::reference::ReferenceSender;
use clap::{Args, CommandFactory, FromArgMatches, Parser, Subcommand};
use host_io::scenario::Sweep;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use steering_ecu::as_state::AsState;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::epos4::{Epos4Config, PositionScale};
use steering_ecu::controller::ControllerKind;
use steering_ecu::protocol::PERIOD_US;

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
    /// cascade) or `ecu` (the ECU's own, README "ECU mode").
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
        /// The candump file to write.
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
        /// The candump file (`candump -l` or `steer-can record`).
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

/// `println!` that ends the program quietly when stdout is closed (`steer-can ... | head`).
macro_rules! say {
    ($($arg:tt)*) => {
        host_io::out::stdout_line("steer-can", format_args!($($arg)*))
    };
}
// `rehearse` prints its steps with it too (it exists with the simulated car only).
#[cfg(feature = "sim")]
pub(crate) use say;

/// Exit code of a campaign that stopped on a fault or Ctrl-C (the log is still written).
pub const EXIT_ABORTED: u8 = 3;

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let matches = command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli.with_command_defaults(&matches),
        Err(e) => e.exit(),
    };
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("steer-can: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The bus the command runs on: the car's SocketCAN interface, or the simulated car
/// (`sim`, `sim:PATH`), which only a build with the `sim` feature has.
fn open(cli: &Cli) -> Result<Box<dyn Transport>, BringupError> {
    if cli.iface == "sim" || cli.iface.starts_with("sim:") {
        return simcar::open(cli);
    }
    #[cfg(target_os = "linux")]
    {
        Ok(Box::new(super::socketcan::SocketCan::open(&cli.iface)?))
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(BringupError::Link(canlink::LinkError::NoInterface {
            iface: cli.iface.clone(),
            detail: "SocketCAN exists on Linux only".into(),
        }))
    }
}

pub(crate) fn decoder(node: NodeId) -> Result<Decoder, BringupError> {
    let counts = Epos4Config::paper(node).counts_per_rev;
    let scale = PositionScale::new(counts).ok_or_else(|| BringupError::Epos {
        reason: format!("{counts} position increments per revolution"),
    })?;
    Ok(Decoder::new(node, scale))
}

/// The process's Ctrl-C flag: the handler is installed once and every command (all the steps
/// of `rehearse` too) watches the same flag.
pub(crate) fn stop_flag() -> Arc<AtomicBool> {
    static FLAG: std::sync::OnceLock<Arc<AtomicBool>> = std::sync::OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let f = flag.clone();
        // Refused only if something else installed a handler; then Ctrl-C ends the process.
        let _ = ctrlc::set_handler(move || f.store(true, Ordering::SeqCst));
        flag
    })
    .clone()
}

/// What a command found, for the exit code and for `rehearse`'s comparison with the README.
#[derive(Debug)]
pub enum Outcome {
    Monitor(Monitor),
    Epos(epos::EposReport),
    /// `send`: what the tool saw on the bus, its own frames included.
    Send(Monitor),
    Campaign(CampaignOutcome),
    Record {
        frames: u64,
        monitor: Monitor,
    },
    Convert(logbuild::Built),
    /// `rehearse`: every step matched the README.
    Rehearsed {
        all_passed: bool,
    },
    /// `sim-car` stopped (Ctrl-C).
    Served,
}

impl Outcome {
    fn exit_code(&self) -> ExitCode {
        match self {
            Outcome::Campaign(c) if c.aborted.is_some() => ExitCode::from(EXIT_ABORTED),
            Outcome::Rehearsed { all_passed: false } => ExitCode::FAILURE,
            _ => ExitCode::SUCCESS,
        }
    }
}

/// What a campaign ended with.
#[derive(Debug)]
pub struct CampaignOutcome {
    pub aborted: Option<campaign::AbortReason>,
    pub profile_samples: usize,
    pub profile_samples_sent: usize,
    pub rate_limited: usize,
    pub final_status: Option<steering_ecu::protocol::Status>,
    pub log_rows: usize,
    pub recording: PathBuf,
}

fn run(cli: Cli) -> Result<ExitCode, BringupError> {
    super::bounds::check(&cli)?;
    let node = NodeId::new(cli.node).ok_or_else(|| BringupError::Usage {
        reason: format!("--node {}: a CANopen node ID is 1 to 127", cli.node),
    })?;
    let dec = decoder(node)?;
    let outcome = match &cli.command {
        Command::Convert {
            candump: path,
            out,
            all_rows,
        } => Outcome::Convert(convert(path, out, &dec, *all_rows)?),
        Command::Rehearse { dir } => {
            if cli.iface != "sim" {
                return Err(BringupError::Usage {
                    reason: format!(
                        "rehearse runs on the simulated car only (--iface sim), not on {}",
                        cli.iface
                    ),
                });
            }
            simcar::rehearse(&cli, dir)?
        }
        Command::SimCar { socket } => simcar::serve(&cli, socket)?,
        command => {
            let mut t = open(&cli)?;
            execute(
                command,
                node,
                &dec,
                t.as_mut(),
                &mut ReferenceSender::default(),
            )?
        }
    };
    Ok(outcome.exit_code())
}

/// Runs one command that needs the bus on `t` (every command but `convert` and `rehearse`).
/// `sender` holds the reference frames' alive counter for the session: the ECU expects each
/// frame's counter one above the last it saw, so the `send`s of one session (`rehearse`)
/// continue one counter rather than each starting from 0, which the ECU would count as a jump.
pub(crate) fn execute(
    command: &Command,
    node: NodeId,
    dec: &Decoder,
    t: &mut dyn Transport,
    sender: &mut ReferenceSender,
) -> Result<Outcome, BringupError> {
    match command {
        Command::Monitor {
            duration_s,
            each,
            refresh_s,
            plot,
        } => Ok(Outcome::Monitor(monitor(
            t,
            dec,
            *duration_s,
            *each,
            *refresh_s,
            plot.then(|| LivePlot::new(1000)),
        )?)),
        Command::Epos {
            what: EposCommand::Check,
        } => {
            let report = epos::check(t, node)?;
            say!("{}", report.text().trim_end());
            Ok(Outcome::Epos(report))
        }
        Command::Send {
            as_state,
            no_finish,
            profile,
        } => Ok(Outcome::Send(send(
            t,
            dec,
            *as_state,
            !*no_finish,
            profile,
            sender,
        )?)),
        Command::Record { out, duration_s } => {
            let (frames, monitor) = record(t, dec, out, *duration_s)?;
            Ok(Outcome::Record { frames, monitor })
        }
        Command::Campaign { kind } => {
            let (profile, common) = match kind {
                CampaignKind::Sweep { sweep, common } => (profile::sweep(to_sweep(sweep))?, common),
                CampaignKind::Track { track, common } => {
                    (profile::track(track.csv.as_deref())?, common)
                }
            };
            Ok(Outcome::Campaign(campaign_cmd(t, dec, profile, common)?))
        }
        Command::Convert { .. } | Command::Rehearse { .. } | Command::SimCar { .. } => {
            Err(BringupError::Usage {
                reason: "convert, rehearse and sim-car do not run on a bus".into(),
            })
        }
    }
}

fn to_sweep(a: &SweepArgs) -> Sweep {
    Sweep {
        amplitude_deg: a.amplitude_deg,
        f_start_hz: a.f_start_hz,
        f_end_hz: a.f_end_hz,
        duration_s: a.duration_s,
    }
}

pub(crate) fn convert(
    path: &Path,
    out: &Path,
    dec: &Decoder,
    all_rows: bool,
) -> Result<logbuild::Built, BringupError> {
    let file = candump::read(path)?;
    if file.dropped_backwards > 0 {
        eprintln!(
            "steer-can: warning: {}: {} frames stamped more than {} ms before the frame read \
             before them were dropped (the first at line {})",
            path.display(),
            file.dropped_backwards,
            candump::BACKWARDS_TOLERANCE_S * 1e3,
            file.first_dropped_line.unwrap_or(0)
        );
    }
    if file.socket_drops > 0 {
        eprintln!(
            "steer-can: warning: {}: candump reports {} frames its socket lost while \
             recording (the first report at line {}); the log has gaps there",
            path.display(),
            file.socket_drops,
            file.first_drop_report_line.unwrap_or(0)
        );
    }
    let rows = if all_rows { Rows::All } else { Rows::Active };
    // The log builder knows frames, not files: name the file the frames came from.
    let built = logbuild::build(&file.frames, dec, rows).map_err(|e| match e {
        BringupError::Log { reason } => BringupError::Log {
            reason: format!("{}: {reason}", path.display()),
        },
        e => e,
    })?;
    campaign::save_log(&built.log, out)?;
    say!(
        "{}: {} frames ({} skipped: not classic 11-bit data), {} references, {} invalid frames",
        path.display(),
        file.frames.len(),
        file.skipped,
        built.references,
        built.invalid_frames
    );
    for n in &built.notes {
        say!("note: {n}");
    }
    say!(
        "log written to {} ({} rows, {:.2} s)",
        out.display(),
        built.log.len(),
        built.log.t.last().copied().unwrap_or(0.0)
    );
    Ok(built)
}

fn monitor(
    t: &mut dyn Transport,
    dec: &Decoder,
    duration_s: Option<f64>,
    each: bool,
    refresh_s: f64,
    mut plot: Option<LivePlot>,
) -> Result<Monitor, BringupError> {
    let stop = stop_flag();
    let mut m = Monitor::new(*dec);
    let start = t.now_us();
    let end = duration_s.map(|d| start + (d * 1e6) as u64);
    // The picture moves at 10 frames a second; the text summary at the refresh period.
    let refresh_s = if plot.is_some() { 0.1 } else { refresh_s };
    let refresh_us = (refresh_s.max(0.05) * 1e6) as u64;
    let mut next = start + refresh_us;
    let mut any = false;
    loop {
        let deadline = end.map_or(next, |e| e.min(next));
        let mut lines = Vec::new();
        pump(t, deadline, |rx| {
            let d = m.on_frame(rx);
            if each {
                lines.push(m.line(rx, &d));
            }
            if let (Some(p), Decoded::Status(Ok(_))) = (plot.as_mut(), &d) {
                p.sample(&m);
            }
            true
        })?;
        for l in lines {
            say!("{l}");
        }
        if m.last_status.is_none() && t.now_us() >= start + campaign::READY_WAIT_US && !any {
            eprintln!(
                "steer-can: warning: {} — still listening",
                BringupError::EcuSilent {
                    waited_ms: campaign::READY_WAIT_US / 1000
                }
            );
            any = true;
        }
        // The end's summary follows below: one for the same instant is enough.
        let ending = end.is_some_and(|e| t.now_us() >= e) || stop.load(Ordering::SeqCst);
        if ending {
            break;
        }
        if t.now_us() >= next {
            match &plot {
                Some(p) => {
                    let (w, h) = liveplot::terminal_size();
                    let title = format!("steer-can monitor --plot on {}", t.name());
                    let frame = p.render(&title, &liveplot::info_lines(&m), w, h);
                    say!("{}{}", liveplot::REDRAW, frame.trim_end());
                }
                None => say!("--- {} ---\n{}", t.name(), m.summary().trim_end()),
            }
            next += refresh_us;
        }
    }
    say!("=== {} ===\n{}", t.name(), m.summary().trim_end());
    if m.last_status.is_none() {
        return Err(BringupError::EcuSilent {
            waited_ms: (t.now_us() - start) / 1000,
        });
    }
    Ok(m)
}

fn record(
    t: &mut dyn Transport,
    dec: &Decoder,
    out: &Path,
    duration_s: Option<f64>,
) -> Result<(u64, Monitor), BringupError> {
    let stop = stop_flag();
    let io = |source| BringupError::Io {
        context: format!("cannot write {}", out.display()),
        source,
    };
    let file = std::fs::File::create(out).map_err(io)?;
    let mut w = candump::Writer::new(
        std::io::BufWriter::new(file),
        t.epoch_s(),
        candump::recorded_iface(t.name()),
    );
    let mut m = Monitor::new(*dec);
    let start = t.now_us();
    let end = duration_s.map(|d| start + (d * 1e6) as u64);
    let mut n = 0u64;
    loop {
        let next = t.now_us() + 1_000_000;
        let deadline = end.map_or(next, |e| e.min(next));
        let mut err = None;
        pump(t, deadline, |rx| {
            m.on_frame(rx);
            n += 1;
            if let Err(e) = w.write(rx) {
                err = Some(e);
                return false;
            }
            true
        })?;
        if let Some(e) = err {
            return Err(io(e));
        }
        host_io::out::progress_line(format_args!(
            "recording {}: {n} frames, {:.1} s",
            out.display(),
            (t.now_us() - start) as f64 * 1e-6
        ));
        if end.is_some_and(|e| t.now_us() >= e) || stop.load(Ordering::SeqCst) {
            break;
        }
    }
    w.flush().map_err(io)?;
    host_io::out::progress_end();
    say!("{n} frames written to {}", out.display());
    say!("{}", m.summary().trim_end());
    Ok((n, m))
}

/// The progress line on stderr, at most 10 times a second of the run.
fn progress(l: &Live, profile_s: f64) {
    if !l.sample.is_multiple_of(10) && l.sample != l.samples {
        return;
    }
    let share = l.sample as f64 / l.samples.max(1) as f64;
    let width = 24;
    let filled = (share * width as f64).round() as usize;
    let err = l.ref_deg - l.column_deg;
    host_io::out::progress_line(format_args!(
        "[{}{}] {:3.0} % {:>7}  t {:6.2} s / {:.1} s  ref {:+7.2} deg  column {:+7.2} deg  \
         error {:+6.2} deg  current {:+6.2} A ",
        "#".repeat(filled),
        "-".repeat(width - filled),
        share * 100.0,
        l.phase,
        l.t_s,
        profile_s,
        l.ref_deg,
        l.column_deg,
        err,
        l.current_a
    ));
}

fn confirm(text: &str) -> Result<(), BringupError> {
    eprintln!("{text}");
    eprint!("type `yes` to start: ");
    let _ = std::io::stderr().flush();
    let mut line = String::new();
    // A closed or empty stdin (a script without --yes) reads as no answer: not a yes.
    std::io::stdin()
        .lock()
        .read_line(&mut line)
        .map_err(|source| BringupError::Io {
            context: "reading the confirmation".into(),
            source,
        })?;
    if line.trim() == "yes" {
        Ok(())
    } else {
        eprintln!();
        Err(BringupError::NotConfirmed)
    }
}

fn campaign_cmd(
    t: &mut dyn Transport,
    dec: &Decoder,
    profile: Profile,
    args: &CampaignArgs,
) -> Result<CampaignOutcome, BringupError> {
    let ready = campaign::ready_check(t, dec)?;
    let plan = format!(
        "campaign on {}: {}\n  AS state claimed: Ready for the lead-in, {} for the profile, \
         Finished at the end\n  largest angle {:.2} deg, {:.1} s, {} samples limited to the \
         ECU's 400 deg/s\n  the wheel is at {:+.2} deg; log -> {}",
        t.name(),
        profile.name,
        super::decode::as_state_words(args.as_state),
        profile.max_abs_deg(),
        profile.duration_s(),
        profile.rate_limited,
        ready.status.angle.0,
        args.out.display()
    );
    if args.yes {
        eprintln!("{plan}");
    } else {
        confirm(&format!(
            "{plan}\nThe actuator will move. Keep hands off the wheel; Ctrl-C stops with the \
             drive disabled."
        ))?;
    }
    if !ready.motor_frames {
        eprintln!("steer-can: warning: no motor frame (0x102) from the ECU: motor_rad will be nan");
    }
    let c = Campaign {
        profile,
        as_state: args.as_state,
        stop: stop_flag(),
    };
    let profile_s = c.profile.duration_s();
    let run = c.run(t, dec, &ready, |l| progress(l, profile_s))?;
    host_io::out::progress_end();
    let record_path = args.record.clone().unwrap_or_else(|| {
        let mut p = args.out.clone().into_os_string();
        p.push(".candump");
        PathBuf::from(p)
    });
    candump::save(
        &record_path,
        t.epoch_s(),
        candump::recorded_iface(t.name()),
        &run.frames,
    )?;
    say!(
        "recording written to {} ({} frames)",
        record_path.display(),
        run.frames.len()
    );
    let built = run.log(dec)?;
    campaign::save_log(&built.log, &args.out)?;
    for n in &built.notes {
        say!("note: {n}");
    }
    say!(
        "log written to {} ({} rows, {:.2} s); diagnose it with `host-sim gap {}`",
        args.out.display(),
        built.log.len(),
        built.log.t.last().copied().unwrap_or(0.0),
        args.out.display()
    );
    let fin = run
        .final_status
        .map(|s| {
            format!(
                "ECU {} with faults: {}",
                super::decode::ecu_state_words(s.ecu_state),
                faults_in_words(s.faults)
            )
        })
        .unwrap_or_else(|| "no status frame at the end".into());
    match run.aborted {
        Some(reason) => say!(
            "ABORTED: {reason}; {} of {} profile samples sent; AS Finished sent; {fin}",
            run.profile_samples_sent,
            c.profile.samples.len()
        ),
        None => say!(
            "completed: {} profile samples sent; AS Finished sent; {fin}",
            run.profile_samples_sent
        ),
    }
    Ok(CampaignOutcome {
        aborted: run.aborted,
        profile_samples: c.profile.samples.len(),
        profile_samples_sent: run.profile_samples_sent,
        rate_limited: c.profile.rate_limited,
        final_status: run.final_status,
        log_rows: built.log.len(),
        recording: record_path,
    })
}

fn send(
    t: &mut dyn Transport,
    dec: &Decoder,
    as_state: Option<AsState>,
    finish: bool,
    which: &SendProfile,
    sender: &mut ReferenceSender,
) -> Result<Monitor, BringupError> {
    let stop = stop_flag();
    let (profile, as_state, clear) = match which {
        SendProfile::ClearFaults => (
            Profile::new("clear faults".into(), vec![0.0; 10], 0.0)?,
            AsState::Off,
            true,
        ),
        other => {
            let as_state = as_state.ok_or_else(|| BringupError::Profile {
                reason: "say which AS state the frames claim: --as-state ready|driving|off|..."
                    .into(),
            })?;
            let p = match other {
                SendProfile::Step {
                    amplitude_deg,
                    at_s,
                    duration_s,
                } => profile::step(*amplitude_deg, *at_s, *duration_s)?,
                SendProfile::Sine {
                    amplitude_deg,
                    freq_hz,
                    duration_s,
                } => profile::sine(*amplitude_deg, *freq_hz, *duration_s)?,
                SendProfile::Sweep(s) => profile::sweep(to_sweep(s))?,
                SendProfile::Track(tr) => profile::track(tr.csv.as_deref())?,
                SendProfile::ClearFaults => unreachable!("handled above"),
            };
            (p, as_state, false)
        }
    };
    eprintln!(
        "sending {} in AS {} on {} ({} samples limited to the ECU's 400 deg/s)",
        profile.name,
        super::decode::as_state_words(as_state),
        t.name(),
        profile.rate_limited
    );
    let mut m = Monitor::new(*dec);
    let mut next = t.now_us();
    let n = profile.samples.len();
    let mut last = 0.0;
    for (i, &angle) in profile.samples.iter().enumerate() {
        pump(t, next, |rx| {
            m.on_frame(rx);
            true
        })?;
        if stop.load(Ordering::SeqCst) {
            eprintln!("\ninterrupted");
            break;
        }
        let frame = sender.frame(angle, as_state, clear);
        t.send(&frame)?;
        m.on_frame(&super::Stamped {
            t_us: t.now_us(),
            frame,
        });
        last = angle;
        let (column, current, faults) = m
            .last_status
            .map(|(_, s)| (f64::from(s.angle.0), f64::from(s.current.0), s.faults))
            .unwrap_or((f64::NAN, f64::NAN, 0));
        if i % 10 == 9 || i + 1 == n {
            host_io::out::progress_line(format_args!(
                "{:5.2} s  ref {angle:+7.2} deg  column {column:+7.2} deg  current {current:+6.2} A  faults: {} ",
                (i + 1) as f64 / profile::RATE_HZ,
                faults_in_words(faults)
            ));
        }
        next = next.max(t.now_us()) + PERIOD_US as u64;
    }
    host_io::out::progress_end();
    if finish && as_state.actuator_may_be_powered() {
        // Leave the drive disabled rather than timing out: 0.2 s of AS Finished.
        for _ in 0..20 {
            pump(t, next, |rx| {
                m.on_frame(rx);
                true
            })?;
            t.send(&sender.frame(last, AsState::Finished, false))?;
            next = next.max(t.now_us()) + PERIOD_US as u64;
        }
        eprintln!("AS Finished sent for 0.2 s: the drive is disabled");
    }
    // Without the finish, long enough for the reference timeout to latch (30 + 100 ms).
    let tail = if finish { 3 } else { 20 };
    pump(t, next + tail * PERIOD_US as u64, |rx| {
        m.on_frame(rx);
        true
    })?;
    say!("{}", m.summary().trim_end());
    if m.last_status.is_none() {
        return Err(BringupError::EcuSilent {
            waited_ms: (profile.duration_s() * 1000.0) as u64,
        });
    }
    Ok(m)
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

    /// Two `send`s on one car in one session (`rehearse`): the second continues the first's
    /// alive counter, so the ECU's E2E check counts no jump at its first frame.
    #[cfg(feature = "sim")]
    #[test]
    fn a_second_send_in_a_session_continues_the_counter() {
        let mut sim = host_sim::sim_ecu::SimEcu::new(host_sim::sim_ecu::SimCar::DEFAULT);
        let node = NodeId::new(1).unwrap();
        let dec = decoder(node).unwrap();
        let step = Command::Send {
            as_state: Some(AsState::Driving),
            no_finish: false,
            profile: SendProfile::Step {
                amplitude_deg: 1.0,
                at_s: 0.1,
                duration_s: 0.3,
            },
        };
        let jumps =
            |sim: &host_sim::sim_ecu::SimEcu| sim.with_ecu(|e| e.e2e().drops().counter_jump);
        let mut session = ReferenceSender::default();
        execute(&step, node, &dec, &mut sim, &mut session).unwrap();
        assert_eq!(jumps(&sim), 0);
        execute(&step, node, &dec, &mut sim, &mut session).unwrap();
        assert_eq!(
            jumps(&sim),
            0,
            "the second send's first frame was a counter jump"
        );
        // A sender of its own, as a separate `steer-can send` has, starts from its own 0.
        execute(&step, node, &dec, &mut sim, &mut ReferenceSender::default()).unwrap();
        assert_eq!(jumps(&sim), 1);
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

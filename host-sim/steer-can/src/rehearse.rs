//! `steer-can rehearse`: the README's first day on the car, run on the simulated car in one
//! session, each step's result beside what the README says to expect.
//!
//! The steps are not a copy of the README's list: they are read from the README itself (built
//! into the binary), so the two cannot drift apart. Every inline `steer-can ...` command of the
//! bring-up section, in order, is parsed with the tool's own command line; one the tool no
//! longer accepts fails its step. What each step must show is the README's sentence for it,
//! checked on the values the command returns, not on its printed text.
//!
//! One session means one simulated car for all steps: a fault left by `send --no-finish` is
//! still latched when the next `monitor` looks, and `send clear-faults` clears it. The files
//! the steps write (logs, recordings, the track profile) go to `--dir`.

use super::args::{self, Cli, Command, SendProfile};
use super::commands::{self, Outcome, say};
use super::decode::{Decoder, ecu_state_words, faults_in_words, nmt_words};
use super::monitor::Monitor;
use super::{BringupError, Transport, WallPaced, simcar};
use canlink::reference::ReferenceSender;
use clap::Parser;
use host_io::scenario;
use host_sim::sim_ecu::SimEcu;
use std::path::{Path, PathBuf};
use std::sync::atomic::Ordering;
use steering_ecu::as_state::AsState;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::cia402::State;
use steering_ecu::canopen::nmt::NmtState;
use steering_ecu::faults::Fault;
use steering_ecu::steering::EcuState;

/// The README this binary was built with.
pub const README: &str = include_str!("../README.md");

/// The heading of the bring-up section.
const SECTION: &str = "### Bring-up on the car with `steer-can`";

/// `monitor` and `record` run until Ctrl-C on the car; in the rehearsal for this long, s.
const MONITOR_S: f64 = 1.0;
const RECORD_S: f64 = 3.0;

/// Status and motor frames must come at 100 Hz: the rate a one-second window measures, within
/// this share (the window's first frame falls anywhere in the first period).
const RATE_TOLERANCE: f64 = 0.02;

/// One step of the README's list.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadmeStep {
    /// The list item it is in ("3. Monitor."), or the paragraph after the list.
    pub item: String,
    /// The command as the README writes it, whitespace collapsed.
    pub command: String,
}

/// An item of the README's list without a `steer-can` command (firmware alone, interface up,
/// the diagnosis): said, not run.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadmeItem {
    pub title: String,
    pub has_steer_can: bool,
    /// The item's first inline command, if any (for the ones rehearse does not run).
    pub first_code: Option<String>,
}

/// The bring-up section's text, fenced blocks (the usage summary) left out.
fn section(readme: &str) -> Result<String, String> {
    let start = readme
        .find(SECTION)
        .ok_or_else(|| format!("the README has no section `{SECTION}`"))?;
    let body = &readme[start + SECTION.len()..];
    let mut out = String::new();
    let mut fenced = false;
    for line in body.lines() {
        if line.starts_with("## ") || line.starts_with("### ") || line.starts_with("<!--") {
            break;
        }
        if line.trim_start().starts_with("```") {
            fenced = !fenced;
            continue;
        }
        if !fenced {
            out.push_str(line);
            out.push('\n');
        }
    }
    Ok(out)
}

/// The list item a line opens: "3. **Monitor.** ..." -> "3. Monitor.".
fn item_title(line: &str) -> Option<String> {
    let (number, rest) = line.split_once(". **")?;
    if number.is_empty() || !number.chars().all(|c| c.is_ascii_digit()) {
        return None;
    }
    let title = rest.split("**").next()?;
    Some(format!("{number}. {title}"))
}

/// The items of the list and the `steer-can` commands in and after it, in the README's order
/// (the section's introduction is not the first day). A mention of `rehearse` is not a step.
pub fn first_day(readme: &str) -> Result<(Vec<ReadmeItem>, Vec<ReadmeStep>), String> {
    let text = section(readme)?;
    let mut items: Vec<ReadmeItem> = Vec::new();
    let mut steps = Vec::new();
    let mut current: Option<String> = None;
    // Inline code may run over a line break: collect spans over the whole text, remembering
    // which item each started in.
    let mut in_code = false;
    let mut code = String::new();
    for line in text.lines() {
        if !in_code {
            if let Some(title) = item_title(line) {
                items.push(ReadmeItem {
                    title: title.clone(),
                    has_steer_can: false,
                    first_code: None,
                });
                current = Some(title);
            } else if !line.trim().is_empty() && !line.starts_with(' ') && current.is_some() {
                // A paragraph after the list: record and convert.
                current = Some("After the list.".into());
            }
        }
        for (i, part) in line.split('`').enumerate() {
            if i > 0 {
                if in_code {
                    let command = code.split_whitespace().collect::<Vec<_>>().join(" ");
                    code.clear();
                    in_code = false;
                    // The section's introduction names commands too; the first day starts
                    // with the list.
                    let Some(item) = current.clone() else {
                        continue;
                    };
                    if let Some(it) = items.iter_mut().rev().find(|it| it.title == item)
                        && it.first_code.is_none()
                    {
                        it.first_code = Some(command.clone());
                    }
                    if command.starts_with("steer-can ")
                        && !command.split_whitespace().any(|w| w == "rehearse")
                    {
                        if let Some(it) = items.iter_mut().rev().find(|it| it.title == item) {
                            it.has_steer_can = true;
                        }
                        steps.push(ReadmeStep { item, command });
                    }
                    continue;
                }
                in_code = true;
            }
            if in_code {
                code.push_str(part);
            }
        }
        if in_code {
            code.push(' ');
        }
    }
    if steps.is_empty() {
        return Err("the README's bring-up section names no `steer-can` command".into());
    }
    Ok((items, steps))
}

/// The session's car, held to the wall clock or not (`--fast`).
enum Car {
    Fast(SimEcu),
    Paced(WallPaced<SimEcu>),
}

impl Car {
    fn transport(&mut self) -> &mut dyn Transport {
        match self {
            Car::Fast(s) => s,
            Car::Paced(p) => p,
        }
    }

    fn sim(&mut self) -> &mut SimEcu {
        match self {
            Car::Fast(s) => s,
            Car::Paced(p) => p.inner_mut(),
        }
    }
}

/// What the session remembers between steps, as a team on the car would.
#[derive(Debug, Default)]
struct Session {
    /// `send --no-finish` left the ECU to time out; the next monitor must see the fault.
    expect_timeout: bool,
    /// The reference frames' alive counter, continued from one `send` to the next.
    sender: ReferenceSender,
}

/// A step's verdict.
struct Verdict {
    expected: String,
    seen: String,
    pass: bool,
}

/// Runs the rehearsal; prints each step and returns whether all matched.
pub fn rehearse(outer: &Cli, dir: &Path) -> Result<Outcome, BringupError> {
    if outer.drive != args::DriveArg::Epos4 {
        return Err(BringupError::Usage {
            reason: "rehearse follows the README's list for the default firmware (EPOS4 mode); \
                     leave out --drive direct"
                .into(),
        });
    }
    let (items, steps) = first_day(README).map_err(|reason| BringupError::Usage { reason })?;
    std::fs::create_dir_all(dir).map_err(|source| BringupError::Io {
        context: format!("cannot create {}", dir.display()),
        source,
    })?;
    let node = NodeId::new(outer.node).ok_or_else(|| BringupError::Usage {
        reason: format!("--node {}: a CANopen node ID is 1 to 127", outer.node),
    })?;
    let dec = commands::decoder(node)?;
    let sim = simcar::sim_car(outer)?;
    let mut car = if outer.fast {
        Car::Fast(sim)
    } else {
        Car::Paced(WallPaced::new(sim))
    };
    say!(
        "rehearsal of the README's first day on the simulated car ({}), one session; files in {}",
        if outer.fast {
            "--fast"
        } else {
            "in wall-clock time"
        },
        dir.display()
    );
    let stop = commands::stop_flag();
    let mut session = Session::default();
    let mut passed = 0;
    let mut failed = 0;
    let mut said: Vec<&str> = Vec::new();
    for (k, step) in steps.iter().enumerate() {
        // Items before this step's that have no steer-can command: on the car only.
        for it in items.iter().take_while(|it| it.title != step.item) {
            if !it.has_steer_can && !said.contains(&it.title.as_str()) {
                say_not_rehearsed(it, dir);
                said.push(&it.title);
            }
        }
        said.push(&step.item);
        say!(
            "\n=== step {} of {}: [{}] {}",
            k + 1,
            steps.len(),
            step.item,
            step.command
        );
        let verdict = run_step(&step.command, dir, &mut car, node, &dec, &mut session);
        say!("  README expects: {}", verdict.expected);
        say!("  seen:           {}", verdict.seen);
        say!("  {}", if verdict.pass { "PASS" } else { "FAIL" });
        if verdict.pass {
            passed += 1;
        } else {
            failed += 1;
        }
        if stop.load(Ordering::SeqCst) {
            say!("interrupted");
            break;
        }
    }
    for it in &items {
        if !it.has_steer_can && !said.contains(&it.title.as_str()) {
            say_not_rehearsed(it, dir);
        }
    }
    let all_passed = failed == 0 && passed == steps.len();
    say!(
        "\nrehearsal: {passed} of {} steps match the README{}",
        steps.len(),
        if all_passed {
            ""
        } else {
            " — see FAIL above"
        }
    );
    Ok(Outcome::Rehearsed { all_passed })
}

fn say_not_rehearsed(it: &ReadmeItem, dir: &Path) {
    let what = match &it.first_code {
        Some(code) if code.contains("host-sim") && code.contains(" gap ") => format!(
            "not a steer-can step: the logs are in {}, run `{code}` there",
            dir.display()
        ),
        _ => "on the car only (no steer-can command)".into(),
    };
    say!("\n--- [{}] {what}", it.title);
}

/// Parse the README's command and run it in the session.
fn run_step(
    command: &str,
    dir: &Path,
    car: &mut Car,
    node: NodeId,
    dec: &Decoder,
    session: &mut Session,
) -> Verdict {
    let fail = |expected: &str, seen: String| Verdict {
        expected: expected.into(),
        seen,
        pass: false,
    };
    let parsed = match Cli::try_parse_from(command.split_whitespace()) {
        Ok(c) => c,
        Err(e) => {
            let first = e.to_string();
            let first = first.lines().next().unwrap_or("").to_string();
            return fail(
                "a command steer-can accepts",
                format!("the README's command does not parse: {first}"),
            );
        }
    };
    let mut command = parsed.command;
    in_dir(&mut command, dir);
    match &mut command {
        Command::Monitor { duration_s, .. } => {
            duration_s.get_or_insert(MONITOR_S);
        }
        Command::Record { duration_s, .. } => {
            duration_s.get_or_insert(RECORD_S);
        }
        Command::Campaign { kind } => {
            let (common, csv) = match kind {
                args::CampaignKind::Sweep { common, .. } => (common, None),
                args::CampaignKind::Track { common, track } => (common, track.csv.as_deref()),
            };
            // The operator's `yes`.
            common.yes = true;
            if let Some(csv) = csv
                && !csv.exists()
                && let Err(e) = write_track_profile(csv)
            {
                return fail("the track profile to send", e.to_string());
            }
        }
        _ => {}
    }
    if matches!(command, Command::Record { .. })
        && let Err(e) = simcar::vehicle_for_record(car.sim())
    {
        return fail("a vehicle computer steering", e.to_string());
    }
    let outcome = match &command {
        Command::Convert {
            candump,
            out,
            all_rows,
        } => commands::convert(candump, out, dec, *all_rows).map(Outcome::Convert),
        Command::Rehearse { .. } | Command::SimCar { .. } => {
            return fail("a first-day step", "not a step of a session".into());
        }
        other => commands::execute(other, node, dec, car.transport(), &mut session.sender),
    };
    let outcome = match outcome {
        Ok(o) => o,
        Err(e) => return fail(expected_of(&command, session), format!("error: {e}")),
    };
    judge(&command, &outcome, car, session)
}

/// The README's words for what `command` must show.
fn expected_of(command: &Command, session: &Session) -> &'static str {
    match command {
        Command::Monitor { .. } if session.expect_timeout => {
            "state `faulted` with `reference timeout` (latched within 130 ms)"
        }
        Command::Monitor { .. } => {
            "0x101 and 0x102 at 100 Hz, no CRC errors, no lost counters, ECU state idle, faults \
             none; the EPOS4's heartbeat and PDOs show too"
        }
        Command::Epos { .. } => {
            "mode 8 (CSP), the seven gains of 0x30A0/0x30A1 as Table 3 (no DIFFERS), no error; \
             the EPOS4 in Switch on disabled in AS Off"
        }
        Command::Send {
            profile: SendProfile::ClearFaults,
            ..
        } => "the fault cleared in AS Off once the cause is gone: state idle, faults none",
        Command::Send {
            no_finish: true, ..
        } => "the frames stop in AS Driving (the next monitor sees the timeout)",
        Command::Send { .. } => {
            "the wheel follows the step; then AS Finished for 0.2 s frees the wheel at once: \
             ECU idle, no fault"
        }
        Command::Campaign { .. } => {
            "the ready check, the plan, the run to the end (no fault, no EMCY): exit 0, the log \
             and the candump recording written"
        }
        Command::Record { .. } => "the raw bus in a candump -l file",
        Command::Convert { .. } => "a log from the recording's references and ECU frames",
        Command::Rehearse { .. } | Command::SimCar { .. } => "",
    }
}

fn status_words(m: &Monitor) -> String {
    match m.last_status {
        Some((_, s)) => format!(
            "state {}, faults {}",
            ecu_state_words(s.ecu_state),
            faults_in_words(s.faults)
        ),
        None => "no status frame".into(),
    }
}

fn rate_hz(m: &Monitor, kind: &str) -> f64 {
    let span_s = m
        .first_us
        .map(|f| m.last_us.saturating_sub(f) as f64 * 1e-6)
        .unwrap_or(0.0);
    let n = m.counts.get(kind).copied().unwrap_or(0);
    if span_s > 0.0 { n as f64 / span_s } else { 0.0 }
}

fn idle_without_faults(m: &Monitor) -> bool {
    matches!(m.last_status, Some((_, s)) if s.ecu_state == EcuState::Idle.code() && s.faults == 0)
}

/// Compare what the step returned with the README's expectation.
fn judge(command: &Command, outcome: &Outcome, car: &mut Car, session: &mut Session) -> Verdict {
    let expected = expected_of(command, session).to_string();
    let (seen, pass) = match (command, outcome) {
        (Command::Monitor { .. }, Outcome::Monitor(m)) if session.expect_timeout => {
            let timeout = 1u16 << Fault::ReferenceTimeout.bit();
            let pass = matches!(m.last_status,
                Some((_, s)) if s.ecu_state == EcuState::Faulted.code() && s.faults & timeout != 0);
            (status_words(m), pass)
        }
        (Command::Monitor { .. }, Outcome::Monitor(m)) => {
            let status = rate_hz(m, "status 0x101");
            let motor = rate_hz(m, "motor 0x102");
            let crc: u64 = m.crc_errors.values().sum();
            let lost = m.status_counter.lost + m.motor_counter.lost;
            let at_100 = |r: f64| (r / 100.0 - 1.0).abs() <= RATE_TOLERANCE;
            let tpdo = m.counts.get("EPOS4 TPDO1").copied().unwrap_or(0);
            let sync = m.counts.get("SYNC").copied().unwrap_or(0);
            let heartbeat = m.last_heartbeat.map(|(_, s)| s);
            let seen = format!(
                "status {status:.1} Hz, motor {motor:.1} Hz, CRC errors {crc}, lost {lost}, {}; \
                 EPOS4 heartbeat {}, {tpdo} TPDO1, {sync} SYNC",
                status_words(m),
                heartbeat.map_or("none", nmt_words)
            );
            let pass = at_100(status)
                && at_100(motor)
                && crc == 0
                && lost == 0
                && idle_without_faults(m)
                && heartbeat == Some(NmtState::Operational)
                && tpdo > 0
                && sync > 0;
            (seen, pass)
        }
        (Command::Epos { .. }, Outcome::Epos(r)) => {
            let state = State::from_statusword(r.statusword);
            let seen = format!(
                "mode {}, {} of {} gains differ, error register 0x{:02X}, error code 0x{:04X}, \
                 {}",
                r.mode,
                r.gain_mismatches(),
                r.gains.len(),
                r.error_register,
                r.error_code,
                state.map_or("CiA 402 state unknown".into(), |st| format!("{st:?}"))
            );
            let pass = r.mode == 8
                && r.gains.len() == 7
                && r.is_ok()
                && state == Some(State::SwitchOnDisabled);
            (seen, pass)
        }
        (
            Command::Send {
                profile: SendProfile::ClearFaults,
                ..
            },
            Outcome::Send(m),
        ) => {
            session.expect_timeout = false;
            (status_words(m), idle_without_faults(m))
        }
        (
            Command::Send {
                no_finish: true, ..
            },
            Outcome::Send(m),
        ) => {
            session.expect_timeout = true;
            let last = m.last_reference.map(|(_, r)| r.as_state);
            (
                match last {
                    Some(a) => format!(
                        "the last frame sent claimed AS {}",
                        super::decode::as_state_words(a)
                    ),
                    None => "no frame sent".into(),
                },
                last == Some(AsState::Driving),
            )
        }
        (Command::Send { profile, .. }, Outcome::Send(m)) => {
            let target = match profile {
                SendProfile::Step { amplitude_deg, .. } => Some(*amplitude_deg),
                _ => None,
            };
            let column = m.last_status.map(|(_, s)| f64::from(s.angle.0));
            let disabled =
                car.sim().output().demand == steering_ecu::steering::DriveDemand::Disabled;
            let seen = format!(
                "column {} deg at the end, drive {}, {}",
                column.map_or("?".into(), |c| format!("{c:+.2}")),
                if disabled { "disabled" } else { "ON" },
                status_words(m)
            );
            let followed = match (target, column) {
                (Some(t), Some(c)) => (c - t).abs() < 0.5,
                (None, Some(_)) => true,
                _ => false,
            };
            (seen, followed && disabled && idle_without_faults(m))
        }
        (Command::Campaign { .. }, Outcome::Campaign(c)) => {
            let end = c
                .final_status
                .map_or("no status frame at the end".into(), |s| {
                    format!(
                        "ECU {}, faults {}",
                        ecu_state_words(s.ecu_state),
                        faults_in_words(s.faults)
                    )
                });
            let seen = match &c.aborted {
                Some(reason) => format!(
                    "ABORTED: {reason}; {} of {} samples sent; {end}",
                    c.profile_samples_sent, c.profile_samples
                ),
                None => format!(
                    "completed, {} samples ({} limited to 400 deg/s), {} log rows, {}; {end}",
                    c.profile_samples_sent,
                    c.rate_limited,
                    c.log_rows,
                    c.recording.display()
                ),
            };
            let idle = matches!(c.final_status,
                Some(s) if s.ecu_state == EcuState::Idle.code() && s.faults == 0);
            let pass = c.aborted.is_none()
                && c.profile_samples_sent == c.profile_samples
                && c.log_rows > 0
                && c.recording.exists()
                && idle;
            (seen, pass)
        }
        (Command::Record { .. }, Outcome::Record { frames, monitor }) => {
            let refs = monitor.counts.get("reference 0x100").copied().unwrap_or(0);
            let status = monitor.counts.get("status 0x101").copied().unwrap_or(0);
            (
                format!("{frames} frames: {refs} references (0x100), {status} status (0x101)"),
                *frames > 0 && refs > 0 && status > 0,
            )
        }
        (Command::Convert { .. }, Outcome::Convert(b)) => (
            format!("{} rows from {} references", b.log.len(), b.references),
            !b.log.is_empty(),
        ),
        (_, other) => (format!("an unexpected outcome: {other:?}"), false),
    };
    Verdict {
        expected,
        seen,
        pass,
    }
}

/// The README's file names are relative: in the rehearsal they live in `dir`.
fn in_dir(command: &mut Command, dir: &Path) {
    let join = |p: &mut PathBuf| {
        if p.is_relative() {
            *p = dir.join(&*p);
        }
    };
    match command {
        Command::Campaign { kind } => match kind {
            args::CampaignKind::Sweep { common, .. } => {
                join(&mut common.out);
                if let Some(r) = &mut common.record {
                    join(r);
                }
            }
            args::CampaignKind::Track { track, common } => {
                join(&mut common.out);
                if let Some(r) = &mut common.record {
                    join(r);
                }
                if let Some(c) = &mut track.csv {
                    join(c);
                }
            }
        },
        Command::Send {
            profile: SendProfile::Track(track),
            ..
        } => {
            if let Some(c) = &mut track.csv {
                join(c);
            }
        }
        Command::Record { out, .. } => join(out),
        Command::Convert { candump, out, .. } => {
            join(candump);
            join(out);
        }
        _ => {}
    }
}

/// The track profile a team would bring (`t,ref_sw_deg`): the built-in 120 s one.
fn write_track_profile(path: &Path) -> Result<(), BringupError> {
    let mut text = String::from("t,ref_sw_deg\n");
    for (k, deg) in scenario::builtin_track().iter().enumerate() {
        text.push_str(&format!("{:.2},{deg:.4}\n", k as f64 * 0.01));
    }
    std::fs::write(path, text).map_err(|source| BringupError::Io {
        context: format!("cannot write {}", path.display()),
        source,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The README's first-day list, as rehearse reads it: the commands in the README's order.
    /// A step dropped from or added to the README changes this list and fails here, so the
    /// rehearsal's reading of the README is checked, not assumed.
    #[test]
    fn the_readme_first_day_list_is_read_in_order() {
        let (items, steps) = first_day(README).unwrap();
        let heads: Vec<String> = steps
            .iter()
            .map(|s| {
                s.command
                    .split_whitespace()
                    .skip(1)
                    .take(2)
                    .collect::<Vec<_>>()
                    .join(" ")
            })
            .collect();
        assert_eq!(
            heads,
            [
                "monitor --iface",
                "epos check",
                "send --as-state",
                "send --as-state",
                "monitor",
                "send clear-faults",
                "campaign sweep",
                "campaign track",
                "record --out",
                "convert bus.candump",
            ],
            "{steps:#?}"
        );
        assert!(steps[3].command.contains("--no-finish"), "{:?}", steps[3]);
        let titles: Vec<&str> = items.iter().map(|i| i.title.as_str()).collect();
        assert_eq!(titles.len(), 8, "{titles:?}");
        assert_eq!(steps[0].item, "3. Monitor.");
        assert_eq!(steps[8].item, "After the list.");
        assert!(!items[0].has_steer_can && !items[7].has_steer_can);
    }

    /// Every command the README names parses with the tool's own command line.
    #[test]
    fn every_readme_command_parses() {
        let (_, steps) = first_day(README).unwrap();
        for s in steps {
            if let Err(e) = Cli::try_parse_from(s.command.split_whitespace()) {
                panic!("{}: {e}", s.command);
            }
        }
    }

    #[test]
    fn a_section_without_commands_is_an_error_not_an_empty_rehearsal() {
        let readme = format!("# x\n{SECTION}\n\nnothing here\n## next\n");
        assert!(first_day(&readme).is_err());
        assert!(first_day("# no such section").is_err());
    }

    /// A command split over two lines of the README is one step.
    #[test]
    fn inline_code_over_a_line_break_is_one_command() {
        let readme = format!(
            "{SECTION}\n\n1. **One.** Run `steer-can send --as-state driving\n   step` now.\n"
        );
        let (_, steps) = first_day(&readme).unwrap();
        assert_eq!(steps.len(), 1);
        assert_eq!(steps[0].command, "steer-can send --as-state driving step");
        assert_eq!(steps[0].item, "1. One.");
    }
}

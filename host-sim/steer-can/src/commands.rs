//! What each `steer-can` command does on a bus: `monitor`, `epos check`, `send`, `record`,
//! `campaign` (`execute`) and `convert`, with the confirmation prompt, Ctrl-C and progress
//! on stderr, results on stdout. Each returns what it found ([`Outcome`]) besides printing it,
//! so `rehearse` judges values, not text.

use super::args::{CampaignArgs, CampaignKind, Command, EposCommand, SendProfile, SweepArgs};
use super::campaign::{self, Campaign, Live};
use super::decode::{Decoded, Decoder, faults_in_words};
use super::liveplot::{self, LivePlot};
use super::logbuild::{self, Rows};
use super::monitor::Monitor;
use super::profile::{self, Profile};
use super::{BringupError, Transport, candump, epos, pump, resume};
use canlink::reference::ReferenceSender;
use host_io::scenario::Sweep;
use std::io::{BufRead, Write};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use steering_ecu::as_state::AsState;
use steering_ecu::canopen::NodeId;
use steering_ecu::canopen::epos4::{Epos4Config, PositionScale};
use steering_ecu::protocol::PERIOD_US;

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
    pub(crate) fn exit_code(&self) -> ExitCode {
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
    let (file, created) = candump::create(out).map_err(io)?;
    if let Some(dir) = &created {
        say!("created directory {}", dir.display());
    }
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
    let heard = resume::listen(t, |rx| m.on_frame(rx))?;
    resume::continue_sender(sender, heard);
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

#[cfg(all(test, feature = "sim"))]
mod tests {
    use super::*;

    /// Two `send`s on one car in one session (`rehearse`): the second continues the first's
    /// alive counter, so the ECU's E2E check counts no jump at its first frame.
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
        // A sender of its own, as a separate `steer-can send` has: it continues from the
        // counter the ECU reports, not from its own 0.
        execute(&step, node, &dec, &mut sim, &mut ReferenceSender::default()).unwrap();
        assert_eq!(
            jumps(&sim),
            0,
            "a new sender's first frame was a counter jump"
        );
    }
}

//! The test campaign in one call: the ECU is checked ready, the profile is sent at 100 Hz
//! with the AS state the caller names, everything on the bus is recorded, and the run stops
//! at the first sign of trouble with the drive disabled.
//!
//! Theory of operation:
//!
//! ```text
//!  ready_check: a status frame within 1 s, no fault bit, ECU idle, nobody else sending 0x100,
//!      |       the reference counter the ECU last saw (motor frame): the run continues it
//!      |
//!      v
//!  lead-in   AS Ready, a ramp at 20 deg/s from where the wheel is to the profile's first
//!      |     sample, then 0.3 s holding it (the drive enables and settles)
//!      v
//!  profile   AS <claimed> (Driving by default), one sample per 10 ms
//!      |
//!      v
//!  settle    0.5 s holding the last sample
//!      |
//!      v
//!  finish    AS Finished for 0.2 s: the state machine disables the drive
//!
//!  at any point: a fault bit in a status frame, an EMCY from the drive, no status frame for
//!  100 ms, or the stop flag (Ctrl-C) -> straight to finish, outcome Aborted(reason)
//! ```
//!
//! Every frame sent and received is kept with its time, so the caller writes the candump
//! recording and, through [`super::logbuild`], the log.

use super::decode::{Decoded, Decoder, faults_in_words};
use super::logbuild::{self, Rows};
use super::monitor::Monitor;
use super::profile::Profile;
use super::resume::{self, LastCounter};
use super::{BringupError, Stamped, Transport, pump};
use canlink::reference::ReferenceSender;
use host_io::logfmt::Log;
use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use steering_ecu::as_state::AsState;
use steering_ecu::protocol::{PERIOD_US, Status};
use steering_ecu::steering::EcuState;

/// How long the ECU may be silent before the ready check fails, µs.
pub const READY_WAIT_US: u64 = 1_000_000;
/// How long the ECU may be silent during a run, µs.
pub const SILENT_ABORT_US: u64 = 100_000;
const LEAD_IN_RATE_DEG_PER_S: f64 = 20.0;
const LEAD_IN_HOLD_S: f64 = 0.3;
const SETTLE_S: f64 = 0.5;
const FINISH_S: f64 = 0.2;

/// What the ready check saw.
#[derive(Debug, Clone, PartialEq)]
pub struct Ready {
    pub status: Status,
    /// A motor frame (0x102) came too: the log will have `motor_rad`.
    pub motor_frames: bool,
    /// The frames seen while checking: the start of the recording.
    pub frames: Vec<Stamped>,
    /// The reference counter the ECU last saw (its motor frame): the run continues after it.
    pub last_counter: Option<LastCounter>,
}

/// Waits for the ECU and checks it may be driven.
pub fn ready_check(
    transport: &mut dyn Transport,
    decoder: &Decoder,
) -> Result<Ready, BringupError> {
    let start = transport.now_us();
    let mut status = None;
    let mut motor = false;
    let mut other_sender = false;
    let mut last_counter = None;
    let mut frames = Vec::new();
    pump(transport, start + READY_WAIT_US, |rx| {
        frames.push(*rx);
        let decoded = decoder.decode(&rx.frame);
        LastCounter::update(&mut last_counter, &decoded);
        match decoded {
            Decoded::Status(Ok(s)) => status = Some(s),
            Decoded::Motor(Ok(_)) => motor = true,
            Decoded::Reference(_) => other_sender = true,
            _ => {}
        }
        // Two status periods after the first status frame: a motor frame would be there.
        !(status.is_some() && motor)
    })?;
    let Some(status) = status else {
        return Err(BringupError::EcuSilent {
            waited_ms: READY_WAIT_US / 1000,
        });
    };
    if other_sender {
        return Err(BringupError::EcuNotReady {
            reason: "another node sends reference frames (0x100): stop the vehicle computer's \
                     steering output first"
                .into(),
        });
    }
    if status.faults != 0 {
        return Err(BringupError::EcuNotReady {
            reason: format!(
                "latched faults: {} — remove the cause, then `steer-can send clear-faults`",
                faults_in_words(status.faults)
            ),
        });
    }
    match EcuState::from_code(status.ecu_state) {
        Some(EcuState::Idle) | Some(EcuState::Standby) => {}
        _ => {
            return Err(BringupError::EcuNotReady {
                reason: format!(
                    "ECU state is {}, expected idle",
                    super::decode::ecu_state_words(status.ecu_state)
                ),
            });
        }
    }
    if !status.angle.0.is_finite() {
        return Err(BringupError::EcuNotReady {
            reason: "the column angle is not available (encoder)".into(),
        });
    }
    Ok(Ready {
        status,
        motor_frames: motor,
        frames,
        last_counter,
    })
}

/// Why a run stopped early.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum AbortReason {
    /// A status frame carried these fault bits.
    Fault { faults: u16, at_s: f64 },
    /// The drive sent an EMCY.
    Emcy { error_code: u16, at_s: f64 },
    /// No status frame for this long.
    EcuSilent { ms: u64, at_s: f64 },
    /// The stop flag (Ctrl-C).
    Interrupted { at_s: f64 },
}

impl fmt::Display for AbortReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            AbortReason::Fault { faults, at_s } => write!(
                f,
                "fault at {at_s:.2} s: {} (bits 0x{faults:04X})",
                faults_in_words(*faults)
            ),
            AbortReason::Emcy { error_code, at_s } => {
                write!(f, "EPOS4 EMCY 0x{error_code:04X} at {at_s:.2} s")
            }
            AbortReason::EcuSilent { ms, at_s } => write!(
                f,
                "no status frame for {ms} ms at {at_s:.2} s: ECU reset or bus lost"
            ),
            AbortReason::Interrupted { at_s } => write!(f, "interrupted at {at_s:.2} s"),
        }
    }
}

/// Where the run is, for the progress line.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Live {
    pub phase: &'static str,
    pub sample: usize,
    pub samples: usize,
    pub t_s: f64,
    pub ref_deg: f64,
    pub column_deg: f64,
    pub current_a: f64,
}

/// The run and what it recorded.
#[derive(Debug, Clone)]
pub struct Run {
    pub aborted: Option<AbortReason>,
    /// Every frame sent and received, in time order.
    pub frames: Vec<Stamped>,
    pub profile_samples_sent: usize,
    /// The last status frame after the finish phase.
    pub final_status: Option<Status>,
    pub monitor: Monitor,
}

impl Run {
    /// The log of the run: rows while the AS state allowed power.
    pub fn log(&self, decoder: &Decoder) -> Result<logbuild::Built, BringupError> {
        logbuild::build(&self.frames, decoder, Rows::Active)
    }
}

/// The campaign's settings.
#[derive(Debug, Clone)]
pub struct Campaign {
    pub profile: Profile,
    /// The AS state claimed while the profile runs (Driving on the car's stands).
    pub as_state: AsState,
    /// Raised by Ctrl-C.
    pub stop: Arc<AtomicBool>,
}

#[derive(Debug, Clone, Copy, PartialEq)]
struct Step {
    angle: f64,
    as_state: AsState,
    phase: &'static str,
}

impl Campaign {
    fn plan(&self, from_deg: f64) -> Vec<Step> {
        let p = &self.profile.samples;
        let first = p.first().copied().unwrap_or(0.0);
        let last = p.last().copied().unwrap_or(0.0);
        let rate = 1e6 / PERIOD_US as f64;
        let mut plan = Vec::new();
        let ramp_n = ((first - from_deg).abs() / LEAD_IN_RATE_DEG_PER_S * rate).ceil() as usize;
        for k in 1..=ramp_n {
            let s = k as f64 / ramp_n as f64;
            plan.push(Step {
                angle: from_deg + s * (first - from_deg),
                as_state: AsState::Ready,
                phase: "lead-in",
            });
        }
        for _ in 0..(LEAD_IN_HOLD_S * rate) as usize {
            plan.push(Step {
                angle: first,
                as_state: AsState::Ready,
                phase: "lead-in",
            });
        }
        for &a in p {
            plan.push(Step {
                angle: a,
                as_state: self.as_state,
                phase: "profile",
            });
        }
        for _ in 0..(SETTLE_S * rate) as usize {
            plan.push(Step {
                angle: last,
                as_state: self.as_state,
                phase: "settle",
            });
        }
        plan
    }

    /// Runs the campaign after a successful [`ready_check`]. `live` is called once per sample.
    pub fn run(
        &self,
        transport: &mut dyn Transport,
        decoder: &Decoder,
        ready: &Ready,
        mut live: impl FnMut(&Live),
    ) -> Result<Run, BringupError> {
        let plan = self.plan(f64::from(ready.status.angle.0));
        let mut sender = ReferenceSender::default();
        resume::continue_sender(&mut sender, ready.last_counter);
        let mut monitor = Monitor::new(*decoder);
        let mut frames: Vec<Stamped> = ready.frames.clone();
        let start = transport.now_us();
        let at_s = |t: u64| (t.saturating_sub(start)) as f64 * 1e-6;
        let mut last_status_us = start;
        let mut aborted: Option<AbortReason> = None;
        let mut profile_sent = 0;
        let mut last_angle = f64::from(ready.status.angle.0);
        let mut next_us = start;
        for (i, step) in plan.iter().enumerate() {
            let stop = &self.stop;
            pump(transport, next_us, |rx| {
                frames.push(*rx);
                match monitor.on_frame(rx) {
                    Decoded::Status(Ok(s)) => {
                        last_status_us = rx.t_us;
                        if s.faults != 0 {
                            aborted = Some(AbortReason::Fault {
                                faults: s.faults,
                                at_s: at_s(rx.t_us),
                            });
                        }
                    }
                    Decoded::Emcy { error_code, .. } if error_code != 0 => {
                        aborted = Some(AbortReason::Emcy {
                            error_code,
                            at_s: at_s(rx.t_us),
                        });
                    }
                    _ => {}
                }
                aborted.is_none()
            })?;
            let now = transport.now_us();
            if aborted.is_none() && now.saturating_sub(last_status_us) > SILENT_ABORT_US {
                aborted = Some(AbortReason::EcuSilent {
                    ms: (now - last_status_us) / 1000,
                    at_s: at_s(now),
                });
            }
            if aborted.is_none() && stop.load(Ordering::SeqCst) {
                aborted = Some(AbortReason::Interrupted { at_s: at_s(now) });
            }
            if aborted.is_some() {
                break;
            }
            let frame = sender.frame(step.angle, step.as_state, false);
            transport.send(&frame)?;
            frames.push(Stamped { t_us: now, frame });
            last_angle = step.angle;
            if step.phase == "profile" {
                profile_sent += 1;
            }
            let (column_deg, current_a) = monitor
                .last_status
                .map(|(_, s)| (f64::from(s.angle.0), f64::from(s.current.0)))
                .unwrap_or((f64::NAN, f64::NAN));
            live(&Live {
                phase: step.phase,
                sample: i + 1,
                samples: plan.len(),
                t_s: at_s(now),
                ref_deg: step.angle,
                column_deg,
                current_a,
            });
            next_us = next_us.max(now) + PERIOD_US as u64;
            // Catch up without bursts if the host fell behind (one frame per period at most).
            if next_us < transport.now_us() {
                next_us = transport.now_us();
            }
        }
        // Finish: AS Finished at the last angle sent, so the state machine disables the drive.
        let finish_n = (FINISH_S * 1e6 / PERIOD_US as f64) as usize;
        let mut final_status = None;
        for _ in 0..finish_n {
            pump(transport, next_us, |rx| {
                frames.push(*rx);
                if let Decoded::Status(Ok(s)) = monitor.on_frame(rx) {
                    final_status = Some(s);
                }
                true
            })?;
            let now = transport.now_us();
            let frame = sender.frame(last_angle, AsState::Finished, false);
            transport.send(&frame)?;
            frames.push(Stamped { t_us: now, frame });
            next_us = now.max(next_us) + PERIOD_US as u64;
        }
        // One more status period, to see the ECU disabled.
        pump(transport, next_us + 2 * PERIOD_US as u64, |rx| {
            frames.push(*rx);
            if let Decoded::Status(Ok(s)) = monitor.on_frame(rx) {
                final_status = Some(s);
            }
            true
        })?;
        Ok(Run {
            aborted,
            frames,
            profile_samples_sent: profile_sent,
            final_status,
            monitor,
        })
    }
}

/// Writes `log` to `path` (`.csv.gz` compressed).
pub fn save_log(log: &Log, path: &std::path::Path) -> Result<(), BringupError> {
    log.save(path).map_err(|e| BringupError::Log {
        reason: e.to_string(),
    })
}

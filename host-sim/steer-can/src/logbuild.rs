//! A recording (reference, status and motor frames with their times) as a log in the project's
//! format: one row per reference period, `t,ref_sw_deg,sw_deg,motor_rad,current_a`, plus
//! `as_state`, `ecu_state` and `faults` columns.
//!
//! Timing, so that a log means what a simulated one means (host-sim/README.md, the log format: the
//! angles are instants at the row's time, the current is the mean over the interval that ends
//! there):
//!
//! - The time axis is the reference grid: reference `k` (counted from the first, lost frames
//!   leave a gap) is in force over the period that ends at the row `t = (k + 1) x 10 ms`,
//!   whatever the jitter of the sender.
//! - The ECU pushes a sample into its interpolator when the frame arrives, one frame time
//!   after it was sent ([`BUS_LATENCY_US`]); the period runs from the push. Each signal is read
//!   from the ECU's frames at the instant the row stands for, each frame's value dated when
//!   the ECU measured it rather than when the frame arrived:
//!
//! ```text
//! signal      | frame | measured at                          | read at
//! ------------+-------+--------------------------------------+------------------------------
//! sw_deg      | 0x101 | the previous 2 ms encoder tick:      | push + 10 ms (the period's
//!             |       | 2 ms before the frame                | end, an instant)
//! motor_rad   | 0x102 | the last 0.5 ms position tick:       | push + 10 ms
//!             |       | 0.25 ms before on average            |
//! current_a   | 0x102 | mean over the 10 ms status period:   | push + 5 ms (the middle of
//!             |       | its middle, 5 ms before              | the period it averages)
//! ```
//!
//! In EPOS4 mode the ECU measures neither: its motor frame forwards the drive's TPDO1 position
//! (0x6064) and TPDO2 averaged current (0x30D1), which the drive sampled at the SYNC it
//! answered, up to a period before the motor frame. When the recording holds those PDOs, each
//! motor frame's angle and current are dated when the latest TPDO1 and TPDO2 arrived, not by
//! the ages above (which, in a simulated EPOS4-mode car, put the motor angle 7 ms and the
//! current 9 ms late against the column, and the diagnosis then read a 10.7 ms `delay_current`
//! into a car with none). Without motor frames the PDOs themselves stand in, dated the same
//! way. Without either (an older firmware), `motor_rad` is `nan` and the current comes from
//! the status frame (one sample, 20 mA). The notes say which.

use super::decode::{Decoded, Decoder};
use super::{BringupError, Stamped};
use host_io::logfmt::{Log, Row};
use steering_ecu::as_state::AsState;
use steering_ecu::protocol::PERIOD_US;

/// One 8-byte frame on the bus at 1 Mbit/s with stuff bits, µs.
pub const BUS_LATENCY_US: u64 = 130;
/// Age of the column-encoder sample in a status frame, µs (one 2 ms encoder period).
pub const ENCODER_AGE_US: u64 = 2_000;
/// Age of the motor angle in a motor frame, µs (half the 0.5 ms position period).
pub const MOTOR_AGE_US: u64 = 250;
/// Age of the mean current in a motor frame, µs (half the 10 ms status period).
pub const CURRENT_AGE_US: u64 = PERIOD_US as u64 / 2;
/// Where each signal is read after the push, µs (see the table above): the angles at the
/// period's end, the period's mean current at its middle.
const SW_AT_US: f64 = 10_000.0;
const MOTOR_AT_US: f64 = 10_000.0;
const CURRENT_CENTRE_US: f64 = 5_000.0;

/// Which reference periods become rows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rows {
    /// Every reference frame.
    All,
    /// Only frames claiming AS Ready or Driving (the drive may be powered).
    Active,
}

/// The log and what went into it.
#[derive(Debug, Clone)]
pub struct Built {
    pub log: Log,
    pub references: usize,
    pub invalid_frames: usize,
    /// Rows dropped at the ends, outside the span the ECU's frames cover.
    pub uncovered: usize,
    pub notes: Vec<String>,
}

/// A time series of one signal, sample times in µs, sorted.
#[derive(Debug, Default)]
struct Series {
    t: Vec<f64>,
    v: Vec<f64>,
}

impl Series {
    fn push(&mut self, t_us: u64, age_us: u64, v: f64) {
        let t = t_us as f64 - age_us as f64;
        // Frames come in order; a late one (bus delay) is kept out of order-sensitive search.
        if self.t.last().is_none_or(|last| t > *last) {
            self.t.push(t);
            self.v.push(v);
        }
    }

    fn covers(&self, t: f64) -> bool {
        matches!((self.t.first(), self.t.last()), (Some(a), Some(b)) if *a <= t && t <= *b)
    }

    /// Linear interpolation; `None` outside the span.
    fn at(&self, t: f64) -> Option<f64> {
        if !self.covers(t) {
            return None;
        }
        let j = self.t.partition_point(|x| *x < t);
        if j == 0 {
            return Some(self.v[0]);
        }
        let (t0, t1) = (self.t[j - 1], self.t[j]);
        let s = if t1 > t0 { (t - t0) / (t1 - t0) } else { 1.0 };
        Some(self.v[j - 1] + s * (self.v[j] - self.v[j - 1]))
    }

    /// The last sample at or before `t` (states and fault bits are not interpolated).
    fn before(&self, t: f64) -> Option<f64> {
        let j = self.t.partition_point(|x| *x <= t);
        (j > 0).then(|| self.v[j - 1])
    }
}

/// The fewest frames, and the shortest span (µs), over which [`grid_drift`] reads a drift.
const DRIFT_MIN_FRAMES: usize = 100;
const DRIFT_MIN_SPAN_US: f64 = 5e6;

/// The period of a train of frames sent every `nominal` µs (some may be lost), µs: the
/// least-squares slope of their times on their period counts, each count the last one plus
/// the whole periods in the gap (so a grid that walks a period or more over the recording is
/// still counted right). `None` where more than one gap in ten is no whole number of periods
/// (within a quarter): no such train.
fn grid_period(t: &[f64], nominal: f64) -> Option<f64> {
    let (&first, &last) = (t.first()?, t.last()?);
    if t.len() < DRIFT_MIN_FRAMES || last - first < DRIFT_MIN_SPAN_US || nominal <= 0.0 {
        return None;
    }
    let (counts, off_grid) = host_io::grid::places_by_gaps(t, nominal);
    if off_grid * 10 > t.len() {
        return None;
    }
    let (_, period) = host_io::grid::line_through(t, &counts)?;
    (period > 0.5 * nominal && period < 1.5 * nominal).then_some(period)
}

/// How fast the SYNC grid (the drive's TPDO1 times, `tpdo_us`) walks against the reference
/// frames (`reference_us`), s per s: its period over theirs, less one. `None` where either is
/// too short to tell (under 100 frames or 5 s) or is no train of `nominal_us` periods.
pub fn grid_drift(tpdo_us: &[f64], reference_us: &[f64], nominal_us: f64) -> Option<f64> {
    let sync = grid_period(tpdo_us, nominal_us)?;
    let reference = grid_period(reference_us, nominal_us)?;
    Some(sync / reference - 1.0)
}

/// The rows over which [`column_sampled_us`] reads where the column's samples sit: the first
/// 10 s (the diagnosis fits an EPOS4 car's SYNC phase on the same head).
const COLUMN_SAMPLED_ROWS: usize = 1000;

/// How long before each row's end (µs) the last column sample before it was taken, the median
/// over the first rows: one number for the log, as the diagnosis reads it. `None` without a
/// row that has a sample before its end.
fn column_sampled_us(samples_us: &[f64], row_ends_us: &[f64]) -> Option<f64> {
    let mut ages: Vec<f64> = row_ends_us
        .iter()
        .take(COLUMN_SAMPLED_ROWS)
        .filter_map(|&end| {
            let j = samples_us.partition_point(|t| *t <= end);
            (j > 0).then(|| end - samples_us[j - 1])
        })
        .collect();
    ages.sort_by(f64::total_cmp);
    ages.get(ages.len() / 2).copied()
}

/// The log of `frames` (in time order), rows per `rows`.
pub fn build(frames: &[Stamped], decoder: &Decoder, rows: Rows) -> Result<Built, BringupError> {
    let mut refs: Vec<(u64, f64, AsState)> = Vec::new();
    let (mut sw, mut status_current, mut state, mut faults) = (
        Series::default(),
        Series::default(),
        Series::default(),
        Series::default(),
    );
    let (mut motor, mut current) = (Series::default(), Series::default());
    // EPOS4 mode: the drive's own position (TPDO1) and current (TPDO2), if no motor frame.
    let (mut epos_motor, mut epos_current) = (Series::default(), Series::default());
    // When the latest TPDO1 / TPDO2 were sent (EPOS4 mode): a motor frame forwards them.
    let (mut tpdo1_sent, mut tpdo2_sent): (Option<u64>, Option<u64>) = (None, None);
    let mut invalid = 0;
    for f in frames {
        match decoder.decode(&f.frame) {
            Decoded::Reference(Ok(r)) => refs.push((f.t_us, f64::from(r.angle.0), r.as_state)),
            Decoded::Status(Ok(s)) => {
                let sent = f.t_us.saturating_sub(BUS_LATENCY_US);
                sw.push(sent, ENCODER_AGE_US, f64::from(s.angle.0));
                status_current.push(sent, 0, f64::from(s.current.0));
                state.push(sent, 0, f64::from(s.ecu_state));
                faults.push(sent, 0, f64::from(s.faults));
            }
            Decoded::Motor(Ok(m)) => {
                let sent = f.t_us.saturating_sub(BUS_LATENCY_US);
                match tpdo1_sent {
                    Some(t) => motor.push(t, 0, f64::from(m.angle.0)),
                    None => motor.push(sent, MOTOR_AGE_US, f64::from(m.angle.0)),
                }
                match tpdo2_sent {
                    Some(t) => current.push(t, 0, f64::from(m.current_mean.0)),
                    None => current.push(sent, CURRENT_AGE_US, f64::from(m.current_mean.0)),
                }
            }
            Decoded::EposTpdo1 { motor_rad, .. } => {
                let sent = f.t_us.saturating_sub(BUS_LATENCY_US);
                tpdo1_sent = Some(sent);
                epos_motor.push(sent, 0, motor_rad)
            }
            Decoded::EposTpdo2 { current_a } => {
                let sent = f.t_us.saturating_sub(BUS_LATENCY_US);
                tpdo2_sent = Some(sent);
                epos_current.push(sent, 0, current_a)
            }
            Decoded::Reference(Err(_)) | Decoded::Status(Err(_)) | Decoded::Motor(Err(_)) => {
                invalid += 1
            }
            _ => {}
        }
    }
    if sw.t.is_empty() {
        return Err(BringupError::Log {
            reason: "no valid status frame (0x101) in the recording".into(),
        });
    }
    if refs.is_empty() {
        return Err(BringupError::Log {
            reason: "no valid reference frame (0x100) in the recording".into(),
        });
    }
    let mut notes = Vec::new();
    if !motor.t.is_empty() && (tpdo1_sent.is_some() || tpdo2_sent.is_some()) {
        notes.push(
            "EPOS4 mode: the motor frames' angle and current are the drive's TPDO1 and TPDO2, \
             dated when those arrived"
                .to_string(),
        );
    }
    // Each TPDO1 answers a SYNC; read before the PDOs may become the motor series.
    let sync_drift = grid_drift(
        &epos_motor.t,
        &refs.iter().map(|r| r.0 as f64).collect::<Vec<_>>(),
        PERIOD_US as f64,
    );
    let from_epos = motor.t.is_empty() && !epos_motor.t.is_empty() && !epos_current.t.is_empty();
    if from_epos {
        notes.push(
            "no motor frame (0x102): motor_rad and current_a are the EPOS4's TPDO1 position \
             and TPDO2 current (EPOS4 mode), dated when they arrived"
                .to_string(),
        );
        motor = epos_motor;
        current = epos_current;
    }
    let have_motor = !motor.t.is_empty();
    if !have_motor {
        notes.push(
            "no motor frame (0x102) and no EPOS4 PDOs: motor_rad is nan and current_a is the \
             status frame's single sample (20 mA); update the ECU firmware"
                .to_string(),
        );
    }
    let period = PERIOD_US as f64;
    let mut log = Log::with_extra_columns(&["as_state", "ecu_state", "faults"]);
    let first_us = refs[0].0 as f64;
    let mut last_k: Option<u64> = None;
    let mut origin_k: Option<u64> = None;
    let mut uncovered = 0;
    let mut row_ends_us: Vec<f64> = Vec::new();
    for &(t_us, angle, as_state) in &refs {
        if rows == Rows::Active && !as_state.actuator_may_be_powered() {
            continue;
        }
        // The period this sample belongs to, on the sender's 10 ms grid.
        let k = ((t_us as f64 - first_us) / period).round().max(0.0) as u64;
        if last_k.is_some_and(|last| k <= last) {
            continue; // two frames in one period: the first one counts
        }
        let push = t_us as f64 + BUS_LATENCY_US as f64;
        let values = if have_motor {
            (
                sw.at(push + SW_AT_US),
                motor.at(push + MOTOR_AT_US),
                current.at(push + CURRENT_CENTRE_US),
            )
        } else {
            (
                sw.at(push + SW_AT_US),
                Some(f64::NAN),
                status_current.at(push + CURRENT_CENTRE_US),
            )
        };
        let (Some(sw_deg), Some(motor_rad), Some(current_a)) = values else {
            uncovered += 1;
            continue;
        };
        last_k = Some(k);
        row_ends_us.push(push + SW_AT_US);
        let k0 = *origin_k.get_or_insert(k);
        let mid = push + CURRENT_CENTRE_US;
        log.push(
            Row {
                t: (k - k0 + 1) as f64 * period * 1e-6,
                ref_sw_deg: angle,
                sw_deg,
                motor_rad,
                current_a,
            },
            &[
                f64::from(as_state.code()),
                state.before(mid).unwrap_or(f64::NAN),
                faults.before(mid).unwrap_or(f64::NAN),
            ],
        );
    }
    // What the diagnosis needs to know of the car: the drive shows on the bus (an EPOS4
    // answers the ECU's SYNCs with TPDOs); the ECU's controller does not, and is left to the
    // diagnosis to fit unless the caller knows it.
    let drive = if tpdo1_sent.is_some() || tpdo2_sent.is_some() {
        "epos4"
    } else {
        "direct"
    };
    log.comments.push(format!("drive: {drive}"));
    // `sync-sample`: the drive's TPDO2 current at each SYNC, read at the middle of the row's
    // period; `interval-mean`: the mean over the row's period (the ECU's own 0x102 current).
    log.comments.push(format!(
        "current: {}",
        if drive == "epos4" {
            "sync-sample"
        } else {
            "interval-mean"
        }
    ));
    // The reference in force over the period that ends at the row's t.
    log.comments.push("reference: period-ending".to_string());
    // The ECU's SYNC grid runs on the ECU's clock, the reference frames on the vehicle
    // computer's: how fast the one walks against the other, read from the bus.
    if let Some(d) = sync_drift.filter(|_| drive == "epos4") {
        log.comments
            .push(format!("sync-drift: {:+.1} ppm", 1e6 * d));
    }
    // The column at each row's end is read off a line between the status frames' samples;
    // where those sit against the rows is the ECU's clock's, and the diagnosis's model of an
    // EPOS4 car reads its column the same way from this line.
    if let Some(a) = column_sampled_us(&sw.t, &row_ends_us).filter(|_| drive == "epos4") {
        log.comments.push(format!(
            "column-sampled: {:.2} ms before each row's end",
            a * 1e-3
        ));
    }
    if log.is_empty() {
        return Err(BringupError::Log {
            reason: match rows {
                Rows::Active => {
                    "no reference in AS Ready or Driving while the ECU was reporting".into()
                }
                Rows::All => "no reference while the ECU was reporting".into(),
            },
        });
    }
    Ok(Built {
        log,
        references: refs.len(),
        invalid_frames: invalid,
        uncovered,
        notes,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use steering_ecu::can::{Frame, StandardId};
    use steering_ecu::canopen::NodeId;
    use steering_ecu::canopen::epos4::PositionScale;
    use steering_ecu::protocol::{AliveCounter, MotorStatus, ProtocolConfig, Reference, Status};
    use steering_ecu::units::{Amps, MotorRad, SteeringDeg};

    fn frames(with_epos: bool) -> Vec<Stamped> {
        let cfg = ProtocolConfig::DEFAULT;
        let mut out = Vec::new();
        for k in 0..20u64 {
            let c = AliveCounter::wrapping(k as u8);
            out.push(Stamped {
                t_us: k * 10_000,
                frame: cfg.encode_reference(&Reference {
                    angle: SteeringDeg(1.0),
                    as_state: AsState::Driving,
                    counter: c,
                    clear_faults: false,
                }),
            });
            out.push(Stamped {
                t_us: k * 10_000 + 3_000,
                frame: cfg.encode_status(&Status {
                    angle: SteeringDeg(1.0),
                    current: Amps(0.5),
                    ecu_state: 2,
                    faults: 0,
                    counter: c,
                }),
            });
            if with_epos {
                let mut tpdo1 = vec![0x37, 0x02];
                tpdo1.extend_from_slice(&42i32.to_le_bytes()); // half a turn at 84 inc/rev
                let tpdo2 = 1500i32.to_le_bytes(); // mA
                for (id, data) in [(0x181u16, &tpdo1[..]), (0x281, &tpdo2[..])] {
                    out.push(Stamped {
                        t_us: k * 10_000 + 1_000,
                        frame: Frame::new(StandardId::new(id).unwrap(), data).unwrap(),
                    });
                }
            }
        }
        out.sort_by_key(|f| f.t_us);
        out
    }

    fn decoder() -> Decoder {
        Decoder::new(NodeId::new(1).unwrap(), PositionScale::new(84).unwrap())
    }

    /// Frames sent every 10 ms x (1 + `drift`) from `phase_us`, one in 50 lost, each stamped
    /// up to 40 us late (a receiver's jitter).
    fn train(n: u64, drift: f64, phase_us: f64) -> Vec<f64> {
        (0..n)
            .filter(|k| k % 50 != 7)
            .map(|k| phase_us + k as f64 * 10_000.0 * (1.0 + drift) + ((k * 37) % 41) as f64)
            .collect()
    }

    #[test]
    fn a_sync_grid_that_walks_against_the_references_is_read_from_their_times() {
        for drift in [0.0, 35e-6, -91e-6, 2e-4] {
            let got = grid_drift(
                &train(3000, drift, 1_850.0),
                &train(3000, 0.0, 0.0),
                10_000.0,
            )
            .unwrap();
            assert!((got - drift).abs() < 0.5e-6, "{drift}: read {got}");
        }
        // Both on a clock 100 ppm fast: no walk between them.
        let got = grid_drift(&train(3000, 1e-4, 900.0), &train(3000, 1e-4, 0.0), 10_000.0).unwrap();
        assert!(got.abs() < 0.5e-6, "{got}");
    }

    /// A recording of `periods` reference periods in EPOS4 mode (no motor frames), the
    /// drive's PDOs on a SYNC grid `drift` off the references'.
    fn epos4_recording(periods: u64, drift: f64) -> Vec<Stamped> {
        let cfg = ProtocolConfig::DEFAULT;
        let mut out = Vec::new();
        for k in 0..periods {
            let c = AliveCounter::wrapping(k as u8);
            out.push(Stamped {
                t_us: k * 10_000,
                frame: cfg.encode_reference(&Reference {
                    angle: SteeringDeg(1.0),
                    as_state: AsState::Driving,
                    counter: c,
                    clear_faults: false,
                }),
            });
            out.push(Stamped {
                t_us: k * 10_000 + 3_000,
                frame: cfg.encode_status(&Status {
                    angle: SteeringDeg(1.0),
                    current: Amps(0.5),
                    ecu_state: 2,
                    faults: 0,
                    counter: c,
                }),
            });
            let sync = (1_850.0 + k as f64 * 10_000.0 * (1.0 + drift)) as u64;
            let mut tpdo1 = vec![0x37, 0x02];
            tpdo1.extend_from_slice(&42i32.to_le_bytes());
            let tpdo2 = 1500i32.to_le_bytes();
            for (id, data, after) in [(0x181u16, &tpdo1[..], 160), (0x281, &tpdo2[..], 280)] {
                out.push(Stamped {
                    t_us: sync + after,
                    frame: Frame::new(StandardId::new(id).unwrap(), data).unwrap(),
                });
            }
        }
        out.sort_by_key(|f| f.t_us);
        out
    }

    /// The header line of the log built from `frames` that starts with `key`.
    fn header_line(frames: &[Stamped], key: &str) -> Option<String> {
        let built = build(frames, &decoder(), Rows::Active).unwrap();
        built
            .log
            .comments
            .iter()
            .find(|c| c.starts_with(key))
            .cloned()
    }

    #[test]
    fn an_epos4_log_says_how_fast_its_sync_grid_walks() {
        let drift_line = |frames: &[Stamped]| header_line(frames, "sync-drift");
        assert_eq!(
            drift_line(&epos4_recording(1000, 50e-6)).as_deref(),
            Some("sync-drift: +50.0 ppm")
        );
        assert_eq!(
            drift_line(&epos4_recording(1000, -91e-6)).as_deref(),
            Some("sync-drift: -91.0 ppm")
        );
        // Too short a recording to tell (20 periods), and a direct-drive one (no PDOs).
        assert_eq!(drift_line(&epos4_recording(20, 50e-6)), None);
        assert_eq!(drift_line(&frames(false)), None);
    }

    #[test]
    fn an_epos4_log_says_where_the_status_frames_sampled_its_column() {
        let line = |frames: &[Stamped]| header_line(frames, "column-sampled");
        // Status frames 3 ms after each reference: sent 0.13 ms before they arrive, the sample
        // dated 2 ms before that, 0.87 ms after the reference; each row ends 10 ms after the
        // reference's push (0.13 ms after it was sent): 9.26 ms after the last sample.
        assert_eq!(
            line(&epos4_recording(200, 0.0)).as_deref(),
            Some("column-sampled: 9.26 ms before each row's end")
        );
        // A direct-drive log: its model reads no such line.
        assert_eq!(line(&frames(false)), None);
    }

    #[test]
    fn too_few_frames_or_too_short_a_span_read_no_drift() {
        assert_eq!(
            grid_drift(&train(60, 1e-4, 0.0), &train(3000, 0.0, 0.0), 10_000.0),
            None
        );
        assert_eq!(grid_drift(&train(3000, 1e-4, 0.0), &[], 10_000.0), None);
        // 400 frames packed into 4 s (every 10 ms, but the span is under 5 s).
        assert_eq!(
            grid_drift(&train(400, 0.0, 0.0), &train(3000, 0.0, 0.0), 10_000.0),
            None
        );
        // Frames whose times are not a 10 ms train at all.
        let wild: Vec<f64> = (0..1000).map(|k| f64::from(k) * 25_000.0).collect();
        assert_eq!(grid_drift(&wild, &train(3000, 0.0, 0.0), 10_000.0), None);
    }

    #[test]
    fn epos4_pdos_stand_in_for_the_motor_frame() {
        let built = build(&frames(true), &decoder(), Rows::Active).unwrap();
        assert!(built.notes[0].contains("TPDO1"), "{:?}", built.notes);
        assert!(built.log.len() > 15);
        for (m, i) in built.log.motor_rad.iter().zip(&built.log.current_a) {
            assert!((m - std::f64::consts::PI).abs() < 1e-6, "{m}");
            assert!((i - 1.5).abs() < 1e-6, "{i}"); // mA through f32
        }
    }

    #[test]
    fn in_epos4_mode_a_motor_frame_is_dated_by_the_pdos_it_forwards() {
        // The drive answers each SYNC (1 ms into the period) with its position and current;
        // the ECU forwards both in its motor frame 7 ms later. Both ramp by one unit a
        // period, so a row's value tells the instant it was read at and the instant its
        // sample was dated at.
        let cfg = ProtocolConfig::DEFAULT;
        let mut frames = frames(false);
        for k in 0..20u64 {
            let v = k as f64;
            let mut tpdo1 = vec![0x37, 0x02];
            // 84 inc/rev: 1 rad is 84 / 2 pi increments; whole increments only.
            tpdo1.extend_from_slice(&(k as i32 * 84).to_le_bytes());
            let tpdo2 = (k as i32 * 1000).to_le_bytes();
            for (id, data) in [(0x181u16, &tpdo1[..]), (0x281, &tpdo2[..])] {
                frames.push(Stamped {
                    t_us: k * 10_000 + 1_000 + BUS_LATENCY_US,
                    frame: Frame::new(StandardId::new(id).unwrap(), data).unwrap(),
                });
            }
            frames.push(Stamped {
                t_us: k * 10_000 + 8_000,
                frame: cfg.encode_motor(&MotorStatus {
                    angle: MotorRad((v * std::f64::consts::TAU) as f32),
                    current_mean: Amps(v as f32),
                    counter: AliveCounter::wrapping(k as u8),
                    reference_counter: AliveCounter::wrapping(k as u8),
                }),
            });
        }
        frames.sort_by_key(|f| f.t_us);
        let built = build(&frames, &decoder(), Rows::Active).unwrap();
        assert!(built.notes[0].contains("TPDO1"), "{:?}", built.notes);
        // Row k: the period from the push at k x 10 ms + 130 us; the current is read at its
        // middle (5.13 ms), the angle at its end (10.13 ms); samples dated 1 ms in: k + 0.413
        // and k + 0.913. Dated by the motor frame's own ages they would read k + 0.226 and
        // k + 0.251.
        for (k, (m, i)) in built
            .log
            .motor_rad
            .iter()
            .zip(&built.log.current_a)
            .enumerate()
            .skip(1)
            .take(15)
        {
            let k = k as f64;
            assert!((i - (k + 0.413)).abs() < 0.01, "row {k}: current {i}");
            let turns = m / std::f64::consts::TAU;
            assert!(
                (turns - (k + 0.913)).abs() < 0.01,
                "row {k}: motor {turns} turns"
            );
        }
    }

    #[test]
    fn without_motor_frames_or_pdos_the_log_says_so() {
        let built = build(&frames(false), &decoder(), Rows::Active).unwrap();
        assert!(built.notes[0].contains("nan"), "{:?}", built.notes);
        assert!(built.log.motor_rad.iter().all(|m| m.is_nan()));
        assert!(built.log.current_a.iter().all(|i| (i - 0.5).abs() < 1e-6));
    }
}

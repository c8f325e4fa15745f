//! The references the actuator is run against, as 100 Hz samples at the steering wheel (deg):
//! the paper's sine sweep (section 4.2), a driverless track run (section 4.4) and a step.

use crate::logfmt::{LogError, Reads, Table, TimeOrder};
use std::f64::consts::PI;
use std::path::Path;
use steering_ecu::paper_mode::REFERENCE_HZ;

/// Reference samples per second: the vehicle computer's rate, one sample per frame.
pub const REFERENCE_RATE_HZ: f64 = REFERENCE_HZ as f64;

/// Linear chirp `A sin(2 pi (f0 t + (f1 - f0) t^2 / (2 T)))`, sampled at 100 Hz over `[0, T]`.
/// The paper's sweep is 0 -> 10 Hz in 10 s at 10 deg (section 4.2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sweep {
    pub amplitude_deg: f64,
    pub f_start_hz: f64,
    pub f_end_hz: f64,
    pub duration_s: f64,
}

impl Sweep {
    pub const PAPER: Sweep = Sweep {
        amplitude_deg: 10.0,
        f_start_hz: 0.0,
        f_end_hz: 10.0,
        duration_s: 10.0,
    };

    pub fn samples(&self) -> Vec<f64> {
        let n = (self.duration_s * REFERENCE_RATE_HZ).round() as usize + 1;
        let rate = (self.f_end_hz - self.f_start_hz) / self.duration_s;
        (0..n)
            .map(|k| {
                let t = k as f64 / REFERENCE_RATE_HZ;
                self.amplitude_deg * (2.0 * PI * (self.f_start_hz * t + 0.5 * rate * t * t)).sin()
            })
            .collect()
    }
}

/// A step of `amplitude_deg` at `at_s`, held until `duration_s`.
pub fn step(amplitude_deg: f64, at_s: f64, duration_s: f64) -> Vec<f64> {
    let n = (duration_s * REFERENCE_RATE_HZ).round() as usize + 1;
    (0..n)
        .map(|k| {
            if k as f64 / REFERENCE_RATE_HZ >= at_s {
                amplitude_deg
            } else {
                0.0
            }
        })
        .collect()
}

/// A built-in driverless run of about 120 s at 5 km/h, shaped like the paper's MPC output
/// (Figure 10): straights with small corrections, corners of 20-75 deg at the wheel, a slalom,
/// a hairpin, a sharp correction near 89 s and a burst of content above 4 Hz near 111 s.
/// Deterministic: the same samples on every machine. Every sine segment spans whole cycles,
/// so the profile has no jumps (`builtin_track_has_no_jumps`).
pub fn builtin_track() -> Vec<f64> {
    // (start s, end s, shape)
    enum Shape {
        Hold(f64),
        Ramp(f64, f64),
        Sine { amp: f64, hz: f64, offset: f64 },
    }
    use Shape::*;
    let segments: &[(f64, f64, Shape)] = &[
        (0.0, 4.0, Hold(0.0)),
        (4.0, 6.0, Ramp(0.0, 35.0)),
        (6.0, 12.0, Hold(35.0)),
        (12.0, 14.0, Ramp(35.0, 0.0)),
        (14.0, 20.0, Hold(0.0)),
        (20.0, 21.5, Ramp(0.0, -50.0)),
        (21.5, 27.0, Hold(-50.0)),
        (27.0, 29.0, Ramp(-50.0, 0.0)),
        (
            29.0,
            45.0,
            Sine {
                amp: 30.0,
                hz: 0.25,
                offset: 0.0,
            },
        ),
        (45.0, 50.0, Hold(0.0)),
        (50.0, 51.5, Ramp(0.0, 75.0)),
        (51.5, 57.0, Hold(75.0)),
        (57.0, 59.0, Ramp(75.0, 10.0)),
        (59.0, 64.0, Ramp(10.0, -20.0)),
        (64.0, 70.0, Hold(-20.0)),
        (70.0, 72.0, Ramp(-20.0, 0.0)),
        (
            72.0,
            86.0,
            Sine {
                amp: 40.0,
                hz: 0.5,
                offset: 0.0,
            },
        ),
        (86.0, 88.8, Hold(0.0)),
        (88.8, 89.2, Ramp(0.0, 25.0)),
        (89.2, 89.6, Ramp(25.0, 5.0)),
        (89.6, 95.0, Ramp(5.0, -30.0)),
        (95.0, 100.0, Hold(-30.0)),
        (100.0, 102.0, Ramp(-30.0, 0.0)),
        (
            102.0,
            110.0,
            Sine {
                amp: 15.0,
                hz: 0.625,
                offset: 0.0,
            },
        ),
        (
            110.0,
            112.0,
            Sine {
                amp: 10.0,
                hz: 4.5,
                offset: 0.0,
            },
        ),
        (112.0, 115.0, Ramp(0.0, 20.0)),
        (115.0, 118.0, Ramp(20.0, 0.0)),
        (118.0, 120.0, Hold(0.0)),
    ];
    let n = (120.0 * REFERENCE_RATE_HZ) as usize + 1;
    // Small, smooth MPC corrections: a deterministic sum of slow sines (0.5 deg).
    let jitter = |t: f64| 0.3 * (2.0 * PI * 0.9 * t).sin() + 0.2 * (2.0 * PI * 1.7 * t + 1.0).sin();
    (0..n)
        .map(|k| {
            let t = k as f64 / REFERENCE_RATE_HZ;
            let base = segments
                .iter()
                .find(|(a, b, _)| t >= *a && t < *b)
                .map(|(a, b, shape)| match shape {
                    Hold(v) => *v,
                    Ramp(from, to) => {
                        // cosine ramp: smooth in position and velocity, as a planner outputs
                        let s = (t - a) / (b - a);
                        from + (to - from) * 0.5 * (1.0 - (PI * s).cos())
                    }
                    Sine { amp, hz, offset } => offset + amp * (2.0 * PI * hz * (t - a)).sin(),
                })
                .unwrap_or(0.0);
            base + jitter(t)
        })
        .collect()
}

/// Why a reference file could not be used.
#[derive(Debug)]
pub enum ReferenceFileError {
    /// The file could not be read or breaks the log format's rules (`logfmt`): file, line and
    /// reason are in the error.
    Log(LogError),
    Header {
        path: String,
        found: String,
    },
    /// A reference sample marked missing (`nan`): a reference has no gaps to fill.
    MissingSample {
        path: String,
        line: usize,
    },
    /// Fewer than [`MIN_TRACK_ROWS`] rows or less than [`MIN_TRACK_S`]: not a recorded track.
    TooShort {
        path: String,
        rows: usize,
        span_s: f64,
    },
    /// Longer than [`MAX_TRACK_S`].
    TooLong {
        path: String,
        span_s: f64,
    },
}

/// The fewest rows and the shortest time a track reference from a file may have: two rows are
/// a straight line between them, and a tracking error over less than a second (the closed
/// loop's settling is 0.1 s) is no track figure.
pub const MIN_TRACK_ROWS: usize = 10;
pub const MIN_TRACK_S: f64 = 1.0;
/// The longest: an hour at 100 Hz is 360 000 samples, still small to hold; a time stamp
/// beyond is garbage rather than a run.
pub const MAX_TRACK_S: f64 = 3600.0;

impl std::fmt::Display for ReferenceFileError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            ReferenceFileError::Log(e) => write!(f, "{e}"),
            ReferenceFileError::Header { path, found } => write!(
                f,
                "{path}: expected a header naming `t` and `ref_sw_deg`, found `{found}`"
            ),
            ReferenceFileError::MissingSample { path, line } => write!(
                f,
                "{path}: line {line}: `ref_sw_deg` is nan; a reference cannot have missing \
                 samples"
            ),
            ReferenceFileError::TooShort { path, rows, span_s } => write!(
                f,
                "{path}: a track reference needs at least {MIN_TRACK_ROWS} samples over at \
                 least {MIN_TRACK_S} s; this one has {rows} over {span_s} s"
            ),
            ReferenceFileError::TooLong { path, span_s } => write!(
                f,
                "{path}: the reference runs to t = {span_s} s; at most {MAX_TRACK_S} s"
            ),
        }
    }
}

impl std::error::Error for ReferenceFileError {}

/// A track profile from a CSV with columns `t` and `ref_sw_deg` (any sampling, further columns
/// skipped unread, a pandas row index or a state word among them, names and fields in double
/// quotes read without them, `#` comments skipped; a full project log works too), resampled
/// to 100 Hz by linear
/// interpolation from `t = 0` (the first sample is held before its time; a wall clock's
/// stamps, Unix seconds, from their first whole second: `logfmt::from_wall_clock`). Read by the log
/// reader (`logfmt::Table`), so plain or gzip, time strictly increasing, values within their
/// physical bounds, every error with file and line.
pub fn track_from_csv(path: &Path) -> Result<Vec<f64>, ReferenceFileError> {
    let name = path.display().to_string();
    let table = Table::load_reading(
        path,
        "t",
        Reads::Only(&["ref_sw_deg"]),
        TimeOrder::Increasing,
    )
    .map_err(|e| match e.root() {
        LogError::MissingNamedColumn { found_header, .. } => ReferenceFileError::Header {
            path: name.clone(),
            found: found_header.clone(),
        },
        _ => ReferenceFileError::Log(e),
    })?;
    let (Some(t), Some(r)) = (table.column("t"), table.column("ref_sw_deg")) else {
        return Err(ReferenceFileError::Header {
            path: name,
            found: [&table.names[..], &table.unread[..]].concat().join(","),
        });
    };
    // A wall clock's stamps (a logger's Unix seconds) from their first whole second.
    let mut t = t.to_vec();
    crate::logfmt::from_wall_clock(&mut t);
    let t = &t;
    if let Some(row) = r.iter().position(|v| v.is_nan()) {
        return Err(ReferenceFileError::MissingSample {
            path: name,
            line: table.lines[row],
        });
    }
    // From t = 0: the first sample is held before its time.
    let span_s = t.last().copied().unwrap_or(0.0).max(0.0);
    if t.len() < MIN_TRACK_ROWS || span_s < MIN_TRACK_S {
        return Err(ReferenceFileError::TooShort {
            path: name,
            rows: t.len(),
            span_s,
        });
    }
    if span_s > MAX_TRACK_S {
        return Err(ReferenceFileError::TooLong { path: name, span_s });
    }
    Ok(resample_to_reference_rate(t, r))
}

/// Linear interpolation of `(t, y)` onto the 100 Hz grid from 0 to the last time.
pub fn resample_to_reference_rate(t: &[f64], y: &[f64]) -> Vec<f64> {
    let end = t.last().copied().unwrap_or(0.0);
    let n = (end * REFERENCE_RATE_HZ).floor().max(0.0) as usize + 1;
    let mut j = 0;
    (0..n)
        .map(|k| {
            let tk = k as f64 / REFERENCE_RATE_HZ;
            while j + 1 < t.len() && t[j + 1] < tk {
                j += 1;
            }
            if tk <= t[0] {
                y[0]
            } else if j + 1 >= t.len() {
                y[t.len() - 1]
            } else {
                let s = (tk - t[j]) / (t[j + 1] - t[j]);
                y[j] + s * (y[j + 1] - y[j])
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn paper_sweep_has_1001_samples_and_the_right_amplitude() {
        let s = Sweep::PAPER.samples();
        assert_eq!(s.len(), 1001);
        let max = s.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        assert!(max > 9.9 && max <= 10.0);
        assert_eq!(s[0], 0.0);
    }

    #[test]
    fn builtin_track_is_120_s_within_the_steering_range() {
        let tr = builtin_track();
        assert_eq!(tr.len(), 12_001);
        assert!(tr.iter().all(|v| v.abs() < 90.0));
        let burst = &tr[11_000..11_200];
        let reversals = burst
            .windows(3)
            .filter(|w| (w[1] - w[0]) * (w[2] - w[1]) < 0.0)
            .count();
        assert!(
            reversals >= 16,
            "a burst above 4 Hz near 111 s: {reversals} reversals"
        );
    }

    #[test]
    fn builtin_track_has_no_jumps() {
        // 100 Hz samples: the fastest intended motion, the 4.5 Hz 10 deg burst, moves at most
        // 2 pi 4.5 10 / 100 = 2.8 deg per sample.
        let tr = builtin_track();
        let worst = tr
            .windows(2)
            .map(|w| (w[1] - w[0]).abs())
            .fold(0.0, f64::max);
        let at = tr
            .windows(2)
            .position(|w| (w[1] - w[0]).abs() == worst)
            .unwrap_or(0);
        assert!(
            worst < 3.0,
            "largest step between samples {worst} deg at {} s",
            at as f64 / 100.0
        );
    }

    #[test]
    fn resampling_interpolates_and_holds_the_ends() {
        let r = resample_to_reference_rate(&[0.005, 0.025], &[0.0, 2.0]);
        assert_eq!(r.len(), 3);
        assert_eq!(r[0], 0.0);
        assert!((r[1] - 0.5).abs() < 1e-12);
        assert!((r[2] - 1.5).abs() < 1e-12);
    }

    #[test]
    fn track_csv_errors_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.csv");
        std::fs::write(&p, "t,ref_sw_deg\n0,1\n0.01,oops\n").unwrap();
        let e = track_from_csv(&p).unwrap_err().to_string();
        assert!(e.contains("bad.csv: line 3") && e.contains("oops"), "{e}");
        std::fs::write(&p, "time,angle\n0,1\n").unwrap();
        assert!(matches!(
            track_from_csv(&p),
            Err(ReferenceFileError::Header { .. })
        ));
        std::fs::write(&p, "t,ref_sw_deg\n0,1\n0,2\n").unwrap();
        assert!(matches!(
            track_from_csv(&p),
            Err(ReferenceFileError::Log(e))
                if matches!(e.root(), LogError::NonMonotonicTime { line: 3, .. })
        ));
        std::fs::write(&p, "t,ref_sw_deg\n0,1\n0.01,nan\n").unwrap();
        assert!(matches!(
            track_from_csv(&p),
            Err(ReferenceFileError::MissingSample { line: 3, .. })
        ));
        let mut text = String::from("# from the MPC\nt,ref_sw_deg,extra\n");
        for k in 0..=10 {
            text += &format!("{},{},9\n", f64::from(k) * 0.1, 2 * k);
        }
        std::fs::write(&p, text).unwrap();
        let r = track_from_csv(&p).unwrap();
        assert_eq!(r.len(), 101);
        assert!(
            (r[5] - 1.0).abs() < 1e-9 && (r[100] - 20.0).abs() < 1e-9,
            "{r:?}"
        );
        // The same rows stamped by a wall clock (Unix seconds) are the same track.
        let mut text = String::from("t,ref_sw_deg\n");
        for k in 0..=10 {
            text += &format!("{:.6},{}\n", 1_733_300_000.0 + f64::from(k) * 0.1, 2 * k);
        }
        // `text` written and read back is the track `r`.
        let same_track = |text: String| {
            std::fs::write(&p, text).unwrap();
            let read = track_from_csv(&p).unwrap();
            assert_eq!(read.len(), r.len());
            assert!(
                read.iter().zip(&r).all(|(a, b)| (a - b).abs() < 1e-9),
                "{read:?}"
            );
        };
        same_track(text);
        // As pandas writes them (its row index first, unnamed), with a state word beside, the
        // reference before the time, every name quoted, each row stamped with a date: the
        // same track.
        let mut text = String::from(",\"ref_sw_deg\",\"t\",\"state\"\n");
        for k in 0..=10 {
            text += &format!(
                "{k},{},2026-12-07T18:10:{:09.6},AS_DRIVING\n",
                2 * k,
                f64::from(k) * 0.1
            );
        }
        same_track(text);
        std::fs::write(&p, "t,angle\n0,1\n").unwrap();
        let e = track_from_csv(&p).unwrap_err().to_string();
        assert!(
            e.contains("naming `t` and `ref_sw_deg`") && e.contains("angle"),
            "{e}"
        );
    }

    #[test]
    fn a_track_file_too_short_or_too_long_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("ref.csv");
        for (text, rows, span_s) in [
            ("t,ref_sw_deg\n0,0\n0.01,1\n", 2, 0.01),
            ("t,ref_sw_deg\n0,0\n5,10\n", 2, 5.0),
        ] {
            std::fs::write(&p, text).unwrap();
            match track_from_csv(&p) {
                Err(ReferenceFileError::TooShort {
                    rows: r, span_s: s, ..
                }) => assert_eq!((r, s), (rows, span_s)),
                other => panic!("{other:?}"),
            }
        }
        let mut text = String::from("t,ref_sw_deg\n");
        for k in 0..10 {
            text += &format!("{},0\n", f64::from(k) * 1000.0);
        }
        std::fs::write(&p, text).unwrap();
        assert!(matches!(
            track_from_csv(&p),
            Err(ReferenceFileError::TooLong { span_s: 9000.0, .. })
        ));
    }
}

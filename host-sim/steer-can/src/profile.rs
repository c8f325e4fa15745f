//! Reference profiles at 100 Hz (deg at the wheel), ready for the frames that carry them
//! (`canlink::reference::ReferenceSender`: alive counter, CRC, and the AS state the tool
//! claims, stated by the caller every time).
//!
//! Every profile goes through the ECU's own limits before it is sent: |angle| <= 90 deg and at
//! most 400 deg/s between samples (`ProtocolConfig::DEFAULT`). A sample beyond the rate would
//! be dropped by the ECU's E2E check, and the log would hold a reference the ECU never
//! followed, so the tool limits the rate itself (to 99 % of the budget, for rounding) and says
//! how many samples it changed. The paper's 10 deg sweep needs this above about 6.4 Hz:
//! 2 pi f A = 400 deg/s there.

use crate::BringupError;
use host_io::scenario::{self, Sweep};
use std::path::Path;
use steering_ecu::as_state::AsState;
use steering_ecu::protocol::{PERIOD_US, ProtocolConfig};

/// Samples per second of every profile (the protocol's period).
pub const RATE_HZ: f64 = 1e6 / PERIOD_US as f64;
/// Share of the ECU's rate budget the tool uses.
const RATE_MARGIN: f64 = 0.99;

/// A profile, ready to send.
#[derive(Debug, Clone, PartialEq)]
pub struct Profile {
    /// What it is, for messages ("sweep 0-10 Hz, 10 deg, 10 s").
    pub name: String,
    /// deg at the wheel, one per 10 ms.
    pub samples: Vec<f64>,
    /// Samples the rate limit changed.
    pub rate_limited: usize,
}

impl Profile {
    /// Checks the range and limits the rate from `start_deg` (the previous sample the ECU
    /// accepted, or where the wheel is).
    pub fn new(name: String, raw: Vec<f64>, start_deg: f64) -> Result<Profile, BringupError> {
        let cfg = ProtocolConfig::DEFAULT;
        let max = f64::from(cfg.max_angle.0);
        if raw.is_empty() {
            return Err(BringupError::Profile {
                reason: format!("{name}: no samples"),
            });
        }
        if let Some((k, v)) = raw
            .iter()
            .enumerate()
            .find(|(_, v)| !(v.is_finite() && v.abs() <= max))
        {
            return Err(BringupError::Profile {
                reason: format!(
                    "{name}: sample {k} ({:.2} s) is {v} deg, beyond the ECU's +-{max} deg",
                    k as f64 / RATE_HZ
                ),
            });
        }
        let step = max_step_deg();
        let mut prev = start_deg;
        let mut limited = 0;
        let samples = raw
            .iter()
            .map(|&v| {
                let next = if (v - prev).abs() <= step {
                    v
                } else {
                    limited += 1;
                    prev + (v - prev).clamp(-step, step)
                };
                prev = next;
                next
            })
            .collect();
        Ok(Profile {
            name,
            samples,
            rate_limited: limited,
        })
    }

    pub fn duration_s(&self) -> f64 {
        self.samples.len() as f64 / RATE_HZ
    }

    pub fn max_abs_deg(&self) -> f64 {
        self.samples.iter().fold(0.0, |m, v| m.max(v.abs()))
    }
}

/// The largest step between two samples the tool sends, deg (99 % of 400 deg/s x 10 ms).
pub fn max_step_deg() -> f64 {
    let cfg = ProtocolConfig::DEFAULT;
    f64::from(cfg.max_rate_deg_per_s) * (cfg.period_us as f64 * 1e-6) * RATE_MARGIN
}

/// A step of `amplitude_deg` after `at_s`, for `duration_s` in all.
pub fn step(amplitude_deg: f64, at_s: f64, duration_s: f64) -> Result<Profile, BringupError> {
    Profile::new(
        format!("step to {amplitude_deg} deg at {at_s} s, {duration_s} s"),
        scenario::step(amplitude_deg, at_s, duration_s),
        0.0,
    )
}

/// `amplitude_deg sin(2 pi f t)` for `duration_s`.
pub fn sine(amplitude_deg: f64, freq_hz: f64, duration_s: f64) -> Result<Profile, BringupError> {
    let n = (duration_s * RATE_HZ).round() as usize + 1;
    let raw = (0..n)
        .map(|k| amplitude_deg * (std::f64::consts::TAU * freq_hz * k as f64 / RATE_HZ).sin())
        .collect();
    Profile::new(
        format!("sine {amplitude_deg} deg at {freq_hz} Hz, {duration_s} s"),
        raw,
        0.0,
    )
}

/// The paper's chirp (section 4.2), `Sweep::PAPER` by default.
pub fn sweep(s: Sweep) -> Result<Profile, BringupError> {
    Profile::new(
        format!(
            "sweep {}-{} Hz, {} deg, {} s",
            s.f_start_hz, s.f_end_hz, s.amplitude_deg, s.duration_s
        ),
        s.samples(),
        0.0,
    )
}

/// A track profile from a CSV `t,ref_sw_deg` (resampled to 100 Hz), or the built-in 120 s one.
pub fn track(csv: Option<&Path>) -> Result<Profile, BringupError> {
    match csv {
        Some(path) => {
            let raw = scenario::track_from_csv(path).map_err(|e| BringupError::Profile {
                reason: e.to_string(),
            })?;
            let start = raw.first().copied().unwrap_or(0.0);
            Profile::new(format!("track {}", path.display()), raw, start)
        }
        None => Profile::new(
            "built-in track, 120 s".into(),
            scenario::builtin_track(),
            0.0,
        ),
    }
}

/// `--as-state` values: what the tool claims to be.
pub fn parse_as_state(s: &str) -> Result<AsState, String> {
    match s.to_ascii_lowercase().as_str() {
        "off" => Ok(AsState::Off),
        "ready" => Ok(AsState::Ready),
        "driving" => Ok(AsState::Driving),
        "emergency" => Ok(AsState::Emergency),
        "finished" => Ok(AsState::Finished),
        "manual" => Ok(AsState::Manual),
        _ => Err(format!(
            "`{s}` is not an AS state (off, ready, driving, emergency, finished, manual)"
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_paper_sweep_is_rate_limited_above_six_hz_only() {
        let p = sweep(Sweep::PAPER).unwrap();
        assert!(p.rate_limited > 0);
        let first = p
            .samples
            .iter()
            .zip(Sweep::PAPER.samples())
            .position(|(a, b)| *a != b)
            .unwrap();
        let f_at = first as f64 / RATE_HZ; // 1 Hz/s chirp: frequency = time
        assert!(
            (6.0..6.6).contains(&f_at),
            "first limited sample at {f_at} Hz"
        );
        for w in p.samples.windows(2) {
            assert!((w[1] - w[0]).abs() <= max_step_deg() + 1e-12);
        }
    }

    #[test]
    fn out_of_range_profiles_are_refused_with_the_sample() {
        match sine(95.0, 1.0, 1.0) {
            Err(BringupError::Profile { reason }) => assert!(reason.contains("90"), "{reason}"),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_step_becomes_a_ramp_the_ecu_accepts() {
        let p = step(10.0, 0.5, 1.0).unwrap();
        assert_eq!(
            p.rate_limited, 2,
            "10 deg in 3.96 deg steps: 2 samples short"
        );
        assert!((p.samples[p.samples.len() - 1] - 10.0).abs() < 1e-12);
    }
}

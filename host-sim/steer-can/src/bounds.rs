//! The range of every numeric option, checked before a command touches the bus or a file (as
//! host-sim checks its own): NaN, infinities and values beyond what an option can mean are
//! refused with the option's name, the value and the range, instead of turning into a
//! zero-length run, a wrapped angle or a profile too large to hold in memory.

use crate::BringupError;
use crate::args::{CampaignKind, Cli, Command, SendProfile, SweepArgs};
use steering_ecu::protocol::ProtocolConfig;

/// An interval of allowed values with its unit and the reason for its ends.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Range {
    pub lo: f64,
    /// `lo` itself is refused.
    pub lo_open: bool,
    pub hi: f64,
    /// `hi` itself is refused.
    pub hi_open: bool,
    pub unit: &'static str,
    pub why: &'static str,
}

impl Range {
    /// Whether `v` lies inside (NaN never does).
    pub fn contains(&self, v: f64) -> bool {
        let above = if self.lo_open {
            v > self.lo
        } else {
            v >= self.lo
        };
        let below = if self.hi_open {
            v < self.hi
        } else {
            v <= self.hi
        };
        above && below
    }

    /// `Ok` inside, else an error naming `option`, `v` and the range.
    pub fn check(&self, option: &str, v: f64) -> Result<(), BringupError> {
        if self.contains(v) {
            return Ok(());
        }
        Err(BringupError::Usage {
            reason: format!(
                "{option} {v}: must be in {}{}, {}{}{}{} ({})",
                if self.lo_open { '(' } else { '[' },
                self.lo,
                self.hi,
                if self.hi_open { ')' } else { ']' },
                if self.unit.is_empty() { "" } else { " " },
                self.unit,
                self.why
            ),
        })
    }
}

const fn range(
    lo: f64,
    lo_open: bool,
    hi: f64,
    hi_open: bool,
    unit: &'static str,
    why: &'static str,
) -> Range {
    Range {
        lo,
        lo_open,
        hi,
        hi_open,
        unit,
        why,
    }
}

/// The ECU's reference limit at the wheel, deg (`ProtocolConfig::DEFAULT.max_angle`).
fn max_angle_deg() -> f64 {
    f64::from(ProtocolConfig::DEFAULT.max_angle.0)
}

/// A profile's length: it is built in memory before it is sent (100 samples a second), and
/// the longest the campaign knows, the built-in track, is 120 s.
pub const PROFILE_S: Range = range(
    0.0,
    true,
    600.0,
    false,
    "s",
    "a profile is built before it is sent",
);
/// How long `monitor` and `record` listen: they stream, but a day is more than any bring-up.
pub const LISTEN_S: Range = range(0.0, true, 86_400.0, false, "s", "at most a day");
/// `monitor`'s summary period: not faster than the eye, not slower than an hour.
pub const REFRESH_S: Range = range(0.05, false, 3_600.0, false, "s", "a summary period");
/// A sine's frequency: at the 100 Hz reference rate, 50 Hz is the Nyquist limit, where every
/// sample of `sin(2 pi f t)` is 0.
pub const SINE_HZ: Range = range(
    0.0,
    true,
    50.0,
    true,
    "Hz",
    "below the 100 Hz reference's Nyquist limit",
);
/// A chirp's end frequency, as host-sim's `sweep --f-end-hz`.
pub const SWEEP_END_HZ: Range = range(
    0.0,
    true,
    50.0,
    false,
    "Hz",
    "the 100 Hz reference's Nyquist limit",
);
/// Where the simulated car is powered up: the column encoder reads one turn of the wheel, so
/// beyond half a turn an angle would wrap.
pub const SIM_COLUMN_DEG: Range = range(
    -180.0,
    false,
    180.0,
    false,
    "deg",
    "the column encoder reads one turn",
);
/// When `--sim-inject` fires, s after the simulated car starts.
pub const INJECT_AT_S: Range = range(0.0, false, 86_400.0, false, "s", "at most a day");
/// A CANopen node ID (CiA 301: 1 to 127; 0 addresses every node).
pub const NODE: Range = range(1.0, false, 127.0, false, "", "a CANopen node ID");

/// When a step starts, s after the first frame: within the longest profile.
pub const AT_S: Range = range(0.0, false, 600.0, false, "s", "within the longest profile");

/// A signed amplitude at the wheel within the ECU's reference limit.
fn amplitude() -> Range {
    let max = max_angle_deg();
    range(-max, false, max, false, "deg", "the ECU's reference limit")
}

/// A positive amplitude within the ECU's reference limit (a chirp's sign means nothing).
fn positive_amplitude() -> Range {
    range(
        0.0,
        true,
        max_angle_deg(),
        false,
        "deg",
        "the ECU's reference limit",
    )
}

fn check_sweep(s: &SweepArgs) -> Result<(), BringupError> {
    positive_amplitude().check("--amplitude-deg", s.amplitude_deg)?;
    SWEEP_END_HZ.check("--f-end-hz", s.f_end_hz)?;
    range(
        0.0,
        false,
        s.f_end_hz,
        true,
        "Hz",
        "below the end frequency",
    )
    .check("--f-start-hz", s.f_start_hz)?;
    PROFILE_S.check("--duration-s", s.duration_s)
}

/// Every numeric option of `cli`, the global ones included whatever the command.
pub fn check(cli: &Cli) -> Result<(), BringupError> {
    NODE.check("--node", f64::from(cli.node))?;
    SIM_COLUMN_DEG.check("--sim-column-deg", cli.sim_column_deg)?;
    match &cli.command {
        Command::Monitor {
            duration_s,
            refresh_s,
            ..
        } => {
            if let Some(d) = duration_s {
                LISTEN_S.check("--duration-s", *d)?;
            }
            REFRESH_S.check("--refresh-s", *refresh_s)
        }
        Command::Record {
            duration_s: Some(d),
            ..
        } => LISTEN_S.check("--duration-s", *d),
        Command::Send { profile, .. } => match profile {
            SendProfile::Step {
                amplitude_deg,
                at_s,
                duration_s,
            } => {
                amplitude().check("--amplitude-deg", *amplitude_deg)?;
                PROFILE_S.check("--duration-s", *duration_s)?;
                // Not tied to the profile's length: a step after its end is a hold at 0
                // (`--amplitude-deg 0 --duration-s 0.3` leaves the default 0.5 s).
                AT_S.check("--at-s", *at_s)
            }
            SendProfile::Sine {
                amplitude_deg,
                freq_hz,
                duration_s,
            } => {
                amplitude().check("--amplitude-deg", *amplitude_deg)?;
                SINE_HZ.check("--freq-hz", *freq_hz)?;
                PROFILE_S.check("--duration-s", *duration_s)
            }
            SendProfile::Sweep(s) => check_sweep(s),
            SendProfile::Track(_) | SendProfile::ClearFaults => Ok(()),
        },
        Command::Campaign {
            kind: CampaignKind::Sweep { sweep, .. },
        } => check_sweep(sweep),
        _ => Ok(()),
    }
}

/// The time of `--sim-inject KIND@SECONDS`, checked.
pub fn inject_at_s(spec: &str, at: &str) -> Result<f64, BringupError> {
    let at_s: f64 = at.trim().parse().map_err(|_| BringupError::Usage {
        reason: format!("--sim-inject `{spec}`: `{at}` is not a number of seconds"),
    })?;
    INJECT_AT_S.check("--sim-inject time", at_s)?;
    Ok(at_s)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_refuse_nan_infinities_and_their_open_ends() {
        for v in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 0.0, -1.0, 601.0] {
            assert!(!PROFILE_S.contains(v), "{v}");
        }
        assert!(PROFILE_S.contains(600.0));
        assert!(!SINE_HZ.contains(50.0));
        assert!(SINE_HZ.contains(49.9));
        let e = SINE_HZ.check("--freq-hz", 50.0).unwrap_err().to_string();
        assert_eq!(
            e,
            "--freq-hz 50: must be in (0, 50) Hz (below the 100 Hz reference's Nyquist limit)"
        );
    }
}

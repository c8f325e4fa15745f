//! `host-sim limits`: what the paper plant allows whatever the controller, and the bound it
//! puts on a sweep's bandwidth.

use super::{Result, write_json};
use host_sim::linear_model::{LimitedBy, MINUS_3_DB, PhysicalLimit};
use host_sim::sim::RunConfig;
use std::path::Path;

/// What the run's plant and supply allow whatever the controller (20 A, as the cascade's limit).
pub(crate) fn physical_limit(cfg: &RunConfig) -> PhysicalLimit {
    PhysicalLimit {
        params: cfg.plant,
        voltage_limit_v: cfg.supply_v,
        ..PhysicalLimit::paper()
    }
}

/// A bound on the bandwidth as `host-sim` prints it: "  3.79 Hz", or "above 50 Hz" (the
/// reference's Nyquist limit, where `bandwidth_bound_hz` stops looking).
pub(crate) fn bound_text(bound_hz: Option<f64>) -> String {
    bound_hz.map_or("above 50 Hz".to_string(), |b| format!("{b:6.2} Hz"))
}

/// A bandwidth as a share of its bound: "61 %", or "-" when either is missing.
pub(crate) fn share_of_bound(bandwidth_hz: Option<f64>, bound_hz: Option<f64>) -> String {
    match (bandwidth_hz, bound_hz) {
        (Some(bw), Some(b)) if b > 0.0 => format!("{:.0} %", 100.0 * bw / b),
        _ => "-".to_string(),
    }
}

pub(crate) fn limits_cmd(amplitude_deg: f64, supply_v: f64, json: Option<&Path>) -> Result<()> {
    if !(amplitude_deg.is_finite() && amplitude_deg > 0.0 && amplitude_deg <= 90.0) {
        return Err(format!("--amplitude-deg {amplitude_deg}: must be in (0, 90] deg").into());
    }
    if !(supply_v.is_finite() && supply_v > 0.0 && supply_v <= 60.0) {
        return Err(format!("--supply-v {supply_v}: must be in (0, 60] V").into());
    }
    let limit = PhysicalLimit {
        voltage_limit_v: supply_v,
        ..PhysicalLimit::paper()
    };
    let pinion = MINUS_3_DB * amplitude_deg;
    say!(
        "Steady state at the motor for a sinusoidal pinion angle (delta_P), paper plant (Tables \
         1, 2, 4; eqs. 1-8), any controller:"
    );
    say!(
        "pinion amplitude {pinion:.2} deg (-3 dB of a {amplitude_deg} deg sweep); limits {} A, \
         {supply_v} V",
        limit.current_limit_a
    );
    say!(
        "{:>6} {:>10} {:>10} {:>24}",
        "f Hz",
        "current A",
        "voltage V",
        "largest amplitude, deg"
    );
    let mut rows = Vec::new();
    for f in 1..=10 {
        let d = limit.demand(f as f64, pinion);
        say!(
            "{:>6.1} {:>10.1} {:>10.1} {:>12.2} ({}-bound)",
            d.f_hz,
            d.current_a,
            d.voltage_v,
            d.largest_amplitude_deg,
            match d.limited_by {
                LimitedBy::Current => "current",
                LimitedBy::Voltage => "voltage",
            }
        );
        rows.push(d);
    }
    say!(
        "Bound on the -3 dB bandwidth of a sweep of amplitude A (the highest f where \
         10^(-3/20) A is reachable):"
    );
    let mut amplitudes = vec![10.0, 5.0, 2.0, 1.0];
    if !amplitudes.contains(&amplitude_deg) {
        amplitudes.insert(0, amplitude_deg);
    }
    say!(
        "  (sinusoidal drive within the limits; saturated drive: a current or voltage clipped at \
         the limit has a fundamental of up to 4/pi of it, {:.1} A / {:.1} V, which a chirp's H1 \
         reads)",
        limit.saturated().current_limit_a,
        limit.saturated().voltage_limit_v
    );
    let mut bounds = Vec::new();
    for a in amplitudes {
        let b = limit.bandwidth_bound_hz(a);
        let sat = limit.saturated().bandwidth_bound_hz(a);
        say!(
            "  {a:5} deg: {} sinusoidal, {} saturated",
            bound_text(b),
            bound_text(sat)
        );
        bounds.push(serde_json::json!({
            "amplitude_deg": a,
            "bandwidth_bound_hz": b,
            "saturated_bandwidth_bound_hz": sat,
        }));
    }
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "current_limit_a": limit.current_limit_a,
                "voltage_limit_v": supply_v,
                "pinion_amplitude_deg": pinion,
                "table": rows,
                "bounds": bounds,
            }),
        )?;
    }
    Ok(())
}

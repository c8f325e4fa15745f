//! The figures each scenario reports, computed from a run; shared by the CLI and the tests so
//! that what the README prints is what the tests assert.

use crate::analysis::{
    FrequencyResponse, TrackingError, bandwidth_hz, h1_estimate, tracking_error,
};
use crate::scenario::Sweep;
use crate::sim::{Run, RunConfig, RunSummary, SimError, run};

/// Lowest frequency considered for the -3 dB point: below it a 10 s sweep has too few cycles.
pub const BANDWIDTH_SEARCH_FROM_HZ: f64 = 0.5;
/// Welch segment for the sweep's frequency response, s (0.5 Hz resolution, 4 averages per s).
pub const SWEEP_SEGMENT_S: f64 = 2.0;

#[derive(Debug, Clone, serde::Serialize)]
pub struct SweepReport {
    pub amplitude_deg: f64,
    pub f_end_hz: f64,
    pub duration_s: f64,
    /// -3 dB bandwidth of column angle / reference, Hz (None: above the sweep's range).
    pub bandwidth_hz: Option<f64>,
    pub max_current_a: f64,
    pub max_voltage_v: f64,
    pub tracking: TrackingError,
    #[serde(flatten)]
    pub summary: RunSummary,
    #[serde(skip)]
    pub response: FrequencyResponse,
}

pub fn sweep(sweep: &Sweep, cfg: &RunConfig) -> Result<(SweepReport, Run), SimError> {
    let r = run(&sweep.samples(), cfg)?;
    let fs = cfg.log_rate_hz as f64;
    let response = h1_estimate(
        &r.log.ref_sw_deg,
        &r.log.sw_deg,
        fs,
        SWEEP_SEGMENT_S.min(sweep.duration_s / 2.0),
        sweep.f_end_hz,
    );
    let report = SweepReport {
        amplitude_deg: sweep.amplitude_deg,
        f_end_hz: sweep.f_end_hz,
        duration_s: sweep.duration_s,
        bandwidth_hz: bandwidth_hz(&response, BANDWIDTH_SEARCH_FROM_HZ),
        max_current_a: r.summary.max_current_a,
        max_voltage_v: r.summary.max_voltage_v,
        tracking: tracking_error(&r.log.ref_sw_deg, &r.log.sw_deg),
        summary: r.summary,
        response,
    };
    Ok((report, r))
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct TrackReport {
    pub rmse_deg: f64,
    pub max_error_deg: f64,
    pub max_error_at_s: f64,
    pub max_current_a: f64,
    pub max_voltage_v: f64,
    #[serde(flatten)]
    pub summary: RunSummary,
}

pub fn track(reference_deg: &[f64], cfg: &RunConfig) -> Result<(TrackReport, Run), SimError> {
    let r = run(reference_deg, cfg)?;
    let te = tracking_error(&r.log.ref_sw_deg, &r.log.sw_deg);
    let report = TrackReport {
        rmse_deg: te.rmse,
        max_error_deg: te.max_abs,
        max_error_at_s: r.log.t.get(te.at_index).copied().unwrap_or(f64::NAN),
        max_current_a: r.summary.max_current_a,
        max_voltage_v: r.summary.max_voltage_v,
        summary: r.summary,
    };
    Ok((report, r))
}

#[derive(Debug, Clone, serde::Serialize)]
pub struct StepReport {
    pub amplitude_deg: f64,
    /// 10-90 % rise time of the column angle, s.
    pub rise_time_s: Option<f64>,
    /// Largest excursion beyond the target, deg (0 if none).
    pub overshoot_deg: f64,
    pub overshoot_pct: f64,
    /// Column angle minus target at the end of the run, deg.
    pub final_error_deg: f64,
    pub max_current_a: f64,
    pub max_voltage_v: f64,
    #[serde(flatten)]
    pub summary: RunSummary,
}

/// Run a step reference (0 then `amplitude_deg`) and measure rise, overshoot and final error.
pub fn step(
    reference_deg: &[f64],
    amplitude_deg: f64,
    cfg: &RunConfig,
) -> Result<(StepReport, Run), SimError> {
    let r = run(reference_deg, cfg)?;
    let log = &r.log;
    let sign = amplitude_deg.signum();
    let start = log.ref_sw_deg.iter().position(|v| *v != 0.0).unwrap_or(0);
    let crossing = |frac: f64| {
        (start..log.len())
            .find(|&i| sign * log.sw_deg[i] >= frac * amplitude_deg.abs())
            .map(|i| log.t[i])
    };
    let rise_time_s = match (crossing(0.1), crossing(0.9)) {
        (Some(a), Some(b)) => Some(b - a),
        _ => None,
    };
    let peak = log.sw_deg[start..]
        .iter()
        .map(|v| sign * v)
        .fold(f64::NEG_INFINITY, f64::max);
    let overshoot_deg = (peak - amplitude_deg.abs()).max(0.0);
    let report = StepReport {
        amplitude_deg,
        rise_time_s,
        overshoot_deg,
        overshoot_pct: if amplitude_deg != 0.0 {
            100.0 * overshoot_deg / amplitude_deg.abs()
        } else {
            0.0
        },
        final_error_deg: log.sw_deg.last().copied().unwrap_or(f64::NAN) - amplitude_deg,
        max_current_a: r.summary.max_current_a,
        max_voltage_v: r.summary.max_voltage_v,
        summary: r.summary,
    };
    Ok((report, r))
}

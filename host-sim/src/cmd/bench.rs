//! `host-sim bench`: the realtime factor of the 120 s track.

use super::{Result, write_json};
use host_sim::scenario;
use host_sim::sim::RunConfig;
use std::path::Path;
use std::time::Instant;

pub(crate) fn bench(repeats: u32, json: Option<&Path>) -> Result<()> {
    let reference = scenario::builtin_track();
    let mut factors = Vec::new();
    let mut factors_logged = Vec::new();
    say!("Track run, 120 s at 20 kHz current / 2 kHz position / 100 Hz reference, one thread:");
    let mut duration = 0.0;
    for i in 0..repeats {
        for (log_rate_hz, out) in [(0, &mut factors), (1000, &mut factors_logged)] {
            let cfg = RunConfig {
                log_rate_hz,
                ..RunConfig::default()
            };
            let start = Instant::now();
            let run = host_sim::sim::run(&reference, &cfg)?;
            let wall = start.elapsed().as_secs_f64();
            duration = run.summary.duration_s;
            out.push(duration / wall);
        }
        say!(
            "  run {}/{}: {:.0}x real time (no log), {:.0}x (1 kHz log)",
            i + 1,
            repeats,
            factors[i as usize],
            factors_logged[i as usize]
        );
    }
    let median = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let rf = median(&mut factors);
    let rf_logged = median(&mut factors_logged);
    say!(
        "  median: {rf:.0}x real time ({:.1} ms per simulated 120 s); with the 1 kHz log {rf_logged:.0}x (target 1000x)",
        1e3 * duration / rf
    );
    if let Some(path) = json {
        write_json(
            path,
            &serde_json::json!({
                "realtime_factor": rf,
                "realtime_factor_with_log": rf_logged,
                "simulated_s": duration,
                "repeats": repeats,
            }),
        )?;
    }
    Ok(())
}

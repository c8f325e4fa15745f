//! `host-sim poles`: the linear plant's and the closed loops' eigenvalues and margins.

use super::{Result, write_json};
use host_sim::linear_model::LinearModel;
use host_sim::plant::PlantParams;
use host_sim::sim::RunConfig;
use std::path::Path;
use steering_ecu::ecu_mode::EcuTuning;
use steering_ecu::gains::EposGains;

pub(crate) fn poles(json: Option<&Path>) -> Result<()> {
    let params = PlantParams::PAPER;
    let mech = params.mechanical_poles();
    say!("Mechanical poles of eqs. 5-8 (Tables 2, 4; belt factor 1/2, eq. 6 with (tauBS/tauP)^2):");
    say!(
        "{:>12} {:>12} {:>10} {:>8} {:>7}",
        "re rad/s",
        "im rad/s",
        "|p| rad/s",
        "Hz",
        "zeta"
    );
    for p in &mech {
        let w = p.norm();
        let zeta = if w > 0.0 { -p.re / w } else { f64::NAN };
        say!(
            "{:>12.2} {:>12.2} {:>10.2} {:>8.2} {:>7.3}",
            p.re,
            p.im,
            w,
            w / std::f64::consts::TAU,
            zeta
        );
    }
    say!(
        "Paper (section 4.3): 0, -334 rad/s real, pairs at 30.9 rad/s (4.9 Hz) and 131 rad/s (20.9 Hz)."
    );
    let em = params.electromechanical_poles();
    say!(
        "With the winding (eq. 1) the fast pole is at {:.0} rad/s.",
        em.last().map_or(f64::NAN, |p| p.norm())
    );
    let model = LinearModel::new(params, &EposGains::PAPER)?;
    let closed = model.closed_loop_poles();
    say!("");
    say!(
        "Closed loop, paper mode (Table 3 gains; linear model: 20 kHz PI, 2 kHz PID + feedforward, \
         exact sensors, no limits), s = ln(z) / 0.5 ms:"
    );
    say!(
        "{:>12} {:>12} {:>10} {:>8} {:>7} {:>8}",
        "re rad/s",
        "im rad/s",
        "|s| rad/s",
        "Hz",
        "zeta",
        "|z|"
    );
    for p in &closed {
        say!(
            "{:>12.2} {:>12.2} {:>10.2} {:>8.2} {:>7.3} {:>8.4}",
            p.re,
            p.im,
            p.wn,
            p.f_hz,
            p.zeta,
            p.z_magnitude
        );
    }
    say!(
        "  {} (|z| < 1 for all). im = +-{:.0} rad/s marks a negative real z: a mode that \
         alternates sign every position tick.",
        if model.is_stable() {
            "stable"
        } else {
            "UNSTABLE"
        },
        std::f64::consts::PI * steering_ecu::paper_mode::POSITION_LOOP_HZ as f64
    );
    let margins = model.margins();
    say!("Position-loop margins (loop broken at the current set-point, 0.01 Hz to 1 kHz):");
    match (margins.gain_margin_db, margins.phase_crossover_hz) {
        (Some(gm), Some(f)) => say!("  gain margin   {gm:6.1} dB  at {f:7.2} Hz (phase -180 deg)"),
        _ => say!("  gain margin   none: the phase never crosses -180 deg with |L| < 1"),
    }
    match (margins.phase_margin_deg, margins.gain_crossover_hz) {
        (Some(pm), Some(f)) => say!("  phase margin  {pm:6.1} deg at {f:7.2} Hz (|L| = 1)"),
        _ => say!("  phase margin  none: |L| never crosses 1"),
    }
    let ecu_margins = model.ecu_margins(&EcuTuning::PAPER);
    say!(
        "ECU mode's loop (the same PID with the column fed back, D on the motor speed; \
         `--controller ecu`):"
    );
    match (ecu_margins.gain_margin_db, ecu_margins.phase_crossover_hz) {
        (Some(gm), Some(f)) => say!("  gain margin   {gm:6.1} dB  at {f:7.2} Hz (phase -180 deg)"),
        _ => say!("  gain margin   none: the phase never crosses -180 deg with |L| < 1"),
    }
    match (ecu_margins.phase_margin_deg, ecu_margins.gain_crossover_hz) {
        (Some(pm), Some(f)) => say!("  phase margin  {pm:6.1} deg at {f:7.2} Hz (|L| = 1)"),
        _ => say!("  phase margin  none: |L| never crosses 1"),
    }
    let log_rate = RunConfig::default().log_rate_hz;
    let bandwidth = model.bandwidth_hz(0.05, 50.0, log_rate);
    match bandwidth {
        Some(bw) => say!(
            "Small-signal -3 dB bandwidth of the column (linear model, as a {log_rate} Hz log \
             sees it): {bw:.2} Hz"
        ),
        None => say!("Small-signal -3 dB bandwidth of the column: above 50 Hz"),
    }
    if let Some(path) = json {
        let poles: Vec<_> = mech
            .iter()
            .map(|p| serde_json::json!({"re": p.re, "im": p.im}))
            .collect();
        let em: Vec<_> = em
            .iter()
            .map(|p| serde_json::json!({"re": p.re, "im": p.im}))
            .collect();
        write_json(
            path,
            &serde_json::json!({
                "poles": poles,
                "electromechanical_poles": em,
                "unit": "rad/s",
                "closed_loop_poles": closed,
                "closed_loop_stable": model.is_stable(),
                "margins": margins,
                "ecu_mode_margins": ecu_margins,
                "small_signal_bandwidth_hz": bandwidth,
            }),
        )?;
    }
    Ok(())
}

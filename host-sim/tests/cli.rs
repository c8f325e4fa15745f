//! The `host-sim` binary end to end: figures as JSON, logs, pictures, clear errors.

#![allow(clippy::unwrap_used)] // test helpers: a failed unwrap is a failed test
use std::path::Path;
use std::process::{Command, Output};

fn host_sim(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_host-sim"))
        .args(args)
        .output()
        .expect("the binary runs")
}

fn json(path: &Path) -> serde_json::Value {
    serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
}

#[test]
fn poles_json_lists_six_poles_in_rad_per_s() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("poles.json");
    let out = host_sim(&["poles", "--json", path.to_str().unwrap()]);
    assert!(out.status.success());
    let v = json(&path);
    let poles = v["poles"].as_array().unwrap();
    assert_eq!(poles.len(), 6);
    let mags: Vec<f64> = poles
        .iter()
        .map(|p| p["re"].as_f64().unwrap().hypot(p["im"].as_f64().unwrap()))
        .collect();
    assert!(mags.iter().any(|m| (m - 334.0).abs() < 33.4));
    assert!(String::from_utf8_lossy(&out.stdout).contains("334"));
}

#[test]
fn sweep_writes_figures_log_and_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let j = dir.path().join("sweep.json");
    let log = dir.path().join("sweep.csv.gz");
    let plots = dir.path().join("plots");
    let out = host_sim(&[
        "sweep",
        "--amplitude-deg",
        "5",
        "--json",
        j.to_str().unwrap(),
        "--log",
        log.to_str().unwrap(),
        "--plots",
        plots.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let v = json(&j);
    let bw = v["bandwidth_hz"].as_f64().unwrap();
    // Paper mode: what the linear model of the same loop says, and below the physical bound.
    let linear = v["analytic_bandwidth_hz"].as_f64().unwrap();
    let bound = v["bandwidth_bound_hz"].as_f64().unwrap();
    assert!(
        (bw - linear).abs() < 0.3,
        "sweep {bw} Hz, linear model {linear} Hz"
    );
    assert!(bw < bound && bound <= v["saturated_bandwidth_bound_hz"].as_f64().unwrap());
    assert!(v["max_current_a"].as_f64().unwrap() <= 20.0);
    assert!(v["max_voltage_v"].as_f64().unwrap() <= 24.0);
    let log = host_sim::logfmt::Log::load(&log).unwrap();
    assert_eq!(log.len(), 10_010);
    for svg in ["sweep_bode.svg", "sweep_time.svg"] {
        let text = std::fs::read_to_string(plots.join(svg)).unwrap();
        assert!(text.starts_with("<svg") && text.trim_end().ends_with("</svg>"));
    }
}

/// Where each polyline of `stroke` (with more than two points: a data line, not a grid line or
/// a legend sample) starts in `svg`.
fn data_lines(svg: &str, stroke: &str) -> Vec<usize> {
    svg.match_indices("<polyline ")
        .map(|(at, _)| (at, &svg[at..at + svg[at..].find("/>").unwrap()]))
        .filter(|(_, tag)| tag.contains(&format!("stroke=\"{stroke}\"")))
        .filter(|(_, tag)| tag.matches(',').count() > 2)
        .map(|(at, _)| at)
        .collect()
}

#[test]
fn time_figures_draw_the_set_point_over_the_current_and_stay_small() {
    let dir = tempfile::tempdir().unwrap();
    let plots = dir.path().join("plots");
    for command in ["step", "track"] {
        let out = host_sim(&[command, "--plots", plots.to_str().unwrap()]);
        assert!(out.status.success(), "{command}");
    }
    let svg = std::fs::read_to_string(plots.join("step_time.svg")).unwrap();
    // The current panel: from its y label (plotters draws the axes first) to the next panel's.
    let start = svg.find("motor current, A").unwrap();
    let end = start + svg[start..].find("voltage, V").unwrap();
    let panel = &svg[start..end];
    let measured = data_lines(panel, "#0072B2");
    let setpoint = data_lines(panel, "#666666");
    assert!(!measured.is_empty() && !setpoint.is_empty());
    assert!(
        measured.iter().max() < setpoint.iter().min(),
        "set-point drawn under the measured current"
    );
    assert!(panel.contains("set-point") && panel.contains("measured"));

    // 120 s logged at 1 kHz in four panels: decimated per pixel column, not 120 000 points a line.
    let track = std::fs::read_to_string(plots.join("track_time.svg")).unwrap();
    assert!(track.starts_with("<svg") && track.trim_end().ends_with("</svg>"));
    assert!(track.len() < 250_000, "{} bytes", track.len());
}

#[test]
fn track_reads_a_reference_csv() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("mpc.csv");
    let mut text = String::from("t,ref_sw_deg\n");
    for k in 0..=300 {
        let t = k as f64 * 0.01;
        text += &format!("{t},{}\n", 20.0 * (std::f64::consts::TAU * 0.5 * t).sin());
    }
    std::fs::write(&csv, text).unwrap();
    // The same CSV under both controllers: ECU mode follows the 0.5 Hz, 20 deg sine closely;
    // paper mode lags it by the belt's 50 ms (about 16 deg of phase at 0.5 Hz).
    let rmse = |controller: &str| {
        let j = dir.path().join(format!("track-{controller}.json"));
        let out = host_sim(&[
            "track",
            "--csv",
            csv.to_str().unwrap(),
            "--controller",
            controller,
            "--json",
            j.to_str().unwrap(),
        ]);
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
        let v = json(&j);
        let rmse = v["rmse_deg"].as_f64().unwrap();
        assert!(v["max_error_deg"].as_f64().unwrap() >= rmse);
        rmse
    };
    let (paper, ecu) = (rmse("paper"), rmse("ecu"));
    assert!(ecu > 0.0 && ecu < 1.0, "ECU mode {ecu} deg");
    assert!(
        paper > 2.0 * ecu,
        "paper mode {paper} deg, ECU mode {ecu} deg"
    );
}

#[test]
fn bench_reports_a_realtime_factor() {
    let dir = tempfile::tempdir().unwrap();
    let j = dir.path().join("bench.json");
    let out = host_sim(&["bench", "--repeats", "1", "--json", j.to_str().unwrap()]);
    assert!(out.status.success());
    // A benchmark, not a timed test: only that a positive figure is reported.
    assert!(json(&j)["realtime_factor"].as_f64().unwrap() > 0.0);
}

#[test]
fn bad_input_is_a_clear_error_not_a_panic() {
    let out = host_sim(&["sweep", "--amplitude-deg", "NaN"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--amplitude-deg") && !err.contains("panicked"),
        "{err}"
    );

    let out = host_sim(&["track", "--csv", "/nonexistent/ref.csv"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("/nonexistent/ref.csv") && !err.contains("panicked"),
        "{err}"
    );

    let out = host_sim(&["step", "--log-rate-hz", "300"]);
    assert!(!out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("does not divide"));

    // A bad `--plant-effects` value: clap quotes the list, the reason names the key and the
    // value once more each, not the whole item again.
    let out = host_sim(&["step", "--plant-effects", "coulomb_n=200,backlash_deg=nan"]);
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.matches("backlash_deg=nan").count(), 1, "{err}");
    assert!(
        err.contains("backlash_deg takes a finite number >= 0") && err.contains("not `nan`"),
        "{err}"
    );
}

//! `host-sim sweep`: the sine sweep at the wheel, its frequency response and bandwidth.

use super::common::{
    Common, plot_title, print_limits, report_setup, save_log, sensors_label, summary_rows,
    time_plot,
};
use super::limits::{bound_text, physical_limit, share_of_bound};
use super::{Result, save_svg, write_json};
use host_sim::analysis::FrequencyResponse;
use host_sim::linear_model::{LinearModel, Output};
use host_sim::plot::{BodePlot, Style};
use host_sim::report::{self, SweepReport};
use host_sim::report_html::{HtmlReport, num};
use host_sim::scenario::Sweep;
use host_sim::sim::Controller;

pub(crate) fn check_sweep(s: &Sweep) -> Result<()> {
    if !(s.amplitude_deg.is_finite() && s.amplitude_deg > 0.0 && s.amplitude_deg <= 90.0) {
        return Err(format!(
            "--amplitude-deg {}: must be in (0, 90] deg (the steering range)",
            s.amplitude_deg
        )
        .into());
    }
    if !(s.f_end_hz.is_finite() && s.f_end_hz > 0.0 && s.f_end_hz <= 50.0) {
        return Err(format!(
            "--f-end-hz {}: must be in (0, 50] Hz (the 100 Hz reference's Nyquist limit)",
            s.f_end_hz
        )
        .into());
    }
    if !(s.duration_s.is_finite() && s.duration_s >= 4.0 && s.duration_s <= 600.0) {
        return Err(format!("--duration-s {}: must be in [4, 600] s", s.duration_s).into());
    }
    Ok(())
}

pub(crate) fn sweep_cmd(sweep: &Sweep, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let (rep, run) = report::sweep(sweep, &cfg)?;
    say!(
        "Sine sweep 0-{} Hz in {} s, {} deg at the wheel ({})",
        sweep.f_end_hz,
        sweep.duration_s,
        sweep.amplitude_deg,
        sensors_label(common)
    );
    match rep.bandwidth_hz {
        Some(bw) => say!(
            "  -3 dB bandwidth    {bw:6.2} Hz  (paper, suspended: 5 Hz; on the ground: 4.8 Hz)"
        ),
        None => say!(
            "  -3 dB bandwidth    above {} Hz (paper: 5 Hz)",
            sweep.f_end_hz
        ),
    }
    let limit = physical_limit(&cfg);
    let bound = limit.bandwidth_bound_hz(sweep.amplitude_deg);
    let saturated = limit.saturated().bandwidth_bound_hz(sweep.amplitude_deg);
    say!(
        "  physical bound     {}  ({} A / {} V sinusoidal on this plant, any controller: \
         `host-sim limits`); the bandwidth is {} of it",
        bound_text(bound),
        limit.current_limit_a,
        limit.voltage_limit_v,
        share_of_bound(rep.bandwidth_hz, bound)
    );
    say!(
        "  saturated bound    {}  (the same limits as square waves: fundamentals 4/pi higher); \
         the bandwidth is {} of it",
        bound_text(saturated),
        share_of_bound(rep.bandwidth_hz, saturated)
    );
    // The linear model of the paper cascade (exact sensors, no limits); not for other controllers.
    let analytic = match cfg.controller {
        Controller::Paper => {
            let model = LinearModel::new(cfg.plant, &cfg.gains)?;
            let grid: Vec<f64> = (1..=(sweep.f_end_hz * 20.0).round() as usize)
                .map(|k| k as f64 / 20.0)
                .collect();
            let fr = model.bode(&grid, Output::Column, cfg.log_rate_hz)?;
            let bw = model.bandwidth_hz(
                report::BANDWIDTH_SEARCH_FROM_HZ,
                sweep.f_end_hz,
                cfg.log_rate_hz,
            );
            if !model.is_stable() {
                say!(
                    "  linear model: the closed loop is UNSTABLE on this plant (`host-sim poles`)"
                );
            }
            match bw {
                Some(bw) => say!(
                    "  linear model       {bw:6.2} Hz  (small signal, exact sensors: `host-sim poles`)"
                ),
                None => say!("  linear model       above {} Hz", sweep.f_end_hz),
            }
            Some((fr, bw))
        }
        Controller::Ecu => None,
    };
    say!("  RMS error          {:6.2} deg", rep.tracking.rmse);
    print_limits(&rep.summary, common.supply_v);
    // Small-signal response for comparison: the same loop where no limit is reached.
    let small = Sweep {
        amplitude_deg: 1.0,
        ..*sweep
    };
    let (small_rep, _) = report::sweep(&small, &cfg)?;
    let json;
    let small_bound = limit.bandwidth_bound_hz(small.amplitude_deg);
    if let Some(bw) = small_rep.bandwidth_hz {
        say!(
            "  (at 1 deg, below the speed limit: {bw:.2} Hz, {} of its bound of {})",
            share_of_bound(Some(bw), small_bound),
            bound_text(small_bound).trim_start()
        );
    }
    {
        let mut v = serde_json::to_value(&rep)?;
        v["small_signal_bandwidth_hz"] = serde_json::json!(small_rep.bandwidth_hz);
        v["paper_bandwidth_hz"] = serde_json::json!(5.0);
        v["bandwidth_bound_hz"] = serde_json::json!(bound);
        v["bandwidth_share_of_bound"] =
            serde_json::json!(rep.bandwidth_hz.zip(bound).map(|(bw, b)| bw / b));
        v["saturated_bandwidth_bound_hz"] = serde_json::json!(saturated);
        v["small_signal_bandwidth_bound_hz"] = serde_json::json!(small_bound);
        v["analytic_bandwidth_hz"] = serde_json::json!(analytic.as_ref().and_then(|a| a.1));
        if let Some(path) = &common.json {
            write_json(path, &v)?;
        }
        json = v;
    }
    save_log(&run.log, common)?;
    if common.plots.is_none() && common.report.is_none() {
        return Ok(());
    }
    let bode = bode_plot(sweep, &rep, &small_rep, analytic.as_ref().map(|a| &a.0));
    let title = format!(
        "Sine sweep 0-{} Hz, {} deg at the wheel",
        sweep.f_end_hz, sweep.amplitude_deg
    );
    let time = time_plot(&plot_title(common, &title), &run, common.supply_v);
    if let Some(dir) = &common.plots {
        save_svg(dir, "sweep_bode.svg", |p| bode.save(p))?;
        save_svg(dir, "sweep_time.svg", |p| time.save(p))?;
    }
    if let Some(path) = &common.report {
        let above = format!("above {} Hz", sweep.f_end_hz);
        let page = report_setup(HtmlReport::new(&format!("host-sim sweep: {title}")), common)
            .numbers(
                &json,
                &[
                    num("-3 dB bandwidth", "/bandwidth_hz", "Hz").absent(&above),
                    num("paper's (suspended)", "/paper_bandwidth_hz", "Hz").decimals(1),
                    num("physical bound", "/bandwidth_bound_hz", "Hz").absent("none"),
                    num("bandwidth / bound", "/bandwidth_share_of_bound", "%")
                        .percent()
                        .decimals(0),
                    num("saturated bound", "/saturated_bandwidth_bound_hz", "Hz").absent("none"),
                    num("linear model", "/analytic_bandwidth_hz", "Hz"),
                    num("RMS error", "/tracking/rmse", "deg"),
                    num("bandwidth at 1 deg", "/small_signal_bandwidth_hz", "Hz").absent(&above),
                    num("bound at 1 deg", "/small_signal_bandwidth_bound_hz", "Hz").absent("none"),
                ],
            );
        summary_rows(page, &json)
            .figure(
                "Frequency response (H1 estimate) with coherence",
                &bode.to_svg(),
            )
            .figure("Time traces of the sweep", &time.to_svg())
            .save(path)?;
        say!("report written to {}", path.display());
    }
    Ok(())
}

pub(crate) fn bode_plot(
    sweep: &Sweep,
    rep: &SweepReport,
    small: &SweepReport,
    analytic: Option<&FrequencyResponse>,
) -> BodePlot {
    let main = format!("{} deg", sweep.amplitude_deg);
    let add = |plot: BodePlot, name: &str, fr: &FrequencyResponse, style: Style| {
        plot.series_styled(name, &fr.freq_hz, &fr.magnitude_db, &fr.phase_deg, style)
    };
    let mut plot = BodePlot::new("Column angle / reference at the wheel (H1 estimate, simulated)");
    plot = add(plot, &main, &rep.response, Style::new());
    plot = add(
        plot,
        "1 deg (small signal)",
        &small.response,
        Style::new().dashed(),
    );
    if let Some(fr) = analytic {
        plot = add(
            plot,
            ANALYTIC_LABEL,
            fr,
            Style::new().dashed().color(host_sim::plot::Color::BLACK),
        );
    }
    plot = plot.coherence(&main, &rep.response.freq_hz, &rep.response.coherence);
    if let Some(bw) = rep.bandwidth_hz {
        plot = plot.bandwidth_of(&main, bw);
    }
    if let Some(bw) = small.bandwidth_hz {
        plot = plot.bandwidth_of("1 deg (small signal)", bw);
    }
    plot
}

/// The Bode plot's name for the linear model's curve (`linear_model.rs`).
pub(crate) const ANALYTIC_LABEL: &str = "analytic (linear model)";

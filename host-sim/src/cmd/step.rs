//! `host-sim step`: a step at the wheel.

use super::common::{Common, print_limits, save_log, sensors_label, time_outputs};
use super::{Result, write_json};
use host_sim::report;
use host_sim::report_html::num;
use host_sim::scenario;

pub(crate) fn step_cmd(amplitude_deg: f64, duration_s: f64, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let reference = scenario::step(amplitude_deg, 0.1, duration_s);
    let (rep, run) = report::step(&reference, amplitude_deg, &cfg)?;
    say!(
        "Step of {amplitude_deg} deg at the wheel at 0.1 s ({})",
        sensors_label(common)
    );
    match rep.rise_time_s {
        Some(t) => say!("  10-90 % rise time  {:6.3} s", t),
        None => say!("  10-90 % rise time  not reached"),
    }
    say!(
        "  overshoot          {:6.2} deg ({:.1} %)",
        rep.overshoot_deg,
        rep.overshoot_pct
    );
    say!("  final error        {:6.2} deg", rep.final_error_deg);
    print_limits(&rep.summary, common.supply_v);
    let json = serde_json::to_value(&rep)?;
    if let Some(path) = &common.json {
        write_json(path, &json)?;
    }
    save_log(&run.log, common)?;
    let title = format!("Step of {amplitude_deg} deg at the wheel");
    time_outputs(
        common,
        &run,
        &title,
        "step_time.svg",
        "host-sim step",
        |page| {
            page.numbers(
                &json,
                &[
                    num("10-90 % rise time", "/rise_time_s", "s")
                        .decimals(3)
                        .absent("not reached"),
                    num("overshoot", "/overshoot_deg", "deg"),
                    num("overshoot", "/overshoot_pct", "%").decimals(1),
                    num("final error", "/final_error_deg", "deg"),
                ],
            )
        },
        &json,
    )
}

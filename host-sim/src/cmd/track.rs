//! `host-sim track`: a driverless track run.

use super::common::{Common, print_limits, save_log, sensors_label, time_outputs};
use super::{Result, write_json};
use host_sim::report::{self, TrackReport};
use host_sim::report_html::num;
use host_sim::sim::Run;

pub(crate) fn track_cmd(reference: &[f64], name: &str, common: &Common) -> Result<()> {
    let cfg = common.config()?;
    let (rep, run): (TrackReport, Run) = report::track(reference, &cfg)?;
    say!(
        "Track run, {} ({:.1} s, {})",
        name,
        rep.summary.duration_s,
        sensors_label(common)
    );
    say!(
        "  RMSE               {:6.2} deg (paper, section 4.4: 3 deg)",
        rep.rmse_deg
    );
    say!(
        "  max |error|        {:6.2} deg at {:.2} s (paper: 4.5 deg at 89.4 s; 15.7 deg in a burst above 4 Hz)",
        rep.max_error_deg,
        rep.max_error_at_s
    );
    print_limits(&rep.summary, common.supply_v);
    let json = serde_json::to_value(&rep)?;
    if let Some(path) = &common.json {
        write_json(path, &json)?;
    }
    save_log(&run.log, common)?;
    let title = format!("Track run: {name}");
    time_outputs(
        common,
        &run,
        &title,
        "track_time.svg",
        "host-sim track",
        |page| {
            page.setup("reference", name).numbers(
                &json,
                &[
                    num("RMSE", "/rmse_deg", "deg"),
                    num("max |error|", "/max_error_deg", "deg"),
                    num("max |error| at", "/max_error_at_s", "s"),
                ],
            )
        },
        &json,
    )
}

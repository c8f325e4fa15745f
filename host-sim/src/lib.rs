//! host-sim: the paper's steering actuator (plant of eqs. 1-8) under the firmware's own control
//! core, with the scenarios, the analysis and the pictures around it.
pub mod analysis;
pub mod car;
pub mod effect_plant;
pub mod epos4_sim;
pub mod firmware_fixture;
pub mod gap;
pub mod golden;
pub mod linear_model;
pub mod plant;
pub mod plot;
pub mod report;
pub mod report_html;
pub mod sim;
pub mod sim_ecu;

// The bus and the files are shared with steer-can, which must build without the numerics
// above, so they live in their own crates (`canlink`, `host-io`); host-sim's modules and tests
// name them here as before.
pub use canlink::canbus;
pub use host_io::{logfmt, out, scenario};

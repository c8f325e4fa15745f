//! host-sim: the paper's steering actuator (plant of eqs. 1-8) under the firmware's own control
//! core, with the scenarios, the analysis and the pictures around it.
pub mod analysis;
pub mod bringup;
pub mod canbus;
pub mod effect_plant;
pub mod epos4_sim;
pub mod gap;
pub mod golden;
pub mod linear_model;
pub mod logfmt;
pub mod out;
pub mod plant;
pub mod plot;
pub mod report;
pub mod report_html;
pub mod scenario;
pub mod sim;
pub mod sim_ecu;

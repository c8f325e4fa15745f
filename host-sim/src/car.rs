//! What a car is, as a log's header names it: its drive and the ECU's controller. Below the
//! simulation and the diagnosis, which both write and read these names.

/// Which steering controller closes the loop.
#[derive(
    Debug,
    Clone,
    Copy,
    PartialEq,
    Eq,
    Default,
    clap::ValueEnum,
    serde::Serialize,
    serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Controller {
    /// The paper's EPOS4 cascade on the motor angle (Table 3), bit-exact with the firmware.
    #[default]
    Paper,
    /// The ECU's own controller (`steering_ecu::ecu_mode`): inverse belt model, model
    /// feedforward, Hall-timed speed, slow column integral. Always Hall feedback.
    Ecu,
}

/// The car's drive, as the firmware's `drive-epos4` / `drive-direct` builds have it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum CarDrive {
    /// The ECU's own bridge: the cascade on Hall counts at 2 kHz / 20 kHz, as `sim::run`.
    #[default]
    Direct,
    /// A maxon EPOS4: the ECU's CSP target each SYNC, the drive's interpolation and loops on
    /// its own motor angle, its position and current as its TPDOs report them.
    Epos4,
}

impl CarDrive {
    pub fn name(self) -> &'static str {
        match self {
            CarDrive::Direct => "direct",
            CarDrive::Epos4 => "epos4",
        }
    }

    pub fn from_name(name: &str) -> Option<CarDrive> {
        match name.trim().to_ascii_lowercase().as_str() {
            "direct" => Some(CarDrive::Direct),
            "epos4" => Some(CarDrive::Epos4),
            _ => None,
        }
    }
}

pub fn controller_name(c: Controller) -> &'static str {
    match c {
        Controller::Paper => "paper",
        Controller::Ecu => "ecu",
    }
}

pub fn controller_from_name(name: &str) -> Option<Controller> {
    match name.trim().to_ascii_lowercase().as_str() {
        "paper" => Some(Controller::Paper),
        "ecu" => Some(Controller::Ecu),
        _ => None,
    }
}

/// The header lines of a log of this car (`# drive: ...`, `# controller: ...`), for the
/// writers.
pub fn header_lines(drive: CarDrive, controller: Controller) -> Vec<String> {
    vec![
        format!("drive: {}", drive.name()),
        format!("controller: {}", controller_name(controller)),
    ]
}

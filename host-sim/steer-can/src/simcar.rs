//! The simulated car behind `--iface sim` and `--iface sim:PATH`, `sim-car` and `rehearse`:
//! host-sim's car (the firmware's tasks, the simulated EPOS4, the plant) as the global options
//! describe it. It exists with the default feature `sim` only; the laptop build
//! (`--no-default-features`, no simulator numerics) answers each of these with
//! [`BringupError::NoSimCar`], which says how to get a build that has it.

use crate::args::Cli;
use crate::commands::Outcome;
use crate::{BringupError, Transport};
use std::path::Path;

#[cfg(feature = "sim")]
use crate::args::{Command, DriveArg};
#[cfg(feature = "sim")]
use crate::commands::stop_flag;
#[cfg(feature = "sim")]
use crate::profile;
#[cfg(feature = "sim")]
use host_sim::sim_ecu::{CarEffects, Injection, SimCar, SimDrive, SimEcu};
#[cfg(feature = "sim")]
use steering_ecu::as_state::AsState;

/// The bus of `--iface sim` (a car of this call alone, held to the wall clock unless `--fast`)
/// or `--iface sim:PATH` (the car `sim-car` serves).
#[cfg(feature = "sim")]
pub fn open(cli: &Cli) -> Result<Box<dyn Transport>, BringupError> {
    if let Some(path) = cli.iface.strip_prefix("sim:") {
        #[cfg(unix)]
        return Ok(Box::new(crate::simsock::SimSocket::connect(Path::new(
            path,
        ))?));
        #[cfg(not(unix))]
        return Err(BringupError::Usage {
            reason: format!("--iface sim:{path}: a shared simulated car needs Unix sockets"),
        });
    }
    let mut sim = sim_car(cli)?;
    if matches!(cli.command, Command::Record { .. }) {
        vehicle_for_record(&mut sim)?;
    }
    if cli.fast {
        return Ok(Box::new(sim));
    }
    Ok(Box::new(crate::WallPaced::new(sim)))
}

/// `sim-car`: one simulated car served on a Unix socket until Ctrl-C.
#[cfg(feature = "sim")]
pub fn serve(cli: &Cli, socket: &Path) -> Result<Outcome, BringupError> {
    #[cfg(unix)]
    {
        crate::simsock::serve(sim_car(cli)?, socket, &stop_flag())?;
        Ok(Outcome::Served)
    }
    #[cfg(not(unix))]
    Err(BringupError::Usage {
        reason: format!("sim-car --socket {}: needs Unix sockets", socket.display()),
    })
}

/// The vehicle computer of the simulated car while `record` listens: 0.3 s in AS Ready, a
/// 5 deg, 1 Hz sine for 2 s in AS Driving, 0.2 s of AS Finished and 0.2 s of AS Off, then
/// silence. On the car someone else steers while `record` listens; without this the recording
/// would hold no reference frame and `convert` would have no log to build.
#[cfg(feature = "sim")]
fn record_vehicle_script() -> Result<Vec<(AsState, f64)>, BringupError> {
    let sine = profile::sine(5.0, 1.0, 2.0)?;
    let mut script = vec![(AsState::Ready, 0.0); 30];
    script.extend(sine.samples.iter().map(|&deg| (AsState::Driving, deg)));
    let last = sine.samples.last().copied().unwrap_or(0.0);
    script.extend([(AsState::Finished, last); 20]);
    script.extend([(AsState::Off, last); 20]);
    Ok(script)
}

/// The simulated car the global options describe (`--drive`, `--controller`,
/// `--sim-column-deg`, `--sim-inject`), at t = 0.
#[cfg(feature = "sim")]
pub fn sim_car(cli: &Cli) -> Result<SimEcu, BringupError> {
    let effects = match &cli.plant_effects {
        Some(list) => list
            .parse::<CarEffects>()
            .map_err(|e| BringupError::Usage {
                reason: format!("--plant-effects `{list}`: {e}"),
            })?,
        None => CarEffects::NONE,
    };
    let mut sim = SimEcu::new(SimCar {
        column_deg: cli.sim_column_deg,
        controller: cli.controller.kind(),
        drive: match cli.drive {
            DriveArg::Epos4 => SimDrive::Epos4,
            DriveArg::Direct => SimDrive::Direct,
        },
        effects,
    });
    if let Some(spec) = &cli.sim_inject {
        let bad = || BringupError::Usage {
            reason: format!(
                "--sim-inject `{spec}`: expected KIND@SECONDS, KIND one of encoder, overcurrent, epos"
            ),
        };
        let (kind, at) = spec.split_once('@').ok_or_else(bad)?;
        let injection = Injection::parse(kind).ok_or_else(bad)?;
        if !sim.can_inject(injection) {
            return Err(BringupError::Usage {
                reason: format!(
                    "--sim-inject `{spec}`: the EPOS4 senses its own current; a current-sense \
                     fault exists in direct drive only (--drive direct)"
                ),
            });
        }
        let at_s = crate::bounds::inject_at_s(spec, at)?;
        sim.inject_at((at_s * 1e6) as u64, injection);
    }
    Ok(sim)
}

/// Let the simulated vehicle computer steer while `record` listens (`record_vehicle_script`).
#[cfg(feature = "sim")]
pub fn vehicle_for_record(sim: &mut SimEcu) -> Result<(), BringupError> {
    eprintln!(
        "sim: a simulated vehicle computer steers while this records (0.3 s AS Ready, a 5 deg \
         1 Hz sine for 2 s in AS Driving, AS Finished, AS Off)"
    );
    sim.script_vehicle(record_vehicle_script()?);
    Ok(())
}

/// Without the `sim` feature: `--iface sim`/`sim:PATH` name a car this build does not have.
#[cfg(not(feature = "sim"))]
pub fn open(cli: &Cli) -> Result<Box<dyn Transport>, BringupError> {
    Err(BringupError::NoSimCar {
        asked: format!("--iface {}", cli.iface),
    })
}

/// Without the `sim` feature: no car to serve.
#[cfg(not(feature = "sim"))]
pub fn serve(_cli: &Cli, _socket: &Path) -> Result<Outcome, BringupError> {
    Err(BringupError::NoSimCar {
        asked: "sim-car".into(),
    })
}

//! The `steer-can` entry point: parse the command line (`args.rs`), open the bus, run the
//! command. `--iface sim` runs every command against the simulated car (`host_sim::sim_ecu`
//! through `simcar`, the default firmware unless `--drive direct`), held to the wall clock
//! unless `--fast`: the tests use it, and a team can rehearse the bring-up on a laptop before
//! the car is there (`rehearse`, `sim-car`).
//!
//! The modules form layers, each importing only from the ones below it:
//!
//! ```text
//!   cli        main, open the bus, dispatch
//!    |-- rehearse   the README's bring-up list on one simulated car
//!    |-- simcar     the simulated car the global options describe
//!   commands   what each command does on a bus, and what it found (Outcome)
//!   args       the clap types
//! ```

use super::args::{Cli, Command, command};
use super::commands::{Outcome, convert, decoder, execute};
#[cfg(feature = "sim")]
use super::rehearse::rehearse;
use super::simcar;
use super::{BringupError, Transport};
use canlink::reference::ReferenceSender;
use clap::FromArgMatches;
use std::process::ExitCode;
use steering_ecu::canopen::NodeId;

/// Entry point of the binary.
pub fn main() -> ExitCode {
    let matches = command().get_matches();
    let cli = match Cli::from_arg_matches(&matches) {
        Ok(cli) => cli.with_command_defaults(&matches),
        Err(e) => e.exit(),
    };
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("steer-can: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// The bus the command runs on: the car's SocketCAN interface, or the simulated car
/// (`sim`, `sim:PATH`), which only a build with the `sim` feature has.
fn open(cli: &Cli) -> Result<Box<dyn Transport>, BringupError> {
    if cli.iface == "sim" || cli.iface.starts_with("sim:") {
        return simcar::open(cli);
    }
    #[cfg(target_os = "linux")]
    {
        Ok(Box::new(super::socketcan::SocketCan::open(&cli.iface)?))
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(BringupError::Link(canlink::LinkError::NoInterface {
            iface: cli.iface.clone(),
            detail: "SocketCAN exists on Linux only".into(),
        }))
    }
}

fn run(cli: Cli) -> Result<ExitCode, BringupError> {
    super::bounds::check(&cli)?;
    let node = NodeId::new(cli.node).ok_or_else(|| BringupError::Usage {
        reason: format!("--node {}: a CANopen node ID is 1 to 127", cli.node),
    })?;
    let dec = decoder(node)?;
    let outcome = match &cli.command {
        Command::Convert {
            candump: path,
            out,
            all_rows,
        } => Outcome::Convert(convert(path, out, &dec, *all_rows)?),
        Command::Rehearse { dir } => {
            if cli.iface != "sim" {
                return Err(BringupError::Usage {
                    reason: format!(
                        "rehearse runs on the simulated car only (--iface sim), not on {}",
                        cli.iface
                    ),
                });
            }
            rehearse(&cli, dir)?
        }
        Command::SimCar { socket } => simcar::serve(&cli, socket)?,
        command => {
            let mut t = open(&cli)?;
            execute(
                command,
                node,
                &dec,
                t.as_mut(),
                &mut ReferenceSender::default(),
            )?
        }
    };
    Ok(outcome.exit_code())
}

/// Without the `sim` feature: no car to rehearse on.
#[cfg(not(feature = "sim"))]
fn rehearse(_cli: &Cli, _dir: &std::path::Path) -> Result<Outcome, BringupError> {
    Err(BringupError::NoSimCar {
        asked: "rehearse".into(),
    })
}

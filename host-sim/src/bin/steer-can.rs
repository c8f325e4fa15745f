//! `steer-can`: CAN bring-up of the steering ECU on the car (see `host_sim::bringup`).
//! `cargo run -p host-sim --bin steer-can -- monitor --iface can0`.

fn main() -> std::process::ExitCode {
    host_sim::bringup::cli::main()
}

//! `steer-can`: CAN bring-up of the steering ECU on the car (see the `steer_can` library).
//! `cargo run --release -p steer-can -- monitor --iface can0`.

fn main() -> std::process::ExitCode {
    steer_can::cli::main()
}

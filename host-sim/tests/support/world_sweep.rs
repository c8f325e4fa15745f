//! The sweep the independent world's tests drive its cars with: 8 deg, 0.2-4 Hz, 6 s
//! ([`sweep`]) or as long as a test needs ([`sweep_of`]).
#![allow(dead_code)] // each test binary takes the one it needs

pub fn sweep() -> Vec<f64> {
    sweep_of(6.0)
}

pub fn sweep_of(duration_s: f64) -> Vec<f64> {
    host_sim::scenario::Sweep {
        amplitude_deg: 8.0,
        f_start_hz: 0.2,
        f_end_hz: 4.0,
        duration_s,
    }
    .samples()
}

//! The sweep the independent world's tests drive its cars with: 8 deg, 0.2-4 Hz, 6 s.

pub fn sweep() -> Vec<f64> {
    host_sim::scenario::Sweep {
        amplitude_deg: 8.0,
        f_start_hz: 0.2,
        f_end_hz: 4.0,
        duration_s: 6.0,
    }
    .samples()
}

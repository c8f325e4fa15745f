//! Figures from a run or a recorded log: the frequency response by the H1 estimator, the
//! -3 dB bandwidth, tracking errors, and the goodness of fit of eq. 11.

use rustfft::FftPlanner;
use rustfft::num_complex::Complex;
use std::f64::consts::PI;

/// Frequency response estimated from input `x` and output `y` sampled at `fs`.
#[derive(Debug, Clone, Default, serde::Serialize)]
pub struct FrequencyResponse {
    pub freq_hz: Vec<f64>,
    pub magnitude_db: Vec<f64>,
    pub phase_deg: Vec<f64>,
    /// Magnitude-squared coherence, 0..1.
    pub coherence: Vec<f64>,
}

/// H1 estimate `Sxy / Sxx` with Welch averaging: Hann-windowed segments of `segment_s`
/// seconds, 75 % overlap, means removed per segment. Bins above `f_max_hz` are dropped.
/// Returns an empty response when the record is shorter than one segment.
pub fn h1_estimate(
    x: &[f64],
    y: &[f64],
    fs: f64,
    segment_s: f64,
    f_max_hz: f64,
) -> FrequencyResponse {
    let len = x.len().min(y.len());
    let nseg = ((segment_s * fs).round() as usize).max(8);
    if len < nseg || fs.is_nan() || fs <= 0.0 {
        return FrequencyResponse::default();
    }
    let hop = (nseg / 4).max(1);
    let window: Vec<f64> = (0..nseg)
        .map(|i| 0.5 - 0.5 * (2.0 * PI * i as f64 / nseg as f64).cos())
        .collect();
    let fft = FftPlanner::<f64>::new().plan_fft_forward(nseg);
    let bins = nseg / 2 + 1;
    let mut sxx = vec![0.0; bins];
    let mut syy = vec![0.0; bins];
    let mut sxy = vec![Complex::new(0.0, 0.0); bins];
    let mut bx = vec![Complex::new(0.0, 0.0); nseg];
    let mut by = vec![Complex::new(0.0, 0.0); nseg];
    let mut start = 0;
    while start + nseg <= len {
        let xs = &x[start..start + nseg];
        let ys = &y[start..start + nseg];
        let mx = xs.iter().sum::<f64>() / nseg as f64;
        let my = ys.iter().sum::<f64>() / nseg as f64;
        for i in 0..nseg {
            bx[i] = Complex::new((xs[i] - mx) * window[i], 0.0);
            by[i] = Complex::new((ys[i] - my) * window[i], 0.0);
        }
        fft.process(&mut bx);
        fft.process(&mut by);
        for k in 0..bins {
            sxx[k] += bx[k].norm_sqr();
            syy[k] += by[k].norm_sqr();
            sxy[k] += bx[k].conj() * by[k];
        }
        start += hop;
    }
    let mut out = FrequencyResponse::default();
    // The largest input power, to skip bins the input never excited.
    let sxx_max = sxx.iter().cloned().fold(0.0, f64::max);
    for k in 1..bins {
        let f = k as f64 * fs / nseg as f64;
        if f > f_max_hz {
            break;
        }
        if sxx[k] <= sxx_max * 1e-6 {
            continue;
        }
        let h = sxy[k] / sxx[k];
        out.freq_hz.push(f);
        out.magnitude_db.push(20.0 * h.norm().max(1e-300).log10());
        out.phase_deg.push(h.arg().to_degrees());
        out.coherence.push(if syy[k] > 0.0 {
            sxy[k].norm_sqr() / (sxx[k] * syy[k])
        } else {
            0.0
        });
    }
    unwrap_phase_deg(&mut out.phase_deg);
    out
}

fn unwrap_phase_deg(phase: &mut [f64]) {
    for i in 1..phase.len() {
        let mut d = phase[i] - phase[i - 1];
        while d > 180.0 {
            phase[i] -= 360.0;
            d -= 360.0;
        }
        while d < -180.0 {
            phase[i] += 360.0;
            d += 360.0;
        }
    }
}

/// The first frequency above `f_min_hz` where the magnitude falls below -3 dB, interpolated
/// linearly (in dB) between bins. `None` if it never does within the response.
pub fn bandwidth_hz(fr: &FrequencyResponse, f_min_hz: f64) -> Option<f64> {
    let pts: Vec<(f64, f64)> = fr
        .freq_hz
        .iter()
        .zip(&fr.magnitude_db)
        .filter(|(f, _)| **f >= f_min_hz)
        .map(|(f, m)| (*f, *m))
        .collect();
    if pts.first().is_some_and(|p| p.1 < -3.0) {
        return pts.first().map(|p| p.0);
    }
    pts.windows(2).find(|w| w[1].1 < -3.0).map(|w| {
        let (f0, m0) = w[0];
        let (f1, m1) = w[1];
        f0 + (f1 - f0) * (m0 + 3.0) / (m0 - m1)
    })
}

/// Tracking figures of `y` against `reference` (same units), NaN samples skipped.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct TrackingError {
    pub rmse: f64,
    pub max_abs: f64,
    /// Index of the largest error.
    pub at_index: usize,
}

pub fn tracking_error(reference: &[f64], y: &[f64]) -> TrackingError {
    let mut sum = 0.0;
    let mut n = 0usize;
    let mut out = TrackingError::default();
    for (i, (r, v)) in reference.iter().zip(y).enumerate() {
        let e = v - r;
        if !e.is_finite() {
            continue;
        }
        sum += e * e;
        n += 1;
        if e.abs() > out.max_abs {
            out.max_abs = e.abs();
            out.at_index = i;
        }
    }
    out.rmse = if n > 0 {
        (sum / n as f64).sqrt()
    } else {
        f64::NAN
    };
    out
}

/// Goodness of fit, eq. 11: `1 - ||y - y_sim|| / ||y - mean(y)||` (1 = perfect, can be < 0).
pub fn goodness_of_fit(measured: &[f64], simulated: &[f64]) -> f64 {
    let n = measured.len().min(simulated.len());
    if n == 0 {
        return f64::NAN;
    }
    let mean = measured[..n].iter().sum::<f64>() / n as f64;
    let num: f64 = (0..n).map(|i| (measured[i] - simulated[i]).powi(2)).sum();
    let den: f64 = measured[..n].iter().map(|v| (v - mean).powi(2)).sum();
    1.0 - (num / den).sqrt()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order low-pass of known corner, driven by a chirp: the estimator must find it.
    #[test]
    fn h1_finds_the_corner_of_a_first_order_lowpass() {
        let fs = 1000.0;
        let fc = 3.0;
        let n = 20_000;
        let x: Vec<f64> = (0..n)
            .map(|k| {
                let t = k as f64 / fs;
                (2.0 * PI * (0.5 * 0.5 * t * t)).sin() // 0 -> 10 Hz in 20 s
            })
            .collect();
        let a = (-2.0 * PI * fc / fs).exp();
        let mut y = vec![0.0; n];
        for k in 1..n {
            y[k] = a * y[k - 1] + (1.0 - a) * x[k - 1];
        }
        let fr = h1_estimate(&x, &y, fs, 2.0, 10.0);
        let bw = bandwidth_hz(&fr, 0.5).expect("falls below -3 dB");
        assert!((bw - fc).abs() < 0.2, "bandwidth {bw} Hz");
        let coh_min = fr.coherence.iter().cloned().fold(1.0, f64::min);
        assert!(
            coh_min > 0.95,
            "noise-free linear system: coherence {coh_min}"
        );
    }

    #[test]
    fn bandwidth_is_none_for_a_flat_response() {
        let fr = FrequencyResponse {
            freq_hz: vec![1.0, 2.0, 3.0],
            magnitude_db: vec![0.0, -0.5, -1.0],
            phase_deg: vec![0.0; 3],
            coherence: vec![1.0; 3],
        };
        assert_eq!(bandwidth_hz(&fr, 0.5), None);
    }

    #[test]
    fn tracking_error_and_gof() {
        let r = [0.0, 1.0, 2.0, 3.0];
        let y = [0.0, 1.0, 2.0, 5.0];
        let te = tracking_error(&r, &y);
        assert!((te.rmse - 1.0).abs() < 1e-12);
        assert_eq!(te.max_abs, 2.0);
        assert_eq!(te.at_index, 3);
        assert!((goodness_of_fit(&r, &r) - 1.0).abs() < 1e-12);
        assert!(goodness_of_fit(&r, &[1.5; 4]) < 0.01);
    }

    #[test]
    fn short_records_give_an_empty_response() {
        let fr = h1_estimate(&[1.0; 10], &[1.0; 10], 100.0, 2.0, 10.0);
        assert!(fr.freq_hz.is_empty());
        assert_eq!(bandwidth_hz(&fr, 0.5), None);
    }
}

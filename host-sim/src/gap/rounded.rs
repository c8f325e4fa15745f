//! A reference column a logger rounded coarser than the car received it.
//!
//! The ECU receives its reference in steps of 0.01 deg (`REF_SteeringAngle`, src/protocol). A
//! team's logger may print it with one decimal, or in half degrees: the column then stands on a
//! level for a few rows and jumps by a step, where the car steered to a reference that moved
//! smoothly between. The model, run on the steps, takes the velocity and acceleration
//! feedforward of each jump: on the independent world's effect-free 120 s track, printed to
//! 0.1 deg (0.028 deg RMS of rounding), the reference's second difference was 650 deg/s^2 RMS
//! off the car's (the track's own is 1 290), the EPOS4 drive fitted better than the direct
//! drive that drove it, and the car was `unexplained` at 248 times its noise floor.
//!
//! Such a column is read as the smoothest line its rounding allows: a centred mean of three
//! rows, held within half a step of the logged value, three times over. On that track this
//! leaves the reference 0.019 deg RMS from the car's and its second difference 178 deg/s^2;
//! on a sweep, whose reference moves several steps a row, it changes little (0.028 -> 0.046
//! deg, its second difference 734 -> 598 deg/s^2 of 3 300).

/// The steps tried, deg, coarsest first: whole degrees, halves, fifths, tenths, twentieths.
/// The car's own 0.01 deg, and anything finer, is read as logged.
const STEPS_DEG: [f64; 5] = [1.0, 0.5, 0.2, 0.1, 0.05];

/// Passes of the three-row mean, each held within the rounding's band.
const PASSES: usize = 3;

/// Fewest changes of the column by one step, and their least share of its changes, for it to
/// be a rounded line rather than a reference of whole steps (a step test's 0 -> 10 deg moves
/// by many steps at once and never by one). The world's sweeps and track printed to 0.1 deg
/// change by one step in 8-35 % of their changes, 95-2 447 times.
const ONE_STEP_CHANGES: usize = 20;
const ONE_STEP_SHARE: f64 = 0.05;

/// The coarsest of [`STEPS_DEG`] that every finite value of `reference` is a whole multiple of,
/// deg, where the column moves as a rounded line does ([`ONE_STEP_CHANGES`]); `None` for a
/// column finer than 0.05 deg (the car's 0.01 deg, a float), or one of whole steps.
pub fn step_of(reference: &[f64]) -> Option<f64> {
    let finite: Vec<f64> = reference
        .iter()
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let step = STEPS_DEG.into_iter().find(|q| {
        finite
            .iter()
            .all(|v| ((v / q) - (v / q).round()).abs() < 1e-6)
    })?;
    let changes: Vec<f64> = finite
        .windows(2)
        .filter(|w| w[1] != w[0])
        .map(|w| (w[1] - w[0]).abs())
        .collect();
    let one_step = changes.iter().filter(|c| **c < 1.5 * step).count();
    (one_step >= ONE_STEP_CHANGES && one_step as f64 >= ONE_STEP_SHARE * changes.len() as f64)
        .then_some(step)
}

/// `reference`, rounded to steps of `step`, read as the smoothest line its rounding allows
/// (module doc): each value stays within half a step of the logged one.
pub fn smoothed_within(reference: &[f64], step: f64) -> Vec<f64> {
    let half = 0.5 * step;
    let mut s = reference.to_vec();
    for _ in 0..PASSES {
        s = (0..s.len())
            .map(|k| {
                let lo = k.saturating_sub(1);
                let hi = (k + 2).min(s.len());
                let mean = s[lo..hi].iter().sum::<f64>() / (hi - lo) as f64;
                mean.clamp(reference[k] - half, reference[k] + half)
            })
            .collect();
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A slow sine of `amplitude` deg, 20 s at 100 Hz, rounded to `step`.
    fn rounded_sine(amplitude: f64, step: f64) -> Vec<f64> {
        (0..2000)
            .map(|k| {
                let v = amplitude * (2.0 * std::f64::consts::PI * 0.3 * 0.01 * k as f64).sin();
                (v / step).round() * step
            })
            .collect()
    }

    #[test]
    fn the_step_is_the_coarsest_every_value_is_a_multiple_of() {
        assert_eq!(step_of(&rounded_sine(3.0, 0.1)), Some(0.1));
        assert_eq!(step_of(&rounded_sine(20.0, 0.5)), Some(0.5));
        assert_eq!(step_of(&rounded_sine(3.0, 0.05)), Some(0.05));
        // The car's own 0.01 deg, and a float, are read as logged.
        assert_eq!(step_of(&rounded_sine(3.0, 0.01)), None);
        let fine: Vec<f64> = rounded_sine(3.0, 0.1).iter().map(|v| v + 1e-4).collect();
        assert_eq!(step_of(&fine), None);
        // A step test's reference is whole degrees but no rounded line.
        let steps: Vec<f64> = (0..2000).map(|k| [0.0, 10.0, -5.0][k / 700]).collect();
        assert_eq!(step_of(&steps), None);
        let mut holed = rounded_sine(3.0, 0.2);
        holed[7] = f64::NAN;
        assert_eq!(step_of(&holed), Some(0.2));
    }

    /// A slow sine (a track's pace) printed to 0.1 deg reads back closer to itself than the
    /// rounding, its second difference far closer, and never beyond half a step of the log.
    #[test]
    fn a_rounded_slow_sine_reads_back_within_its_band_and_smoother() {
        let truth = rounded_sine(3.0, 1e-12);
        let rounded = rounded_sine(3.0, 0.1);
        let back = smoothed_within(&rounded, 0.1);
        let rms = |a: &[f64], b: &[f64]| {
            (a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum::<f64>() / a.len() as f64).sqrt()
        };
        let second =
            |a: &[f64]| -> Vec<f64> { a.windows(3).map(|w| w[2] - 2.0 * w[1] + w[0]).collect() };
        assert!(rms(&back, &truth) < rms(&rounded, &truth));
        assert!(
            rms(&second(&back), &second(&truth)) < 0.5 * rms(&second(&rounded), &second(&truth))
        );
        assert!(
            back.iter()
                .zip(&rounded)
                .all(|(b, r)| (b - r).abs() <= 0.05 + 1e-12)
        );
    }
}

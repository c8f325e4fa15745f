//! What the effort keeps that repeats with the motor's turn: cogging, a torque ripple, an
//! encoder's eccentricity. No candidate effect and no Table 4 parameter depends on where the
//! rotor stands within its turn, so a line at a whole number of periods a turn in the nominal
//! model's effort residual is something the model does not have.
//!
//! Where the motor is slow, the position loop holds the rotor against such a torque and the
//! current carries it (`-T(theta) / k_t`); where it is fast, the inertia filters it and a row's
//! mean current averages it out. So the residual is read on the rows where the motor turned
//! less than half the shortest period scanned, against the rotor's angle over the row.
//!
//! The residual also keeps what the model gets wrong elsewhere (Table 4 a few per cent off,
//! an effect), which falls on every order alike: the strongest order is read against the
//! median of the others, the residual's own level at an order that nothing in the car makes.

use super::Record;
use steering_ecu::sensors::HALL_COUNTS_PER_REV;

/// The orders scanned, periods per motor turn. The lowest orders follow the column's angle
/// (the motor turns 85 times for the column once, so a spring or a tyre error that grows with
/// the steering angle gives them a share); the highest is under half the Hall counts a turn
/// (84) that a log's motor angle may be quantised to: on them an order `n` and `84 - n` read
/// the same, and 42 reads nothing.
pub const ORDERS: std::ops::RangeInclusive<u32> = 4..=(HALL_COUNTS_PER_REV / 2 - 1);

/// A row is slow when the motor turned less than this share of the shortest period scanned.
const SLOW_SHARE_OF_PERIOD: f64 = 0.5;

/// A line stands out at this many times the other orders' median: tracks without a torque of
/// the rotor's angle (the independent world's, either drive and every logger, and the
/// simulated car's) read at most 4.6; the world's cogging tracks (0.010-0.028 Nm) 7.8 or more.
pub const MIN_RATIO: f64 = 6.0;
/// ...and at least this amplitude, A: 2.6 mNm at Table 1's torque constant, a quarter of the
/// smallest cogging the world draws (the simulated car's tracks read at most 0.038 A).
pub const MIN_AMPLITUDE_A: f64 = 0.05;

/// Fewest slow rows to read a line on.
const MIN_ROWS: usize = 200;

/// The strongest line in the effort residual against the motor's angle.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct MotorRipple {
    /// Periods per motor turn of the strongest order.
    pub periods_per_rev: u32,
    /// Its amplitude, the effort's unit (A on the paper rig).
    pub amplitude: f64,
    /// The median amplitude of the other orders: what the residual gives an order by chance.
    pub median_other: f64,
    /// The rows slow enough to read it on.
    pub rows: usize,
    /// The torque the amplitude takes at the motor's torque constant, Nm: a lower bound, as the
    /// loop counters only part of such a torque where the motor moves.
    pub torque_nm: f64,
}

impl MotorRipple {
    /// The strongest order against the others' median.
    pub fn ratio(&self) -> f64 {
        self.amplitude / self.median_other.max(1e-12)
    }

    /// A line no chance gives the residual, and large enough to matter.
    pub fn stands_out(&self) -> bool {
        self.ratio() >= MIN_RATIO && self.amplitude >= MIN_AMPLITUDE_A
    }
}

/// The line, from the log's motor column (output units through the rigid gearing, as
/// [`Record::motor`]), `motor_per_output` motor radians per output unit, and the nominal
/// model's effort; its torque at `torque_constant` Nm per effort unit. `None` without a motor
/// column or with too few slow rows.
pub fn motor_ripple(
    rec: &Record,
    model_effort: &[f64],
    motor_per_output: f64,
    torque_constant: f64,
    skip: usize,
) -> Option<MotorRipple> {
    let motor = rec.motor.as_ref()?;
    let n = rec.len().min(model_effort.len()).min(motor.len());
    let shortest = std::f64::consts::TAU / f64::from(*ORDERS.end());
    let slow = SLOW_SHARE_OF_PERIOD * shortest;
    let rows: Vec<(f64, f64)> = (skip.max(1)..n)
        .filter_map(|k| {
            let (a, b) = (motor[k - 1] * motor_per_output, motor[k] * motor_per_output);
            let r = rec.effort[k] - model_effort[k];
            ((b - a).abs() < slow && r.is_finite() && a.is_finite() && b.is_finite())
                .then_some((0.5 * (a + b), r))
        })
        .collect();
    if rows.len() < MIN_ROWS {
        return None;
    }
    let amplitudes: Vec<(u32, f64)> = ORDERS
        .map(|order| (order, amplitude(&rows, f64::from(order))))
        .collect();
    let &(periods_per_rev, peak) = amplitudes.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    let mut others: Vec<f64> = amplitudes
        .iter()
        .filter(|(o, _)| *o != periods_per_rev)
        .map(|(_, a)| *a)
        .collect();
    others.sort_by(f64::total_cmp);
    Some(MotorRipple {
        periods_per_rev,
        amplitude: peak,
        median_other: others[others.len() / 2],
        rows: rows.len(),
        torque_nm: peak * torque_constant,
    })
}

/// The amplitude of `r = c + a sin(order theta) + b cos(order theta)`, least squares.
fn amplitude(rows: &[(f64, f64)], order: f64) -> f64 {
    // Normal equations of [1, s, c] against r.
    let mut m = [[0.0f64; 3]; 3];
    let mut v = [0.0f64; 3];
    for &(theta, r) in rows {
        let x = [1.0, (order * theta).sin(), (order * theta).cos()];
        for i in 0..3 {
            for j in 0..3 {
                m[i][j] += x[i] * x[j];
            }
            v[i] += x[i] * r;
        }
    }
    match solve3(m, v) {
        Some([_, a, b]) => a.hypot(b),
        None => 0.0,
    }
}

/// `m x = v` by Cramer's rule; `None` when `m` is singular (every row at one angle).
fn solve3(m: [[f64; 3]; 3], v: [f64; 3]) -> Option<[f64; 3]> {
    let det = |m: &[[f64; 3]; 3]| {
        m[0][0] * (m[1][1] * m[2][2] - m[1][2] * m[2][1])
            - m[0][1] * (m[1][0] * m[2][2] - m[1][2] * m[2][0])
            + m[0][2] * (m[1][0] * m[2][1] - m[1][1] * m[2][0])
    };
    let d = det(&m);
    if d.abs() <= 1e-9 * m[0][0].powi(3).max(1e-300) {
        return None;
    }
    Some(std::array::from_fn(|c| {
        let mut mc = m;
        for (row, value) in mc.iter_mut().zip(v) {
            row[c] = value;
        }
        det(&mc) / d
    }))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A motor that steps between standstills over 3.3 turns, the residual a line of
    /// `amplitude` A at `order` periods a turn and a seeded noise of `noise` A; the motor
    /// column in motor radians.
    fn stepping(order: f64, amplitude: f64, noise: f64) -> (Record, Vec<f64>) {
        let mut rng = crate::gap::rng::seeded(7);
        let n = 6000;
        // A standstill of 20 rows at each of 300 angles over 3.3 turns, in no order that
        // follows any one period.
        let motor: Vec<f64> = (0..n)
            .map(|k| ((k / 20) as f64 * 0.0697).rem_euclid(std::f64::consts::TAU * 3.3))
            .collect();
        let effort: Vec<f64> = motor
            .iter()
            .map(|th| amplitude * (order * th).sin() + noise * rng.normal())
            .collect();
        let rec = Record {
            dt: 0.01,
            reference: vec![0.0; n],
            output: vec![0.0; n],
            effort,
            motor: Some(motor),
            ..Record::default()
        };
        (rec, vec![0.0; n])
    }

    #[test]
    fn a_line_at_24_periods_a_turn_is_read_with_its_size() {
        let (rec, model) = stepping(24.0, 0.3, 0.2);
        let r = motor_ripple(&rec, &model, 1.0, 0.05, 0).expect("read");
        assert_eq!(r.periods_per_rev, 24);
        assert!((r.amplitude - 0.3).abs() < 0.03, "{r:?}");
        assert!(r.stands_out(), "{r:?}");
    }

    #[test]
    fn noise_alone_does_not_stand_out() {
        let (rec, model) = stepping(24.0, 0.0, 0.2);
        let r = motor_ripple(&rec, &model, 1.0, 0.05, 0).expect("read");
        assert!(r.ratio() < MIN_RATIO, "{r:?}");
        assert!(!r.stands_out(), "{r:?}");
    }

    #[test]
    fn a_line_too_small_to_matter_is_not_named() {
        let (rec, model) = stepping(24.0, 0.5 * MIN_AMPLITUDE_A, 0.0);
        let r = motor_ripple(&rec, &model, 1.0, 0.05, 0).expect("read");
        assert!(r.ratio() > MIN_RATIO, "{r:?}");
        assert!(!r.stands_out(), "{r:?}");
    }

    #[test]
    fn without_a_motor_column_or_slow_rows_nothing_is_read() {
        let (mut rec, model) = stepping(24.0, 0.3, 0.0);
        let fast: Vec<f64> = (0..rec.len()).map(|k| k as f64 * 0.5).collect();
        rec.motor = Some(fast);
        assert_eq!(motor_ripple(&rec, &model, 1.0, 0.05, 0), None);
        rec.motor = None;
        assert_eq!(motor_ripple(&rec, &model, 1.0, 0.05, 0), None);
    }

    #[test]
    fn rows_that_are_not_finite_are_left_out() {
        let (mut rec, model) = stepping(24.0, 0.3, 0.0);
        for k in (0..rec.len()).step_by(7) {
            rec.effort[k] = f64::NAN;
        }
        if let Some(m) = rec.motor.as_mut() {
            m[100] = f64::INFINITY;
        }
        let r = motor_ripple(&rec, &model, 1.0, 0.05, 0).expect("read");
        assert_eq!(r.periods_per_rev, 24);
        assert!(r.amplitude.is_finite() && r.stands_out(), "{r:?}");
    }
}

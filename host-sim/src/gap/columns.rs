//! A column a team's logger wrote with the other sign, or in another unit.
//!
//! A steering loop that works moves its column with the reference, its motor with its column
//! through the gearing, and draws the current the model's physics draws: each of these goes
//! the same way whatever the car's faults (a friction, play, a tyre, a late reference, Table 4
//! off all keep it). A logger decides the signs of its columns on its own: a current sensor
//! mounted the other way round, an angle counted clockwise, a reference written in the
//! vehicle computer's convention. Read as logged, such a log is a car that steers against its
//! reference, and the diagnosis named on it what fits a current of the wrong sign best (a
//! 100 ms late current on an effect-free sweep).
//!
//! So before the car is fitted, each column is read against the nominal model's on the log's
//! first 10 s (the direct drive under the paper controller: the drives differ in how they
//! follow, not in which way), which the reference drives and which lags as the car does, at
//! the lag where the log's column follows the model's most closely (a reference that reaches
//! the car late lags every column alike; read at no lag, the independent world's sweep with a
//! 59 ms late reference and rack friction read its column at 0.48-0.59 against the model's,
//! and its current at x-0.20 to x0.21, under four loggers):
//! - the column and the motor angle (through the gearing, as [`Record::motor`] holds it): their
//!   correlations with the model's, and the motor's slope, which a motor angle in another unit
//!   than the rig's (degrees for radians) puts far from one;
//! - the current: the effort scale (`score::effort_scale`), whose sign no Table 4
//!   error and no candidate turns, and whose size far outside what any car gives is a current
//!   in another unit than amperes (milliamperes): refused, as a column in another unit is.
//!
//! - the column's slope on the model's: a car turns its column about as the model does
//!   whatever its faults, so a slope far from one is a column in another unit than its
//!   reference (radians beside degrees), on which no diagnosis is possible: it is refused.
//!
//! A column that goes the other way by far more than chance is read negated, and the car line
//! says so with the figure; where the column, the motor angle and the current all oppose the
//! reference, the reference is read negated instead (one column, not three). A motor angle
//! whose slope is no gearing's is left out, as a log without one. Each reading has a margin
//! that no working car's log comes near (the figures at the constants), so a log whose columns
//! agree is read exactly as before.

use super::Record;
use super::drive::{SYNC_SEARCH_S, head, with_car};
use super::model::{Effects, SimOut};
use super::rig::{CarDrive, Rig, RigModel};
use super::score::{Scale, Scorer, effort_scale};
use crate::sim::Controller;

/// A column whose correlation with the nominal model's is below this goes the other way
/// (a noise column reads about zero). At their lags the independent world's logs (the first
/// 20 cars under five loggers of either drive, the first 40 with an effect no candidate has)
/// read the column at 0.845 or more, the motor angle at 0.845 or more.
pub const REVERSED_CORRELATION: f64 = -0.5;

/// A current whose effort scale is below this, and below zero by [`REVERSED_SCALE_SE`]
/// standard errors, was logged with the other sign. The same logs read x0.31-1.40, the
/// lowest a `parameters` car's at 7 standard errors from zero; negated, x-0.34 and below.
pub const REVERSED_SCALE: f64 = -0.15;
/// ... the standard errors below zero it must be.
pub const REVERSED_SCALE_SE: f64 = 4.0;

/// The motor angle's slope on the model's, both through the gearing in the column's unit,
/// that a gearing gives (the same logs read 0.88-1.02: the belt's and the torsion bar's
/// twist). Outside, the motor column is not in the rig's unit (a motor angle in degrees reads
/// x57.3), and is left out.
pub const MOTOR_SLOPE_RANGE: std::ops::RangeInclusive<f64> = 0.5..=2.0;

/// The column's slope on the nominal model's that a steering column in the reference's unit
/// gives, whatever the car's faults, with a wide margin: the world's logs read 0.42-1.07 at
/// their lags (the first 40 cars under ours, the drawn loggers and the EPOS4 car as a row per
/// TPDO; the lowest a car with 1 kN of rack friction and a tyre on a 5 deg sweep). Outside,
/// the column is in another unit than the reference (a column in radians beside a reference
/// in degrees reads x0.017, the other way round x57), and no diagnosis of the car is possible
/// on it: the log is refused.
pub const OUTPUT_SLOPE_RANGE: std::ops::RangeInclusive<f64> = 0.1..=10.0;

/// The effort scales a current in amperes can take: a torque constant or Table 4 off as far
/// as any car's (1 004 of the world's logs, seeds 1 and 3 under every logger, read x0.33-2.65,
/// the nearest 2.8 standard errors inside the bar; its `parameters` cars the lowest). A
/// current beyond them by six standard errors is in another unit (milliamperes read x1000,
/// centiamperes x100, a drive's per-mille of its rated current something else), on which no
/// diagnosis of the car is possible: the log is refused. Read as logged, such a current is
/// all residual: the log was read as the loop's chatter, its current weighed as noise, and
/// a verdict from the angles alone looked like any other.
pub const PHYSICAL_SCALE: std::ops::RangeInclusive<f64> = 0.2..=5.0;
/// ... the standard errors beyond them it must be.
pub const UNIT_SCALE_SE: f64 = 6.0;

/// How the log's columns were read.
#[derive(Debug, Clone, Copy, PartialEq, Default, serde::Serialize)]
pub struct ColumnSigns {
    /// The reference column read negated: the column, the motor angle (where the log has one)
    /// and the current all oppose it.
    pub reference_reversed: bool,
    /// The column (output) read negated.
    pub output_reversed: bool,
    /// The motor angle read negated.
    pub motor_reversed: bool,
    /// The current (effort) read negated.
    pub effort_reversed: bool,
    /// The motor angle left out: its slope on the column is no gearing's.
    pub motor_left_out: bool,
    /// How far the log follows the nominal model, s: the lag at which its column is the
    /// closest to the model's (a reference that reached the car late lags it).
    pub lag_s: f64,
    /// The column's correlation with the nominal model's at that lag, as logged, and its
    /// slope on it.
    pub output_correlation: f64,
    pub output_slope: f64,
    /// The motor angle's correlation with the nominal model's and its slope on it, at the
    /// same lag, as logged.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_correlation: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub motor_slope: Option<f64>,
    /// The log's current over the nominal model's at the same lag, as logged, and its
    /// standard error.
    pub effort_scale: f64,
    pub effort_scale_se: f64,
    /// The current's scale lies outside [`PHYSICAL_SCALE`] (either sign) by
    /// [`UNIT_SCALE_SE`] standard errors: not in the rig's unit; the log is refused.
    pub effort_unit_suspect: bool,
}

impl ColumnSigns {
    /// Why the log cannot be diagnosed as logged: its column is in another unit than its
    /// reference ([`OUTPUT_SLOPE_RANGE`]), or its current is not in amperes
    /// ([`PHYSICAL_SCALE`]).
    pub fn refusal(&self) -> Option<String> {
        if !OUTPUT_SLOPE_RANGE.contains(&self.output_slope.abs()) {
            return Some(format!(
                "the column turns x{:.3} the nominal model's for the logged reference (a car \
                 turns its column x{}-{} of it, whatever its faults): the column and the \
                 reference are not in one unit (a column in radians beside a reference in \
                 degrees reads x0.017, the other way round x57); log both as the steering \
                 column's angle in degrees",
                self.output_slope,
                OUTPUT_SLOPE_RANGE.start(),
                OUTPUT_SLOPE_RANGE.end()
            ));
        }
        self.effort_unit_suspect.then(|| {
            format!(
                "the current is x{:.3} the nominal model's (standard error {:.3}) for the \
                 logged reference, beyond what a torque constant or Table 4 off gives \
                 (x{}-{}): it is not the motor's current in amperes (milliamperes read \
                 x1000, centiamperes x100); log it in amperes",
                self.effort_scale,
                self.effort_scale_se,
                PHYSICAL_SCALE.start(),
                PHYSICAL_SCALE.end()
            )
        })
    }

    /// Any column read otherwise than logged.
    pub fn any(&self) -> bool {
        self.reference_reversed
            || self.output_reversed
            || self.motor_reversed
            || self.effort_reversed
            || self.motor_left_out
    }

    /// `rec` as the diagnosis reads it.
    pub fn apply(&self, rec: &Record) -> Record {
        let negate = |v: &[f64]| v.iter().map(|x| -x).collect::<Vec<f64>>();
        let mut r = rec.clone();
        if self.reference_reversed {
            r.reference = negate(&rec.reference);
        }
        if self.output_reversed {
            r.output = negate(&rec.output);
        }
        if self.effort_reversed {
            r.effort = negate(&rec.effort);
        }
        if self.motor_left_out {
            r.motor = None;
        } else if self.motor_reversed {
            r.motor = rec.motor.as_deref().map(negate);
        }
        r
    }

    /// One clause for the report's car line; empty where every column is read as logged.
    pub fn describe(&self) -> String {
        let mut parts: Vec<String> = Vec::new();
        if self.reference_reversed {
            parts.push(format!(
                "the reference column read with its sign reversed (against the nominal \
                 model's the column reads correlation {:.2}, the current x{:.2} at {:.1} \
                 standard errors{})",
                self.output_correlation,
                self.effort_scale,
                self.effort_scale / self.effort_scale_se.max(1e-12),
                if self.motor_left_out || self.motor_correlation.is_none() {
                    ""
                } else {
                    ", the motor angle turns with the column"
                }
            ));
        }
        if self.output_reversed {
            parts.push(format!(
                "the column read with its sign reversed (as logged its correlation with the \
                 nominal model's is {:.2})",
                self.output_correlation
            ));
        }
        if self.effort_reversed {
            parts.push(format!(
                "the current read with its sign reversed (as logged it is x{:.2} the nominal \
                 model's, standard error {:.3})",
                self.effort_scale, self.effort_scale_se
            ));
        }
        if self.motor_reversed {
            parts.push(format!(
                "the motor angle read with its sign reversed (as logged its correlation with \
                 the nominal model's is {:.2})",
                self.motor_correlation.unwrap_or(f64::NAN)
            ));
        }
        if self.motor_left_out {
            parts.push(format!(
                "the motor angle left out: through the gearing it turns x{:.2} the nominal \
                 model's motor, no gearing's (a motor angle in degrees for radians reads x57.3)",
                self.motor_slope.unwrap_or(f64::NAN)
            ));
        }
        parts.join("; ")
    }
}

/// The log's columns against the nominal model's on the log's first 10 s, on the paper rig,
/// at the lag where the log's column follows the model's most closely (`None` on another rig,
/// or a log whose column follows the model's at no lag: nothing to read a sign against).
pub fn read(rig: &Rig, rec: &Record) -> Option<ColumnSigns> {
    if !matches!(rig.model, RigModel::Paper(_)) {
        return None;
    }
    let on = head(rec, SYNC_SEARCH_S);
    let skip = Scorer::new(rig, &on).skip();
    let sim = super::simulate(
        &with_car(rig, CarDrive::Direct, Controller::Paper, 0.0),
        &on,
        &Effects::nominal(),
    );
    let (lag, output_correlation, output_slope) = best_lag(&sim.output, &on.output, skip)?;
    let output_reversed = output_correlation < REVERSED_CORRELATION;
    let (model, log) = lagged(&sim, &on, lag);
    let motor = log
        .motor
        .as_deref()
        .and_then(|m| regression(&model.motor, m, skip));
    let motor_reversed = motor.is_some_and(|(c, _)| c < REVERSED_CORRELATION);
    let motor_left_out = motor.is_some_and(|(_, slope)| !MOTOR_SLOPE_RANGE.contains(&slope.abs()));
    let Scale {
        factor,
        standard_error,
    } = effort_scale(&log, &model, skip);
    let effort_reversed =
        factor < REVERSED_SCALE && factor + REVERSED_SCALE_SE * standard_error < 0.0;
    let mut signs = ColumnSigns {
        reference_reversed: false,
        output_reversed,
        motor_reversed: motor_reversed && !motor_left_out,
        effort_reversed,
        motor_left_out,
        lag_s: lag as f64 * rec.dt,
        output_correlation,
        output_slope,
        motor_correlation: motor.map(|(c, _)| c),
        motor_slope: motor.map(|(_, s)| s),
        effort_scale: factor,
        effort_scale_se: standard_error,
        effort_unit_suspect: factor.abs() - UNIT_SCALE_SE * standard_error > *PHYSICAL_SCALE.end()
            || factor.abs() + UNIT_SCALE_SE * standard_error < *PHYSICAL_SCALE.start(),
    };
    // Every column against the model that the reference drives: the reference is the one
    // reversed.
    let motor_agrees = signs.motor_reversed || signs.motor_left_out || motor.is_none();
    if signs.output_reversed && signs.effort_reversed && motor_agrees {
        signs.output_reversed = false;
        signs.effort_reversed = false;
        signs.motor_reversed = false;
        signs.reference_reversed = true;
    }
    Some(signs)
}

/// The lags tried, in rows of the grid (10 ms): from two rows early (a logger that writes the
/// reference that starts at each row, a stamp's jitter) to half a second late (a reference
/// that reaches the car late: the world's are 15-60 ms).
const LAGS_ROWS: std::ops::RangeInclusive<i64> = -2..=50;

/// The lag (rows the log follows the model by) at which the log's column is the most
/// correlated with the model's, either sign, that correlation and the column's slope on the
/// model's there; `None` where the correlation is under [`REVERSED_CORRELATION`] in size at
/// every lag. A column of the other sign reads as close at the same lag, the opposite way:
/// the sign of the closest lag is the column's.
fn best_lag(model: &[f64], log: &[f64], skip: usize) -> Option<(i64, f64, f64)> {
    LAGS_ROWS
        .filter_map(|lag| {
            let (m, l) = pairs_at(model, log, lag);
            regression(&m, &l, skip).map(|(c, slope)| (lag, c, slope))
        })
        .max_by(|a, b| a.1.abs().total_cmp(&b.1.abs()))
        .filter(|(_, c, _)| c.abs() >= REVERSED_CORRELATION.abs())
}

/// `model[k]` beside `log[k + lag]`, where both are in range.
fn pairs_at(model: &[f64], log: &[f64], lag: i64) -> (Vec<f64>, Vec<f64>) {
    let n = model.len().min(log.len()) as i64;
    (0..n)
        .filter(|k| (0..n).contains(&(k + lag)))
        .map(|k| (model[k as usize], log[(k + lag) as usize]))
        .unzip()
}

/// The model's run and the log with the log `lag` rows later, both cut to the rows they
/// share.
fn lagged(sim: &SimOut, rec: &Record, lag: i64) -> (SimOut, Record) {
    let pair = |m: &[f64], l: &[f64]| pairs_at(m, l, lag);
    let (output, log_output) = pair(&sim.output, &rec.output);
    let (effort, log_effort) = pair(&sim.effort, &rec.effort);
    let (motor, log_motor) = match &rec.motor {
        Some(m) if !sim.motor.is_empty() => {
            let (a, b) = pair(&sim.motor, m);
            (a, Some(b))
        }
        _ => (Vec::new(), None),
    };
    let log = Record {
        dt: rec.dt,
        reference: pair(&rec.reference, &rec.reference).1,
        output: log_output,
        effort: log_effort,
        motor: log_motor,
        ..Record::default()
    };
    (
        SimOut {
            output,
            effort,
            motor,
        },
        log,
    )
}

/// A column varies where its spread about its mean exceeds this share of its square about
/// zero: above the rounding of a mean of one value (1e-32 of it on 100 rows), far below any
/// sensor's resolution over its range.
const VARIES: f64 = 1e-20;

/// The correlation of `y` with `x` and the slope of `y` on `x` over the rows from `skip`
/// where both are finite; `None` with fewer than 10 such rows or without variance in either.
fn regression(x: &[f64], y: &[f64], skip: usize) -> Option<(f64, f64)> {
    let rows: Vec<(f64, f64)> = x
        .iter()
        .zip(y)
        .skip(skip)
        .filter(|(a, b)| a.is_finite() && b.is_finite())
        .map(|(a, b)| (*a, *b))
        .collect();
    if rows.len() < 10 {
        return None;
    }
    let n = rows.len() as f64;
    let (sum_x, sum_y) = rows
        .iter()
        .fold((0.0, 0.0), |(sx, sy), (a, b)| (sx + a, sy + b));
    let (mx, my) = (sum_x / n, sum_y / n);
    let (mut sxx, mut syy, mut sxy) = (0.0, 0.0, 0.0);
    let (mut xx, mut yy) = (0.0, 0.0);
    for (a, b) in &rows {
        sxx += (a - mx) * (a - mx);
        syy += (b - my) * (b - my);
        sxy += (a - mx) * (b - my);
        xx += a * a;
        yy += b * b;
    }
    // A column that holds one value varies by its mean's rounding alone.
    let varies = |about_mean: f64, about_zero: f64| about_mean > VARIES * about_zero;
    (varies(sxx, xx) && varies(syy, yy)).then(|| (sxy / (sxx * syy).sqrt(), sxy / sxx))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_correlation_and_a_slope_are_read_and_a_flat_column_gives_none() {
        let x: Vec<f64> = (0..100).map(|k| (k as f64 * 0.1).sin()).collect();
        let y: Vec<f64> = x.iter().map(|v| -2.0 * v + 3.0).collect();
        let (c, s) = regression(&x, &y, 0).expect("read");
        assert!((c + 1.0).abs() < 1e-9 && (s + 2.0).abs() < 1e-9, "{c} {s}");
        assert_eq!(regression(&x, &[1.0; 100], 0), None);
        assert_eq!(regression(&[0.1; 100], &y, 0), None);
        assert_eq!(regression(&x[..9], &y[..9], 0), None);
        let mut holed = y.clone();
        holed[5] = f64::NAN;
        let (c, _) = regression(&x, &holed, 0).expect("read without the hole");
        assert!((c + 1.0).abs() < 1e-9, "{c}");
    }
}

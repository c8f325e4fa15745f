//! `monitor --plot`: the bus as a picture that scrolls in the terminal, for bring-up teams who
//! would rather look than read. Three strip charts over the last seconds (reference and column
//! angle at the wheel, the motor angle, the current), each on its own scale, and below them the
//! state, the faults and the counters from the monitor's summary. Plain text and two ANSI
//! sequences (cursor home, clear below), so it needs no terminal library and the laptop build
//! stays small; [`LivePlot::render`] is pure, so what it draws is tested as text.

use crate::monitor::Monitor;
use std::collections::VecDeque;

/// A chart's title and its traces: a mark and the values it draws, oldest first.
type Chart<'a> = (&'a str, Vec<(char, Vec<f64>)>);

/// One sample per status frame (100 Hz): what the charts draw.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Sample {
    ref_deg: f64,
    column_deg: f64,
    motor_rad: f64,
    current_a: f64,
}

/// The history the charts scroll over.
#[derive(Debug, Clone)]
pub struct LivePlot {
    samples: VecDeque<Sample>,
    capacity: usize,
}

/// The terminal sequences that redraw in place: cursor to the top left, clear to the end.
pub const REDRAW: &str = "\x1b[H\x1b[J";

impl LivePlot {
    /// Keeps the last `capacity` samples (at 100 Hz, 1000 are 10 s).
    pub fn new(capacity: usize) -> LivePlot {
        LivePlot {
            samples: VecDeque::with_capacity(capacity),
            capacity: capacity.max(1),
        }
    }

    /// Takes the monitor's latest values as one sample (call it at each status frame).
    pub fn sample(&mut self, m: &Monitor) {
        let last = |v: Option<f64>| v.unwrap_or(f64::NAN);
        let s = Sample {
            ref_deg: last(m.last_reference.map(|(_, r)| f64::from(r.angle.0))),
            column_deg: last(m.last_status.map(|(_, s)| f64::from(s.angle.0))),
            motor_rad: last(m.last_motor.map(|(_, s)| f64::from(s.angle.0))),
            current_a: last(m.last_status.map(|(_, s)| f64::from(s.current.0))),
        };
        if self.samples.len() == self.capacity {
            self.samples.pop_front();
        }
        self.samples.push_back(s);
    }

    /// Samples held.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// The picture, `width` columns by about `height` rows: a title, the three charts (newest
    /// sample at the right edge) and `info` (lines of text) below them.
    pub fn render(&self, title: &str, info: &[String], width: usize, height: usize) -> String {
        let label_w = 10;
        let plot_w = width.saturating_sub(label_w + 1).max(10);
        let rows = height.saturating_sub(info.len() + 5).max(9) / 3;
        let rows = rows.saturating_sub(1).max(2);
        // The whole history across the width: a column per sample while they fit, else the
        // last sample of each column's share of the history.
        let n = self.samples.len();
        let window: Vec<&Sample> = if n <= plot_w {
            self.samples.iter().collect()
        } else {
            (1..=plot_w)
                .filter_map(|x| self.samples.get(x * n / plot_w - 1))
                .collect()
        };
        let mut out = format!(
            "{title}  (the last {:.1} s; newest at the right)\n",
            n as f64 / 100.0
        );
        let charts: [Chart; 3] = [
            (
                "angle at the wheel, deg: reference `.`, column `#`",
                vec![
                    ('.', window.iter().map(|s| s.ref_deg).collect()),
                    ('#', window.iter().map(|s| s.column_deg).collect()),
                ],
            ),
            (
                "motor angle, rad `#`",
                vec![('#', window.iter().map(|s| s.motor_rad).collect())],
            ),
            (
                "current, A `#`",
                vec![('#', window.iter().map(|s| s.current_a).collect())],
            ),
        ];
        for (name, traces) in &charts {
            out.push_str(&format!("{:>label_w$} {name}\n", ""));
            out.push_str(&chart(traces, plot_w, rows, label_w));
        }
        for line in info {
            out.push_str(line);
            out.push('\n');
        }
        out
    }
}

/// One strip chart: `traces` (a mark and its values, oldest first) right-aligned in `w`
/// columns and `h` rows, the scale from the finite values shown, its ends labelled.
fn chart(traces: &[(char, Vec<f64>)], w: usize, h: usize, label_w: usize) -> String {
    let finite = traces
        .iter()
        .flat_map(|(_, v)| v.iter().copied())
        .filter(|v| v.is_finite());
    let (mut lo, mut hi) = finite.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    });
    if !lo.is_finite() {
        (lo, hi) = (-1.0, 1.0);
    }
    // A flat trace gets a span around it, so it draws as a line in the middle.
    if hi - lo < 1e-6 {
        (lo, hi) = (lo - 1.0, hi + 1.0);
    }
    let mut grid = vec![vec![' '; w]; h];
    for (mark, values) in traces {
        let offset = w.saturating_sub(values.len());
        for (x, v) in values.iter().enumerate() {
            if !v.is_finite() {
                continue;
            }
            let y = ((hi - v) / (hi - lo) * (h - 1) as f64).round() as usize;
            grid[y.min(h - 1)][(offset + x).min(w - 1)] = *mark;
        }
    }
    let mut out = String::new();
    for (i, row) in grid.iter().enumerate() {
        let label = match i {
            0 => format!("{hi:+.2}"),
            _ if i == h - 1 => format!("{lo:+.2}"),
            _ => String::new(),
        };
        out.push_str(&format!("{label:>label_w$}|"));
        out.extend(row.iter());
        out.push('\n');
    }
    out
}

/// The lines of the monitor's summary that say state, faults and counters (not the table of
/// frame rates, which the charts stand in for).
pub fn info_lines(m: &Monitor) -> Vec<String> {
    m.summary()
        .lines()
        .skip(1)
        // One level of indent: the per-page details of the diagnostics block stay in the
        // text summary.
        .filter(|l| !l.contains(" Hz  CRC errors") && !l.starts_with("    "))
        .filter(|l| !l.trim_start().starts_with("diagnostics ("))
        .map(str::to_string)
        .collect()
}

/// The terminal's size from `COLUMNS` and `LINES` when the shell exports them, else 100 by 34.
pub fn terminal_size() -> (usize, usize) {
    let get = |name: &str, default: usize| {
        std::env::var(name)
            .ok()
            .and_then(|v| v.trim().parse().ok())
            .filter(|&n: &usize| (20..=1000).contains(&n))
            .unwrap_or(default)
    };
    (get("COLUMNS", 100), get("LINES", 34))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)] // a failed unwrap is a failed test
mod tests {
    use super::*;

    fn plot_of(values: impl Iterator<Item = (f64, f64)>) -> LivePlot {
        let mut p = LivePlot::new(1000);
        for (r, c) in values {
            p.samples.push_back(Sample {
                ref_deg: r,
                column_deg: c,
                motor_rad: c * 10.0,
                current_a: f64::NAN,
            });
        }
        p
    }

    /// A ramp draws from the bottom left to the top right, the newest sample at the right edge,
    /// and the scale's ends are its extremes.
    #[test]
    fn a_ramp_draws_rising_to_the_right_edge() {
        let p = plot_of((0..50).map(|k| (f64::from(k), f64::from(k))));
        let text = p.render("t", &[], 60, 30);
        let lines: Vec<&str> = text.lines().collect();
        let rows: Vec<&&str> = lines.iter().filter(|l| l.contains('|')).collect();
        let first = rows[0];
        assert!(first.starts_with("    +49.00|"), "{text}");
        assert!(
            first.ends_with('#'),
            "the newest sample at the right edge: {text}"
        );
        // The motor chart has its own scale.
        assert!(text.contains("+490.00|"), "{text}");
        // Current is all missing: a flat default scale, no marks.
        let current = text.split("current, A `#`").nth(1).unwrap();
        assert!(!current.contains('#'), "{current}");
    }

    /// The reference and the column share the angle chart with their own marks; the history
    /// scrolls: only the newest samples that fit are drawn.
    #[test]
    fn the_history_scrolls_and_both_angles_show() {
        let mut p = LivePlot::new(20);
        let node = steering_ecu::canopen::NodeId::new(1).unwrap();
        let m = Monitor::new(crate::commands::decoder(node).unwrap());
        for _ in 0..25 {
            p.sample(&m);
        }
        assert_eq!(p.len(), 20);
        let p = plot_of((0..80).map(|k| (5.0, if k < 40 { 0.0 } else { 2.0 })));
        let text = p.render("t", &["  ECU        state idle".into()], 60, 30);
        let angle = text.split("motor angle").next().unwrap();
        assert!(angle.contains('.') && angle.contains('#'), "{angle}");
        assert!(text.ends_with("  ECU        state idle\n"), "{text}");
    }
}

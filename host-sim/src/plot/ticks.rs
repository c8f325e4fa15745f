//! Where the ticks go: 1-2-5 steps, decades (with 1-2-5 labels where they fit), multiples
//! of 45 deg, and how many decimals their labels need.

/// Tick positions at 1-2-5 steps (times a power of ten) inside `lo..=hi`, as many as fit within
/// `max_count` intervals. Empty if the range is not finite or empty.
///
/// `nice_ticks(0.0, 9.7, 5)` is `[0, 2, 4, 6, 8]`.
pub fn nice_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    if !(lo.is_finite() && hi.is_finite() && lo < hi) {
        return Vec::new();
    }
    let raw = (hi - lo) / max_count.max(1) as f64;
    let magnitude = 10f64.powf(raw.log10().floor());
    let step = [1.0, 2.0, 5.0, 10.0]
        .into_iter()
        .map(|m| m * magnitude)
        .find(|&s| s >= raw * (1.0 - 1e-9))
        .unwrap_or(10.0 * magnitude);
    ticks_with_step(lo, hi, step)
}

/// Ticks for a logarithmic axis: `(labelled, unlabelled)`. Labelled are 1-2-5 times a decade
/// (what a reader needs to read off a bandwidth such as 2.3 Hz), or only the decades when 1-2-5
/// would give more than `max_count` labels, or 1..9 times a decade when the range is too short
/// for two 1-2-5 labels.
pub fn log_ticks(lo: f64, hi: f64, max_count: usize) -> (Vec<f64>, Vec<f64>) {
    if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi) {
        return (Vec::new(), Vec::new());
    }
    let inside = |v: f64| v >= lo * (1.0 - 1e-9) && v <= hi * (1.0 + 1e-9);
    let first = lo.log10().floor() as i32;
    let last = hi.log10().ceil() as i32;
    let candidates: Vec<(u32, f64)> = (first..=last)
        .flat_map(|k| (1..=9u32).map(move |m| (m, f64::from(m) * 10f64.powi(k))))
        .filter(|&(_, v)| inside(v))
        .collect();
    let split = |mantissas: &[u32]| -> (Vec<f64>, Vec<f64>) {
        let (major, minor): (Vec<_>, Vec<_>) =
            candidates.iter().partition(|(m, _)| mantissas.contains(m));
        (
            major.iter().map(|&(_, v)| v).collect(),
            minor.iter().map(|&(_, v)| v).collect(),
        )
    };
    let one_two_five = split(&[1, 2, 5]);
    let labels = one_two_five.0.len();
    if (2..=max_count.max(2)).contains(&labels) {
        return one_two_five;
    }
    let decades = split(&[1]);
    if labels > max_count && decades.0.len() >= 2 {
        return decades;
    }
    if labels >= 2 {
        return one_two_five;
    }
    split(&[1, 2, 3, 4, 5, 6, 7, 8, 9])
}

pub(super) fn degree_ticks(lo: f64, hi: f64, max_count: usize) -> Vec<f64> {
    let span = hi - lo;
    match [1.0, 2.0, 5.0, 10.0, 15.0, 30.0, 45.0, 90.0, 180.0, 360.0]
        .into_iter()
        .find(|&s| span / s <= max_count.max(1) as f64)
    {
        Some(step) => ticks_with_step(lo, hi, step),
        None => nice_ticks(lo, hi, max_count),
    }
}

pub(super) fn ticks_with_step(lo: f64, hi: f64, step: f64) -> Vec<f64> {
    let first = (lo / step - 1e-9).ceil() as i64;
    let last = (hi / step + 1e-9).floor() as i64;
    // Multiples of the step rather than repeated addition, so 0.1-steps do not drift.
    (first..=last).map(|k| k as f64 * step).collect()
}

/// A tick label with as many decimals as the step needs, never "-0".
pub(super) fn tick_label(v: f64, step: f64) -> String {
    let decimals = if step >= 1.0 {
        0
    } else {
        (-step.log10() - 1e-9).ceil().max(0.0) as usize
    };
    let text = format!("{v:.decimals$}");
    if text.starts_with('-') && text[1..].bytes().all(|b| b == b'0' || b == b'.') {
        text[1..].to_string()
    } else {
        text
    }
}

pub(super) fn log_tick_label(v: f64) -> String {
    let decade = (v.log10() + 1e-9).floor();
    tick_label(v, 10f64.powf(decade))
}

pub(super) fn format_hz(f: f64) -> String {
    match f {
        f if f >= 100.0 => format!("{f:.0}"),
        f if f >= 1.0 => format!("{f:.1}"),
        f if f >= 0.1 => format!("{f:.2}"),
        f => format!("{f:.3}"),
    }
}

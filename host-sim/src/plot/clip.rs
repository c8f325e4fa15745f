//! Lines cut at the edge of the plotting area.

use super::scale::Scale;

/// Cuts runs to the plotting box (plotters draws wherever it is told, also over the axes): a
/// line leaving the box ends on its edge, one coming back starts a new run there. Straight in
/// the axis' own coordinates, so on a log axis it is cut in decades, as it is drawn.
pub(super) fn clip(runs: Vec<Vec<(f64, f64)>>, x: &Scale, y: (f64, f64)) -> Vec<Vec<(f64, f64)>> {
    let (Some(x_lo), Some(x_hi)) = (x.transform(x.lo), x.transform(x.hi)) else {
        return Vec::new();
    };
    let bounds = [x_lo, x_hi, y.0, y.1];
    let inside = |(tx, ty): (f64, f64)| (x_lo..=x_hi).contains(&tx) && (y.0..=y.1).contains(&ty);
    let mut out = Vec::new();
    for run in runs {
        let points: Vec<(f64, f64)> = run
            .iter()
            .filter_map(|&(px, py)| Some((x.transform(px)?, py)))
            .collect();
        let mut current: Vec<(f64, f64)> = Vec::new();
        if let [only] = points[..] {
            if inside(only) {
                out.push(vec![(x.inverse(only.0), only.1)]);
            }
            continue;
        }
        for pair in points.windows(2) {
            let Some((a, b, cut_end)) = clip_segment(pair[0], pair[1], bounds) else {
                if !current.is_empty() {
                    out.push(std::mem::take(&mut current));
                }
                continue;
            };
            if current.is_empty() {
                current.push((x.inverse(a.0), a.1));
            }
            current.push((x.inverse(b.0), b.1));
            if cut_end {
                out.push(std::mem::take(&mut current));
            }
        }
        if !current.is_empty() {
            out.push(current);
        }
    }
    out
}

pub(super) type Point = (f64, f64);

/// Liang-Barsky: the part of `p0..p1` inside `[x_lo, x_hi, y_lo, y_hi]`, and whether the end
/// was cut off.
pub(super) fn clip_segment(
    p0: (f64, f64),
    p1: (f64, f64),
    [x_lo, x_hi, y_lo, y_hi]: [f64; 4],
) -> Option<(Point, Point, bool)> {
    let (dx, dy) = (p1.0 - p0.0, p1.1 - p0.1);
    let (mut t0, mut t1) = (0.0f64, 1.0f64);
    for (p, q) in [
        (-dx, p0.0 - x_lo),
        (dx, x_hi - p0.0),
        (-dy, p0.1 - y_lo),
        (dy, y_hi - p0.1),
    ] {
        if p == 0.0 {
            if q < 0.0 {
                return None;
            }
        } else {
            let r = q / p;
            if p < 0.0 {
                t0 = t0.max(r);
            } else {
                t1 = t1.min(r);
            }
        }
    }
    if t0 > t1 {
        return None;
    }
    let at = |t: f64| (p0.0 + t * dx, p0.1 + t * dy);
    Some((at(t0), at(t1), t1 < 1.0))
}

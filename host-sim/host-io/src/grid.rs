//! Where stamped events sit on a regular grid: a log's rows on its logger's, a train of CAN
//! frames on its sender's period. One way of counting for `host-sim gap`'s log timing and
//! `steer-can convert`'s SYNC drift, so the two read a walking or gappy grid alike.

/// The median of the gaps between successive stamps, at least 1 ns (so a spacing divides
/// safely): a logger's row spacing, which a lost row or a late stamp does not move. 1 ns for
/// fewer than two stamps.
pub fn median_gap(t: &[f64]) -> f64 {
    let mut gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if gaps.is_empty() {
        return 1e-9;
    }
    gaps.sort_by(f64::total_cmp);
    gaps[gaps.len() / 2].max(1e-9)
}

/// Each stamp's place on a grid of `spacing`: the place before it plus the whole spacings in
/// its gap (at least one), so lost events count and a grid that walks a spacing or more over
/// the stamps is still counted right. Also how many gaps were no whole number of spacings
/// (more than a quarter off, or under one): where those are many, the stamps are no such grid.
pub fn places_by_gaps(t: &[f64], spacing: f64) -> (Vec<u64>, usize) {
    let mut places = Vec::with_capacity(t.len());
    let mut place = 0u64;
    let mut off_grid = 0usize;
    if !t.is_empty() {
        places.push(0);
    }
    for w in t.windows(2) {
        let spacings = (w[1] - w[0]) / spacing;
        let whole = spacings.round();
        if (spacings - whole).abs() > 0.25 || whole < 1.0 {
            off_grid += 1;
        }
        place += (whole as u64).max(1);
        places.push(place);
    }
    (places, off_grid)
}

/// The least-squares line through the stamps `t` at their `places`, `t = origin + period *
/// place`: `(origin, period)`. `None` where it has no finite slope (fewer than two distinct
/// places, or a stamp not finite).
pub fn line_through(t: &[f64], places: &[u64]) -> Option<(f64, f64)> {
    let n = t.len().min(places.len());
    if n < 2 {
        return None;
    }
    let (t, places) = (&t[..n], &places[..n]);
    let nf = n as f64;
    let mean_place = places.iter().map(|&p| p as f64).sum::<f64>() / nf;
    let mean_t = t.iter().sum::<f64>() / nf;
    let (mut spt, mut spp) = (0.0, 0.0);
    for (&p, &tj) in places.iter().zip(t) {
        let dp = p as f64 - mean_place;
        spt += dp * (tj - mean_t);
        spp += dp * dp;
    }
    let period = spt / spp;
    (spp > 0.0 && period.is_finite()).then_some((mean_t - period * mean_place, period))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_median_gap_is_not_moved_by_a_lost_row() {
        assert_eq!(median_gap(&[0.0, 10.0, 30.0, 40.0, 50.0]), 10.0);
        assert_eq!(median_gap(&[5.0]), 1e-9);
    }

    #[test]
    fn a_lost_event_is_counted_in_its_gap() {
        let t = [0.0, 10.0, 30.0, 40.0];
        let (places, off) = places_by_gaps(&t, 10.0);
        assert_eq!(places, vec![0, 1, 3, 4]);
        assert_eq!(off, 0);
        let (origin, period) = line_through(&t, &places).unwrap();
        assert!(origin.abs() < 1e-12 && (period - 10.0).abs() < 1e-12);
    }

    #[test]
    fn a_grid_that_walks_past_a_spacing_is_still_counted_one_by_one() {
        // 1 % slow over 200 events: the stamps walk two spacings, each gap stays one.
        let t: Vec<f64> = (0..200).map(|i| i as f64 * 10.1).collect();
        let (places, off) = places_by_gaps(&t, 10.0);
        assert_eq!(places.last(), Some(&199));
        assert_eq!(off, 0);
        let (_, period) = line_through(&t, &places).unwrap();
        assert!((period - 10.1).abs() < 1e-9, "{period}");
    }

    #[test]
    fn gaps_off_the_grid_are_counted_and_a_stamp_that_repeats_takes_a_place_of_its_own() {
        let (places, off) = places_by_gaps(&[0.0, 10.0, 15.0, 15.0, 25.0], 10.0);
        assert_eq!(places, vec![0, 1, 2, 3, 4]);
        assert_eq!(off, 2);
    }

    #[test]
    fn no_line_through_one_place_or_a_stamp_that_is_not_finite() {
        assert_eq!(line_through(&[1.0], &[0]), None);
        assert_eq!(line_through(&[1.0, 2.0], &[3, 3]), None);
        assert_eq!(line_through(&[1.0, f64::NAN], &[0, 1]), None);
    }
}

//! The log on the rig's grid ([`Record`]) and what its stamps say of the logger
//! ([`LogTiming`]).

/// A log on the rig's grid. For the paper rig the grid is the 10 ms reference period, and
/// each step `k` holds what the log means (host-sim/README.md, "The log format"): the reference in force over
/// the period, the column and motor angles at the instant the period ends, and the mean
/// motor current over the period. The model computes the same quantities at the same
/// instants. EMPS samples are taken as they are.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Record {
    /// Grid step, s.
    pub dt: f64,
    /// Reference in force over each step.
    pub reference: Vec<f64>,
    /// Output at the end of each step.
    pub output: Vec<f64>,
    /// Mean effort over each step.
    pub effort: Vec<f64>,
    /// Motor angle in output units through the rigid gearing, at the end of each step; for
    /// the segment analysis.
    pub motor: Option<Vec<f64>>,
    /// A known disturbance added to the effort (EMPS pulses).
    pub disturbance: Option<Vec<f64>>,
    /// The measured supply at each step, V; 0 while the drive is off (BAM: torque disabled).
    pub supply_v: Option<Vec<f64>>,
    /// The steps at the log's start before the car's drive first reported (paper rig: rows
    /// whose motor and current are both empty, as `steer-can convert` writes the rows before
    /// the EPOS4's first status frame): the car was powering up, its drive not yet running.
    /// 0 for a log that starts with the drive running.
    pub powered_from: usize,
    /// The current column holds instantaneous samples of a current loop's chatter, which no
    /// model repeats sample for sample (stated or found, [`super::chatter`]):
    /// [`super::Scorer::fit`]'s GoF pairs the output with the motor angle, not with the
    /// effort, and the likelihood takes the effort's whole scatter about the nominal model
    /// for its noise.
    pub current_chatter: bool,
}

/// What a log's current column holds (the header's `# current:` line).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum CurrentSamples {
    /// The mean over the interval that ends at the row's time (the 0x102 frame, host-sim's
    /// own logs): the default.
    #[default]
    IntervalMean,
    /// The EPOS4's own sample at each SYNC, as `steer-can convert` places it in the rows:
    /// binned as an interval mean, read as the EPOS4 readout says
    /// ([`super::rig::Epos4Readout`]).
    SyncSample,
    /// Instantaneous samples (`# current: instantaneous`): the inner loop's chatter is then
    /// in them, which the likelihood weighs by its measured noise.
    Instantaneous,
}

impl CurrentSamples {
    /// Every kind, in the order a header's error lists them.
    pub const ALL: [CurrentSamples; 3] = [
        CurrentSamples::IntervalMean,
        CurrentSamples::SyncSample,
        CurrentSamples::Instantaneous,
    ];

    /// The name a header line `# current: ...` gives it.
    pub fn name(self) -> &'static str {
        match self {
            CurrentSamples::IntervalMean => "interval-mean",
            CurrentSamples::SyncSample => "sync-sample",
            CurrentSamples::Instantaneous => "instantaneous",
        }
    }

    /// The kind a header line names; `None` for a name this reader does not know.
    pub fn from_name(name: &str) -> Option<CurrentSamples> {
        Self::ALL.into_iter().find(|c| c.name() == name.trim())
    }
}

/// Which reference a row stamped at a reference instant holds.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
#[serde(rename_all = "kebab-case")]
pub enum ReferenceConvention {
    /// The reference in force over the row interval that ends at the row: at a reference
    /// instant, still the previous sample (host-sim's and steer-can's logs).
    PeriodEnding,
    /// The reference that starts at the row: at a reference instant, already the sample the
    /// ECU starts to use there.
    PeriodStarting,
}

impl ReferenceConvention {
    /// Both conventions.
    pub const ALL: [ReferenceConvention; 2] = [
        ReferenceConvention::PeriodEnding,
        ReferenceConvention::PeriodStarting,
    ];

    /// The name a header line `# reference: ...` gives it.
    pub fn name(self) -> &'static str {
        match self {
            ReferenceConvention::PeriodEnding => "period-ending",
            ReferenceConvention::PeriodStarting => "period-starting",
        }
    }

    /// The convention a header line names; `None` for a name this reader does not know.
    pub fn from_name(name: &str) -> Option<ReferenceConvention> {
        Self::ALL.into_iter().find(|c| c.name() == name.trim())
    }

    /// Its short name, `ending` or `starting`.
    pub fn short(self) -> &'static str {
        match self {
            ReferenceConvention::PeriodEnding => "ending",
            ReferenceConvention::PeriodStarting => "starting",
        }
    }
}

/// Linear interpolation of `y(t)` at `tk`, held at the ends.
pub(crate) fn interp_at(t: &[f64], y: &[f64], tk: f64) -> f64 {
    let j = t.partition_point(|v| *v < tk);
    if j == 0 {
        y[0]
    } else if j >= t.len() {
        y[t.len() - 1]
    } else {
        let s = (tk - t[j - 1]) / (t[j] - t[j - 1]).max(1e-12);
        y[j - 1] + s * (y[j] - y[j - 1])
    }
}

/// A log's timing, as its stamps show it: the logger's, not the car's.
#[derive(Debug, Clone, Copy, Default, PartialEq, serde::Serialize)]
pub struct LogTiming {
    /// The row spacing: the slope of the least-squares line through the stamps, s.
    pub row_dt_s: f64,
    /// Where the row grid starts: one spacing before the first row's place on the grid that
    /// fits every stamp best (median), s.
    pub grid_origin_s: f64,
    /// Stamp jitter around that grid: the RMS of the stamps' offsets (median absolute
    /// deviation x 1.48, robust to a few far ones; their RMS where the stamps are rounded as
    /// coarsely as that), s.
    pub jitter_s: f64,
    /// Rows missing from the grid (gaps of more than 1.5 spacings, counted in spacings).
    pub missing_rows: usize,
    pub rows: usize,
    /// The rows sit on the grid at their places, each stamp off its place by the jitter:
    /// the jitter is under a fifth of the spacing, or the rows' order placed them
    /// ([`LogTiming::with_places`]).
    pub on_grid: bool,
}

/// Rows on each side of a row that [`places_by_order`] averages over to see a lost row, at
/// least: at +-1 ms of jitter on 2.5 ms rows a lost row stands 15 standard errors above the
/// average's noise, and the first spacing's error (0.5 %) adds 0.15 spacings.
const ORDER_WINDOW: usize = 30;

/// The noise, in spacings, that the average over the rows [`places_by_order`] reads a lost
/// row from is held under on a log of up to about 30 s at 1 kHz: a tenth of a spacing, so
/// that half a spacing stands five times its noise above it (a longer log holds it lower).
/// The stamps' own scatter sets the window: 30 rows at 400-500 Hz and +-1 ms, 72-84 at
/// 1 kHz.
const ORDER_NOISE: f64 = 0.1;

/// The largest jitter (RMS, in spacings) the rows' order places rows under: +-1 ms reads
/// 0.37 on a 500 Hz grid (its median absolute deviation x 1.48) and 0.64-0.74 at 1 kHz,
/// where the rows kept in order pull the stamps in.
const ORDER_MAX_JITTER: f64 = 0.8;

/// How far a gap between two stamps may fall short of the rows' spacing, in the gaps' own
/// spread (a standard deviation, by their median absolute deviation), for stamps that go back
/// to be a receiver's jitter: +-1 ms at 1 kHz falls short by at most 2 ms, 2.3 spreads; a
/// normal jitter of any size by five spreads once in 3.5 million gaps.
const STAMP_GAP_SPREADS: f64 = 5.0;

/// Stamps `t` that go back somewhere, each row at its place on the grid the rows' order puts
/// them on ([`LogTiming::with_places`]), and the stamps' timing about that grid. `None` unless the
/// rows sit on one grid and every gap, the ones that go back too, is within
/// [`STAMP_GAP_SPREADS`] of the gaps' spread short of their median: a stamp far out of its
/// place in a log of regular stamps (a duplicated line, two logs run together) is no
/// receiver's jitter.
pub(super) fn placed_in_order(t: &[f64]) -> Option<(Vec<f64>, LogTiming)> {
    let gaps: Vec<f64> = t.windows(2).map(|w| w[1] - w[0]).collect();
    if gaps.is_empty() {
        return None;
    }
    let shortest = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    let resolution = stamp_resolution(t);
    let (median, spread) = median_and_spread(gaps, resolution);
    if !(median > 0.0 && median - shortest <= STAMP_GAP_SPREADS * spread) {
        return None;
    }
    let (timing, places) = LogTiming::at_resolution(t, resolution);
    timing
        .is_regular()
        .then(|| (timing.at_places(&places), timing))
}

/// The step of the mean of a series (`sum(k)`: the sum of its first `k` values, `n` values
/// in all) between the `w` rows before row `j` and as many from `j` on.
fn order_step(sum: impl Fn(usize) -> f64, n: usize, j: usize, w: usize) -> f64 {
    let (a, b) = (j.saturating_sub(w), (j + w).min(n));
    (sum(b) - sum(j)) / (b - j) as f64 - (sum(j) - sum(a)) / (j - a) as f64
}

/// The median of `v` (not empty) and its spread as a standard deviation: the median absolute
/// deviation x 1.4826, which a few far values (a lost row's gap) do not move. Values rounded
/// to a `resolution` as coarse as that spread (stamps in whole milliseconds on a 1 kHz
/// logger's +-1 ms) take a few values, and the median of their absolute deviations falls on
/// one of them: it reads 0 or 1.48 resolutions. Their RMS about the median reads the spread
/// then, rounding and all.
fn median_and_spread(mut v: Vec<f64>, resolution: f64) -> (f64, f64) {
    v.sort_by(f64::total_cmp);
    let median = v[v.len() / 2];
    for x in &mut v {
        *x = (*x - median).abs();
    }
    let rms = (v.iter().map(|x| x * x).sum::<f64>() / v.len() as f64).sqrt();
    v.sort_by(f64::total_cmp);
    let spread = 1.4826 * v[v.len() / 2];
    (
        median,
        if resolution >= 0.5 * spread {
            rms
        } else {
            spread
        },
    )
}

/// The coarsest decimal resolution, 1 s down to 1 us, that every stamp of `t` is a whole
/// multiple of after the first (a logger's stamp format: whole milliseconds, microseconds;
/// from the first, so that a clock's large epoch does not hide it), s; 0 for stamps finer
/// than a microsecond.
fn stamp_resolution(t: &[f64]) -> f64 {
    let first = t.first().copied().unwrap_or(0.0);
    (0..=6)
        .map(|k| 10f64.powi(-k))
        .find(|r| {
            t.iter()
                .map(|v| (v - first) / r)
                .all(|x| (x - x.round()).abs() < 1e-3)
        })
        .unwrap_or(0.0)
}

/// The running sums of `v`: `sum[k]` is the sum of its first `k` values (`v.len() + 1` of
/// them).
fn running_sums(v: &[f64]) -> Vec<f64> {
    let mut sum = vec![0.0; v.len() + 1];
    for (j, x) in v.iter().enumerate() {
        sum[j + 1] = sum[j] + x;
    }
    sum
}

/// The stamps' offsets from a grid of one row a place, less a spacing for each row taken as
/// lost at or before them, and their running sums. The rows taken as lost are counted in
/// two Fenwick trees (how many up to a row, and the sum of their rows), so that taking one
/// and reading an offset or a sum each cost O(log rows), not a pass over every later row.
struct Offsets {
    raw: Vec<f64>,
    /// `raw_sum[k]`: the sum of the first `k` raw offsets.
    raw_sum: Vec<f64>,
    /// Over rows + 1: the rows taken as lost at each row.
    count: Vec<u64>,
    /// Over rows + 1: those rows' indices, summed.
    at: Vec<u64>,
}

impl Offsets {
    fn new(t: &[f64], spacing: f64) -> Offsets {
        let n = t.len();
        let raw: Vec<f64> = (0..n).map(|j| (t[j] - t[0]) / spacing - j as f64).collect();
        Offsets {
            raw_sum: running_sums(&raw),
            raw,
            count: vec![0; n + 1],
            at: vec![0; n + 1],
        }
    }

    /// One more row lost just before row `j`: every offset from `j` on is a spacing less.
    fn lose(&mut self, j: usize) {
        let mut i = j + 1;
        while i < self.count.len() {
            self.count[i] += 1;
            self.at[i] += j as u64;
            i += i & i.wrapping_neg();
        }
    }

    /// How many rows are lost before rows `0..k`, and the sum of the rows they were lost at.
    fn lost_before(&self, k: usize) -> (u64, u64) {
        let (mut i, mut count, mut at) = (k, 0, 0);
        while i > 0 {
            count += self.count[i];
            at += self.at[i];
            i -= i & i.wrapping_neg();
        }
        (count, at)
    }

    /// Row `q`'s offset.
    fn offset(&self, q: usize) -> f64 {
        self.raw[q] - self.lost_before(q + 1).0 as f64
    }

    /// The sum of the first `k` offsets: a row lost at `p < k` takes one from each of the
    /// `k - p` offsets from `p` on.
    fn sum(&self, k: usize) -> f64 {
        let (count, at) = self.lost_before(k);
        self.raw_sum[k] - (k as u64 * count - at) as f64
    }
}

/// The rows lost just before each row of `t` on a grid of `spacing`. A lost row shows where
/// the stamps' offset from a grid of one row a place steps up by half a spacing or more
/// between the `w` rows before a row and as many from it on. It is taken at the
/// first row from which the offsets stand more than half a spacing above the level before
/// (the largest sum of their excess from there to two windows on), one row at a time, and
/// the rows a window back are looked at again: two rows lost within a window read as one
/// step of nearly two, whose largest step lies between them, so the first is taken first and
/// the second is then a step of its own. `None` where more than a twentieth of the rows are
/// lost.
fn lost_by_order(t: &[f64], spacing: f64, w: usize) -> Option<Vec<u64>> {
    let n = t.len();
    // The first and last rows' averages are over too few rows to see a step.
    let edge = w / 3;
    if n < 4 * w {
        return None;
    }
    let mut offsets = Offsets::new(t, spacing);
    let mut lost = vec![0u64; n];
    let mut total = 0usize;
    let mut j = edge;
    while j + edge < n {
        if order_step(|k| offsets.sum(k), n, j, w) < 0.5 {
            j += 1;
            continue;
        }
        // The step first reaches half its size about half a window on, so the window before
        // `j` is the level before it.
        let from = j.saturating_sub(w);
        let before = (offsets.sum(j) - offsets.sum(from)) / (j - from) as f64;
        let (mut at, mut best, mut excess) = (j, f64::NEG_INFINITY, 0.0);
        for q in (j..(j + 2 * w).min(n)).rev() {
            excess += offsets.offset(q) - before - 0.5;
            if excess > best {
                (at, best) = (q, excess);
            }
        }
        total += 1;
        if total * 20 > n {
            return None;
        }
        lost[at] += 1;
        offsets.lose(at);
        j = at.saturating_sub(w).max(edge);
    }
    Some(lost)
}

/// The stamps a receiver writes for `rows` rows of a grid of `spacing` s: each within
/// +-`jitter` s of its place, kept in order (a stamp is never before the one before it),
/// a `lost` share of the rows left out at random (`seed`), as in a CAN recording. With the
/// rows lost, for `gap bench` and the tests.
pub(crate) fn receiver_stamps(
    rows: u64,
    spacing: f64,
    jitter: f64,
    lost: f64,
    seed: u64,
) -> (Vec<f64>, Vec<u64>) {
    let mut rng = super::rng::seeded(seed);
    let (mut t, mut gone): (Vec<f64>, Vec<u64>) = (Vec::new(), Vec::new());
    for place in 0..rows {
        if rng.unit() < lost {
            gone.push(place);
            continue;
        }
        let at = spacing * place as f64 + rng.range(-jitter, jitter);
        t.push(t.last().map_or(at, |&last: &f64| at.max(last + 1e-6)));
    }
    (t, gone)
}

/// Each row's place on a grid of about `spacing` by the rows' order: the row before's place
/// plus one, plus the rows lost between them ([`lost_by_order`]). `None` where the stamps'
/// offsets from the grid through the rows so placed still step by half a spacing or more
/// anywhere: no grid of one spacing with rows lost (rows closer together than it, or a rate
/// that wanders).
///
/// Jitter of half a spacing (a 500 Hz logger stamping +-1 ms) leaves each stamp as near the
/// place before or after its own as its own, so neither its gap nor its stamp places it;
/// the average over a few dozen rows still shows the whole spacing a lost row adds.
/// `resolution`: the stamps' own ([`stamp_resolution`]), s.
fn places_by_order(t: &[f64], spacing: f64, resolution: f64) -> Option<Vec<u64>> {
    let n = t.len();
    let places = |lost: Vec<u64>| -> Vec<u64> {
        let mut place = 0u64;
        (0..n)
            .map(|j| {
                place += lost[j];
                place + j as u64
            })
            .collect()
    };
    // The first spacing is the median over ten rows, which the rows lost lengthen (a lost
    // row in a tenth of the spans: 0.35-0.5 % at 1 % lost, 16-24 rows over a 12 s log at
    // 400 Hz, 0.15 spacings over two windows); the grid through the rows so placed has the
    // spacing the rows keep, and they are placed again on it (twice: at 1 kHz and +-1 ms a
    // first placement still misses a few lost rows).
    let mut b = spacing;
    for _ in 0..2 {
        let first = places(lost_by_order(t, b, ORDER_WINDOW)?);
        b = match host_io::grid::line_through(t, &first) {
            Some((_, b)) if b > 0.0 => b,
            _ => return None,
        };
    }
    // The stamps' scatter about their places, from neighbouring rows' gaps (each gap holds
    // two rows' jitter; a lost row's whole spacing is one gap in a hundred, which the
    // median does not see), sets the window the rows are placed by at last.
    let gaps: Vec<f64> = t.windows(2).map(|p| (p[1] - p[0]) / b - 1.0).collect();
    let sigma = median_and_spread(gaps, resolution / b).1 / std::f64::consts::SQRT_2;
    let window = |noise: f64| {
        ((2.0 * (sigma / noise).powi(2)).ceil() as usize)
            .min(n / 8)
            .max(ORDER_WINDOW)
    };
    // A long log holds more windows, and the largest of their averages' noise is larger:
    // about sqrt(2 ln windows) of its standard deviations, as the largest of as many draws
    // of a normal variate. Half a spacing stands that and 1.5 more above it, five at least.
    let windows = n as f64 / window(ORDER_NOISE) as f64;
    let margin = ((2.0 * windows.max(1.0).ln()).sqrt() + 1.5).max(0.5 / ORDER_NOISE);
    let w = window(0.5 / margin);
    // Placed on that window until the offsets from the grid through the rows so placed no
    // longer step. A grid the first placements left a little fast (at 1 kHz, +-1 ms in
    // whole milliseconds, a window of 30 rows takes a few dozen rows as lost that were not:
    // 0.2 %) drifts by a tenth of a spacing over the window; the grid through the rows
    // placed on it is nearer, and they are placed again on that. Stamps kept in order and
    // then rounded (a 1 kHz logger's clock in whole milliseconds, +-1 ms) sit off their
    // places in runs, not each on its own, and their average over the window scatters more
    // than their gaps tell: twice the window, then four times, on the grid reached.
    let mut w = w;
    for attempt in 0..4 {
        if attempt >= 2 {
            w = (2 * w).min(n / 8);
        }
        let placed = places(lost_by_order(t, b, w)?);
        let (a, line_b) = host_io::grid::line_through(t, &placed)?;
        let residual: Vec<f64> = (0..n)
            .map(|j| (t[j] - a) / line_b - placed[j] as f64)
            .collect();
        let sum = running_sums(&residual);
        let edge = w / 3;
        if (edge..n - edge).all(|j| order_step(|k| sum[k], n, j, w).abs() < 0.5) {
            return Some(placed);
        }
        b = line_b;
    }
    None
}

/// Where the reference's periods start within the record's steps, s after each step's
/// start (`origin` + k `step`), from the rows where the reference changes: each such change
/// with no row lost before it puts a period's start between the two rows, and the phase is
/// the circular mean of those intervals' middles (within half a row of the start: at 250 Hz
/// the starts fall on a row and between two rows by turns).
/// `None` where the reference never changes between two neighbouring rows.
fn boundary_phase(
    t: &[f64],
    reference: &[f64],
    origin: f64,
    step: f64,
    row_dt: f64,
) -> Option<f64> {
    let (mut c, mut s, mut count) = (0.0, 0.0, 0usize);
    for i in changes(t, reference, row_dt) {
        // The middle of the interval the start lies in (which end is closed is the
        // convention's; the middle serves both).
        let middle = 0.5 * (t[i - 1] + t[i]) - origin;
        let angle = std::f64::consts::TAU * middle / step;
        c += angle.cos();
        s += angle.sin();
        count += 1;
    }
    (count > 0).then(|| (s.atan2(c) / std::f64::consts::TAU).rem_euclid(1.0) * step)
}

/// Where the reference's periods may start after `origin`, modulo `step`, s: the phases that
/// lie in the most of the intervals between two neighbouring rows across which the reference
/// changes (each holds a period start), as the latest of them and the width of their run.
/// Where the rows' rate and the periods' are commensurate the run keeps a width (8 ms rows
/// against 10 ms periods: 2 ms), and a row may sit on a start at either of its ends: only the
/// rows that lie in a period for every start of the run are surely that period's.
fn period_start_by_changes(
    t: &[f64],
    reference: &[f64],
    origin: f64,
    step: f64,
    row_dt: f64,
) -> Option<(f64, f64)> {
    const BINS: usize = 400;
    let width = step / BINS as f64;
    // A difference array over the bins, each interval (lo, hi] added modulo the step.
    let mut diff = vec![0i64; BINS + 1];
    let mut count = 0usize;
    for i in changes(t, reference, row_dt) {
        let span = t[i] - t[i - 1];
        if span >= step {
            continue;
        }
        let lo = ((t[i - 1] - origin).rem_euclid(step) / width).floor() as usize + 1;
        let n = ((span / width).floor() as usize).max(1);
        let (from, len) = (lo % BINS, n.min(BINS));
        let first = len.min(BINS - from);
        diff[from] += 1;
        diff[from + first] -= 1;
        if len > first {
            diff[0] += 1;
            diff[len - first] -= 1;
        }
        count += 1;
    }
    if count == 0 {
        return None;
    }
    let mut hits = Vec::with_capacity(BINS);
    let mut level = 0i64;
    for d in &diff[..BINS] {
        level += d;
        hits.push(level);
    }
    let top = *hits.iter().max()?;
    // The widest circular run of bins at the top.
    let (mut best, mut best_len) = (0usize, 0usize);
    for start in 0..BINS {
        if hits[start] != top || hits[(start + BINS - 1) % BINS] == top && start != 0 {
            continue;
        }
        let len = (0..BINS)
            .take_while(|&k| hits[(start + k) % BINS] == top)
            .count();
        if len > best_len {
            (best, best_len) = (start, len);
        }
    }
    Some((
        ((best + best_len) as f64 * width).rem_euclid(step),
        best_len as f64 * width,
    ))
}

/// How near a period's ends a row of a log of fewer than two rows a period is not taken as
/// surely the period's, s ([`period_sample`]).
const PERIOD_EDGE_S: f64 = 1e-3;

/// The sample of the reference's period whose middle is `mid`, from rows fewer than two a
/// period (`origin` on the latest start the rows allow, `unsure` the width of the starts
/// they allow): the row that lies in the period for every such start, a millisecond inside
/// ([`PERIOD_EDGE_S`]; whichever the convention, it holds that period's sample), or a row at
/// an end whose sample differs from its neighbour's across that end; where no row holds the
/// period's sample, the cubic through the two periods' samples on either side, each at its
/// period's middle (the acceleration feedforward acts on the second difference, which a
/// straight line across a sine would spike).
fn period_sample(
    t: &[f64],
    reference: &[f64],
    (origin, step, row_dt): (f64, f64, f64),
    unsure: f64,
    mid: f64,
) -> f64 {
    // The period starts at `mid - step / 2` at the latest, and may end `unsure` before
    // `mid + step / 2`; a row within a millisecond of either end may hold a neighbour's
    // sample still (the reference's frames reach the car with a jitter of their own).
    let (from, to) = (
        mid - 0.5 * step + PERIOD_EDGE_S,
        mid + 0.5 * step - unsure - PERIOD_EDGE_S,
    );
    let sure_mid = 0.5 * (from + to);
    let j = t.partition_point(|v| *v < sure_mid).min(t.len() - 1);
    let nearest = (j.saturating_sub(1)..=j)
        .min_by(|&a, &b| (t[a] - sure_mid).abs().total_cmp(&(t[b] - sure_mid).abs()))
        .unwrap_or(j);
    if (from..to).contains(&t[nearest]) {
        return reference[nearest];
    }
    // A row at an end holds this period's sample where it differs from its neighbour's across
    // that end (the sample changed at the row, or changes after it), the two a row apart.
    let spacing = |a: usize, b: usize| t[b] - t[a] <= 1.5 * row_dt;
    let at_start = (from - 2.0 * PERIOD_EDGE_S..from).contains(&t[nearest])
        && nearest > 0
        && spacing(nearest - 1, nearest)
        && reference[nearest] != reference[nearest - 1];
    let at_end = (to..to + 2.0 * PERIOD_EDGE_S).contains(&t[nearest])
        && nearest + 1 < t.len()
        && spacing(nearest, nearest + 1)
        && reference[nearest] != reference[nearest + 1];
    if at_start || at_end {
        return reference[nearest];
    }
    // Each row's period middle; the nearest two periods with a row on either side.
    let period = |i: usize| ((t[i] - origin) / step).floor();
    let here = ((mid - origin) / step).floor();
    let mut points: Vec<(f64, f64)> = Vec::with_capacity(4);
    let before = t.partition_point(|v| *v < mid);
    let mut take = |i: usize, side: f64, upto: usize| {
        let p = period(i);
        if (p - here) * side > 0.0 && points.iter().all(|(q, _)| *q != p) {
            points.push((p, reference[i]));
        }
        points.len() >= upto
    };
    // Two periods before, then after up to four in all (`any` stops at the count).
    let _ = (0..before).rev().any(|i| take(i, -1.0, 2));
    let _ = (before..t.len()).any(|i| take(i, 1.0, 4));
    if points.len() < 2 {
        return reference[nearest];
    }
    lagrange(&points, here)
}

/// The polynomial through `points` (`(x, y)`, distinct `x`) at `x`, by Lagrange's form.
fn lagrange(points: &[(f64, f64)], x: f64) -> f64 {
    points
        .iter()
        .enumerate()
        .map(|(i, &(xi, yi))| {
            let w: f64 = points
                .iter()
                .enumerate()
                .filter(|&(m, _)| m != i)
                .map(|(_, &(xm, _))| (x - xm) / (xi - xm))
                .product();
            w * yi
        })
        .sum()
}

/// The rows `i` at which the reference changes from row `i - 1`, with no row lost between
/// the two: a period start lies between them.
fn changes<'a>(
    t: &'a [f64],
    reference: &'a [f64],
    row_dt: f64,
) -> impl Iterator<Item = usize> + 'a {
    (1..t.len())
        .filter(move |&i| reference[i] != reference[i - 1] && t[i] - t[i - 1] <= 1.5 * row_dt)
}

/// How far the steps of `step` from `origin` must move for their starts to sit on the
/// reference's period starts, s: zero where they already do. Each change of the reference
/// between two neighbouring rows puts a period start in the closed interval between them
/// (which end is the logger's convention). Where the steps' start lies in at least half of
/// those intervals (modulo the step, within a quarter row), it stays: a row on a step's
/// boundary is then read by the convention the rows show. Otherwise it moves to the nearest
/// phase that lies in the most of them, where that puts the steps' middles within a row of
/// a period start (a first row lost at 400 Hz: 2.5 ms); a 1 kHz log whose stamps run 3 ms
/// late keeps its steps. A reference that reaches the car with a jitter of
/// its own moves some changes by a row or two, so the phase is the one most changes agree
/// on, not one all of them allow. `centre` is the changes' [`boundary_phase`] against
/// `origin`.
fn period_alignment(
    t: &[f64],
    reference: &[f64],
    origin: f64,
    step: f64,
    row_dt: f64,
    centre: f64,
) -> f64 {
    // A time's phase against the centre, within half a step of it.
    let wrap = |d: f64| d - step * (d / step).round();
    let rel = |x: f64| wrap(x - origin - centre);
    let tolerance = 0.25 * row_dt;
    let (mut lows, mut highs) = (Vec::new(), Vec::new());
    for i in changes(t, reference, row_dt) {
        lows.push(rel(t[i - 1]) - tolerance);
        highs.push(rel(t[i]) + tolerance);
    }
    lows.sort_by(f64::total_cmp);
    highs.sort_by(f64::total_cmp);
    // How many intervals hold phase `x`.
    let holding = |x: f64| lows.partition_point(|&l| l <= x) - highs.partition_point(|&h| h < x);
    let start = wrap(-centre);
    if 2 * holding(start) >= lows.len() {
        return 0.0;
    }
    // The intervals' own ends, without the tolerance.
    let ends = lows
        .iter()
        .map(|l| l + tolerance)
        .chain(highs.iter().map(|h| h - tolerance));
    let best = ends.map(|x| (holding(x), x)).max_by(|a, b| {
        a.0.cmp(&b.0)
            .then_with(|| (b.1 - start).abs().total_cmp(&(a.1 - start).abs()))
    });
    // Moved only where the steps' middles lie within a row of a period start, where a
    // middle row lost leaves a neighbour from either period: elsewhere the rows near the
    // middle are the step's own, and the model fits where in its period each sample is taken.
    let shift = best.map_or(0.0, |(_, x)| x - start);
    if 0.5 * step - shift.abs() <= row_dt + tolerance {
        shift
    } else {
        0.0
    }
}

/// Which of rows `j - 1` and `j`, with rows lost between them, holds the sample of the
/// reference period that the step whose middle is `mid` reads: the two hold the same sample,
/// or exactly one period start (at `phase`, [`boundary_phase`]) falls between them and `mid`
/// lies on that row's side of it. `None` where the gap holds two or more starts (a whole
/// period's rows lost) or the phase is not known.
fn side_of_the_boundary(
    t: &[f64],
    reference: &[f64],
    j: usize,
    mid: f64,
    origin: f64,
    step: f64,
    phase: Option<f64>,
) -> Option<usize> {
    if j == 0 {
        return None;
    }
    if reference[j - 1] == reference[j] {
        return Some(j);
    }
    let phase = phase?;
    let first = ((t[j - 1] - origin - phase) / step).ceil();
    let last = ((t[j] - origin - phase) / step).floor();
    if first != last {
        return None;
    }
    let start = origin + phase + first * step;
    Some(if mid < start { j - 1 } else { j })
}

impl LogTiming {
    /// From a log's (increasing) stamps. Each row is placed on the grid by its gap to the row
    /// before (so a clock a little off the nominal rate does not drift the count), and the
    /// grid is the least-squares line through those places.
    pub fn of(t: &[f64]) -> LogTiming {
        LogTiming::with_places(t).0
    }

    /// [`LogTiming::of`], with each row's place on the grid.
    pub fn with_places(t: &[f64]) -> (LogTiming, Vec<u64>) {
        LogTiming::at_resolution(t, stamp_resolution(t))
    }

    /// [`LogTiming::with_places`] for stamps of a known `resolution`
    /// ([`stamp_resolution`]), s.
    fn at_resolution(t: &[f64], resolution: f64) -> (LogTiming, Vec<u64>) {
        if t.len() < 2 {
            return (
                LogTiming {
                    rows: t.len(),
                    ..LogTiming::default()
                },
                (0..t.len() as u64).collect(),
            );
        }
        let median_gap = host_io::grid::median_gap(t);
        let (places, _) = host_io::grid::places_by_gaps(t, median_gap);
        let by_gaps = LogTiming::on_places(t, &places, median_gap, resolution);
        if by_gaps.is_regular() {
            return (by_gaps, places);
        }
        // The spacing over ten rows (the median: a lost row in a tenth of them moves it not
        // at all, a stamp's jitter by a tenth).
        let k = 10.min(t.len() - 1);
        let mut spans: Vec<f64> = t.windows(k + 1).map(|w| (w[k] - w[0]) / k as f64).collect();
        spans.sort_by(|a, b| a.total_cmp(b));
        let spacing = spans[spans.len() / 2].max(1e-9);
        // Jitter of up to half the spacing (a 400 or 500 Hz logger stamping +-1 ms, its rows
        // in the order they came): the rows' order places them.
        if let Some(by_order) = places_by_order(t, spacing, resolution) {
            let mut timing = LogTiming::on_places(t, &by_order, spacing, resolution);
            if timing.jitter_s < ORDER_MAX_JITTER * timing.row_dt_s {
                timing.on_grid = true;
                return (timing, by_order);
            }
        }
        // Jitter of the order of the spacing (a 1 kHz logger stamping +-1 ms, its rows in the
        // order they came): the gaps no longer tell a lost row from a late stamp, and placing
        // each row by its gap piles the errors up (a faster grid, thousands of rows missing).
        // Each row by its stamp against the spacing over ten rows, then, which keeps every
        // error within a row's jitter; taken when it leaves the stamps closer to a grid.
        let mut by_stamp = Vec::with_capacity(t.len());
        let mut last: Option<u64> = None;
        for &tj in t {
            let at = ((tj - t[0]) / spacing).round().max(0.0) as u64;
            let at = last.map_or(at, |l| at.max(l + 1));
            by_stamp.push(at);
            last = Some(at);
        }
        let by_stamps = LogTiming::on_places(t, &by_stamp, spacing, resolution);
        if by_stamps.jitter_s / by_stamps.row_dt_s < by_gaps.jitter_s / by_gaps.row_dt_s {
            (by_stamps, by_stamp)
        } else {
            (by_gaps, places)
        }
    }

    /// The grid through stamps `t` at rows `places`: the least-squares line, the robust
    /// spread about it, the rows the places skip. `spacing` where the line has no slope;
    /// `resolution`: the stamps' own ([`stamp_resolution`]), s.
    fn on_places(t: &[f64], places: &[u64], spacing: f64, resolution: f64) -> LogTiming {
        // t = a + b * place by least squares; through the mean with `spacing` where that
        // has no positive slope.
        let (a, b) = match host_io::grid::line_through(t, places) {
            Some((a, b)) if b > 0.0 => (a, b),
            _ => {
                let n = t.len() as f64;
                let mx = places.iter().map(|&p| p as f64).sum::<f64>() / n;
                (t.iter().sum::<f64>() / n - spacing * mx, spacing)
            }
        };
        let offsets: Vec<f64> = places
            .iter()
            .zip(t)
            .map(|(&p, &tj)| tj - (a + b * p as f64))
            .collect();
        let (median, jitter_s) = median_and_spread(offsets, resolution);
        let last = places.last().copied().unwrap_or(0);
        LogTiming {
            row_dt_s: b,
            grid_origin_s: a + median - b,
            jitter_s,
            missing_rows: (last + 1).saturating_sub(t.len() as u64) as usize,
            rows: t.len(),
            on_grid: jitter_s < 0.2 * b,
        }
    }

    /// The times of grid `places` (a place counts rows from one spacing after the origin), s.
    pub fn at_places(&self, places: &[u64]) -> Vec<f64> {
        places
            .iter()
            .map(|&p| self.grid_origin_s + self.row_dt_s * (p + 1) as f64)
            .collect()
    }

    /// The stamps are a regular grid with jitter (not an irregular sampling), each row at its
    /// place ([`LogTiming::on_grid`]).
    pub fn is_regular(&self) -> bool {
        self.row_dt_s > 0.0 && self.on_grid
    }
}

/// Rows closer than this share of a step are several a step; from it up to one a step,
/// fewer than two ([`Record::from_samples`] reads them by the reference's periods).
pub(super) const FEWER_ROWS_A_STEP: f64 = 0.65;

/// How near the rows' spacing must be to a grid step for each row to be its step: 1 %, an
/// ECU on its internal RC oscillator (the largest SYNC drift the EPOS4 model takes).
pub(super) const ONE_ROW_A_STEP: f64 = super::model::MAX_SYNC_DRIFT;

impl Record {
    /// Log rows at any rate (>= the grid's is best) onto a grid of step `dt`; with a row a
    /// step (the spacing within 1 % of `dt`), of the rows' own spacing, so that a logger on
    /// a clock of its own keeps each row as its step. The grid
    /// starts where the first row's interval starts (its time minus the typical row
    /// spacing), so a log written from t = one row interval on, as host-sim writes them,
    /// lands on the reference periods exactly. Rows need not sit on the grid: angles are
    /// interpolated to the step ends, interval means are weighted by their overlap with
    /// each step. With rows on the reference's period boundaries, `stated` (a header's
    /// `# reference:` line) says which period a boundary's row holds, wherever the first row
    /// lies.
    // The columns, the grid and what the header says of two of them: each a caller's own.
    #[allow(clippy::too_many_arguments)]
    pub fn from_samples(
        t: &[f64],
        reference: &[f64],
        output: &[f64],
        effort: &[f64],
        motor: Option<Vec<f64>>,
        dt: f64,
        current: CurrentSamples,
        stated: Option<ReferenceConvention>,
    ) -> Record {
        if t.len() < 2 {
            return Record {
                dt,
                ..Record::default()
            };
        }
        let (timing, places) = LogTiming::with_places(t);
        // A logger that stamps rows of a regular sampling with jitter (a CAN recording's
        // receive times): each row is taken at its place on the grid, not at its stamp. Stamps
        // already on a grid are kept as they are.
        let snapped: Vec<f64>;
        let t = if timing.is_regular() && timing.jitter_s > 1e-7 {
            snapped = timing.at_places(&places);
            &snapped[..]
        } else {
            t
        };
        let row_dt = if timing.is_regular() {
            timing.row_dt_s
        } else {
            host_io::grid::median_gap(t)
        };
        // The grid from every row's stamp, not the first one's alone: a logger's stamps jitter,
        // and the first row's jitter would shift every step of the log by as much.
        let origin = if timing.is_regular() {
            timing.grid_origin_s
        } else {
            t[0] - row_dt
        };
        // At the grid's own rate each row is its step, whatever clock stamped it: the grid's
        // step is then the rows' spacing (`dt` stays the record's, the reference's period). A
        // logger that writes a row as each TPDO arrives stamps the ECU's SYNCs in the vehicle
        // computer's time; 72 ppm apart, a 120 s track's rows walk 8.6 ms against steps of
        // exactly 10 ms, and each row read at those steps' ends was a blend of two SYNCs.
        let step = if timing.is_regular() && (row_dt / dt - 1.0).abs() < ONE_ROW_A_STEP {
            row_dt
        } else {
            dt
        };
        let last = t[t.len() - 1];
        let several_rows = timing.is_regular() && row_dt < FEWER_ROWS_A_STEP * dt;
        // Fewer than two rows a step but more than one (a 125 Hz logger): a step's middle row
        // need not hold the step's sample, and the row after its middle often holds the next
        // step's. The steps are moved onto the reference's periods, which the rows' changes
        // place, and each takes a row that lies in its period ([`period_sample`]): that
        // period's sample whichever convention wrote it.
        let fewer_rows = timing.is_regular()
            && (FEWER_ROWS_A_STEP * dt..(1.0 - ONE_ROW_A_STEP) * dt).contains(&row_dt);
        // With several rows a step, a row within a quarter of the spacing of a place is that
        // place's: rows placed on a grid whose spacing was estimated (a jittered log's) drift
        // from the 10 ms steps by the estimate's error, 30 us over 12 s at 200 Hz. Otherwise
        // a millionth of a row, for the rounding of binary fractions of 0.01 s.
        let near = if several_rows {
            0.25 * row_dt
        } else {
            1e-6 * row_dt
        };
        // With several rows a period, the steps are moved to the reference's period starts
        // where they fall inside a period (the grid's origin is one spacing before the first
        // row, so a first row lost moves it by a row: 2.5 ms at 400 Hz, the steps' middles
        // then on the period starts, and a step whose middle row was lost took either
        // neighbour's sample).
        let phase = several_rows
            .then(|| boundary_phase(t, reference, origin, step, row_dt))
            .flatten();
        let shift = phase.map_or(0.0, |centre| {
            period_alignment(t, reference, origin, step, row_dt, centre)
        });
        let starts = fewer_rows
            .then(|| period_start_by_changes(t, reference, origin, step, row_dt))
            .flatten();
        // (Fewer rows than several a step have no `phase`, so `shift` is 0 there.)
        let shift = starts.map_or(shift, |(latest, _)| latest);
        let unsure = starts.map_or(0.5 * step, |(_, width)| width);
        let origin = origin + shift;
        // The row stamped at `at`, within a quarter of a row spacing.
        let row_at = |at: f64| {
            let j = t.partition_point(|v| *v < at - 0.25 * row_dt);
            (j < t.len() && (t[j] - at).abs() < 0.25 * row_dt).then_some(j)
        };
        // With more than one row per step, which step a row on a step's boundary holds: ours
        // hold the step that ends there (the row equals the one before it), a logger that
        // takes the new sample at once the step that starts there (equals the one after).
        // Only on a regular grid (the rows at their places): a log whose stamps jitter by
        // as much as its spacing has no row that sits on a boundary.
        let (mut ending, mut starting) = (0usize, 0usize);
        if several_rows {
            let n = (((last - origin + near) / step + 1e-6).floor() as usize).max(1);
            for k in 0..n {
                if let Some(j) = row_at(origin + (k + 1) as f64 * step)
                    && j > 0
                    && j + 1 < t.len()
                {
                    let (before, after) = (reference[j - 1], reference[j + 1]);
                    match (reference[j] == before, reference[j] == after) {
                        (true, false) => ending += 1,
                        (false, true) => starting += 1,
                        _ => {}
                    }
                }
            }
        }
        // Rows on the periods' boundaries leave each period's start at either end of the two
        // rows across which the reference changes: the row on it holds the period that ends
        // there or the one that starts there. The rows alone cannot tell which, and the steps
        // start one spacing before the first row: right for a log written from the start of
        // a period, a row off for one cut from a longer recording or begun mid-period (5 ms
        // at 200 Hz: the reference half a period early or late to the model). A header's
        // `# reference:` line says which, and the steps move by that row.
        let moved = match stated {
            Some(c) if ending + starting > 0 => {
                match (starting > ending, c == ReferenceConvention::PeriodStarting) {
                    (true, false) => -row_dt,
                    (false, true) => row_dt,
                    _ => 0.0,
                }
            }
            _ => 0.0,
        };
        let origin = origin + moved;
        let period_starting = match stated {
            Some(c) if ending + starting > 0 => c == ReferenceConvention::PeriodStarting,
            _ => starting > ending,
        };
        // The period starts against the moved steps.
        let phase = phase.map(|centre| (centre - shift - moved).rem_euclid(step));
        let n = (((last - origin + near) / step + 1e-6).floor() as usize).max(1);
        let end = |k: usize| origin + (k + 1) as f64 * step;
        let reference = (0..n)
            .map(|k| {
                // The row whose interval holds the middle of the step.
                let mid = origin + (k as f64 + 0.5) * step;
                if fewer_rows {
                    return period_sample(t, reference, (origin, step, row_dt), unsure, mid);
                }
                // A row stamped `near` below the middle is the middle's (200 Hz rows sit on
                // it).
                let j = t.partition_point(|v| *v < mid - near).min(t.len() - 1);
                // Rows missing before row j: its value is the reference of its own interval
                // only; over the missing ones, the cubic through the neighbours' (each at its
                // interval's middle). The controller's acceleration feedforward acts on the
                // reference's second difference, so a straight line across a lost row of a
                // sine would be a current spike the car never had.
                let missing = j > 0 && t[j] - t[j - 1] > 1.5 * row_dt && mid < t[j] - row_dt;
                // Several rows a step, none on its middle (lost, or rows off the 5 ms
                // points): the row on the step's boundary that holds it, if kept.
                let boundary = if period_starting {
                    end(k) - step
                } else {
                    end(k)
                };
                // Many rows a step (1 kHz): the row nearest the middle, if it lies well inside
                // the step. The grid's boundaries need not sit on the ECU's periods (its
                // origin comes from the stamps, the periods from the car), so a row on a
                // boundary may hold either neighbour; a row a few ms from the middle holds
                // the step's own sample for any offset under half a step less a row.
                let inside = 0.5 * step - 0.75 * row_dt;
                let near_mid = || {
                    (j.saturating_sub(1)..=j)
                        .filter(|&i| (t[i] - mid).abs() <= inside)
                        .min_by(|&a, &b| (t[a] - mid).abs().total_cmp(&(t[b] - mid).abs()))
                };
                let mid_lost = several_rows && row_at(mid).is_none();
                if mid_lost && let Some(i) = near_mid() {
                    reference[i]
                } else if mid_lost && let Some(b) = row_at(boundary) {
                    reference[b]
                } else if let Some(side) = (several_rows && missing)
                    .then(|| side_of_the_boundary(t, reference, j, mid, origin, step, phase))
                    .flatten()
                {
                    reference[side]
                } else if missing {
                    let lo = j.saturating_sub(2);
                    let hi = (j + 1).min(t.len() - 1);
                    let points: Vec<(f64, f64)> = (lo..=hi)
                        .map(|i| (t[i] - 0.5 * row_dt, reference[i]))
                        .collect();
                    lagrange(&points, mid)
                } else {
                    reference[j]
                }
            })
            .collect();
        let effort = match current {
            CurrentSamples::IntervalMean | CurrentSamples::SyncSample => (0..n)
                .map(|k| {
                    let (a, b) = (end(k) - step, end(k));
                    let (mut sum, mut w) = (0.0, 0.0);
                    let j0 = t.partition_point(|v| *v <= a);
                    for j in j0..t.len() {
                        let lo = if j == 0 { t[0] - row_dt } else { t[j - 1] };
                        if lo >= b {
                            break;
                        }
                        let overlap = t[j].min(b) - lo.max(a);
                        if overlap > 0.0 && effort[j].is_finite() {
                            sum += overlap * effort[j];
                            w += overlap;
                        }
                    }
                    if w > 0.0 {
                        sum / w
                    } else {
                        interp_at(t, effort, b - 0.5 * step)
                    }
                })
                .collect(),
            CurrentSamples::Instantaneous => (0..n)
                .map(|k| {
                    let (a, b) = (end(k) - step, end(k));
                    let j0 = t.partition_point(|v| *v <= a + 1e-9 * step);
                    let j1 = t.partition_point(|v| *v <= b + 1e-9 * step);
                    let vals: Vec<f64> = effort[j0..j1]
                        .iter()
                        .copied()
                        .filter(|v| v.is_finite())
                        .collect();
                    if vals.is_empty() {
                        interp_at(t, effort, b - 0.5 * step)
                    } else {
                        vals.iter().sum::<f64>() / vals.len() as f64
                    }
                })
                .collect(),
        };
        Record {
            dt,
            reference,
            output: (0..n).map(|k| interp_at(t, output, end(k))).collect(),
            effort,
            motor: motor.map(|m| (0..n).map(|k| interp_at(t, &m, end(k))).collect()),
            disturbance: None,
            supply_v: None,
            powered_from: 0,
            current_chatter: false,
        }
    }

    pub fn len(&self) -> usize {
        self.reference.len()
    }

    pub fn is_empty(&self) -> bool {
        self.reference.is_empty()
    }

    pub fn duration_s(&self) -> f64 {
        self.len() as f64 * self.dt
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Stamps of a 2 ms grid, `lost` rows left out, each stamp off its place by up to
    /// `jitter` spacings (a fixed pseudo-random draw), kept in order as a receiver keeps them.
    fn stamps(n: u64, lost: &[u64], jitter: f64) -> Vec<f64> {
        let mut rng = super::super::rng::seeded(1);
        let mut t: Vec<f64> = Vec::new();
        for place in (0..n).filter(|p| !lost.contains(p)) {
            let at = 2e-3 * (place as f64 + 1.0 + rng.range(-jitter, jitter));
            t.push(t.last().map_or(at, |&last: &f64| at.max(last + 1e-6)));
        }
        t
    }

    #[test]
    fn rows_jittered_by_half_their_spacing_are_placed_by_their_order() {
        // Two lost rows five apart, one alone, and three in a row.
        let lost = [700, 705, 2_000, 4_100, 4_101, 4_102];
        let t = stamps(6_000, &lost, 0.5);
        let (timing, places) = LogTiming::with_places(&t);
        assert!(timing.on_grid, "{timing:?}");
        assert_eq!(timing.missing_rows, lost.len(), "{timing:?}");
        assert!((timing.row_dt_s - 2e-3).abs() < 1e-8, "{timing:?}");
        let truth: Vec<u64> = (0..6_000).filter(|p| !lost.contains(p)).collect();
        let wrong = places.iter().zip(&truth).filter(|(p, q)| p != q).count();
        // A lost row is placed from the rows around it, within a few rows of where it was.
        assert!(wrong < 20, "{wrong} rows off their place");
        // The gaps alone, at this jitter, find rows lost that were not.
        let (by_gaps, _) = host_io::grid::places_by_gaps(&t, host_io::grid::median_gap(&t));
        assert!(by_gaps.last().copied().unwrap_or(0) > 6_000);
    }

    #[test]
    fn stamps_that_are_no_grid_are_not_placed_on_one() {
        // Rows 1-3 ms apart at random: a logger that samples as it gets to it.
        let mut rng = super::super::rng::seeded(2);
        let mut t = vec![0.0];
        for _ in 0..6_000 {
            let last = t[t.len() - 1];
            t.push(last + rng.range(1e-3, 3e-3));
        }
        let timing = LogTiming::of(&t);
        assert!(!timing.on_grid, "{timing:?}");
        assert!(!timing.is_regular(), "{timing:?}");
    }

    #[test]
    fn offsets_with_rows_lost_read_as_a_pass_that_takes_each_off_every_later_row() {
        let t = stamps(3_000, &[10, 11, 900], 0.4);
        let mut rng = super::super::rng::seeded(3);
        let mut offsets = Offsets::new(&t, 2e-3);
        let mut direct = offsets.raw.clone();
        // Rows lost anywhere, some at the same row, some before rows already taken.
        for _ in 0..200 {
            let at = rng.range(0.0, t.len() as f64) as usize;
            offsets.lose(at);
            for o in &mut direct[at..] {
                *o -= 1.0;
            }
        }
        let mut sum = 0.0;
        for (k, &offset) in direct.iter().enumerate() {
            assert!(
                (offsets.sum(k) - sum).abs() < 1e-6 * (1.0 + sum.abs()),
                "sum to row {k}"
            );
            assert!((offsets.offset(k) - offset).abs() < 1e-9, "row {k}");
            sum += offset;
        }
        assert!((offsets.sum(t.len()) - sum).abs() < 1e-6 * (1.0 + sum.abs()));
    }

    #[test]
    fn a_long_log_at_1_khz_with_jitter_and_rows_lost_is_placed_with_every_row_counted() {
        // 30 min at 1 kHz, +-1 ms, 1 % lost: 1.8 million rows, about 18 000 of them lost.
        let (t, lost) = receiver_stamps(1_800_000, 1e-3, 1e-3, 0.01, 7);
        let timing = LogTiming::of(&t);
        assert!(timing.on_grid, "{timing:?}");
        // The first and last rows' averages are too short to see a lost row.
        let inside = lost
            .iter()
            .filter(|&&p| (200..1_799_800).contains(&p))
            .count();
        assert!(
            (inside..=lost.len()).contains(&timing.missing_rows),
            "{} missing, {} lost ({inside} inside)",
            timing.missing_rows,
            lost.len()
        );
    }

    #[test]
    fn stamps_rounded_as_coarsely_as_their_jitter_read_it_by_their_rms() {
        // 1 kHz, +-1 ms, 1 % lost, stamped in whole milliseconds, in order and not, on a
        // clock counting from 0 and from a Unix epoch: the stamps' error is the +-1 ms
        // (0.58 ms RMS) and the rounding's (0.29 ms), 0.65 ms in all. Twenty draws: stamps
        // kept in order sit off their places in runs, which a window set by their gaps alone
        // reads as a step on some.
        for seed in 11..31 {
            let epoch = if seed % 2 == 0 { 1.7e9 } else { 0.0 };
            let (stamps, lost) = receiver_stamps(20_000, 1e-3, 1e-3, 0.01, seed);
            let rounded: Vec<f64> = stamps
                .iter()
                .map(|v| epoch + (v * 1e3).round() * 1e-3)
                .collect();
            assert_eq!(stamp_resolution(&rounded), 1e-3);
            let timing = LogTiming::of(&rounded);
            let jitter_ms = 1e3 * timing.jitter_s;
            assert!(timing.on_grid, "{timing:?}");
            assert!((0.55..0.75).contains(&jitter_ms), "{timing:?}");
            assert!(timing.missing_rows.abs_diff(lost.len()) <= 2, "{timing:?}");
            // The same rows drawn without keeping their order: placed by it.
            let mut rng = super::super::rng::seeded(seed);
            let past: Vec<f64> = (0..20_000u64)
                .filter(|p| !lost.contains(p))
                .map(|p| ((epoch + 1e-3 * p as f64 + rng.range(-1e-3, 1e-3)) * 1e3).round() * 1e-3)
                .collect();
            let Some((_, timing)) = placed_in_order(&past) else {
                panic!("stamps within their jitter of their places are placed");
            };
            assert!(
                (0.55..0.75).contains(&(1e3 * timing.jitter_s)),
                "{timing:?}"
            );
        }
        // A finer clock's stamps keep their median absolute deviation.
        let (fine, _) = receiver_stamps(20_000, 1e-3, 1e-3, 0.0, 5);
        assert_eq!(stamp_resolution(&fine), 0.0);
    }
}

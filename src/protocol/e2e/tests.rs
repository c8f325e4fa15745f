//! E2E checker tests: one per rule and outcome, then arbitrary frames and streams.

use super::*;
use crate::can::StandardId;
use crate::protocol::{REFERENCE_ID, frame_crc};
use proptest::prelude::*;

const T: u64 = 10_000; // one reference period, us

fn checker() -> E2eChecker {
    E2eChecker::new(ProtocolConfig::DEFAULT).unwrap()
}

/// A reference frame with a correct CRC from raw fields (so invalid codes can be built too).
fn frame(counter: u8, code: u8, angle_raw: i16) -> Frame {
    let mut bytes = [0u8; 8];
    bytes[1] = (counter & 0x0F) | code << 4;
    bytes[2..4].copy_from_slice(&angle_raw.to_le_bytes());
    bytes[0] = frame_crc(REFERENCE_ID, &bytes);
    Frame::new(REFERENCE_ID, &bytes).unwrap()
}

const DRIVING: u8 = 2;

fn is_valid(v: E2eVerdict) -> bool {
    matches!(v, E2eVerdict::Valid(_))
}

fn error(v: E2eVerdict) -> Option<FrameError> {
    match v {
        E2eVerdict::Valid(_) => None,
        E2eVerdict::Dropped { error, .. } | E2eVerdict::Fault { error, .. } => Some(error),
    }
}

#[test]
fn a_stream_at_300_deg_per_s_is_accepted_whole() {
    // +-90 deg sine at 0.53 Hz peaks at 300 deg/s, below the 400 deg/s limit.
    let mut c = checker();
    for n in 0..2_000u64 {
        let t = n as f32 * 0.01;
        let angle = 90.0 * (2.0 * core::f32::consts::PI * 0.53 * t).sin();
        let raw = (angle * 100.0) as i16;
        let v = c.check(&frame(n as u8, DRIVING, raw), n * T);
        let E2eVerdict::Valid(r) = v else {
            panic!("frame {n}: {v:?}")
        };
        assert_eq!(r.as_state, AsState::Driving);
        assert_eq!(r.angle, SteeringDeg(f32::from(raw) * 0.01));
    }
    assert_eq!(*c.drops(), DropCounters::default());
}

#[test]
fn corrupted_crc_is_dropped_and_counted() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 100), 0)));
    let good = frame(1, DRIVING, 150);
    let mut bytes: [u8; 8] = good.data().try_into().unwrap();
    bytes[2] ^= 0x04;
    let bad = Frame::new(REFERENCE_ID, &bytes).unwrap();
    assert!(matches!(
        c.check(&bad, T),
        E2eVerdict::Dropped {
            error: FrameError::Crc { .. },
            invalid_in_row: 1
        }
    ));
    assert_eq!(c.drops().crc, 1);
    // The corrupted counter byte was not trusted: the intact frame 1 is still next in line.
    assert!(is_valid(c.check(&good, T + 100)));
}

#[test]
fn repeated_counter_is_stale() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(4, DRIVING, 0), 0)));
    assert_eq!(
        error(c.check(&frame(4, DRIVING, 0), T)),
        Some(FrameError::Stale { counter: 4 })
    );
    assert_eq!(c.drops().stale, 1);
    assert!(is_valid(c.check(&frame(5, DRIVING, 0), 2 * T)));
}

#[test]
fn a_counter_jump_is_dropped_and_the_next_frame_in_sequence_accepted() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(15, DRIVING, 0), 0)));
    // Frame 0 lost: 1 is a jump (wrapping 15 -> 0 -> 1), dropped; 2 follows 1 and is accepted.
    assert_eq!(
        error(c.check(&frame(1, DRIVING, 300), 2 * T)),
        Some(FrameError::Counter {
            expected: 0,
            found: 1
        })
    );
    assert_eq!(c.drops().counter_jump, 1);
    assert!(is_valid(c.check(&frame(2, DRIVING, 600), 3 * T)));
}

/// The counter a new sender continues from is the last authentic frame's, accepted or not:
/// a frame dropped for its angle still moves it, a frame that fails the CRC does not.
#[test]
fn the_last_counter_is_the_one_the_next_frame_must_follow() {
    let mut c = checker();
    assert_eq!(c.last_counter(), None, "any counter before the first frame");
    assert!(is_valid(c.check(&frame(6, DRIVING, 0), 0)));
    assert_eq!(c.last_counter(), AliveCounter::new(6));
    // 95 deg: out of range, dropped, but its counter is authentic.
    assert!(error(c.check(&frame(7, DRIVING, 9500), T)).is_some());
    assert_eq!(c.last_counter(), AliveCounter::new(7));
    let mut bytes: [u8; 8] = frame(8, DRIVING, 0).data().try_into().unwrap();
    bytes[1] ^= 0x0F;
    let corrupted = Frame::new(REFERENCE_ID, &bytes).unwrap();
    assert!(matches!(
        error(c.check(&corrupted, 2 * T)),
        Some(FrameError::Crc { .. })
    ));
    assert_eq!(c.last_counter(), AliveCounter::new(7));
    // A sender that continues from it is accepted at once.
    let next = c.last_counter().unwrap().next().raw();
    assert!(is_valid(c.check(&frame(next, DRIVING, 0), 3 * T)));
    c.reset();
    assert_eq!(c.last_counter(), None);
}

#[test]
fn five_invalid_in_a_row_is_a_fault() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    for n in 1..=4u8 {
        assert!(matches!(
            c.check(&frame(0, DRIVING, 0), u64::from(n) * T),
            E2eVerdict::Dropped { invalid_in_row, .. } if invalid_in_row == n
        ));
        assert!(!c.in_fault());
    }
    assert!(matches!(
        c.check(&frame(0, DRIVING, 0), 5 * T),
        E2eVerdict::Fault {
            error: FrameError::Stale { counter: 0 },
            invalid_in_row: 5
        }
    ));
    assert!(c.in_fault());
    assert!(matches!(
        c.check(&frame(0, 9, 0), 6 * T),
        E2eVerdict::Fault {
            invalid_in_row: 5,
            ..
        }
    ));
    // Not latched here: a valid frame takes the score below the limit (the state machine
    // latches).
    assert!(is_valid(c.check(&frame(1, DRIVING, 0), 7 * T)));
    assert_eq!(c.invalid_in_row(), 4);
    assert!(!c.in_fault());
}

#[test]
fn a_counter_repeated_in_four_of_five_frames_is_a_fault() {
    // One good frame in five must not wipe the four bad ones: the score saturates, it is not
    // reset by a good frame.
    let mut c = checker();
    let mut counter = 0u8;
    let mut faulted = false;
    for n in 0..50u64 {
        if n % 5 == 0 {
            counter = (counter + 1) % 16;
        }
        let v = c.check(&frame(counter, DRIVING, 0), n * T);
        faulted |= matches!(v, E2eVerdict::Fault { .. });
    }
    assert!(faulted, "score {}", c.invalid_in_row());
}

#[test]
fn wrong_counters_saturate() {
    let mut c = checker();
    let stale = frame(3, DRIVING, 0);
    for n in 0..70_000u64 {
        c.check(&stale, n * T);
    }
    assert_eq!(c.drops().stale, u16::MAX);
    assert_eq!(c.invalid_in_row(), 5, "the score saturates at the limit");
    assert!(c.in_fault());
}

#[test]
fn foreign_ids_are_counted_but_never_a_fault() {
    let mut c = checker();
    let other = Frame::new(StandardId::new(0x300).unwrap(), &[0; 8]).unwrap();
    for n in 0..10 {
        assert!(matches!(
            c.check(&other, n * T),
            E2eVerdict::Dropped {
                error: FrameError::WrongId { .. },
                invalid_in_row: 0
            }
        ));
    }
    assert_eq!(c.drops().wrong_id, 10);
    assert_eq!(c.drops().invalid_total(), 0);
}

#[test]
fn wrong_length_is_dropped_and_counted() {
    let mut c = checker();
    let short = Frame::new(REFERENCE_ID, &frame(0, DRIVING, 0).data()[..6]).unwrap();
    assert_eq!(
        error(c.check(&short, 0)),
        Some(FrameError::WrongLength { len: 6 })
    );
    assert_eq!(c.drops().wrong_length, 1);
}

#[test]
fn unknown_as_state_is_dropped_and_counted() {
    let mut c = checker();
    assert_eq!(
        error(c.check(&frame(0, 6, 0), 0)),
        Some(FrameError::UnknownAsState { code: 6 })
    );
    assert_eq!(c.drops().unknown_as_state, 1);
    // Its CRC was right, so its counter stands: 1 comes next.
    assert!(is_valid(c.check(&frame(1, DRIVING, 0), T)));
}

#[test]
fn angle_beyond_90_deg_is_dropped() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 9000), 0)));
    assert!(matches!(
        error(c.check(&frame(1, DRIVING, 9001), T)),
        Some(FrameError::AngleOutOfRange {
            limit: SteeringDeg(90.0),
            ..
        })
    ));
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, -9000), 0)));
    // The "not available" raw value is out of range as well.
    assert!(matches!(
        error(c.check(&frame(1, DRIVING, i16::MIN), T)),
        Some(FrameError::AngleOutOfRange { .. })
    ));
    assert_eq!(c.drops().angle_out_of_range, 1);
}

#[test]
fn a_configured_range_is_honoured() {
    let config = ProtocolConfig {
        max_angle: SteeringDeg(30.0),
        ..ProtocolConfig::DEFAULT
    };
    let mut c = E2eChecker::new(config).unwrap();
    assert!(is_valid(c.check(&frame(0, DRIVING, 3000), 0)));
    assert!(!is_valid(c.check(&frame(1, DRIVING, 3001), T)));
}

#[test]
fn step_above_4_deg_in_10_ms_is_dropped() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 1000), 0)));
    assert!(is_valid(c.check(&frame(1, DRIVING, 1400), T)));
    let Some(FrameError::RateTooHigh { step, allowed }) =
        error(c.check(&frame(2, DRIVING, 1801), 2 * T))
    else {
        panic!("a 4.01 deg step is dropped for its rate")
    };
    assert!(
        (step.0 - 4.01).abs() < 1e-5 && allowed == SteeringDeg(4.0),
        "{step:?} {allowed:?}"
    );
    assert_eq!(c.drops().rate_too_high, 1);
}

#[test]
fn early_frames_get_one_period_of_budget() {
    // Bus jitter: a sample 10 ms after the last may arrive 2 ms after it.
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    assert!(is_valid(c.check(&frame(1, DRIVING, 400), 2_000)));
    // ... but one period of budget in all, not one per early frame: a second full step that
    // early (here with a clock that steps back) is dropped.
    assert!(matches!(
        error(c.check(&frame(2, DRIVING, 800), 1_000)),
        Some(FrameError::RateTooHigh { .. })
    ));
}

#[test]
fn frames_sent_faster_than_the_period_cannot_beat_the_rate_limit() {
    // A burst beats a per-frame limit: 20 frames 1 ms apart, +4 deg each (a period's full step
    // each), must stay within the real-time window.
    let mut c = checker();
    let mut accepted = 0i16;
    for n in 0..20u8 {
        let angle = i16::from(n) * 400;
        if is_valid(c.check(&frame(n, DRIVING, angle), u64::from(n) * 1_000)) {
            accepted = angle;
        }
    }
    // 400 deg/s over the 19 ms, plus one period's 4 deg: 11.6 deg at most.
    assert!(
        accepted <= 1160,
        "moved {} deg in 19 ms",
        f32::from(accepted) / 100.0
    );
    assert_eq!(c.early_frames(), 19, "every frame but the first came early");
}

#[test]
fn rate_budget_grows_while_references_are_dropped() {
    // A 20 deg jump is dropped until 50 ms have passed since the last accepted sample.
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    for n in 1..5u8 {
        assert!(matches!(
            error(c.check(&frame(n, DRIVING, 2000), u64::from(n) * T)),
            Some(FrameError::RateTooHigh { .. })
        ));
    }
    assert!(is_valid(c.check(&frame(5, DRIVING, 2000), 5 * T)));
}

#[test]
fn timeout_after_50_ms_without_a_valid_reference() {
    let mut c = checker();
    assert!(c.timed_out(0), "no reference yet");
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 1_000)));
    assert!(!c.timed_out(51_000));
    assert!(c.timed_out(51_001));
    assert_eq!(c.since_accepted_us(21_000), Some(20_000));
}

#[test]
fn reset_forgets_counter_and_angle_but_keeps_the_counts() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    assert!(!is_valid(c.check(&frame(0, DRIVING, 0), T)));
    c.reset();
    assert!(is_valid(c.check(&frame(9, DRIVING, 8000), 2 * T)));
    assert_eq!(c.drops().stale, 1);
    assert_eq!(c.since_accepted_us(2 * T), Some(0));
}

/// Arbitrary bytes, biased so that a fair share reaches every rule: mostly the right ID and
/// length, often a fixed CRC, often the next counter and a small step.
fn arbitrary_frame() -> impl Strategy<Value = (u16, usize, [u8; 8], bool, Option<i16>, bool)> {
    (
        prop_oneof![3 => Just(0x100u16), 1 => 0u16..=0x7FF],
        prop_oneof![3 => Just(8usize), 1 => 0usize..=8],
        any::<[u8; 8]>(),
        any::<bool>(),                                  // next counter
        proptest::option::of(-700i16..700),             // small step instead of a random angle
        prop_oneof![4 => Just(true), 1 => Just(false)], // fix the CRC
    )
}

fn build(
    prev_counter: u8,
    prev_raw: i16,
    (id, len, mut bytes, next_counter, step, fix_crc): (
        u16,
        usize,
        [u8; 8],
        bool,
        Option<i16>,
        bool,
    ),
) -> Frame {
    if next_counter {
        bytes[1] = (bytes[1] & 0xF0) | ((prev_counter + 1) & 0x0F);
    }
    if let Some(step) = step {
        bytes[1] &= 0x7F; // AS state code 0..=7: mostly valid
        bytes[2..4].copy_from_slice(&prev_raw.saturating_add(step).to_le_bytes());
    }
    let id = StandardId::new(id).unwrap();
    if fix_crc {
        bytes[0] = frame_crc(id, &bytes);
    }
    Frame::new(id, &bytes[..len]).unwrap()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(100_000))]

    /// One valid-CRC frame primes the checker, then an arbitrary frame: no panic, and an
    /// accepted frame obeys every rule.
    #[test]
    fn arbitrary_frames_never_panic_and_accepted_ones_obey_every_rule(
        prev_counter in 0u8..16,
        prev_code in 0u8..8,
        prev_raw in -9500i16..9500,
        second in arbitrary_frame(),
        dt_us in 0u64..40_000,
    ) {
        let cfg = ProtocolConfig::DEFAULT;
        let mut c = E2eChecker::new(cfg).unwrap();
        let prev_valid = is_valid(c.check(&frame(prev_counter, prev_code, prev_raw), 0));
        let f = build(prev_counter, prev_raw, second);
        let decoded = cfg.decode_reference(&f);
        let verdict = c.check(&f, dt_us);

        if let E2eVerdict::Valid(r) = verdict {
            let bytes: [u8; 8] = f.data().try_into().unwrap();
            let raw = i16::from_le_bytes([bytes[2], bytes[3]]);
            prop_assert_eq!(f.id(), REFERENCE_ID);
            prop_assert_eq!(bytes[0], frame_crc(REFERENCE_ID, &bytes));
            prop_assert_eq!(r.counter.raw(), (prev_counter + 1) % 16);
            prop_assert_eq!(r.as_state.code(), bytes[1] >> 4);
            prop_assert!(i32::from(raw).abs() <= 9000);
            prop_assert_eq!(r.angle, SteeringDeg(f32::from(raw) * 0.01));
            if prev_valid {
                let budget = 40_000 * dt_us.max(T) / 1_000_000;
                prop_assert!(u64::from((i32::from(raw) - i32::from(prev_raw)).unsigned_abs()) <= budget);
            }
            prop_assert_eq!(decoded, Ok(r));
        } else {
            let run = c.invalid_in_row();
            let is_foreign = matches!(error(verdict), Some(FrameError::WrongId { .. }));
            let expected_run = u8::from(!prev_valid) + u8::from(!is_foreign);
            prop_assert_eq!(run, expected_run);
            if let Err(e @ (FrameError::WrongId { .. } | FrameError::WrongLength { .. } | FrameError::Crc { .. })) = decoded {
                // The decoder's frame-level reasons come first in the checker too.
                prop_assert_eq!(error(verdict), Some(e));
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2_000))]

    /// Streams of 40 mutated frames: the counter, rate and fault rules hold across a history.
    #[test]
    fn streams_keep_the_rules_across_history(
        frames in proptest::collection::vec((arbitrary_frame(), 0u64..25_000), 40),
    ) {
        let mut c = checker();
        let mut last_seen: Option<u8> = None; // counter of the last frame with a good CRC
        let mut last_accepted: Option<(i16, u64)> = None;
        let mut run = 0u8;
        let mut now = 0u64;
        let mut seen_raw = 0i16;
        for (spec, dt) in frames {
            now += dt;
            let f = build(last_seen.unwrap_or(0), seen_raw, spec);
            let bytes = f.data();
            let crc_ok = f.id() == REFERENCE_ID
                && bytes.len() == 8
                && bytes[0] == frame_crc(REFERENCE_ID, bytes.try_into().unwrap());
            let verdict = c.check(&f, now);
            match verdict {
                E2eVerdict::Valid(r) => {
                    prop_assert!(crc_ok);
                    let raw = i16::from_le_bytes([bytes[2], bytes[3]]);
                    if let Some(seen) = last_seen {
                        prop_assert_eq!(r.counter.raw(), (seen + 1) % 16);
                    }
                    prop_assert!(i32::from(raw).abs() <= 9000);
                    if let Some((prev, at)) = last_accepted {
                        let budget = 40_000 * now.saturating_sub(at).max(T) / 1_000_000;
                        prop_assert!(u64::from((i32::from(raw) - i32::from(prev)).unsigned_abs()) <= budget);
                    }
                    last_accepted = Some((raw, now));
                    seen_raw = raw;
                    run = run.saturating_sub(1);
                }
                E2eVerdict::Dropped { error, invalid_in_row } | E2eVerdict::Fault { error, invalid_in_row } => {
                    if !matches!(error, FrameError::WrongId { .. }) {
                        run = run.saturating_add(1).min(5);
                    }
                    prop_assert_eq!(invalid_in_row, run);
                    prop_assert_eq!(matches!(verdict, E2eVerdict::Fault { .. }), run >= 5);
                }
            }
            if crc_ok {
                last_seen = Some(bytes[1] & 0x0F);
            }
        }
    }
}

// The tests below kill what `.ci/mutation.sh` found missed in e2e.rs.

/// The accessors say what the checker holds.
#[test]
fn the_invalid_total_sums_every_reason_but_foreign_ids() {
    let d = DropCounters {
        wrong_id: 1000,
        wrong_length: 1,
        crc: 2,
        stale: 4,
        counter_jump: 8,
        unknown_as_state: 16,
        angle_out_of_range: 32,
        rate_too_high: u16::MAX,
    };
    assert_eq!(d.invalid_total(), 63 + u32::from(u16::MAX));
}

#[test]
fn the_checker_keeps_the_configuration_it_was_given() {
    let config = ProtocolConfig {
        max_invalid_in_row: 9,
        max_rate_deg_per_s: 250.0,
        ..ProtocolConfig::DEFAULT
    };
    let c = E2eChecker::new(config).unwrap();
    assert_eq!(c.config().max_invalid_in_row, 9);
    assert_eq!(c.config().max_rate_deg_per_s, 250.0);
}

#[test]
fn a_frame_is_early_only_when_it_comes_within_half_a_period() {
    let mut c = checker();
    // Gaps after the first frame, us: half a period is not early, just under it is.
    let mut t = 0;
    let mut early = Vec::new();
    for (n, gap) in [0u64, 4_999, 5_000, 6_000, 10_000, 1]
        .into_iter()
        .enumerate()
    {
        t += gap;
        let _ = c.check(&frame(n as u8, DRIVING, 0), t);
        early.push(c.early_frames());
    }
    assert_eq!(early, [0, 1, 1, 1, 1, 2]);
}

/// The real-time window restarts at the last accepted value once its anchor is 250 ms old, so a
/// burst after a long quiet stretch is judged against the recent past, not against an anchor
/// whose age would allow a hundred degrees.
#[test]
fn a_burst_right_after_the_window_restarts_is_held_to_the_rate() {
    let mut c = checker();
    let mut n = 0u8;
    for k in 0..=24u64 {
        assert!(is_valid(c.check(&frame(n, DRIVING, 0), k * T)), "hold {k}");
        n = n.wrapping_add(1);
    }
    // From 250 ms (the anchor at 0 is exactly 250 ms old): +3.9 deg every 1 ms, each step
    // within the per-frame budget (4 deg for anything up to one period).
    let mut accepted_deg = 0.0;
    for k in 0..10u64 {
        let angle = 390 * (k as i16 + 1);
        if let E2eVerdict::Valid(r) = c.check(&frame(n, DRIVING, angle), 250_000 + k * 1_000) {
            accepted_deg = r.angle.0;
        }
        n = n.wrapping_add(1);
    }
    // Against the anchor at 240 ms: 400 deg/s x (elapsed + one period) allows 8 to 12 deg.
    assert!(
        accepted_deg <= 12.0,
        "the burst reached {accepted_deg} deg within 10 ms"
    );
    assert!(accepted_deg >= 3.9, "the first step is within the rate");
}

#[test]
fn the_window_allows_exactly_the_rate_times_elapsed_plus_one_period() {
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    // 1 ms later: 4.00 deg of the 4.40 the window allows.
    assert!(is_valid(c.check(&frame(1, DRIVING, 400), 1_000)));
    // 2 ms: 400 deg/s x (2 + 10) ms = 4.80 deg from the anchor, exactly what this frame moved.
    assert!(is_valid(c.check(&frame(2, DRIVING, 480), 2_000)));
    // One hundredth of a degree more is refused.
    assert!(matches!(
        error(c.check(&frame(3, DRIVING, 521), 3_000)),
        Some(FrameError::RateTooHigh { .. })
    ));
}

/// At exactly 250 ms the window restarts at the last accepted value (the frame at 240 ms), not
/// at the frame being judged one frame later: the next frames are measured from 240 ms.
#[test]
fn the_window_restarts_when_its_anchor_is_exactly_250_ms_old() {
    let mut c = checker();
    let mut n = 0u8;
    let mut send = |c: &mut E2eChecker, angle_raw: i16, t: u64| {
        let v = c.check(&frame(n, DRIVING, angle_raw), t);
        n = n.wrapping_add(1);
        v
    };
    for k in 0..=24u64 {
        assert!(is_valid(send(&mut c, 0, k * T)), "hold {k}");
    }
    assert!(is_valid(send(&mut c, -400, 250_000)), "4 deg down");
    assert!(is_valid(send(&mut c, 0, 251_000)), "back");
    // 4 deg from 0 deg at 240 ms, 12 ms ago: 400 deg/s x 22 ms allows 8.8.
    assert!(is_valid(send(&mut c, 400, 252_000)), "4 deg up");
}

/// The AS state of a frame that passes the CRC is the sender's word whatever
/// its counter (a jump after a lost frame, a repeat); a frame that fails the CRC, or carries
/// an unknown code, gives none.
#[test]
fn a_crc_good_frame_gives_its_as_state_whatever_its_counter() {
    const EMERGENCY: u8 = 3;
    let mut c = checker();
    assert!(is_valid(c.check(&frame(0, DRIVING, 0), 0)));
    assert_eq!(c.authentic_as_state(), Some(AsState::Driving));
    // Counter 1 lost: 2 jumps.
    let v = c.check(&frame(2, EMERGENCY, 0), T);
    assert!(
        matches!(error(v), Some(FrameError::Counter { .. })),
        "{v:?}"
    );
    assert_eq!(c.authentic_as_state(), Some(AsState::Emergency));
    // A repeat of counter 2.
    let v = c.check(&frame(2, EMERGENCY, 0), 2 * T);
    assert!(matches!(error(v), Some(FrameError::Stale { .. })), "{v:?}");
    assert_eq!(c.authentic_as_state(), Some(AsState::Emergency));
    // An unknown code (with a good counter) and a bad CRC give nothing.
    let v = c.check(&frame(3, 9, 0), 3 * T);
    assert!(matches!(
        error(v),
        Some(FrameError::UnknownAsState { code: 9 })
    ));
    assert_eq!(c.authentic_as_state(), None);
    let good = frame(4, EMERGENCY, 0);
    let mut bytes: [u8; 8] = good.data().try_into().unwrap();
    bytes[0] ^= 0x01;
    let v = c.check(&Frame::new(REFERENCE_ID, &bytes).unwrap(), 4 * T);
    assert!(matches!(error(v), Some(FrameError::Crc { .. })));
    assert_eq!(c.authentic_as_state(), None);
    // An unknown code with a jumped counter is still reported as the counter's failure.
    let v = c.check(&frame(9, 9, 0), 5 * T);
    assert!(
        matches!(error(v), Some(FrameError::Counter { .. })),
        "{v:?}"
    );
    assert_eq!(c.authentic_as_state(), None);
}

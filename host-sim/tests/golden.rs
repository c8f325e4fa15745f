//! The golden vectors in `hil-tests/vectors` are what this code computes now: the emulated
//! suite (`cd hil-tests && cargo emulate`) compares the Cortex-M4F against them, so stale files
//! would blame the target for a change made here.

use golden_vectors::loops::{self, NoMeter, Verdict};
use host_sim::golden;
use std::path::Path;

const REGENERATE: &str = "regenerate with `cargo run --release -p host-sim -- golden --write \
                          hil-tests/vectors` and commit the files";

#[test]
fn stored_golden_vectors_are_current() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(golden::DIR);
    let fresh = golden::generate().expect("the golden runs start");
    for v in &fresh {
        let path = dir.join(v.name);
        let stored = std::fs::read(&path)
            .unwrap_or_else(|e| panic!("{}: {e}; {REGENERATE}", path.display()));
        assert!(
            stored == v.bytes,
            "{} is stale ({} B stored, {} B now); {REGENERATE}",
            path.display(),
            stored.len(),
            v.bytes.len()
        );
    }
}

#[test]
fn golden_loops_replay_bit_exact_on_the_host() {
    // The replay builds its cascade from the header as host-sim's run does; if the two drift
    // apart, this fails here rather than on the target.
    for v in golden::generate().expect("the golden runs start") {
        if v.name == "cases.bin" {
            let differing = golden_vectors::cases::check(&v.bytes, &mut |g, r, _| {
                assert_eq!(r.differing, 0, "{}", g.name());
            })
            .expect("cases file readable");
            assert_eq!(differing, 0);
            continue;
        }
        let report = loops::replay(&v.bytes, &mut NoMeter, None).expect("loop file readable");
        assert_eq!(
            report.verdict(),
            Verdict::BitExact,
            "{}: {report:?}",
            v.name
        );
        // Every period replayed whole: 20 position and 200 current steps (the shortest window,
        // ECU mode on the track, is 25 periods).
        assert!(report.periods >= 25, "{}: {report:?}", v.name);
        assert_eq!(report.current_steps, 200 * report.periods, "{}", v.name);
    }
}

#[test]
fn a_corrupted_vector_is_caught() {
    let sweep = golden::generate()
        .expect("the golden runs start")
        .into_iter()
        .find(|v| v.name == "sweep.bin")
        .expect("a sweep file");
    let tamper = loops::Tamper {
        current_step: 5_000,
    };
    let report = loops::replay(&sweep.bytes, &mut NoMeter, Some(tamper)).expect("readable");
    assert_eq!(report.verdict(), Verdict::Differs);
    assert_eq!(report.differing, 1);
    let cut = &sweep.bytes[..sweep.bytes.len() - 1];
    assert!(loops::replay(cut, &mut NoMeter, None).is_err());
}

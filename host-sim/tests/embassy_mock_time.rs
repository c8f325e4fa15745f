//! The firmware's way of running (Embassy tasks, timers) works on the host in virtual time:
//! a ticker task sees exact 10 ms steps while the harness advances the mock clock.
//! Own test binary: the mock clock and the task pool are global to the process.

use embassy_executor::{Executor, Spawner};
use embassy_time::{Duration, Instant, MockDriver, Ticker};
use std::sync::Mutex;

static STAMPS: Mutex<Vec<u64>> = Mutex::new(Vec::new());

#[embassy_executor::task]
async fn ticker_100hz() {
    let mut ticker = Ticker::every(Duration::from_millis(10));
    loop {
        STAMPS
            .lock()
            .map(|mut v| v.push(Instant::now().as_micros()))
            .ok();
        ticker.next().await;
    }
}

/// Always ready, so the executor polls again after every time step instead of sleeping.
#[embassy_executor::task]
async fn keep_awake() {
    loop {
        embassy_futures::yield_now().await;
    }
}

#[test]
fn ticker_task_runs_in_exact_virtual_time() {
    MockDriver::get().reset();
    let executor: &'static mut Executor = Box::leak(Box::new(Executor::new()));
    let mut steps = 0u32;
    executor.run_until(
        |spawner: Spawner| {
            spawner.spawn(ticker_100hz().expect("task pool"));
            spawner.spawn(keep_awake().expect("task pool"));
        },
        || {
            // 50 us per round: the current-loop period, where the plant would step.
            MockDriver::get().advance(Duration::from_micros(50));
            steps += 1;
            steps >= 2_000 // 100 ms of virtual time
        },
    );
    let stamps = STAMPS.lock().map(|v| v.clone()).unwrap_or_default();
    assert_eq!(&stamps[..5], &[0, 10_000, 20_000, 30_000, 40_000]);
    assert!(stamps.len() >= 10, "{stamps:?}");
}

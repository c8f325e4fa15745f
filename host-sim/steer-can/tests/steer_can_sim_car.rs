//! One simulated car across separate `steer-can` calls (`sim-car --socket PATH`, attached with
//! `--iface sim:PATH`), as processes: a fault one call leaves is seen and cleared by the next,
//! and a `record` running beside a `send` records the reference frames the send puts on the
//! bus. The car keeps to the wall clock, so this test takes a few seconds.
#![cfg(all(unix, feature = "sim"))]
#![allow(clippy::unwrap_used)] // a failed unwrap is a failed test

use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// The car's process, ended when the test ends however it ends.
struct Car(Child);

impl Drop for Car {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `steer-can --iface sim:SOCKET` with `args` as one would type them.
fn steer_can(socket: &Path, args: &str) -> Output {
    Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .arg("--iface")
        .arg(format!("sim:{}", socket.display()))
        .args(args.split_whitespace())
        .stdin(Stdio::null())
        .output()
        .unwrap()
}

/// `steer-can sim-car --socket SOCKET`, once its socket is there.
fn start_car(socket: &Path) -> Car {
    let car = Car(Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .args(["sim-car", "--socket"])
        .arg(socket)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap());
    let started = Instant::now();
    while !socket.exists() {
        assert!(started.elapsed() < Duration::from_secs(10), "no socket");
        std::thread::sleep(Duration::from_millis(20));
    }
    car
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

#[test]
fn calls_share_one_car_and_a_record_sees_another_calls_frames() {
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("car.sock");
    let _car = start_car(&socket);

    // The README's step 5 across three calls.
    let o = steer_can(
        &socket,
        "send --as-state driving --no-finish step --amplitude-deg 0 --duration-s 0.3",
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = steer_can(&socket, "monitor --duration-s 0.3");
    assert!(o.status.success());
    assert!(
        stdout(&o).contains("state faulted, faults: reference timeout"),
        "the fault the previous call left: {}",
        stdout(&o)
    );
    let o = steer_can(&socket, "send clear-faults");
    assert!(
        stdout(&o).contains("state idle, faults: none"),
        "{}",
        stdout(&o)
    );

    // A record beside a send. The record outlasts the send by seconds and gets most of a
    // second to attach first: on a loaded machine (a CI run beside a selftest) a 2 s record
    // started 0.3 s ahead missed three of the send's frames.
    let file = dir.path().join("bus.candump");
    let record = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .arg("--iface")
        .arg(format!("sim:{}", socket.display()))
        .args(["record", "--duration-s", "5", "--out"])
        .arg(&file)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    std::thread::sleep(Duration::from_millis(800));
    let o = steer_can(
        &socket,
        "send --as-state driving step --amplitude-deg 3 --duration-s 1",
    );
    assert!(o.status.success());
    let recorded = record.wait_with_output().unwrap();
    assert!(recorded.status.success());
    let text = std::fs::read_to_string(&file).unwrap();
    let references = text.lines().filter(|l| l.contains(" 100#")).count();
    // 1 s of step at 100 Hz and 0.2 s of AS Finished, all inside the 5 s recording.
    assert_eq!(references, 101 + 20, "{text:.300}");
    let log = dir.path().join("log.csv");
    let o = Command::new(env!("CARGO_BIN_EXE_steer-can"))
        .arg("convert")
        .arg(&file)
        .arg("--out")
        .arg(&log)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    // The log's rows are the send's AS Driving periods: they end with the wheel on the step.
    let rows = host_io::logfmt::Log::load(&log).unwrap();
    assert!((95..=101).contains(&rows.len()), "{} rows", rows.len());
    let end = rows.sw_deg.last().copied().unwrap();
    assert!((end - 3.0).abs() < 0.5, "the wheel at the end: {end} deg");
}

#[test]
fn attaching_to_no_car_says_how_to_start_one() {
    let dir = tempfile::tempdir().unwrap();
    let o = steer_can(&dir.path().join("none.sock"), "monitor --duration-s 0.1");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("steer-can sim-car --socket"), "{err}");
}

/// Two `send` calls one after the other on one car, as two processes on `can0` would be: the
/// second continues the reference counter the ECU last saw, so the ECU's E2E check counts no
/// counter jump at its first frame.
#[test]
fn a_second_send_call_continues_the_counter_the_ecu_last_saw() {
    let dir = tempfile::tempdir().unwrap();
    let socket = dir.path().join("car.sock");
    let _car = start_car(&socket);
    for _ in 0..2 {
        let o = steer_can(
            &socket,
            "send --as-state driving step --amplitude-deg 1 --duration-s 0.3",
        );
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    }
    // One round of the diagnostic frame (0x103) brings the drop counters.
    let o = steer_can(&socket, "monitor --duration-s 0.5");
    assert!(o.status.success());
    let text = stdout(&o);
    assert!(
        text.contains("dropped: counter jump 0,"),
        "the ECU counted a counter jump: {text}"
    );
}

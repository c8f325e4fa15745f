//! One simulated car for several `steer-can` calls: `steer-can sim-car --socket PATH` runs the
//! car (as `--iface sim` does, held to the wall clock) and serves its bus on a Unix socket;
//! `--iface sim:PATH` attaches a command to it. So a fault one call leaves is still there for
//! the next, and a `record` in one terminal sees what a `send` in another puts on the bus, as
//! two sockets on `can0` would.
//!
//! The wire is text, one candump line per frame with the car's time (`(s.us) sim ID#DATA`,
//! epoch 0), plus a bare time stamp `(s.us)` every millisecond of the car's time so a client
//! waiting for a deadline knows the time has come. A client's lines are frames it puts on the
//! bus; the car stamps them with its own time and echoes them to the other clients.

use super::candump::{format_line, parse_frame_line};
use super::{BringupError, Clock, LinkError, Stamped, Transport};
use host_sim::sim_ecu::SimEcu;
use std::io::{BufRead, BufReader, Write};
use std::os::unix::net::{UnixListener, UnixStream};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::{Duration, Instant};
use steering_ecu::can::Frame;

/// The car's clock reaches its clients in steps of this, µs.
pub const BEACON_US: u64 = 1_000;
/// A client that cannot take a line for this long is dropped (it stopped reading).
const WRITE_TIMEOUT: Duration = Duration::from_millis(200);
/// A client hears from the car at least every millisecond; silence this long means it is gone.
const READ_TIMEOUT: Duration = Duration::from_secs(2);

fn io(context: String) -> impl FnOnce(std::io::Error) -> LinkError {
    move |source| LinkError::Io { context, source }
}

fn beacon(t_us: u64) -> String {
    format!("({}.{:06})\n", t_us / 1_000_000, t_us % 1_000_000)
}

fn frame_line(stamped: &Stamped) -> String {
    let mut line = format_line(0.0, "sim", stamped);
    line.push('\n');
    line
}

/// Serves `sim` on `socket` until `stop` is raised; removes the socket file at the end.
pub fn serve(mut sim: SimEcu, socket: &Path, stop: &AtomicBool) -> Result<(), BringupError> {
    if UnixStream::connect(socket).is_ok() {
        return Err(BringupError::Usage {
            reason: format!("{}: a simulated car already serves there", socket.display()),
        });
    }
    // A file left by a car that was killed: nobody answers on it.
    let _ = std::fs::remove_file(socket);
    let listener =
        UnixListener::bind(socket).map_err(io(format!("cannot listen on {}", socket.display())))?;
    listener
        .set_nonblocking(true)
        .map_err(io(format!("{}", socket.display())))?;
    eprintln!(
        "simulated car on {}: attach with `steer-can --iface sim:{} <command>`; Ctrl-C stops it",
        socket.display(),
        socket.display()
    );
    let result = serve_on(&mut sim, &listener, stop);
    let _ = std::fs::remove_file(socket);
    result
}

struct Client {
    id: usize,
    writer: UnixStream,
}

fn serve_on(
    sim: &mut SimEcu,
    listener: &UnixListener,
    stop: &AtomicBool,
) -> Result<(), BringupError> {
    let started = Instant::now();
    let (tx, rx) = mpsc::channel::<(usize, Frame)>();
    let mut clients: Vec<Client> = Vec::new();
    let mut next_id = 0;
    while !stop.load(Ordering::SeqCst) {
        // New clients: a reader thread each hands their frames to this loop.
        while let Ok((stream, _)) = listener.accept() {
            let id = next_id;
            next_id += 1;
            let writer = match stream.try_clone() {
                Ok(w) => w,
                Err(_) => continue,
            };
            let _ = writer.set_write_timeout(Some(WRITE_TIMEOUT));
            let tx = tx.clone();
            std::thread::spawn(move || {
                for line in BufReader::new(stream).lines() {
                    let Ok(line) = line else { break };
                    // A line that is not a frame is the client's mistake: ignored, as a bus
                    // ignores garbage, and said once on the car's terminal.
                    match parse_frame_line(&line) {
                        Ok(Some((_, frame))) => {
                            if tx.send((id, frame)).is_err() {
                                break;
                            }
                        }
                        Ok(None) => {}
                        Err(e) => eprintln!("sim-car: client {id}: `{line}`: {e}"),
                    }
                }
            });
            let mut client = Client { id, writer };
            if client
                .writer
                .write_all(beacon(sim.now_us()).as_bytes())
                .is_ok()
            {
                clients.push(client);
            }
        }
        // Frames from clients: onto the bus now, and to the other clients.
        while let Ok((from, frame)) = rx.try_recv() {
            sim.send(&frame)?;
            let line = frame_line(&Stamped {
                t_us: sim.now_us(),
                frame,
            });
            clients.retain_mut(|c| c.id == from || c.writer.write_all(line.as_bytes()).is_ok());
        }
        // The car up to the wall clock, a millisecond at a time.
        let wall = u64::try_from(started.elapsed().as_micros()).unwrap_or(u64::MAX);
        if sim.now_us() + BEACON_US > wall {
            std::thread::sleep(Duration::from_micros(300));
            continue;
        }
        let until = sim.now_us() + BEACON_US;
        let mut out = String::new();
        while let Some(rx) = sim.recv_until(until)? {
            out.push_str(&frame_line(&rx));
        }
        out.push_str(&beacon(sim.now_us()));
        clients.retain_mut(|c| c.writer.write_all(out.as_bytes()).is_ok());
    }
    Ok(())
}

/// A command's end of a served car (`--iface sim:PATH`).
#[derive(Debug)]
pub struct SimSocket {
    name: String,
    reader: BufReader<UnixStream>,
    writer: UnixStream,
    now_us: u64,
    line: String,
}

impl SimSocket {
    pub fn connect(socket: &Path) -> Result<SimSocket, LinkError> {
        // Not a CAN interface: `ip link` cannot help, a car served on the socket can.
        let no_car = |source: std::io::Error| LinkError::Io {
            context: format!(
                "--iface sim:{0}: no simulated car serves this socket; start one in another \
                 terminal with `steer-can sim-car --socket {0}`, or use `--iface sim` for a car \
                 of this call alone",
                socket.display()
            ),
            source,
        };
        let stream = UnixStream::connect(socket).map_err(no_car)?;
        stream
            .set_read_timeout(Some(READ_TIMEOUT))
            .map_err(no_car)?;
        let writer = stream.try_clone().map_err(no_car)?;
        let mut s = SimSocket {
            name: format!("sim:{}", PathBuf::from(socket).display()),
            reader: BufReader::new(stream),
            writer,
            now_us: 0,
            line: String::new(),
        };
        // The car's time comes first.
        s.read_one()?;
        Ok(s)
    }

    /// One line from the car: a frame, or `None` for a time stamp.
    fn read_one(&mut self) -> Result<Option<Stamped>, LinkError> {
        self.line.clear();
        let n = self
            .reader
            .read_line(&mut self.line)
            .map_err(io(format!("{}: the simulated car is silent", self.name)))?;
        if n == 0 {
            return Err(LinkError::NoInterface {
                iface: self.name.clone(),
                detail: "the simulated car stopped".into(),
            });
        }
        let line = self.line.trim();
        let bad = |m: String| LinkError::Io {
            context: format!("{}: `{line}`", self.name),
            source: std::io::Error::new(std::io::ErrorKind::InvalidData, m),
        };
        if !line.contains(' ') {
            let t_s: f64 = line
                .trim_start_matches('(')
                .trim_end_matches(')')
                .parse()
                .map_err(|_| bad("not a time stamp".into()))?;
            self.now_us = self.now_us.max((t_s * 1e6).round() as u64);
            return Ok(None);
        }
        match parse_frame_line(line).map_err(bad)? {
            Some((t_s, frame)) => {
                let t_us = (t_s * 1e6).round() as u64;
                self.now_us = self.now_us.max(t_us);
                Ok(Some(Stamped { t_us, frame }))
            }
            None => Ok(None),
        }
    }
}

impl Clock for SimSocket {
    fn now_us(&self) -> u64 {
        self.now_us
    }
}

impl Transport for SimSocket {
    fn send(&mut self, frame: &Frame) -> Result<(), LinkError> {
        let line = frame_line(&Stamped {
            t_us: self.now_us,
            frame: *frame,
        });
        self.writer
            .write_all(line.as_bytes())
            .map_err(io(format!("{}: cannot send", self.name)))
    }

    fn recv_until(&mut self, deadline_us: u64) -> Result<Option<Stamped>, LinkError> {
        // Lines already read come first, even past the deadline.
        while self.now_us < deadline_us || !self.reader.buffer().is_empty() {
            if let Some(rx) = self.read_one()? {
                return Ok(Some(rx));
            }
        }
        Ok(None)
    }

    fn name(&self) -> &str {
        &self.name
    }

    fn epoch_s(&self) -> f64 {
        host_sim::sim_ecu::EPOCH_S
    }
}

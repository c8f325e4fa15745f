//! candump log files (can-utils `candump -l`): `(1700000000.123456) can0 101#0011223344556677`,
//! one frame a line. Read with line numbers in every error, written in the same form, so
//! `steer-can record` files open in can-utils, SavvyCAN and cantools, and candump files from
//! the car convert to the project's log format.
//!
//! Only what this bus carries is kept: classic data frames with 11-bit IDs. Extended IDs,
//! remote frames and CAN FD frames are valid candump but not ours: they are skipped and
//! counted, not errors.
//!
//! What other tools write for `candump -l` files is read too: the direction ` R`/` T` after
//! the frame (`candump -l -x`, python-can's `CanutilsLogWriter`), a raw DLC above 8
//! (`123#0011223344556677_9`), `candump -ta`'s spelled-out `123 [2] 01 02`, SavvyCAN's
//! zero-padded relative stamps (`(0000000003.800000) vcan0 ...`), the `DROPCOUNT:` lines
//! candump writes when its socket lost frames (counted, and said), CRLF line ends and a UTF-8
//! byte-order mark. Hand-written rather than the `socketcan` crate's `dump` parser: that one is
//! a dependency on Linux only, and `convert` runs on any laptop.

use super::{BringupError, Stamped};
use host_io::lines::Capped;
use std::io::{BufRead, Write};
use std::path::Path;
use steering_ecu::can::{Frame, StandardId};

/// A candump file as frames with µs times relative to its first line.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct CandumpFile {
    /// Unix time of the first frame, s.
    pub epoch_s: f64,
    pub frames: Vec<Stamped>,
    /// Lines that are valid candump but not classic 11-bit data frames.
    pub skipped: usize,
    /// Frames dropped because they were stamped more than [`BACKWARDS_TOLERANCE_S`] before the
    /// latest frame kept, and the line of the first of them.
    pub dropped_backwards: usize,
    pub first_dropped_line: Option<usize>,
    /// Frames candump's socket lost while recording (its `DROPCOUNT:` lines), and the line of
    /// the first such report.
    pub socket_drops: u64,
    pub first_drop_report_line: Option<usize>,
}

/// The longest candump line read, bytes: a CAN FD frame with 64 data bytes takes under 200; a
/// file without a line end for longer is not a candump log and is refused at once, not read
/// whole.
pub const MAX_LINE_BYTES: usize = 4096;

/// The most frames a candump file may hold for `convert`, which keeps them all in memory (tens
/// of bytes each, and the log built from them): over 20 min of a full 1 Mbit/s bus (about
/// 7,700 frames/s), hours of the car's bus. A longer recording is refused at the frame past
/// it, not read on; its parts (`split -l 10000000 FILE`) convert one by one.
pub const MAX_FRAMES: usize = 10_000_000;

/// How far a frame may be stamped before the one read just before it and still be kept (at the
/// later time). One socket's stamps never go back, but a file merged from two captures can
/// jitter by a little; a frame a second back is out of place, and clamping it would move it
/// and everything it carries, so it is dropped and counted instead.
pub const BACKWARDS_TOLERANCE_S: f64 = 1e-3;

/// The latest time stamp a candump line may carry: year 2286 in Unix time. `candump -l` writes
/// Unix time; a stamp beyond this is garbage, and it would leave every later frame "before" it.
pub const LATEST_STAMP_S: f64 = 1e10;

/// One parsed line.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Line {
    Frame { t_s: f64, frame: Frame },
    NotOurs,
}

fn parse_line(line: &str) -> Result<Line, String> {
    let mut parts = line.split_whitespace();
    let stamp = parts.next().ok_or_else(|| "empty line".to_string())?;
    let seconds = stamp
        .strip_prefix('(')
        .and_then(|s| s.strip_suffix(')'))
        .ok_or_else(|| {
            format!("expected a time stamp like (1700000000.123456), found `{stamp}`")
        })?;
    let t_s: f64 = seconds
        .parse()
        .ok()
        .filter(|t: &f64| t.is_finite())
        .ok_or_else(|| format!("time stamp `{seconds}` is not a number of seconds"))?;
    if !(0.0..=LATEST_STAMP_S).contains(&t_s) {
        return Err(format!(
            "time stamp `{seconds}` is not a Unix time in seconds (0 to {LATEST_STAMP_S:e})"
        ));
    }
    let _iface = parts
        .next()
        .ok_or_else(|| "missing interface name after the time stamp".to_string())?;
    let body = parts
        .next()
        .ok_or_else(|| "missing frame `ID#DATA` after the interface name".to_string())?;
    let rest: Vec<&str> = parts.collect();
    let spelled;
    let (id_hex, data_hex, after) = match body.split_once('#') {
        Some((id, data)) => (id, data, &rest[..]),
        None => match rest.first().and_then(|d| spelled_out_len(d)) {
            // `candump -ta`'s `ID [LEN] B0 B1 ...`: the data as pairs, written here as
            // candump -l would.
            Some(len) if rest.len() > len && rest[1..=len].iter().all(|b| b.len() == 2) => {
                spelled = rest[1..=len].concat();
                (body, spelled.as_str(), &rest[len + 1..])
            }
            Some(len) => {
                return Err(format!(
                    "frame `{body} [{len}]` needs {len} data bytes as pairs of hex digits"
                ));
            }
            None => return Err(format!("frame `{body}` has no `#` between ID and data")),
        },
    };
    match after {
        [] => {}
        // The direction: received or transmitted by the recording host (`candump -x`,
        // python-can). Either way the frame was on the bus.
        [dir] if dir.eq_ignore_ascii_case("R") || dir.eq_ignore_ascii_case("T") => {}
        [extra, ..] => return Err(format!("unexpected `{extra}` after the frame")),
    }
    if id_hex.is_empty() || !id_hex.chars().all(|c| c.is_ascii_hexdigit()) {
        return Err(format!("ID `{id_hex}` is not hexadecimal"));
    }
    if data_hex.starts_with('#') || data_hex.starts_with('R') || id_hex.len() == 8 {
        // CAN FD (`##`), remote frame (`#R`), extended ID (8 digits): valid, not ours.
        return Ok(Line::NotOurs);
    }
    if id_hex.len() != 3 {
        return Err(format!(
            "ID `{id_hex}` must have 3 hex digits (11-bit) or 8 (29-bit)"
        ));
    }
    let raw = u16::from_str_radix(id_hex, 16).map_err(|e| format!("ID `{id_hex}`: {e}"))?;
    let id = StandardId::new(raw).ok_or_else(|| format!("ID 0x{raw:03X} is above 0x7FF"))?;
    let mut data_hex: String = data_hex.chars().filter(|c| *c != '.').collect();
    // A raw DLC of 9 to 15 after 8 bytes (`_9`..`_F`): still 8 bytes of data.
    if data_hex.len() == 18
        && data_hex.as_bytes()[16] == b'_'
        && matches!(data_hex.as_bytes()[17], b'9' | b'A'..=b'F' | b'a'..=b'f')
    {
        data_hex.truncate(16);
    }
    if !data_hex.len().is_multiple_of(2) || data_hex.len() > 16 {
        return Err(format!(
            "data `{data_hex}` must be 0 to 8 bytes as pairs of hex digits"
        ));
    }
    let mut data = Vec::with_capacity(8);
    for i in (0..data_hex.len()).step_by(2) {
        let pair = &data_hex[i..i + 2];
        data.push(
            u8::from_str_radix(pair, 16).map_err(|_| format!("data byte `{pair}` is not hex"))?,
        );
    }
    let frame = Frame::new(id, &data).ok_or_else(|| "more than 8 data bytes".to_string())?;
    Ok(Line::Frame { t_s, frame })
}

/// `[LEN]` of `candump -ta`'s spelled-out frames, 0 to 8.
fn spelled_out_len(word: &str) -> Option<usize> {
    let len: usize = word.strip_prefix('[')?.strip_suffix(']')?.parse().ok()?;
    (len <= 8).then_some(len)
}

/// The frames a `DROPCOUNT: dropped N CAN frame(s) on 'can0' socket (total drops M)` line
/// reports, if the line is one.
fn drop_report(line: &str) -> Option<Result<u64, String>> {
    let rest = line.trim_start().strip_prefix("DROPCOUNT:")?;
    let n = rest
        .split_whitespace()
        .nth(1)
        .and_then(|w| w.parse().ok())
        .ok_or_else(|| format!("`{}`: no frame count after `dropped`", line.trim()));
    Some(n)
}

/// One candump line read as a classic 11-bit data frame and its time stamp, s; `Ok(None)` for
/// a valid line that is not such a frame (CAN FD, remote, extended ID).
pub fn parse_frame_line(line: &str) -> Result<Option<(f64, Frame)>, String> {
    Ok(match parse_line(line)? {
        Line::Frame { t_s, frame } => Some((t_s, frame)),
        Line::NotOurs => None,
    })
}

/// Reads a candump log, plain or gzip-compressed (recognised by content, so `.candump.gz`
/// works); blank lines are skipped, anything else malformed is an error naming the file and
/// the line.
pub fn read(path: &Path) -> Result<CandumpFile, BringupError> {
    let file = std::fs::File::open(path).map_err(|source| BringupError::Io {
        context: format!("cannot open candump file {}", path.display()),
        source,
    })?;
    let mut reader = std::io::BufReader::new(file);
    let head = reader.fill_buf().map_err(|source| BringupError::Io {
        context: format!("cannot read candump file {}", path.display()),
        source,
    })?;
    let (is_gzip, is_blf) = (head.starts_with(&[0x1f, 0x8b]), head.starts_with(BLF_MAGIC));
    if is_blf {
        return Err(BringupError::Candump {
            path: path.to_path_buf(),
            line: 1,
            message: "a Vector BLF log (binary), not a candump one; `can_logconvert FILE.blf \
                      FILE.log` (python-can) writes one"
                .to_string(),
        });
    }
    if is_gzip {
        let unpacked = std::io::BufReader::new(flate2::read::MultiGzDecoder::new(reader));
        read_from(unpacked, path).map_err(|e| match e {
            BringupError::Io { context, source }
                if source.kind() == std::io::ErrorKind::UnexpectedEof =>
            {
                BringupError::Io {
                    context: format!(
                        "{context}: truncated gzip (the file ends before its compressed data \
                         does)"
                    ),
                    source,
                }
            }
            e => e,
        })
    } else {
        read_from(reader, path)
    }
}

/// As [`read`], from any reader; `path` names it in errors.
pub fn read_from(reader: impl BufRead, path: &Path) -> Result<CandumpFile, BringupError> {
    read_at_most(reader, path, MAX_FRAMES)
}

/// As [`read_from`], refusing a file with more than `max_frames` frames (skipped lines do not
/// count) at the first frame past them.
fn read_at_most(
    reader: impl BufRead,
    path: &Path,
    max_frames: usize,
) -> Result<CandumpFile, BringupError> {
    let mut out = CandumpFile::default();
    let mut first: Option<f64> = None;
    let mut latest_s = f64::NEG_INFINITY;
    let mut last_us = 0u64;
    let mut reader = reader;
    let mut text = String::new();
    for line_no in 1.. {
        let err = |message: String| BringupError::Candump {
            path: path.to_path_buf(),
            line: line_no,
            message,
        };
        let read = host_io::lines::read_line_capped(&mut reader, &mut text, MAX_LINE_BYTES)
            .map_err(|source| BringupError::Io {
                context: format!("{}:{line_no}", path.display()),
                source,
            })?;
        match read {
            Capped::End => break,
            Capped::TooLong => {
                return Err(err(format!(
                    "longer than {MAX_LINE_BYTES} bytes: not a candump log (a binary file, or \
                     no line ends?); nothing past it was read"
                )));
            }
            Capped::Line => {}
        }
        // A byte-order mark from an editor or a Windows tool.
        let line = if line_no == 1 {
            text.trim_start_matches('\u{feff}')
        } else {
            &text
        };
        if line.trim().is_empty() {
            continue;
        }
        if let Some(report) = drop_report(line) {
            out.socket_drops += report.map_err(err)?;
            out.first_drop_report_line.get_or_insert(line_no);
            continue;
        }
        let parsed = parse_line(line).map_err(|message| {
            // A first line in another tool's format: say which, and what converts it.
            match foreign_format(line).filter(|_| first.is_none() && out.skipped == 0) {
                Some(format) => err(format!("{message}: {format}")),
                None => err(message),
            }
        })?;
        match parsed {
            Line::NotOurs => out.skipped += 1,
            Line::Frame { t_s, frame } => {
                if t_s < latest_s - BACKWARDS_TOLERANCE_S {
                    out.dropped_backwards += 1;
                    out.first_dropped_line.get_or_insert(line_no);
                    continue;
                }
                if out.frames.len() == max_frames {
                    return Err(err(format!(
                        "more than {max_frames} frames, the most convert holds in memory; \
                         nothing past this line was read (convert the file in parts: \
                         `split -l {max_frames}`)"
                    )));
                }
                latest_s = latest_s.max(t_s);
                let t0 = *first.get_or_insert(t_s);
                let rel = t_s - t0;
                // Round to the µs the file carries; never go backwards (equal stamps, and the
                // small steps back within the tolerance, take the latest time).
                let t_us = ((rel.max(0.0) * 1e6).round() as u64).max(last_us);
                last_us = t_us;
                out.frames.push(Stamped { t_us, frame });
            }
        }
    }
    out.epoch_s = first.unwrap_or(0.0);
    Ok(out)
}

/// What another tool's CAN log looks like on its first line, and what writes a candump log
/// from it (can-utils' `asc2log`, python-can's `can_logconvert`, which picks each file's
/// format by its suffix); `None` for a line of no format known here.
fn foreign_format(line: &str) -> Option<&'static str> {
    let line = line.trim();
    if line.starts_with("date ") || line.starts_with("base ") {
        Some(
            "a Vector ASC log, not a candump one; `asc2log -I FILE.asc -O FILE.log` \
             (can-utils) or `can_logconvert FILE.asc FILE.log` (python-can) writes one",
        )
    } else if line.starts_with(';') {
        Some(
            "a PEAK TRC log, not a candump one; `can_logconvert FILE.trc FILE.log` \
             (python-can) writes one",
        )
    } else if line.starts_with("timestamp,arbitration_id") {
        Some(
            "python-can's CSV log, not a candump one; `can_logconvert FILE.csv FILE.log` \
             (python-can) writes one",
        )
    } else if line.split(',').any(|name| name.trim() == "ref_sw_deg") {
        Some(
            "a steering log already (its header names `ref_sw_deg`), not a recording of the \
             bus: `host-sim gap FILE` reads it as it is",
        )
    } else {
        None
    }
}

/// The first bytes of a Vector BLF log (binary).
const BLF_MAGIC: &[u8] = b"LOGG";

/// The interface name a recording of the simulated car (`sim`, `sim:PATH`) carries: `can0`,
/// the car's, so a rehearsal's file goes through the same commands as the car's
/// (`log2asc -I bus.candump can0`, cantools, python-can) without being told of `sim`.
pub const SIM_RECORDING_IFACE: &str = "can0";

/// The interface name to write for a transport called `name`.
pub fn recorded_iface(name: &str) -> &str {
    if name == "sim" || name.starts_with("sim:") {
        SIM_RECORDING_IFACE
    } else {
        name
    }
}

/// One candump line for `frame` at `epoch_s + t_us`.
pub fn format_line(epoch_s: f64, iface: &str, stamped: &Stamped) -> String {
    // Whole seconds and µs apart, so a large epoch keeps its µs exact.
    let base_us = (epoch_s * 1e6).round() as u64;
    let t = base_us + stamped.t_us;
    let mut data = String::with_capacity(16);
    for b in stamped.frame.data() {
        data.push_str(&format!("{b:02X}"));
    }
    format!(
        "({}.{:06}) {iface} {:03X}#{data}",
        t / 1_000_000,
        t % 1_000_000,
        stamped.frame.id().raw()
    )
}

/// Creates `path` to write a candump log into, and its missing parent directories first, as
/// the log's save does (`convert --out`, `campaign --out`). Returns the file and the directory
/// created, if one was.
pub fn create(path: &Path) -> std::io::Result<(std::fs::File, Option<std::path::PathBuf>)> {
    let missing = path
        .parent()
        .filter(|d| !d.as_os_str().is_empty() && !d.exists())
        .map(Path::to_path_buf);
    if let Some(dir) = &missing {
        std::fs::create_dir_all(dir)?;
    }
    Ok((std::fs::File::create(path)?, missing))
}

/// Writes frames as a candump log.
#[derive(Debug)]
pub struct Writer<W: Write> {
    out: W,
    epoch_s: f64,
    iface: String,
}

impl<W: Write> Writer<W> {
    pub fn new(out: W, epoch_s: f64, iface: &str) -> Self {
        Writer {
            out,
            epoch_s,
            iface: iface.to_string(),
        }
    }

    pub fn write(&mut self, stamped: &Stamped) -> std::io::Result<()> {
        writeln!(
            self.out,
            "{}",
            format_line(self.epoch_s, &self.iface, stamped)
        )
    }

    pub fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

/// Writes `frames` to `path` as a candump log.
pub fn save(
    path: &Path,
    epoch_s: f64,
    iface: &str,
    frames: &[Stamped],
) -> Result<(), BringupError> {
    let io = |source| BringupError::Io {
        context: format!("cannot write candump file {}", path.display()),
        source,
    };
    let (file, _) = create(path).map_err(io)?;
    let mut w = Writer::new(std::io::BufWriter::new(file), epoch_s, iface);
    for f in frames {
        w.write(f).map_err(io)?;
    }
    w.flush().map_err(io)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<CandumpFile, BringupError> {
        read_from(std::io::Cursor::new(text), Path::new("x.log"))
    }

    #[test]
    fn lines_round_trip_with_their_microseconds() {
        let text = "(1700000000.123456) can0 101#0011223344556677\n\
                    (1700000000.133456) can0 100#\n\
                    (1700000000.143457) can0 7FF#AB\n";
        let f = parse(text).unwrap();
        assert_eq!(f.frames.len(), 3);
        assert_eq!(f.frames[1].t_us, 10_000);
        assert_eq!(f.frames[2].t_us, 20_001);
        let back: Vec<String> = f
            .frames
            .iter()
            .map(|s| format_line(f.epoch_s, "can0", s))
            .collect();
        assert_eq!(back.join("\n") + "\n", text);
    }

    /// A file with more frames than the bound is refused at the first frame past it, naming
    /// the bound; one at the bound reads whole, and skipped lines do not count.
    #[test]
    fn a_candump_over_the_frame_bound_is_refused_at_the_line_past_it() {
        let mut text = String::from("(1700000000.000000) can0 12345678#00\n");
        for k in 0..1001u32 {
            text += &format!("(1700000000.{:06}) can0 101#{:02X}\n", k * 10, k % 256);
        }
        let read = |max| read_at_most(std::io::Cursor::new(&text), Path::new("big.log"), max);
        let whole = read(1001).unwrap();
        assert_eq!((whole.frames.len(), whole.skipped), (1001, 1));
        match read(1000) {
            Err(e @ BringupError::Candump { line: 1002, .. }) => {
                let said = e.to_string();
                assert!(
                    said.starts_with("big.log:1002: more than 1000 frames"),
                    "{said}"
                );
                assert!(said.contains("split -l 1000"), "{said}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn malformed_lines_are_named_by_number() {
        let text = "(1.0) can0 101#00\n\n(2.0) can0 10G#00\n";
        match parse(text) {
            Err(BringupError::Candump { line, message, .. }) => {
                assert_eq!(line, 3);
                assert!(message.contains("10G"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        for bad in [
            "1.0 can0 101#00",
            "(x) can0 101#00",
            "(1.0) can0",
            "(1.0) can0 101-00",
            "(1.0) can0 101#0",
            "(1.0) can0 101#001122334455667788",
            "(1.0) can0 1#00",
            "(1.0) can0 801#00",
        ] {
            assert!(
                matches!(parse(bad), Err(BringupError::Candump { line: 1, .. })),
                "{bad}"
            );
        }
    }

    #[test]
    fn absurd_time_stamps_are_refused_with_their_line() {
        for stamp in ["1e300", "-5.0", "2e10"] {
            let text = format!("(1.0) can0 101#00\n({stamp}) can0 101#01\n");
            match parse(&text) {
                Err(BringupError::Candump { line, message, .. }) => {
                    assert_eq!(line, 2, "{stamp}");
                    assert!(message.contains(stamp), "{message}");
                }
                other => panic!("{stamp}: {other:?}"),
            }
        }
    }

    #[test]
    fn frames_stamped_back_are_dropped_and_counted_not_moved() {
        let text = "(10.000) can0 101#00\n(10.010) can0 101#01\n(9.020) can0 101#02\n\
                    (10.0095) can0 101#03\n(10.030) can0 101#04\n";
        let f = parse(text).unwrap();
        assert_eq!(f.dropped_backwards, 1);
        assert_eq!(f.first_dropped_line, Some(3));
        let kept: Vec<(u64, u8)> = f
            .frames
            .iter()
            .map(|s| (s.t_us, s.frame.data()[0]))
            .collect();
        // Half a millisecond back is within the tolerance: kept, at the latest time.
        assert_eq!(kept, [(0, 0), (10_000, 1), (10_000, 3), (30_000, 4)]);
    }

    /// Another tool's CAN log is refused at its first line, naming the format and what
    /// converts it to a candump log.
    #[test]
    fn another_tools_can_log_is_named_with_its_converter() {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes, said) in [
            (
                "bus.asc",
                &b"date Mon Dec 7 18:10:01.000 2026\nbase hex  timestamps absolute\n"[..],
                "asc2log",
            ),
            (
                "bus.trc",
                b";$FILEVERSION=2.1\n;$STARTTIME=46000.7\n",
                "PEAK TRC",
            ),
            (
                "bus.csv",
                b"timestamp,arbitration_id,extended,remote,error,dlc,data\n",
                "python-can's CSV",
            ),
            ("bus.blf", b"LOGG\x90\x00\x00\x00\x01\x02", "BLF"),
            (
                "log.csv",
                b"t,ref_sw_deg,sw_deg,motor_rad,current_a\n0,0,0,0,0\n",
                "host-sim gap FILE",
            ),
        ] {
            let path = dir.path().join(name);
            std::fs::write(&path, bytes).unwrap();
            let e = read(&path).unwrap_err().to_string();
            assert!(e.contains(name) && e.contains(said), "{name}: {e}");
        }
        // A stray line in the middle of a candump log is an error of that line alone.
        let path = dir.path().join("stray.log");
        std::fs::write(&path, "(1700000000.000100) can0 101#0102\n; note\n").unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(e.contains("stray.log") && !e.contains("TRC"), "{e}");
    }

    /// What other tools write for `candump -l` logs reads as the same frames.
    #[test]
    fn other_tools_candump_logs_read_as_the_same_frames() {
        let plain =
            parse("(1700000000.000100) can0 101#0102\n(1700000000.010100) can0 080#\n").unwrap();
        for (tool, text) in [
            (
                "python-can CanutilsLogWriter, candump -l -x",
                "(1700000000.000100) vcan0 101#0102 R\n(1700000000.010100) vcan0 080# T\n",
            ),
            (
                "a byte-order mark and CRLF",
                "\u{feff}(1700000000.000100) can0 101#0102\r\n(1700000000.010100) can0 080#\r\n",
            ),
            (
                "candump -ta, spelled out",
                "(1700000000.000100)  can0  101   [2]  01 02\n(1700000000.010100)  can0  080   [0]\n",
            ),
            (
                "nanosecond stamps",
                "(1700000000.000100000) can0 101#0102\n(1700000000.010100000) can0 080#\n",
            ),
        ] {
            let f = parse(text).unwrap_or_else(|e| panic!("{tool}: {e}"));
            assert_eq!(f.frames, plain.frames, "{tool}");
            assert_eq!(f.epoch_s, plain.epoch_s, "{tool}");
        }
        // SavvyCAN stamps from the start of its capture, zero-padded.
        let savvy =
            parse("(0000000003.800000) vcan0 101#0102\n(0000000003.810000) vcan0 080#\n").unwrap();
        assert_eq!(savvy.frames, plain.frames);
        assert_eq!(savvy.epoch_s, 3.8);
        // A raw DLC above 8 is 8 bytes of data.
        let raw = parse("(1.0) can0 101#0011223344556677_9\n").unwrap();
        assert_eq!(
            raw.frames[0].frame.data(),
            [0, 0x11, 0x22, 0x33, 0x44, 0x55, 0x66, 0x77]
        );
        // Anything else after the frame is still an error.
        assert!(matches!(
            parse("(1.0) can0 101#00 X\n"),
            Err(BringupError::Candump { line: 1, .. })
        ));
    }

    #[test]
    fn candump_drop_reports_are_counted_not_refused() {
        let text = "(1.00) can0 101#00\n\
                    DROPCOUNT: dropped 3 CAN frames on 'can0' socket (total drops 3)\n\
                    (1.01) can0 101#01\n\
                    DROPCOUNT: dropped 1 CAN frame on 'can0' socket (total drops 4)\n";
        let f = parse(text).unwrap();
        assert_eq!(f.frames.len(), 2);
        assert_eq!((f.socket_drops, f.first_drop_report_line), (4, Some(2)));
    }

    /// A line past the cap is refused with its number, having read about the cap only.
    #[test]
    fn an_overlong_line_is_refused_without_reading_it_whole() {
        let mut text = String::from("(1.0) can0 101#00\n");
        text.push_str(&"\0".repeat(4 * 1024 * 1024));
        match parse(&text) {
            Err(BringupError::Candump { line, message, .. }) => {
                assert_eq!(line, 2);
                assert!(message.contains("longer than 4096 bytes"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn extended_remote_and_fd_frames_are_skipped_and_counted() {
        let text =
            "(1.0) can0 12345678#00\n(1.1) can0 101#R\n(1.2) can0 101##1AA\n(1.3) can0 101#01\n";
        let f = parse(text).unwrap();
        assert_eq!(f.skipped, 3);
        assert_eq!(f.frames.len(), 1);
    }
}

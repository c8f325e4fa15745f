//! The one log format of the project: simulated runs, recordings from the car and the input of
//! the sim-to-real comparison are all written and read here, so they can be compared column by
//! column.
//!
//! # The format
//!
//! A log is a UTF-8 CSV file, plain (`.csv`) or gzip-compressed (`.csv.gz`):
//!
//! ```text
//! # source: host-sim, scenario step_10deg        <- optional comments, only before the header
//! t,ref_sw_deg,sw_deg,motor_rad,current_a,voltage_v
//! 0.000000,0.0000,0.0000,0.00000,0.0000,0
//! 0.000500,10.0000,0.0031,0.00212,19.9871,23.91
//! 0.001000,10.0000,nan,0.00845,20.0000,24
//! ```
//!
//! * **Header.** The first non-comment line names the columns. The first five are required, with
//!   exactly these names and in exactly this order ([`REQUIRED_COLUMNS`]):
//!
//!   | column      | quantity                                        | unit |
//!   |-------------|-------------------------------------------------|------|
//!   | `t`         | time since the start of the log                 | s    |
//!   | `ref_sw_deg`| position reference, as an angle at the steering wheel | deg  |
//!   | `sw_deg`    | steering column encoder, as an angle at the wheel | deg  |
//!   | `motor_rad` | motor shaft angle                               | rad  |
//!   | `current_a` | motor current                                   | A    |
//!
//!   Any number of further columns may follow; put the unit in the name (`voltage_v`). Names are
//!   case-sensitive, unique and non-empty, and contain no comma, quote or control character
//!   (there is no quoting).
//! * **Rows.** One line per sample with as many comma-separated fields as the header. A field is
//!   a decimal number as Rust's `f64` parser reads it (`12`, `-0.5`, `1e-3`).
//! * **Time.** `t` is finite and strictly increasing from row to row; it need not start at 0 nor
//!   be evenly spaced. ([`Table`] may also read it as stamped, [`TimeOrder::AsStamped`], for a
//!   caller that places rows whose stamps jitter past each other.)
//! * **Missing samples.** Any column but `t` may hold `nan` (any letter case) or nothing (an
//!   empty field, as a spreadsheet or pandas writes a missing value) for a sensor dropout; it
//!   is read as `f64::NAN`. Infinities are refused everywhere: no sensor reports one,
//!   so one in a file means a bug upstream. A tool that cannot use a gap fills it with
//!   [`fill_missing`] (linear between the neighbours) and says how many samples it filled; a
//!   log whose rows each hold one CAN frame's columns, the others' left empty, with
//!   [`hold_missing`] (each signal holds until its next frame).
//! * **Physical bounds.** Every value, time included, must lie within a bound set by the unit at
//!   the end of its column's name ([`bound_for`]): the time column 1e10 s (a Unix clock's
//!   seconds, as a wall-clock logger stamps its rows, up to the year 2286), `_s` 1e6 s,
//!   `_deg` 1e6 deg, `_rad` 1e6 rad, `_a` 1e4 A, `_v` 1e4 V, `_m` 1e3 m, `_n` 1e6 N, anything else 1e12. The bounds are
//!   far beyond the actuator (its motor needs 36 min at full speed to turn 1e6 rad), so they
//!   only catch garbage such as an uninitialised float or `1e300`, which would otherwise turn
//!   every figure computed from the log into `inf` or NaN. Refused with line and column.
//! * **Leniency.** Lines whose first non-blank character is `#` are comments if they come before
//!   the header; they are skipped and not kept (after the header, `#` is an error, so a stray
//!   line in the data is not silently dropped). Blank lines are ignored anywhere (trailing ones
//!   in particular), spaces and tabs around fields are ignored, LF and CRLF line ends are both
//!   read, and a leading UTF-8 byte-order mark (spreadsheet exports) is skipped.
//! * **Compression.** [`Log::save`] gzips when the file name ends in `.gz`; [`Log::load`]
//!   recognises gzip by its magic bytes whatever the name. A gzip file cut short (an interrupted
//!   copy) is refused as truncated, not read as far as it goes.
//! * **Other column names.** [`Table`] reads any CSV of numeric columns with one named time
//!   column by these same rules (a rig's logs for `host-sim gap`, a track reference). It may
//!   read only the columns its caller names ([`Reads::Only`]), skipping the others unread (a
//!   team's logger writes columns of its own), reads names and fields in double quotes
//!   without them, and a time column's date and time (ISO 8601) as Unix seconds, a time of
//!   day as seconds from its midnight.
//! * **Precision.** The writer rounds the required columns to fixed decimals well below what is
//!   measured (see the constants below), and an extra column whose name ends in one of their
//!   units or in `_v` (1 mV) likewise; any other extra column (a state code, a count) is
//!   written losslessly. A file with the header and no rows is a valid, empty log.
use std::fmt;
use std::fs::{self, File};
use std::io::{self, BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};

use crate::lines::{Capped, read_line_capped};
use flate2::Compression;
use flate2::read::MultiGzDecoder;
use flate2::write::GzEncoder;

/// The columns every log starts with, in this order.
pub const REQUIRED_COLUMNS: [&str; 5] = ["t", "ref_sw_deg", "sw_deg", "motor_rad", "current_a"];

// Decimals written for the required columns. Each is at least ten times finer than what is
// logged, so rounding loses nothing that was measured, yet it drops the noise digits of a
// simulation, which would otherwise triple the file and defeat gzip.
/// 1 µs: the fastest loop on the car (EPOS4 current loop, 25 kHz) has a 40 µs period.
const T_DECIMALS: usize = 6;
/// 1e-4 deg: a 14-bit column encoder resolves 0.022 deg.
const DEG_DECIMALS: usize = 4;
/// 1e-5 rad: a 4096-count quadrature motor encoder resolves 3.8e-4 rad.
const RAD_DECIMALS: usize = 5;
/// 0.1 mA: the EPOS4 reports current in mA.
const AMP_DECIMALS: usize = 4;
/// 1 mV: a 24 V PWM bridge with a 12-bit duty cycle resolves 6 mV.
const VOLT_DECIMALS: usize = 3;

/// The fixed decimals of an extra column, from the unit at the end of its name (as its bound,
/// [`bound_for`]); `None` for a column without one of these units (a state code, a count),
/// which is written exactly.
fn decimals_for(column: &str) -> Option<usize> {
    let (_, unit) = column.rsplit_once('_')?;
    match unit.to_ascii_lowercase().as_str() {
        "s" => Some(T_DECIMALS),
        "deg" => Some(DEG_DECIMALS),
        "rad" => Some(RAD_DECIMALS),
        "a" => Some(AMP_DECIMALS),
        "v" => Some(VOLT_DECIMALS),
        _ => None,
    }
}

const GZIP_MAGIC: [u8; 2] = [0x1f, 0x8b];

/// One sample of the five required columns.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Row {
    /// Time, s.
    pub t: f64,
    /// Position reference as a steering-wheel angle, deg.
    pub ref_sw_deg: f64,
    /// Column encoder as a steering-wheel angle, deg.
    pub sw_deg: f64,
    /// Motor shaft angle, rad.
    pub motor_rad: f64,
    /// Motor current, A.
    pub current_a: f64,
}

/// A log held column by column, the way the analysis uses it.
///
/// All columns have the same length; [`Log::write_to`] checks it, together with everything else
/// the reader would refuse, so a log that saves also loads.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Log {
    pub t: Vec<f64>,
    pub ref_sw_deg: Vec<f64>,
    pub sw_deg: Vec<f64>,
    pub motor_rad: Vec<f64>,
    pub current_a: Vec<f64>,
    /// Further columns, by name, in file order.
    pub extra: Vec<(String, Vec<f64>)>,
    /// Comment lines before the header, without their `#`: what the writer says of the car
    /// and the log (`drive: epos4`, `controller: paper`, `current: interval-mean`, ...).
    pub comments: Vec<String>,
}

/// Everything that can go wrong reading or writing a log. Line numbers count every line of the
/// file from 1, comments and blank lines included, so they match what an editor shows.
#[derive(Debug)]
pub enum LogError {
    /// The file (or stream, `path: None`) could not be opened, read or written.
    Io {
        path: Option<PathBuf>,
        source: io::Error,
    },
    /// An error inside the named file; `source` says what and where.
    InFile {
        path: PathBuf,
        source: Box<LogError>,
    },
    /// The input holds no header: it is empty or only comments and blank lines.
    Empty,
    /// A required column is not in the header at all.
    MissingColumn {
        expected: &'static str,
        found_header: String,
    },
    /// The required columns are all there but not first or not in the required order.
    WrongColumnOrder { found: Vec<String> },
    /// A column name that is empty, repeated or not writable without quoting.
    BadColumnName { name: String, reason: &'static str },
    /// A data line with more or fewer fields than the header.
    WrongFieldCount {
        line: usize,
        expected: usize,
        found: usize,
    },
    /// A field that is not a number, or is infinite.
    BadNumber {
        line: usize,
        column: String,
        text: String,
    },
    /// A value beyond the physical bound of its column ([`bound_for`]).
    OutOfBounds {
        line: usize,
        column: String,
        value: f64,
        bound: f64,
        unit: &'static str,
    },
    /// A [`Table`]'s header lacks the named column.
    MissingNamedColumn {
        expected: String,
        found_header: String,
    },
    /// A header with no comma whose fields are separated by another character (`;` as a
    /// spreadsheet in a comma-decimal locale writes, or a tab): the log's fields are
    /// comma-separated, so the whole line would be read as one column's name.
    Separator { separator: char, header: String },
    /// A gzip file that ends before its compressed data does.
    TruncatedGzip,
    /// A time stamp that is `nan`.
    NonFiniteTime { line: usize },
    /// A time stamp not after the one before it.
    NonMonotonicTime {
        line: usize,
        previous: f64,
        current: f64,
    },
    /// Writing: a column whose length differs from `t`.
    ColumnLength {
        column: String,
        expected: usize,
        found: usize,
    },
    /// A line longer than [`MAX_LINE_BYTES`]: not a log (a binary file, no line ends).
    LineTooLong { line: usize, max_bytes: usize },
    /// Writing: a non-finite time, or two samples that round to the same microsecond (rows
    /// count from 0).
    TimeNotWritable { row: usize, reason: &'static str },
    /// Writing: an infinite value, which the reader would refuse (rows count from 0).
    InfiniteValue { row: usize, column: String },
    /// Writing: a value beyond its column's bound, which the reader would refuse.
    ValueOutOfBounds {
        row: usize,
        column: String,
        value: f64,
    },
}

impl fmt::Display for LogError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Io {
                path: Some(path),
                source,
            } => write!(f, "{}: {source}", path.display()),
            Self::Io { path: None, source } => write!(f, "input/output error: {source}"),
            Self::InFile { path, source } => write!(f, "{}: {source}", path.display()),
            Self::Empty => write!(
                f,
                "no header line found (the log is empty or only comments); expected `{}`",
                REQUIRED_COLUMNS.join(",")
            ),
            Self::MissingColumn {
                expected,
                found_header,
            } => write!(
                f,
                "the header lacks the required column `{expected}`: found `{found_header}`, \
                 expected it to start with `{}`",
                REQUIRED_COLUMNS.join(",")
            ),
            Self::WrongColumnOrder { found } => write!(
                f,
                "the header must start with `{}` in this order, found `{}`",
                REQUIRED_COLUMNS.join(","),
                found.join(",")
            ),
            Self::BadColumnName { name, reason } => {
                write!(f, "bad column name `{name}`: {reason}")
            }
            Self::WrongFieldCount {
                line,
                expected,
                found,
            } => write!(
                f,
                "line {line}: {found} fields, but the header names {expected} columns"
            ),
            Self::BadNumber { line, column, text } => write!(
                f,
                "line {line}, column `{column}`: cannot read `{text}` as a value; expected a \
                 finite number, or `nan` or nothing for a missing sample"
            ),
            Self::OutOfBounds {
                line,
                column,
                value,
                bound,
                unit,
            } => {
                write!(
                    f,
                    "line {line}, column `{column}`: {value:e} is outside the physical bound of \
                     +-{bound:e} {unit} for this column"
                )?;
                // A drive's current in its own unit: an EPOS4 reports milliamperes.
                if *unit == "A" && value.abs() < 1e3 * bound {
                    write!(f, "; is it in milliamperes (an EPOS4 reports mA)?")?;
                }
                Ok(())
            }
            Self::MissingNamedColumn {
                expected,
                found_header,
            } => write!(
                f,
                "the header lacks the column `{expected}`: found `{found_header}`"
            ),
            Self::Separator { separator, header } => write!(
                f,
                "the header `{header}` separates its fields by {}, not by commas: a log's \
                 fields are comma-separated, with `.` as the decimal point (export the file \
                 again as comma-separated)",
                match separator {
                    '\t' => "tabs".to_string(),
                    c => format!("`{c}`"),
                }
            ),
            Self::TruncatedGzip => write!(
                f,
                "truncated gzip: the file ends before its compressed data does (an \
                 interrupted copy or recording?)"
            ),
            Self::NonFiniteTime { line } => {
                write!(f, "line {line}: time `t` must be a finite number")
            }
            Self::NonMonotonicTime {
                line,
                previous,
                current,
            } => write!(
                f,
                "line {line}: time goes from {previous} s to {current} s; `t` must strictly \
                 increase"
            ),
            Self::ColumnLength {
                column,
                expected,
                found,
            } => write!(
                f,
                "column `{column}` has {found} samples but `t` has {expected}"
            ),
            Self::LineTooLong { line, max_bytes } => write!(
                f,
                "line {line} is longer than {} KiB: not a log (a binary file, or no line \
                 ends?); nothing past it was read",
                max_bytes / 1024
            ),
            Self::TimeNotWritable { row, reason } => write!(f, "row {row}: {reason}"),
            Self::InfiniteValue { row, column } => write!(
                f,
                "row {row}, column `{column}`: infinite value (use NaN for a missing sample)"
            ),
            Self::ValueOutOfBounds { row, column, value } => write!(
                f,
                "row {row}, column `{column}`: {value:e} is outside the column's physical bound"
            ),
        }
    }
}

impl std::error::Error for LogError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            Self::InFile { source, .. } => Some(source.as_ref()),
            _ => None,
        }
    }
}

impl LogError {
    /// The error without the file context that [`Log::load`] and [`Log::save`] wrap around it,
    /// for matching on what went wrong.
    pub fn root(&self) -> &LogError {
        match self {
            Self::InFile { source, .. } => source.root(),
            other => other,
        }
    }

    fn io(source: io::Error) -> Self {
        Self::Io { path: None, source }
    }

    /// This error as it reads for the file at `path` (also for errors a caller finds in a
    /// file after reading it).
    pub fn in_file(self, path: &Path) -> Self {
        match self {
            // An I/O error on a stream is about this file; say so in the error itself rather
            // than wrapping it.
            Self::Io { path: None, source } => Self::Io {
                path: Some(path.to_path_buf()),
                source,
            },
            e @ (Self::Io { .. } | Self::InFile { .. }) => e,
            e => Self::InFile {
                path: path.to_path_buf(),
                source: Box::new(e),
            },
        }
    }
}

impl Log {
    /// An empty log with only the required columns.
    pub fn new() -> Self {
        Self::default()
    }

    /// An empty log with these further columns after the required ones. Names are checked when
    /// the log is written (see the module doc for the rules).
    pub fn with_extra_columns(names: &[&str]) -> Self {
        Self {
            extra: names.iter().map(|n| (n.to_string(), Vec::new())).collect(),
            ..Self::default()
        }
    }

    /// Appends one sample: the required values and one value per extra column, in column order.
    ///
    /// # Panics
    /// If `extra` does not hold exactly one value per extra column: that is a bug in the
    /// caller, and padding or dropping values would misalign every later row.
    pub fn push(&mut self, row: Row, extra: &[f64]) {
        assert_eq!(
            extra.len(),
            self.extra.len(),
            "Log::push: {} extra values for {} extra columns",
            extra.len(),
            self.extra.len()
        );
        self.t.push(row.t);
        self.ref_sw_deg.push(row.ref_sw_deg);
        self.sw_deg.push(row.sw_deg);
        self.motor_rad.push(row.motor_rad);
        self.current_a.push(row.current_a);
        for ((_, column), &v) in self.extra.iter_mut().zip(extra) {
            column.push(v);
        }
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.t.len()
    }

    pub fn is_empty(&self) -> bool {
        self.t.is_empty()
    }

    /// The required values of sample `i`, if there is one.
    pub fn row(&self, i: usize) -> Option<Row> {
        Some(Row {
            t: *self.t.get(i)?,
            ref_sw_deg: *self.ref_sw_deg.get(i)?,
            sw_deg: *self.sw_deg.get(i)?,
            motor_rad: *self.motor_rad.get(i)?,
            current_a: *self.current_a.get(i)?,
        })
    }

    /// The extra column of this name.
    pub fn extra(&self, name: &str) -> Option<&[f64]> {
        self.extra
            .iter()
            .find(|(n, _)| n == name)
            .map(|(_, v)| v.as_slice())
    }

    /// Names of the extra columns, in file order.
    pub fn extra_names(&self) -> impl Iterator<Item = &str> {
        self.extra.iter().map(|(n, _)| n.as_str())
    }

    /// Writes the log as CSV. Refuses (before writing anything) what [`Log::read_from`] would
    /// refuse: bad column names, unequal columns, time that is not finite and increasing at
    /// microsecond resolution, infinite values.
    pub fn write_to(&self, w: impl Write) -> Result<(), LogError> {
        self.check_writable()?;
        let mut w = BufWriter::new(w);
        for c in &self.comments {
            // One line each: a newline inside would end the comment and start a data line.
            writeln!(w, "# {}", c.replace(['\r', '\n'], " ")).map_err(LogError::io)?;
        }
        let mut header: Vec<&str> = REQUIRED_COLUMNS.to_vec();
        header.extend(self.extra_names());
        writeln!(w, "{}", header.join(",")).map_err(LogError::io)?;

        let extra_decimals: Vec<Option<usize>> = self.extra_names().map(decimals_for).collect();
        let mut line = String::new();
        for i in 0..self.len() {
            line.clear();
            push_fixed(&mut line, self.t[i], T_DECIMALS);
            for (column, decimals) in [
                (&self.ref_sw_deg, DEG_DECIMALS),
                (&self.sw_deg, DEG_DECIMALS),
                (&self.motor_rad, RAD_DECIMALS),
                (&self.current_a, AMP_DECIMALS),
            ] {
                line.push(',');
                push_fixed(&mut line, column[i], decimals);
            }
            for ((_, column), decimals) in self.extra.iter().zip(&extra_decimals) {
                line.push(',');
                match decimals {
                    Some(d) => push_fixed(&mut line, column[i], *d),
                    None => push_exact(&mut line, column[i]),
                }
            }
            line.push('\n');
            w.write_all(line.as_bytes()).map_err(LogError::io)?;
        }
        w.flush().map_err(LogError::io)
    }

    /// Reads a log in the format of the module doc from plain (not compressed) CSV text.
    pub fn read_from(r: impl BufRead) -> Result<Log, LogError> {
        let table = read_table(r, TimeOrder::Increasing, |line| {
            Ok(Layout::every(parse_header(line)?, 0))
        })?;
        let mut columns = table.columns.into_iter();
        let mut next = || columns.next().unwrap_or_default();
        let (t, ref_sw_deg, sw_deg, motor_rad, current_a) =
            (next(), next(), next(), next(), next());
        let extra = table.names[REQUIRED_COLUMNS.len()..]
            .iter()
            .cloned()
            .zip(columns)
            .collect();
        Ok(Log {
            t,
            ref_sw_deg,
            sw_deg,
            motor_rad,
            current_a,
            extra,
            comments: table.comments,
        })
    }

    /// Writes the log to `path`, gzip-compressed if the name ends in `.gz`, creating missing
    /// parent directories. The file is written under a temporary name and renamed when
    /// complete, so a failed save never leaves a truncated log behind.
    pub fn save(&self, path: &Path) -> Result<(), LogError> {
        self.check_writable().map_err(|e| e.in_file(path))?;
        let io_err = |source| LogError::Io {
            path: Some(path.to_path_buf()),
            source,
        };
        if let Some(dir) = path.parent().filter(|d| !d.as_os_str().is_empty()) {
            fs::create_dir_all(dir).map_err(io_err)?;
        }
        let mut tmp_name = path.as_os_str().to_owned();
        tmp_name.push(".partial");
        let tmp = PathBuf::from(tmp_name);

        let written = File::create(&tmp).map_err(io_err).and_then(|file| {
            if is_gz_name(path) {
                let mut gz = GzEncoder::new(BufWriter::new(file), Compression::default());
                self.write_to(&mut gz)?;
                let mut inner = gz.finish().map_err(LogError::io)?;
                inner.flush().map_err(LogError::io)
            } else {
                self.write_to(file)
            }
        });
        let result = written.and_then(|()| fs::rename(&tmp, path).map_err(io_err));
        if result.is_err() {
            // Best effort: the error to report is the one that made the save fail.
            let _ = fs::remove_file(&tmp);
        }
        result.map_err(|e| e.in_file(path))
    }

    /// Reads a log from `path`, plain or gzip-compressed (recognised by content, not name).
    pub fn load(path: &Path) -> Result<Log, LogError> {
        read_file(path, Log::read_from)
    }

    fn check_writable(&self) -> Result<(), LogError> {
        let n = self.len();
        let required = [
            (REQUIRED_COLUMNS[1], &self.ref_sw_deg),
            (REQUIRED_COLUMNS[2], &self.sw_deg),
            (REQUIRED_COLUMNS[3], &self.motor_rad),
            (REQUIRED_COLUMNS[4], &self.current_a),
        ];
        let columns = required
            .into_iter()
            .chain(self.extra.iter().map(|(n, v)| (n.as_str(), v)));
        for (name, values) in columns.clone() {
            if values.len() != n {
                return Err(LogError::ColumnLength {
                    column: name.to_string(),
                    expected: n,
                    found: values.len(),
                });
            }
        }
        let mut seen: Vec<&str> = REQUIRED_COLUMNS.to_vec();
        for name in self.extra_names() {
            check_column_name(name, &seen)?;
            seen.push(name);
        }

        let mut previous_us = None;
        for (row, &t) in self.t.iter().enumerate() {
            if !t.is_finite() {
                return Err(LogError::TimeNotWritable {
                    row,
                    reason: "time is not finite",
                });
            }
            // Compare what will be in the file, not the f64: two samples closer than the
            // written resolution would read back as time standing still.
            let us = (t * 10f64.powi(T_DECIMALS as i32)).round();
            if previous_us.is_some_and(|p| us <= p) {
                return Err(LogError::TimeNotWritable {
                    row,
                    reason: "time does not increase by at least the 1 µs the format resolves",
                });
            }
            previous_us = Some(us);
        }
        for (name, values) in columns.clone() {
            if let Some(row) = values.iter().position(|v| v.is_infinite()) {
                return Err(LogError::InfiniteValue {
                    row,
                    column: name.to_string(),
                });
            }
        }
        let time = std::iter::once(("t", &self.t));
        for (name, values) in time.chain(columns) {
            let (bound, _) = bound_for(name);
            if let Some(row) = values.iter().position(|v| v.abs() > bound) {
                return Err(LogError::ValueOutOfBounds {
                    row,
                    column: name.to_string(),
                    value: values[row],
                });
            }
        }
        Ok(())
    }
}

/// A CSV of named numeric columns with one time column, read and checked by the rules of the
/// module doc (comments, `nan`, bounds, strictly increasing finite time, gzip), whatever the
/// names: a rig's logs for `host-sim gap` and a track reference name their own columns.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Table {
    /// The names of the columns read, in file order.
    pub names: Vec<String>,
    /// One vector per name, all as long as the time column.
    pub columns: Vec<Vec<f64>>,
    /// The header's other columns, skipped unread ([`Reads::Only`]), in file order, as named
    /// (an unnamed one as an empty name).
    pub unread: Vec<String>,
    /// The file's line number of each row, for errors found after reading.
    pub lines: Vec<usize>,
    /// The comment lines before the header, without their `#` (a log may say
    /// `# current: instantaneous` there).
    pub comments: Vec<String>,
}

/// What the reader asks of the time column besides being finite.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum TimeOrder {
    /// Strictly increasing from row to row (the module doc's rule).
    Increasing,
    /// As the logger stamped its rows, in the rows' order: a receiver that stamps each row
    /// within a millisecond of its place may stamp one before the row ahead of it. The
    /// caller places the rows ([`Table::first_time_back`] finds where the stamps go back).
    AsStamped,
}

/// Which of a table's columns the reader reads.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reads<'a> {
    /// Every column: each must be named, once, and hold numbers (a track reference).
    All,
    /// The time column and these, where the header has them. Any other column is skipped
    /// unread, its name and fields unchecked, and listed in [`Table::unread`]: a team's
    /// logger writes columns of its own beside the ones a diagnosis reads (the row index
    /// pandas' `to_csv` writes under an empty name, a state as text, the empty column of a
    /// comma at each line's end).
    Only(&'a [&'a str]),
}

impl Table {
    /// Reads plain CSV text whose header names `time_column`.
    pub fn read_from(r: impl BufRead, time_column: &str) -> Result<Table, LogError> {
        Table::read_from_ordered(r, time_column, TimeOrder::Increasing)
    }

    /// As [`Table::read_from`], with the time column's order as `order` asks.
    pub fn read_from_ordered(
        r: impl BufRead,
        time_column: &str,
        order: TimeOrder,
    ) -> Result<Table, LogError> {
        Table::read_from_reading(r, time_column, Reads::All, order)
    }

    /// As [`Table::read_from_ordered`], reading the columns `reads` names. A name or a field
    /// in double quotes (R's `write.csv`, a spreadsheet quoting every field) is read without
    /// them.
    pub fn read_from_reading(
        r: impl BufRead,
        time_column: &str,
        reads: Reads<'_>,
        order: TimeOrder,
    ) -> Result<Table, LogError> {
        read_table(r, order, |line| {
            let names: Vec<String> = line
                .split(',')
                .map(|f| unquoted(f.trim()).to_string())
                .collect();
            let read: Vec<bool> = names
                .iter()
                .map(|n| match reads {
                    Reads::All => true,
                    Reads::Only(wanted) => n == time_column || wanted.contains(&n.as_str()),
                })
                .collect();
            let mut seen: Vec<&str> = Vec::new();
            for (name, _) in names.iter().zip(&read).filter(|(_, r)| **r) {
                check_column_name(name, &seen)?;
                seen.push(name);
            }
            let time = names.iter().position(|n| n == time_column).ok_or_else(|| {
                LogError::MissingNamedColumn {
                    expected: time_column.to_string(),
                    found_header: line.to_string(),
                }
            })?;
            Ok(Layout {
                names,
                time,
                read,
                unquote: true,
            })
        })
    }

    /// Reads `path`, plain or gzip-compressed (recognised by content), as
    /// [`Table::read_from_reading`] reads text; errors name the file.
    pub fn load_reading(
        path: &Path,
        time_column: &str,
        reads: Reads<'_>,
        order: TimeOrder,
    ) -> Result<Table, LogError> {
        read_file(path, |r| {
            Table::read_from_reading(r, time_column, reads, order)
        })
    }

    /// The first row whose time `time` is not after the row's before it, as the error
    /// [`TimeOrder::Increasing`] reports (its file line, the two times); `None` where time
    /// strictly increases.
    pub fn first_time_back(&self, time: &[f64]) -> Option<LogError> {
        let k = time.windows(2).position(|w| w[1] <= w[0])? + 1;
        Some(LogError::NonMonotonicTime {
            line: self.lines.get(k).copied().unwrap_or(k),
            previous: time[k - 1],
            current: time[k],
        })
    }

    /// The column of this name.
    pub fn column(&self, name: &str) -> Option<&[f64]> {
        self.names
            .iter()
            .position(|n| n == name)
            .map(|i| self.columns[i].as_slice())
    }

    /// Number of rows.
    pub fn len(&self) -> usize {
        self.lines.len()
    }

    pub fn is_empty(&self) -> bool {
        self.lines.is_empty()
    }
}

/// From this stamp on, s, a log's time is a wall clock's (Unix seconds, 1.7e9 in 2024):
/// 1e6 s is 11.6 days, more than any log runs from its own zero.
pub const WALL_CLOCK_S: f64 = 1e6;

/// Stamps of a wall clock (the first at [`WALL_CLOCK_S`] or beyond) read from the first
/// stamp's whole second, which keeps each stamp's place within a 10 ms grid and leaves the
/// numbers a log's length, not 1.7e9 s. At 1.7e9 s an f64 holds a stamp to 0.24 us; read back
/// to the microsecond (the finest a CAN logger writes), each stamp is the one its text gives.
/// Returns the whole second taken off, `None` (and `t` as it was) for stamps from their own
/// zero.
pub fn from_wall_clock(t: &mut [f64]) -> Option<f64> {
    let first = *t.first()?;
    if !first.is_finite() || first.abs() < WALL_CLOCK_S {
        return None;
    }
    let from = first.floor();
    t.iter_mut()
        .for_each(|v| *v = ((*v - from) * 1e6).round() / 1e6);
    Some(from)
}

/// Fills each run of missing samples (NaN) linearly between the samples on either side; a run
/// at the start or the end takes the nearest sample. Returns how many were filled, or `None`
/// when there is no sample at all to fill from. Interpolation, not zero or a hold, because a
/// dropout of a few samples in a smooth signal is best guessed by its neighbours, and a step
/// would look like an effect to the diagnosis.
pub fn fill_missing(values: &mut [f64]) -> Option<usize> {
    let first = fill_head(values)?;
    let mut filled = first;
    let mut last_good = first;
    for i in first + 1..values.len() {
        if values[i].is_nan() {
            continue;
        }
        let gap = i - last_good;
        for k in 1..gap {
            let s = k as f64 / gap as f64;
            values[last_good + k] = values[last_good] + s * (values[i] - values[last_good]);
            filled += 1;
        }
        last_good = i;
    }
    let tail = values[last_good];
    filled += values.len() - last_good - 1;
    values[last_good + 1..].fill(tail);
    Some(filled)
}

/// As [`fill_missing`], but each `nan` after the first sample takes the last sample before
/// it (a value that holds until the next comes, as a CAN signal does between its frames); the
/// ones before the first sample take the first. The count filled; `None` if all are `nan`.
pub fn hold_missing(values: &mut [f64]) -> Option<usize> {
    let first = fill_head(values)?;
    let mut filled = first;
    let mut last = values[first];
    for v in &mut values[first..] {
        if v.is_nan() {
            *v = last;
            filled += 1;
        } else {
            last = *v;
        }
    }
    Some(filled)
}

/// The `nan`s before the first sample set to it, [`fill_missing`]'s and [`hold_missing`]'s
/// rule alike: the index of that sample (as many were filled); `None` if all are `nan`.
fn fill_head(values: &mut [f64]) -> Option<usize> {
    let first = values.iter().position(|v| !v.is_nan())?;
    let head = values[first];
    values[..first].fill(head);
    Some(first)
}

/// The largest stamp the time column may hold, s: a Unix clock's seconds (1.7e9 in 2024) fit
/// until the year 2286, so a logger on the wall clock is read; stamps in milliseconds or
/// nanoseconds since 1970 (1.7e12, 1.7e18) do not.
pub const TIME_BOUND_S: f64 = 1e10;

/// The largest magnitude a column may hold and its unit, from the unit at the end of its name
/// (module doc). Generous on purpose: the bound is for garbage, not for physics.
pub fn bound_for(column: &str) -> (f64, &'static str) {
    if column == "t" {
        return (TIME_BOUND_S, "s");
    }
    let suffix = match column.rsplit_once('_') {
        Some((_, unit)) => unit.to_ascii_lowercase(),
        None => String::new(),
    };
    match suffix.as_str() {
        "s" => (1e6, "s"),
        "deg" => (1e6, "deg"),
        "rad" => (1e6, "rad"),
        "a" => (1e4, "A"),
        "v" => (1e4, "V"),
        "m" => (1e3, "m"),
        "n" => (1e6, "N"),
        _ => (1e12, "(no unit in the name)"),
    }
}

/// Opens `path`, unpacks gzip if its content is gzip, and reads it with `read`; every error
/// names the file, and a gzip stream cut short is said to be one.
fn read_file<T>(
    path: &Path,
    read: impl FnOnce(Box<dyn BufRead>) -> Result<T, LogError>,
) -> Result<T, LogError> {
    let file = File::open(path).map_err(|source| LogError::Io {
        path: Some(path.to_path_buf()),
        source,
    })?;
    let mut reader = BufReader::new(file);
    let is_gzip = reader
        .fill_buf()
        .map_err(|e| LogError::io(e).in_file(path))?
        .starts_with(&GZIP_MAGIC);
    let result = if is_gzip {
        // Multi-member, so logs appended gzip chunk by gzip chunk read whole.
        read(Box::new(BufReader::new(MultiGzDecoder::new(reader)))).map_err(|e| match e {
            LogError::Io { path: None, source }
                if source.kind() == io::ErrorKind::UnexpectedEof =>
            {
                LogError::TruncatedGzip
            }
            e => e,
        })
    } else {
        read(Box::new(reader))
    };
    result.map_err(|e| e.in_file(path))
}

/// A header as a reader takes it.
struct Layout {
    /// Every field's name, in file order.
    names: Vec<String>,
    /// The time column's field.
    time: usize,
    /// For each field, whether it is read.
    read: Vec<bool>,
    /// Fields in double quotes are read without them.
    unquote: bool,
}

impl Layout {
    /// Every field read, as written.
    fn every(names: Vec<String>, time: usize) -> Layout {
        Layout {
            read: vec![true; names.len()],
            names,
            time,
            unquote: false,
        }
    }
}

/// `field` without one pair of double quotes around it.
fn unquoted(field: &str) -> &str {
    field
        .strip_prefix('"')
        .and_then(|f| f.strip_suffix('"'))
        .unwrap_or(field)
}

/// The one CSV reader behind [`Log`] and [`Table`]: `header` checks the first line that is
/// neither blank nor a comment and says which fields are read and which is the time.
fn read_table(
    mut r: impl BufRead,
    order: TimeOrder,
    header: impl FnOnce(&str) -> Result<Layout, LogError>,
) -> Result<Table, LogError> {
    let mut text = String::new();
    let mut line_no = 0;
    let mut comments = Vec::new();

    let layout = loop {
        line_no += 1;
        if next_line(&mut r, &mut text, line_no)? {
            return Err(LogError::Empty);
        }
        let line = if line_no == 1 {
            text.trim_start_matches('\u{feff}')
        } else {
            &text
        };
        let line = line.trim();
        if let Some(comment) = line.strip_prefix('#') {
            comments.push(comment.trim().to_string());
        } else if !line.is_empty() {
            if let Some(separator) = foreign_separator(line) {
                return Err(LogError::Separator {
                    separator,
                    header: line.to_string(),
                });
            }
            break header(line)?;
        }
    };
    let Layout {
        names: fields,
        time: time_field,
        read,
        unquote,
    } = layout;
    // Each field's slot among the columns read.
    let slots: Vec<Option<usize>> = read
        .iter()
        .scan(0, |next, &r| {
            let slot = r.then_some(*next);
            *next += usize::from(r);
            Some(slot)
        })
        .collect();
    let time = slots[time_field].unwrap_or_default();
    let (read_names, unread): (Vec<_>, Vec<_>) = fields.iter().zip(&read).partition(|(_, r)| **r);
    let names: Vec<String> = read_names.into_iter().map(|(n, _)| n.clone()).collect();
    let bounds: Vec<(f64, &'static str)> = names
        .iter()
        .enumerate()
        .map(|(i, n)| {
            if i == time {
                bound_for("t")
            } else {
                bound_for(n)
            }
        })
        .collect();

    let mut table = Table {
        columns: vec![Vec::new(); names.len()],
        names,
        unread: unread.into_iter().map(|(n, _)| n.clone()).collect(),
        lines: Vec::new(),
        comments,
    };
    let mut values = vec![0.0; table.names.len()];
    loop {
        line_no += 1;
        if next_line(&mut r, &mut text, line_no)? {
            break;
        }
        let line = text.trim();
        if line.is_empty() {
            continue;
        }
        let found = line.split(',').count();
        if found != fields.len() {
            return Err(LogError::WrongFieldCount {
                line: line_no,
                expected: fields.len(),
                found,
            });
        }
        let read_fields = line
            .split(',')
            .zip(&slots)
            .filter_map(|(field, slot)| slot.map(|i| (field, i)));
        for ((field, i), value) in read_fields.zip(&mut values) {
            let name = &table.names[i];
            let field = field.trim();
            let field = if unquote { unquoted(field) } else { field };
            *value = match parse_value(field, line_no, name) {
                // A table's time may be a date and time (a logger stamping rows with its
                // clock's `isoformat()`).
                Err(e) if unquote && i == time => unix_seconds(field).ok_or(e)?,
                v => v?,
            };
            let (bound, unit) = bounds[i];
            if value.abs() > bound {
                return Err(LogError::OutOfBounds {
                    line: line_no,
                    column: name.clone(),
                    value: *value,
                    bound,
                    unit,
                });
            }
        }
        let t = values[time];
        if t.is_nan() {
            return Err(LogError::NonFiniteTime { line: line_no });
        }
        if order == TimeOrder::Increasing
            && let Some(&previous) = table.columns[time].last()
            && t <= previous
        {
            return Err(LogError::NonMonotonicTime {
                line: line_no,
                previous,
                current: t,
            });
        }
        for (column, &v) in table.columns.iter_mut().zip(&values) {
            column.push(v);
        }
        table.lines.push(line_no);
    }
    Ok(table)
}

/// The separator of a header that has no comma but splits at `;` or a tab: `None` for a
/// comma-separated header, and for a one-column one.
fn foreign_separator(header: &str) -> Option<char> {
    if header.contains(',') {
        return None;
    }
    [';', '\t'].into_iter().find(|c| header.contains(*c))
}

/// The longest line the reader takes, bytes: a row of thousands of columns fits, and a file
/// that is not a log (no line end for gigabytes) is refused after this much, not held whole.
pub const MAX_LINE_BYTES: usize = 64 * 1024;

/// Reads line `line_no` into `text`; `true` at the end of the input.
fn next_line(r: &mut impl BufRead, text: &mut String, line_no: usize) -> Result<bool, LogError> {
    match read_line_capped(r, text, MAX_LINE_BYTES).map_err(LogError::io)? {
        Capped::Line => Ok(false),
        Capped::End => Ok(true),
        Capped::TooLong => Err(LogError::LineTooLong {
            line: line_no,
            max_bytes: MAX_LINE_BYTES,
        }),
    }
}

fn is_gz_name(path: &Path) -> bool {
    path.extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("gz"))
}

/// Splits and checks a header line; returns the column names.
fn parse_header(line: &str) -> Result<Vec<String>, LogError> {
    let names: Vec<String> = line.split(',').map(|f| f.trim().to_string()).collect();
    for expected in REQUIRED_COLUMNS {
        if !names.iter().any(|n| n == expected) {
            return Err(LogError::MissingColumn {
                expected,
                found_header: line.to_string(),
            });
        }
    }
    if names.iter().zip(REQUIRED_COLUMNS).any(|(n, r)| n != r) {
        return Err(LogError::WrongColumnOrder { found: names });
    }
    let mut seen: Vec<&str> = REQUIRED_COLUMNS.to_vec();
    for name in &names[REQUIRED_COLUMNS.len()..] {
        check_column_name(name, &seen)?;
        seen.push(name);
    }
    Ok(names)
}

fn check_column_name(name: &str, earlier: &[&str]) -> Result<(), LogError> {
    let reason = if name.is_empty() {
        Some("empty")
    } else if earlier.contains(&name) {
        Some("the column appears twice")
    } else if name.contains([',', '"']) || name.chars().any(char::is_control) {
        Some("names cannot contain commas, quotes or control characters")
    } else if name.trim() != name {
        Some("names cannot start or end with whitespace")
    } else {
        None
    };
    match reason {
        Some(reason) => Err(LogError::BadColumnName {
            name: name.to_string(),
            reason,
        }),
        None => Ok(()),
    }
}

/// Seconds since 1970-01-01 00:00 UTC of a date and time as ISO 8601 writes them
/// (`2026-12-07 18:10:01.123456`, or with `T` between the date and the time), with an
/// optional `Z` or `+01:00`-style offset; a time without one is read as UTC (a log's stamps
/// count only against each other). A time of day alone (`18:10:01.25`) is seconds since its
/// midnight. `None` for anything else.
fn unix_seconds(text: &str) -> Option<f64> {
    let Some((date, time)) = text.split_once(['T', ' ']) else {
        return seconds_of_day(text);
    };
    let mut ymd = date.split('-');
    let year: i64 = digits(ymd.next()?)?.parse().ok()?;
    let month: i64 = digits(ymd.next()?)?.parse().ok()?;
    let day: i64 = digits(ymd.next()?)?.parse().ok()?;
    if ymd.next().is_some()
        || !(1..=9999).contains(&year)
        || !(1..=12).contains(&month)
        || !(1..=31).contains(&day)
    {
        return None;
    }
    // Days from 1970-01-01 in the proleptic Gregorian calendar, the year counted from March
    // so that the leap day falls at its end.
    let y = if month <= 2 { year - 1 } else { year };
    let era = y.div_euclid(400);
    let year_of_era = y - 400 * era;
    let day_of_year = (153 * ((month + 9) % 12) + 2) / 5 + day - 1;
    let day_of_era = 365 * year_of_era + year_of_era / 4 - year_of_era / 100 + day_of_year;
    let days = 146_097 * era + day_of_era - 719_468;
    Some((86_400 * days) as f64 + seconds_of_day(time)?)
}

/// Seconds since midnight UTC of `HH:MM:SS[.fraction]` with an optional `Z` or
/// `+01:00`-style offset (before midnight, or a day's worth past it, where the offset
/// carries it over).
fn seconds_of_day(time: &str) -> Option<f64> {
    let (clock, offset_s) = match time.strip_suffix('Z') {
        Some(clock) => (clock, 0),
        None => match time.rfind(['+', '-']) {
            Some(at) => {
                let (hours, minutes) = time[at + 1..].split_once(':')?;
                let size = 3600 * i64::from(digits(hours)?.parse::<u8>().ok()?)
                    + 60 * i64::from(digits(minutes)?.parse::<u8>().ok()?);
                (
                    &time[..at],
                    if &time[at..=at] == "-" { -size } else { size },
                )
            }
            None => (time, 0),
        },
    };
    let mut hms = clock.split(':');
    let hour: i64 = digits(hms.next()?)?.parse().ok()?;
    let minute: i64 = digits(hms.next()?)?.parse().ok()?;
    let second = hms.next()?;
    let second: f64 = second
        .chars()
        .all(|c| c.is_ascii_digit() || c == '.')
        .then(|| second.parse().ok())??;
    if hms.next().is_some() || hour > 23 || minute > 59 || second >= 61.0 {
        return None;
    }
    Some((3600 * hour + 60 * minute - offset_s) as f64 + second)
}

/// `text` where it is one or more ASCII digits.
fn digits(text: &str) -> Option<&str> {
    (!text.is_empty() && text.bytes().all(|b| b.is_ascii_digit())).then_some(text)
}

fn parse_value(field: &str, line: usize, column: &str) -> Result<f64, LogError> {
    // An empty field is a missing sample, as a spreadsheet or pandas (`to_csv`) writes one.
    if field.is_empty() {
        return Ok(f64::NAN);
    }
    match field.parse::<f64>() {
        Ok(v) if !v.is_infinite() => Ok(v),
        _ => Err(LogError::BadNumber {
            line,
            column: column.to_string(),
            text: field.to_string(),
        }),
    }
}

/// Fixed decimals; `nan` for a missing sample; no `-0.0000` for tiny negative noise, so files of
/// the same run diff cleanly.
fn push_fixed(out: &mut String, v: f64, decimals: usize) {
    use fmt::Write;
    if v.is_nan() {
        out.push_str("nan");
        return;
    }
    let start = out.len();
    // Writing to a String cannot fail.
    let _ = write!(out, "{v:.decimals$}");
    if out[start..].starts_with('-') && out[start + 1..].bytes().all(|b| b == b'0' || b == b'.') {
        out.remove(start);
    }
}

/// Shortest text that reads back to the same f64: extra columns carry any quantity, so there is
/// no resolution to round to. Very large or small magnitudes use an exponent to stay short.
fn push_exact(out: &mut String, v: f64) {
    use fmt::Write;
    if v.is_nan() {
        out.push_str("nan");
    } else if v == 0.0 || (1e-4..1e15).contains(&v.abs()) {
        // Writing to a String cannot fail.
        let _ = write!(out, "{v}");
    } else {
        let _ = write!(out, "{v:e}");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample_log(extra: &[&str]) -> Log {
        let mut log = Log::with_extra_columns(extra);
        for i in 0..200 {
            let t = i as f64 * 0.0005;
            let row = Row {
                t,
                ref_sw_deg: 10.0 * (t * 7.0).sin(),
                sw_deg: if i == 17 {
                    f64::NAN
                } else {
                    9.9 * (t * 7.0 - 0.1).sin()
                },
                motor_rad: 141.371_669 * (t * 7.0 - 0.1).sin(),
                current_a: 20.0 * (t * 30.0).cos() - 1e-9,
            };
            let extras: Vec<f64> = (0..extra.len())
                .map(|k| (k as f64 + 1.0) * 1.234_567_890_123e-7 * i as f64)
                .collect();
            log.push(row, &extras);
        }
        log
    }

    fn read_str(text: &str) -> Result<Log, LogError> {
        Log::read_from(text.as_bytes())
    }

    /// Equal up to the rounding of the writer; NaN equals NaN.
    fn assert_close(a: &[f64], b: &[f64], tol: f64) {
        assert_eq!(a.len(), b.len());
        for (i, (x, y)) in a.iter().zip(b).enumerate() {
            assert!(
                (x.is_nan() && y.is_nan()) || (x - y).abs() <= tol,
                "sample {i}: {x} vs {y}"
            );
        }
    }

    fn assert_round_trip(original: &Log, back: &Log) {
        assert_close(&original.t, &back.t, 0.6e-6);
        assert_close(&original.ref_sw_deg, &back.ref_sw_deg, 0.6e-4);
        assert_close(&original.sw_deg, &back.sw_deg, 0.6e-4);
        assert_close(&original.motor_rad, &back.motor_rad, 0.6e-5);
        assert_close(&original.current_a, &back.current_a, 0.6e-4);
        assert_eq!(original.extra.len(), back.extra.len());
        for ((name_a, a), (name_b, b)) in original.extra.iter().zip(&back.extra) {
            assert_eq!(name_a, name_b);
            // An extra column with a unit keeps its unit's decimals; one without is lossless.
            let tol = decimals_for(name_a).map_or(0.0, |d| 0.6 * 10f64.powi(-(d as i32)));
            assert_close(a, b, tol);
        }
    }

    #[test]
    fn csv_file_round_trips() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("nested/dir/run.csv");
        let log = sample_log(&["voltage_v"]);
        log.save(&path).expect("save");
        let text = fs::read_to_string(&path).expect("read back");
        assert!(text.starts_with("t,ref_sw_deg,sw_deg,motor_rad,current_a,voltage_v\n"));
        assert_round_trip(&log, &Log::load(&path).expect("load"));
    }

    #[test]
    fn gzip_file_round_trips_and_is_detected_by_content() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("run.csv.gz");
        let log = sample_log(&["voltage_v", "speed_rad_s"]);
        log.save(&path).expect("save");
        let bytes = fs::read(&path).expect("read back");
        assert!(bytes.starts_with(&GZIP_MAGIC));
        assert_round_trip(&log, &Log::load(&path).expect("load"));

        let renamed = dir.path().join("run.csv");
        fs::rename(&path, &renamed).expect("rename");
        assert_round_trip(&log, &Log::load(&renamed).expect("load by content"));
    }

    #[test]
    fn save_leaves_no_partial_file() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("run.csv");
        sample_log(&[]).save(&path).expect("save");
        let names: Vec<_> = fs::read_dir(dir.path()).expect("list").flatten().collect();
        assert_eq!(names.len(), 1);
    }

    /// A simulated run's f32 signals in extra columns are written with their unit's decimals,
    /// as the required columns are, not as the f32's 16 digits; a state code is kept exact.
    #[test]
    fn extra_columns_with_a_unit_get_its_fixed_decimals() {
        let mut log = Log::with_extra_columns(&["current_setpoint_a", "voltage_v", "faults"]);
        let row = Row {
            t: 0.0,
            ref_sw_deg: 0.0,
            sw_deg: 0.0,
            motor_rad: 0.0,
            current_a: 0.0,
        };
        let volts = f64::from(-9.090_424_f32);
        assert_eq!(volts.to_string(), "-9.090423583984375");
        log.push(row, &[f64::from(1.234_567_8_f32), volts, 3.0]);
        let mut out = Vec::new();
        log.write_to(&mut out).expect("write");
        let text = String::from_utf8(out).expect("utf-8");
        assert_eq!(
            text.lines().nth(1),
            Some("0.000000,0.0000,0.0000,0.00000,0.0000,1.2346,-9.090,3"),
            "{text}"
        );
    }

    #[test]
    fn extra_columns_are_kept_by_name_and_order() {
        let text = "t,ref_sw_deg,sw_deg,motor_rad,current_a,voltage_v,temp_c\n\
                    0,1,2,3,4,23.9,40\n\
                    0.01,1,2,3,4,24.1,41\n";
        let log = read_str(text).expect("valid log");
        assert_eq!(
            log.extra_names().collect::<Vec<_>>(),
            ["voltage_v", "temp_c"]
        );
        assert_eq!(log.extra("temp_c"), Some(&[40.0, 41.0][..]));
        assert_eq!(log.extra("voltage_v"), Some(&[23.9, 24.1][..]));
        assert_eq!(log.extra("nope"), None);
        let mut out = Vec::new();
        log.write_to(&mut out).expect("write");
        assert_eq!(
            read_str(&String::from_utf8(out).expect("utf-8")).expect("re-read"),
            log
        );
    }

    #[test]
    fn comments_blank_lines_crlf_whitespace_and_bom_are_accepted() {
        let text = "\u{feff}# recorded on the car\r\n\r\n  # operator: test\r\n\
                    t , ref_sw_deg,sw_deg ,motor_rad,current_a\r\n\
                    0.0, 1.5 ,\t2,3,4\r\n\
                    0.5,1,NaN,3,-4e-1\r\n\r\n\r\n";
        let log = read_str(text).expect("valid log");
        assert_eq!(log.len(), 2);
        assert_eq!(
            log.row(0),
            Some(Row {
                t: 0.0,
                ref_sw_deg: 1.5,
                sw_deg: 2.0,
                motor_rad: 3.0,
                current_a: 4.0
            })
        );
        assert!(log.sw_deg[1].is_nan());
        // Parsing is exact, so compare bits rather than within a tolerance.
        assert_eq!(log.current_a[1].to_bits(), (-0.4f64).to_bits());
    }

    #[test]
    fn missing_required_column_is_named() {
        let err = read_str("t,ref_sw_deg,sw_deg,current_a\n0,1,2,3\n").expect_err("must fail");
        assert!(
            matches!(
                err,
                LogError::MissingColumn {
                    expected: "motor_rad",
                    ..
                }
            ),
            "{err:?}"
        );
        assert!(err.to_string().contains("motor_rad"), "{err}");
    }

    #[test]
    fn required_columns_out_of_order_are_refused() {
        let err = read_str("t,sw_deg,ref_sw_deg,motor_rad,current_a\n").expect_err("must fail");
        assert!(matches!(err, LogError::WrongColumnOrder { .. }), "{err:?}");
        let err = read_str("x,t,ref_sw_deg,sw_deg,motor_rad,current_a\n").expect_err("must fail");
        assert!(matches!(err, LogError::WrongColumnOrder { .. }), "{err:?}");
    }

    #[test]
    fn duplicate_extra_column_is_refused() {
        let err = read_str("t,ref_sw_deg,sw_deg,motor_rad,current_a,v,v\n").expect_err("must fail");
        assert!(matches!(err, LogError::BadColumnName { .. }), "{err:?}");
    }

    #[test]
    fn bad_number_reports_line_and_column() {
        let text =
            "# comment\nt,ref_sw_deg,sw_deg,motor_rad,current_a\n0,1,2,3,4\n\n0.1,1,2x,3,4\n";
        let err = read_str(text).expect_err("must fail");
        match &err {
            LogError::BadNumber { line, column, text } => {
                assert_eq!((*line, column.as_str(), text.as_str()), (5, "sw_deg", "2x"));
            }
            other => panic!("unexpected {other:?}"),
        }
        assert!(
            err.to_string().starts_with("line 5, column `sw_deg`"),
            "{err}"
        );
    }

    #[test]
    fn infinity_in_data_is_refused() {
        let text = "t,ref_sw_deg,sw_deg,motor_rad,current_a\n0,1,2,3,inf\n";
        let err = read_str(text).expect_err("must fail");
        assert!(
            matches!(err, LogError::BadNumber { line: 2, .. }),
            "{err:?}"
        );
    }

    #[test]
    fn wrong_field_count_is_reported() {
        let text = "t,ref_sw_deg,sw_deg,motor_rad,current_a\n0,1,2,3\n";
        let err = read_str(text).expect_err("must fail");
        assert!(
            matches!(
                err,
                LogError::WrongFieldCount {
                    line: 2,
                    expected: 5,
                    found: 4
                }
            ),
            "{err:?}"
        );
    }

    #[test]
    fn time_must_be_finite_and_strictly_increasing() {
        let head = "t,ref_sw_deg,sw_deg,motor_rad,current_a\n";
        let err = read_str(&format!("{head}0,1,2,3,4\n0,1,2,3,4\n")).expect_err("repeated t");
        assert!(
            matches!(err, LogError::NonMonotonicTime { line: 3, .. }),
            "{err:?}"
        );
        let err = read_str(&format!("{head}nan,1,2,3,4\n")).expect_err("nan t");
        assert!(
            matches!(err, LogError::NonFiniteTime { line: 2 }),
            "{err:?}"
        );
        let err = read_str(&format!("{head}inf,1,2,3,4\n")).expect_err("infinite t");
        assert!(
            matches!(err, LogError::BadNumber { line: 2, .. }),
            "{err:?}"
        );
    }

    #[test]
    fn an_empty_field_is_a_missing_sample_and_an_empty_time_is_refused() {
        let head = "t,ref_sw_deg,sw_deg,motor_rad,current_a\n";
        let log = read_str(&format!("{head}0,1,,3,4\n0.1,1,2,3, \n")).expect("valid");
        assert!(log.sw_deg[0].is_nan() && log.current_a[1].is_nan());
        assert_eq!((log.sw_deg[1], log.current_a[0]), (2.0, 4.0));
        let err = read_str(&format!("{head},1,2,3,4\n")).expect_err("empty t");
        assert!(
            matches!(err, LogError::NonFiniteTime { line: 2 }),
            "{err:?}"
        );
    }

    #[test]
    fn a_table_read_as_stamped_keeps_stamps_that_go_back_and_says_where() {
        let text = "t,x\n0.000,1\n0.0021,2\n0.0019,3\n0.003,4\n";
        let err = Table::read_from(text.as_bytes(), "t").expect_err("time back");
        assert!(
            matches!(err, LogError::NonMonotonicTime { line: 4, .. }),
            "{err:?}"
        );
        let table = Table::read_from_ordered(text.as_bytes(), "t", TimeOrder::AsStamped)
            .expect("read as stamped");
        let t = table.column("t").expect("t").to_vec();
        assert_eq!(t, [0.0, 0.0021, 0.0019, 0.003]);
        assert_eq!(table.column("x"), Some(&[1.0, 2.0, 3.0, 4.0][..]));
        let back = table.first_time_back(&t).expect("goes back");
        assert_eq!(back.to_string(), err.to_string());
        assert!(table.first_time_back(&[0.0, 0.001, 0.002, 0.003]).is_none());
        let nan = "t,x\n0,1\nnan,2\n";
        let err =
            Table::read_from_ordered(nan.as_bytes(), "t", TimeOrder::AsStamped).expect_err("nan t");
        assert!(
            matches!(err, LogError::NonFiniteTime { line: 3 }),
            "{err:?}"
        );
    }

    #[test]
    fn a_line_past_the_length_cap_is_refused_with_its_number() {
        let mut text = String::from("t,ref_sw_deg,sw_deg,motor_rad,current_a\n0,0,0,0,0\n");
        text.push_str(&"0".repeat(4 * 1024 * 1024));
        text.push('\n');
        match read_str(&text) {
            Err(LogError::LineTooLong { line, max_bytes }) => {
                assert_eq!((line, max_bytes), (3, MAX_LINE_BYTES));
            }
            other => panic!("{other:?}"),
        }
        // A header without a line end for longer than the cap is refused as well.
        let zeros = "\0".repeat(MAX_LINE_BYTES + 1);
        assert!(matches!(
            read_str(&zeros),
            Err(LogError::LineTooLong { line: 1, .. })
        ));
    }

    #[test]
    fn only_comments_is_empty_but_header_alone_is_an_empty_log() {
        assert!(matches!(read_str("# nothing\n\n"), Err(LogError::Empty)));
        assert!(matches!(read_str(""), Err(LogError::Empty)));
        let log = read_str("t,ref_sw_deg,sw_deg,motor_rad,current_a\n").expect("header only");
        assert!(log.is_empty());
    }

    #[test]
    fn comment_after_header_is_an_error_not_skipped() {
        let text = "t,ref_sw_deg,sw_deg,motor_rad,current_a\n# late\n";
        assert!(matches!(
            read_str(text),
            Err(LogError::WrongFieldCount { line: 2, .. })
        ));
    }

    #[test]
    fn writer_refuses_what_the_reader_would_refuse() {
        let mut log = sample_log(&[]);
        log.t[5] = log.t[4] + 1e-7;
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::TimeNotWritable { row: 5, .. })
        ));

        let mut log = sample_log(&["v"]);
        log.extra[0].1.pop();
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::ColumnLength { .. })
        ));

        let mut log = sample_log(&[]);
        log.current_a[3] = f64::INFINITY;
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::InfiniteValue { row: 3, .. })
        ));

        let log = Log::with_extra_columns(&["a,b"]);
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::BadColumnName { .. })
        ));
    }

    #[test]
    fn load_errors_name_the_file_and_keep_the_cause() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("broken.csv");
        fs::write(
            &path,
            "t,ref_sw_deg,sw_deg,motor_rad,current_a\n0,1,2,3,x\n",
        )
        .expect("write");
        let err = Log::load(&path).expect_err("must fail");
        assert!(
            matches!(err.root(), LogError::BadNumber { line: 2, .. }),
            "{err:?}"
        );
        assert!(err.to_string().contains("broken.csv: line 2"), "{err}");

        let missing = Log::load(&dir.path().join("absent.csv")).expect_err("must fail");
        assert!(
            matches!(missing, LogError::Io { path: Some(_), .. }),
            "{missing:?}"
        );
    }

    #[test]
    fn tiny_negative_values_are_written_without_minus_sign() {
        let mut log = Log::new();
        log.push(
            Row {
                t: 0.0,
                ref_sw_deg: -1e-9,
                sw_deg: -0.0,
                motor_rad: -2e-7,
                current_a: -0.00004,
            },
            &[],
        );
        let mut out = Vec::new();
        log.write_to(&mut out).expect("write");
        let text = String::from_utf8(out).expect("utf-8");
        assert_eq!(
            text.lines().nth(1),
            Some("0.000000,0.0000,0.0000,0.00000,0.0000")
        );
    }

    #[test]
    fn values_beyond_their_physical_bound_are_refused_with_line_and_column() {
        let head = "t,ref_sw_deg,sw_deg,motor_rad,current_a,voltage_v,gain\n0,1,2,3,4,5,6\n";
        for (row, column) in [
            ("0.1,1e300,2,3,4,5,6", "ref_sw_deg"),
            ("0.1,1,2,-2e6,4,5,6", "motor_rad"),
            ("0.1,1,2,3,1e5,5,6", "current_a"),
            ("0.1,1,2,3,4,2e4,6", "voltage_v"),
            ("0.1,1,2,3,4,5,1e13", "gain"),
            ("1e300,1,2,3,4,5,6", "t"),
            ("1.7e12,1,2,3,4,5,6", "t"),
        ] {
            let err = read_str(&format!("{head}{row}\n")).expect_err(row);
            assert!(
                matches!(&err, LogError::OutOfBounds { line: 3, column: c, .. } if c == column),
                "{row}: {err:?}"
            );
            assert!(err.to_string().contains("physical bound"), "{err}");
        }
        // Within the bounds: a long log's motor angle, a large unitless value.
        read_str(&format!("{head}0.1,90,-90,9e5,-20,24,9e11\n")).expect("in bounds");
        // A wall clock's stamps (Unix seconds).
        read_str(&format!("{head}1733300000.01,90,-90,9e5,-20,24,9e11\n")).expect("Unix time");
    }

    #[test]
    fn bounds_follow_the_unit_at_the_end_of_the_name() {
        assert_eq!(bound_for("t"), (1e10, "s"));
        assert_eq!(bound_for("t_s"), (1e6, "s"));
        assert_eq!(bound_for("vir_V"), (1e4, "V"));
        assert_eq!(bound_for("current_setpoint_a"), (1e4, "A"));
        assert_eq!(bound_for("qm_m"), (1e3, "m"));
        assert_eq!(bound_for("gain").0, 1e12);
    }

    #[test]
    fn a_wall_clocks_stamps_are_read_from_their_first_whole_second_to_the_microsecond() {
        let mut t = vec![1_733_300_000.017_61, 1_733_300_000.027_61, 1_733_300_001.5];
        assert_eq!(from_wall_clock(&mut t), Some(1_733_300_000.0));
        assert_eq!(t, vec![0.017_61, 0.027_61, 1.5]);
        let mut own = vec![0.01, 0.02, 999_999.0];
        assert_eq!(from_wall_clock(&mut own), None);
        assert_eq!(own, vec![0.01, 0.02, 999_999.0]);
        assert_eq!(from_wall_clock(&mut []), None);
    }

    #[test]
    fn writer_refuses_a_value_beyond_its_bound() {
        let mut log = sample_log(&["voltage_v"]);
        log.extra[0].1[7] = 1e300;
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::ValueOutOfBounds { row: 7, .. })
        ));
        // A wall clock's Unix seconds are written; milliseconds since 1970 are not.
        let mut log = sample_log(&[]);
        for t in &mut log.t {
            *t += 1.7e9;
        }
        assert!(log.write_to(Vec::new()).is_ok());
        for t in &mut log.t {
            *t *= 1e3;
        }
        assert!(matches!(
            log.write_to(Vec::new()),
            Err(LogError::ValueOutOfBounds { row: 0, column, .. }) if column == "t"
        ));
    }

    #[test]
    fn a_truncated_gzip_log_is_named_truncated() {
        let dir = tempfile::tempdir().expect("temp dir");
        let path = dir.path().join("run.csv.gz");
        sample_log(&[]).save(&path).expect("save");
        let bytes = fs::read(&path).expect("read back");
        fs::write(&path, &bytes[..bytes.len() / 2]).expect("cut");
        let err = Log::load(&path).expect_err("must fail");
        assert!(matches!(err.root(), LogError::TruncatedGzip), "{err:?}");
        assert!(
            err.to_string().contains("run.csv.gz: truncated gzip"),
            "{err}"
        );
    }

    #[test]
    fn a_table_reads_any_names_by_the_log_rules() {
        let text = "# EMPS\nt_s,qg_m,vir_V\n0,0.1,1\n0.001,nan,2\n0.002,0.3,3\n";
        let table = Table::read_from(text.as_bytes(), "t_s").expect("valid");
        assert_eq!(table.len(), 3);
        assert_eq!(table.lines, [3, 4, 5]);
        assert!(table.column("qg_m").expect("column")[1].is_nan());
        assert_eq!(table.column("vir_V"), Some(&[1.0, 2.0, 3.0][..]));

        let err = Table::read_from(text.as_bytes(), "t").expect_err("no such time column");
        assert!(
            matches!(err, LogError::MissingNamedColumn { .. }),
            "{err:?}"
        );
        let back = "t_s,x\n0,1\n0.002,1\n0.001,1\n";
        let err = Table::read_from(back.as_bytes(), "t_s").expect_err("time back");
        assert!(
            matches!(err, LogError::NonMonotonicTime { line: 4, .. }),
            "{err:?}"
        );
    }

    #[test]
    fn a_table_read_for_some_columns_skips_the_others_unread() {
        let read_x = |text: &str| {
            Table::read_from_reading(
                text.as_bytes(),
                "t",
                Reads::Only(&["x"]),
                TimeOrder::Increasing,
            )
        };
        // pandas' row index under an empty name, a state as text, a comma at the line's end.
        let text = ",t,x,state,\n0,0.0,1,AS_READY,\n1,0.01,2,AS_DRIVING,\n";
        let table = read_x(text).expect("the columns read are valid");
        assert_eq!(table.names, ["t", "x"]);
        assert_eq!(table.column("x"), Some(&[1.0, 2.0][..]));
        assert_eq!(table.unread, ["", "state", ""]);
        // Every column read: the unnamed one is refused, as before.
        let err = Table::read_from(text.as_bytes(), "t").expect_err("an empty name");
        assert!(matches!(err, LogError::BadColumnName { .. }), "{err:?}");
        // A bad number in a column read is still refused, with its line.
        let err = read_x(",t,x\n0,0.0,1\n1,0.01,y\n").expect_err("a bad number");
        assert!(
            matches!(err, LogError::BadNumber { line: 3, .. }),
            "{err:?}"
        );
        // A column read twice is ambiguous.
        let err = read_x("t,x,x\n0,1,2\n").expect_err("x twice");
        assert!(matches!(err, LogError::BadColumnName { .. }), "{err:?}");
    }

    #[test]
    fn a_date_and_time_is_read_as_unix_seconds() {
        // 2026-12-07 18:10:01 UTC is 1 796 667 001 s (date -u -d '2026-12-07 18:10:01' +%s).
        let at = 1_796_667_001.0;
        for (text, expected) in [
            ("2026-12-07 18:10:01", at),
            ("2026-12-07T18:10:01.25", at + 0.25),
            ("2026-12-07T18:10:01.000123Z", at + 0.000123),
            ("2026-12-07T19:10:01+01:00", at),
            ("2026-12-07T13:40:01-04:30", at),
            ("1970-01-01 00:00:00", 0.0),
            ("2024-02-29 00:00:00", 1_709_164_800.0),
            ("2000-03-01 00:00:00", 951_868_800.0),
            ("18:10:01.5", 65_401.5),
        ] {
            let read = unix_seconds(text).unwrap_or(f64::NAN);
            assert!((read - expected).abs() < 1e-6, "{text}: {read}");
        }
        for text in [
            "2026-12-07",
            "18:10",
            "2026-13-07 18:10:01",
            "2026-12-07 24:00:00",
            "2026-12-07 18:10:1e1",
            "2026-12-07 18:10:01:02",
            "2026-12-07T18:10:01+0100",
            "today 18:10:01",
            "10000-01-01 00:00:00",
            "9223372036854775807-01-01 00:00:00",
            "2026-12-07 99999999999999999999:00:00",
        ] {
            assert_eq!(unix_seconds(text), None, "{text}");
        }
        let text = "t,x\n2026-12-07 18:10:01.00,1\n2026-12-07 18:10:01.01,2\n";
        let table = Table::read_from(text.as_bytes(), "t").expect("stamps of a clock");
        let t = table.column("t").expect("t");
        assert!((t[1] - t[0] - 0.01).abs() < 1e-6, "{t:?}");
        // A date is a stamp, not a value: elsewhere it is refused, as is any text.
        let text = "t,x\n0,2026-12-07 18:10:01\n";
        let err = Table::read_from(text.as_bytes(), "t").expect_err("a date as x");
        assert!(matches!(err, LogError::BadNumber { .. }), "{err:?}");
    }

    #[test]
    fn no_text_makes_a_reader_panic() {
        // Short texts drawn from the characters the readers look at (separators, quotes,
        // signs, a date's and a clock's marks, comments, line ends), each read every way:
        // any may be refused, none may panic.
        const ALPHABET: &[u8] = b"0123456789,,,\"-+:.TZ e\n\n#;tx_ab";
        let mut state = 0x2545_f491_4f6c_dd1d_u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for _ in 0..20_000 {
            let len = (next() % 64) as usize;
            let text: String = (0..len)
                .map(|_| char::from(ALPHABET[(next() % ALPHABET.len() as u64) as usize]))
                .collect();
            // Half with a header the readers take, half with whatever came.
            let text = if next() % 2 == 0 {
                format!("t,x\n{text}")
            } else {
                text
            };
            let _ = Table::read_from_reading(
                text.as_bytes(),
                "t",
                Reads::Only(&["x"]),
                TimeOrder::AsStamped,
            );
            let _ = Table::read_from(text.as_bytes(), "t");
            let _ = read_str(&text);
            for field in text.split([',', '\n']) {
                let _ = unix_seconds(field);
            }
        }
    }

    #[test]
    fn a_table_reads_names_and_fields_in_double_quotes_without_them() {
        let text = "\"t\",\"x\"\n\"0\",\"1.5\"\n0.01,2\n";
        let table = Table::read_from(text.as_bytes(), "t").expect("quoted");
        assert_eq!(table.names, ["t", "x"]);
        assert_eq!(table.column("x"), Some(&[1.5, 2.0][..]));
        // The project's own format is written without quotes and read so.
        assert!(read_str("\"t\",ref_sw_deg,sw_deg,motor_rad,current_a\n").is_err());
    }

    #[test]
    fn a_header_split_by_semicolons_or_tabs_is_named_so() {
        for (text, separator) in [
            ("t;ref_sw_deg;sw_deg;current_a\n0;1,5;1,4;0,2\n", ';'),
            ("t\tref_sw_deg\tsw_deg\tcurrent_a\n0\t1.5\t1.4\t0.2\n", '\t'),
        ] {
            let err = read_str(text).expect_err("not comma-separated");
            assert!(
                matches!(err, LogError::Separator { separator: s, .. } if s == separator),
                "{err:?}"
            );
            let err = Table::read_from(text.as_bytes(), "t").expect_err("not comma-separated");
            assert!(
                matches!(err, LogError::Separator { separator: s, .. } if s == separator),
                "{err:?}"
            );
            let shown = err.to_string();
            assert!(shown.contains("comma-separated"), "{shown}");
        }
        // A one-column table and a comma-separated header with a `;` in a name are not
        // taken for another separator.
        assert!(Table::read_from("t\n0\n1\n".as_bytes(), "t").is_ok());
        let err = Table::read_from("t,a;b\n0,1\n".as_bytes(), "t");
        assert!(!matches!(err, Err(LogError::Separator { .. })), "{err:?}");
    }

    #[test]
    fn missing_samples_are_filled_between_neighbours_and_counted() {
        let nan = f64::NAN;
        let mut v = [nan, 1.0, nan, nan, 4.0, 5.0, nan];
        assert_eq!(fill_missing(&mut v), Some(4));
        assert_eq!(v, [1.0, 1.0, 2.0, 3.0, 4.0, 5.0, 5.0]);
        let mut clean = [1.0, 2.0];
        assert_eq!(fill_missing(&mut clean), Some(0));
        assert_eq!(fill_missing(&mut [nan, nan]), None);
        assert_eq!(fill_missing(&mut []), None);
    }

    #[test]
    fn missing_samples_are_held_from_the_last_and_counted() {
        let nan = f64::NAN;
        let mut v = [nan, 1.0, nan, nan, 4.0, 5.0, nan];
        assert_eq!(hold_missing(&mut v), Some(4));
        assert_eq!(v, [1.0, 1.0, 1.0, 1.0, 4.0, 5.0, 5.0]);
        let mut clean = [1.0, 2.0];
        assert_eq!(hold_missing(&mut clean), Some(0));
        assert_eq!(hold_missing(&mut [nan, nan]), None);
        assert_eq!(hold_missing(&mut []), None);
    }

    #[test]
    #[should_panic(expected = "extra values")]
    fn push_with_wrong_number_of_extra_values_panics() {
        Log::with_extra_columns(&["a", "b"]).push(Row::default(), &[1.0]);
    }
}

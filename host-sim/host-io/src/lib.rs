//! host-io: what the host tools (host-sim and steer-can) read and write, shared so that a log
//! steer-can records on the car is read by `host-sim gap` through the very same code.
//!
//! - [`logfmt`]: the project's one log format (CSV or `.csv.gz`, the columns, their bounds).
//! - [`scenario`]: the references at 100 Hz: the paper's sweep, the built-in track, a step, a
//!   track from a CSV.
//! - [`grid`]: where stamped events sit on a regular grid (a log's rows, a train of frames).
//! - [`lines`]: reading text a line at a time with a cap on a line's length.
//! - [`out`]: printing for the command-line programs (a closed pipe ends them quietly,
//!   progress lines on a terminal only).
//!
//! Nothing here needs a numerics crate, so the laptop build of steer-can stays small.

pub mod grid;
pub mod lines;
pub mod logfmt;
pub mod out;
pub mod scenario;

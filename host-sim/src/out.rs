//! Printing for the command-line programs (`host-sim`, `steer-can`).

use std::io::Write;

/// One line on stdout, like `println!`, except that a closed stdout (`... | head`) ends the
/// program quietly with status 0 instead of a panic, and any other write error ends it with
/// status 1 and a message naming `program`.
pub fn stdout_line(program: &str, args: std::fmt::Arguments<'_>) {
    if let Err(e) = writeln!(std::io::stdout().lock(), "{args}") {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            std::process::exit(0);
        }
        eprintln!("{program}: cannot write to stdout: {e}");
        std::process::exit(1);
    }
}

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

/// Whether progress lines are drawn: only when stderr is a terminal. They redraw one line with
/// `\r`; in a pipe or a CI log that would be one endless line of redraws, where the reader
/// wants one line per event.
pub fn progress_shown() -> bool {
    use std::io::IsTerminal;
    static SHOWN: std::sync::OnceLock<bool> = std::sync::OnceLock::new();
    *SHOWN.get_or_init(|| std::io::stderr().is_terminal())
}

/// Redraws the progress line on stderr, on a terminal only.
pub fn progress_line(args: std::fmt::Arguments<'_>) {
    if progress_shown() {
        eprint!("\r{args}");
    }
}

/// Ends the progress line (a newline, on a terminal only).
pub fn progress_end() {
    if progress_shown() {
        eprintln!();
    }
}

//! Reading text one line at a time with a cap on a line's length, so a file that is not text
//! (a 2 GB file of zeros, a binary capture given by mistake) is refused after reading a few
//! kilobytes instead of being held whole in memory as one "line" first.

use std::io::{self, BufRead};

/// What [`read_line_capped`] found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Capped {
    /// A line (with its line end, if it had one) is in the buffer.
    Line,
    /// The end of the input: nothing more was read.
    End,
    /// The line goes on past the cap; the buffer holds its start only.
    TooLong,
}

/// Reads one line into `line` (cleared first), at most `max_bytes` of it: stops with
/// [`Capped::TooLong`] as soon as the line is longer, having read at most one buffer more.
/// Invalid UTF-8 is an `InvalidData` error, as `BufRead::read_line` gives.
pub fn read_line_capped(
    r: &mut impl BufRead,
    line: &mut String,
    max_bytes: usize,
) -> io::Result<Capped> {
    let mut bytes = std::mem::take(line).into_bytes();
    bytes.clear();
    let found = loop {
        let available = match r.fill_buf() {
            Ok(b) => b,
            Err(e) if e.kind() == io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if available.is_empty() {
            break if bytes.is_empty() {
                Capped::End
            } else {
                Capped::Line
            };
        }
        let (take, ends) = match available.iter().position(|&b| b == b'\n') {
            Some(i) => (i + 1, true),
            None => (available.len(), false),
        };
        if bytes.len() + take > max_bytes + usize::from(ends) {
            // Keep the start for the error message; the rest is never read.
            let room = max_bytes.saturating_sub(bytes.len()).min(take);
            bytes.extend_from_slice(&available[..room]);
            r.consume(room);
            break Capped::TooLong;
        }
        bytes.extend_from_slice(&available[..take]);
        r.consume(take);
        if ends {
            break Capped::Line;
        }
    };
    if found == Capped::TooLong {
        // The start of an overlong line may end inside a character: keep what decodes.
        *line = String::from_utf8_lossy(&bytes).into_owned();
        return Ok(found);
    }
    *line = String::from_utf8(bytes).map_err(|_| {
        io::Error::new(
            io::ErrorKind::InvalidData,
            "stream did not contain valid UTF-8",
        )
    })?;
    Ok(found)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    #[test]
    fn lines_up_to_the_cap_are_read_and_a_longer_one_is_not() {
        let text = "abc\nabcd\nabcde\n";
        let mut r = io::BufReader::with_capacity(2, text.as_bytes());
        let mut line = String::new();
        assert_eq!(
            read_line_capped(&mut r, &mut line, 4).unwrap(),
            Capped::Line
        );
        assert_eq!(line, "abc\n");
        assert_eq!(
            read_line_capped(&mut r, &mut line, 4).unwrap(),
            Capped::Line
        );
        assert_eq!(line, "abcd\n", "the line end does not count");
        assert_eq!(
            read_line_capped(&mut r, &mut line, 4).unwrap(),
            Capped::TooLong
        );
        assert_eq!(line, "abcd");
    }

    #[test]
    fn the_last_line_needs_no_line_end_and_the_end_is_said() {
        let mut r = io::Cursor::new("x\ny");
        let mut line = String::new();
        assert_eq!(
            read_line_capped(&mut r, &mut line, 9).unwrap(),
            Capped::Line
        );
        assert_eq!(
            read_line_capped(&mut r, &mut line, 9).unwrap(),
            Capped::Line
        );
        assert_eq!(line, "y");
        assert_eq!(read_line_capped(&mut r, &mut line, 9).unwrap(), Capped::End);
        assert!(line.is_empty());
    }

    /// Memory is bounded by the cap, not the input: a line of zeros far longer than the cap is
    /// refused having consumed about the cap.
    #[test]
    fn an_endless_line_is_refused_after_the_cap() {
        let zeros = io::repeat(0).take(1 << 30);
        let mut r = io::BufReader::new(zeros);
        let mut line = String::new();
        assert_eq!(
            read_line_capped(&mut r, &mut line, 1000).unwrap(),
            Capped::TooLong
        );
        assert_eq!(line.len(), 1000);
        assert!(line.capacity() < 64 * 1024, "{}", line.capacity());
    }

    #[test]
    fn invalid_utf8_is_an_error() {
        let mut r = io::Cursor::new(b"\xff\xfe\n".to_vec());
        let mut line = String::new();
        let e = read_line_capped(&mut r, &mut line, 9).unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::InvalidData);
    }
}

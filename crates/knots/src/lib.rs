//! Knot files (thesis A.2.3), parsed strictly: every violation is an error naming the file,
//! line, column and what was expected, found before any motor is enabled. The generators
//! (`qmarc-plugins`), the console, the waypoints and the fuzzers read them here.
//!
//! Offline (cubic spline): the first line is the number of knots; then one knot per line,
//! the time in seconds and one position per motor in whole counts.
//!
//! ```text
//! 3
//! 0.0  0      0
//! 0.25 2000  -2000
//! 0.5   3000  -4500
//! ```
//!
//! PVT (online): one knot per line; per motor a one-character label (discarded), the position
//! in whole counts, the velocity in counts/s and the time to the next knot in ms — the same
//! time for every motor of a line.
//!
//! ```text
//! X    0    0    25.00000    Y    0    0    25.00000
//! X   309  16000 35.00000    Y   309  16000 35.00000
//! ```
//!
//! Columns are separated by tabs or spaces; blank lines and lines whose first non-blank
//! character is `#` (comments) are skipped anywhere; `\r\n` line ends (Excel's "Text (tab
//! delimited)") and a UTF-8 byte-order mark are accepted. Everything else is strict. Every
//! number that becomes a duration is bounded: a path may last at most
//! `trajectory.max_duration_s` ([`KnotRules`]), and a line may have at most
//! [`MAX_LINE_BYTES`] bytes (a stream of bytes without line ends, `/dev/zero`, is refused).
#![deny(missing_docs)]

use qmarc_proto::MAX_MOTORS;
use std::io::BufRead;
use std::path::Path;

/// Most knots a file may hold: bounds the memory of the knots and the spline's coefficients.
pub const MAX_KNOTS: usize = 1 << 20;
/// Largest knot file read into memory, bytes.
pub const MAX_KNOT_FILE_BYTES: u64 = 64 << 20;
/// Longest line of a knot file or stream, bytes (a knot of four motors needs about 200).
pub const MAX_LINE_BYTES: usize = 4096;
/// Default longest path, s (`trajectory.max_duration_s`): 24 h.
pub const DEFAULT_MAX_DURATION_S: f64 = qmarc_config::DEFAULT_MAX_DURATION_S;
/// Largest position magnitude, counts: the range of the thesis' 32-bit software counter
/// (3.10.2), far beyond any physical path (2³¹ counts ≈ 43 700 motor revolutions).
pub const MAX_POSITION_COUNTS: i64 = i32::MAX as i64;

/// A knot file or stream could not be used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum KnotFileError {
    /// The file could not be read.
    #[error("{file}: cannot read the knot file: {reason}")]
    Read {
        /// The file (`-` for standard input).
        file: String,
        /// Why.
        reason: String,
    },
    /// The file is larger than a knot file may be.
    #[error("{file}: the file has more than {limit} bytes, the most a knot file may have")]
    TooLarge {
        /// The file.
        file: String,
        /// [`MAX_KNOT_FILE_BYTES`].
        limit: u64,
    },
    /// A line breaks the format.
    #[error("{file}:{line}:{column}: {message}")]
    Invalid {
        /// The file.
        file: String,
        /// 1-based line.
        line: usize,
        /// 1-based column (characters).
        column: usize,
        /// What is wrong and what was expected.
        message: String,
    },
}

/// What the parsers and generators check a path against besides its format.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnotRules {
    /// Motors: position columns per knot.
    pub n_motors: usize,
    /// Longest path from the first knot, s (`trajectory.max_duration_s`).
    pub max_duration_s: f64,
    /// Per motor, the fastest a path may move it, counts/s (`max_velocity_counts_per_s`;
    /// infinite: unchecked).
    pub max_velocity: [f64; MAX_MOTORS],
    /// Per motor, the largest acceleration a path may ask, counts/s²
    /// (`max_acceleration_counts_per_s2`; infinite: unchecked).
    pub max_acceleration: [f64; MAX_MOTORS],
}

impl KnotRules {
    /// The rules for `n_motors` with the default longest path and no motion limits.
    pub fn new(n_motors: usize) -> KnotRules {
        KnotRules {
            n_motors,
            max_duration_s: DEFAULT_MAX_DURATION_S,
            max_velocity: [f64::INFINITY; MAX_MOTORS],
            max_acceleration: [f64::INFINITY; MAX_MOTORS],
        }
    }

    /// The rules of `s`: the motors it drives, its longest path, each motor's motion limits.
    pub fn from_settings(s: &qmarc_config::Settings) -> KnotRules {
        let mut rules = KnotRules::new(s.n_motors).max_duration_s(s.trajectory.max_duration_s);
        for (m, limits) in s.safety.iter().enumerate().take(s.n_motors) {
            rules.max_velocity[m] = limits.max_velocity_counts_per_s;
            rules.max_acceleration[m] = limits.max_acceleration_counts_per_s2;
        }
        rules
    }

    /// The same rules without motion limits (for a tool that converts paths, not runs them).
    pub fn without_motion_limits(self) -> KnotRules {
        KnotRules {
            max_velocity: [f64::INFINITY; MAX_MOTORS],
            max_acceleration: [f64::INFINITY; MAX_MOTORS],
            ..self
        }
    }

    /// The same rules with the longest path `max_duration_s`.
    pub fn max_duration_s(self, max_duration_s: f64) -> KnotRules {
        KnotRules { max_duration_s, ..self }
    }
}

/// The knots of an offline path: time (s) and position (counts) per motor.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct OfflineKnots {
    /// Knot times, strictly increasing.
    pub times: Vec<f64>,
    /// Positions per knot; motors beyond the file's are 0.
    pub positions: Vec<[f64; MAX_MOTORS]>,
    /// Motors in the file.
    pub n_motors: usize,
    /// The file they came from, for errors found later (the path's dynamics).
    pub file: String,
    /// Each knot's line in the file (empty for knots not from a file).
    pub lines: Vec<usize>,
}

/// One PVT knot: position and velocity per motor and the time to the next knot.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct PvtKnot {
    /// Position per motor, counts.
    pub pos: [f64; MAX_MOTORS],
    /// Velocity per motor, counts/s.
    pub vel: [f64; MAX_MOTORS],
    /// Time to the next knot, s.
    pub dt_s: f64,
}

/// Reads a knot file into memory, refusing files over [`MAX_KNOT_FILE_BYTES`].
pub fn read_knot_file(path: &Path) -> Result<String, KnotFileError> {
    let file = path.display().to_string();
    let read_err =
        |e: std::io::Error| KnotFileError::Read { file: file.clone(), reason: e.to_string() };
    let too_large = || KnotFileError::TooLarge { file: file.clone(), limit: MAX_KNOT_FILE_BYTES };
    if std::fs::metadata(path).map_err(read_err)?.len() > MAX_KNOT_FILE_BYTES {
        return Err(too_large());
    }
    // The size a device reports (`/dev/zero`: 0) says nothing: the read is bounded too.
    let raw = qmarc_config::read_bounded(path, MAX_KNOT_FILE_BYTES)
        .map_err(read_err)?
        .ok_or_else(too_large)?;
    text_of(&file, raw)
}

/// The text of `raw` (a leading UTF-8 byte-order mark dropped), or an error naming the line
/// of the first byte that is not UTF-8.
pub fn text_of(file: &str, mut raw: Vec<u8>) -> Result<String, KnotFileError> {
    if raw.starts_with(&[0xEF, 0xBB, 0xBF]) {
        raw.drain(..3);
    }
    String::from_utf8(raw).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        let bytes = e.as_bytes();
        let line = bytes[..at].iter().filter(|&&b| b == b'\n').count() + 1;
        let column = String::from_utf8_lossy(&bytes[..at])
            .rsplit('\n')
            .next()
            .map_or(0, |l| l.chars().count())
            + 1;
        KnotFileError::Invalid {
            file: file.to_string(),
            line,
            column,
            message: "expected text (UTF-8), found a byte that is not".into(),
        }
    })
}

/// One whitespace-separated token of a line and its 1-based column.
struct Token<'a> {
    text: &'a str,
    column: usize,
}

fn tokens(line: &str) -> Vec<Token<'_>> {
    line.split_whitespace()
        .map(|t| {
            let byte = t.as_ptr() as usize - line.as_ptr() as usize;
            Token { text: t, column: line[..byte].chars().count() + 1 }
        })
        .collect()
}

/// Where errors of one file point.
struct At<'a> {
    file: &'a str,
}

impl At<'_> {
    fn err(&self, line: usize, column: usize, message: impl Into<String>) -> KnotFileError {
        KnotFileError::Invalid {
            file: self.file.to_string(),
            line,
            column,
            message: message.into(),
        }
    }

    fn counts(&self, line: usize, tok: &Token<'_>, what: &str) -> Result<f64, KnotFileError> {
        let v: i64 = tok.text.parse().map_err(|_| {
            self.err(
                line,
                tok.column,
                format!("{what}: expected a whole number of counts, found `{}`", tok.text),
            )
        })?;
        if v.abs() > MAX_POSITION_COUNTS {
            return Err(self.err(
                line,
                tok.column,
                format!("{what} {v} is outside the software counter's range ±{MAX_POSITION_COUNTS} counts"),
            ));
        }
        Ok(v as f64)
    }

    fn number(
        &self,
        line: usize,
        tok: &Token<'_>,
        what: &str,
        unit: &str,
    ) -> Result<f64, KnotFileError> {
        let v: f64 = tok.text.parse().map_err(|_| {
            self.err(
                line,
                tok.column,
                format!("{what}: expected a number of {unit}, found `{}`", tok.text),
            )
        })?;
        if !v.is_finite() {
            return Err(self.err(
                line,
                tok.column,
                format!("{what}: expected a finite number of {unit}, found `{}`", tok.text),
            ));
        }
        Ok(v)
    }

    fn columns(
        &self,
        line: usize,
        text: &str,
        toks: &[Token<'_>],
        want: usize,
        what: &str,
    ) -> Result<(), KnotFileError> {
        if toks.len() == want {
            return Ok(());
        }
        let column = toks.get(want).map_or(text.trim_end().chars().count() + 1, |t| t.column);
        Err(self.err(
            line,
            column,
            format!("expected {want} columns ({what}), found {}", toks.len()),
        ))
    }
}

/// `x` as a person reads it: plain up to 10⁷, in exponent notation beyond (`1e20`).
fn num(x: f64) -> String {
    if x.abs() >= 1e7 { format!("{x:e}") } else { format!("{x}") }
}

/// True for a line without a knot: blank, or a `#` comment.
fn is_blank_or_comment(line: &str) -> bool {
    let t = line.trim_start();
    t.is_empty() || t.starts_with('#')
}

/// The error for a line longer than [`MAX_LINE_BYTES`].
fn line_too_long(file: &str, line: usize) -> KnotFileError {
    KnotFileError::Invalid {
        file: file.to_string(),
        line,
        column: 1,
        message: format!(
            "the line has more than {MAX_LINE_BYTES} bytes, the most a knot line may have"
        ),
    }
}

/// Numbered lines of `text` that hold knots (or the offline header); an error for a line
/// longer than [`MAX_LINE_BYTES`].
fn content_lines<'a>(
    file: &'a str,
    text: &'a str,
) -> impl Iterator<Item = Result<(usize, &'a str), KnotFileError>> + 'a {
    text.lines().enumerate().map(|(i, l)| (i + 1, l)).filter(|(_, l)| !is_blank_or_comment(l)).map(
        move |(n, l)| {
            if l.len() > MAX_LINE_BYTES { Err(line_too_long(file, n)) } else { Ok((n, l)) }
        },
    )
}

/// Reads one line of a stream into `buf` (its end and a `\r` before it dropped), reading no
/// more than [`MAX_LINE_BYTES`] + 2 bytes of it: `Ok(false)` at the end of the stream, an
/// error (`InvalidData`, with the line's length) for a longer line.
pub fn read_line_bounded(
    reader: &mut dyn std::io::BufRead,
    buf: &mut Vec<u8>,
) -> std::io::Result<bool> {
    buf.clear();
    let limit = (MAX_LINE_BYTES + 2) as u64;
    let n = std::io::Read::take(&mut *reader, limit).read_until(b'\n', buf)?;
    if n == 0 {
        return Ok(false);
    }
    if buf.last() == Some(&b'\n') {
        buf.pop();
    } else if n as u64 == limit {
        return Err(std::io::Error::new(std::io::ErrorKind::InvalidData, "line too long"));
    }
    if buf.last() == Some(&b'\r') {
        buf.pop();
    }
    Ok(true)
}

pub mod dynamics;
mod offline;
mod pvt;
mod waypoints;
pub use offline::parse_offline;
pub use pvt::{MIN_PVT_KNOTS, PvtLineParser, parse_pvt};
pub use waypoints::{Waypoints, parse_waypoints};

#[doc(hidden)]
pub mod fuzzing;

#[cfg(test)]
mod tests;

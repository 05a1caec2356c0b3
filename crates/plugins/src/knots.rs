//! Knot files (thesis A.2.3), parsed strictly: every violation is an error naming the file,
//! line, column and what was expected, found before any motor is enabled.
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
    #[error("{file}: the file has {bytes} bytes, more than the {limit} a knot file may have")]
    TooLarge {
        /// The file.
        file: String,
        /// Its size.
        bytes: u64,
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

/// What the parsers check a file against besides its format.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct KnotRules {
    /// Motors: position columns per knot.
    pub n_motors: usize,
    /// Longest path from the first knot, s (`trajectory.max_duration_s`).
    pub max_duration_s: f64,
}

impl KnotRules {
    /// The rules for `n_motors` with the default longest path.
    pub fn new(n_motors: usize) -> KnotRules {
        KnotRules { n_motors, max_duration_s: DEFAULT_MAX_DURATION_S }
    }

    /// The rules of `s`: the motors it drives, its longest path.
    pub fn from_settings(s: &qmarc_config::Settings) -> KnotRules {
        KnotRules::new(s.n_motors).max_duration_s(s.trajectory.max_duration_s)
    }

    /// The same rules with the longest path `max_duration_s`.
    pub fn max_duration_s(self, max_duration_s: f64) -> KnotRules {
        KnotRules { max_duration_s, ..self }
    }
}

impl From<KnotFileError> for qmarc_controller::traj::TrajStartError {
    /// Bad knots met as the move starts (a stream's): the loop's start error carries them.
    fn from(e: KnotFileError) -> Self {
        qmarc_controller::traj::TrajStartError::Generator(Box::new(e))
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
    let bytes = std::fs::metadata(path).map_err(read_err)?.len();
    if bytes > MAX_KNOT_FILE_BYTES {
        return Err(KnotFileError::TooLarge { file, bytes, limit: MAX_KNOT_FILE_BYTES });
    }
    let raw = std::fs::read(path).map_err(read_err)?;
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

/// Parses an offline knot file by `rules`.
pub fn parse_offline(
    file: &str,
    text: &str,
    rules: &KnotRules,
) -> Result<OfflineKnots, KnotFileError> {
    let n_motors = rules.n_motors;
    let at = At { file };
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut lines = content_lines(file, text);
    let Some((hline, header)) = lines.next().transpose()? else {
        return Err(at.err(
            1,
            1,
            "expected the number of knots on the first line, found an empty file",
        ));
    };
    let htoks = tokens(header);
    let declared: usize = htoks[0].text.parse().map_err(|_| {
        at.err(
            hline,
            htoks[0].column,
            format!("expected the number of knots (a whole number), found `{}`", htoks[0].text),
        )
    })?;
    if let Some(extra) = htoks.get(1) {
        return Err(at.err(
            hline,
            extra.column,
            format!(
                "expected only the number of knots on the first line, found `{}` after it",
                extra.text
            ),
        ));
    }
    if declared < 2 {
        return Err(at.err(
            hline,
            htoks[0].column,
            format!("a cubic spline needs at least 2 knots, the file says {declared}"),
        ));
    }
    if declared > MAX_KNOTS {
        return Err(at.err(
            hline,
            htoks[0].column,
            format!("{declared} knots is more than the {MAX_KNOTS} the memory budget allows"),
        ));
    }
    let what =
        format!("time and {n_motors} motor position{}", if n_motors == 1 { "" } else { "s" });
    let mut knots = OfflineKnots {
        times: Vec::with_capacity(declared),
        positions: Vec::with_capacity(declared),
        n_motors,
    };
    let mut prev: Option<(f64, usize)> = None;
    let mut last_line = hline;
    for next in lines {
        let (lno, line) = next?;
        last_line = lno;
        if knots.times.len() == declared {
            return Err(at.err(
                lno,
                1,
                format!(
                    "the first line says {declared} knots but there are more: this is knot {}",
                    declared + 1
                ),
            ));
        }
        let toks = tokens(line);
        at.columns(lno, line, &toks, 1 + n_motors, &what)?;
        let t = at.number(lno, &toks[0], "time", "seconds")?;
        if let Some((pt, pl)) = prev {
            if t == pt {
                return Err(at.err(
                    lno,
                    toks[0].column,
                    format!("time {t} s repeats the previous knot's time (line {pl})"),
                ));
            }
            if t < pt {
                return Err(at.err(
                    lno,
                    toks[0].column,
                    format!("time {t} s is before the previous knot's {pt} s (line {pl}): times must increase"),
                ));
            }
        }
        if let Some(&t0) = knots.times.first()
            && t - t0 > rules.max_duration_s
        {
            return Err(at.err(
                lno,
                toks[0].column,
                format!(
                    "time {} s is {} s after the first knot: longer than the longest path, \
                     trajectory.max_duration_s = {} s",
                    num(t),
                    num(t - t0),
                    rules.max_duration_s
                ),
            ));
        }
        prev = Some((t, lno));
        let mut p = [0.0; MAX_MOTORS];
        for (m, tok) in toks[1..].iter().enumerate() {
            p[m] = at.counts(lno, tok, &format!("motor {} position", m + 1))?;
        }
        knots.times.push(t);
        knots.positions.push(p);
    }
    if knots.times.len() < declared {
        return Err(at.err(
            last_line + 1,
            1,
            format!("the first line says {declared} knots but the file has {}", knots.times.len()),
        ));
    }
    Ok(knots)
}

/// Parses PVT knots line by line, so that a stream can be checked knot by knot as it
/// arrives. [`parse_pvt`] parses a whole file with it.
#[derive(Debug, Clone)]
pub struct PvtLineParser {
    file: String,
    rules: KnotRules,
    line: usize,
    knots: usize,
    /// Time of the next knot from the first one, s.
    elapsed_s: f64,
}

impl PvtLineParser {
    /// A parser by `rules`; errors name `file`.
    pub fn new(file: &str, rules: &KnotRules) -> PvtLineParser {
        PvtLineParser { file: file.to_string(), rules: *rules, line: 0, knots: 0, elapsed_s: 0.0 }
    }

    /// Counts a line that could not be read because it was longer than [`MAX_LINE_BYTES`]
    /// and returns its error.
    pub fn too_long(&mut self) -> KnotFileError {
        self.line += 1;
        line_too_long(&self.file, self.line)
    }

    /// Knots parsed so far.
    pub fn knots(&self) -> usize {
        self.knots
    }

    /// Lines seen so far.
    pub fn lines(&self) -> usize {
        self.line
    }

    /// Parses the next line: `None` for a blank line or a comment.
    pub fn parse_line(&mut self, line: &str) -> Result<Option<PvtKnot>, KnotFileError> {
        self.line += 1;
        let lno = self.line;
        let line = line.strip_suffix('\r').unwrap_or(line);
        let line = if lno == 1 { line.strip_prefix('\u{feff}').unwrap_or(line) } else { line };
        if is_blank_or_comment(line) {
            return Ok(None);
        }
        if line.len() > MAX_LINE_BYTES {
            return Err(line_too_long(&self.file, lno));
        }
        let at = At { file: &self.file };
        if self.knots >= MAX_KNOTS {
            return Err(at.err(
                lno,
                1,
                format!("more than {MAX_KNOTS} knots: more than the memory budget allows"),
            ));
        }
        let toks = tokens(line);
        let n = self.rules.n_motors;
        let what = format!(
            "label, position, velocity and time for each of {n} motor{}",
            if n == 1 { "" } else { "s" }
        );
        at.columns(lno, line, &toks, 4 * n, &what)?;
        let mut k = PvtKnot::default();
        let mut first_dt: Option<(f64, &str)> = None;
        for m in 0..n {
            let c = &toks[4 * m..4 * m + 4];
            let motor = m + 1;
            if c[0].text.chars().count() != 1 {
                return Err(at.err(
                    lno,
                    c[0].column,
                    format!("motor {motor} label `{}` must be one character", c[0].text),
                ));
            }
            k.pos[m] = at.counts(lno, &c[1], &format!("motor {motor} position"))?;
            k.vel[m] = at.number(lno, &c[2], &format!("motor {motor} velocity"), "counts/s")?;
            let dt_ms =
                at.number(lno, &c[3], &format!("motor {motor} time to the next knot"), "ms")?;
            if dt_ms <= 0.0 {
                return Err(at.err(
                    lno,
                    c[3].column,
                    format!("motor {motor} time to the next knot must be > 0 ms, found {dt_ms}"),
                ));
            }
            match first_dt {
                None => first_dt = Some((dt_ms, c[3].text)),
                Some((t1, _)) if t1 != dt_ms => {
                    return Err(at.err(
                        lno,
                        c[3].column,
                        format!(
                            "motor {motor} time to the next knot {dt_ms} ms differs from motor 1's {t1} ms: \
                             one line is one step of time for every motor"
                        ),
                    ));
                }
                Some(_) => {}
            }
        }
        k.dt_s = first_dt.map_or(0.0, |(ms, _)| ms) / 1000.0;
        let max = self.rules.max_duration_s;
        if self.elapsed_s + k.dt_s > max {
            return Err(at.err(
                lno,
                toks[3].column,
                format!(
                    "this knot's segment ends {} s after the first knot: longer than the longest \
                     path, trajectory.max_duration_s = {max} s",
                    num(self.elapsed_s + k.dt_s)
                ),
            ));
        }
        self.elapsed_s += k.dt_s;
        self.knots += 1;
        Ok(Some(k))
    }

    /// The error for a path that ended with fewer than [`MIN_PVT_KNOTS`] knots.
    pub fn too_few(&self) -> KnotFileError {
        KnotFileError::Invalid {
            file: self.file.clone(),
            line: self.line + 1,
            column: 1,
            message: format!(
                "a PVT path needs at least {MIN_PVT_KNOTS} knots, found {}",
                self.knots
            ),
        }
    }
}

/// Fewest knots of a PVT path (thesis A.2.3.2: three must be known before the move).
pub const MIN_PVT_KNOTS: usize = 3;

/// Parses a whole PVT file by `rules`.
pub fn parse_pvt(file: &str, text: &str, rules: &KnotRules) -> Result<Vec<PvtKnot>, KnotFileError> {
    let mut parser = PvtLineParser::new(file, rules);
    let mut knots = Vec::new();
    for line in text.lines() {
        if let Some(k) = parser.parse_line(line)? {
            knots.push(k);
        }
    }
    if knots.len() < MIN_PVT_KNOTS {
        return Err(parser.too_few());
    }
    Ok(knots)
}

/// Entry points for the fuzz targets (`fuzz/`) and their corpus replay test: parse
/// arbitrary bytes and check what a successful parse promises.
#[doc(hidden)]
pub mod fuzzing {
    use super::*;

    fn motors_and_text(data: &[u8]) -> Option<(usize, String)> {
        let (&first, rest) = data.split_first()?;
        Some((usize::from(first % MAX_MOTORS as u8) + 1, String::from_utf8(rest.to_vec()).ok()?))
    }

    /// Offline parser: never panics; a success has the declared count, ≥ 2 knots, strictly
    /// increasing finite times and in-range whole positions.
    pub fn offline(data: &[u8]) {
        let Some((n, text)) = motors_and_text(data) else { return };
        if let Ok(k) = parse_offline("fuzz", &text, &KnotRules::new(n)) {
            assert!(k.times.len() >= 2 && k.times.len() == k.positions.len());
            assert!(k.times.windows(2).all(|w| w[0] < w[1] && w[1].is_finite()));
            for p in &k.positions {
                assert!(
                    p[..n]
                        .iter()
                        .all(|v| v.fract() == 0.0 && v.abs() <= MAX_POSITION_COUNTS as f64)
                );
                assert!(p[n..].iter().all(|&v| v == 0.0));
            }
        }
    }

    /// PVT parser: never panics; a success has ≥ 3 knots with positive finite segment times,
    /// finite velocities and in-range whole positions.
    pub fn pvt(data: &[u8]) {
        let Some((n, text)) = motors_and_text(data) else { return };
        if let Ok(ks) = parse_pvt("fuzz", &text, &KnotRules::new(n)) {
            assert!(ks.len() >= MIN_PVT_KNOTS);
            for k in &ks {
                assert!(k.dt_s > 0.0 && k.dt_s.is_finite());
                assert!(k.vel.iter().all(|v| v.is_finite()));
                assert!(
                    k.pos[..n]
                        .iter()
                        .all(|v| v.fract() == 0.0 && v.abs() <= MAX_POSITION_COUNTS as f64)
                );
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn two() -> KnotRules {
        KnotRules::new(2)
    }

    fn offline_err(text: &str, n: usize, expected: &str) {
        match parse_offline("k.txt", text, &KnotRules::new(n)) {
            Ok(k) => panic!("accepted {k:?}"),
            Err(e) => assert_eq!(e.to_string(), expected),
        }
    }

    fn pvt_err(text: &str, n: usize, expected: &str) {
        match parse_pvt("p.txt", text, &KnotRules::new(n)) {
            Ok(k) => panic!("accepted {k:?}"),
            Err(e) => assert_eq!(e.to_string(), expected),
        }
    }

    #[test]
    fn thesis_offline_example_parses() {
        let k = parse_offline(
            "k.txt",
            "3\n0.0  0      0\n0.25 2000  -2000\n0.5   3000  -4500\n",
            &two(),
        )
        .unwrap();
        assert_eq!(k.times, [0.0, 0.25, 0.5]);
        assert_eq!(k.positions[2][..2], [3000.0, -4500.0]);
        // Tabs, CRLF and trailing blank lines, as Excel writes them.
        let k2 = parse_offline(
            "k.txt",
            "3\r\n0.0\t0\t0\r\n0.25\t2000\t-2000\r\n0.5\t3000\t-4500\r\n\r\n",
            &two(),
        )
        .unwrap();
        assert_eq!(k, k2);
    }

    #[test]
    fn thesis_pvt_example_parses() {
        let text = "X    0    0    25.00000    Y    0    0    25.00000\n\
                    X   309  16000 35.00000    Y   309  16000 35.00000\n\
                    X   700  0     35.00000    Y   700  0     35.00000\n";
        let ks = parse_pvt("p.txt", text, &two()).unwrap();
        assert_eq!(ks.len(), 3);
        assert_eq!((ks[1].pos[0], ks[1].vel[1], ks[1].dt_s), (309.0, 16000.0, 0.035));
        assert_eq!(ks[0].dt_s, 0.025);
    }

    #[test]
    fn offline_errors_are_exact() {
        offline_err(
            "",
            1,
            "k.txt:1:1: expected the number of knots on the first line, found an empty file",
        );
        offline_err(
            "three\n",
            1,
            "k.txt:1:1: expected the number of knots (a whole number), found `three`",
        );
        offline_err(
            "3 knots\n",
            1,
            "k.txt:1:3: expected only the number of knots on the first line, found `knots` after it",
        );
        offline_err(
            "1\n0 0\n",
            1,
            "k.txt:1:1: a cubic spline needs at least 2 knots, the file says 1",
        );
        offline_err(
            "2000000\n",
            1,
            "k.txt:1:1: 2000000 knots is more than the 1048576 the memory budget allows",
        );
        offline_err(
            "3\n0 0\n1 5\n",
            1,
            "k.txt:4:1: the first line says 3 knots but the file has 2",
        );
        offline_err(
            "2\n0 0\n1 5\n2 7\n",
            1,
            "k.txt:4:1: the first line says 2 knots but there are more: this is knot 3",
        );
        offline_err(
            "2\n0 0 0\n1 5\n",
            3,
            "k.txt:2:6: expected 4 columns (time and 3 motor positions), found 3",
        );
        offline_err(
            "2\n0 0 0 0 9\n1 5 5 5\n",
            3,
            "k.txt:2:9: expected 4 columns (time and 3 motor positions), found 5",
        );
        offline_err(
            "2\n0,5 0\n1 5\n",
            1,
            "k.txt:2:1: time: expected a number of seconds, found `0,5`",
        );
        offline_err(
            "2\n0 0\ninf 5\n",
            1,
            "k.txt:3:1: time: expected a finite number of seconds, found `inf`",
        );
        offline_err(
            "2\nNaN 0\n1 5\n",
            1,
            "k.txt:2:1: time: expected a finite number of seconds, found `NaN`",
        );
        offline_err(
            "3\n0 0\n0.5 1\n0.25 2\n",
            1,
            "k.txt:4:1: time 0.25 s is before the previous knot's 0.5 s (line 3): times must increase",
        );
        offline_err(
            "3\n0 0\n0.5 1\n0.5 2\n",
            1,
            "k.txt:4:1: time 0.5 s repeats the previous knot's time (line 3)",
        );
        offline_err(
            "2\n0 0 12.5\n1 5 5\n",
            2,
            "k.txt:2:5: motor 2 position: expected a whole number of counts, found `12.5`",
        );
        offline_err(
            "2\n0 abc\n1 5\n",
            1,
            "k.txt:2:3: motor 1 position: expected a whole number of counts, found `abc`",
        );
        offline_err(
            "2\n0 3000000000\n1 5\n",
            1,
            "k.txt:2:3: motor 1 position 3000000000 is outside the software counter's range ±2147483647 counts",
        );
    }

    #[test]
    fn pvt_errors_are_exact() {
        let ok = "X 0 0 10";
        pvt_err(
            "X 0 0 10 Y 0 0 10\n",
            3,
            "p.txt:1:18: expected 12 columns (label, position, velocity and time for each of 3 motors), found 8",
        );
        pvt_err("XY 0 0 10\n", 1, "p.txt:1:1: motor 1 label `XY` must be one character");
        pvt_err(
            "X 0 0 10 Y 0 0 10\nX 0 0 10 Y 0 0 30\n",
            2,
            "p.txt:2:16: motor 2 time to the next knot 30 ms differs from motor 1's 10 ms: one line is one step of time for every motor",
        );
        pvt_err("X 0 0 0\n", 1, "p.txt:1:7: motor 1 time to the next knot must be > 0 ms, found 0");
        pvt_err(
            "X 0 0 -5\n",
            1,
            "p.txt:1:7: motor 1 time to the next knot must be > 0 ms, found -5",
        );
        pvt_err(
            "X 0 0 inf\n",
            1,
            "p.txt:1:7: motor 1 time to the next knot: expected a finite number of ms, found `inf`",
        );
        pvt_err(
            "X 0 fast 10\n",
            1,
            "p.txt:1:5: motor 1 velocity: expected a number of counts/s, found `fast`",
        );
        pvt_err(
            "X 0 NaN 10\n",
            1,
            "p.txt:1:5: motor 1 velocity: expected a finite number of counts/s, found `NaN`",
        );
        pvt_err(
            "X 1.5 0 10\n",
            1,
            "p.txt:1:3: motor 1 position: expected a whole number of counts, found `1.5`",
        );
        pvt_err(
            "X -2147483648 0 10\n",
            1,
            "p.txt:1:3: motor 1 position -2147483648 is outside the software counter's range ±2147483647 counts",
        );
        pvt_err(
            &format!("{ok}\n{ok}\n"),
            1,
            "p.txt:3:1: a PVT path needs at least 3 knots, found 2",
        );
        pvt_err("", 1, "p.txt:1:1: a PVT path needs at least 3 knots, found 0");
        pvt_err(
            &format!("{ok}\n\n{ok}\nX 0 0\n"),
            1,
            "p.txt:4:6: expected 4 columns (label, position, velocity and time for each of 1 motor), found 3",
        );
    }

    #[test]
    fn pvt_stream_parser_counts_lines_and_knots() {
        let mut p = PvtLineParser::new("-", &KnotRules::new(1));
        assert_eq!(p.parse_line("").unwrap(), None);
        assert!(p.parse_line("A 5 -10.5 20\r").unwrap().is_some());
        assert_eq!((p.lines(), p.knots()), (2, 1));
        assert_eq!(p.too_few().to_string(), "-:3:1: a PVT path needs at least 3 knots, found 1");
    }

    #[test]
    fn non_utf8_is_named_with_its_line() {
        let e = text_of("k.txt", b"2\n0 0\n1 \xff\n".to_vec()).unwrap_err();
        assert_eq!(e.to_string(), "k.txt:3:3: expected text (UTF-8), found a byte that is not");
    }

    #[test]
    fn too_large_files_are_refused_before_reading() {
        let e = KnotFileError::TooLarge {
            file: "big.txt".into(),
            bytes: 70_000_000,
            limit: MAX_KNOT_FILE_BYTES,
        };
        assert_eq!(
            e.to_string(),
            "big.txt: the file has 70000000 bytes, more than the 67108864 a knot file may have"
        );
        let missing = read_knot_file(Path::new("/nonexistent/k.txt")).unwrap_err().to_string();
        assert!(
            missing.starts_with("/nonexistent/k.txt: cannot read the knot file: "),
            "{missing}"
        );
    }

    /// Issue 10, item 1: every number that becomes a duration is bounded; a path longer than
    /// `trajectory.max_duration_s` is an error naming file, line and column (a time of 1e20
    /// used to overflow the sample count, one of 1e300 to spin for minutes).
    #[test]
    fn paths_longer_than_the_longest_are_refused_issue_10() {
        offline_err(
            "2\n0 0\n1e20 5\n",
            1,
            "k.txt:3:1: time 1e20 s is 1e20 s after the first knot: longer than the longest path, \
             trajectory.max_duration_s = 86400 s",
        );
        pvt_err(
            "X 0 0 10\nX 5 0 1e300\nX 9 0 10\n",
            1,
            "p.txt:2:7: this knot's segment ends 1e297 s after the first knot: longer than the \
             longest path, trajectory.max_duration_s = 86400 s",
        );
        let short = KnotRules::new(1).max_duration_s(1.0);
        let e = parse_pvt("p.txt", "X 0 0 600\nX 5 0 600\nX 9 0 10\n", &short).unwrap_err();
        assert!(e.to_string().starts_with("p.txt:2:7: this knot's segment ends 1.2 s"), "{e}");
        assert!(parse_offline("k.txt", "2\n0 0\n1 5\n", &short).is_ok(), "1 s is allowed");
    }

    /// Issue 10, items 2 and 16: comments and blank lines anywhere; a byte-order mark; lines
    /// and streams are bounded.
    #[test]
    fn comments_blank_lines_and_bounded_lines_issue_10() {
        let k = parse_offline(
            "k.txt",
            "\u{feff}# a path\n\n3\n  # times in s\n0 0 0\n\n1 5 5\n# the end\n2 9 9\n",
            &two(),
        )
        .unwrap();
        assert_eq!(k.times, [0.0, 1.0, 2.0]);
        let ks = parse_pvt(
            "p.txt",
            "\u{feff}X 0 0 10\n# two\nX 5 0 10\n\nX 9 0 10\n",
            &KnotRules::new(1),
        )
        .unwrap();
        assert_eq!(ks.len(), 3);
        // Everything else stays strict: a comment after a knot is not a comment.
        pvt_err(
            "X 0 0 10 # first\n",
            1,
            "p.txt:1:10: expected 4 columns (label, position, velocity and time for each of 1 motor), found 6",
        );
        let long = format!("2\n0 0\n1 {}\n", "5".repeat(MAX_LINE_BYTES));
        offline_err(
            &long,
            1,
            "k.txt:3:1: the line has more than 4096 bytes, the most a knot line may have",
        );
        // A stream without line ends stops after the limit instead of filling the memory.
        let mut zeros = std::io::BufReader::new(std::io::repeat(0));
        let mut buf = Vec::new();
        let e = read_line_bounded(&mut zeros, &mut buf).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidData);
        assert!(buf.len() <= MAX_LINE_BYTES + 2);
        let mut two_lines = std::io::Cursor::new(b"ab\r\ncd".to_vec());
        assert!(read_line_bounded(&mut two_lines, &mut buf).unwrap());
        assert_eq!(buf, b"ab");
        assert!(read_line_bounded(&mut two_lines, &mut buf).unwrap());
        assert_eq!(buf, b"cd");
        assert!(!read_line_bounded(&mut two_lines, &mut buf).unwrap());
    }
}

//! The PVT knot file (thesis A.2.3.2, the online generator's): per motor a label, a whole
//! position in counts, a velocity in counts/s and the time to the next knot in ms, one line
//! per knot — parsed line by line, so a stream is checked knot by knot as it arrives.

use super::dynamics::{check_segment, hermite_end_accelerations};
use super::{
    At, KnotFileError, KnotRules, MAX_KNOTS, MAX_LINE_BYTES, PvtKnot, Token, is_blank_or_comment,
    line_too_long, num, tokens,
};

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
    /// The last knot and its line: the segment to the next one is checked against the motion
    /// limits when that one arrives.
    last: Option<(PvtKnot, usize)>,
}

impl PvtLineParser {
    /// A parser by `rules`; errors name `file`.
    pub fn new(file: &str, rules: &KnotRules) -> PvtLineParser {
        PvtLineParser {
            file: file.to_string(),
            rules: *rules,
            line: 0,
            knots: 0,
            elapsed_s: 0.0,
            last: None,
        }
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
        let k = motor_columns(&at, lno, &toks, n)?;
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
        self.check_dynamics(&at, lno, &toks, &k)?;
        self.elapsed_s += k.dt_s;
        self.knots += 1;
        self.last = Some((k, lno));
        Ok(Some(k))
    }

    /// The motion limits, as knot `k` of line `lno` arrives: the segment from the last knot to
    /// it, its largest velocity and acceleration exactly (the first knot: its velocity). Errors
    /// point at the motor's velocity.
    fn check_dynamics(
        &self,
        at: &At<'_>,
        lno: usize,
        toks: &[Token<'_>],
        k: &PvtKnot,
    ) -> Result<(), KnotFileError> {
        let r = &self.rules;
        for m in 0..r.n_motors {
            let segment = match self.last {
                None => (k.vel[m], 0.0, 0.0, 1.0),
                Some((p, _)) => {
                    let (a0, a1) =
                        hermite_end_accelerations(p.pos[m], p.vel[m], k.pos[m], k.vel[m], p.dt_s);
                    (p.vel[m], a0, a1, p.dt_s)
                }
            };
            check_segment(r, m, segment)
                .map_err(|e| at.err(lno, toks[4 * m + 2].column, e.describe()))?;
        }
        Ok(())
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

/// The knot of line `lno` from its `4 × n` tokens: each motor's label, position, velocity and
/// time to the next knot, which must be the same for every motor.
fn motor_columns(
    at: &At<'_>,
    lno: usize,
    toks: &[Token<'_>],
    n: usize,
) -> Result<PvtKnot, KnotFileError> {
    let mut k = PvtKnot::default();
    let mut first_dt: Option<f64> = None;
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
        let dt_ms = at.number(lno, &c[3], &format!("motor {motor} time to the next knot"), "ms")?;
        if dt_ms <= 0.0 {
            return Err(at.err(
                lno,
                c[3].column,
                format!("motor {motor} time to the next knot must be > 0 ms, found {dt_ms}"),
            ));
        }
        match first_dt {
            None => first_dt = Some(dt_ms),
            Some(t1) if t1 != dt_ms => {
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
    k.dt_s = first_dt.unwrap_or(0.0) / 1000.0;
    Ok(k)
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

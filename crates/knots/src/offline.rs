//! The offline knot file (thesis A.2.3.1, the cubic spline's): the number of knots, then one
//! knot per line — the time in seconds and one whole position in counts per motor.

use super::{
    At, KnotFileError, KnotRules, MAX_KNOTS, OfflineKnots, Token, content_lines, num, tokens,
};
use qmarc_proto::MAX_MOTORS;

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
    let declared = declared_knots(&at, hline, header)?;
    let what =
        format!("time and {n_motors} motor position{}", if n_motors == 1 { "" } else { "s" });
    let mut knots = OfflineKnots {
        times: Vec::with_capacity(declared),
        positions: Vec::with_capacity(declared),
        n_motors,
        file: file.to_string(),
        lines: Vec::with_capacity(declared),
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
        check_time(&at, (lno, &toks[0]), t, prev, knots.times.first().copied(), rules)?;
        prev = Some((t, lno));
        let mut p = [0.0; MAX_MOTORS];
        for (m, tok) in toks[1..].iter().enumerate() {
            p[m] = at.counts(lno, tok, &format!("motor {} position", m + 1))?;
        }
        knots.times.push(t);
        knots.positions.push(p);
        knots.lines.push(lno);
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

/// The number of knots the first line (`hline`) declares: a whole number 2‥[`MAX_KNOTS`],
/// alone on its line.
fn declared_knots(at: &At<'_>, hline: usize, header: &str) -> Result<usize, KnotFileError> {
    let htoks = tokens(header);
    let declared: usize = htoks[0].text.parse().map_err(|_| {
        // A PVT file's lines begin with a motor letter (thesis A.2.3.2).
        let pvt =
            htoks[0].text.len() == 1 && htoks[0].text.chars().all(|c| c.is_ascii_alphabetic());
        let hint = if pvt { " (it looks like a PVT file: run it with --method pvt)" } else { "" };
        at.err(
            hline,
            htoks[0].column,
            format!(
                "expected the number of knots (a whole number), found `{}`{hint}",
                htoks[0].text
            ),
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
    Ok(declared)
}

/// Checks a knot's time `t` (token `tok` of line `lno`) against the previous knot's `(time,
/// line)` — times strictly increase — and the first knot's time — the path lasts at most
/// `trajectory.max_duration_s`.
pub(super) fn check_time(
    at: &At<'_>,
    (lno, tok): (usize, &Token<'_>),
    t: f64,
    prev: Option<(f64, usize)>,
    first: Option<f64>,
    rules: &KnotRules,
) -> Result<(), KnotFileError> {
    if let Some((pt, pl)) = prev {
        if t == pt {
            return Err(at.err(
                lno,
                tok.column,
                format!("time {t} s repeats the previous knot's time (line {pl})"),
            ));
        }
        if t < pt {
            return Err(at.err(
                lno,
                tok.column,
                format!(
                    "time {t} s is before the previous knot's {pt} s (line {pl}): times must increase"
                ),
            ));
        }
    }
    if let Some(t0) = first
        && t - t0 > rules.max_duration_s
    {
        return Err(at.err(
            lno,
            tok.column,
            format!(
                "time {} s is {} s after the first knot: longer than the longest path, \
                 trajectory.max_duration_s = {} s",
                num(t),
                num(t - t0),
                rules.max_duration_s
            ),
        ));
    }
    Ok(())
}

//! Cartesian waypoint files (`qmarc-starter path --waypoints`): one waypoint per line, the
//! time in seconds and the effector's x, y, z in metres; blank lines and `#` comments are
//! skipped; times strictly increase.
//!
//! ```text
//! # t_s   x_m     y_m   z_m
//! 0.0    -0.15    0.0  -0.600
//! 0.05   -0.15    0.0  -0.575
//! ```

use super::offline::check_time;
use super::{At, KnotFileError, KnotRules, MAX_KNOTS, content_lines, tokens};

/// The waypoints of a file, each with the line it came from.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Waypoints {
    /// Times, s, strictly increasing.
    pub times: Vec<f64>,
    /// Effector centre per waypoint, m.
    pub points: Vec<[f64; 3]>,
    /// 1-based line of each waypoint.
    pub lines: Vec<usize>,
}

/// Parses a waypoint file; a path lasts at most `rules.max_duration_s` (`rules.n_motors` is
/// not used: a waypoint is a point, whatever the robot's motors).
pub fn parse_waypoints(
    file: &str,
    text: &str,
    rules: &KnotRules,
) -> Result<Waypoints, KnotFileError> {
    let at = At { file };
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    let mut w = Waypoints::default();
    let mut last_line = 0;
    for next in content_lines(file, text) {
        let (lno, line) = next?;
        last_line = lno;
        if w.times.len() == MAX_KNOTS {
            return Err(at.err(lno, 1, format!("more than {MAX_KNOTS} waypoints")));
        }
        let toks = tokens(line);
        at.columns(lno, line, &toks, 4, "t_s x_m y_m z_m")?;
        let t = at.number(lno, &toks[0], "time", "seconds")?;
        let prev = w.times.last().copied().zip(w.lines.last().copied());
        check_time(&at, (lno, &toks[0]), t, prev, w.times.first().copied(), rules)?;
        let mut p = [0.0; 3];
        for (k, (tok, axis)) in toks[1..].iter().zip(["x", "y", "z"]).enumerate() {
            p[k] = at.number(lno, tok, axis, "metres")?;
        }
        w.times.push(t);
        w.points.push(p);
        w.lines.push(lno);
    }
    if w.times.len() < 2 {
        return Err(at.err(
            last_line + 1,
            1,
            format!("a path needs at least 2 waypoints, the file has {}", w.times.len()),
        ));
    }
    Ok(w)
}

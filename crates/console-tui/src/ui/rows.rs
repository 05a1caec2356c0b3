//! The rows above the message line and the message line itself: what a move is doing (homing's
//! motor and stage), where the robot is (live, or at rest with its source) and the gripper,
//! each wrapped whole at the screen's width — nothing the user must read is cut at 80×24.

use super::*;

/// `rows` each after a space (the screen's left margin).
pub(super) fn indented(rows: Vec<Line<'static>>) -> Vec<Line<'static>> {
    rows.into_iter()
        .map(|mut l| {
            l.spans.insert(0, Span::raw(" "));
            l
        })
        .collect()
}

/// The message line's rows at `width`: the message and, while a point is typed (Ctrl-G), the
/// point with a cursor — wrapped whole on up to `max_rows` rows, the last marked `…` if it
/// had to be cut.
pub(super) fn message_rows(app: &App, width: usize, max_rows: usize) -> Vec<Line<'static>> {
    let (msg, err) = &app.status;
    let style = if *err { Style::new().fg(Color::Red).bold() } else { Style::new() };
    let typed = app.prompt.as_ref().map(|t| format!(" {t}▏")).unwrap_or_default();
    let mut rows = wrap_spans(&[(format!("{msg}{typed}"), style)], width);
    if rows.len() > max_rows {
        rows.truncate(max_rows);
        if let Some(last) = rows.last_mut() {
            let text: String = last.spans.iter().map(|s| s.content.as_ref()).collect();
            let kept: String = text.chars().take(width.saturating_sub(1)).chain(['…']).collect();
            *last = Line::styled(kept, style);
        }
    }
    rows
}

/// What the console says about the robot.
#[derive(Debug, Clone)]
pub(super) struct RobotView {
    /// `At rest`, or the running move: `home running 3.2 s`.
    head: String,
    /// What is known (a `false` second: not known).
    items: Vec<(String, bool)>,
    /// Where it comes from.
    source: String,
}

/// The robot now: the running move and what its progress page and telemetry say (homing's
/// motor and stage, the effector, the gripper), or the robot at rest ([`crate::rest::Rest`]).
pub(super) fn robot_view(app: &App) -> RobotView {
    let Some(r) = &app.running else {
        return RobotView {
            head: "At rest:".to_string(),
            items: app.rest.items(),
            source: app.rest.source(),
        };
    };
    let mut items = Vec::new();
    let mut source = String::new();
    if let Some(live) = &app.live {
        // Homing says which motor and what it does, as the CLI's status line.
        items.extend(live.stage.clone().map(|s| (s, true)));
        // Where the effector is, live.
        let at = live.whereabouts();
        items.extend(
            at.split(" · ").filter(|s| !s.trim().is_empty()).map(|s| (s.to_string(), true)),
        );
        if live.samples > 0 {
            source = "live, from its telemetry".to_string();
        }
    }
    let aborting = if r.aborted.is_some() { " (aborting)" } else { "" };
    RobotView {
        head: format!(
            "{} running {:.1} s{aborting}",
            r.mode.arg(),
            r.started.elapsed().as_secs_f64()
        ),
        items,
        source,
    }
}

/// A non-breaking space: inside an item, so that rows break between items.
const NBSP: char = '\u{a0}';

/// The segments of `robot`: its head, its items (one not known in yellow) by ` · `, and
/// where they come from (dim) after `lead`.
fn robot_segments(robot: &RobotView, lead: &str) -> Vec<(String, Style)> {
    let glue = |t: &str| t.replace(' ', &NBSP.to_string());
    let mut segments = vec![(format!("{} ", glue(&robot.head)), Style::new().bold())];
    for (k, (item, known)) in robot.items.iter().enumerate() {
        if k > 0 {
            segments.push((" · ".to_string(), Style::new()));
        }
        let style = if *known { Style::new() } else { Style::new().fg(Color::Yellow) };
        segments.push((glue(item), style));
    }
    if !robot.source.is_empty() {
        segments.push((format!("{lead}({})", robot.source), Style::new().dim()));
    }
    segments
}

/// The robot on rows of their own, `width` wide.
pub(super) fn robot_strip(robot: &RobotView, width: usize) -> Vec<Line<'static>> {
    wrap_spans(&robot_segments(robot, " "), width)
}

/// The robot in the room the setup page's left column leaves under its fields, if it fits
/// there whole — with where it comes from, or, when the fields' messages leave too little
/// room for that, without: its lines.
pub(super) fn setup_robot_column(
    app: &App,
    robot: &RobotView,
    body: Rect,
) -> Option<Vec<Line<'static>>> {
    let [left, _] = setup_columns(body);
    // A column of margin before the border.
    let width = usize::from(left.width.saturating_sub(2));
    let room = usize::from(left.height)
        .saturating_sub(setup_lines(app, usize::from(left.width.saturating_sub(2))).len());
    let full = wrap_spans(&robot_segments(robot, "\n"), width);
    if full.len() <= room {
        return Some(full);
    }
    let short = RobotView { source: String::new(), ..robot.clone() };
    Some(wrap_spans(&robot_segments(&short, "\n"), width)).filter(|l| l.len() <= room)
}

/// `segments` (text and style) broken into rows of at most `width` characters: at spaces
/// where it can, else at non-breaking spaces, else across a word; a `\n` breaks the row.
/// Nothing is lost, and non-breaking spaces are shown as spaces.
pub(super) fn wrap_spans(segments: &[(String, Style)], width: usize) -> Vec<Line<'static>> {
    let width = width.max(1);
    let chars: Vec<(char, Style)> =
        segments.iter().flat_map(|(t, s)| t.chars().map(move |c| (c, *s))).collect();
    let mut rows: Vec<&[(char, Style)]> = Vec::new();
    let mut start = 0;
    while start < chars.len() {
        if !rows.is_empty() {
            // A row does not start with the space it was broken at.
            while chars.get(start).is_some_and(|c| c.0 == ' ' || c.0 == NBSP) {
                start += 1;
            }
        }
        let end = (start + width).min(chars.len());
        let cut = if let Some(nl) = (start..end).find(|&i| chars[i].0 == '\n') {
            nl
        } else if end == chars.len() {
            end
        } else {
            let last = |c: char| (start + 1..=end).rev().find(|&i| chars[i].0 == c);
            last(' ').or_else(|| last(NBSP)).unwrap_or(end)
        };
        rows.push(&chars[start..cut]);
        start = if chars.get(cut).is_some_and(|c| c.0 == '\n') { cut + 1 } else { cut };
    }
    if rows.is_empty() {
        return vec![Line::default()];
    }
    rows.into_iter()
        .map(|row| {
            let mut spans: Vec<Span<'static>> = Vec::new();
            let mut text = String::new();
            let mut style = row.first().map_or(Style::new(), |c| c.1);
            for &(c, s) in row {
                if s != style && !text.is_empty() {
                    spans.push(Span::styled(std::mem::take(&mut text), style));
                }
                style = s;
                text.push(if c == NBSP { ' ' } else { c });
            }
            spans.push(Span::styled(text, style));
            Line::from(spans)
        })
        .collect()
}

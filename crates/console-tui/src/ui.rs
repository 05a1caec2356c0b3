//! Drawing the console. Every page fits 80×24 and uses more room when there is more; nothing
//! here can panic on a small or resized terminal (layouts shrink, text is clipped). What the
//! user must read is never cut at 80 columns: the message line wraps, and the robot — the
//! running move (homing's motor and stage, the effector, the gripper) or the robot at rest —
//! has rows of its own (on the setup page, the foot of its left column when it fits there).

use crate::app::{App, Page};
use crate::form::{Action, Field, GAIN_ROWS, Kind, Section};
use crate::results::{ChartsView, thin};
use ratatui::Frame;
use ratatui::layout::{Constraint, Layout, Rect};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Borders, Chart, Dataset, GraphType, Paragraph, Wrap};

const PAGES: [(Page, &str); 5] = [
    (Page::Setup, "F1 Setup"),
    (Page::Log, "F3 Log"),
    (Page::Results, "F4 Results"),
    (Page::Charts, "F7 Charts"),
    (Page::History, "F8 History"),
];

/// Draws the whole console.
pub fn draw(f: &mut Frame, app: &App) {
    let area = f.area();
    let width = usize::from(area.width);
    // The message line, wrapped, so that it is read whole at 80 columns (at most a quarter of
    // the screen; past that, its end is marked cut).
    let message = message_rows(app, width.saturating_sub(1), usize::from(area.height / 4).max(1));
    // The robot: the running move (homing's motor and stage, where the effector is, the
    // gripper), or the robot at rest. On the setup page in the room its left column leaves,
    // when it fits whole there; else on rows of its own above the message line (during a
    // move on every page, at rest on the setup page only: the others show a move's data).
    let robot = robot_view(app);
    let layout = |strip: usize| {
        Layout::vertical([
            Constraint::Length(1),
            Constraint::Length(1),
            Constraint::Min(0),
            Constraint::Length(u16::try_from(strip).unwrap_or(u16::MAX)),
            Constraint::Length(u16::try_from(message.len()).unwrap_or(u16::MAX)),
            Constraint::Length(1),
        ])
        .areas::<6>(area)
    };
    let [_, _, body, ..] = layout(0);
    let column = (app.page == Page::Setup).then(|| setup_robot_column(app, &robot, body)).flatten();
    let strip = if column.is_some() || (app.running.is_none() && app.page != Page::Setup) {
        Vec::new()
    } else {
        robot_strip(&robot, width.saturating_sub(1))
    };
    let [title, tabs, body, strip_area, status, keys] = layout(strip.len());
    let modified = if app.form.dirty() { " [modified]" } else { "" };
    f.render_widget(
        Line::from(vec![
            Span::styled(" QMARC console ", Style::new().bold().reversed()),
            Span::raw(format!(" {}{modified}", app.form.path.display())),
        ]),
        title,
    );
    let tab_spans: Vec<Span> = PAGES
        .iter()
        .flat_map(|(p, name)| {
            let style = if *p == app.page { Style::new().reversed().bold() } else { Style::new() };
            [Span::styled(format!(" {name} "), style), Span::raw(" ")]
        })
        .collect();
    f.render_widget(Line::from(tab_spans), tabs);
    match app.page {
        Page::Setup => draw_setup(f, app, body, column),
        Page::Log => draw_log(f, app, body),
        Page::Results => draw_results(f, app, body),
        Page::Charts => draw_charts(f, app, body),
        Page::History => history::draw_history(f, app, body),
    }
    f.render_widget(Paragraph::new(indented(strip)), strip_area);
    f.render_widget(Paragraph::new(indented(message)), status);
    f.render_widget(
        Line::from(" F2 Home F5 Run F6 Step ^T Tune ^G Go to ^O Grip F9 Abort F10 Exit F12 Cancel")
            .style(Style::new().dim()),
        keys,
    );
}

/// `rows` each after a space (the screen's left margin).
fn indented(rows: Vec<Line<'static>>) -> Vec<Line<'static>> {
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
fn message_rows(app: &App, width: usize, max_rows: usize) -> Vec<Line<'static>> {
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
struct RobotView {
    /// `At rest`, or the running move: `home running 3.2 s`.
    head: String,
    /// What is known (a `false` second: not known).
    items: Vec<(String, bool)>,
    /// Where it comes from.
    source: String,
}

/// The robot now: the running move and what its progress page and telemetry say (homing's
/// motor and stage, the effector, the gripper), or the robot at rest ([`crate::rest::Rest`]).
fn robot_view(app: &App) -> RobotView {
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
fn robot_strip(robot: &RobotView, width: usize) -> Vec<Line<'static>> {
    wrap_spans(&robot_segments(robot, " "), width)
}

/// The robot in the room the setup page's left column leaves under its fields, if it fits
/// there whole — with where it comes from, or, when the fields' messages leave too little
/// room for that, without: its lines.
fn setup_robot_column(app: &App, robot: &RobotView, body: Rect) -> Option<Vec<Line<'static>>> {
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
fn wrap_spans(segments: &[(String, Style)], width: usize) -> Vec<Line<'static>> {
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

fn value_style(app: &App, i: usize, f: &Field) -> Style {
    let mut s = Style::new();
    if !app.form.enabled(i) {
        s = s.fg(Color::DarkGray);
    } else if f.error.is_some() {
        s = s.fg(Color::Red).bold();
    }
    if i == app.focus && app.page == Page::Setup {
        s = s.add_modifier(Modifier::REVERSED);
    }
    s
}

fn section_title(s: Section) -> &'static str {
    match s {
        Section::General => "General",
        Section::Trajectory => "Trajectory",
        Section::Step => "Step",
        Section::Gains => "Gains",
        Section::Gathering => "Data gathering",
    }
}

/// The setup page's two columns: the settings, and the gains and actions.
fn setup_columns(area: Rect) -> [Rect; 2] {
    Layout::horizontal([Constraint::Percentage(47), Constraint::Percentage(53)]).areas(area)
}

/// The setup page's left column, `width` wide: the sections with one value per line, an
/// invalid value's message right under it.
fn setup_lines(app: &App, width: usize) -> Vec<Line<'static>> {
    let mut lines: Vec<Line> = Vec::new();
    for section in [Section::General, Section::Trajectory, Section::Step, Section::Gathering] {
        lines.push(Line::styled(section_title(section), Style::new().bold().underlined()));
        for (i, fld) in app.form.fields.iter().enumerate() {
            if fld.section != section || fld.place.motor().is_some() {
                continue;
            }
            let shown = if fld.kind == Kind::Choice {
                format!("‹ {} ›", fld.text)
            } else {
                fld.text.clone()
            };
            let mark = if fld.error.is_some() { "!" } else { " " };
            lines.push(Line::from(vec![
                Span::raw(format!(" {:<10}{mark}", fld.label)),
                Span::styled(shown, value_style(app, i, fld)),
            ]));
            if let Some(e) = &fld.error {
                // Wrapped on up to four lines: a knot-file error's position and reason come
                // after its path.
                let chars: Vec<char> = e.chars().collect();
                let w = width.saturating_sub(5).max(8);
                for (k, chunk) in chars.chunks(w).take(4).enumerate() {
                    let lead = if k == 0 { "   ↳ " } else { "     " };
                    let text = format!("{lead}{}", chunk.iter().collect::<String>());
                    lines.push(Line::styled(text, Style::new().fg(Color::Red)));
                }
            }
        }
    }
    lines
}

/// The setup page; `robot`: the robot's lines, at the foot of its left column.
fn draw_setup(f: &mut Frame, app: &App, area: Rect, robot: Option<Vec<Line<'static>>>) {
    let [left, right] = setup_columns(area);
    let mut lines = setup_lines(app, usize::from(left.width.saturating_sub(2)));
    if let Some(robot) = robot {
        // Under the settings, at the column's foot.
        let gap = usize::from(left.height).saturating_sub(lines.len() + robot.len());
        lines.extend(std::iter::repeat_n(Line::default(), gap));
        lines.extend(robot);
    }
    f.render_widget(Paragraph::new(lines).block(Block::new().borders(Borders::RIGHT)), left);

    // The gains take what they need (13 rows) as long as the actions keep three.
    let [gains, actions] = Layout::vertical([Constraint::Max(13), Constraint::Min(3)]).areas(right);
    draw_gains(f, app, gains);
    draw_actions(f, app, actions);
}

fn draw_gains(f: &mut Frame, app: &App, area: Rect) {
    let n = app.form.motor_tables;
    let cell = usize::from(area.width.saturating_sub(7)) / n.max(1);
    let cell = cell.clamp(4, 11);
    let mut lines = Vec::new();
    let mut head = vec![Span::raw(format!("{:<6}", ""))];
    for m in 0..n {
        let style = if m < app.form.n_motors() {
            Style::new().bold()
        } else {
            Style::new().fg(Color::DarkGray)
        };
        head.push(Span::styled(format!("{:>cell$}", format!("M{}", m + 1)), style));
    }
    lines.push(Line::from(head));
    let rows: Vec<&str> = std::iter::once("Home").chain(GAIN_ROWS).collect();
    for label in rows {
        let mut spans = vec![Span::raw(format!("{label:<6}"))];
        for (i, fld) in app
            .form
            .fields
            .iter()
            .enumerate()
            .filter(|(_, f)| f.label == label && f.place.motor().is_some())
        {
            // A value wider than its cell shows its end while typed, else its start and '…'
            // (the message line has it whole).
            let room = cell.saturating_sub(1);
            let n = fld.text.chars().count();
            let text: String = if n <= room {
                fld.text.clone()
            } else if i == app.focus && app.editing.is_some() {
                fld.text.chars().skip(n - room).collect()
            } else {
                fld.text.chars().take(room.saturating_sub(1)).chain(['…']).collect()
            };
            let mark = if fld.error.is_some() { "!" } else { " " };
            spans.push(Span::styled(
                format!("{text:>w$}{mark}", w = cell - 1),
                value_style(app, i, fld),
            ));
        }
        lines.push(Line::from(spans));
    }
    f.render_widget(
        Paragraph::new(lines).block(
            Block::bordered()
                .title(" Gains (one column per motor) ")
                .title_bottom(" ^T tune on the path · ^A take tuned "),
        ),
        area,
    );
}

fn draw_actions(f: &mut Frame, app: &App, area: Rect) {
    let rows = usize::from(area.height.saturating_sub(2));
    let width = usize::from(area.width.saturating_sub(2));
    let actions = [
        ("F2", "Home robot", Some(Action::Home)),
        ("F5", "Start controller", Some(Action::Run)),
        ("F6", "Step motors now", Some(Action::Step)),
        ("F10", "Exit (save)", Some(Action::Save)),
        ("F12", "Cancel (leave without saving)", None),
    ];
    let mut lines = Vec::new();
    if rows >= actions.len() {
        // One line per action, cut at the box's edge: the box never overflows.
        for (key, name, action) in actions {
            let (text, style) = match action.map(|a| app.form.blocking(a)) {
                Some(Some((field, _))) => {
                    // The reason is shown at the field itself; here only which field it is.
                    let by = field
                        .map_or("the settings file".to_string(), |i| app.form.fields[i].name());
                    (format!(" {key:<4}{name} — blocked by {by}"), Style::new().fg(Color::DarkGray))
                }
                Some(None) if app.running.is_some() && key != "F12" => {
                    (format!(" {key:<4}{name} — a move is running"), Style::new().dim())
                }
                _ => (format!(" {key:<4}{name}"), Style::new()),
            };
            lines.push(Line::styled(clip(&text, width), style));
        }
    } else if rows > 0 {
        // Too short for a line each: the keys that can act now, on one line.
        let ready: Vec<&str> = actions
            .iter()
            .filter(|(_, _, a)| a.is_none_or(|a| app.form.blocking(a).is_none()))
            .map(|(k, _, _)| *k)
            .collect();
        lines.push(Line::from(clip(&format!(" ready: {}", ready.join(" ")), width)));
    }
    f.render_widget(Paragraph::new(lines).block(Block::bordered().title(" Actions ")), area);
}

/// `text` cut to `width` characters, with `…` where it was cut.
fn clip(text: &str, width: usize) -> String {
    let n = text.chars().count();
    if n <= width {
        text.to_string()
    } else {
        text.chars().take(width.saturating_sub(1)).chain(['…']).collect()
    }
}

/// `line` cut into rows of at most `width` characters (the log wraps, it does not cut).
fn wrap_rows(line: &str, width: usize) -> Vec<String> {
    let chars: Vec<char> = line.chars().collect();
    if chars.is_empty() {
        return vec![String::new()];
    }
    chars.chunks(width.max(1)).map(|c| c.iter().collect()).collect()
}

fn draw_log(f: &mut Frame, app: &App, area: Rect) {
    let (w, h) =
        (usize::from(area.width.saturating_sub(2)), usize::from(area.height.saturating_sub(2)));
    let rows: Vec<(String, bool)> = app
        .log
        .iter()
        .flat_map(|l| {
            let red = l.contains("FAULT") || l.contains("error") || l.contains("fault");
            wrap_rows(l, w).into_iter().map(move |r| (r, red))
        })
        .collect();
    // Scrolled up from the end by `log_scroll` rows, never past the first.
    let last_start = rows.len().saturating_sub(h);
    let start = last_start.saturating_sub(app.log_scroll.min(last_start));
    let lines: Vec<Line> = rows[start..(start + h).min(rows.len())]
        .iter()
        .map(|(r, red)| {
            Line::styled(r.clone(), if *red { Style::new().fg(Color::Red) } else { Style::new() })
        })
        .collect();
    let title = if start < last_start {
        format!(
            " qmarc-starter output — rows {}‥{} of {} (End: follow) ",
            start + 1,
            start + lines.len(),
            rows.len()
        )
    } else {
        " qmarc-starter output ".to_string()
    };
    f.render_widget(Paragraph::new(lines).block(Block::bordered().title(title)), area);
}

fn draw_results(f: &mut Frame, app: &App, area: Rect) {
    let tuned = app.tuned.as_ref().filter(|t| t.latest);
    let mut lines = tuned.map(crate::tuning::lines).unwrap_or_default();
    let title = match (tuned, &app.last) {
        (None, None) => {
            let text = match &app.results_note {
                Some(why) => format!("No results to show: {why}"),
                None => "No move yet: F6 steps, F5 runs the trajectory, F2 homes.".to_string(),
            };
            f.render_widget(
                Paragraph::new(text)
                    .wrap(Wrap { trim: true })
                    .block(Block::bordered().title(" Results ")),
                area,
            );
            return;
        }
        (Some(_), last) => {
            if last.is_some() {
                lines.push(Line::styled("The path with the tuned gains:", Style::new().bold()));
            }
            " Results of the last tuning ".to_string()
        }
        (None, Some(r)) => {
            // The last move left none of its own: the folder's are an earlier move's.
            let whose = match &app.results_note {
                Some(why) => {
                    lines.push(Line::styled(
                        format!("An earlier move's results — {why}."),
                        Style::new().fg(Color::Yellow),
                    ));
                    "an earlier move"
                }
                None => "the last move",
            };
            match r.age(std::time::SystemTime::now()) {
                Some(age) => format!(" Results of {whose} ({age}) "),
                None => format!(" Results of {whose} "),
            }
        }
    };
    if let Some(r) = &app.last {
        lines.extend(move_lines(r));
    }
    // Wrapped, so a long fault message is read whole at 80 columns; scrolled (↑↓ PgUp PgDn),
    // so a long report is read whole at 80×24.
    let p = scrolled(lines, app.page_scroll, area);
    f.render_widget(p.block(Block::bordered().title(title)), area);
}

/// The summary of the move `r`: its outcome, error figures, settling and timing.
fn move_lines(r: &crate::results::MoveResult) -> Vec<Line<'static>> {
    let s = &r.summary;
    let mut lines = Vec::new();
    let what = s.what();
    let all_followed = s.motors.iter().all(|m| m.followed);
    match &s.fault {
        None if all_followed => lines.push(Line::styled(
            format!("{what}: ok — {} cycles of {} µs", s.cycles, s.period_us),
            Style::new().fg(Color::Green).bold(),
        )),
        None => lines.push(Line::styled(
            format!("{what}: done — a motor did not follow its command ({} cycles)", s.cycles),
            Style::new().fg(Color::Red).bold(),
        )),
        Some(fl) => lines.push(Line::styled(
            format!("{what}: FAULT {}: {}", fl.kind, fl.message),
            Style::new().fg(Color::Red).bold(),
        )),
    }
    lines.push(Line::from(format!(
        "{}{}",
        s.timing.policy,
        if s.degraded { " — DEGRADED: not real time" } else { "" }
    )));
    if let Some(homing) = &s.homing {
        lines.push(Line::styled("homing (counts before homing)", Style::new().bold()));
        for m in &homing.motors {
            let at = |v: Option<f64>| v.map_or("not reached".to_string(), |c| format!("{c:.0}"));
            lines.push(Line::from(format!(
                "M{} switch found {}, cleared {}, home {}{}",
                m.motor,
                at(m.switch_found_counts),
                at(m.switch_cleared_counts),
                at(m.home_counts),
                if m.home { " ✓ reads 0" } else { "" }
            )));
        }
    }
    if !s.motors.is_empty() {
        lines.push(Line::styled(
            format!(
                "{:<3}{:>9}{:>9}{:>12}{:>14}{:>10}{:>10}",
                "M", "min cnt", "max cnt", "Σ|e| cnt", "Σe² cnt²", "Σ|e| rad", "Σe² rad²"
            ),
            Style::new().bold(),
        ));
    }
    for (m, e) in s.motors.iter().enumerate() {
        lines.push(Line::from(format!(
            "{:<3}{:>9.1}{:>9.1}{:>12.0}{:>14.3e}{:>10.3}{:>10.3e}",
            m + 1,
            e.min_error_counts,
            e.max_error_counts,
            e.accumulated_abs_error_counts,
            e.sum_squares_error_counts2,
            e.accumulated_abs_error_rad,
            e.sum_squares_error_rad2
        )));
        let note = if e.followed { String::new() } else { "  DID NOT FOLLOW".to_string() };
        lines.push(Line::styled(
            format!(
                "{:<3}{:>9}{:>9}   rad: min {:.3e}  max {:.3e}{note}",
                "", "", "", e.min_error_rad, e.max_error_rad
            ),
            if e.followed { Style::new().dim() } else { Style::new().fg(Color::Red).bold() },
        ));
    }
    if let Some(a) = &s.approach {
        lines.push(Line::from(format!(
            "approach {:.2} s to the path's start (apart from the figures above)",
            a.seconds
        )));
    }
    if let Some(st) = &s.settle {
        let list = |v: &[f64]| v.iter().map(|e| format!("{e:.1}")).collect::<Vec<_>>().join(" ");
        lines.push(Line::from(format!(
            "settle {:.2} s: error at its end {} cnt",
            st.seconds,
            list(&st.final_error_counts)
        )));
    }
    let t = &s.timing;
    lines.push(Line::styled(
        format!("{:<20}{:>10}{:>10}{:>10}{:>10}", "timing", "p50", "p99", "p99.9", "max"),
        Style::new().bold(),
    ));
    for (name, p) in [
        ("wake latency", &t.wake_latency_us),
        ("period error", &t.period_error_us),
        ("read round trip", &t.read_us),
        ("tick → DAC written", &t.output_latency_us),
    ] {
        let u = qmarc_report::table::human_us;
        lines.push(Line::from(format!(
            "{name:<20}{:>10}{:>10}{:>10}{:>10}",
            u(p.p50),
            u(p.p99),
            u(p.p999),
            u(p.max)
        )));
    }
    lines.push(Line::from(format!(
        "periods off by > 40 µs: {}   missed: {}",
        t.outside_40us, t.missed_periods
    )));
    for w in &s.warnings {
        lines.push(Line::styled(format!("warning: {w}"), Style::new().fg(Color::Yellow)));
    }
    lines
}

fn bounds(pts: &[&[(f64, f64)]]) -> ([f64; 2], [f64; 2]) {
    let mut x = [f64::INFINITY, f64::NEG_INFINITY];
    let mut y = [f64::INFINITY, f64::NEG_INFINITY];
    for p in pts.iter().flat_map(|s| s.iter()) {
        x = [x[0].min(p.0), x[1].max(p.0)];
        y = [y[0].min(p.1), y[1].max(p.1)];
    }
    if !x[0].is_finite() {
        return ([0.0, 1.0], [0.0, 1.0]);
    }
    let pad = ((y[1] - y[0]) * 0.05).max(1e-9);
    ([x[0], x[1].max(x[0] + 1e-9)], [y[0] - pad, y[1] + pad])
}

/// One line of a chart: its name, colour and points.
type Trace<'a> = (&'a str, Color, &'a [(f64, f64)]);

fn chart<'a>(title: impl Into<Line<'a>>, sets: Vec<Trace<'a>>) -> Chart<'a> {
    let slices: Vec<&[(f64, f64)]> = sets.iter().map(|s| s.2).collect();
    let legend = Line::from(
        sets.iter()
            .flat_map(|(name, color, _)| {
                [Span::styled(" ━ ", Style::new().fg(*color)), Span::raw(format!("{name} "))]
            })
            .collect::<Vec<_>>(),
    )
    .right_aligned();
    let (xb, yb) = bounds(&slices);
    let datasets = sets
        .into_iter()
        .map(|(name, color, data)| {
            Dataset::default()
                .name(name)
                .marker(symbols::Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::new().fg(color))
                .data(data)
        })
        .collect();
    Chart::new(datasets)
        // The legend is in the bottom border, so it costs the plot no room at any size.
        .block(Block::bordered().title(title).title_bottom(legend))
        .legend_position(None)
        .x_axis(
            Axis::default().bounds(xb).labels([format!("{:.2}s", xb[0]), format!("{:.2}s", xb[1])]),
        )
        .y_axis(
            Axis::default().bounds(yb).labels([format!("{:.0}", yb[0]), format!("{:.0}", yb[1])]),
        )
}

fn draw_charts(f: &mut Frame, app: &App, area: Rect) {
    let (last, series, note) = match app.charts_view() {
        // While a move runs: its live telemetry, the newest seconds.
        ChartsView::Live(live) => {
            let [area, note] =
                Layout::vertical([Constraint::Min(6), Constraint::Length(1)]).areas(area);
            f.render_widget(Line::styled(live.title(), Style::new().bold()), note);
            return draw_series(f, app, &live.series, area);
        }
        ChartsView::Nothing(why) => {
            f.render_widget(
                Paragraph::new(why)
                    .wrap(Wrap { trim: true })
                    .block(Block::bordered().title(" Charts ")),
                area,
            );
            return;
        }
        ChartsView::Gathered { result, series, note } => (result, series, note),
    };
    // Whose data they are, when not the last move's (wrapped whole), and the PNG plots of
    // the same move, on the last lines.
    let yellow = Style::new().fg(Color::Yellow);
    let note = note.map_or_else(Vec::new, |n| wrap_spans(&[(n, yellow)], usize::from(area.width)));
    let [note_area, area, files] = Layout::vertical([
        Constraint::Length(u16::try_from(note.len()).unwrap_or(u16::MAX)),
        Constraint::Min(6),
        Constraint::Length(2),
    ])
    .areas(area);
    f.render_widget(Paragraph::new(note), note_area);
    let names: Vec<String> = last.plots.iter().map(|p| p.display().to_string()).collect();
    f.render_widget(
        Paragraph::new(if names.is_empty() {
            "PNG plots: none for this move".to_string()
        } else {
            format!("PNG plots: {}", names.join("  "))
        })
        .wrap(Wrap { trim: true }),
        files,
    );
    draw_series(f, app, series, area);
}

/// The three charts of `series`: command vs actual of the charted motor, its following
/// error, and the servo period.
fn draw_series(f: &mut Frame, app: &App, series: &crate::results::Series, area: Rect) {
    let m = app.chart_motor;
    let width = usize::from(area.width) * 2;
    let cmd = thin(&series.points(series.cmd.get(m)), width);
    let act = thin(&series.points(series.act.get(m)), width);
    let err = thin(&series.error(m), width);
    let period = thin(&series.period_us, width);
    let [a, b, c] = Layout::vertical([
        Constraint::Ratio(2, 5),
        Constraint::Ratio(3, 10),
        Constraint::Ratio(3, 10),
    ])
    .areas(area);
    f.render_widget(
        chart(
            format!(" motor {} (←/→): command vs actual, counts ", m + 1),
            vec![("command", Color::Cyan, &cmd), ("actual", Color::Yellow, &act)],
        ),
        a,
    );
    f.render_widget(
        chart(" following error, counts ", vec![("command − actual", Color::Red, &err)]),
        b,
    );
    f.render_widget(chart(" servo period, µs ", vec![("period", Color::Green, &period)]), c);
}

/// `lines` wrapped to `area` and scrolled down by `scroll` rows, never past the last page.
fn scrolled<'a>(lines: Vec<Line<'a>>, scroll: usize, area: Rect) -> Paragraph<'a> {
    let width = usize::from(area.width.saturating_sub(2)).max(1);
    let height = usize::from(area.height.saturating_sub(2));
    let rows: usize = lines.iter().map(|l| l.width().max(1).div_ceil(width)).sum();
    let top = scroll.min(rows.saturating_sub(height));
    Paragraph::new(lines)
        .wrap(Wrap { trim: false })
        .scroll((u16::try_from(top).unwrap_or(u16::MAX), 0))
}

mod history;
#[cfg(test)]
mod tests;

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
    // The keys whole where they fit, in 80 columns shorter.
    let bar = if keys.width >= 86 {
        " F2 Home F5 Run F6 Step ^T Tune ^G Go to ^O Grip ^B Belt F9 Abort F10 Exit F12 Cancel"
    } else {
        "F2 Home F5 Run F6 Step ^T Tune ^G Go ^O Grip ^B Belt F9 Stop F10 Exit F12 Cancel"
    };
    f.render_widget(Line::from(bar).style(Style::new().dim()), keys);
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

mod charts;
mod history;
mod rows;
use charts::draw_charts;
use rows::{indented, message_rows, robot_strip, robot_view, setup_robot_column, wrap_spans};
#[cfg(test)]
mod tests;

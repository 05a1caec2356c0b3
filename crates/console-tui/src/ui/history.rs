//! The history page: the session's moves and their accumulated errors.

use super::*;

pub(super) fn draw_history(f: &mut Frame, app: &App, area: Rect) {
    let mut lines = vec![Line::styled(
        format!("{:<4}{:<16}{:<18}{}", "#", "move", "outcome", "Σ|error| per motor, counts"),
        Style::new().bold(),
    )];
    if app.history.is_empty() {
        lines.push(Line::from("No move yet this session."));
    }
    for (i, h) in app.history.iter().enumerate() {
        // The trend compares whole moves of the same kind: a move a fault cut short has a
        // smaller sum without being better.
        let prev = app.history[..i]
            .iter()
            .rev()
            .find(|p| p.what == h.what && p.fault.is_none())
            .filter(|_| h.fault.is_none())
            .map(|p| &p.accumulated);
        let outcome = h.fault.map_or("ok".to_string(), |k| k.to_string());
        let acc: Vec<String> = h
            .accumulated
            .iter()
            .enumerate()
            .map(|(m, a)| {
                let trend = match prev.and_then(|p| p.get(m)) {
                    Some(p) if a < p => " ↓",
                    Some(p) if a > p => " ↑",
                    _ => "",
                };
                format!("{a:.0}{trend}")
            })
            .collect();
        let gains: Vec<String> =
            h.gains.iter().map(|(kp, kd, kvff)| format!("{kp:.0}/{kd:.0}/{kvff:.0}")).collect();
        let style = if h.fault.is_some() { Style::new().fg(Color::Red) } else { Style::new() };
        lines.push(Line::styled(
            format!("{:<4}{:<16}{:<18}{}", h.n, h.what, outcome, acc.join("  ")),
            style,
        ));
        lines
            .push(Line::styled(format!("    Kp/Kd/Kvff {}", gains.join("  ")), Style::new().dim()));
    }
    let p = scrolled(lines, app.page_scroll, area);
    f.render_widget(
        p.block(
            Block::bordered()
                .title(" History (↓ ↑: Σ|e| against the last whole move of its kind) "),
        ),
        area,
    );
}

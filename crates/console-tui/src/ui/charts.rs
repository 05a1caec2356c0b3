//! The charts page (F7): a running move's live telemetry, or the gathered data of the last
//! move (or, after a move that left none, of the one before it, said so).

use super::*;

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

pub(super) fn draw_charts(f: &mut Frame, app: &App, area: Rect) {
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

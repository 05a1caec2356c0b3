//! The plots of one move, from its `gather.csv` and `summary.json`.

use crate::PlotError;
use crate::chart::{
    COMMAND, Drawn, FONT, Panel, PanelSpec, Trace, figure, legend, line_panel, motor_colour,
    per_motor, range, text, ticks, widen,
};
use plotters::prelude::*;
use qmarc_kinematics::{ARMS, Robot};
use qmarc_report::Summary;
use qmarc_report::output::PLOT_FILES;
use qmarc_report::series::Series;
use std::ops::Range;
use std::path::{Path, PathBuf};

const TIME: &str = "time, s";

/// Draws the plots of the move whose files are in `dir` (its `summary`; `robot` for the
/// end-effector plots, which need three arms) into `dir`, and returns their paths: the
/// names of [`PLOT_FILES`], those the gathered columns allow.
pub fn move_plots(
    dir: &Path,
    summary: &Summary,
    robot: Option<&Robot>,
) -> Result<Vec<PathBuf>, PlotError> {
    let period_s = f64::from(summary.period_us) * 1e-6;
    let s = Series::read(dir, period_s).map_err(PlotError::Data)?;
    if s.t.len() < 3 {
        return Err(PlotError::Data(format!(
            "{}: gather.csv has {} rows, too few to plot",
            dir.display(),
            s.t.len()
        )));
    }
    let title = format!("QMARC {}", summary.what());
    let [arms_png, error_png, velocity_png, period_png, e3d_png, exz_png] =
        PLOT_FILES.map(|f| dir.join(f));
    let mut done = Vec::new();
    let n = s.n_motors();
    if n > 0 {
        // Where things happen, when that is a small part of the move (a step's response in
        // its first tenth): the arms zoom on it, the error gets a detail panel.
        let errors: Vec<Vec<(f64, f64)>> = (0..n).map(|m| s.error(m)).collect();
        let detail = active_window(&s.t, &errors);
        done.push(figure(&arms_png, 260, n, &title, |p| arms(p, &s, detail.clone()))?);
        let panels = if detail.is_some() { 2 } else { 1 };
        done.push(figure(&error_png, 420, panels, &title, |p| {
            error(&p[0], &s, summary, None)?;
            match &detail {
                Some(w) => error(&p[1], &s, summary, Some(w.clone())),
                None => Ok(()),
            }
        })?);
        let nominal: Vec<f64> = s.cycle.iter().map(|c| c * period_s).collect();
        done.push(figure(&velocity_png, 360, 2, &title, |p| velocity(p, &s, &nominal))?);
    }
    if !s.period_us.is_empty() || !s.dac.is_empty() {
        done.push(figure(&period_png, 360, 2, &title, |p| period(p, &s, summary))?);
    }
    if let Some(robot) = robot.filter(|_| n == ARMS) {
        let path = EffectorPath::of(robot, &s);
        if path.cmd.len() >= 2 {
            done.push(figure(&e3d_png, 760, 1, &title, |p| effector_3d(&p[0], &path))?);
            done.push(figure(&exz_png, 400, 2, &title, |p| effector_xz(p, &path))?);
        }
    }
    Ok(done)
}

/// The stretch of a move where its following error is more than 2 % of its largest (from a
/// little before the first such row to a fifth of the stretch after the last), if it is less
/// than a quarter of the move: the rest is holding still, and drawn whole it would squeeze
/// the dynamics into a sliver.
pub(crate) fn active_window(t: &[f64], errors: &[Vec<(f64, f64)>]) -> Option<Range<f64>> {
    let (t0, t1) = (*t.first()?, *t.last()?);
    let peak = errors.iter().flatten().map(|p| p.1.abs()).fold(0.0, f64::max);
    if !(peak > 0.0 && t1 > t0) {
        return None;
    }
    let busy: Vec<f64> =
        errors.iter().flatten().filter(|p| p.1.abs() > 0.02 * peak).map(|p| p.0).collect();
    let (first, last) =
        (busy.iter().copied().fold(t1, f64::min), busy.iter().copied().fold(t0, f64::max));
    let span = (last - first).max(0.01 * (t1 - t0));
    let window = (first - 0.05 * span).max(t0)..(last + 0.2 * span).min(t1);
    (window.end - window.start < 0.25 * (t1 - t0)).then_some(window)
}

/// `pts` within `w` (all of them without one).
fn within(pts: &[(f64, f64)], w: Option<&Range<f64>>) -> Vec<(f64, f64)> {
    pts.iter().filter(|p| w.is_none_or(|w| w.contains(&p.0))).copied().collect()
}

/// One panel per motor: command and actual position, counts — over `detail` only, where
/// the move's dynamics are a small part of it.
fn arms(panels: &[Panel<'_, '_>], s: &Series, detail: Option<Range<f64>>) -> Drawn {
    let zoom = detail.as_ref().map_or(String::new(), |w| {
        format!(
            " (detail: {:.3}–{:.3} s of {:.3}–{:.3} s; the rest holds)",
            w.start,
            w.end,
            s.t[0],
            s.t[s.t.len() - 1]
        )
    });
    for (m, area) in panels.iter().enumerate() {
        let (cmd, act) = (s.points(s.cmd.get(m)), s.points(s.act.get(m)));
        let (cmd, act) = (within(&cmd, detail.as_ref()), within(&act, detail.as_ref()));
        line_panel(
            area,
            &PanelSpec {
                min_span: (0.0, 0.0),
                integer_x: false,
                from_zero: false,
                title: format!("motor {}: command and actual position{zoom}", m + 1),
                x: TIME,
                y: "position, counts".into(),
                traces: vec![
                    Trace { name: "command".into(), colour: COMMAND, points: false, pts: &cmd },
                    Trace {
                        name: "actual".into(),
                        colour: motor_colour(m),
                        points: false,
                        pts: &act,
                    },
                ],
            },
        )?;
    }
    Ok(())
}

/// Every motor's following error, counts (with its size in rad at the arm in the caption);
/// over `detail` only, if given.
fn error(area: &Panel<'_, '_>, s: &Series, summary: &Summary, detail: Option<Range<f64>>) -> Drawn {
    let errors: Vec<Vec<(f64, f64)>> =
        (0..s.n_motors()).map(|m| within(&s.error(m), detail.as_ref())).collect();
    let per_rad = summary.counts_per_rad;
    let what = match &detail {
        Some(w) => format!("following error, detail {:.3}–{:.3} s", w.start, w.end),
        None => "following error, command − actual".to_string(),
    };
    line_panel(
        area,
        &PanelSpec {
            min_span: (0.0, 0.0),
            integer_x: false,
            from_zero: false,
            title: if per_rad > 0.0 {
                format!("{what} (1 count = {:.3e} rad)", 1.0 / per_rad)
            } else {
                what
            },
            x: TIME,
            y: "error, counts".into(),
            traces: per_motor("motor", &errors),
        },
    )
}

/// d y / d x at each interior point (central differences; `x` may be unevenly spaced).
pub(crate) fn derivative(x: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    x.windows(3)
        .zip(y.windows(3))
        .filter(|(x, _)| x[2] > x[0])
        .map(|(x, y)| (x[1], (y[2] - y[0]) / (x[2] - x[0])))
        .collect()
}

/// d² y / d x² at each interior point.
pub(crate) fn second_derivative(x: &[f64], y: &[f64]) -> Vec<(f64, f64)> {
    x.windows(3)
        .zip(y.windows(3))
        .filter(|(x, _)| x[2] > x[1] && x[1] > x[0])
        .map(|(x, y)| {
            let (h1, h2) = (x[1] - x[0], x[2] - x[1]);
            (x[1], 2.0 * ((y[2] - y[1]) / h2 - (y[1] - y[0]) / h1) / (h1 + h2))
        })
        .collect()
}

/// `x` and `y` with the rest before and after the move: a point a step before the first
/// holding the first command, and one a step after the last holding the last. Every move
/// starts and ends at rest, so the derivatives at its ends are there too: a step's
/// acceleration shows its rise as well as its fall (before: the first sample, not interior,
/// had none, and only the negative spike was drawn).
pub(crate) fn at_rest_around(x: &[f64], y: &[f64]) -> (Vec<f64>, Vec<f64>) {
    let (Some(&x0), Some(&xn), Some(&y0), Some(&yn)) = (x.first(), x.last(), y.first(), y.last())
    else {
        return (x.to_vec(), y.to_vec());
    };
    let (h0, hn) = match x {
        [a, b, ..] => (b - a, x[x.len() - 1] - x[x.len() - 2]),
        _ => (1.0, 1.0),
    };
    let xs = std::iter::once(x0 - h0).chain(x.iter().copied()).chain([xn + hn]).collect();
    let ys = std::iter::once(y0).chain(y.iter().copied()).chain([yn]).collect();
    (xs, ys)
}

/// The command's velocity and acceleration per motor, from the gathered command on the
/// nominal clock (cycle × period: the command advances by cycles, whatever the wake times),
/// at rest before and after it.
fn velocity(panels: &[Panel<'_, '_>], s: &Series, nominal: &[f64]) -> Drawn {
    let n = s.n_motors();
    let padded: Vec<_> = (0..n).map(|m| at_rest_around(nominal, &s.cmd[m])).collect();
    let v: Vec<_> = padded.iter().map(|(x, y)| derivative(x, y)).collect();
    let a: Vec<_> = padded.iter().map(|(x, y)| second_derivative(x, y)).collect();
    for (area, (what, unit, series)) in
        panels.iter().zip([("velocity", "counts/s", &v), ("acceleration", "counts/s²", &a)])
    {
        line_panel(
            area,
            &PanelSpec {
                min_span: (0.0, 0.0),
                integer_x: false,
                from_zero: false,
                title: format!("command {what}"),
                x: TIME,
                y: format!("{what}, {unit}"),
                traces: per_motor("motor", series),
            },
        )?;
    }
    Ok(())
}

/// The servo period over the move with the ±40 µs band (thesis Fig. 5-1), and the DAC
/// output that goes with it.
fn period(panels: &[Panel<'_, '_>], s: &Series, summary: &Summary) -> Drawn {
    let nominal = f64::from(summary.period_us);
    let (t0, t1) = (s.t[0], s.t[s.t.len() - 1]);
    let lo = [(t0, nominal - 40.0), (t1, nominal - 40.0)];
    let hi = [(t0, nominal + 40.0), (t1, nominal + 40.0)];
    let band = RGBColor(150, 150, 150);
    let every = summary.gather_every.max(1);
    let t = &summary.timing;
    // A stall of milliseconds would stretch the axis until the ±40 µs band is a line: the
    // axis keeps to the band's scale, and the periods beyond it are drawn at its edge and
    // counted.
    let axis = PeriodAxis::of(nominal, &s.period_us);
    let beyond = match axis.beyond {
        0 => String::new(),
        k => format!(
            "; {k} beyond ±{PERIOD_AXIS_US:.0} µs drawn at the edge, the longest {}",
            qmarc_report::table::human_us(axis.longest_us)
        ),
    };
    let counted = format!(
        "the loop counted {} periods off by > 40 µs, {} missed{beyond}",
        t.outside_40us, t.missed_periods
    );
    line_panel(
        &panels[0],
        &PanelSpec {
            min_span: (0.0, 100.0),
            integer_x: false,
            from_zero: false,
            title: if summary.deterministic {
                "servo period: simulated time (--deterministic), exact by construction".into()
            } else if every > 1 {
                format!("servo period, mean over each {every} gathered cycles ({counted})")
            } else {
                format!("servo period ({counted})")
            },
            x: TIME,
            y: "period, µs".into(),
            traces: vec![
                Trace {
                    name: "period".into(),
                    colour: motor_colour(2),
                    points: false,
                    pts: &axis.pts,
                },
                Trace {
                    name: format!("{nominal} ± 40 µs"), colour: band, points: false, pts: &lo
                },
                Trace { name: String::new(), colour: band, points: false, pts: &hi },
            ],
        },
    )?;
    let dac: Vec<_> = s.dac.iter().map(|d| s.points(Some(d))).collect();
    line_panel(
        &panels[1],
        &PanelSpec {
            min_span: (0.0, 0.0),
            integer_x: false,
            from_zero: false,
            title: "DAC output (±8191 = ±10 V)".into(),
            x: TIME,
            y: "DAC, codes".into(),
            traces: per_motor("motor", &dac),
        },
    )
}

/// How far from the nominal period the period panel's axis reaches, µs (five times the
/// ±40 µs band).
pub(crate) const PERIOD_AXIS_US: f64 = 200.0;

/// The periods as the panel draws them: within [`PERIOD_AXIS_US`] of the nominal, those
/// beyond at the edge, counted, with the longest.
pub(crate) struct PeriodAxis {
    pub(crate) pts: Vec<(f64, f64)>,
    pub(crate) beyond: usize,
    pub(crate) longest_us: f64,
}

impl PeriodAxis {
    pub(crate) fn of(nominal: f64, periods: &[(f64, f64)]) -> PeriodAxis {
        let (lo, hi) = (nominal - PERIOD_AXIS_US, nominal + PERIOD_AXIS_US);
        let out: Vec<f64> =
            periods.iter().map(|p| p.1).filter(|v| !(lo..=hi).contains(v)).collect();
        PeriodAxis {
            pts: periods.iter().map(|&(t, v)| (t, v.clamp(lo, hi))).collect(),
            beyond: out.len(),
            longest_us: out.iter().copied().fold(0.0, f64::max),
        }
    }
}

/// The end-effector path through the forward kinematics, mm: rows whose command or actual
/// has no pose are left out.
struct EffectorPath {
    t: Vec<f64>,
    cmd: Vec<[f64; 3]>,
    act: Vec<[f64; 3]>,
}

impl EffectorPath {
    fn of(robot: &Robot, s: &Series) -> EffectorPath {
        let mut p = EffectorPath { t: Vec::new(), cmd: Vec::new(), act: Vec::new() };
        for (i, &t) in s.t.iter().enumerate() {
            let at = |v: &[Vec<f64>]| -> [f64; ARMS] { std::array::from_fn(|m| v[m][i]) };
            if let (Ok(c), Ok(a)) = (robot.point_of(&at(&s.cmd)), robot.point_of(&at(&s.act))) {
                p.t.push(t);
                p.cmd.push([c.x * 1e3, c.y * 1e3, c.z * 1e3]);
                p.act.push([a.x * 1e3, a.y * 1e3, a.z * 1e3]);
            }
        }
        p
    }
}

/// The names of the 3-D plot's axes: x, y, z.
pub(crate) const AXIS_NAMES: [&str; 3] = ["x, mm", "y, mm", "z, mm (up)"];

/// The path in 3-D, command and actual (plotters' vertical axis is its y: z goes there).
fn effector_3d(area: &Panel<'_, '_>, p: &EffectorPath) -> Drawn {
    let both = || p.cmd.iter().chain(&p.act);
    let r = [0, 1, 2].map(|k| range(both().map(|q| q[k])));
    // Each axis spans at least a quarter of the widest, about its middle: a path flat in y
    // is drawn flat, not its tenth of a millimetre blown up to the box's depth.
    let widest = r.iter().map(|r| r.end - r.start).fold(0.0, f64::max);
    let [xs, ys, zs] = r.map(|r| widen(r, widest / 4.0));
    let (fx, fy, fz) = (ticks(&xs), ticks(&ys), ticks(&zs));
    let mut chart = text(
        ChartBuilder::on(area)
            .caption("end-effector path, mm (x, y across; z up)", (FONT, 20))
            .margin(20)
            .build_cartesian_3d(xs.clone(), zs.clone(), ys.clone()),
    )?;
    chart.with_projection(|mut pb| {
        pb.yaw = 0.6;
        pb.pitch = 0.35;
        pb.scale = 0.8;
        pb.into_matrix()
    });
    text(
        chart
            .configure_axes()
            .x_formatter(&fx)
            .y_formatter(&fz)
            .z_formatter(&fy)
            .label_style((FONT, 14))
            .light_grid_style(RGBColor(225, 225, 225))
            .max_light_lines(4)
            .draw(),
    )?;
    // plotters' 3-D axes take no descriptions: each axis is named at its far end.
    let named = (FONT, 16).into_font().color(&BLACK);
    let (x_end, z_lo, y_lo) = (xs.end, zs.start, ys.start);
    for (name, at) in [
        (AXIS_NAMES[0], (x_end, z_lo, y_lo)),
        (AXIS_NAMES[1], (xs.start, z_lo, ys.end)),
        (AXIS_NAMES[2], (xs.start, zs.end, y_lo)),
    ] {
        text(chart.draw_series(std::iter::once(Text::new(name, at, named.clone()))))?;
    }
    for (name, pts, colour, width) in
        [("command", &p.cmd, COMMAND, 1), ("actual", &p.act, motor_colour(0), 2)]
    {
        let style = colour.stroke_width(width);
        text(chart.draw_series(LineSeries::new(pts.iter().map(|q| (q[0], q[2], q[1])), style)))?
            .label(name)
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
    }
    legend(&mut chart, SeriesLabelPosition::UpperRight)
}

/// The X-Z projection, command and actual (thesis Fig. 5-4), and the distance between them.
fn effector_xz(panels: &[Panel<'_, '_>], p: &EffectorPath) -> Drawn {
    let xz = |v: &[[f64; 3]]| -> Vec<(f64, f64)> { v.iter().map(|q| (q[0], q[2])).collect() };
    let (cmd, act) = (xz(&p.cmd), xz(&p.act));
    line_panel(
        &panels[0],
        &PanelSpec {
            // At least 10 mm each way: millimetres of command stay millimetres, encoder
            // counts (38 µm at the arm tip) do not fill the panel.
            min_span: (10.0, 10.0),
            integer_x: false,
            from_zero: false,
            title: "end-effector path, X-Z projection".into(),
            x: "x, mm",
            y: "z, mm".into(),
            traces: vec![
                Trace { name: "command".into(), colour: COMMAND, points: false, pts: &cmd },
                Trace { name: "actual".into(), colour: motor_colour(0), points: false, pts: &act },
            ],
        },
    )?;
    let dist: Vec<(f64, f64)> =
        p.t.iter()
            .zip(p.cmd.iter().zip(&p.act))
            .map(|(&t, (c, a))| {
                (t, ((c[0] - a[0]).powi(2) + (c[1] - a[1]).powi(2) + (c[2] - a[2]).powi(2)).sqrt())
            })
            .collect();
    line_panel(
        &panels[1],
        &PanelSpec {
            min_span: (0.0, 0.0),
            integer_x: false,
            from_zero: false,
            title: "end-effector error, |command − actual|".into(),
            x: TIME,
            y: "distance, mm".into(),
            traces: vec![Trace {
                name: "distance".into(),
                colour: motor_colour(1),
                points: false,
                pts: &dist,
            }],
        },
    )
}

//! The drawing every plot shares: a figure of stacked panels written atomically, a line
//! panel with its units and legend, the ranges, the colours.

use crate::PlotError;
use plotters::coord::{CoordTranslate, Shift};
use plotters::prelude::*;
use std::path::{Path, PathBuf};
use std::sync::Once;

/// The family every text is drawn in; registered once from the embedded DejaVu Sans.
pub(crate) const FONT: &str = "sans-serif";

/// One panel of a figure.
pub(crate) type Panel<'a, 'b> = DrawingArea<BitMapBackend<'a>, Shift>;

/// A drawing failure, as text (plotters' errors carry the backend's type).
pub(crate) type Drawn = Result<(), String>;

/// Turns any plotters error into text.
pub(crate) fn text<T, E: std::fmt::Display>(r: Result<T, E>) -> Result<T, String> {
    r.map_err(|e| e.to_string())
}

/// Colour of motor/arm `m` (0-based): four that tell apart on paper and screen.
pub(crate) fn motor_colour(m: usize) -> RGBColor {
    [RGBColor(31, 119, 180), RGBColor(214, 39, 40), RGBColor(44, 160, 44), RGBColor(148, 103, 189)]
        [m % 4]
}

/// The command's colour when drawn against an actual.
pub(crate) const COMMAND: RGBColor = RGBColor(40, 40, 40);

/// At most about `2·buckets` of `pts`: of each run of consecutive points its lowest and its
/// highest, in their order — every peak and every stall stays, and a dense series draws fast.
pub(crate) fn decimate(pts: &[(f64, f64)], buckets: usize) -> Vec<(f64, f64)> {
    let run = pts.len().div_ceil(buckets.max(1)).max(1);
    if run <= 2 {
        return pts.to_vec();
    }
    let mut out = Vec::with_capacity(2 * buckets + 2);
    for c in pts.chunks(run) {
        let lo = c.iter().enumerate().min_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i);
        let hi = c.iter().enumerate().max_by(|a, b| a.1.1.total_cmp(&b.1.1)).map(|(i, _)| i);
        let (Some(lo), Some(hi)) = (lo, hi) else { continue };
        out.push(c[lo.min(hi)]);
        if lo != hi {
            out.push(c[lo.max(hi)]);
        }
    }
    out
}

/// One line of a panel.
pub(crate) struct Trace<'p> {
    /// Legend text.
    pub name: String,
    /// Colour.
    pub colour: RGBColor,
    /// A marker at each point too (few points: trials).
    pub points: bool,
    /// The points (x, y).
    pub pts: &'p [(f64, f64)],
}

/// One thick trace per motor, named `motor 1`, `motor 2`, …
pub(crate) fn per_motor<'p>(label: &str, series: &'p [Vec<(f64, f64)>]) -> Vec<Trace<'p>> {
    series
        .iter()
        .enumerate()
        .map(|(m, pts)| Trace {
            name: format!("{label} {}", m + 1),
            colour: motor_colour(m),
            points: false,
            pts,
        })
        .collect()
}

/// What a panel shows.
pub(crate) struct PanelSpec<'p> {
    /// Caption above it.
    pub title: String,
    /// x axis label, with its unit.
    pub x: &'static str,
    /// y axis label, with its unit.
    pub y: String,
    /// The lines.
    pub traces: Vec<Trace<'p>>,
    /// Each axis spans at least this much (x, y), about its data's middle: a path that
    /// hardly moves in one direction is not blown up to fill the panel. 0: the data's span.
    pub min_span: (f64, f64),
    /// The x axis counts whole things (trials): only whole numbers are labelled.
    pub integer_x: bool,
    /// The y axis starts at zero (or below, for negative data): a small spread of large
    /// values is shown as what it is, not stretched over the whole axis.
    pub from_zero: bool,
}

/// A line panel's layout: its caption's size (pt; the caption takes about 1.5 × that in
/// px), the margin around it and the room of the x and y labels, px.
const CAPTION_PT: u32 = 20;
const PANEL_MARGIN_PX: u32 = 10;
const X_LABELS_PX: u32 = 45;
const Y_LABELS_PX: u32 = 95;

/// Pixels of a legend's line of text and of its frame around the lines (at the 15-point
/// legend font), and of its distance from the plot's corner.
const LEGEND_LINE_PX: f64 = 21.0;
const LEGEND_FRAME_PX: f64 = 16.0;
const LEGEND_MARGIN_PX: f64 = 12.0;
/// A character of the legend font, wide ones included, px.
const LEGEND_CHAR_PX: f64 = 9.0;
/// The legend's sample line and the gap after it, px.
const LEGEND_SAMPLE_PX: f64 = 40.0;

/// Where a legend goes, and the y range to draw with it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct LegendPlace {
    /// The corner.
    pub corner: SeriesLabelPosition,
    /// The y axis (raised above the data when no corner is free).
    pub ys: std::ops::Range<f64>,
}

/// Where the legend of `names` goes on a plot of `plot_px` (width, height) pixels whose axes
/// span `xs` × `ys`: the first corner — upper right, upper left, lower right, lower left —
/// whose box holds none of `pts`; when every corner has data, upper right above all of it,
/// the y axis raised to make the room. A legend never covers data.
pub(crate) fn legend_place(
    pts: &[(f64, f64)],
    names: &[&str],
    xs: &std::ops::Range<f64>,
    ys: &std::ops::Range<f64>,
    plot_px: (f64, f64),
) -> LegendPlace {
    use SeriesLabelPosition::{LowerLeft, LowerRight, UpperLeft, UpperRight};
    let chars = names.iter().map(|n| n.chars().count()).max().unwrap_or(0) as f64;
    let box_px = (
        LEGEND_SAMPLE_PX + chars * LEGEND_CHAR_PX + LEGEND_FRAME_PX + LEGEND_MARGIN_PX,
        names.len() as f64 * LEGEND_LINE_PX + LEGEND_FRAME_PX + LEGEND_MARGIN_PX,
    );
    let (fw, fh) = ((box_px.0 / plot_px.0.max(1.0)).min(1.0), (box_px.1 / plot_px.1.max(1.0)));
    let (w, h) = (fw * (xs.end - xs.start), fh.min(1.0) * (ys.end - ys.start));
    let free = |right: bool, upper: bool| {
        let x = if right { (xs.end - w)..=xs.end } else { xs.start..=(xs.start + w) };
        let y = if upper { (ys.end - h)..=ys.end } else { ys.start..=(ys.start + h) };
        !pts.iter().any(|(px, py)| x.contains(px) && y.contains(py))
    };
    for (corner, right, upper) in [
        (UpperRight, true, true),
        (UpperLeft, false, true),
        (LowerRight, true, false),
        (LowerLeft, false, false),
    ] {
        if free(right, upper) {
            return LegendPlace { corner, ys: ys.clone() };
        }
    }
    // Raised: the data's top stays below the box, the box a fraction `f` of the new span.
    let f = fh.min(0.6);
    let top = pts.iter().map(|p| p.1).filter(|v| v.is_finite()).fold(ys.start, f64::max);
    LegendPlace { corner: UpperRight, ys: ys.start..((top - f * ys.start) / (1.0 - f)) }
}

/// `lo..hi` covering `values`, padded by 5 % (a flat series gets ±1 around its value).
pub(crate) fn range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| (lo.min(v), hi.max(v)));
    if lo > hi {
        return 0.0..1.0;
    }
    let pad = if hi > lo { 0.05 * (hi - lo) } else { lo.abs().max(1.0) * 0.05 };
    (lo - pad)..(hi + pad)
}

/// `r` widened about its middle to span at least `min`.
pub(crate) fn widen(r: std::ops::Range<f64>, min: f64) -> std::ops::Range<f64> {
    let (mid, half) = ((r.start + r.end) / 2.0, (r.end - r.start).max(min) / 2.0);
    (mid - half)..(mid + half)
}

/// Tick labels for an axis spanning `r`: as many decimals as its tick spacing needs, no more
/// ("3000", "0.25", "0.0015"). The spacing is about a tenth of the span rounded up to 1, 2 or
/// 5 × 10ᵏ, as the axis draws it.
pub(crate) fn ticks(r: &std::ops::Range<f64>) -> impl Fn(&f64) -> String + use<> {
    let raw = (r.end - r.start).abs() / 10.0;
    let decimals = if raw > 0.0 && raw.is_finite() {
        let p = 10f64.powf(raw.log10().floor());
        let nice = p * [1.0, 2.0, 5.0, 10.0].into_iter().find(|&m| raw / p <= m).unwrap_or(10.0);
        (-nice.log10() - 1e-9).ceil().clamp(0.0, 8.0) as usize
    } else {
        0
    };
    // Large figures (accelerations in counts/s²) in powers of ten, so they fit their axis.
    let big = r.start.abs().max(r.end.abs()) >= 1e5;
    move |v: &f64| {
        if big && *v != 0.0 { format!("{v:.1e}") } else { format!("{v:.decimals$}") }
    }
}

/// Draws a figure of `panels` stacked panels, `title` on top, into `path`: drawn under a
/// temporary name beside it and renamed into place.
pub(crate) fn figure(
    path: &Path,
    height_per_panel: u32,
    panels: usize,
    title: &str,
    draw: impl FnOnce(&[Panel<'_, '_>]) -> Drawn,
) -> Result<PathBuf, PlotError> {
    static FONT_ONCE: Once = Once::new();
    FONT_ONCE.call_once(|| {
        // The embedded font is valid: a failure here is a broken build, and would show as
        // a drawing error naming the font below.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    // The backend picks the format from the extension: the temporary name keeps `.png`.
    let tmp = path.with_file_name(format!(".{}.{}.png", name, std::process::id()));
    let fail = |why: String| {
        let _ = std::fs::remove_file(&tmp);
        PlotError::Draw { path: path.to_path_buf(), why }
    };
    let height = 60 + height_per_panel * panels.max(1) as u32;
    let result = (|| -> Drawn {
        let root = BitMapBackend::new(&tmp, (1200, height)).into_drawing_area();
        text(root.fill(&WHITE))?;
        let body = text(root.titled(title, (FONT, 26)))?;
        let areas = body.split_evenly((panels.max(1), 1));
        draw(&areas)?;
        text(root.present())
    })();
    result.map_err(fail)?;
    std::fs::rename(&tmp, path).map_err(|e| fail(e.to_string()))?;
    Ok(path.to_path_buf())
}

/// Draws a line panel: its caption, labelled axes, the traces and a legend.
pub(crate) fn line_panel(area: &Panel<'_, '_>, spec: &PanelSpec<'_>) -> Drawn {
    let xs =
        widen(range(spec.traces.iter().flat_map(|t| t.pts.iter().map(|p| p.0))), spec.min_span.0);
    let zero = spec.from_zero.then_some(0.0);
    let ys = widen(
        range(spec.traces.iter().flat_map(|t| t.pts.iter().map(|p| p.1)).chain(zero)),
        spec.min_span.1,
    );
    // What is drawn (the lines' points, decimated as drawn), and where the legend has room.
    let drawn: Vec<Vec<(f64, f64)>> = spec
        .traces
        .iter()
        .map(|t| {
            decimate(t.pts, 1_500)
                .into_iter()
                .filter(|p| p.0.is_finite() && p.1.is_finite())
                .collect()
        })
        .collect();
    let all: Vec<(f64, f64)> = drawn.iter().flatten().copied().collect();
    let names: Vec<&str> =
        spec.traces.iter().map(|t| t.name.as_str()).filter(|n| !n.is_empty()).collect();
    let (w, h) = area.dim_in_pixel();
    // The plot inside the panel: less the y labels, the x labels, the caption and margins.
    let (margins, caption) = (2.0 * f64::from(PANEL_MARGIN_PX), 1.5 * f64::from(CAPTION_PT));
    let plot_px = (
        f64::from(w) - f64::from(Y_LABELS_PX) - margins,
        f64::from(h) - f64::from(X_LABELS_PX) - margins - caption,
    );
    let place = legend_place(&all, &names, &xs, &ys, plot_px);
    let ys = place.ys.clone();
    let (fx, fy) = (ticks(&xs), ticks(&ys));
    let whole =
        |v: &f64| if (v - v.round()).abs() < 1e-9 { format!("{v:.0}") } else { String::new() };
    let fx: &dyn Fn(&f64) -> String = if spec.integer_x { &whole } else { &fx };
    let mut chart = text(
        ChartBuilder::on(area)
            .caption(&spec.title, (FONT, CAPTION_PT))
            .margin(PANEL_MARGIN_PX)
            .x_label_area_size(X_LABELS_PX)
            .y_label_area_size(Y_LABELS_PX)
            .build_cartesian_2d(xs, ys),
    )?;
    text(
        chart
            .configure_mesh()
            .x_label_formatter(fx)
            .y_label_formatter(&fy)
            .x_desc(spec.x)
            .y_desc(spec.y.as_str())
            .label_style((FONT, 15))
            .axis_desc_style((FONT, 16))
            .light_line_style(RGBColor(235, 235, 235))
            .draw(),
    )?;
    for (i, (t, pts)) in spec.traces.iter().zip(&drawn).enumerate() {
        // One pixel wide: a thicker line's joins spike past the data on dense, noisy series.
        let style = t.colour.stroke_width(1);
        // Markers one kind per trace in turn: two traces with the same values stay apart.
        let c = t.colour;
        match (t.points, i % 3) {
            (false, _) => {}
            (true, 0) => {
                text(chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled()))))?;
            }
            (true, 1) => {
                let m = pts.iter().map(|&p| TriangleMarker::new(p, 6, c.filled()));
                text(chart.draw_series(m))?;
            }
            (true, _) => {
                let m = pts.iter().map(|&p| Cross::new(p, 5, c.stroke_width(2)));
                text(chart.draw_series(m))?;
            }
        }
        let drawn = text(chart.draw_series(LineSeries::new(pts.iter().copied(), style)))?;
        // A nameless trace (the second line of a band) has no legend entry of its own.
        if !t.name.is_empty() {
            drawn
                .label(t.name.as_str())
                .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 24, y)], style));
        }
    }
    legend(&mut chart, place.corner)
}

/// The legend of a chart (2-D or 3-D), in `corner`.
pub(crate) fn legend<'a, DB: DrawingBackend + 'a, CT: CoordTranslate>(
    chart: &mut ChartContext<'a, DB, CT>,
    corner: SeriesLabelPosition,
) -> Drawn {
    text(
        chart
            .configure_series_labels()
            .position(corner)
            .margin(LEGEND_MARGIN_PX as u32)
            .background_style(WHITE.mix(0.85))
            .border_style(RGBColor(160, 160, 160))
            .label_font((FONT, 15))
            .draw(),
    )
}

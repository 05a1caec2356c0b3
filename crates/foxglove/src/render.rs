//! A scene (`foxglove.SceneUpdate`) drawn as a picture without Foxglove: a side view (x
//! across, z up) beside a top view (x across, y up), orthographic, on one scale fitted to
//! the scene. Lines are drawn with their thickness, cylinders as discs (top) or their
//! outline (side), cubes turned by their yaw. `qmarc-foxglove scene` draws one from a
//! gather.mcap; the tests draw the scene they read back and look at its pixels.

use foxglove::messages::{
    Color as SceneColor, CubePrimitive, CylinderPrimitive, LinePrimitive, Pose, SceneUpdate,
};
use plotters::prelude::*;
use std::path::Path;

/// How a world point lands on the picture: m to pixels, each view's origin.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct View {
    /// Pixels per metre.
    pub scale: f64,
    /// The world's x, y and z at the views' centres, m.
    pub centre: [f64; 3],
    /// Each view's width and the picture's height, pixels.
    pub panel: (u32, u32),
}

impl View {
    /// The side view's pixel of the world point `p` (x, z).
    pub fn side(&self, p: [f64; 3]) -> (i32, i32) {
        self.px(p[0], p[2], 0)
    }

    /// The top view's pixel of the world point `p` (x, y).
    pub fn top(&self, p: [f64; 3]) -> (i32, i32) {
        self.px(p[0], p[1], 1)
    }

    fn px(&self, h: f64, v: f64, panel: u32) -> (i32, i32) {
        let (w, ht) = (f64::from(self.panel.0), f64::from(self.panel.1));
        let cv = if panel == 0 { self.centre[2] } else { self.centre[1] };
        let x = f64::from(panel) * w + w / 2.0 + (h - self.centre[0]) * self.scale;
        let y = ht / 2.0 - (v - cv) * self.scale;
        (x.round() as i32, y.round() as i32)
    }
}

/// A scene colour on the picture, its transparency kept (the base plate's: the effector
/// shows through it from above).
fn rgb(c: Option<&SceneColor>) -> RGBAColor {
    let c = c.cloned().unwrap_or(SceneColor { r: 0.5, g: 0.5, b: 0.5, a: 1.0 });
    let k = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round() as u8;
    RGBAColor(k(c.r), k(c.g), k(c.b), c.a.clamp(0.0, 1.0))
}

fn position(pose: Option<&Pose>) -> [f64; 3] {
    pose.and_then(|p| p.position.as_ref()).map_or([0.0; 3], |v| [v.x, v.y, v.z])
}

/// The yaw of a pose (a turn about z), rad.
fn yaw(pose: Option<&Pose>) -> f64 {
    pose.and_then(|p| p.orientation.as_ref()).map_or(0.0, |q| 2.0 * q.z.atan2(q.w))
}

/// A cube's four corners seen from above, world x and y, and its z extent.
fn cube_corners(c: &CubePrimitive) -> ([[f64; 2]; 4], [f64; 2]) {
    let p = position(c.pose.as_ref());
    let s = c.size.as_ref().map_or([0.0; 3], |v| [v.x, v.y, v.z]);
    let (sn, cs) = yaw(c.pose.as_ref()).sin_cos();
    let corner = |a: f64, b: f64| {
        let (dx, dy) = (a * s[0] / 2.0, b * s[1] / 2.0);
        [p[0] + dx * cs - dy * sn, p[1] + dx * sn + dy * cs]
    };
    let corners = [corner(-1.0, -1.0), corner(1.0, -1.0), corner(1.0, 1.0), corner(-1.0, 1.0)];
    (corners, [p[2] - s[2] / 2.0, p[2] + s[2] / 2.0])
}

/// Every point of `update`, m: what the view is fitted to.
fn extent(update: &SceneUpdate) -> Vec<[f64; 3]> {
    let mut pts = Vec::new();
    for e in &update.entities {
        for l in &e.lines {
            pts.extend(l.points.iter().map(|p| [p.x, p.y, p.z]));
        }
        for c in &e.cubes {
            let (corners, z) = cube_corners(c);
            pts.extend(corners.iter().flat_map(|q| z.map(|z| [q[0], q[1], z])));
        }
        for c in &e.cylinders {
            let p = position(c.pose.as_ref());
            let r = c.size.as_ref().map_or(0.0, |s| s.x / 2.0);
            pts.extend([[p[0] - r, p[1] - r, p[2]], [p[0] + r, p[1] + r, p[2]]]);
        }
    }
    pts
}

/// The view that fits `update` into two panels of `panel` pixels with a margin.
pub fn fit(update: &SceneUpdate, panel: (u32, u32)) -> View {
    let pts = extent(update);
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in &pts {
        for k in 0..3 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if pts.is_empty() {
        (lo, hi) = ([-1.0; 3], [1.0; 3]);
    }
    let span = |k: usize| (hi[k] - lo[k]).max(1e-3);
    let w = f64::from(panel.0) * 0.9;
    let h = f64::from(panel.1) * 0.85;
    let scale = (w / span(0)).min(h / span(2)).min(h / span(1));
    View { scale, centre: std::array::from_fn(|k| (lo[k] + hi[k]) / 2.0), panel }
}

/// Draws `update` as [`View`] `view` says into an RGB buffer of two panels, `title` on top.
pub fn draw(update: &SceneUpdate, view: &View, title: &str) -> Result<Vec<u8>, String> {
    register_font();
    let (w, h) = (view.panel.0 * 2, view.panel.1);
    let mut buf = vec![255u8; (w * h * 3) as usize];
    {
        let root = BitMapBackend::with_buffer(&mut buf, (w, h)).into_drawing_area();
        let err = |e: DrawingAreaErrorKind<_>| e.to_string();
        root.fill(&WHITE).map_err(err)?;
        // Cubes (the belt, its parts, the fingers) first, then the links, then the plates:
        // from above, what lies lowest is drawn first.
        for c in update.entities.iter().flat_map(|e| &e.cubes) {
            let (corners, z) = cube_corners(c);
            let color = rgb(c.color.as_ref()).filled();
            let top: Vec<_> = corners.iter().map(|q| view.top([q[0], q[1], 0.0])).collect();
            root.draw(&Polygon::new(top, color)).map_err(err)?;
            let (x0, x1) = corners
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), q| (a.min(q[0]), b.max(q[0])));
            let (a, b) = (view.side([x0, 0.0, z[1]]), view.side([x1, 0.0, z[0]]));
            root.draw(&Rectangle::new([a, b], color)).map_err(err)?;
        }
        for l in update.entities.iter().flat_map(|e| &e.lines) {
            draw_lines(&root, view, l).map_err(err)?;
        }
        for c in update.entities.iter().flat_map(|e| &e.cylinders) {
            draw_cylinder(&root, view, c).map_err(err)?;
        }
        let style = TextStyle::from((FONT, 18).into_font()).color(&BLACK);
        root.draw_text(title, &style, (10, 8)).map_err(err)?;
        let half = view.panel.0 as i32;
        root.draw_text("side (x →, z ↑)", &style, (10, h as i32 - 26)).map_err(err)?;
        root.draw_text("top (x →, y ↑)", &style, (half + 10, h as i32 - 26)).map_err(err)?;
        root.draw(&PathElement::new(vec![(half, 0), (half, h as i32)], BLACK.mix(0.3)))
            .map_err(err)?;
        root.present().map_err(err)?;
    }
    Ok(buf)
}

fn draw_lines<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    l: &LinePrimitive,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let width = ((l.thickness * view.scale).round() as u32).max(1);
    let style = rgb(l.color.as_ref()).stroke_width(width);
    for pair in l.points.chunks_exact(2) {
        let (a, b) = ([pair[0].x, pair[0].y, pair[0].z], [pair[1].x, pair[1].y, pair[1].z]);
        root.draw(&PathElement::new(vec![view.side(a), view.side(b)], style))?;
        root.draw(&PathElement::new(vec![view.top(a), view.top(b)], style))?;
    }
    Ok(())
}

fn draw_cylinder<DB: DrawingBackend>(
    root: &DrawingArea<DB, plotters::coord::Shift>,
    view: &View,
    c: &CylinderPrimitive,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    let p = position(c.pose.as_ref());
    let s = c.size.as_ref().map_or([0.0; 3], |v| [v.x, v.y, v.z]);
    let color = rgb(c.color.as_ref()).filled();
    let r = ((s[0] / 2.0 * view.scale).round() as i32).max(1);
    root.draw(&Circle::new(view.top(p), r, color))?;
    let a = view.side([p[0] - s[0] / 2.0, 0.0, p[2] + s[2] / 2.0]);
    let b = view.side([p[0] + s[0] / 2.0, 0.0, p[2] - s[2] / 2.0]);
    root.draw(&Rectangle::new([a, (b.0, b.1.max(a.1 + 1))], color))
}

/// The font the picture's text is in (DejaVu Sans, embedded: no system font needed).
const FONT: &str = "qmarc-scene-sans";

fn register_font() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        // The embedded font is valid: a failure would show as a drawing error naming it.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// Draws `update` into the PNG `path` (two panels of `panel` pixels).
pub fn png(
    update: &SceneUpdate,
    path: &Path,
    panel: (u32, u32),
    title: &str,
) -> Result<View, String> {
    let view = fit(update, panel);
    let buf = draw(update, &view, title)?;
    image::save_buffer(path, &buf, panel.0 * 2, panel.1, image::ColorType::Rgb8)
        .map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(view)
}

//! Finding a calibration target's dots in a frame and naming each by its column and row:
//! the dark round regions on the bright board, the grid's four corners from their convex
//! hull, every dot's cell from the corners' perspective map, the origin by its larger dot
//! ([`crate::render::ORIGIN_DOT_SCALE`]) and the rows' side by the camera looking down
//! (the across direction is the travel turned +90° seen from above).

use crate::blobs::{Labeller, Polarity, Region};
use crate::calib::homography;
use image::GrayImage;
use nalgebra::{Matrix3, Vector3};

/// A target's dots: where each is in the frame and on the belt, column by column.
#[derive(Debug, Clone, PartialEq)]
pub struct Dots {
    /// Each dot's centroid, px.
    pub pixels: Vec<[f64; 2]>,
    /// Each dot's belt point, mm.
    pub belt: Vec<[f64; 2]>,
}

/// The grid was not found, and what was.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("no {cols}x{rows} grid of dots: {found}")]
pub struct GridError {
    /// The grid's columns.
    pub cols: u32,
    /// …and rows.
    pub rows: u32,
    /// What the frame has instead.
    pub found: String,
}

/// The dots of a `grid` (columns along the belt, rows across) target, `pitch_mm` apart, its
/// origin dot at `origin_mm`, in `img`.
pub fn find(
    img: &GrayImage,
    grid: [u32; 2],
    pitch_mm: f64,
    origin_mm: [f64; 2],
) -> Result<Dots, GridError> {
    let [cols, rows] = grid;
    let fail = |found: String| GridError { cols, rows, found };
    let mut regions = Vec::new();
    // Otsu's level is the dark class's top: the dots are at or below it.
    Labeller::default().regions(img, Polarity::Dark, otsu(img).saturating_add(1), &mut regions);
    let round: Vec<Region> = regions
        .iter()
        .filter(|r| !r.at_border && r.area >= 6 && r.elongation < 3.0)
        .copied()
        .collect();
    let Some(median) = median_area(&round) else {
        return Err(fail(format!("no dark round region (of {} dark regions)", regions.len())));
    };
    let dots: Vec<Region> = round
        .iter()
        .filter(|r| (0.3..=4.0).contains(&(f64::from(r.area) / median)))
        .copied()
        .collect();
    if dots.len() != (cols * rows) as usize {
        return Err(fail(format!(
            "{} dots of about {median} px (the grid has {}); {} other dark regions",
            dots.len(),
            cols * rows,
            regions.len() - dots.len()
        )));
    }
    let at: Vec<[f64; 2]> = dots.iter().map(|r| r.centroid).collect();
    let corners = corners(&at).ok_or_else(|| fail("dots with no four corners".into()))?;
    let biggest = (0..dots.len()).max_by_key(|&k| dots[k].area).unwrap_or(0);
    let marked = f64::from(dots[biggest].area) > 1.6 * median;
    if !marked {
        return Err(fail(format!(
            "{} dots, but none larger than the others: the origin dot is {}× as wide",
            dots.len(),
            crate::render::ORIGIN_DOT_SCALE
        )));
    }
    let mut wrong_side = false;
    for order in labellings(&corners) {
        let Some(cells) = cells(&at, &order, grid) else { continue };
        if cells[biggest] != [0, 0] {
            continue;
        }
        // Seen from above the image is mirrored: along × across < 0 in pixels.
        let find_cell = |c: [u32; 2]| cells.iter().position(|&x| x == c).map(|k| at[k]);
        let (Some(o), Some(a), Some(b)) = (find_cell([0, 0]), find_cell([1, 0]), find_cell([0, 1]))
        else {
            continue;
        };
        let cross = (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]);
        if cross > 0.0 {
            wrong_side = true;
            continue;
        }
        let belt = cells
            .iter()
            .map(|c| {
                [
                    origin_mm[0] + f64::from(c[0]) * pitch_mm,
                    origin_mm[1] + f64::from(c[1]) * pitch_mm,
                ]
            })
            .collect();
        return Ok(Dots { pixels: at, belt });
    }
    Err(fail(if wrong_side {
        "the rows run from the origin dot against the across direction (the belt's travel \
         turned +90° seen from above): lay the target with the origin dot at its upstream \
         corner on the other side"
            .into()
    } else {
        format!(
            "{} dots, not in {cols} columns and {rows} rows with the origin dot at a corner",
            dots.len()
        )
    }))
}

/// Otsu's threshold of `img`: the level that best splits its histogram in two.
pub fn otsu(img: &GrayImage) -> u8 {
    let mut hist = [0u64; 256];
    for p in img.as_raw() {
        hist[*p as usize] += 1;
    }
    let total: u64 = hist.iter().sum();
    let sum: f64 = hist.iter().enumerate().map(|(v, &n)| v as f64 * n as f64).sum();
    let (mut below, mut sum_below, mut best, mut level) = (0u64, 0.0, -1.0, 0u8);
    for (v, &n) in hist.iter().enumerate() {
        below += n;
        sum_below += v as f64 * n as f64;
        let above = total - below;
        if below == 0 || above == 0 {
            continue;
        }
        let (m0, m1) = (sum_below / below as f64, (sum - sum_below) / above as f64);
        let between = below as f64 * above as f64 * (m0 - m1).powi(2);
        if between > best {
            (best, level) = (between, v as u8);
        }
    }
    level
}

fn median_area(regions: &[Region]) -> Option<f64> {
    let mut a: Vec<u32> = regions.iter().map(|r| r.area).collect();
    a.sort_unstable();
    a.get(a.len() / 2).map(|&m| f64::from(m))
}

/// The four corners of the points' convex hull (its four sharpest turns), in hull order.
fn corners(points: &[[f64; 2]]) -> Option<[[f64; 2]; 4]> {
    let mut p = points.to_vec();
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut hull: Vec<[f64; 2]> = Vec::new();
    for pass in [p.clone(), p.into_iter().rev().collect()] {
        let start = hull.len();
        for q in pass {
            while hull.len() >= start + 2
                && cross(hull[hull.len() - 2], hull[hull.len() - 1], q) <= 0.0
            {
                hull.pop();
            }
            hull.push(q);
        }
        hull.pop();
    }
    if hull.len() < 4 {
        return None;
    }
    let n = hull.len();
    let turn = |k: usize| {
        let (a, b, c) = (hull[(k + n - 1) % n], hull[k], hull[(k + 1) % n]);
        let (u, v) = ([b[0] - a[0], b[1] - a[1]], [c[0] - b[0], c[1] - b[1]]);
        (u[0] * v[0] + u[1] * v[1]) / (f64::hypot(u[0], u[1]) * f64::hypot(v[0], v[1]))
    };
    // The smallest cosines between one edge and the next: the sharpest turns.
    let mut by_turn: Vec<usize> = (0..n).collect();
    by_turn.sort_by(|&a, &b| turn(a).total_cmp(&turn(b)));
    let mut four = [by_turn[0], by_turn[1], by_turn[2], by_turn[3]];
    four.sort_unstable();
    Some(four.map(|k| hull[k]))
}

/// The eight ways to name the corners (0, 0), (C−1, 0), (C−1, R−1), (0, R−1): each corner
/// first, the hull walked either way.
fn labellings(c: &[[f64; 2]; 4]) -> impl Iterator<Item = [[f64; 2]; 4]> + '_ {
    (0..4).flat_map(move |s| {
        [
            [c[s], c[(s + 1) % 4], c[(s + 2) % 4], c[(s + 3) % 4]],
            [c[s], c[(s + 3) % 4], c[(s + 2) % 4], c[(s + 1) % 4]],
        ]
    })
}

/// Each point's cell when the corners are `order`: named through the corners' perspective
/// map (within 0.45 of a cell), then again through the map fitted to every dot so named
/// (within 0.3: a lens' distortion bends the rows the corners' map cannot follow); `None`
/// unless every point lies near a cell of the grid and no two on one.
fn cells(points: &[[f64; 2]], order: &[[f64; 2]; 4], grid: [u32; 2]) -> Option<Vec<[u32; 2]>> {
    let (c, r) = (f64::from(grid[0] - 1), f64::from(grid[1] - 1));
    let corners: Matrix3<f64> = homography(order, &[[0.0, 0.0], [c, 0.0], [c, r], [0.0, r]])?;
    let first = name(points, &corners, grid, 0.45)?;
    let cells: Vec<[f64; 2]> = first.iter().map(|c| c.map(f64::from)).collect();
    let all = homography(points, &cells)?;
    name(points, &all, grid, 0.3)
}

/// Each point's cell through `to_grid`, within `tolerance` of a cell; `None` if one is not,
/// or two share one.
fn name(
    points: &[[f64; 2]],
    to_grid: &Matrix3<f64>,
    grid: [u32; 2],
    tolerance: f64,
) -> Option<Vec<[u32; 2]>> {
    let (c, r) = (f64::from(grid[0] - 1), f64::from(grid[1] - 1));
    let mut seen = vec![false; grid[0] as usize * grid[1] as usize];
    let mut out = Vec::with_capacity(points.len());
    for p in points {
        let v = to_grid * Vector3::new(p[0], p[1], 1.0);
        let (i, j) = (v.x / v.z, v.y / v.z);
        let (ri, rj) = (i.round(), j.round());
        let off = (i - ri).abs() > tolerance || (j - rj).abs() > tolerance;
        if off || ri < 0.0 || rj < 0.0 || ri > c || rj > r {
            return None;
        }
        let k = (rj as u32 * grid[0] + ri as u32) as usize;
        if std::mem::replace(&mut seen[k], true) {
            return None;
        }
        out.push([ri as u32, rj as u32]);
    }
    Some(out)
}

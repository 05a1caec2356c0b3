//! Unit tests of the plots: real PNGs from a synthetic move, decoded and looked at.

use super::*;
use crate::chart::ticks;
use crate::moves::{derivative, second_derivative};
use qmarc_kinematics::{Geometry, JointFrame, Point, Robot};
use qmarc_report::Summary;
use qmarc_report::output::PLOT_FILES;
use qmarc_report::trials::TrialRow;
use std::path::Path;

fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("qmarc-plots-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn robot() -> Robot {
    let g = Geometry::ASSUMED;
    let home = g.inverse(&Point::new(0.0, 0.0, -0.6)).unwrap();
    let per_rad = 4096.0 * 12.0 / std::f64::consts::TAU;
    Robot {
        geometry: g,
        frame: JointFrame { home_rad: [home[0], home[1], home[2]], counts_per_rad: per_rad },
    }
}

/// A 0.4 s move of the effector 100 mm along x and back, the actual 2 ms late, gathered
/// every cycle of 400 µs with one late wake.
fn write_move(dir: &Path, r: &Robot) -> Summary {
    let mut csv = String::from("cycle,time_s,cmd1,act1,dac1,cmd2,act2,dac2,cmd3,act3,dac3\n");
    let at = |t: f64| {
        let x = 0.05 * (1.0 - (std::f64::consts::TAU * t / 0.4).cos());
        r.counts_of(&Point::new(x, 0.0, -0.6)).unwrap()
    };
    for k in 0..1000u32 {
        let t = f64::from(k) * 4e-4;
        let wake = if k == 500 { t + 1.5e-4 } else { t };
        let (c, a) = (at(t), at((t - 0.002).max(0.0)));
        csv += &format!("{k},{wake}");
        for m in 0..3 {
            csv += &format!(",{},{},{}", c[m], a[m], ((c[m] - a[m]) * 10.0).round());
        }
        csv += "\n";
    }
    std::fs::write(dir.join("gather.csv"), csv).unwrap();
    let mut s =
        Summary::controller_lost((qmarc_config::Mode::Run, true), 3, 400, 1000, String::new());
    s.trajectory = "spline".into();
    s.counts_per_rad = r.frame.counts_per_rad;
    s.gather_every = 1;
    s
}

/// Width, height and how many pixels are far from white and grey (the traces' colours).
fn look(png: &Path) -> (u32, u32, usize) {
    let img = image::open(png).unwrap_or_else(|e| panic!("{}: {e}", png.display())).to_rgb8();
    let coloured = img
        .pixels()
        .filter(|p| {
            let [r, g, b] = p.0.map(i32::from);
            (r - g).abs().max((g - b).abs()).max((r - b).abs()) > 60
        })
        .count();
    (img.width(), img.height(), coloured)
}

#[test]
fn a_move_gives_every_plot_readable() {
    let dir = scratch("move");
    let r = robot();
    let s = write_move(&dir, &r);
    let done = move_plots(&dir, &s, Some(&r)).unwrap();
    let names: Vec<String> =
        done.iter().map(|p| p.file_name().unwrap().to_string_lossy().into_owned()).collect();
    assert_eq!(names, PLOT_FILES, "every plot, under the names a new set retires");
    for png in &done {
        let (w, h, coloured) = look(png);
        assert_eq!(w, 1200, "{}", png.display());
        assert!(h >= 400, "{}: {h} px high", png.display());
        assert!(coloured > 400, "{}: {coloured} coloured pixels: no traces drawn?", png.display());
    }
    // No temporary file is left beside them.
    let left: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with('.'))
        .collect();
    assert!(left.is_empty(), "{left:?}");
    // Without a robot (or with other than 3 motors) the effector plots are not drawn.
    let done = move_plots(&dir, &s, None).unwrap();
    assert_eq!(done.len(), 4);
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_move_without_data_is_an_error_naming_the_file() {
    let dir = scratch("nodata");
    let s = Summary::controller_lost((qmarc_config::Mode::Step, false), 3, 400, 0, String::new());
    let e = move_plots(&dir, &s, None).unwrap_err().to_string();
    assert!(e.contains(&format!("{}", dir.join("gather.csv").display())), "{e}");
    std::fs::write(dir.join("gather.csv"), "cycle,time_s,cmd1,act1\n0,0,0,0\n").unwrap();
    let e = move_plots(&dir, &s, None).unwrap_err().to_string();
    assert!(e.ends_with("gather.csv has 1 rows, too few to plot"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn derivatives_of_a_parabola_are_exact() {
    let p = |x: &f64| 3.0 * x * x - x;
    let even: Vec<f64> = (0..6).map(|k| 0.5 * f64::from(k)).collect();
    let v = derivative(&even, &even.iter().map(p).collect::<Vec<_>>());
    assert_eq!(v.len(), 4);
    for (x, v) in v {
        assert!((v - (6.0 * x - 1.0)).abs() < 1e-12, "{x}: {v}");
    }
    // The second difference is exact for a parabola on any spacing.
    let uneven = [0.0, 0.5, 1.0, 2.0, 2.5];
    let a = second_derivative(&uneven, &uneven.iter().map(p).collect::<Vec<_>>());
    assert_eq!(a.len(), 3);
    for (_, a) in a {
        assert!((a - 6.0).abs() < 1e-12, "{a}");
    }
}

#[test]
fn trials_give_their_two_plots() {
    let dir = scratch("trials");
    let rows: Vec<TrialRow> = (1..=20)
        .map(|k| TrialRow {
            trial: k,
            abs_rad: vec![0.5 + 0.01 * f64::from(k % 3), 0.51, 0.53],
            sq_rad: vec![0.002; 3],
            periods_off_40us: u64::from(k % 4),
            missed_periods: u64::from(k == 7),
            fault: String::new(),
        })
        .collect();
    let done = trial_plots(&dir, "run (spline)", &rows).unwrap();
    assert_eq!(done.len(), TRIAL_PLOT_FILES.len());
    for png in &done {
        let (w, _, coloured) = look(png);
        assert!(w == 1200 && coloured > 500, "{}: {coloured}", png.display());
    }
    assert!(trial_plots(&dir, "x", &[]).is_err());
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn tick_labels_carry_the_decimals_their_spacing_needs() {
    let label = |lo: f64, hi: f64, v: f64| ticks(&(lo..hi))(&v);
    assert_eq!(label(0.55, 10.45, 3.0), "3", "trials 1..10: whole numbers");
    assert_eq!(label(-3000.0, 3000.0, 2000.0), "2000");
    assert_eq!(label(5.03, 5.5, 5.05), "5.05");
    assert_eq!(label(0.0, 2.0, 0.2), "0.2");
    assert_eq!(label(-0.007, 0.007, -0.004), "-0.004");
}

/// Issue 28, item 11: a legend never covers data. A step held to the panel's end fills the
/// upper right (before: the arms' legend hid its last 0.15 s): the legend goes to a free
/// corner; data in every corner raise the y axis to make room above it.
#[test]
fn a_legend_goes_where_there_is_no_data() {
    use crate::chart::legend_place;
    use plotters::prelude::SeriesLabelPosition;
    let names = ["motor 1", "motor 2", "motor 3"];
    let (xs, ys, px) = (0.0..2.0, 0.0..1000.0, (1085.0, 300.0));
    let box_w = |corner_x: f64| (corner_x - 0.0).abs() / 2.0 * 1085.0;
    // A step: 0 until 0.01 s, 1000 after, to the end.
    let step: Vec<(f64, f64)> = (0..2000)
        .map(|k| f64::from(k) * 1e-3)
        .map(|t| (t, if t < 0.01 { 0.0 } else { 1000.0 }))
        .collect();
    let place = legend_place(&step, &names, &xs, &ys, px);
    assert_eq!(place.corner, SeriesLabelPosition::LowerRight);
    assert_eq!(place.ys, ys, "a free corner needs no room made");
    assert!(box_w(0.3) > 100.0);
    // Data in every corner: upper right, the axis raised so the data stay below the legend.
    let full: Vec<(f64, f64)> =
        (0..2000).map(|k| f64::from(k) * 1e-3).flat_map(|t| [(t, 0.0), (t, 1000.0)]).collect();
    let place = legend_place(&full, &names, &xs, &ys, px);
    assert_eq!(place.corner, SeriesLabelPosition::UpperRight);
    let legend_px = 3.0 * 21.0 + 16.0 + 12.0;
    let room = (place.ys.end - 1000.0) / (place.ys.end - place.ys.start) * px.1;
    assert!(room >= legend_px - 1e-6, "{room} px above the data for a {legend_px} px legend");
    // Trials' points in the middle: the upper right is free.
    let mid = [(1.0, 500.0), (1.5, 520.0)];
    assert_eq!(legend_place(&mid, &names, &xs, &ys, px).corner, SeriesLabelPosition::UpperRight);
}

/// Issue 28, item 11: a step's command acceleration has its rise and its fall — the move
/// starts and ends at rest (before: only the negative spike, the first sample having no
/// neighbour before it).
#[test]
fn a_steps_acceleration_rises_and_falls() {
    use crate::moves::at_rest_around;
    let t: Vec<f64> = (0..10).map(|k| f64::from(k) * 4e-4).collect();
    let cmd: Vec<f64> = (0..10).map(|k| if k == 0 { 0.0 } else { 1000.0 }).collect();
    let (x, y) = at_rest_around(&t, &cmd);
    assert_eq!((x.len(), y.len()), (12, 12));
    let a = second_derivative(&x, &y);
    let v = derivative(&x, &y);
    assert_eq!(a.len(), t.len(), "an acceleration at every gathered sample");
    let (lo, hi) = a.iter().fold((0.0f64, 0.0f64), |(lo, hi), p| (lo.min(p.1), hi.max(p.1)));
    assert!(hi > 1e9 && lo < -1e9, "rise {hi}, fall {lo}");
    assert!((hi + lo).abs() < 1e-3 * hi, "as large either way: {hi} {lo}");
    assert!(v.iter().all(|p| p.1 >= 0.0) && v[0].1 > 0.0, "{v:?}");
    let (x, y) = at_rest_around(&[], &[]);
    assert!(x.is_empty() && y.is_empty());
}

/// Issue 28, item 11: the trials' error from zero — a 0.1 % spread is a flat row of
/// points, as it is — with each arm beside the trial's number, so equal arms both show.
#[test]
fn trials_show_their_spread_from_zero() {
    let dir = scratch("trials-spread");
    let rows: Vec<TrialRow> = (1..=5)
        .map(|k| TrialRow {
            trial: k,
            abs_rad: vec![10.0 + 0.001 * f64::from(k), 10.0 + 0.001 * f64::from(k), 10.003],
            sq_rad: vec![0.002; 3],
            periods_off_40us: 0,
            missed_periods: 0,
            fault: String::new(),
        })
        .collect();
    let done = trial_plots(&dir, "step", &rows).unwrap();
    let img = image::open(&done[0]).unwrap().to_rgb8();
    // Arm 1's colour and arm 2's both drawn (beside each other, not one under the other).
    let count =
        |c: plotters::style::RGBColor| img.pixels().filter(|p| p.0 == [c.0, c.1, c.2]).count();
    let (a1, a2) = (count(crate::chart::motor_colour(0)), count(crate::chart::motor_colour(1)));
    assert!(a1 > 100 && a2 > 100, "arm 1 {a1} px, arm 2 {a2} px");
    // Arm 1's trials 1–3 (the left half: the legend is in a right corner) lie in one flat
    // row, not stretched from the axis' bottom to its top.
    let c = crate::chart::motor_colour(0);
    let rows: Vec<u32> = img
        .enumerate_pixels()
        .filter(|(x, _, p)| *x < 600 && p.0 == [c.0, c.1, c.2])
        .map(|(_, y, _)| y)
        .collect();
    let spread = rows.iter().max().unwrap() - rows.iter().min().unwrap();
    assert!(spread < 20, "arm 1 spans {spread} px of the axis");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Issue 42: a step's response (its first 0.15 s of 2 s) is drawn in a detail of its own; a
/// move busy all along is not cut.
#[test]
fn where_a_move_is_busy_is_found_when_it_is_a_small_part_of_it() {
    use crate::moves::active_window;
    let t: Vec<f64> = (0..5000).map(|k| f64::from(k) * 4e-4).collect();
    let step: Vec<(f64, f64)> =
        t.iter().map(|&t| (t, if t < 0.15 { 1000.0 * (-t / 0.03).exp() } else { 0.0 })).collect();
    let w = active_window(&t, &[step]).expect("a detail");
    assert!(w.start == 0.0 && (0.1..0.25).contains(&w.end), "{w:?}");
    let busy: Vec<(f64, f64)> = t.iter().map(|&t| (t, (t * 7.0).sin())).collect();
    assert_eq!(active_window(&t, &[busy]), None);
    assert_eq!(active_window(&t, &[t.iter().map(|&t| (t, 0.0)).collect()]), None);
}

/// Issue 42: one stall of 10 ms keeps the period axis at the band's scale, drawn at its edge
/// and counted with its length.
#[test]
fn a_stall_does_not_hide_the_period_band() {
    use crate::moves::{PERIOD_AXIS_US, PeriodAxis};
    let periods: Vec<(f64, f64)> = (0..1000)
        .map(|k| (f64::from(k) * 4e-4, if k == 500 { 10_400.0 } else { 400.0 + f64::from(k % 7) }))
        .collect();
    let axis = PeriodAxis::of(400.0, &periods);
    assert_eq!((axis.beyond, axis.longest_us), (1, 10_400.0));
    assert!(axis.pts.iter().all(|p| (p.1 - 400.0).abs() <= PERIOD_AXIS_US));
    assert_eq!(axis.pts[500].1, 400.0 + PERIOD_AXIS_US);
    assert_eq!(axis.pts[3], periods[3], "the rest as they were");
}

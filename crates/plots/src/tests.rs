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
fn a_move_gives_every_plot_readable_issue_13() {
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
fn trials_give_their_two_plots_issue_13() {
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

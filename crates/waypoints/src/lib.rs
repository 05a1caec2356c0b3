//! Cartesian paths for the Delta (`qmarc-starter path`): a waypoint file
//! ([`qmarc_knots::parse_waypoints`]) becomes a knot file for the spline or the PVT
//! generator (thesis A.2.3) through the robot's inverse kinematics.
//!
//! The Cartesian path is a natural cubic spline in t through the waypoints, one per axis (the
//! thesis' own offline interpolation, 3.12.1). Knots sit at the waypoints, or every `T` ms
//! from the first (`--every-ms`, as the thesis resampled its paths: 37 knots 11.07 ms apart),
//! the last waypoint always among them. Each knot's joint position is the inverse kinematics
//! of the path's point, in whole counts of the homed frame; a PVT knot's velocity is
//! θ̇ = J·ṗ, the Jacobian times the path's exact tangent velocity. (The thesis' eq. 5-1 took
//! the forward difference (X₍ₙ₊₁₎ − Xₙ)/Δt of its 37 knots instead: exact only for a straight
//! line, and the velocity of the half-way point, half a segment late; the Hermite segments
//! between the knots then bulge, the "slight arcs" of its Fig. 5-8.)
//!
//! ```
//! use qmarc_knots::{KnotRules, parse_waypoints};
//! use qmarc_waypoints::{KnotFormat, joint_knots, render};
//! # fn main() -> Result<(), Box<dyn std::error::Error>> {
//! let robot = qmarc_kinematics::Robot {
//!     geometry: qmarc_kinematics::Geometry::ASSUMED,
//!     frame: qmarc_kinematics::JointFrame { home_rad: [0.2; 3], counts_per_rad: 7823.0 },
//! };
//! let w = parse_waypoints("w.txt", "0 0 0 -0.6\n0.5 0.1 0 -0.6\n", &KnotRules::new(3))?;
//! let knots = joint_knots(&robot, &w, "w.txt", Some(0.1))?;
//! assert_eq!(knots.len(), 6);
//! let text = render(&knots, KnotFormat::Pvt, "# from w.txt");
//! assert_eq!(text.lines().filter(|l| l.starts_with('X')).count(), 6);
//! # Ok(()) }
//! ```
#![deny(missing_docs)]

#[cfg(test)]
mod tests;

use qmarc_config::Settings;
use qmarc_kinematics::{ARMS, KinematicsError, Point, Robot};
use qmarc_knots::{
    KnotFileError, KnotRules, MAX_KNOTS, Waypoints, parse_offline, parse_pvt, parse_waypoints,
    read_knot_file,
};
use qmarc_plugins::spline::NaturalSpline;
use std::fmt::Write;
use std::path::Path;

/// The knot file a path becomes: the spline's (thesis A.2.3.1) or the PVT's (A.2.3.2).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum KnotFormat {
    /// Number of knots, then `t_s counts…` per knot.
    Spline,
    /// Per knot and motor: label, counts, counts/s, time to the next knot in ms.
    Pvt,
}

impl KnotFormat {
    /// The format of the trajectory method `name` (`spline`, `pvt`).
    pub fn of_method(name: &str) -> Option<KnotFormat> {
        match name {
            "spline" => Some(KnotFormat::Spline),
            "pvt" => Some(KnotFormat::Pvt),
            _ => None,
        }
    }
}

/// One knot of the joint path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JointKnot {
    /// Time from the path's start, s.
    pub t_s: f64,
    /// Joint positions in the homed frame, counts (not rounded).
    pub counts: [f64; ARMS],
    /// Joint velocities, counts/s.
    pub counts_per_s: [f64; ARMS],
}

/// A path could not be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum PathError {
    /// The waypoint file is unreadable or breaks its format.
    #[error(transparent)]
    Waypoints(#[from] KnotFileError),
    /// The settings describe no robot.
    #[error("{0}: no [robot] table, or not 3 motors: a Cartesian path needs the robot's geometry")]
    NoRobot(String),
    /// The resampling interval is unusable.
    #[error("--every-ms must be a finite number of ms > 0, found {}", qmarc_config::num(*.0))]
    Every(f64),
    /// Resampling makes too many knots.
    #[error(
        "--every-ms {} makes {knots} knots, more than the {MAX_KNOTS} a knot file may hold",
        qmarc_config::num(*every_ms)
    )]
    TooManyKnots {
        /// The interval, ms.
        every_ms: f64,
        /// The knots it would make.
        knots: u64,
    },
    /// A point of the path has no joint position or velocity.
    #[error("{file}:{lines}: at t = {t_s} s: {why}")]
    Kinematics {
        /// The waypoint file.
        file: String,
        /// Its line (`7`), or the lines of the waypoints around a resampled knot (`7-8`).
        lines: String,
        /// The knot's time from the path's start, s.
        t_s: f64,
        /// Why: said in the message, not chained as a source (a chain printed with `{:#}`
        /// would say it twice).
        why: KinematicsError,
    },
    /// The knot file made does not read back (a bug: it is checked before it is written).
    #[error("the knot file made does not read back: {0}")]
    Unreadable(KnotFileError),
}

/// The knot times: the waypoints', or every `every_s` from the first with the last waypoint
/// appended when the grid misses it.
fn knot_times(w: &Waypoints, every_s: Option<f64>) -> Result<Vec<f64>, PathError> {
    let (t0, t_end) = (w.times[0], *w.times.last().unwrap_or(&w.times[0]));
    let Some(every) = every_s else { return Ok(w.times.clone()) };
    if !(every.is_finite() && every > 0.0) {
        return Err(PathError::Every(every * 1e3));
    }
    let steps = ((t_end - t0) / every + 1e-9).floor();
    let knots = steps as u64 + 2;
    if knots > MAX_KNOTS as u64 {
        return Err(PathError::TooManyKnots { every_ms: every * 1e3, knots });
    }
    let mut times: Vec<f64> = (0..=steps as u64).map(|k| t0 + k as f64 * every).collect();
    if t_end - times[times.len() - 1] > 1e-9 * every.max(1.0) {
        times.push(t_end);
    }
    Ok(times)
}

/// The joint knots of the path through `w` (from `file`), at the waypoints or every
/// `every_s`.
pub fn joint_knots(
    robot: &Robot,
    w: &Waypoints,
    file: &str,
    every_s: Option<f64>,
) -> Result<Vec<JointKnot>, PathError> {
    let times = knot_times(w, every_s)?;
    let axis = |k: usize| {
        NaturalSpline::new(w.times.clone(), w.points.iter().map(|p| p[k]).collect())
            .expect("parse_waypoints gives at least 2 strictly increasing times")
    };
    let mut splines = [axis(0), axis(1), axis(2)];
    let t0 = w.times[0];
    let mut knots = Vec::with_capacity(times.len());
    for t in times {
        let p = Point::from_fn(|k, _| splines[k].position(t));
        let v = Point::from_fn(|k, _| splines[k].velocity(t));
        let lines = || match w.times.iter().position(|&wt| wt >= t) {
            Some(i) if w.times[i] == t => w.lines[i].to_string(),
            Some(i) => format!("{}-{}", w.lines[i - 1], w.lines[i]),
            None => w.lines[w.lines.len() - 1].to_string(),
        };
        let at = |why| PathError::Kinematics {
            file: file.to_string(),
            lines: lines(),
            t_s: t - t0,
            why,
        };
        let theta = robot.geometry.inverse(&p).map_err(at)?;
        let theta_dot = robot.geometry.jacobian(&p, &theta).map_err(at)? * v;
        knots.push(JointKnot {
            t_s: t - t0,
            counts: robot.frame.counts(&theta),
            counts_per_s: robot.frame.counts_per_s(&theta_dot),
        });
    }
    Ok(knots)
}

/// The knot file of `knots` in `format`, after the comment lines `header`.
pub fn render(knots: &[JointKnot], format: KnotFormat, header: &str) -> String {
    let mut t = String::new();
    for line in header.lines() {
        let _ = writeln!(t, "# {}", line.trim_start_matches('#').trim_start());
    }
    // Whole counts, and a velocity that prints as zero, never read "-0".
    let no_negative_zero = |v: f64, below: f64| if v.abs() < below { 0.0 } else { v };
    let whole = |c: f64| no_negative_zero(c.round(), 0.5);
    match format {
        KnotFormat::Spline => {
            let _ = writeln!(t, "{}", knots.len());
            for k in knots {
                let _ = write!(t, "{:.6}", k.t_s);
                for c in k.counts {
                    let _ = write!(t, "\t{}", whole(c));
                }
                let _ = writeln!(t);
            }
        }
        KnotFormat::Pvt => {
            for (i, k) in knots.iter().enumerate() {
                // The time to the next knot; the last knot's is not used (the previous one's).
                let next = knots.get(i + 1).or(knots.get(i.wrapping_sub(1)));
                let dt_ms = next.map_or(0.0, |n| (n.t_s - k.t_s).abs() * 1e3);
                let cells: Vec<String> = (0..ARMS)
                    .map(|m| {
                        format!(
                            "{}\t{}\t{:.3}\t{dt_ms:.5}",
                            ["X", "Y", "Z"][m],
                            whole(k.counts[m]),
                            no_negative_zero(k.counts_per_s[m], 0.0005)
                        )
                    })
                    .collect();
                let _ = writeln!(t, "{}", cells.join("\t"));
            }
        }
    }
    t
}

/// A knot file made by [`generate`].
#[derive(Debug, Clone, PartialEq)]
pub struct KnotFile {
    /// Its text.
    pub text: String,
    /// The knots it holds.
    pub knots: usize,
}

/// `qmarc-starter path`: the knot file of the waypoint file `waypoints` for `format`, on the
/// robot of `settings`, knots every `every_ms` or at the waypoints. The text is read back by
/// the generator's own parser before it is returned.
pub fn generate(
    settings: &Settings,
    waypoints: &Path,
    format: KnotFormat,
    every_ms: Option<f64>,
) -> Result<KnotFile, PathError> {
    let robot = settings
        .robot()
        .ok_or_else(|| PathError::NoRobot(settings.source.display().to_string()))?;
    let file = waypoints.display().to_string();
    // A conversion, not a move: the motion limits are checked when the path is run.
    let rules =
        KnotRules { n_motors: ARMS, ..KnotRules::from_settings(settings) }.without_motion_limits();
    let w = parse_waypoints(&file, &read_knot_file(waypoints)?, &rules)?;
    let knots = joint_knots(&robot, &w, &file, every_ms.map(|ms| ms * 1e-3))?;
    let spacing = every_ms.map_or("at the waypoints".to_string(), |ms| format!("every {ms} ms"));
    let header = format!(
        "made by `qmarc-starter path` from {file} ({} waypoints), knots {spacing}\n\
         through the inverse kinematics of the [robot] in {}",
        w.times.len(),
        settings.source.display()
    );
    let text = render(&knots, format, &header);
    let check = match format {
        KnotFormat::Spline => parse_offline("(made)", &text, &rules).err(),
        KnotFormat::Pvt => parse_pvt("(made)", &text, &rules).err(),
    };
    match check {
        Some(e) => Err(PathError::Unreadable(e)),
        None => Ok(KnotFile { text, knots: knots.len() }),
    }
}

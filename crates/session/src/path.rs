//! A timed path sent to a serving controller (`qmarc/path`, a ROS 2 `JointTrajectory` through
//! the bridge) as the samples its loop follows ([`path_queue`]): the PVT knots of a knot file
//! (thesis 3.12.2), checked as a knot file is, from where the robot rests.
//!
//! The path's first knot is where the robot rests, at rest, at time 0 (a point at time 0 must
//! be there already); every other knot is one of the request's, its time from that start
//! rising. Each segment is the cubic [`Hermite`] of a PVT file; each motor's largest velocity
//! and acceleration over it, found exactly ([`check_segment`]), must be within its limits;
//! every sample within the soft limits. A path ends at rest: its last velocities are 0. With
//! no velocities given, each inner knot's is the slope of the parabola through it and its
//! neighbours (0 where the path turns, so no segment overshoots a turn), and the ends' 0.

use crate::generator::SoftLimits;
use crate::wire::{MAX_PATH_KNOTS, PathKnot, PathRequest, Refusal, Refused};
use qmarc_config::Settings;
use qmarc_knots::KnotRules;
use qmarc_knots::dynamics::{check_segment, hermite_end_accelerations};
use qmarc_plugins::pvt::Hermite;
use qmarc_plugins::source::QUEUE_BUDGET_BYTES;
use qmarc_proto::MAX_MOTORS;

/// A path refused as a bad request, for `why`.
fn bad(why: String) -> Refused {
    Refused::new(Refusal::BadRequest, why)
}

/// The velocity at a knot between segments of slopes `s0` (length `h0`) and `s1` (`h1`): the
/// parabola's through the three knots, 0 where the path turns or stops.
fn inner_velocity(s0: f64, h0: f64, s1: f64, h1: f64) -> f64 {
    if s0 * s1 <= 0.0 { 0.0 } else { (s0 * h1 + s1 * h0) / (h0 + h1) }
}

/// The path's knots from `start` (its first, at rest at time 0), checked for their form:
/// times finite and rising, numbers finite, the end at rest; and each knot's point number in
/// the request (the start's 0).
fn knots_from(
    req: &PathRequest,
    start: &[f64; MAX_MOTORS],
    n: usize,
    tolerance: f64,
) -> Result<(Vec<PathKnot>, Vec<usize>), Refused> {
    if req.n_knots == 0 || req.n_knots as usize > MAX_PATH_KNOTS {
        return Err(bad(format!("a path has 1 to {MAX_PATH_KNOTS} points, found {}", req.n_knots)));
    }
    let given = req.has_velocities();
    let mut knots = vec![PathKnot { t_s: 0.0, pos: *start, vel: [0.0; MAX_MOTORS] }];
    let mut points = vec![0];
    for (i, k) in req.knots().iter().enumerate() {
        let point = i + 1;
        let prev = knots[knots.len() - 1].t_s;
        if let Some(v) =
            k.pos[..n].iter().chain(if given { &k.vel[..n] } else { &[] }).find(|v| !v.is_finite())
        {
            return Err(bad(format!("point {point}: the numbers must be finite, found {v}")));
        }
        if !k.t_s.is_finite() || k.t_s < 0.0 {
            return Err(bad(format!(
                "point {point}: time_from_start must be ≥ 0 s, found {}",
                k.t_s
            )));
        }
        if i == 0 && k.t_s == 0.0 {
            // A point at the start is where the robot is already, at rest.
            if let Some(m) = (0..n)
                .find(|&m| (k.pos[m] - start[m]).abs() > tolerance || (given && k.vel[m] != 0.0))
            {
                return Err(bad(format!(
                    "point 1: at time 0 the robot is where it rests, at rest; motor {} is at \
                     {:.0} counts, the point asks {:.0} counts at {} counts/s",
                    m + 1,
                    start[m],
                    k.pos[m],
                    if given { k.vel[m] } else { 0.0 }
                )));
            }
            continue;
        }
        if k.t_s <= prev {
            return Err(bad(format!(
                "point {point}: time_from_start {} s is not after the point before's, {prev} s",
                k.t_s
            )));
        }
        let mut k = *k;
        if !given {
            k.vel = [0.0; MAX_MOTORS];
        }
        k.vel[n..].fill(0.0);
        k.pos[n..].copy_from_slice(&start[n..]);
        knots.push(k);
        points.push(point);
    }
    let last = knots.len() - 1;
    if given {
        if let Some(m) = (0..n).find(|&m| knots[last].vel[m] != 0.0) {
            return Err(bad(format!(
                "point {}: a path ends at rest: its last velocities must be 0, motor {}'s is {} \
                 counts/s",
                req.n_knots,
                m + 1,
                knots[last].vel[m]
            )));
        }
    } else {
        for i in 1..last {
            let (h0, h1) = (knots[i].t_s - knots[i - 1].t_s, knots[i + 1].t_s - knots[i].t_s);
            for m in 0..n {
                let s0 = (knots[i].pos[m] - knots[i - 1].pos[m]) / h0;
                let s1 = (knots[i + 1].pos[m] - knots[i].pos[m]) / h1;
                knots[i].vel[m] = inner_velocity(s0, h0, s1, h1);
            }
        }
    }
    Ok((knots, points))
}

/// The samples, one per servo period, of the path `req` from `start` (where the command
/// rests) under `settings`: its first sample `start`, its last the path's end. `soft`: the
/// frame is homed and every sample must be within these soft limits. The samples take at most
/// [`QUEUE_BUDGET_BYTES`].
pub fn path_queue(
    req: &PathRequest,
    start: &[f64; MAX_MOTORS],
    settings: &Settings,
    soft: Option<SoftLimits>,
) -> Result<Vec<[f64; MAX_MOTORS]>, Refused> {
    path_queue_within(req, start, settings, soft, QUEUE_BUDGET_BYTES)
}

/// [`path_queue`], its samples taking at most `budget` bytes.
fn path_queue_within(
    req: &PathRequest,
    start: &[f64; MAX_MOTORS],
    settings: &Settings,
    soft: Option<SoftLimits>,
    budget: u64,
) -> Result<Vec<[f64; MAX_MOTORS]>, Refused> {
    let n = settings.n_motors;
    let (knots, points) = knots_from(req, start, n, settings.trajectory.start_tolerance_counts)?;
    if knots.len() == 1 {
        // Only a point at time 0, where the robot rests: nothing to follow, at once done.
        return Ok(vec![*start]);
    }
    let end = knots[knots.len() - 1].t_s;
    let max = settings.trajectory.max_duration_s;
    if end > max {
        return Err(bad(format!(
            "the path lasts {end} s: longer than the longest path, trajectory.max_duration_s = \
             {max} s"
        )));
    }
    let period = settings.period_s();
    // (A path a whole number of periods long is that many periods, not one more for rounding.)
    let samples = (end / period - 1e-9).ceil() as u64 + 1;
    let bytes = samples * std::mem::size_of::<[f64; MAX_MOTORS]>() as u64;
    if bytes > budget {
        return Err(bad(format!(
            "the path lasts {end} s: {samples} samples, more than the {:.1} MiB a path may take",
            budget as f64 / f64::from(1 << 20)
        )));
    }
    let rules = KnotRules::from_settings(settings);
    for (i, w) in knots.windows(2).enumerate() {
        let h = w[1].t_s - w[0].t_s;
        for m in 0..n {
            let (a0, a1) =
                hermite_end_accelerations(w[0].pos[m], w[0].vel[m], w[1].pos[m], w[1].vel[m], h);
            check_segment(&rules, m, (w[0].vel[m], a0, a1, h))
                .map_err(|e| bad(format!("point {}: {}", points[i + 1], e.describe())))?;
        }
    }
    let mut queue = Vec::with_capacity(samples as usize);
    let mut seg = 0;
    for k in 0..samples {
        let t = (k as f64 * period).min(end);
        seg = segment_of(&knots, seg, t);
        let (a, b) = (&knots[seg], &knots[seg + 1]);
        let mut c = *start;
        for (m, c) in c.iter_mut().enumerate().take(n) {
            *c = Hermite::new(a.pos[m], a.vel[m], b.pos[m], b.vel[m], b.t_s - a.t_s)
                .position(t - a.t_s);
        }
        queue.push(c);
    }
    queue[0] = *start;
    let last = queue.len() - 1;
    queue[last] = knots[knots.len() - 1].pos;
    if let Some((m, k, [lo, hi])) = soft.and_then(|soft| outside_soft_limits(&queue, &soft[..n])) {
        return Err(Refused::new(
            Refusal::SoftLimits,
            format!(
                "the path takes motor {} to {:.0} counts at {:.3} s, outside its soft limits \
                 [{lo}, {hi}]",
                m + 1,
                queue[k][m],
                k as f64 * period
            ),
        ));
    }
    Ok(queue)
}

/// The segment time `t` (at most the last knot's) falls in, from segment `seg` on: the one
/// whose end is the first at or after `t`. (At a knot's time either segment gives the
/// knot: the one before at its end, the next at its start.)
fn segment_of(knots: &[PathKnot], mut seg: usize, t: f64) -> usize {
    while seg + 2 < knots.len() && t > knots[seg + 1].t_s {
        seg += 1;
    }
    seg
}

/// The first motor (by number) some sample of `queue` takes outside its `soft` limits (one
/// per motor the robot has): the motor, the sample's index and the limits. A serving session's sampled moves (a path, a
/// straight line, an approach) are checked with it before the loop gets them.
pub fn outside_soft_limits(
    queue: &[[f64; MAX_MOTORS]],
    soft: &[(f64, f64)],
) -> Option<(usize, usize, [f64; 2])> {
    soft.iter().enumerate().find_map(|(m, &(lo, hi))| {
        queue.iter().position(|c| !(lo..=hi).contains(&c[m])).map(|k| (m, k, [lo, hi]))
    })
}

#[cfg(test)]
mod tests;

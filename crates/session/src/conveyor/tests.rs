//! The conveyor session's safety: a part is handed to the loop only if the gripper closes on
//! it inside the window and within reach; the loop follows a part exactly, never past the
//! window or out of reach, grips it once and places it; the belt's count at an exposure is
//! the loop's samples interpolated.

use super::dispatch::{BeltRead, counts_at, intercepts};
use super::picker::{Picker, PickerHandle, relative_limits, relative_limits_of};
use super::*;
use crate::generator::{NotTaken, Order, ServeHandle};
use qmarc_controller::status::LoopStatus;
use qmarc_controller::traj::{Sample, TrajectoryGenerator};
use qmarc_conveyor::{Detection, Part, PartState};
use qmarc_plugins::motion::{MotionLimits, Profile};
use qmarc_proto::{Gripper, MotorFlags};
use std::collections::VecDeque;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::Ordering;

/// The shipped settings.
fn settings() -> Settings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    Settings::load(&path, &qmarc_config::Names::any()).unwrap()
}

fn part(across_mm: f64) -> Part {
    let seen = Detection { t_ns: 0, latched_counts: 0, belt_mm: 0.0, across_mm };
    Part { id: 1, seen, state: PartState::Pending }
}

/// How long after it is told the gripper's read says it has closed: its travel and two
/// cycles.
fn closing_s(s: &Settings) -> f64 {
    s.s626.gripper_close_s + 2.0 * s.period_s()
}

/// Whether the picker at rest at the place intercepts a part now `at` mm along at `speed`,
/// and the intercept's duration.
fn intercept(s: &Settings, at: f64, across: f64, speed: f64) -> (bool, f64) {
    let frame = BeltFrame::of(s).unwrap();
    let relative = relative_limits(&frame, &MotionLimits::of(s), 3, speed, s.camera.spread_mm);
    intercept_within(s, &relative, at, across, speed)
}

/// [`intercept`] under the relative limits `relative`.
fn intercept_within(
    s: &Settings,
    relative: &MotionLimits,
    at: f64,
    across: f64,
    speed: f64,
) -> (bool, f64) {
    let frame = BeltFrame::of(s).unwrap();
    let command = frame.counts_at_mm(s.conveyor.place_mm).unwrap();
    let mut profile = Profile::new(3, command);
    let closing = closing_s(s);
    let ok =
        intercepts(&frame, relative, &mut profile, 3, &command, &part(across), at, speed, closing);
    (ok, profile.duration())
}

/// The gripper closes inside the window: told to close no earlier than its start, closed no
/// later than its end — to the mm of the planned intercept.
#[test]
fn a_part_is_handed_over_only_if_the_grip_falls_inside_the_window() {
    let s = settings();
    let [start, end] = s.conveyor.window_mm;
    let (speed, close_s) = (500.0, closing_s(&s));
    // Where the intercept would grip a part now at the window's start.
    let (ok, t) = intercept(&s, start, 0.0, speed);
    assert!(ok && t > 0.05, "{t}");
    // Upstream: handed over once the grip would come at the window's start, not before.
    let (early, t_early) = intercept(&s, start - speed * t - 30.0, 0.0, speed);
    assert!(
        !early,
        "gripped {} mm before the window",
        start - (start - speed * t - 30.0 + speed * t_early)
    );
    let upstream = start - speed * t + 30.0;
    let (ok, t_up) = intercept(&s, upstream, 0.0, speed);
    assert_eq!(ok, upstream + speed * t_up >= start, "{upstream} + {}", speed * t_up);
    // Downstream: not when the gripper would close past the window's end.
    let mut at = start;
    while intercept(&s, at + 1.0, 0.0, speed).0 {
        at += 1.0;
    }
    let (_, t_last) = intercept(&s, at, 0.0, speed);
    let closed = at + speed * (t_last + close_s);
    assert!(
        closed <= end && closed > end - 10.0,
        "the last part handed over closes at {closed} mm"
    );
    // A still belt: a part inside the window is handed over, one upstream of it never.
    assert!(intercept(&s, (start + end) / 2.0, 0.0, 0.0).0);
    assert!(!intercept(&s, start - 1.0, 0.0, 0.0).0);
    assert!(intercept(&s, start, 0.0, 0.0).0);
    let last = end - super::picker::CLOSE_MARGIN_MM;
    assert!(intercept(&s, last, 0.0, 0.0).0, "closed at the end, the margin kept: inside");
    assert!(!intercept(&s, last + 0.1, 0.0, 0.0).0);
}

#[test]
fn a_part_out_of_reach_is_never_handed_over() {
    let s = settings();
    let mid = (s.conveyor.window_mm[0] + s.conveyor.window_mm[1]) / 2.0;
    assert!(intercept(&s, mid, 0.0, 0.0).0);
    assert!(!intercept(&s, mid, 1_500.0, 0.0).0, "1.5 m across the belt");
    assert!(!intercept(&s, mid, -1_500.0, 0.0).0);
}

#[test]
fn the_count_at_an_exposure_is_interpolated_between_the_loops_samples() {
    let read = |(counts, ns)| BeltRead { counts, ns, sample: 0 };
    let h: VecDeque<BeltRead> = [(0, 1_000), (10, 2_000), (30, 3_000)].map(read).into();
    assert_eq!(counts_at(&h, 1_000), Some(0));
    assert_eq!(counts_at(&h, 1_500), Some(5));
    assert_eq!(counts_at(&h, 2_000), Some(10));
    assert_eq!(counts_at(&h, 2_250), Some(15));
    assert_eq!(counts_at(&h, 3_000), Some(30));
    assert_eq!(counts_at(&h, 999), None, "before the first sample");
    assert_eq!(counts_at(&h, 3_001), None, "after the last");
    assert_eq!(counts_at(&VecDeque::new(), 5), None);
}

/// A picker at rest at the place, its handles, and its settings.
fn picker(s: &Settings) -> (Picker, ServeHandle, PickerHandle) {
    let (mut p, serve, handle) = Picker::new(s, Arc::new(LoopStatus::default())).unwrap();
    p.start(&BeltFrame::of(s).unwrap().counts_at_mm(s.conveyor.place_mm).unwrap()).unwrap();
    (p, serve, handle)
}

/// Runs the picker on a belt at `counts_per_cycle` from `belt`, its gripper closing and
/// opening in `grip_cycles`, for `cycles` samples from `n`: the commands and the events.
struct Rig {
    n: u64,
    belt: i64,
    gripper: Gripper,
    told: Option<bool>,
    since: u64,
    /// The picks whose intercept began, and the cycle (apart from the other events).
    intercepting: Vec<(u32, u64)>,
    /// The motors' positions the next cycle reads: the last command (a robot that follows it
    /// a cycle late), or where `lag` puts them.
    act: [f64; MAX_MOTORS],
    /// Where the motors are, given the command of a cycle (default: on it, a cycle late).
    lag: Lag,
    /// Each cycle: its sample, the motors' positions and the belt it read.
    reads: Vec<(u64, [f64; MAX_MOTORS], i64)>,
}

/// Where the rig's motors are after the command of a sample.
type Lag = Box<dyn Fn(&[f64; MAX_MOTORS], u64) -> [f64; MAX_MOTORS]>;

impl Rig {
    fn run(
        &mut self,
        p: &mut Picker,
        h: &mut PickerHandle,
        cycles: u64,
        speed: i64,
    ) -> (Vec<[f64; MAX_MOTORS]>, Vec<PickEvent>, Sample) {
        let (mut cmds, mut events, mut last) = (Vec::new(), Vec::new(), Sample::Ready);
        for _ in 0..cycles {
            self.belt += speed;
            p.belt(self.belt);
            p.observe(&self.act, &[MotorFlags::default(); MAX_MOTORS]);
            self.reads.push((self.n, self.act, self.belt));
            let mut cmd = [0.0; MAX_MOTORS];
            last = p.sample(self.n, &mut cmd);
            if last == Sample::Done {
                break;
            }
            self.act = (self.lag)(&cmd, self.n);
            cmds.push(cmd);
            // The gripper takes 50 cycles to get where it is told.
            let told = p.gripper(self.gripper);
            if told != self.told {
                (self.told, self.since) = (told, self.n);
            }
            let there = self.n >= self.since + 50;
            self.gripper = Gripper(match (told, there) {
                (Some(true), true) => Gripper::CLOSE | Gripper::CLOSED,
                (Some(true), false) => Gripper::CLOSE,
                (_, true) => Gripper::OPEN,
                (_, false) => 0,
            });
            while let Ok(e) = h.events.pop() {
                match e {
                    PickEvent::Intercepting { id, cycle } => self.intercepting.push((id, cycle)),
                    _ => events.push(e),
                }
            }
            self.n += 1;
        }
        (cmds, events, last)
    }
}

fn rig() -> Rig {
    Rig {
        n: 0,
        belt: 0,
        gripper: Gripper(Gripper::OPEN),
        told: None,
        since: 0,
        intercepting: Vec::new(),
        act: [0.0; MAX_MOTORS],
        lag: Box::new(|cmd, _| *cmd),
        reads: Vec::new(),
    }
}

/// No jump, in position or in velocity: each step of `cmds` within what the motors' velocity
/// allows, each change of step within what their acceleration allows (a velocity that jumped
/// at a change of phase — the belt's own speed misjudged, a profile begun a sample late —
/// would break it).
fn smooth(s: &Settings, cmds: &[[f64; MAX_MOTORS]]) {
    let limits = MotionLimits::of(s);
    let (v, a) = (limits.velocity[0] * s.period_s(), limits.acceleration[0] * s.period_s().powi(2));
    for w in cmds.windows(2) {
        assert!((0..3).all(|m| (w[1][m] - w[0][m]).abs() <= v * 1.01), "{w:?}");
    }
    let j = limits.jerk[0] * s.period_s().powi(3);
    for (k, w) in cmds.windows(4).enumerate() {
        let third = (0..3)
            .map(|m| (w[3][m] - 3.0 * w[2][m] + 3.0 * w[1][m] - w[0][m]).abs())
            .fold(0.0, f64::max);
        assert!(
            third <= j * 1.5,
            "sample {k}: a third difference of {third} counts, the jerk's {j}"
        );
    }
    for (k, w) in cmds.windows(3).enumerate() {
        let change = (0..3).map(|m| (w[2][m] - 2.0 * w[1][m] + w[0][m]).abs()).fold(0.0, f64::max);
        assert!(
            change <= a * (1.0 + 1e-6),
            "sample {k}: a change of step of {change} counts, the acceleration's {a}"
        );
    }
}

/// A part handed over is intercepted, followed exactly while the gripper closes, lifted,
/// placed and let go, once; the command never jumps.
#[test]
fn the_picker_intercepts_follows_and_places_a_part_once() {
    let s = settings();
    let (mut p, serve, mut h) = picker(&s);
    let frame = BeltFrame::of(&s).unwrap();
    let mut r = rig();
    // The belt at 500 mm/s: 4 counts of 0.05 mm a 400 µs cycle is 0.5 m/s.
    let speed = 4;
    let (rest, _, _) = r.run(&mut p, &mut h, 40, speed);
    assert!(h.shared.ready.load(Ordering::Acquire));
    assert!(!serve.shared.moving.load(Ordering::Acquire), "at rest");
    let pick = Pick { id: 7, belt_mm: 320.0, across_mm: 30.0, latched_counts: r.belt };
    h.picks.push(pick).unwrap();
    let start = r.n;
    // Sample by sample: the command moves from the pick on, and the next pick is waited
    // for only once the gripper reads open after the place (50 cycles in this rig).
    let (mut cmds, mut events) = (Vec::new(), Vec::new());
    let mut placed_at = None;
    for _ in 0..2_000 {
        let (c, e, _) = r.run(&mut p, &mut h, 1, speed);
        cmds.extend(c);
        events.extend(e);
        if placed_at.is_none() && events.iter().any(|e| matches!(e, PickEvent::Placed { .. })) {
            placed_at = Some(r.n);
        }
        let ready = h.shared.ready.load(Ordering::Acquire);
        assert!(
            !ready || placed_at.is_some_and(|at| r.n >= at + 50),
            "ready at cycle {} before the gripper read open ({placed_at:?})",
            r.n
        );
        if placed_at.is_none() {
            assert!(serve.shared.moving.load(Ordering::Acquire), "moving at cycle {}", r.n);
        }
    }
    assert!(!serve.shared.moving.load(Ordering::Acquire), "at rest again");
    // At rest before it (two samples: a velocity), then the pick: no jump where the
    // intercept begins either.
    let mut all = rest[rest.len() - 2..].to_vec();
    all.extend_from_slice(&cmds);
    assert!(!h.shared.ready.load(Ordering::Acquire) || events.len() == 3, "{events:?}");
    let gripping = events.iter().find_map(|e| match e {
        PickEvent::Gripping { id: 7, cycle } => Some(*cycle),
        _ => None,
    });
    let grip = gripping.expect("gripped");
    assert!(matches!(events[1], PickEvent::Lifted { id: 7 }), "{events:?}");
    assert!(matches!(events[2], PickEvent::Placed { id: 7, .. }), "{events:?}");
    assert_eq!(events.len(), 3, "once: {events:?}");
    // Its intercept began in the cycle the pick was there for.
    assert_eq!(r.intercepting, [(7, start)]);
    // On the part, exactly, from the grip until the gripper has closed (50 cycles).
    for k in grip..grip + 50 {
        let belt = pick.latched_counts + speed * (k - start + 1) as i64;
        let along = frame.along(&pick, belt);
        let on = frame.counts(along, pick.across_mm).unwrap();
        let cmd = cmds[(k - start) as usize];
        assert!((0..3).all(|m| (cmd[m] - on[m]).abs() < 1e-6), "cycle {k}: {cmd:?} against {on:?}");
        assert!(along <= s.conveyor.window_mm[1]);
    }
    smooth(&s, &all);
    // Back at rest, waiting for the next.
    assert!(h.shared.ready.load(Ordering::Acquire));
}

/// A part the belt carries past the window before the gripper has closed on it is given up:
/// the gripper opens, the command stops — never chased.
#[test]
fn a_part_leaving_the_window_is_given_up_never_chased() {
    let s = settings();
    let (mut p, _serve, mut h) = picker(&s);
    let mut r = rig();
    let speed = 4;
    let (rest, _, _) = r.run(&mut p, &mut h, 40, speed);
    // Just short of the window's end (by no whole number of the belt's 0.2 mm steps).
    let end = s.conveyor.window_mm[1];
    let pick = Pick { id: 3, belt_mm: end - 0.93, across_mm: 0.0, latched_counts: r.belt };
    h.picks.push(pick).unwrap();
    // Given up in the cycle the belt carries it past the end (the fifth 0.2 mm step), not
    // chased until the intercept would end.
    let (mut cmds, mut events) = (vec![rest[rest.len() - 1]], Vec::new());
    let mut cycles = 0;
    while events.is_empty() {
        let (c, e, _) = r.run(&mut p, &mut h, 1, speed);
        cmds.extend(c);
        events.extend(e);
        cycles += 1;
    }
    assert_eq!(cycles, 5, "given up {cycles} cycles after the pick arrived");
    let (c, e, _) = r.run(&mut p, &mut h, 1_500, speed);
    cmds.extend(c);
    events.extend(e);
    assert_eq!(
        events.first(),
        Some(&PickEvent::GaveUp { id: 3, why: GaveUp::LeftWindow }),
        "{events:?}"
    );
    // Given up while moving: on to the place without a repeated sample or a jump.
    smooth(&s, &cmds);
    assert!(!events.iter().any(|e| matches!(e, PickEvent::Gripping { .. })), "{events:?}");
    assert_eq!(r.told, Some(false), "the gripper told to open");
    assert!(h.shared.ready.load(Ordering::Acquire), "ready for the next");
    // Out of reach: given up at once.
    let far = Pick { id: 4, belt_mm: 400.0, across_mm: 2_000.0, latched_counts: r.belt };
    h.picks.push(far).unwrap();
    let (_, events, _) = r.run(&mut p, &mut h, 200, speed);
    assert_eq!(
        events.first(),
        Some(&PickEvent::GaveUp { id: 4, why: GaveUp::OutOfReach }),
        "{events:?}"
    );
}

/// A quit ends the picking: a part in the gripper is still placed, then the session ends at
/// rest with the gripper open; a move is not taken, and says why.
#[test]
fn a_quit_finishes_the_part_held_and_moves_are_not_taken() {
    let s = settings();
    let (mut p, mut serve, mut h) = picker(&s);
    let mut r = rig();
    let speed = 4;
    r.run(&mut p, &mut h, 40, speed);
    let limits = MotionLimits::of(&s);
    serve.orders.push(Order::Move { id: 9, target: [0.0; MAX_MOTORS], limits }).unwrap();
    r.run(&mut p, &mut h, 2, speed);
    assert_eq!(serve.shared.not_taken.load(Ordering::Acquire), 9);
    let why = NotTaken::from_wire(serve.shared.not_taken_why.load(Ordering::Acquire));
    assert_eq!(why, Some(NotTaken::Picking));
    let pick = Pick { id: 5, belt_mm: 320.0, across_mm: 0.0, latched_counts: r.belt };
    h.picks.push(pick).unwrap();
    // Until the gripper has closed on it, then quit.
    let mut events = Vec::new();
    while !events.iter().any(|e| matches!(e, PickEvent::Lifted { .. })) {
        events.extend(r.run(&mut p, &mut h, 1, speed).1);
        assert!(r.n < 5_000, "{events:?}");
    }
    serve.orders.push(Order::Quit { limits }).unwrap();
    let (cmds, rest, end) = r.run(&mut p, &mut h, 5_000, speed);
    assert_eq!(end, Sample::Done, "the session ended");
    assert!(matches!(rest.first(), Some(PickEvent::Placed { id: 5, .. })), "{rest:?}");
    assert!(h.shared.ending.load(Ordering::Acquire) && !h.shared.ready.load(Ordering::Acquire));
    assert_eq!(r.told, Some(false), "open at the end");
    let last = cmds.last().unwrap();
    assert_eq!(cmds[cmds.len() - 2], *last, "at rest");
}

/// The gripper is told to close only if its read will say closed before the belt carries the
/// part past the window's end (its travel, two cycles and `CLOSE_MARGIN_MM`): parts reached
/// late are given up at the end of the intercept, inside the window, never gripped.
#[test]
fn the_gripper_closes_only_if_it_closes_inside_the_window() {
    let s = settings();
    let end = s.conveyor.window_mm[1];
    let speed = 4; // counts a cycle: 500 mm/s
    let mm_s = speed as f64 * s.conveyor.mm_per_count / s.period_s();
    let closing_mm = mm_s * closing_s(&s) + super::picker::CLOSE_MARGIN_MM;
    let (mut gripped, mut gated) = (0, 0);
    for k in 0..60 {
        let (mut p, _serve, mut h) = picker(&s);
        let mut r = rig();
        r.run(&mut p, &mut h, 40, speed);
        let start = end - 200.0 + 3.07 * f64::from(k);
        let pick = Pick { id: 1, belt_mm: start, across_mm: 0.0, latched_counts: r.belt };
        h.picks.push(pick).unwrap();
        let (mut event, mut cmds) = (None, Vec::new());
        while event.is_none() && r.n < 3_000 {
            let (c, e, _) = r.run(&mut p, &mut h, 1, speed);
            cmds.extend(c);
            event = e.first().copied();
        }
        // Where the part was in the cycle of the event (the last one run).
        let along = pick.belt_mm + (r.belt - pick.latched_counts) as f64 * s.conveyor.mm_per_count;
        match event {
            Some(PickEvent::Gripping { .. }) => {
                gripped += 1;
                assert!(along + closing_mm <= end + 1e-9, "gripped at {along} mm");
            }
            Some(PickEvent::GaveUp { why: GaveUp::LeftWindow, .. }) => {
                // Inside the window still: the gate, not the end, gave it up.
                if along <= end {
                    gated += 1;
                    assert!(along + closing_mm > end - 0.3, "given up at {along} mm");
                    // On to the place from the sample it was on the part: no jump.
                    cmds.extend(r.run(&mut p, &mut h, 300, speed).0);
                    smooth(&s, &cmds);
                }
            }
            other => panic!("{other:?} for a part from {start} mm"),
        }
    }
    assert!(gripped > 5 && gated > 0, "{gripped} gripped, {gated} given up inside the window");
}

/// The picker as the loop sees it: named `conveyor`, of no fixed length, at rest at its end.
#[test]
fn the_picker_is_an_endless_generator_that_ends_at_rest() {
    let s = settings();
    let (p, _serve, _h) = picker(&s);
    assert_eq!(p.name(), "conveyor");
    assert_eq!(p.samples(), None);
    assert_eq!(p.end_velocity(), Some([0.0; MAX_MOTORS]));
}

/// The limits a part's frame leaves each motor, checked against the belt's own demand found
/// independently: the motor's velocity over a dense grid of the window (every 5 mm along,
/// every 5 mm across the spread) at the fastest belt speed, by a central difference.
#[test]
fn the_relative_limits_leave_the_motors_what_the_belt_does_not_take() {
    let s = settings();
    let frame = BeltFrame::of(&s).unwrap();
    let limits = MotionLimits::of(&s);
    let (fastest, spread) = (700.0, s.camera.spread_mm);
    let r = relative_limits(&frame, &limits, 3, fastest, spread);
    let [w0, w1] = frame.window_mm;
    let mut demand = [0.0f64; 3];
    let mut along = w0;
    while along <= w1 + 1e-9 {
        let mut across = -spread / 2.0;
        while across <= spread / 2.0 + 1e-9 {
            let (a, b) = (frame.counts(along - 0.01, across), frame.counts(along + 0.01, across));
            if let (Ok(a), Ok(b)) = (a, b) {
                for m in 0..3 {
                    demand[m] = demand[m].max((b[m] - a[m]).abs() / 0.02 * fastest);
                }
            }
            across += 5.0;
        }
        along += 5.0;
    }
    for m in 0..3 {
        assert!(demand[m] > 0.0 && demand[m] < 0.8 * limits.velocity[m], "{demand:?}");
        // The belt's demand and a tenth of it in reserve taken from the velocity (to the
        // grid's and the difference's precision).
        let taken = limits.velocity[m] - r.velocity[m];
        let ratio = taken / (1.1 * demand[m]);
        assert!((0.99..1.01).contains(&ratio), "motor {}: {taken} taken, {ratio}", m + 1);
        assert_eq!(r.acceleration[m], 0.8 * limits.acceleration[m]);
        assert_eq!(r.jerk[m], 0.8 * limits.jerk[m]);
    }
    // A belt too fast for a motor leaves it a fifth of its velocity, never less.
    let r = relative_limits(&frame, &limits, 3, 1e6, spread);
    for m in 0..3 {
        assert_eq!(r.velocity[m], 0.2 * limits.velocity[m]);
    }
    // Motors past n_motors are left as they are.
    let r = relative_limits(&frame, &limits, 2, fastest, spread);
    assert_eq!(r.velocity[2], limits.velocity[2]);
}

/// The dispatcher hands a part over by the intercept the picker will then plan: the same
/// duration, to a cycle, from the place to parts along and across the belt (its start state
/// relative to the moving part — position and the belt's velocity — as the picker's).
#[test]
fn the_dispatchers_intercept_is_the_one_the_picker_runs() {
    let s = settings();
    let frame = BeltFrame::of(&s).unwrap();
    let relative = relative_limits_of(&s, &frame);
    let t = s.period_s();
    let speed = 4; // counts a cycle: 500 mm/s
    let mm_s = speed as f64 * s.conveyor.mm_per_count / t;
    for (at, across) in [(300.0, 0.0), (320.0, 40.0), (280.0, -45.0)] {
        let (handed, planned) = intercept_within(&s, &relative, at, across, mm_s);
        assert!(handed, "{at} mm along, {across} across");
        // The picker at rest at the place, its belt tracker on the belt's speed.
        let (mut p, _serve, mut h) = picker(&s);
        let mut r = rig();
        r.run(&mut p, &mut h, 500, speed);
        h.picks
            .push(Pick { id: 1, belt_mm: at, across_mm: across, latched_counts: r.belt })
            .unwrap();
        let start = r.n;
        let mut grip = None;
        while grip.is_none() && r.n < start + 5_000 {
            grip = r.run(&mut p, &mut h, 1, speed).1.iter().find_map(|e| match e {
                PickEvent::Gripping { cycle, .. } => Some(*cycle),
                _ => None,
            });
        }
        let ran = (grip.expect("gripped") - start + 1) as f64 * t;
        assert!(
            (ran - planned).abs() <= 1.5 * t,
            "{at} mm along, {across} across: planned {planned} s, the picker ran {ran} s"
        );
    }
}

/// A part picked by motors that follow the command as `lag` says: the cycle the gripper was
/// told to close, and the distance from the effector (the forward kinematics of that cycle's
/// read) to the part where that cycle's read of the belt had it — `parts.csv`'s `error_mm`.
fn grip_with(s: &Settings, lag: Lag) -> (u64, f64) {
    let frame = BeltFrame::of(s).unwrap();
    let (mut p, _serve, mut h) = picker(s);
    let mut r = rig();
    r.lag = lag;
    let speed = 4;
    r.run(&mut p, &mut h, 40, speed);
    let pick = Pick { id: 1, belt_mm: 320.0, across_mm: 20.0, latched_counts: r.belt };
    h.picks.push(pick).unwrap();
    let mut grip = None;
    while grip.is_none() && r.n < 5_000 {
        grip = r.run(&mut p, &mut h, 1, speed).1.iter().find_map(|e| match e {
            PickEvent::Gripping { cycle, .. } => Some(*cycle),
            _ => None,
        });
    }
    let g = grip.expect("gripped");
    let &(_, act, belt) = r.reads.iter().find(|(n, ..)| *n == g).unwrap();
    let part = (pick.belt_mm, pick.across_mm, pick.latched_counts as f64);
    (g, frame.effector_error_mm([act[0], act[1], act[2]], belt as f64, part).unwrap())
}

/// The gripper is told to close once the effector is on the part — the forward kinematics of
/// the cycle's read within GRIP_WITHIN_MM of the part where the cycle's read of the belt has
/// it — so a robot still off the part (a host's stall) settles first; one that never comes
/// that near is gripped after SETTLE_MAX_S on it all the same.
#[test]
fn the_gripper_closes_once_the_effector_is_on_the_part() {
    use super::picker::{GRIP_WITHIN_MM, SETTLE_MAX_S};
    let s = settings();
    let off = |cmd: &[f64; MAX_MOTORS]| -> [f64; MAX_MOTORS] {
        std::array::from_fn(|m| cmd[m] + [60.0, -60.0, 60.0, 0.0][m])
    };
    // On the command a cycle late: the gripper told at the intercept's end.
    let (on_time, error) = grip_with(&s, Box::new(|cmd, _| *cmd));
    assert!(error <= GRIP_WITHIN_MM, "{error} mm");
    // Off the part until 20 cycles later: told in the first cycle whose read is on it.
    let (settled, error) =
        grip_with(&s, Box::new(move |cmd, n| if n < on_time + 20 { off(cmd) } else { *cmd }));
    assert_eq!(settled, on_time + 21);
    assert!(error <= GRIP_WITHIN_MM, "{error} mm");
    // Never on it: told after SETTLE_MAX_S all the same, however far.
    let (late, error) = grip_with(&s, Box::new(move |cmd, _| off(cmd)));
    assert_eq!(late, on_time + (SETTLE_MAX_S / s.period_s()).round() as u64);
    assert!(error > 2.0 * GRIP_WITHIN_MM, "{error} mm: the offset is no test");
}

/// The belt frame's points and counts are the settings' belt (`ConveyorSettings::point_mm`,
/// the part's height on top): along, across and above it, off the centre line too.
#[test]
fn the_belt_frame_puts_a_part_where_the_settings_say() {
    let s = settings();
    let (frame, c, height) = (BeltFrame::of(&s).unwrap(), &s.conveyor, s.camera.part_height_mm);
    let up_mm = 25.0;
    for (along, across) in [(300.0, 0.0), (420.0, 45.0), (500.0, -40.0)] {
        let want = c.point_mm(along, across, height);
        let got = frame.grip_point_mm(along, across);
        assert!((0..3).all(|i| (got[i] - want[i]).abs() < 1e-9), "{got:?} for {want:?}");
        let up = frame.counts_up(along, across, up_mm).unwrap();
        let above = frame.counts_at_mm(c.point_mm(along, across, height + up_mm)).unwrap();
        assert_eq!(up, above, "{up_mm} mm above the part at {along}, {across}");
    }
}

mod cancel;

//! The serving generator: it holds until an order arrives, takes each order in the cycle it
//! arrives, keeps the limits across every change, follows lines and hands their queues back,
//! refuses a profile that would leave the soft limits, and ends only after a quit's stop.

use super::*;
use qmarc_plugins::motion::sampled_ratio;
use std::path::Path;

/// The shipped settings.
fn settings() -> Settings {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml");
    Settings::load(&path, &qmarc_config::Names::any()).unwrap()
}

const SOFT: [(f64, f64); MAX_MOTORS] = [(-9_000.0, 10_000.0); MAX_MOTORS];

/// A serving generator started at `start`, and its handle.
fn serving(start: [f64; MAX_MOTORS]) -> (ServeMove, ServeHandle, MotionLimits, f64) {
    let s = settings();
    let limits = ServeLimits { soft: Some(SOFT), ..ServeLimits::of(&s, true) };
    let (mut g, h) = ServeMove::new(&s, &limits, Arc::new(LoopStatus::default()));
    g.start(&start).unwrap();
    (g, h, MotionLimits::of(&s), s.period_s())
}

/// Samples `from..to` into `cmds`; the last answer.
fn run(g: &mut ServeMove, n: std::ops::Range<u64>, cmds: &mut Vec<[f64; MAX_MOTORS]>) -> Sample {
    let mut last = Sample::Ready;
    for k in n {
        let mut cmd = [0.0; MAX_MOTORS];
        last = g.sample(k, &mut cmd);
        if last != Sample::Ready {
            break;
        }
        cmds.push(cmd);
    }
    last
}

fn load(a: &AtomicU64) -> u64 {
    a.load(Ordering::Acquire)
}

#[test]
fn it_holds_where_it_starts_until_an_order_arrives() {
    let start = [100.0, -200.0, 300.0, 0.0];
    let (mut g, h, ..) = serving(start);
    let mut cmds = Vec::new();
    assert_eq!(run(&mut g, 0..50, &mut cmds), Sample::Ready);
    assert!(cmds.iter().all(|c| *c == start));
    assert!(!h.shared.moving.load(Ordering::Acquire));
    assert_eq!((load(&h.shared.taken), load(&h.shared.settled)), (0, 0));
    assert_eq!(g.samples(), None, "a session has no known length");
}

#[test]
fn a_move_is_taken_in_the_cycle_it_arrives_and_settles_on_its_target() {
    let (mut g, mut h, limits, t) = serving([0.0; MAX_MOTORS]);
    let mut cmds = Vec::new();
    run(&mut g, 0..10, &mut cmds);
    let target = [3000.0, -1500.0, 800.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target, limits }).is_ok());
    run(&mut g, 10..11, &mut cmds);
    // The cycle it was taken in counts the loop's cycles (its status; no loop runs here: 0)
    // and that one.
    assert_eq!((load(&h.shared.taken), load(&h.shared.taken_cycle)), (1, 1));
    assert_eq!(g.name(), "serve");
    assert_ne!(cmds[10], cmds[9], "the cycle that takes it already moves");
    assert!(h.shared.moving.load(Ordering::Acquire));
    assert_eq!(load(&h.shared.settled), 0, "not at rest yet");
    // Moving until the sample that reaches the target, at rest (settled) from that one on.
    let mut n = 11;
    while *cmds.last().unwrap() != target {
        assert!(h.shared.moving.load(Ordering::Acquire), "sample {n}");
        run(&mut g, n..n + 1, &mut cmds);
        n += 1;
    }
    assert!(!h.shared.moving.load(Ordering::Acquire));
    assert_eq!(load(&h.shared.settled), 1);
    run(&mut g, n..2_000, &mut cmds);
    assert_eq!(*cmds.last().unwrap(), target);
    assert_eq!(load(&h.shared.settled), 1);
    assert!(!h.shared.moving.load(Ordering::Acquire));
    assert!(sampled_ratio(&cmds, 3, t, &limits) <= 1.0 + 1e-6);
}

#[test]
fn a_new_target_or_a_stop_takes_over_within_the_limits() {
    let (mut g, mut h, limits, t) = serving([0.0; MAX_MOTORS]);
    let mut cmds = Vec::new();
    let far = [8000.0, 8000.0, -8000.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target: far, limits }).is_ok());
    run(&mut g, 0..60, &mut cmds);
    let back = [-2000.0, 1000.0, 0.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 2, target: back, limits }).is_ok());
    run(&mut g, 60..120, &mut cmds);
    assert!(h.orders.push(Order::Stop { id: 3, limits }).is_ok());
    run(&mut g, 120..3_000, &mut cmds);
    assert!(sampled_ratio(&cmds, 3, t, &limits) <= 1.0 + 1e-6, "no jump at either change");
    let end = *cmds.last().unwrap();
    assert_ne!(end, back, "the stop came first");
    assert_eq!(cmds[cmds.len() - 2], end, "at rest");
    assert_eq!((load(&h.shared.taken), load(&h.shared.settled)), (3, 3));
}

#[test]
fn a_line_is_followed_then_its_queue_handed_back_to_be_freed() {
    let start = [10.0, 20.0, 30.0, 0.0];
    let (mut g, mut h, limits, t) = serving(start);
    let mut cmds = Vec::new();
    run(&mut g, 0..5, &mut cmds);
    // From rest to rest, well within the limits: a raised cosine of 500 counts.
    let along = |k: usize| 10.0 + 250.0 * (1.0 - (std::f64::consts::PI * k as f64 / 199.0).cos());
    let queue: LineQueue = (0..200).map(|k| [along(k), 20.0, 30.0, 0.0]).collect();
    let end = queue[199];
    assert!(h.orders.push(Order::Line { id: 1, queue: queue.clone() }).is_ok());
    run(&mut g, 5..204, &mut cmds);
    assert!(h.shared.moving.load(Ordering::Acquire), "one sample before the line's end");
    run(&mut g, 204..205, &mut cmds);
    assert!(!h.shared.moving.load(Ordering::Acquire), "on the line's last sample");
    assert_eq!(load(&h.shared.settled), 1);
    run(&mut g, 205..400, &mut cmds);
    assert_eq!(cmds[5..205], queue[..], "sample by sample from the cycle it arrived");
    assert_eq!(*cmds.last().unwrap(), end);
    assert_eq!(load(&h.shared.settled), 1);
    assert_eq!(h.spent.pop().map(|q| q.len()), Ok(200), "handed back, not freed in the loop");
    // A line that does not start where the robot is is not taken.
    assert!(h.orders.push(Order::Line { id: 2, queue: queue.clone() }).is_ok());
    run(&mut g, 400..401, &mut cmds);
    assert_eq!((load(&h.shared.not_taken), cmds[400]), (2, end));
    let why = NotTaken::from_wire(h.shared.not_taken_why.load(Ordering::Acquire));
    assert_eq!(why, Some(NotTaken::NotFromRest));
    assert!(h.spent.pop().is_ok(), "handed back");
    // A target while a line runs takes over from the line's state: a line at the limits
    // (a full-speed jerk-limited move's samples), left while it accelerates hardest, so a
    // velocity or an acceleration taken wrongly would break a limit.
    let mut fast = qmarc_plugins::online::OnlineMove::new([3000.0, 20.0, 30.0, 0.0], 3, t, limits);
    fast.start(&end).unwrap();
    let mut back = Vec::new();
    let mut cmd = [0.0; MAX_MOTORS];
    for n in 0..fast.samples().unwrap() {
        fast.sample(n, &mut cmd);
        back.push(cmd);
    }
    assert!(h.orders.push(Order::Line { id: 3, queue: back.into() }).is_ok());
    run(&mut g, 401..416, &mut cmds);
    let elsewhere = [200.0, 20.0, 30.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 4, target: elsewhere, limits }).is_ok());
    run(&mut g, 416..3_000, &mut cmds);
    assert_eq!(*cmds.last().unwrap(), elsewhere, "the target, not the line's end");
    assert!(h.spent.pop().is_ok(), "the line left for the target is handed back too");
    // From the line's position, velocity and acceleration: no jump where the target took over.
    assert!(sampled_ratio(&cmds[400..], 3, t, &limits) <= 1.0 + 1e-6);
}

#[test]
fn a_profile_that_would_leave_the_soft_limits_is_not_taken() {
    let (mut g, mut h, limits, t) = serving([0.0; MAX_MOTORS]);
    let mut cmds = Vec::new();
    let target = [9_000.0, 0.0, 0.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target, limits }).is_ok());
    run(&mut g, 0..80, &mut cmds);
    // At a twentieth of the speed (1/400 of the acceleration) the motor cannot turn round
    // before 10 000 counts: not taken; the move goes on to its target.
    let slow = limits.at_speed(0.05);
    assert!(h.orders.push(Order::Move { id: 2, target: [0.0; MAX_MOTORS], limits: slow }).is_ok());
    run(&mut g, 80..3_000, &mut cmds);
    assert_eq!(load(&h.shared.not_taken), 2);
    // Said truly (issue 42: `wait` blamed the soft limits for any order not taken).
    let why = NotTaken::from_wire(h.shared.not_taken_why.load(Ordering::Acquire));
    assert_eq!(why, Some(NotTaken::SoftLimits(1)));
    assert_eq!(*cmds.last().unwrap(), target);
    assert!(cmds.iter().all(|c| c[0] <= 10_000.0));
    assert!(sampled_ratio(&cmds, 3, t, &limits) <= 1.0 + 1e-6);
}

#[test]
fn a_move_with_no_profile_is_not_taken_and_said_so() {
    let (mut g, mut h, limits, _) = serving([0.0; MAX_MOTORS]);
    let mut cmds = Vec::new();
    let vanishing = limits.at_speed(1e-300);
    let target = [100.0, 0.0, 0.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target, limits: vanishing }).is_ok());
    run(&mut g, 0..10, &mut cmds);
    assert_eq!(load(&h.shared.not_taken), 1);
    let why = NotTaken::from_wire(h.shared.not_taken_why.load(Ordering::Acquire));
    assert_eq!(why, Some(NotTaken::NoProfile));
    assert!(why.unwrap().words().contains("no jerk-limited profile"));
    assert!(cmds.iter().all(|c| *c == [0.0; MAX_MOTORS]), "held where it was");
}

#[test]
fn quit_stops_then_ends_the_move() {
    let (mut g, mut h, limits, _) = serving([0.0; MAX_MOTORS]);
    let mut cmds = Vec::new();
    let far = [6000.0, 0.0, 0.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target: far, limits }).is_ok());
    run(&mut g, 0..50, &mut cmds);
    assert!(h.orders.push(Order::Quit { limits }).is_ok());
    let end = run(&mut g, 50..5_000, &mut cmds);
    assert_eq!(end, Sample::Done);
    let last = *cmds.last().unwrap();
    assert!(last[0] < far[0], "stopped short of the target: {last:?}");
    // The stop's last sample is its rest; it came to it jerk-limited, at a crawl.
    let crawl = (last[0] - cmds[cmds.len() - 2][0]) / 400e-6;
    assert!(crawl.abs() < 5.0, "{crawl} counts/s into its rest");
    let mut after = [0.0; MAX_MOTORS];
    assert_eq!(g.sample(5_000, &mut after), Sample::Done, "and stays ended");
    assert_eq!(g.end_velocity(), Some([0.0; MAX_MOTORS]));
}

/// Issue 30: a grip order tells the gripper in the cycle it arrives and leaves the motion as
/// it is; it settles once the command is at rest and a read finds the gripper there.
#[test]
fn a_grip_is_told_at_once_and_settles_when_the_gripper_is_there() {
    let (mut g, mut h, limits, _) = serving([0.0; MAX_MOTORS]);
    let mut cmd = [0.0; MAX_MOTORS];
    let open = Gripper(Gripper::OPEN);
    g.sample(0, &mut cmd);
    assert_eq!(g.gripper(open), None, "told nothing: left as it is");
    assert_eq!(load(&h.shared.settled), 0);
    // A move, then a grip while it moves: the grip takes over nothing of the motion.
    let target = [2000.0, 0.0, 0.0, 0.0];
    assert!(h.orders.push(Order::Move { id: 1, target, limits }).is_ok());
    g.sample(1, &mut cmd);
    assert!(h.orders.push(Order::Grip { id: 2, close: true }).is_ok());
    g.sample(2, &mut cmd);
    assert_eq!(load(&h.shared.taken), 2);
    assert_eq!(g.gripper(open), Some(true), "told in the cycle it arrives");
    let mut n = 3;
    while g.sample(n, &mut cmd) == Sample::Ready && cmd != target {
        assert_eq!(g.gripper(Gripper(Gripper::CLOSE)), Some(true), "closing");
        n += 1;
    }
    assert_eq!(cmd, target, "the move went on to its target");
    // At rest, but the gripper still closing: not settled.
    for k in n + 1..n + 20 {
        g.sample(k, &mut cmd);
        assert_eq!(g.gripper(Gripper(Gripper::CLOSE)), Some(true));
    }
    assert_eq!(load(&h.shared.settled), 0, "the gripper is not there yet");
    g.gripper(Gripper(Gripper::CLOSE | Gripper::CLOSED));
    g.sample(n + 20, &mut cmd);
    assert_eq!(load(&h.shared.settled), 2);
    // Opened: settled only when a read finds it open (a closed one is not "there").
    assert!(h.orders.push(Order::Grip { id: 3, close: false }).is_ok());
    g.sample(n + 21, &mut cmd);
    assert_eq!(g.gripper(Gripper(Gripper::CLOSE | Gripper::CLOSED)), Some(false));
    g.sample(n + 22, &mut cmd);
    g.gripper(Gripper(Gripper::CLOSED));
    g.sample(n + 23, &mut cmd);
    assert_eq!(load(&h.shared.settled), 2, "still opening");
    g.gripper(Gripper(Gripper::OPEN));
    g.sample(n + 24, &mut cmd);
    assert_eq!(load(&h.shared.settled), 3);
}

/// `motion` is the last motion order taken — a line, a stop, a move — and a grip is none: a
/// path goes on through a grip, and a client watching it (the bridge's action) sees so.
#[test]
fn a_grip_is_no_motion_a_line_a_stop_and_a_move_are() {
    let (mut g, h, limits, _) = serving([0.0; MAX_MOTORS]);
    let mut h = h;
    let mut cmds = Vec::new();
    run(&mut g, 0..2, &mut cmds);
    let queue: LineQueue = (0..50)
        .map(|k| {
            let mut c = [0.0; MAX_MOTORS];
            c[0] = f64::from(k);
            c
        })
        .collect();
    assert!(h.orders.push(Order::Line { id: 1, queue }).is_ok());
    run(&mut g, 2..5, &mut cmds);
    assert_eq!(load(&h.shared.motion), 1);
    assert!(h.orders.push(Order::Grip { id: 2, close: true }).is_ok());
    run(&mut g, 5..8, &mut cmds);
    assert_eq!(load(&h.shared.motion), 1, "the line goes on through a grip");
    assert_eq!(cmds.last().unwrap()[0], 5.0, "still on the line");
    assert!(h.orders.push(Order::Stop { id: 3, limits }).is_ok());
    run(&mut g, 8..9, &mut cmds);
    assert_eq!(load(&h.shared.motion), 3);
    let mut target = [0.0; MAX_MOTORS];
    target[0] = 10.0;
    assert!(h.orders.push(Order::Move { id: 4, target, limits }).is_ok());
    run(&mut g, 9..10, &mut cmds);
    assert_eq!(load(&h.shared.motion), 4);
}

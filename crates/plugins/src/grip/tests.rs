//! The gripper at a move's end: told in the cycle of the path's last sample, the path's end
//! held until a read finds it there, a gripper that never gets there fails the move, and
//! none wired fails it at once.

use super::*;

/// A path of `samples` samples: sample n commands n counts on motor 1.
fn path(samples: u64) -> Box<dyn TrajectoryGenerator> {
    Box::new(TestPath(samples))
}

struct TestPath(u64);

impl TrajectoryGenerator for TestPath {
    fn name(&self) -> &'static str {
        "test"
    }
    fn start(&mut self, _: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        Ok(())
    }
    fn samples(&self) -> Option<u64> {
        Some(self.0)
    }
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        if n >= self.0 {
            return Sample::Done;
        }
        cmd[0] = n as f64;
        Sample::Ready
    }
    fn gripper(&mut self, _: Gripper) -> Option<bool> {
        Some(false)
    }
    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        Some([(-3.0, self.0 as f64); MAX_MOTORS])
    }
    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        Some([0.5, 0.25, 0.0, 0.0])
    }
    fn observe(&mut self, act: &[f64; MAX_MOTORS], _: &[MotorFlags; MAX_MOTORS]) {
        self.0 = act[0] as u64;
    }
    fn progress(&self) -> u32 {
        7
    }
    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        Ok(Some([2.0; MAX_MOTORS]))
    }
    fn lead_in(&self) -> u64 {
        12
    }
}

/// Runs `g` against a gripper that is there `after` cycles after it is told (never: `None`);
/// every (command, gripper answer), and how it ended.
fn run(g: &mut GripAtEnd, after: Option<u64>) -> (Vec<(f64, Option<bool>)>, Sample) {
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut told_at = None;
    let mut out = Vec::new();
    for n in 0..10_000 {
        let mut cmd = [f64::NAN; MAX_MOTORS];
        let s = g.sample(n, &mut cmd);
        if s != Sample::Ready {
            return (out, s);
        }
        let close = g.close;
        let there = matches!((told_at, after), (Some(t), Some(a)) if n >= t + a);
        let state = match (told_at.is_some(), there, close) {
            (false, _, _) => Gripper(Gripper::OPEN | if close { 0 } else { Gripper::CLOSE }),
            (true, false, true) => Gripper(Gripper::CLOSE),
            (true, true, true) => Gripper(Gripper::CLOSE | Gripper::CLOSED),
            (true, false, false) => Gripper(0),
            (true, true, false) => Gripper(Gripper::OPEN),
        };
        let answer = g.gripper(state);
        if answer == Some(close) && told_at.is_none() && n + 1 >= g.path {
            told_at = Some(n);
        }
        out.push((cmd[0], answer));
    }
    (out, Sample::Ready)
}

#[test]
fn the_gripper_is_told_at_the_path_end_and_the_move_ends_once_it_is_there() {
    let mut g = GripAtEnd::new(path(100), true, 0.05, 0.0004);
    let (out, end) = run(&mut g, Some(125));
    assert_eq!(g.samples(), Some(100 + 250 + 10), "twice the travel and ten periods");
    assert_eq!(end, Sample::Done);
    // The path's own answers until its last sample, told in that one.
    assert!(out[..99].iter().all(|&(_, a)| a == Some(false)), "the path's own gripper");
    assert_eq!(out[99], (99.0, Some(true)));
    // Held at the path's end until the read that finds it closed; done at the next sample.
    assert!(out[100..].iter().all(|&(c, a)| c == 99.0 && a == Some(true)));
    assert_eq!(out.len(), 99 + 125 + 1, "told at 99, there at 224, done at 225");
    assert_eq!(g.failure(), None);
    assert_eq!(g.name(), "test");
}

#[test]
fn a_gripper_that_is_never_there_fails_the_move_after_its_wait() {
    let mut g = GripAtEnd::new(path(10), false, 0.01, 0.001);
    let (out, end) = run(&mut g, None);
    assert_eq!(end, Sample::Failed);
    assert_eq!(out.len(), 10 + 30, "the path, then 2 × 10 ms + 10 periods at 1 ms");
    let why = g.failure().unwrap();
    assert!(why.starts_with("the gripper did not open within 0.030 s"), "{why}");
    // One that is there on the last sample of the wait is in time; one sample later is not.
    let mut g = GripAtEnd::new(path(10), false, 0.01, 0.001);
    assert_eq!(run(&mut g, Some(30)).1, Sample::Done);
    let mut g = GripAtEnd::new(path(10), false, 0.01, 0.001);
    assert_eq!(run(&mut g, Some(31)).1, Sample::Failed);
}

#[test]
fn no_gripper_wired_fails_at_the_path_end() {
    let mut g = GripAtEnd::new(path(10), true, 0.05, 0.0004);
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    for n in 0..10 {
        assert_eq!(g.sample(n, &mut cmd), Sample::Ready);
        g.gripper(Gripper(Gripper::ABSENT));
    }
    assert_eq!(g.sample(10, &mut cmd), Sample::Failed);
    assert!(g.failure().unwrap().contains("no gripper is wired"), "{:?}", g.failure());
}

/// What the wrapped path says of itself, the wrapper says: its bounds, end velocity, progress,
/// first command and lead-in, and it sees what the loop observes.
#[test]
fn the_path_is_the_wrapped_generators() {
    let mut g = GripAtEnd::new(path(10), true, 0.05, 0.0004);
    assert_eq!(g.first_command().unwrap(), Some([2.0; MAX_MOTORS]));
    g.observe(&[40.0, 0.0, 0.0, 0.0], &[MotorFlags::default(); MAX_MOTORS]);
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    assert_eq!(g.samples(), Some(40 + 250 + 10), "the observed path's length");
    assert_eq!(g.path_bounds(), Some([(-3.0, 40.0); MAX_MOTORS]));
    assert_eq!(g.end_velocity(), Some([0.5, 0.25, 0.0, 0.0]));
    assert_eq!((g.progress(), g.lead_in()), (7, 12));
}

/// `move --grip on|off` alone: one sample, where the robot is, at rest.
#[test]
fn here_is_one_sample_where_the_robot_is() {
    let mut h = Here::default();
    let at = [100.0, -200.0, 300.0, 0.0];
    h.start(&at).unwrap();
    assert_eq!((h.name(), h.samples()), ("move", Some(1)));
    assert_eq!(
        h.path_bounds(),
        Some([(100.0, 100.0), (-200.0, -200.0), (300.0, 300.0), (0.0, 0.0)])
    );
    assert_eq!(h.end_velocity(), Some([0.0; MAX_MOTORS]));
    let mut cmd = [f64::NAN; MAX_MOTORS];
    assert_eq!(h.sample(0, &mut cmd), Sample::Ready);
    assert_eq!(cmd, at);
    let mut after = [f64::NAN; MAX_MOTORS];
    assert_eq!(h.sample(1, &mut after), Sample::Done);
    assert!(after[0].is_nan(), "nothing written after the end");
}

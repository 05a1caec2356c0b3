//! Unit tests of homing: an ideal robot (actual = command), its switches where the test
//! says, and switches injected in every phase.

use super::*;

fn settings() -> HomingSettings {
    HomingSettings {
        velocity_counts_per_s: 2_500.0,
        creep_counts_per_s: 250.0,
        clear_within_counts: 10.0,
        max_travel_counts: 1_000.0,
        settle_s: 0.004,
    }
}

fn safety(offset: f64) -> [MotorSafety; MAX_MOTORS] {
    [MotorSafety { home_offset_counts: offset, top_direction: -1.0, ..MotorSafety::default() };
        MAX_MOTORS]
}

/// Drives the homing against an ideal robot (actual = command) whose top switch is active
/// at or below `switch`, until it ends; the commands of motor 1.
fn drive(h: &mut Homing, switch: f64, stuck: bool) -> (Sample, Vec<f64>) {
    let mut act = [0.0; MAX_MOTORS];
    let mut cmd = [0.0; MAX_MOTORS];
    h.start(&act).unwrap();
    let mut seen = Vec::new();
    let mut tripped = false;
    for n in 0..100_000 {
        let mut flags = [MotorFlags::default(); MAX_MOTORS];
        tripped |= act[0] <= switch;
        if act[0] <= switch || (stuck && tripped) {
            flags[0] = MotorFlags(MotorFlags::TOP);
        }
        h.observe(&act, &flags);
        match h.sample(n, &mut cmd) {
            Sample::Ready => seen.push(cmd[0]),
            other => return (other, seen),
        }
        act = cmd;
    }
    panic!("homing did not end");
}

#[test]
fn finds_the_switch_backs_off_and_goes_to_the_offset() {
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let (end, cmds) = drive(&mut h, -200.0, false);
    assert_eq!(end, Sample::Done);
    let r = h.reports()[0];
    assert_eq!(r.switch_found_counts.unwrap(), -200.0, "1 count per sample at 2500 counts/s");
    assert!(
        r.switch_cleared_counts.unwrap() > -200.0 && r.switch_cleared_counts.unwrap() < -199.0,
        "{r:?}"
    );
    assert_eq!(r.home_counts.unwrap(), r.switch_cleared_counts.unwrap() + 300.0);
    assert!((r.ended_counts.unwrap() - r.home_counts.unwrap()).abs() < 1e-9, "{r:?}");
    assert_eq!(h.report().homed_frame.unwrap()[0], r.home_counts.unwrap());
    assert!(!r.started_on_switch);
    assert!(cmds.iter().all(|&c| c >= -200.0), "never past the switch");
}

#[test]
fn starting_deep_on_the_switch_leaves_it_and_comes_back_to_its_edge() {
    let mut h = Homing::new(1, 0.0004, settings(), safety(50.0));
    // The switch is active at and below +40: the robot starts 40 counts into it.
    let (end, _) = drive(&mut h, 40.0, false);
    assert_eq!(end, Sample::Done);
    let r = h.reports()[0];
    assert!(r.started_on_switch);
    assert_eq!(r.switch_found_counts.unwrap(), 40.0, "found again at its edge");
}

#[test]
fn a_stuck_switch_fails_within_ten_counts() {
    let mut h = Homing::new(1, 0.0004, settings(), safety(50.0));
    let (end, cmds) = drive(&mut h, -100.0, true);
    assert_eq!(end, Sample::Failed);
    assert_eq!(h.failure_kind(), FaultKind::HomingFailed);
    let msg = h.failure().unwrap();
    assert!(msg.starts_with("homing motor 1: its top switch was still active 10."), "{msg}");
    assert!(cmds.last().unwrap() - -100.0 <= 10.0 + 0.1);
}

#[test]
fn no_switch_within_the_travel_fails() {
    let mut h = Homing::new(1, 0.0004, settings(), safety(50.0));
    let (end, _) = drive(&mut h, -5_000.0, false);
    assert_eq!(end, Sample::Failed);
    assert!(
        h.failure().unwrap().starts_with("homing motor 1: no top switch within 1001 counts"),
        "{:?}",
        h.failure()
    );
}

/// Issue 9, item 3: while motor 1 homes, a switch of motor 2 (not yet homed) that trips
/// ends the homing naming motor and side; one that motor 2 rested on from the start is
/// its own homing's business, until it clears.
#[test]
fn another_motors_switch_ends_homing() {
    let run = |start_on_top: bool, trip_bottom_at: Option<u64>| -> (Sample, Option<String>) {
        let mut h = Homing::new(2, 0.0004, settings(), safety(300.0));
        let mut act = [0.0; MAX_MOTORS];
        let mut cmd = [0.0; MAX_MOTORS];
        h.start(&act).unwrap();
        for n in 0..100_000 {
            let mut flags = [MotorFlags::default(); MAX_MOTORS];
            if act[0] <= -200.0 {
                flags[0] = MotorFlags(MotorFlags::TOP);
            }
            if start_on_top && h.motor == 0 {
                flags[1] = MotorFlags(MotorFlags::TOP);
            }
            if trip_bottom_at.is_some_and(|at| n >= at) {
                flags[1] = MotorFlags(flags[1].0 | MotorFlags::BOTTOM);
            }
            h.observe(&act, &flags);
            match h.sample(n, &mut cmd) {
                Sample::Ready => act = cmd,
                end => return (end, h.failure()),
            }
            if h.motor == 1 {
                return (Sample::Ready, None); // motor 1 is home
            }
        }
        panic!("homing did not end");
    };
    let (end, why) = run(false, Some(50));
    assert_eq!(end, Sample::Failed);
    assert_eq!(why.unwrap(), "homing motor 1: motor 2's bottom limit switch tripped");
    assert_eq!(run(true, None), (Sample::Ready, None), "resting on its top switch");
    let (end, why) = run(true, Some(100));
    assert_eq!(end, Sample::Failed);
    assert_eq!(why.unwrap(), "homing motor 1: motor 2's bottom limit switch tripped");
}

/// Issue 9, item 3: a motor homed already is watched too — its switch tripping while a
/// later motor homes (a cable caught, the arm pushed) ends the homing.
#[test]
fn a_homed_motors_switch_ends_the_homing_of_the_next() {
    let mut h = Homing::new(2, 0.0004, settings(), safety(300.0));
    let mut act = [0.0; MAX_MOTORS];
    let mut cmd = [0.0; MAX_MOTORS];
    h.start(&act).unwrap();
    for n in 0..200_000 {
        let mut flags = [MotorFlags::default(); MAX_MOTORS];
        for (f, &a) in flags.iter_mut().zip(&act).take(2) {
            if a <= -200.0 {
                *f = MotorFlags(MotorFlags::TOP); // each motor's top switch
            }
        }
        if h.motor == 1 && n % 1_000 == 999 {
            flags[0] = MotorFlags(MotorFlags::TOP); // motor 1, home, bumped into its switch
        }
        h.observe(&act, &flags);
        match h.sample(n, &mut cmd) {
            Sample::Ready => act = cmd,
            end => {
                assert_eq!(end, Sample::Failed);
                assert_eq!(
                    h.failure().unwrap(),
                    "homing motor 2: motor 1's top limit switch tripped"
                );
                return;
            }
        }
    }
    panic!("motor 1's switch went unnoticed while motor 2 homed");
}
/// Issue 32: a robot of three motors away from 0, exact in binary: 4096 counts/s at a
/// period of 1/2048 s (two counts a sample), creep 256 counts/s (1/8 count a sample).
/// Motors 1 and 2 find their top switch below them, motor 3 above; motor 2 starts on it.
struct Robot {
    start: [f64; MAX_MOTORS],
    top: [f64; MAX_MOTORS],
    dir: [f64; MAX_MOTORS],
}

/// One sample of a [`Robot`] run: the progress word before it and after it, the commands.
#[derive(Debug, Clone, Copy)]
struct Step {
    before: u32,
    after: u32,
    cmd: [f64; MAX_MOTORS],
}

const PERIOD: f64 = 1.0 / 2048.0;

fn exact() -> HomingSettings {
    HomingSettings {
        velocity_counts_per_s: 4096.0,
        creep_counts_per_s: 256.0,
        clear_within_counts: 10.0,
        max_travel_counts: 1_000.0,
        settle_s: 4.0 * PERIOD,
    }
}

impl Robot {
    fn three() -> Robot {
        Robot {
            start: [5_000.0, -3_000.0, 12_346.0, 0.0],
            top: [4_800.0, -2_960.0, 12_500.0, 0.0],
            dir: [-1.0, -1.0, 1.0, -1.0],
        }
    }

    fn homing(&self, offset: f64) -> Homing {
        let mut motors = [MotorSafety::default(); MAX_MOTORS];
        for (m, s) in motors.iter_mut().enumerate() {
            *s = MotorSafety {
                home_offset_counts: offset,
                top_direction: self.dir[m],
                ..MotorSafety::default()
            };
        }
        Homing::new(3, PERIOD, exact(), motors)
    }

    /// Each motor's top switch is active at and past `top` (in its direction), its
    /// bottom switch never; `inject` may add switches to a sample's flags.
    fn run(
        &self,
        h: &mut Homing,
        mut inject: impl FnMut(u32, &mut [MotorFlags; MAX_MOTORS]),
    ) -> (Sample, Vec<Step>) {
        let mut act = self.start;
        let mut cmd = [f64::NAN; MAX_MOTORS];
        h.start(&act).unwrap();
        let mut steps = Vec::new();
        for n in 0..200_000 {
            let mut flags = [MotorFlags::default(); MAX_MOTORS];
            for m in 0..3 {
                if (act[m] - self.top[m]) * self.dir[m] >= 0.0 {
                    flags[m] = MotorFlags(MotorFlags::TOP);
                }
            }
            // The phase this sample runs in (progress() says 0 until feedback arrives).
            let before = h.phase_code();
            inject(before, &mut flags);
            h.observe(&act, &flags);
            let end = h.sample(n, &mut cmd);
            if end != Sample::Ready {
                return (end, steps);
            }
            steps.push(Step { before, after: h.progress(), cmd });
            act = cmd;
        }
        panic!("homing did not end");
    }
}

/// Issue 32: from anywhere, each motor in turn leaves its switch if it starts on it,
/// approaches it at the homing velocity, creeps off it, goes to its offset and settles
/// for the settle time; the others hold where they are (the homed ones at home); every
/// command moves a motor by exactly what its phase allows.
#[test]
fn homes_three_motors_from_anywhere_at_each_phases_speed() {
    let robot = Robot::three();
    let mut h = robot.homing(300.0);
    assert_eq!(h.samples(), None, "homing ends when every motor is home");
    assert_eq!(h.progress(), 0, "nothing seen yet");
    assert_eq!(h.name(), "home");
    let (end, steps) = robot.run(&mut h, |_, _| {});
    assert_eq!(end, Sample::Done, "{:?}", h.failure());
    assert_eq!(h.progress(), 0, "done");
    let reports = h.reports();
    assert_eq!(reports.len(), 3);
    let mut home = [0.0; MAX_MOTORS];
    for (m, r) in reports.iter().enumerate() {
        let (dir, top) = (robot.dir[m], robot.top[m]);
        assert_eq!(r.motor, m + 1);
        assert!(r.home, "{r:?}");
        assert_eq!(r.started_on_switch, m == 1, "{r:?}");
        assert_eq!(r.switch_found_counts.unwrap(), top, "two counts a sample from an even count");
        // Cleared one creep step (1/8 count) back from the trip.
        assert_eq!(r.switch_cleared_counts.unwrap(), top - dir * 0.125, "{r:?}");
        assert_eq!(r.home_counts.unwrap(), r.switch_cleared_counts.unwrap() - dir * 300.0, "{r:?}");
        assert_eq!(r.ended_counts.unwrap(), r.home_counts.unwrap(), "{r:?}");
        home[m] = r.home_counts.unwrap();
    }
    assert_eq!(h.report().homed_frame, Some(home));

    let phase = |p: u32| (p >> 8, p & 0xff);
    let mut settling = [0; 3];
    let mut last = robot.start;
    for s in &steps {
        let (motor, ph) = phase(s.before);
        let m = motor as usize - 1;
        for k in (0..3).filter(|&k| k != m) {
            let held = if k < m { home[k] } else { robot.start[k] };
            assert_eq!(s.cmd[k], held, "motor {} while motor {motor} homes", k + 1);
        }
        let moved = s.cmd[m] - last[m];
        let dir = robot.dir[m];
        if s.after == s.before {
            match ph {
                1 => assert_eq!(moved, -dir * 2.0, "leaving the switch: the velocity"),
                2 => assert_eq!(moved, dir * 2.0, "approaching: the velocity"),
                3 => assert_eq!(moved, -dir * 0.125, "backing off: the creep"),
                4 => assert_eq!(moved, -dir * 2.0, "to home: the velocity"),
                5 => assert_eq!(moved, 0.0, "settling"),
                _ => unreachable!(),
            }
        }
        if phase(s.after) == (motor, 5) {
            settling[m] += 1;
        }
        last = s.cmd;
    }
    assert_eq!(settling, [5; 3], "settle_s is 4 periods, then one more sample to move on");

    // What the console says, in order, for motor 2 (which started on its switch).
    let mut said: Vec<String> = steps
        .iter()
        .filter(|s| phase(s.after).0 == 2)
        .filter_map(|s| describe_progress(s.after))
        .collect();
    said.dedup();
    assert_eq!(
        said,
        [
            "homing motor 2: approaching the top switch",
            "homing motor 2: leaving the top switch it started on",
            "homing motor 2: approaching the top switch",
            "homing motor 2: backing off the top switch",
            "homing motor 2: moving to home",
            "homing motor 2: settling at home",
        ]
    );
    assert_eq!(describe_progress(0), None);
    assert_eq!(describe_progress(2), None, "no motor 0");
    assert_eq!(describe_progress(1 << 8 | 6), None);
}

/// Issue 32: during homing the switches are the only limit protection. In every phase of
/// every motor's homing, any switch that trips ends it naming the switch — but the top
/// switch of the motor homing while it leaves, approaches or backs off it, its bottom
/// switch while it approaches (moving away from it), and a switch a motor not yet homed
/// has rested on since the start.
#[test]
fn every_unexpected_switch_in_every_phase_ends_the_homing() {
    let robot = Robot::three();
    let mut cases = 0;
    for m in 0..3u32 {
        for ph in 1..=5u32 {
            if ph == 1 && m != 1 {
                continue; // only motor 2 starts on its switch
            }
            for k in 0..3usize {
                for top in [true, false] {
                    let mut h = robot.homing(300.0);
                    let at = (m + 1) << 8 | ph;
                    // In the phase's second sample (the first feedback of all is what
                    // the motors rest on).
                    let mut seen = 0;
                    let bit = if top { MotorFlags::TOP } else { MotorFlags::BOTTOM };
                    let (end, steps) = robot.run(&mut h, |before, flags| {
                        seen += u32::from(before == at);
                        if before == at && seen == 2 {
                            flags[k] = MotorFlags(flags[k].0 | bit);
                        }
                    });
                    assert!(seen >= 2, "motor {} not two samples in phase {ph}", m + 1);
                    let mine = k == m as usize;
                    let resting = k == 1 && top && m == 0; // motor 2 rests on its top
                    let allowed = mine && if top { ph <= 3 } else { ph == 2 } || resting;
                    let case = format!(
                        "motor {}'s {} switch while motor {} is in phase {ph}",
                        k + 1,
                        if top { "top" } else { "bottom" },
                        m + 1
                    );
                    let refused =
                        Some(HomingFailure::UnexpectedSwitch { motor: k, top, homing: m as usize });
                    if allowed {
                        assert!(steps.iter().any(|s| s.before == at), "{case}: {:?}", h.failure());
                        assert_ne!(h.failure, refused, "{case}");
                    } else {
                        assert_eq!((end, h.failure), (Sample::Failed, refused), "{case}");
                        // In the very sample that saw it.
                        assert_eq!(steps.last().map(|s| s.after), Some(at), "{case}");
                    }
                    cases += 1;
                }
            }
        }
    }
    assert_eq!(cases, (1 + 4 * 3) * 6);
}

/// Issue 32: a motor that starts on its bottom switch may move away from it, but the
/// switch must clear: still active when its top switch trips (a stuck switch, a short),
/// it ends the homing.
#[test]
fn a_bottom_switch_that_never_clears_ends_the_homing_at_the_top() {
    let robot = Robot::three();
    let mut h = robot.homing(300.0);
    let (end, steps) = robot.run(&mut h, |_, flags| {
        flags[0] = MotorFlags(flags[0].0 | MotorFlags::BOTTOM);
    });
    assert_eq!(end, Sample::Failed);
    assert_eq!(
        h.failure,
        Some(HomingFailure::UnexpectedSwitch { motor: 0, top: false, homing: 0 })
    );
    assert_eq!(steps.last().unwrap().after, 1 << 8 | 3, "at the trip, backing off");
}

/// Issue 32: the runaway guards count travel from where the motor's homing began, not
/// from 0: no switch within `max_travel_counts`, a switch it started on that never
/// clears within it, a switch that does not clear within `clear_within_counts` of its
/// trip — each to the count.
#[test]
fn the_runaway_guards_hold_from_any_origin() {
    let far = Robot { top: [-1e9, 1e9, 1e9, 0.0], ..Robot::three() };
    // Motor 1 at 5000 finds nothing: it stops one step past the travel.
    let mut h = far.homing(300.0);
    let (end, steps) = far.run(&mut h, |_, _| {});
    assert_eq!(end, Sample::Failed);
    assert_eq!(h.failure, Some(HomingFailure::NoSwitch { motor: 0, travel: 1002.0 }));
    assert_eq!(h.reports().iter().map(|r| (r.motor, r.home)).collect::<Vec<_>>(), [(1, false)]);
    assert_eq!(steps.last().unwrap().cmd[0], 5_000.0 - 1_000.0);
    // Motor 3 (upwards), from 12 346, after motors 1 and 2 homed.
    let far3 = Robot { top: [4_800.0, -2_960.0, 1e9, 0.0], ..Robot::three() };
    let mut h = far3.homing(300.0);
    assert_eq!(far3.run(&mut h, |_, _| {}).0, Sample::Failed);
    assert_eq!(h.failure, Some(HomingFailure::NoSwitch { motor: 2, travel: 1002.0 }));
    // The report says motors 1 and 2 got home and motor 3 did not.
    let homes: Vec<(usize, bool)> = h.reports().iter().map(|r| (r.motor, r.home)).collect();
    assert_eq!(homes, [(1, true), (2, true), (3, false)]);
    // Motor 2 starts on a switch that is active everywhere: it leaves for 1000 counts.
    let stuck = Robot { top: [4_800.0, 1e9, 12_500.0, 0.0], ..Robot::three() };
    let mut h = stuck.homing(300.0);
    let (end, steps) = stuck.run(&mut h, |_, _| {});
    assert_eq!(end, Sample::Failed);
    assert_eq!(h.failure, Some(HomingFailure::NotCleared { motor: 1, backed_off: 1002.0 }));
    assert_eq!(steps.last().unwrap().cmd[1], -3_000.0 + 1_000.0);
    // Motor 1's switch sticks once tripped: refused 10 counts back, 80 creep steps.
    let robot = Robot::three();
    let mut h = robot.homing(300.0);
    let mut tripped = false;
    let (end, steps) = robot.run(&mut h, |_, flags| {
        tripped |= flags[0].top();
        if tripped {
            flags[0] = MotorFlags(MotorFlags::TOP);
        }
    });
    assert_eq!(end, Sample::Failed);
    assert_eq!(h.failure, Some(HomingFailure::NotCleared { motor: 0, backed_off: 10.0 }));
    assert_eq!(steps.last().unwrap().cmd[0], 4_800.0 + 10.0);
}

/// Drives one motor's homing against a plant that follows its command but coasts through a
/// host stall: at sample `stall_at` the next `missed` periods go by without a sample, the
/// plant moving on meanwhile at the velocity it had. Its top switch is active at or below
/// `switch` (and for good once tripped, if `stuck`). Returns how it ended, the commands and
/// the sample indices.
fn drive_through_a_stall(
    h: &mut Homing,
    switch: f64,
    stuck: bool,
    stall: (u64, u64),
) -> (Sample, Vec<(u64, f64)>) {
    drive_through_stalls(h, switch, stuck, &[stall], 1.0)
}

/// [`drive_through_a_stall`] with several stalls (sample, periods missed), and a plant that
/// goes `lag` of the way to its command each period (1: all the way).
fn drive_through_stalls(
    h: &mut Homing,
    switch: f64,
    stuck: bool,
    stalls: &[(u64, u64)],
    lag: f64,
) -> (Sample, Vec<(u64, f64)>) {
    let mut act = [0.0; MAX_MOTORS];
    let mut cmd = [0.0; MAX_MOTORS];
    h.start(&act).unwrap();
    let (mut seen, mut tripped, mut n) = (Vec::new(), false, 0);
    while n < 100_000 {
        tripped |= act[0] <= switch;
        let mut flags = [MotorFlags::default(); MAX_MOTORS];
        if act[0] <= switch || (stuck && tripped) {
            flags[0] = MotorFlags(MotorFlags::TOP);
        }
        h.observe(&act, &flags);
        match h.sample(n, &mut cmd) {
            Sample::Ready => seen.push((n, cmd[0])),
            other => return (other, seen),
        }
        let velocity = lag * (cmd[0] - act[0]);
        act[0] += velocity;
        n += 1;
        if let Some(&(_, missed)) = stalls.iter().find(|(at, _)| *at == n) {
            act[0] += velocity * missed as f64; // coasting on the last output
            n += missed;
        }
    }
    panic!("homing did not end");
}

/// Issue 28, item 6: a host stall while homing. The command keeps pace with time (a sample
/// after missed periods moves it as far as those periods would have: the plant coasted on
/// meanwhile, and a command left behind is a following error), the settle time is time, and
/// a switch passed during the stall is judged from where it was last seen open, not from
/// where the stall left the motor (before: "its top switch was still active 10 counts back
/// from where it tripped" after a 50 ms stall at the trip).
#[test]
fn homing_keeps_pace_through_a_host_stall() {
    // 1 count a period (2500 counts/s at 400 µs); the switch at −200; 10 000 counts/s creep.
    let settings = || HomingSettings { creep_counts_per_s: 2_500.0, ..settings() };
    // A 125-period (50 ms) stall on the way to the switch: the next command is 126 on.
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let (end, cmds) = drive_through_a_stall(&mut h, -200.0, false, (50, 125));
    assert_eq!(end, Sample::Done);
    let at = cmds.iter().position(|&(n, _)| n > 50).unwrap();
    assert_eq!((cmds[at - 1], cmds[at]), ((49, -50.0), (175, -176.0)));
    // The same stall just before the trip: the motor coasts 100 counts into the switch
    // (found at −250), which is open again at −199 on the way back; home is 300 from there.
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let (end, _) = drive_through_a_stall(&mut h, -200.0, false, (150, 100));
    assert_eq!(end, Sample::Done, "{:?}", h.failure());
    let r = h.reports()[0];
    assert_eq!(r.switch_found_counts.unwrap(), -250.0);
    assert_eq!(r.switch_cleared_counts.unwrap(), -199.0, "the first open position");
    assert_eq!(r.home_counts.unwrap(), r.switch_cleared_counts.unwrap() + 300.0);
    // A switch that sticks is still refused within 10 counts of where it can have tripped
    // (a period after it was last seen open, at −149: −150).
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let (end, cmds) = drive_through_a_stall(&mut h, -200.0, true, (150, 100));
    assert_eq!(end, Sample::Failed);
    assert_eq!(h.failure, Some(HomingFailure::NotCleared { motor: 0, backed_off: 10.0 }));
    assert_eq!(cmds.last().unwrap().1, -150.0 + 10.0);
    // Settling is time: a stall longer than the settle time (10 periods) ends it.
    let settled = |stall: (u64, u64)| {
        let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
        let (end, cmds) = drive_through_a_stall(&mut h, -200.0, false, stall);
        assert_eq!(end, Sample::Done);
        cmds.len()
    };
    let plain = settled((0, 0));
    // Stalled with 10 of the settle's 11 samples to go (10 periods, and the one that ends
    // it): the sample after the stall finds the time gone, the next one ends it.
    let stall_at = plain - 10;
    assert_eq!(settled((stall_at as u64, 50)), stall_at + 2);
}

/// Issue 28, item 6: a stall while backing off and one on the way to the offset move the
/// command on by the periods that went by, at the creep and at the homing velocity.
#[test]
fn backing_off_and_going_home_keep_pace_through_stalls() {
    let settings = || HomingSettings { creep_counts_per_s: 2_500.0, ..settings() };
    // A stall before the trip (the motor coasts to −250), one while backing off (at 260),
    // one on the way home (at 330: the switch clears at −199, home is 101).
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let stalls = [(150, 100), (260, 10), (330, 20)];
    let (end, cmds) = drive_through_stalls(&mut h, -200.0, false, &stalls, 1.0);
    assert_eq!(end, Sample::Done, "{:?}", h.failure());
    let around = |at: u64| {
        let i = cmds.iter().position(|&(n, _)| n >= at).unwrap();
        (cmds[i - 1], cmds[i])
    };
    let ((before, b), (after, a)) = around(260);
    assert_eq!((after - before, a - b), (11, 11.0), "backing off: 11 periods of creep");
    let ((before, b), (after, a)) = around(330);
    assert_eq!((after - before, a - b), (21, 21.0), "going home: 21 periods at the velocity");
}

/// Issue 28, item 6: without a stall, a motor that lags its command (here while it speeds
/// up, going half-way to its command each period) is judged from where it was seen on the
/// switch — nearer than a period's travel after where it was last seen open.
#[test]
fn a_lagging_motor_is_judged_from_where_it_tripped() {
    // 2 counts a period: commands −2, −4, …; the motor at 0, −1, −2.5: found at −2.5, last
    // seen open at −1, a period after that is −3.
    let fast = HomingSettings { velocity_counts_per_s: 5_000.0, ..settings() };
    let mut h = Homing::new(1, 0.0004, fast, safety(300.0));
    let (end, _) = drive_through_stalls(&mut h, -2.0, false, &[], 0.5);
    assert_eq!(end, Sample::Done, "{:?}", h.failure());
    let found = h.reports()[0].switch_found_counts.unwrap();
    assert_eq!(found, -2.5);
    assert_eq!(h.trip, found);
    // Passed during a stall: a period after where it was last seen open.
    let mut h = Homing::new(1, 0.0004, settings(), safety(300.0));
    let (end, _) = drive_through_stalls(&mut h, -200.0, false, &[(150, 100)], 1.0);
    assert_eq!(end, Sample::Done, "{:?}", h.failure());
    assert_eq!((h.reports()[0].switch_found_counts.unwrap(), h.trip), (-250.0, -150.0));
}

/// A host stall while backing off that carries the motor off the switch and past its command
/// (it runs on its last output): the move home starts where the motor is, never pulling it
/// back toward the switch it just cleared (before: the loop pulled it back onto the switch,
/// and homing failed on a switch that tripped while going home).
#[test]
fn a_stall_that_carries_the_motor_off_the_switch_does_not_pull_it_back() {
    let switch = -200.0;
    let flags_at = |x: f64| {
        let mut f = [MotorFlags::default(); MAX_MOTORS];
        if x <= switch {
            f[0] = MotorFlags(MotorFlags::TOP);
        }
        f
    };
    // Into the back-off, then a 50-period stall that leaves the motor at `after` (off the
    // switch): the command before and after the stall.
    let after_a_stall = |after: f64| {
        let settings = HomingSettings { creep_counts_per_s: 2_500.0, ..settings() };
        let mut h = Homing::new(1, 0.0004, settings, safety(300.0));
        let (mut act, mut cmd, mut n) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS], 0);
        h.start(&act).unwrap();
        while h.phase != Phase::Backoff {
            h.observe(&act, &flags_at(act[0]));
            assert_eq!(h.sample(n, &mut cmd), Sample::Ready);
            act[0] = cmd[0];
            n += 1;
        }
        // Ten periods of back-off with the motor still on the switch: the command leads.
        for _ in 0..10 {
            h.observe(&act, &flags_at(act[0]));
            assert_eq!(h.sample(n, &mut cmd), Sample::Ready);
            n += 1;
        }
        let before = cmd[0];
        act[0] = after;
        h.observe(&act, &flags_at(act[0]));
        assert_eq!(h.sample(n + 50, &mut cmd), Sample::Ready);
        assert_eq!(h.phase, Phase::ToOffset);
        (before, cmd[0])
    };
    // The motor ran 40 counts off the switch, past its command: the move home starts there.
    let (_, cmd) = after_a_stall(switch + 40.0);
    assert_eq!(cmd, switch + 40.0, "the move home starts at the motor, not behind it");
    // The motor just cleared, still behind its command: the command is not pulled back.
    let (before, cmd) = after_a_stall(switch + 1.0);
    assert!(before > switch + 1.0, "the command led the motor: {before}");
    assert_eq!(cmd, before, "the command stays ahead of the motor");
}

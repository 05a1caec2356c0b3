//! The servo loop with every registered generator and law against the hwserver's core: the
//! servo cycle allocates nothing, does no I/O and never blocks; the fault handler disables the motors; the loop runs over the real
//! iceoryx2 link.

mod util;

use qmarc_controller::fault::HostStall;
use qmarc_controller::link::{HwLink, IoxLink, LinkTimeouts};
use qmarc_controller::plan::{MoveLimits, MovePlan};
use qmarc_controller::servo::{CycleEnd, Phase, Servo};
use qmarc_hwserver::server::{AnswerEnd, AnswerOptions, answer_requests};
use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
use qmarc_plugins::registry::{GENERATORS, LAWS};
use qmarc_proto::state::FaultKind;

use qmarc_proto::{HwMsg, MAX_MOTORS, MsgType};
use qmarc_timer::{ManualTicker, MockClock, Ticker};
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use util::{
    CountingAllocator, ThreadCounters, allocations, knots, lockstep, plan, settings, sim_core,
    warmed_up,
};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Every generator the loop runs: the registry's, and a path behind its approach (`run
/// --approach`; slow, so that the cycles counted are all the way there, a command queue the
/// path's own proof does not cover).
fn all_generators() -> Vec<qmarc_plugins::registry::GeneratorEntry> {
    let approach = qmarc_plugins::registry::GeneratorEntry {
        name: "approach",
        description: "the way to the X-Z path's start, then the path",
        kind: qmarc_plugins::registry::GeneratorKind::KnotPath,
        build: |s| {
            let mut s = s.clone();
            s.trajectory.knots = Some(knots("xz-pick-place-spline.txt"));
            s.trajectory.approach_speed = 0.02;
            let path = Box::new(qmarc_plugins::spline::CubicSpline::from_settings(&s)?);
            Ok(Box::new(qmarc_plugins::moveto::Approach::from_settings(path, &s)))
        },
    };
    GENERATORS.iter().copied().chain([approach]).collect()
}

/// Every law the loop runs: the registry's, and the check's open loop (which the controller
/// process picks for `check`, whatever `general.law` says).
fn all_laws() -> Vec<qmarc_plugins::registry::LawEntry> {
    let open_loop = qmarc_plugins::registry::LawEntry {
        name: "open-loop",
        description: "the check's",
        build: |s| Box::new(qmarc_plugins::check::OpenLoop::from_settings(s)),
    };
    LAWS.iter().copied().chain([open_loop]).collect()
}

/// The settings `g` runs with in the proofs: an example path (the knot readers' threads are
/// not the loop's), and a jog, a check, a move and the pick cycle that last longer than the
/// cycles counted.
fn example_settings(g: &qmarc_plugins::registry::GeneratorEntry) -> qmarc_config::Settings {
    let mut s = settings();
    let example = if g.name == "pvt" { "pvt-3motors.txt" } else { "sine-3motors.txt" };
    s.trajectory.knots = Some(knots(example));
    s.jog.counts = 20_000;
    s.check.rest_s = 5.0;
    s.set_move_xyz([80.0, -40.0, -660.0]).unwrap();
    s.set_move_speed(0.01).unwrap();
    s.motion.linear = g.name == "linear";
    // The pick cycle from where the simulated robot stands (the work centre is 0 counts on
    // every arm), slow enough to outlast the cycles counted.
    s.pick.at_mm = [0.0, 0.0, -600.0];
    s.pick.speed = 0.25;
    s.pick.dwell_s = 0.5;
    s
}

/// The step move with the PID feed-forward law, timed on a mock clock.
fn step_servo(s: &qmarc_config::Settings) -> Servo {
    Servo::new(
        plan(3),
        (GENERATORS[0].build)(s).unwrap(),
        (LAWS[0].build)(s),
        Box::new(MockClock::new(0)),
    )
}

#[test]
fn servo_cycle_allocates_nothing_with_every_generator_and_law() {
    for g in all_generators() {
        let s = example_settings(&g);
        for l in all_laws() {
            let generator = (g.build)(&s).unwrap();
            // With live telemetry, a sample every cycle into a ring nobody empties.
            let (telemetry, _ring) = qmarc_controller::telemetry::ring(1);
            let mut servo =
                Servo::new(plan(3), generator, (l.build)(&s), Box::new(MockClock::new(0)))
                    .with_telemetry(Some(telemetry));
            let mut link = sim_core(lockstep());
            let mut ticker = ManualTicker::new(400_000);
            let (mut moving, reading) = warmed_up(&mut servo, &mut link, &mut ticker);
            let kernel_before = ThreadCounters::now();
            let before = allocations();
            for k in 0..3_000 {
                if k == 1_500 {
                    ticker.inject_delay(150_000, 3); // a stall: missed periods on the way
                }
                let tick = ticker.wait().unwrap();
                assert_eq!(moving.cycle(&mut link, &tick), CycleEnd::Continue);
            }
            let during = allocations() - before;
            let kernel = kernel_before.delta(ThreadCounters::now());
            assert_eq!(during, 0, "{} + {}: {during} allocations in 3000 cycles", g.name, l.name);
            // No I/O and no blocking (no lock waited on, no sleep) in the cycle itself.
            assert_eq!(
                kernel, reading,
                "{} + {}: syscalls or blocking in the cycle",
                g.name, l.name
            );
            assert_eq!(servo.timing().missed, 3);
            assert_eq!(servo.gather().rows().len(), 3_010);
        }
    }
}

/// The online planner refuses what it cannot plan — a state that is not finite, a limit that
/// is not positive — before Ruckig sees it, so even a refused plan allocates nothing (Ruckig's
/// own refusal formats a message).
#[test]
fn a_refused_online_plan_allocates_nothing() {
    use qmarc_plugins::motion::MotionLimits;
    use qmarc_plugins::motion::{MotionState, NoProfile, Profile};
    let good = MotionLimits::of(&settings());
    let mut p = Profile::new(3, [0.0; MAX_MOTORS]);
    let mut no_jerk = good;
    no_jerk.jerk[1] = 0.0;
    let mut nan_limit = good;
    nan_limit.velocity[2] = f64::NAN;
    let nan_state = MotionState { v: [0.0, f64::NAN, 0.0, 0.0], ..MotionState::default() };
    let to = [100.0, 200.0, 300.0, 0.0];
    let before = allocations();
    let refused = [
        p.plan(&nan_state, &to, &good),
        p.plan(&MotionState::default(), &to, &no_jerk),
        p.plan(&MotionState::default(), &to, &nan_limit),
        p.plan(&MotionState::default(), &[f64::INFINITY; MAX_MOTORS], &good),
        p.plan_stop(&nan_state, &good),
    ];
    assert_eq!(allocations() - before, 0, "a refused plan allocated");
    assert!(refused.iter().all(|r| *r == Err(NoProfile)), "{refused:?}");
}

#[test]
fn limit_switch_trip_disables_every_motor_in_the_same_cycle() {
    let s = settings();
    let mut params = lockstep();
    // Motor 2 starts 300 counts below its bottom switch; the step drives it through.
    params.start_counts[1] = params.plant.bottom_switch_counts - 300.0;
    let mut link = sim_core(params);
    let mut servo = step_servo(&s);
    let stop = AtomicBool::new(false);
    servo.run(&mut link, &mut ManualTicker::new(400_000), &stop).unwrap();
    let fault = servo.fault().expect("a fault");
    assert_eq!((fault.kind, fault.motor), (FaultKind::LimitSwitch, Some(1)));
    assert!(
        fault.message().starts_with("motor 2 hit its bottom limit switch at cycle"),
        "{}",
        fault.message()
    );
    assert!(!link.any_enabled(), "all motors disabled");
    // The cycle that saw the switch wrote no DAC: the last gathered row is the one before.
    let rows = servo.gather().rows();
    assert_eq!(rows.last().unwrap().cycle + 1, fault.cycle);
}

#[test]
fn a_stop_request_aborts_the_move_and_disables_the_motors() {
    let s = settings();
    let mut link = sim_core(lockstep());
    let mut servo = step_servo(&s);
    let stop = AtomicBool::new(true);
    servo.run(&mut link, &mut ManualTicker::new(400_000), &stop).unwrap();
    assert_eq!(servo.fault().map(|f| f.kind), Some(FaultKind::Aborted));
    assert!(!link.any_enabled());
}

/// The loop over real iceoryx2, the server in another thread of this process. Our code
/// allocates nothing; iceoryx2 0.10 allocates once per loan (an `Rc` per request,
/// eclipse-iceoryx/iceoryx2#101), so exactly one allocation per exchange, two per cycle.
#[test]
fn over_iceoryx2_each_cycle_allocates_only_the_two_request_loans() {
    let ipc = util::IpcDir::new("alloc");
    let location = ipc.location.clone();
    let server_location = location.clone();
    let server = std::thread::spawn(move || {
        let mut core = HwCore::new(Box::new(SimDeltabot::new(lockstep()).unwrap()));
        let opts = AnswerOptions {
            watchdog_ns: 5_000_000_000,
            spin: false,
            lockstep: false,
            shutdown_grace_ns: 1_000_000_000,
        };
        answer_requests(&mut core, &server_location, &opts, &AtomicBool::new(false))
    });
    // Deadlines far beyond any stall: a missed one would allocate (the liveness check).
    let timeouts =
        LinkTimeouts { deadline_ns: 1_000_000_000, give_up_ns: 5_000_000_000, spin_ns: 0 };
    let mut link = IoxLink::connect(&location, timeouts, Duration::from_secs(5), None).unwrap();
    let s = settings();
    let mut servo = step_servo(&s);
    let mut ticker = ManualTicker::new(400_000);
    let mut moving = servo.prepare(&mut link).unwrap();
    moving.set_t0(ticker.start().unwrap());
    for _ in 0..50 {
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let before = allocations();
    let cycles = 1_000;
    for _ in 0..cycles {
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let during = allocations() - before;
    assert_eq!(during, 2 * cycles, "iceoryx2's loans only");
    link.exchange(&HwMsg::request(MsgType::Exit)).unwrap();
    assert_eq!(server.join().unwrap().unwrap(), AnswerEnd::Exit);
    drop(link);
}

/// Name of this test, for running it again in a child process.
const STRICT_TEST: &str = "servo_cycle_makes_no_system_call_under_seccomp_strict_mode";

/// Phases of the strict-mode thread, set by it and by the watching thread.
static STRICT_PHASE: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
static STRICT_FAILED: AtomicBool = AtomicBool::new(false);

fn wait_phase(phase: u32) {
    use std::sync::atomic::Ordering::SeqCst;
    while STRICT_PHASE.load(SeqCst) < phase {
        std::hint::spin_loop();
    }
}

/// The cycle (read, sample, law, write, gather) with the in-process link makes no system
/// call at all. Proof: the cycles run in a thread in seccomp strict mode, where any system
/// call other than read, write, exit and sigreturn kills the process; the thread's read and
/// write counts are compared before and after. It runs in a child process (this test binary
/// again) so that a violation is reported instead of killing the test run.
#[test]
fn servo_cycle_makes_no_system_call_under_seccomp_strict_mode() {
    use std::os::unix::process::ExitStatusExt;
    use std::sync::atomic::Ordering::SeqCst;
    if std::env::var_os("QMARC_STRICT_CHILD").is_none() {
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args([STRICT_TEST, "--exact", "--nocapture", "--test-threads=1"])
            .env("QMARC_STRICT_CHILD", "1")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success(),
            "exit {:?} / signal {:?}\n{stdout}\n{}",
            out.status.code(),
            out.status.signal(),
            String::from_utf8_lossy(&out.stderr)
        );
        assert_eq!(
            stdout.matches("strict mode: 3000 cycles, 0 reads, 0 writes").count(),
            all_generators().len() * all_laws().len(),
            "{stdout}"
        );
        return;
    }
    for g in all_generators() {
        for l in all_laws() {
            let s = example_settings(&g);
            let (telemetry, ring) = qmarc_controller::telemetry::ring(1);
            let mut servo = Servo::new(
                plan(3),
                (g.build)(&s).unwrap(),
                (l.build)(&s),
                Box::new(MockClock::new(0)),
            )
            .with_telemetry(Some(telemetry));
            let mut link = sim_core(lockstep());
            let mut ticker = ManualTicker::new(400_000);
            STRICT_PHASE.store(0, SeqCst);
            let (tid_tx, tid_rx) = std::sync::mpsc::channel();
            let thread = std::thread::spawn(move || {
                // Prepared and warmed up on this thread, before strict mode: the prepared
                // move is its own.
                let mut moving = servo.prepare(&mut link).unwrap();
                moving.set_t0(ticker.start().unwrap());
                for _ in 0..10 {
                    moving.cycle(&mut link, &ticker.wait().unwrap());
                }
                // SAFETY: gettid and prctl have no memory preconditions.
                let tid = unsafe { libc::syscall(libc::SYS_gettid) };
                tid_tx.send(tid).unwrap();
                // SAFETY: as above; from here on only read, write, exit and sigreturn.
                let rc = unsafe {
                    libc::prctl(
                        libc::PR_SET_SECCOMP,
                        libc::SECCOMP_MODE_STRICT as libc::c_ulong,
                        0,
                        0,
                        0,
                    )
                };
                assert_eq!(rc, 0, "seccomp strict mode");
                STRICT_PHASE.store(1, SeqCst);
                wait_phase(2);
                for _ in 0..3_000 {
                    let tick = ticker.wait().unwrap_or_default();
                    if moving.cycle(&mut link, &tick) != CycleEnd::Continue {
                        STRICT_FAILED.store(true, SeqCst);
                    }
                }
                STRICT_PHASE.store(3, SeqCst);
                wait_phase(4);
                // SAFETY: the thread's only way out in strict mode; it leaks its stack and
                // never returns to Rust.
                unsafe { libc::syscall(libc::SYS_exit, 0) };
                unreachable!()
            });
            let tid = tid_rx.recv().unwrap();
            // Strict mode kills only the offending thread (do_exit(SIGKILL)): watch for it.
            let watch = |phase: u32| {
                while STRICT_PHASE.load(SeqCst) < phase {
                    assert!(
                        std::path::Path::new(&format!("/proc/self/task/{tid}")).exists(),
                        "{} + {}: the servo cycle made a system call: seccomp strict mode killed \
                         the thread",
                        g.name,
                        l.name
                    );
                    std::thread::sleep(Duration::from_millis(1));
                }
            };
            let io = || {
                let text = std::fs::read_to_string(format!("/proc/self/task/{tid}/io")).unwrap();
                let get = |k: &str| -> u64 {
                    text.lines()
                        .find_map(|l| l.strip_prefix(k))
                        .unwrap()
                        .trim_start_matches(':')
                        .trim()
                        .parse()
                        .unwrap()
                };
                (get("syscr"), get("syscw"))
            };
            watch(1);
            let before = io();
            STRICT_PHASE.store(2, SeqCst);
            watch(3);
            let after = io();
            STRICT_PHASE.store(4, SeqCst);
            std::mem::forget(thread); // it exited by itself; there is nothing to join
            assert!(
                !STRICT_FAILED.load(SeqCst),
                "{} + {}: a cycle did not continue",
                g.name,
                l.name
            );
            // Every cycle handed its live sample over, without a system call.
            assert_eq!(ring.slots(), 3_010, "{} + {}: telemetry samples", g.name, l.name);
            println!(
                "{} + {}: strict mode: 3000 cycles, {} reads, {} writes",
                g.name,
                l.name,
                after.0 - before.0,
                after.1 - before.1
            );
        }
    }
}

/// Every input of the fuzz corpus (`fuzz/corpus/`), through the same checks the fuzz targets
/// run: the parsers never panic and what they accept keeps its promises.
#[test]
fn fuzz_corpus_replays_cleanly() {
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../fuzz/corpus");
    let mut replayed = 0;
    for (target, check) in [
        ("knots_offline", qmarc_knots::fuzzing::offline as fn(&[u8])),
        ("knots_pvt", qmarc_knots::fuzzing::pvt),
    ] {
        for entry in std::fs::read_dir(root.join(target)).unwrap() {
            let path = entry.unwrap().path();
            check(&std::fs::read(&path).unwrap());
            replayed += 1;
        }
    }
    assert!(replayed >= 10, "the corpus is there: {replayed} inputs");
}

/// A generator that ramps every motor at `rate` counts per sample forever and does not say
/// where it goes (like a stream): only the in-loop checks can stop it.
struct Ramp(f64, [f64; MAX_MOTORS]);

impl qmarc_controller::traj::TrajectoryGenerator for Ramp {
    fn name(&self) -> &'static str {
        "ramp"
    }
    fn start(
        &mut self,
        start: &[f64; MAX_MOTORS],
    ) -> Result<(), qmarc_controller::traj::TrajStartError> {
        self.1 = *start;
        Ok(())
    }
    fn samples(&self) -> Option<u64> {
        None
    }
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> qmarc_controller::traj::Sample {
        for (c, s) in cmd.iter_mut().zip(&self.1) {
            *c = s + self.0 * n as f64;
        }
        qmarc_controller::traj::Sample::Ready
    }
}

fn run_with(
    plan: MovePlan,
    generator: Box<dyn qmarc_controller::traj::TrajectoryGenerator>,
    params: SimParams,
) -> (Servo, HwCore, Result<(), qmarc_controller::servo::MoveError>) {
    let s = settings();
    let mut link = sim_core(params);
    let mut servo = Servo::new(plan, generator, (LAWS[0].build)(&s), Box::new(MockClock::new(0)));
    let r = servo.run(&mut link, &mut ManualTicker::new(400_000), &AtomicBool::new(false));
    (servo, link, r)
}

fn limits() -> MoveLimits {
    MoveLimits {
        soft: Some([(-1_000.0, 1_000.0); MAX_MOTORS]),
        max_following_error: [500.0; MAX_MOTORS],
        max_integrated_error: [1e9; MAX_MOTORS],
        max_missed_in_row: 5,
    }
}

#[test]
fn a_following_error_past_its_limit_ends_the_move_in_that_cycle() {
    let mut p = lockstep();
    p.plant.stall_motor = Some(2); // 1-based
    let stalled = MovePlan { limits: limits(), ..plan(3) };
    let (servo, link, r) = run_with(stalled, Box::new(Ramp(2.0, [0.0; MAX_MOTORS])), p);
    r.unwrap();
    let f = servo.fault().expect("a fault");
    assert_eq!((f.kind, f.motor, f.integrated), (FaultKind::FollowingError, Some(1), false));
    assert!(f.value > 500.0 && f.value <= 502.0, "{}", f.value);
    assert!(f.disabled && !link.any_enabled());
    assert_eq!(servo.phase(), Phase::Fault);
    // The integrated limit, with the instantaneous one out of the way: Σ FE of a stalled ramp.
    let mut p = lockstep();
    p.plant.stall_motor = Some(1);
    let integrated = MovePlan {
        limits: MoveLimits {
            max_following_error: [1e9; MAX_MOTORS],
            max_integrated_error: [10_000.0; MAX_MOTORS],
            ..limits()
        },
        ..plan(3)
    };
    let (servo, _, r) = run_with(integrated, Box::new(Ramp(2.0, [0.0; MAX_MOTORS])), p);
    r.unwrap();
    let f = servo.fault().expect("a fault");
    assert_eq!((f.kind, f.motor, f.integrated), (FaultKind::FollowingError, Some(0), true));
    assert!(f.message().starts_with("motor 1 integrated following error 10"), "{}", f.message());
}

#[test]
fn software_limits_refuse_a_known_path_and_stop_an_unknown_one() {
    let s = settings();
    // A known path: the step's bounds are checked before any motor is enabled.
    let plan = MovePlan { limits: limits(), ..plan(3) };
    let mut s_big = s.clone();
    s_big.step.size = 5_000;
    // (a step beyond the following-error limit is refused when it is built: issue 27)
    for m in &mut s_big.safety {
        m.max_following_error_counts = 10_000.0;
    }
    let (servo, link, r) =
        run_with(plan.clone(), (GENERATORS[0].build)(&s_big).unwrap(), lockstep());
    assert_eq!(
        r.unwrap_err().to_string(),
        "motor 1: the path reaches 5000.0 counts, outside its software limits [-1000, 1000]: refused before the move"
    );
    assert!(servo.fault().is_none() && !link.any_enabled());
    // An unknown path (a stream): caught in the loop before the command is applied.
    let plan = MovePlan {
        limits: MoveLimits { max_following_error: [1e9; MAX_MOTORS], ..limits() },
        ..plan
    };
    let (servo, link, r) = run_with(plan, Box::new(Ramp(1.0, [0.0; MAX_MOTORS])), lockstep());
    r.unwrap();
    let f = servo.fault().expect("a fault");
    assert_eq!(
        (f.kind, f.motor, f.value, f.limit),
        (FaultKind::SoftwareLimit, Some(0), 1_001.0, 1_000.0)
    );
    assert_eq!(
        servo.gather().rows().last().unwrap().cycle,
        1_000,
        "the last command applied was 1000"
    );
    assert!(!link.any_enabled());
}

#[test]
fn too_many_missed_periods_in_a_row_are_an_overrun() {
    let s = settings();
    let plan = MovePlan {
        limits: MoveLimits { max_following_error: [1e9; MAX_MOTORS], ..limits() },
        ..plan(3)
    };
    let mut link = sim_core(lockstep());
    let mut servo = Servo::new(
        plan,
        (GENERATORS[0].build)(&s).unwrap(),
        (LAWS[0].build)(&s),
        Box::new(MockClock::new(0)),
    );
    let mut ticker = ManualTicker::new(400_000);
    let mut moving = servo.prepare(&mut link).unwrap();
    ticker.start().unwrap();
    for _ in 0..10 {
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    ticker.inject_delay(0, 4); // 4 in a row: tolerated
    assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    ticker.inject_delay(0, 5); // 5: the limit
    match moving.cycle(&mut link, &ticker.wait().unwrap()) {
        CycleEnd::Fault(f) => {
            assert_eq!((f.kind, f.value), (FaultKind::Overrun, 5.0));
            assert!(
                f.message().starts_with("5 servo periods in a row went by without a cycle"),
                "{}",
                f.message()
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn an_unhomed_frame_is_refused_when_homing_is_required() {
    let s = settings();
    let plan = MovePlan { require_homed: true, ..plan(3) };
    let mut p = lockstep();
    (p.plant.homed, p.plant.counter_offset) = (false, 777);
    let (_, link, r) = run_with(plan, (GENERATORS[0].build)(&s).unwrap(), p);
    assert_eq!(
        r.unwrap_err().to_string(),
        "motor 1 is not homed: run `qmarc-starter home` first, or give --unhomed (software limits off)"
    );
    assert!(!link.any_enabled());
}

/// A homing run in process, to its end (the switches found), on the simulated robot.
fn homed_in_process() -> (Servo, HwCore) {
    let mut s = settings();
    s.homing.velocity_counts_per_s = 20_000.0;
    s.homing.creep_counts_per_s = 1_000.0;
    s.homing.settle_s = 0.02;
    let mut p = lockstep();
    (p.plant.homed, p.plant.counter_offset) = (false, 5_000);
    let plan =
        MovePlan { monitor_switches: false, ..MovePlan::new(qmarc_config::Mode::Home, 3, 400_000) };
    let (servo, link, r) =
        run_with(plan, Box::new(qmarc_plugins::homing::Homing::from_settings(&s)), p);
    r.unwrap();
    assert!(servo.fault().is_none(), "{:?}", servo.fault());
    assert_eq!(servo.phase(), Phase::Done);
    (servo, link)
}

#[test]
fn homing_in_process_finds_the_switches_and_presets_the_frame() {
    let (mut servo, mut link) = homed_in_process();
    let home = servo.homed_frame().expect("a homed frame");
    for (m, h) in home.iter().enumerate().take(3) {
        // The switch at −9500 reads −4500 (offset 5000); home is 9500 below where it cleared.
        assert!((h - 5_000.0).abs() <= 10.0, "motor {}: home at {h}", m + 1);
    }
    let before = link.exchange(&HwMsg::read_all_encoders()).unwrap();
    let after = servo.preset_home(&mut link).expect("the read after the preset");
    assert!(servo.fault().is_none(), "{:?}", servo.fault());
    for (m, home) in home.iter().enumerate().take(3) {
        assert!(qmarc_proto::MotorFlags(after.aux[m]).homed());
        // Home reads 0: where it stands reads its distance from home (the robot coasts a
        // count or two in each of the three exchanges between the reads).
        let wanted = before.data[m] - home;
        assert!((after.data[m] - wanted).abs() <= 6.0, "{} vs {wanted}", after.data[m]);
    }
}

/// The hwserver between the loop and the preset: answers every request, except that the
/// preset fails (`fail`: no answer in time) or is refused (`refuse`: the status it says).
struct PresetFails {
    core: HwCore,
    fail: bool,
    refuse: qmarc_proto::Status,
}

impl HwLink for PresetFails {
    fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, qmarc_controller::link::LinkError> {
        if req.msg_type() != Ok(MsgType::ResetEncoderZero) {
            return self.core.exchange(req);
        }
        if self.fail {
            let lost = qmarc_controller::link::LinkError::Lost {
                waited_ns: 100_000_000,
                server_alive: true,
            };
            return Err(lost);
        }
        let mut resp = req.response();
        resp.status = self.refuse.0;
        Ok(resp)
    }
}

/// Seen in CI on a loaded host: a preset the hwserver did not answer in time ended the controller
/// with an internal error and no results. It is the move's fault now: the hwserver lost,
/// every motor disabled, the frame not homed — and a refused preset a failed home.
#[test]
fn a_preset_that_fails_is_the_homing_runs_fault() {
    for (fail, refuse, kind) in [
        (true, qmarc_proto::Status::OK, FaultKind::HwserverLost),
        (false, qmarc_proto::Status::NOT_KEPT, FaultKind::HomingFailed),
    ] {
        let (mut servo, core) = homed_in_process();
        let mut link = PresetFails { core, fail, refuse };
        let read = servo.preset_home(&mut link);
        assert_eq!(read.is_some(), !fail, "the read after an answered preset");
        let f = servo.fault().expect("a fault");
        assert_eq!(f.kind, kind);
        assert!(f.disabled, "the disable was acknowledged");
        assert_eq!(servo.phase(), Phase::Fault);
        assert!(!link.core.any_enabled(), "every motor disabled");
        let now = link.core.exchange(&HwMsg::read_all_encoders()).unwrap();
        assert!(!qmarc_proto::MotorFlags(now.aux[0]).homed(), "the frame is not homed");
    }
}

/// Issue 9, item 1: the loop tells the law how many servo periods a late cycle spans, so the
/// real `PidFf` outputs after a stall what a punctual cycle would — no feed-forward kick.
#[test]
fn a_late_cycle_outputs_what_a_punctual_one_would() {
    use std::cell::Cell;
    use std::rc::Rc;

    /// A motor exactly on its command (the test says where), recording the DAC code written.
    struct OnCommand {
        at: Rc<Cell<f64>>,
        dac: Rc<Cell<i32>>,
    }
    impl HwLink for OnCommand {
        fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, qmarc_controller::link::LinkError> {
            let mut resp = req.response();
            match req.msg_type() {
                Ok(MsgType::ReadAllEncoders) => resp.data[0] = self.at.get(),
                Ok(MsgType::WriteAllDacs) => self.dac.set(req.aux[0]),
                _ => {}
            }
            Ok(resp)
        }
    }

    let gains = qmarc_config::MotorGains { kp: 182_000.0, kvff: 119_000.0, ..Default::default() };
    let law = qmarc_plugins::pidff::PidFf::new(&[gains]);
    let plan = MovePlan::new(qmarc_config::Mode::Run, 1, 400_000);
    let ramp = util::Ramp { slope: 17.0, samples: 1_000 }; // 17 counts per sample on motor 1
    let mut servo = Servo::new(plan, Box::new(ramp), Box::new(law), Box::new(MockClock::new(0)));
    let (at, dac) = (Rc::new(Cell::new(0.0)), Rc::new(Cell::new(0)));
    let mut link = OnCommand { at: at.clone(), dac: dac.clone() };
    let mut ticker = ManualTicker::new(400_000);
    let mut moving = servo.prepare(&mut link).unwrap();
    moving.set_t0(ticker.start().unwrap());
    let mut cycle = |ticker: &mut ManualTicker| {
        let tick = ticker.wait().unwrap();
        at.set(17.0 * tick.index as f64); // no following error: only the feed-forward acts
        assert_eq!(moving.cycle(&mut link, &tick), CycleEnd::Continue);
        (tick.index, tick.missed, dac.get())
    };
    let mut punctual = (0, 0, 0);
    for _ in 0..10 {
        punctual = cycle(&mut ticker);
    }
    assert!(punctual.2 > 1_000, "the feed-forward drives the ramp: {punctual:?}");
    ticker.inject_delay(50_000, 3); // three periods missed
    let late = cycle(&mut ticker);
    assert_eq!((late.0, late.1), (punctual.0 + 4, 3), "the late cycle skipped three samples");
    assert_eq!(late.2, punctual.2, "a late cycle outputs what a punctual one would");
    assert_eq!(cycle(&mut ticker).2, punctual.2, "and so does the next");
}

/// Issue 12: with the Sensoray 626 backend (its instruction lists against the fake of the
/// driver) the servo cycle — and the hardware server's side of it — allocates nothing either.
#[test]
fn the_626_backends_cycle_allocates_nothing() {
    let mut s = util::settings_of("s626.toml");
    s.set_device(std::path::Path::new("fake")).unwrap();
    let card = qmarc_hwserver::backends::s626::S626::open(&s, false).unwrap();
    let mut link = qmarc_hwserver::HwCore::new(Box::new(card));
    let mut servo = step_servo(&s);
    let mut ticker = ManualTicker::new(400_000);
    let mut moving = servo.prepare(&mut link).unwrap();
    moving.set_t0(ticker.start().unwrap());
    for _ in 0..10 {
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let before = allocations();
    for _ in 0..2_000 {
        let tick = ticker.wait().unwrap();
        assert_eq!(moving.cycle(&mut link, &tick), CycleEnd::Continue);
    }
    assert_eq!(allocations() - before, 0, "allocations in 2000 cycles over the 626 backend");
    assert!(link.position(0) > 100, "the fake card's motor followed the step");
}

/// Issue 13 (review): the path's gathered rows are told from the settle's by sample index.
/// Missed periods skip samples, so counting executed cycles would drop the path's last rows.
#[test]
fn the_path_rows_end_where_the_settle_begins_after_missed_periods() {
    let mut s = settings();
    s.step.duration_s = 0.02; // samples 0..=50
    let plan = MovePlan { settle_cycles: 10, ..plan(3) };
    let mut servo = Servo::new(
        plan,
        (GENERATORS[0].build)(&s).unwrap(),
        (LAWS[0].build)(&s),
        Box::new(MockClock::new(0)),
    );
    let mut link = sim_core(lockstep());
    let mut ticker = ManualTicker::new(400_000);
    ticker.inject_delay(0, 3); // the first wake finds three periods missed
    servo.run(&mut link, &mut ticker, &AtomicBool::new(false)).unwrap();
    let record = servo.into_record();
    let rows = record.gather.rows();
    let path: Vec<u64> =
        rows.iter().map(|r| r.cycle).filter(|&c| record.is_path_sample(c)).collect();
    assert_eq!(path.len() as u64, record.cycles, "every executed path cycle is a path row");
    assert_eq!(path.last(), Some(&50), "the path's last sample is among them");
    let settle = rows.iter().filter(|r| !record.is_path_sample(r.cycle)).count() as u64;
    assert_eq!(settle, record.settle.unwrap().cycles);
}

/// The loop hands its samples to a ring (no allocation: the tests above); the publishing
/// thread's iceoryx2 publish allocates exactly one block per sample (the loan's `Rc`,
/// eclipse-iceoryx/iceoryx2#101), with a reader attached. And every sample put into the ring
/// reaches the reader, in order, through the real relay thread.
#[test]
fn a_telemetry_publish_allocates_exactly_its_loan_and_the_relay_delivers_every_sample() {
    use qmarc_proto::telemetry::TelemetrySample;
    use qmarc_telemetry::reader::TelemetryReader;
    use qmarc_telemetry::relay::{TelemetryPublisher, spawn};
    let ipc = util::IpcDir::new("telemetry");
    {
        let publisher = TelemetryPublisher::open(&ipc.location).unwrap();
        let mut reader = TelemetryReader::open(&ipc.location).unwrap();
        assert!(publisher.publish(TelemetrySample::default()), "the first, connecting");
        let before = allocations();
        for k in 0..500 {
            assert!(publisher.publish(TelemetrySample { cycle: k, ..TelemetrySample::default() }));
        }
        assert_eq!(allocations() - before, 500, "one allocation per publish");
        let mut got = 0;
        while reader.receive().unwrap().is_some() {
            got += 1;
        }
        assert_eq!(got, 501);
    }
    // Through the relay: the loop's end of the ring, let go when the move ends. The reader
    // reads while the relay lives (a reader reads what a living publisher sent; the console
    // and the scope read as the move goes), then what is left once the ring is let go.
    let (cycles, reader) = {
        let (mut tx, rx) = qmarc_controller::telemetry::ring(1);
        let relay = spawn(ipc.location.clone(), rx).unwrap();
        // Once the relay serves (30 s at most: a loaded machine starts its thread late).
        let opening = std::time::Instant::now();
        let mut reader = loop {
            if let Ok(r) = TelemetryReader::open(&ipc.location) {
                break r;
            }
            assert!(opening.elapsed() < Duration::from_secs(30), "the relay's service");
            std::thread::sleep(Duration::from_millis(10));
        };
        for k in 0..1_000 {
            tx.offer(TelemetrySample { cycle: k, ..TelemetrySample::default() });
        }
        let mut cycles = Vec::new();
        let deadline = std::time::Instant::now() + Duration::from_secs(30);
        while cycles.len() < 1_000 && std::time::Instant::now() < deadline {
            match reader.receive().unwrap() {
                Some(s) => cycles.push(s.cycle),
                None => std::thread::sleep(Duration::from_millis(1)),
            }
        }
        drop(tx);
        let report = relay.join();
        assert_eq!((report.published, report.refused, report.error), (1_000, 0, None));
        cycles.extend(std::iter::from_fn(|| reader.receive().unwrap()).map(|s| s.cycle));
        (cycles, reader)
    };
    assert_eq!(cycles, (0..1_000).collect::<Vec<_>>(), "every sample, in order");
    assert_eq!(reader.publishers(), 0, "the relay let go of the service");
}

/// Issue 27, item 2: a command that is not a finite number (every limit compares false with
/// NaN) or a law output that is not a DAC code ends the move in that cycle, every motor
/// disabled, before it reaches the law or the DAC — never a silent 0 V with the amplifiers on.
#[test]
fn a_non_finite_command_or_output_is_a_fault_in_that_cycle() {
    use qmarc_controller::law::{NOT_A_CODE, ServoInput, ServoLaw};
    use qmarc_controller::traj::{Sample, TrajStartError, TrajectoryGenerator};

    /// At rest, then motor 2 commanded to NaN from sample `.0` on.
    struct GoesNan(u64);
    impl TrajectoryGenerator for GoesNan {
        fn name(&self) -> &'static str {
            "nan"
        }
        fn start(&mut self, _: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
            Ok(())
        }
        fn samples(&self) -> Option<u64> {
            Some(1_000)
        }
        fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
            *cmd = [0.0; MAX_MOTORS];
            if n >= self.0 {
                cmd[1] = f64::NAN;
            }
            Sample::Ready
        }
    }
    let (servo, link, r) = run_with(plan(3), Box::new(GoesNan(50)), lockstep());
    r.unwrap();
    let f = servo.fault().expect("a fault");
    assert_eq!((f.kind, f.motor, f.cycle), (FaultKind::BadCommand, Some(1), 50));
    assert!(f.disabled && !link.any_enabled(), "{f:?}");
    assert_eq!(servo.cycles(), 50, "samples 0‥49 ran, 50 did not");
    assert!(
        f.message()
            .starts_with("the trajectory commanded motor 2 to NaN counts, not a finite number"),
        "{}",
        f.message()
    );
    assert_eq!(f.kind.name(), "bad_command");
    // NaN from the first sample: refused before any motor is enabled.
    let (servo, link, r) = run_with(plan(3), Box::new(GoesNan(0)), lockstep());
    assert_eq!(
        r.unwrap_err().to_string(),
        "motor 2: the path reaches NaN counts at sample 0: not a finite number"
    );
    assert!(servo.fault().is_none() && !link.any_enabled());

    /// Zero output, then no DAC code for motor 3 from sample 20 on.
    struct NanLaw;
    impl ServoLaw for NanLaw {
        fn name(&self) -> &'static str {
            "nan"
        }
        fn reset(&mut self, _: &[f64; MAX_MOTORS], _: &[f64; MAX_MOTORS]) {}
        fn step(&mut self, input: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]) {
            *dac = [0; MAX_MOTORS];
            if input.n >= 20 {
                dac[2] = NOT_A_CODE;
            }
        }
    }
    let s = settings();
    let mut link = sim_core(lockstep());
    let generator = (GENERATORS[0].build)(&s).unwrap();
    let mut servo = Servo::new(plan(3), generator, Box::new(NanLaw), Box::new(MockClock::new(0)));
    servo.run(&mut link, &mut ManualTicker::new(400_000), &AtomicBool::new(false)).unwrap();
    let f = servo.fault().expect("a fault");
    assert_eq!((f.kind, f.motor, f.cycle), (FaultKind::BadOutput, Some(2), 20));
    assert!(f.disabled && !link.any_enabled(), "{f:?}");
    assert!(servo.gather().rows().iter().all(|r| r.dac.iter().all(|&c| c == 0)));
    assert_eq!(f.kind.name(), "bad_output");
}

/// Issue 28, item 6: a fault shortly after a host stall says so — the loop could not act
/// for those periods, the motors ran on their last output — naming how many periods went by
/// and how long before; one without a recent stall does not, and neither does a lock-step
/// run (simulated time does not see the host's stalls).
#[test]
fn a_fault_after_a_host_stall_says_so() {
    let fault_after = |stall_at: Option<u64>, deterministic: bool| {
        let mut p = lockstep();
        p.plant.stall_motor = Some(2);
        let plan = MovePlan { limits: limits(), deterministic, ..plan(3) };
        let s = settings();
        let mut link = sim_core(p);
        let ramp = Box::new(Ramp(2.0, [0.0; MAX_MOTORS]));
        let mut servo = Servo::new(plan, ramp, (LAWS[0].build)(&s), Box::new(MockClock::new(0)));
        let mut ticker = ManualTicker::new(400_000);
        let mut moving = servo.prepare(&mut link).unwrap();
        ticker.start().unwrap();
        for i in 0..10_000 {
            if Some(i) == stall_at {
                ticker.inject_delay(0, 4);
            }
            if let CycleEnd::Fault(f) = moving.cycle(&mut link, &ticker.wait().unwrap()) {
                servo.handle_fault(&mut link, f);
                return servo.fault().unwrap();
            }
        }
        panic!("no fault");
    };
    let f = fault_after(Some(100), false);
    assert_eq!((f.kind, f.motor), (FaultKind::FollowingError, Some(1)));
    let before = f.cycle - 104;
    assert_eq!(f.stall, Some(HostStall { missed: 4, cycles_before: before }));
    let said = format!(
        " at cycle {} (4 servo periods went by without a cycle {before} cycles before: a host \
         stall",
        f.cycle
    );
    assert!(f.message().contains(&said), "{}", f.message());
    assert_eq!(fault_after(None, false).stall, None);
    assert!(!fault_after(None, false).message().contains("host stall"));
    assert_eq!(fault_after(Some(100), true).stall, None, "lock-step");
}

/// Periods missed at the very end of a path skip its last samples; the settle then holds
/// the path's last command, not the one before the stall.
#[test]
fn a_stall_at_the_end_of_a_path_settles_on_its_last_command() {
    use qmarc_controller::law::{ServoInput, ServoLaw};

    struct Off;
    impl ServoLaw for Off {
        fn name(&self) -> &'static str {
            "off"
        }
        fn reset(&mut self, _: &[f64; MAX_MOTORS], _: &[f64; MAX_MOTORS]) {}
        fn step(&mut self, _: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]) {
            *dac = [0; MAX_MOTORS];
        }
    }
    /// A hardware that stands still at 0.
    struct Still;
    impl HwLink for Still {
        fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, qmarc_controller::link::LinkError> {
            Ok(req.response())
        }
    }
    for (stall_after, skip) in [(7, 5), (9, 0)] {
        let plan =
            MovePlan { settle_cycles: 10, ..MovePlan::new(qmarc_config::Mode::Run, 1, 400_000) };
        let ramp = util::Ramp { slope: 1.0, samples: 11 }; // sample n commands n counts
        let mut servo =
            Servo::new(plan, Box::new(ramp), Box::new(Off), Box::new(MockClock::new(0)));
        let mut ticker = ManualTicker::new(400_000);
        let mut moving = servo.prepare(&mut Still).unwrap();
        moving.set_t0(ticker.start().unwrap());
        let end = loop {
            let tick = ticker.wait().unwrap();
            if tick.index == stall_after {
                ticker.inject_delay(0, skip);
            }
            match moving.cycle(&mut Still, &tick) {
                CycleEnd::Continue => {}
                end => break (end, tick.index),
            }
        };
        assert_eq!(end.0, CycleEnd::Done, "{end:?}");
        let record = servo.into_record();
        assert_eq!(record.last_error[0], 10.0, "skip {skip}: the path's last command is held");
    }
}

//! Integration tests of the controller library: the servo cycle allocates nothing, does no
//! I/O and never blocks; the fault handler disables the motors; the loop runs over the real
//! iceoryx2 link.

mod util;

use qmarc_controller::link::{HwLink, IoxLink, LinkTimeouts};
use qmarc_controller::registry::{GENERATORS, LAWS};
use qmarc_controller::servo::{CycleEnd, MovePlan, Servo};
use qmarc_controller::summary::FaultKind;
use qmarc_hwserver::server::{ServeEnd, ServeOptions, serve};
use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
use qmarc_proto::service::IpcLocation;
use qmarc_proto::{HwMsg, MsgType};
use qmarc_timer::{ManualTicker, MockClock, Ticker};
use std::sync::atomic::AtomicBool;
use std::time::Duration;
use util::{CoreLink, CountingAllocator, ThreadCounters, allocations, settings};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

fn plan(n_motors: usize) -> MovePlan {
    MovePlan {
        mode: "step".into(),
        n_motors,
        period_ns: 400_000,
        gather_every: 1,
        deterministic: false,
    }
}

/// The step move with the PID feed-forward law, timed on a mock clock.
fn step_servo(s: &qmarc_controller::config::Settings) -> Servo {
    Servo::new(plan(3), (GENERATORS[0].build)(s), (LAWS[0].build)(s), Box::new(MockClock::new(0)))
}

fn lockstep() -> SimParams {
    SimParams { n_motors: 3, lockstep: true, ..SimParams::default() }
}

#[test]
fn servo_cycle_allocates_nothing_with_every_generator_and_law() {
    let s = settings();
    for g in GENERATORS {
        for l in LAWS {
            let mut servo =
                Servo::new(plan(3), (g.build)(&s), (l.build)(&s), Box::new(MockClock::new(0)));
            let mut link = CoreLink::new(lockstep());
            let mut ticker = ManualTicker::new(400_000);
            servo.prepare(&mut link).unwrap();
            servo.set_t0(ticker.start().unwrap());
            for _ in 0..10 {
                assert_eq!(servo.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
            }
            // What reading the counters costs by itself.
            let (a, b) = (ThreadCounters::now(), ThreadCounters::now());
            let reading = a.delta(b);
            let kernel_before = ThreadCounters::now();
            let before = allocations();
            for k in 0..3_000 {
                if k == 1_500 {
                    ticker.inject_delay(150_000, 3); // a stall: missed periods on the way
                }
                let tick = ticker.wait().unwrap();
                assert_eq!(servo.cycle(&mut link, &tick), CycleEnd::Continue);
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

#[test]
fn limit_switch_trip_disables_every_motor_in_the_same_cycle() {
    let s = settings();
    let mut params = lockstep();
    // Motor 2 starts 300 counts below its bottom switch; the step drives it through.
    params.start_counts[1] = params.bottom_switch_counts - 300.0;
    let mut link = CoreLink::new(params);
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
    assert!(!link.0.any_enabled(), "all motors disabled");
    // The cycle that saw the switch wrote no DAC: the last gathered row is the one before.
    let rows = servo.gather().rows();
    assert_eq!(rows.last().unwrap().cycle + 1, fault.cycle);
}

#[test]
fn a_stop_request_aborts_the_move_and_disables_the_motors() {
    let s = settings();
    let mut link = CoreLink::new(lockstep());
    let mut servo = step_servo(&s);
    let stop = AtomicBool::new(true);
    servo.run(&mut link, &mut ManualTicker::new(400_000), &stop).unwrap();
    assert_eq!(servo.fault().map(|f| f.kind), Some(FaultKind::Aborted));
    assert!(!link.0.any_enabled());
}

/// The loop over real iceoryx2, the server in another thread of this process. Our code
/// allocates nothing; iceoryx2 0.10 allocates once per loan (an `Rc` per request,
/// eclipse-iceoryx/iceoryx2#101), so exactly one allocation per exchange, two per cycle.
#[test]
fn over_iceoryx2_each_cycle_allocates_only_the_two_request_loans() {
    let dir = std::env::temp_dir().join(format!("qmarc-ctl-alloc-{}", std::process::id()));
    let location = IpcLocation::new(
        &format!("qc{}_alloc_", std::process::id()),
        &format!("{}/", dir.display()),
    );
    let server_location = location.clone();
    let server = std::thread::spawn(move || {
        let mut core = HwCore::new(Box::new(SimDeltabot::new(lockstep()).unwrap()));
        let opts = ServeOptions {
            watchdog_ns: 5_000_000_000,
            spin: false,
            shutdown_grace_ns: 1_000_000_000,
        };
        serve(&mut core, &server_location, &opts, &AtomicBool::new(false))
    });
    let timeouts = LinkTimeouts { deadline_ns: 50_000_000, give_up_ns: 2_000_000_000 };
    let mut link = IoxLink::connect(&location, timeouts, Duration::from_secs(5)).unwrap();
    let s = settings();
    let mut servo = step_servo(&s);
    let mut ticker = ManualTicker::new(400_000);
    servo.prepare(&mut link).unwrap();
    servo.set_t0(ticker.start().unwrap());
    for _ in 0..50 {
        assert_eq!(servo.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let before = allocations();
    let cycles = 1_000;
    for _ in 0..cycles {
        assert_eq!(servo.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let during = allocations() - before;
    assert_eq!(during, 2 * cycles, "iceoryx2's loans only");
    link.exchange(&HwMsg::request(MsgType::Exit)).unwrap();
    assert_eq!(server.join().unwrap().unwrap(), ServeEnd::Exit);
    drop(link);
    location.remove_files();
    assert!(location.files().is_empty());
    let _ = std::fs::remove_dir_all(&dir);
}

//! The serving generator in the loop: orders arriving while the robot moves are taken in the
//! cycle they arrive, and the cycle still allocates nothing, makes no I/O and never blocks
//! (the proof `qmarc-plugins`' tests give every registered generator, for the one that is not
//! in the registry).

// The loop's test helpers (a counting allocator, the in-process hardware core) are the
// plug-ins' tests' own: one file, compiled here too.
#[allow(dead_code)]
#[path = "../../plugins/tests/util.rs"]
mod util;

use qmarc_controller::plan::MovePlan;
use qmarc_controller::servo::{CycleEnd, Servo};
use qmarc_plugins::motion::MotionLimits;
use qmarc_plugins::registry::LAWS;
use qmarc_proto::MAX_MOTORS;
use qmarc_session::generator::{Order, ServeLimits, ServeMove};
use qmarc_timer::{ManualTicker, MockClock, Ticker};
use std::sync::atomic::Ordering;
use util::{
    CountingAllocator, ThreadCounters, allocations, lockstep, plan, settings, sim_core, warmed_up,
};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// Serving: a new target, a stop and a new target again arrive while the loop runs — each
/// planned in the cycle it arrives — and the cycle still allocates nothing, makes no I/O and
/// never blocks; the loop takes every order.
#[test]
fn serve_cycle_allocates_nothing_while_commands_arrive() {
    let s = settings();
    let limits = MotionLimits::of(&s);
    let soft = [(-9_000.0, 10_000.0); MAX_MOTORS];
    let status = std::sync::Arc::new(qmarc_controller::status::LoopStatus::default());
    let limits_of = ServeLimits { soft: Some(soft), ..ServeLimits::of(&s, true) };
    let (serve, mut handle) = ServeMove::new(&s, &limits_of, status.clone());
    // With the gripper on DIO6: a grip's third exchange is in the counted cycles too. The
    // rows in a gather page (shared memory, as a serving controller keeps them), a ring of
    // 1000 that wraps three times in the cycles counted.
    let plan = MovePlan {
        gripper_mask: 1 << 6,
        stream_gather_samples: 1_000,
        gather_keeps_last: true,
        ..plan(3)
    };
    let page = std::env::temp_dir().join(format!("qmarc-servo-page-{}", std::process::id()));
    let mut servo =
        Servo::new(plan, Box::new(serve), (LAWS[0].build)(&s), Box::new(MockClock::new(0)))
            .with_gather_page(page.clone())
            .with_status(status);
    let mut link = sim_core(lockstep()).with_gripper(1 << 6, 0.05);
    let mut ticker = ManualTicker::new(400_000);
    let (mut moving, reading) = warmed_up(&mut servo, &mut link, &mut ticker);
    let kernel_before = ThreadCounters::now();
    let before = allocations();
    let mut id = 0;
    for k in 0..3_000 {
        if k % 200 == 0 {
            id += 1;
            let sign = if id % 2 == 0 { 1.0 } else { -1.0 };
            let order = if id % 5 == 0 {
                Order::Stop { id, limits }
            } else if id % 3 == 0 {
                Order::Grip { id, close: id % 2 == 0 }
            } else {
                Order::Move { id, target: [sign * 3000.0, -sign * 1500.0, 800.0, 0.0], limits }
            };
            assert!(handle.orders.push(order).is_ok());
        }
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
    }
    let during = allocations() - before;
    let kernel = kernel_before.delta(ThreadCounters::now());
    assert_eq!(during, 0, "{during} allocations in 3000 cycles of serving");
    assert_eq!(kernel, reading, "syscalls or blocking in the cycle");
    assert_eq!(handle.shared.taken.load(Ordering::Acquire), id, "every order taken");
    assert_eq!(handle.shared.not_taken.load(Ordering::Acquire), 0);
    assert!(handle.spent.pop().is_err());
    // The last grip (id 12: close) was written and the gripper has closed.
    assert_eq!(handle.status.gripper().name(), "closed", "as the loop's status says it");
    assert_eq!(handle.status.cycles(), servo.status().cycles());
    assert!(handle.status.begun());
    // The rows went into the page (the last 1000), as another process would read them.
    assert!(servo.gather().in_a_page());
    let salvaged = qmarc_controller::gather::Gather::salvage(&page).expect("the page");
    let last: Vec<u64> = salvaged.rows().iter().map(|r| r.cycle).collect();
    assert_eq!(
        (last.len(), last.last()),
        (999, Some(&3_009)),
        "the ring's last rows but its oldest"
    );
    assert!(last.windows(2).all(|w| w[1] == w[0] + 1));
    let _ = std::fs::remove_file(&page);
}

/// The conveyor session's picker in the loop: it intercepts parts on the moving belt, grips
/// and places them, one after the other, and its cycles allocate nothing, make no I/O and
/// never block — planning an intercept in the cycle a pick arrives included.
#[test]
fn picker_cycle_allocates_nothing_while_it_picks() {
    use qmarc_hwserver::backends::sim::{SimBelt, SimDeltabot};
    use qmarc_session::conveyor::picker::Picker;
    use qmarc_session::conveyor::{Pick, PickEvent};
    let s = settings();
    let status = std::sync::Arc::new(qmarc_controller::status::LoopStatus::default());
    let (picker, _serve, mut handle) = Picker::new(&s, status.clone()).expect("the Delta");
    let plan = MovePlan {
        gripper_mask: 1 << 6,
        stream_gather_samples: 4_000,
        mode: qmarc_config::Mode::Conveyor,
        ..plan(3)
    };
    let mut servo =
        Servo::new(plan, Box::new(picker), (LAWS[0].build)(&s), Box::new(MockClock::new(0)))
            .with_status(status.clone());
    let robot = SimDeltabot::new(lockstep()).unwrap().with_belt(SimBelt::of(&s));
    let mut link = qmarc_hwserver::HwCore::new(Box::new(robot)).with_gripper(1 << 6, 0.05);
    let mut ticker = ManualTicker::new(400_000);
    let (mut moving, reading) = warmed_up(&mut servo, &mut link, &mut ticker);
    let kernel_before = ThreadCounters::now();
    let before = allocations();
    let (mut given, mut events) = (0u32, [None; 64]);
    let mut n_events = 0;
    for _ in 0..3_000 {
        // The dispatcher's part: a part at the window's start whenever the picker waits.
        if handle.shared.ready.load(Ordering::Acquire) && handle.picks.slots() == 2 {
            given += 1;
            let (belt, _) = status.belt();
            let pick = Pick { id: given, belt_mm: 300.0, across_mm: 20.0, latched_counts: belt };
            assert!(handle.picks.push(pick).is_ok());
        }
        assert_eq!(moving.cycle(&mut link, &ticker.wait().unwrap()), CycleEnd::Continue);
        while let Ok(e) = handle.events.pop() {
            events[n_events] = Some(e);
            n_events += 1;
        }
    }
    let during = allocations() - before;
    let kernel = kernel_before.delta(ThreadCounters::now());
    assert_eq!(during, 0, "{during} allocations in 3000 cycles of picking");
    assert_eq!(kernel, reading, "syscalls or blocking in the cycle");
    let placed = events.iter().flatten().filter(|e| matches!(e, PickEvent::Placed { .. })).count();
    assert!(placed >= 2, "{:?}", &events[..n_events]);
    assert!(
        !events.iter().flatten().any(|e| matches!(e, PickEvent::GaveUp { .. })),
        "{:?}",
        &events[..n_events]
    );
}

//! Integration tests of the real tickers and the real-time set-up on this machine. They
//! check what each wake reports, never how fast the machine is.

use qmarc_timer::TickerKind;
use qmarc_timer::rt::{RtRequest, spawn};

fn check_ticks(kind: TickerKind) {
    let period = 1_000_000;
    let mut ticker = kind.build(period);
    let t0 = ticker.start().unwrap();
    let mut expected_index = 0;
    let mut last_woke = 0;
    for _ in 0..30 {
        let tick = ticker.wait().unwrap();
        assert!(tick.index >= expected_index, "{kind:?}: index went back");
        assert_eq!(tick.index, expected_index + tick.missed, "{kind:?}: skipped ticks are counted");
        assert_eq!(
            tick.intended_ns,
            t0 + expected_index * period,
            "{kind:?}: first unserviced tick"
        );
        assert!(tick.woke_ns >= tick.intended_ns, "{kind:?}: woke before the expiry");
        assert!(tick.woke_ns >= last_woke);
        last_woke = tick.woke_ns;
        expected_index = tick.index + 1;
    }
}

#[test]
fn timerfd_ticks_are_reported_against_their_expiry() {
    check_ticks(TickerKind::TimerFd);
}

#[test]
fn nanosleep_ticks_are_reported_against_their_expiry() {
    check_ticks(TickerKind::Nanosleep);
}

#[test]
fn periodic_timerfd_ticks_are_reported_against_their_expiry() {
    check_ticks(TickerKind::TimerFdPeriodic);
}

/// Issue 14: the one-shot timerfd counts a stall longer than a period as missed ticks,
/// measured against the first unserviced one, as the periodic one does.
#[test]
fn a_stall_is_counted_by_every_kind() {
    for kind in TickerKind::ALL {
        let mut t = kind.build(1_000_000);
        t.start().unwrap();
        t.wait().unwrap();
        std::thread::sleep(std::time::Duration::from_millis(3));
        let tick = t.wait().unwrap();
        assert!(tick.missed >= 2, "{kind:?}: {tick:?}");
        assert!(tick.latency_ns() >= 2_000_000, "{kind:?}: {tick:?}");
    }
}

#[test]
fn fifo_is_granted_or_reported_as_degraded() {
    // A short SCHED_FIFO thread that only sleeps: it cannot starve the other tests.
    let req = RtRequest {
        priority: Some(10),
        lock_memory: false,
        prefault_stack_bytes: 32 * 1024,
        cpu: None,
    };
    let status = spawn("fifo-probe", req, |s| {
        let mut t = TickerKind::Nanosleep.build(500_000);
        t.start().unwrap();
        for _ in 0..5 {
            t.wait().unwrap();
        }
        s
    })
    .unwrap()
    .join()
    .unwrap();
    match status.fifo_priority {
        Some(p) => {
            assert_eq!(p, 10);
            assert!(!status.degraded() && status.warnings.is_empty());
        }
        None => {
            assert!(status.degraded());
            assert!(status.warnings[0].contains("SCHED_FIFO 10 refused"), "{:?}", status.warnings);
        }
    }
}

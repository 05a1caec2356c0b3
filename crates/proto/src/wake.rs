//! A futex wake-up for iceoryx2's event services, and the service type of the link that uses it.
//!
//! iceoryx2 0.10's `ipc` service wakes a listener with a datagram on a unix socket
//! (`iceoryx2-cal`'s `UnixDatagramShmCountingBitSet`): a `sendto` in the notifier and a
//! `recvfrom` in the woken process, where a futex hand-over is one word in shared memory. Its
//! semaphore trigger is a futex, but its timed wait polls (`UnnamedSemaphore::timed_wait` on a
//! monotonic clock is an adaptive yield-then-sleep loop), and both our waits have a deadline.
//!
//! [`FutexHandle`] and [`FutexWaiter`] plug into iceoryx2-cal's generic event (`EventImpl`: the
//! counting bit set of event ids, the notification state, the shared-memory storage and its
//! clean-up stay iceoryx2's) as the part that puts a listener to sleep and wakes it:
//! - the storage's management record holds a `signalled` word and a `sleepers` count;
//! - `notify` sets `signalled` and calls `FUTEX_WAKE` only when somebody sleeps on it, so a
//!   notification nobody waits for costs no system call;
//! - a wait takes `signalled` if set, otherwise counts itself in `sleepers` and calls
//!   `FUTEX_WAIT_BITSET` with an absolute `CLOCK_MONOTONIC` deadline.
//!
//! A timed wait's deadline is rounded up to the kernel's tick (1/HZ, the resolution of
//! `CLOCK_MONOTONIC_COARSE`), as the socket's `SO_RCVTIMEO` it replaces rounds up to a jiffy.
//! Ticks fall on multiples of the tick period, so the wait's timer expires with the tick the
//! CPU has armed anyway: arming and cancelling it reprograms no timer hardware, which on a VM
//! is a hypervisor exit each time. Measured on this VM at 10 kHz (`qmarc-starter step
//! --period-us 100`, read round trip p50): 7–8 µs rounded, 18–19 µs with exact deadlines,
//! 14 µs with iceoryx2's socket. A deadline is met at most one tick late (4 ms at HZ = 250):
//! our waits' deadlines are the hwserver's watchdog and the controller's alive check, which
//! had that granularity before.
//!
//! Notifier and waiter check each other's word after writing their own (sequentially consistent
//! atomics), so a wake-up is never lost: a notifier that saw no sleeper set `signalled` before the
//! sleeper's `FUTEX_WAIT`, which then returns at once.
//!
//! [`Link`] is iceoryx2's `ipc` service with this event: the controller ⇄ hwserver link's node
//! and its three services are of this type, everything else (telemetry) stays `ipc::Service`.

use core::fmt::Debug;
use core::mem::MaybeUninit;
use core::ptr::NonNull;
use core::sync::atomic::{AtomicU32, Ordering};
use core::time::Duration;
use iceoryx2_bb_elementary_traits::testing::abandonable::Abandonable;
use iceoryx2_bb_elementary_traits::zero_copy_send::ZeroCopySend;
use iceoryx2_bb_lock_free::mpmc::counting_bit_set::RelocatableCountingBitSet;
use iceoryx2_cal::dynamic_storage::posix_shared_memory;
use iceoryx2_cal::event::common::EventImpl;
use iceoryx2_cal::event::event_state::EventState;
use iceoryx2_cal::event::trigger::{Configuration, HandlerInterface, State, WaiterInterface};
use iceoryx2_cal::event::{
    FileName, ListenerCreateError, ListenerWaitError, NotifierNotifyError, NotifierOpenError, Path,
};
use iceoryx2_cal::named_concept::{NamedConceptPathHintRemoveError, NamedConceptRemoveError};
use std::marker::PhantomData;

/// The futex words of one listener, in the event's shared memory.
#[derive(Debug)]
#[repr(C)]
pub struct FutexMgmt {
    /// 1 when a notification came that no wait has taken yet (the futex word).
    signalled: AtomicU32,
    /// How many waits are in (or about to enter) `FUTEX_WAIT`.
    sleepers: AtomicU32,
}

// SAFETY: two `u32` atomics, `repr(C)`, no pointers: valid in every process that maps them.
unsafe impl ZeroCopySend for FutexMgmt {}

/// The storage of one listener's event state and its [`FutexMgmt`].
pub type FutexStorage<E> = posix_shared_memory::Storage<State<E, FutexMgmt>>;

/// The notifier's side: wakes the listener.
#[derive(Debug)]
pub struct FutexHandle<E: EventState> {
    mgmt: NonNull<FutexMgmt>,
    _state: PhantomData<E>,
}

/// The listener's side: sleeps until notified.
#[derive(Debug)]
pub struct FutexWaiter<E: EventState> {
    mgmt: NonNull<FutexMgmt>,
    /// The kernel tick a timed wait's deadline is rounded up to (0: not rounded).
    tick_ns: u64,
    _state: PhantomData<E>,
}

// SAFETY: both only touch atomics in shared memory that the event's storage keeps mapped for as
// long as the notifier or listener holding them exists (`EventImpl` owns the storage beside).
unsafe impl<E: EventState> Send for FutexHandle<E> {}
unsafe impl<E: EventState> Sync for FutexHandle<E> {}
unsafe impl<E: EventState> Send for FutexWaiter<E> {}
unsafe impl<E: EventState> Sync for FutexWaiter<E> {}

impl<E: EventState> Abandonable for FutexHandle<E> {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

impl<E: EventState> Abandonable for FutexWaiter<E> {
    unsafe fn abandon_in_place(_this: NonNull<Self>) {}
}

fn mgmt<'a>(ptr: NonNull<FutexMgmt>) -> &'a FutexMgmt {
    // SAFETY: see the `Send` impls: the storage outlives the handle and the waiter.
    unsafe { ptr.as_ref() }
}

/// `FUTEX_WAKE` one sleeper. Shared (not `_PRIVATE`): the word is in memory two processes map.
fn futex_wake(word: &AtomicU32) -> Result<(), i32> {
    // SAFETY: the address is a live, aligned u32; the other arguments are ignored by WAKE.
    let r = unsafe { libc::syscall(libc::SYS_futex, word.as_ptr(), libc::FUTEX_WAKE, 1) };
    if r < 0 { Err(std::io::Error::last_os_error().raw_os_error().unwrap_or(0)) } else { Ok(()) }
}

/// `ts` in ns.
fn ns(ts: &libc::timespec) -> u64 {
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// CLOCK_MONOTONIC now, ns.
fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid out-pointer; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ns(&ts)
}

/// The kernel's tick (1/HZ), ns: the resolution of `CLOCK_MONOTONIC_COARSE`, which advances
/// once per jiffy. 0 where it cannot be read (deadlines are then not rounded).
fn kernel_tick_ns() -> u64 {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: `ts` is a valid out-pointer.
    let r = unsafe { libc::clock_getres(libc::CLOCK_MONOTONIC_COARSE, &mut ts) };
    let tick = ns(&ts);
    if r == 0 && tick <= 100_000_000 { tick } else { 0 }
}

/// `FUTEX_WAIT` while `word` is 0, at most until `deadline_ns` on CLOCK_MONOTONIC (`None`: no
/// limit). `FUTEX_WAIT_BITSET` takes the deadline as an absolute time.
fn futex_wait_until(word: &AtomicU32, deadline_ns: Option<u64>) -> Result<(), i32> {
    let ts = deadline_ns.map(|d| libc::timespec {
        tv_sec: (d / 1_000_000_000) as libc::time_t,
        tv_nsec: (d % 1_000_000_000) as libc::c_long,
    });
    let ts_ptr = ts.as_ref().map_or(core::ptr::null(), |t| t as *const libc::timespec);
    // SAFETY: the address is a live, aligned u32, `ts_ptr` is null or points at `ts`, the
    // second address is unused by this operation.
    let r = unsafe {
        libc::syscall(
            libc::SYS_futex,
            word.as_ptr(),
            libc::FUTEX_WAIT_BITSET,
            0,
            ts_ptr,
            core::ptr::null::<u32>(),
            libc::FUTEX_BITSET_MATCH_ANY,
        )
    };
    if r < 0 {
        match std::io::Error::last_os_error().raw_os_error().unwrap_or(0) {
            // Already signalled, or woken for nothing, or the deadline: the caller looks again.
            libc::EAGAIN | libc::ETIMEDOUT => Ok(()),
            e => Err(e),
        }
    } else {
        Ok(())
    }
}

impl<E: EventState> HandlerInterface<E, FutexMgmt, FutexStorage<E>> for FutexHandle<E> {
    fn open(
        _name: &FileName,
        _config: &Configuration,
        mgmt: &FutexMgmt,
    ) -> Result<Self, NotifierOpenError> {
        Ok(FutexHandle { mgmt: NonNull::from(mgmt), _state: PhantomData })
    }

    fn notify(&self) -> Result<(), NotifierNotifyError> {
        let m = mgmt(self.mgmt);
        m.signalled.store(1, Ordering::SeqCst);
        if m.sleepers.load(Ordering::SeqCst) == 0 {
            return Ok(());
        }
        futex_wake(&m.signalled).map_err(|_| NotifierNotifyError::InternalFailure)
    }
}

impl<E: EventState> FutexWaiter<E> {
    /// Takes a notification if one came; true if it did.
    fn take(&self) -> bool {
        mgmt(self.mgmt).signalled.swap(0, Ordering::SeqCst) != 0
    }

    /// Sleeps until notified or, with a timeout, until it has passed, rounded up to the next
    /// kernel tick (see the module doc).
    fn sleep(&self, timeout: Option<Duration>) -> Result<(), ListenerWaitError> {
        let m = mgmt(self.mgmt);
        let deadline = timeout.map(|t| {
            let end = monotonic_ns().saturating_add(t.as_nanos().min(u64::MAX as u128) as u64);
            end.div_ceil(self.tick_ns.max(1)).checked_mul(self.tick_ns.max(1)).unwrap_or(end)
        });
        loop {
            if self.take() {
                return Ok(());
            }
            if deadline.is_some_and(|d| monotonic_ns() >= d) {
                return Ok(());
            }
            m.sleepers.fetch_add(1, Ordering::SeqCst);
            let slept = futex_wait_until(&m.signalled, deadline);
            m.sleepers.fetch_sub(1, Ordering::SeqCst);
            match slept {
                Ok(()) => {}
                Err(libc::EINTR) => return Err(ListenerWaitError::InterruptSignal),
                Err(_) => return Err(ListenerWaitError::InternalFailure),
            }
        }
    }
}

impl<E: EventState> WaiterInterface<E, FutexMgmt, FutexStorage<E>> for FutexWaiter<E> {
    const IS_FILE_DESCRIPTOR_BASED: bool = false;

    unsafe fn remove(
        _name: &FileName,
        _config: &Configuration,
    ) -> Result<bool, NamedConceptRemoveError> {
        Ok(true) // nothing beside the storage, which the event removes
    }

    fn remove_path_hint(_value: &Path) -> Result<(), NamedConceptPathHintRemoveError> {
        Ok(())
    }

    fn create(
        _name: &FileName,
        _config: &Configuration,
        mgmt: &mut MaybeUninit<FutexMgmt>,
    ) -> Result<Self, ListenerCreateError> {
        let written =
            mgmt.write(FutexMgmt { signalled: AtomicU32::new(0), sleepers: AtomicU32::new(0) });
        let tick_ns = kernel_tick_ns();
        Ok(FutexWaiter { mgmt: NonNull::from(&*written), tick_ns, _state: PhantomData })
    }

    fn try_wait(&self) -> Result<(), ListenerWaitError> {
        self.take();
        Ok(())
    }

    fn timed_wait(&self, timeout: Duration) -> Result<(), ListenerWaitError> {
        self.sleep(Some(timeout))
    }

    fn blocking_wait(&self) -> Result<(), ListenerWaitError> {
        self.sleep(None)
    }

    /// Leaves the word alone: only a wait takes a notification. iceoryx2 drains the event-id
    /// counters after every wait; were the word cleared there, a notifier that had set it
    /// (state PENDING) but not yet marked the state NOTIFIED would find the next wait asleep
    /// and the one after it skip the wake (NOTIFIED) — held until the wait's deadline. A word
    /// left set costs the next wait one early return, no system call.
    fn empty_buffer(&self) -> Result<(), ListenerWaitError> {
        Ok(())
    }
}

/// iceoryx2-cal's counting-bit-set event with the futex wake-up.
pub type FutexShmCountingBitSet = EventImpl<
    RelocatableCountingBitSet,
    FutexMgmt,
    FutexStorage<RelocatableCountingBitSet>,
    FutexHandle<RelocatableCountingBitSet>,
    FutexWaiter<RelocatableCountingBitSet>,
>;

/// iceoryx2's `ipc` service with the futex wake-up: the type of the controller ⇄ hwserver link.
#[derive(Debug, Clone)]
pub struct Link {}

impl iceoryx2::service::Service for Link {
    type StaticStorage = iceoryx2_cal::static_storage::recommended::Ipc;
    type ConfigSerializer = iceoryx2_cal::serialize::recommended::Recommended;
    type PersistentDynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::PersistentIpc<T>;
    type Bag = iceoryx2_cal::bag::recommended::Recommended;
    type DynamicStorage<T: Debug + Send + Sync + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::Ipc<T>;
    type ServiceNameHasher = iceoryx2_cal::hash::recommended::Recommended;
    type SharedMemory = iceoryx2_cal::shared_memory::recommended::Ipc<
        iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator,
    >;
    type ResizableSharedMemory = iceoryx2_cal::resizable_shared_memory::recommended::Ipc<
        iceoryx2_cal::shm_allocator::pool_allocator::PoolAllocator,
    >;
    type Connection = iceoryx2_cal::zero_copy_connection::recommended::Ipc;
    type Event = FutexShmCountingBitSet;
    type Monitoring = iceoryx2_cal::monitoring::recommended::Ipc;
    type Reactor = iceoryx2_cal::reactor::recommended::Ipc;
    type ArcThreadSafetyPolicy<T: Send + Debug + Abandonable> =
        iceoryx2_cal::arc_sync_policy::single_threaded::SingleThreaded<T>;
    type BlackboardMgmt<KeyType: Send + Sync + Debug + ZeroCopySend + 'static> =
        iceoryx2_cal::dynamic_storage::recommended::Ipc<KeyType>;
    type BlackboardPayload = iceoryx2_cal::shared_memory::recommended::Ipc<
        iceoryx2_cal::shm_allocator::bump_allocator::BumpAllocator,
    >;
    type UniqueId = iceoryx2::unique_id_generator::unique_system_id::UniqueSystemId;
}

impl iceoryx2::service::internal::ServiceInternal<Link> for Link {}

#[cfg(test)]
mod tests {
    use crate::service::{IpcLocation, create_node, open_event_service};
    use iceoryx2::prelude::*;
    use std::time::{Duration, Instant};

    /// A test's location, removed when the test ends, passed or failed.
    struct Scratch(IpcLocation, std::path::PathBuf);

    impl Drop for Scratch {
        fn drop(&mut self) {
            self.0.remove_files();
            let _ = std::fs::remove_dir_all(&self.1);
        }
    }

    /// Runs `f` in an iceoryx2 location of this test's own, then checks nothing is left.
    fn with_events(tag: &str, f: impl FnOnce(&IpcLocation)) {
        let dir = std::env::temp_dir().join(format!("qmarc-wake-{tag}-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let loc = IpcLocation::new(
            &format!("qw{tag}{}_", std::process::id()),
            &dir.display().to_string(),
        );
        let scratch = Scratch(loc.clone(), dir);
        f(&loc);
        drop(scratch);
        assert!(loc.files().is_empty());
    }

    fn event(node: &Node<super::Link>, name: &str) -> crate::service::EventService {
        open_event_service(node, name).unwrap()
    }

    #[test]
    fn a_notification_before_the_wait_is_kept_and_an_empty_wait_times_out() {
        with_events("keep", |loc| {
            let node = create_node::<super::Link>("t", loc).unwrap();
            let ev = event(&node, "t/ev");
            let listener = ev.listener_builder().create().unwrap();
            let notifier = ev.notifier_builder().create().unwrap();
            notifier.notify().unwrap();
            // Taken at once though the wait could last a minute.
            assert_eq!(listener.timed_wait(|_| {}, Duration::from_secs(60)).unwrap(), 1);
            // Nothing more: after at most one early return (the word that notification left
            // set), the wait runs out, at least its timeout (the futex's deadline is on the
            // monotonic clock).
            let wait = || listener.timed_wait(|_| {}, Duration::from_millis(20)).unwrap();
            let t0 = Instant::now();
            assert_eq!(wait(), 0);
            if t0.elapsed() < Duration::from_millis(20) {
                let t1 = Instant::now();
                assert_eq!(wait(), 0);
                assert!(t1.elapsed() >= Duration::from_millis(20));
            }
        });
    }

    /// Waits, as the link does, until one notification came: early returns are allowed, a
    /// wait that runs out its 30 s deadline is a lost wake-up.
    fn wait_for_one(listener: &iceoryx2::port::listener::Listener<super::Link>) {
        let t0 = Instant::now();
        let mut got = 0;
        while got == 0 {
            got = listener.timed_wait(|_| {}, Duration::from_secs(30)).unwrap();
            assert!(t0.elapsed() < Duration::from_secs(30), "a wake-up was lost");
        }
        assert_eq!(got, 1);
    }

    #[test]
    fn no_wake_up_is_lost_in_a_ping_pong_between_threads() {
        with_events("pp", |loc| {
            let node = create_node::<super::Link>("t", loc).unwrap();
            let (ping, pong) = (event(&node, "t/ping"), event(&node, "t/pong"));
            let pong_listener = pong.listener_builder().create().unwrap();
            let (loc2, ready) = (loc.clone(), std::sync::Arc::new(std::sync::Barrier::new(2)));
            let ready2 = std::sync::Arc::clone(&ready);
            const ROUNDS: usize = 5_000;
            let echo = std::thread::spawn(move || {
                let node = create_node::<super::Link>("echo", &loc2).unwrap();
                let ping_listener = event(&node, "t/ping").listener_builder().create().unwrap();
                let pong_notifier = event(&node, "t/pong").notifier_builder().create().unwrap();
                ready2.wait();
                for _ in 0..ROUNDS {
                    wait_for_one(&ping_listener);
                    pong_notifier.notify().unwrap();
                }
            });
            ready.wait();
            let ping_notifier = ping.notifier_builder().create().unwrap();
            for _ in 0..ROUNDS {
                ping_notifier.notify().unwrap();
                wait_for_one(&pong_listener);
            }
            echo.join().unwrap();
        });
    }
}

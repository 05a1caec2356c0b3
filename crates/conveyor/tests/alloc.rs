//! The part queue allocates nothing once it has its capacity: detections, claims, sweeps and
//! picks, the queue full and making room, counted by a global allocator on the test's own
//! thread (the test harness's threads allocate as they please, more so on a loaded machine).

use qmarc_conveyor::{Belt, Detection, PartQueue};
use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};

struct Counting;
static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    /// This thread's allocations are counted.
    static COUNTED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

// SAFETY: forwards to the system allocator, counting.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        if COUNTED.with(std::cell::Cell::get) {
            ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
        }
        // SAFETY: the caller's layout, as System requires.
        unsafe { System.alloc(layout) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: allocated by System above with this layout.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

#[test]
fn the_queue_allocates_nothing_once_made() {
    let belt = Belt { mm_per_count: 0.05 };
    let mut q = PartQueue::new([300.0, 500.0], 2.0, 16);
    COUNTED.with(|c| c.set(true));
    let before = ALLOCATIONS.load(Ordering::Relaxed);
    let (mut picked, mut seen) = (0, 0);
    for k in 0..2_000i64 {
        let now = k * 100; // 5 mm of belt a step
        // A new part every 4 steps, across the belt by turns.
        if k % 4 == 0 {
            let across = ((k / 4) % 5) as f64 * 20.0 - 40.0;
            let d = Detection { t_ns: 0, latched_counts: now, belt_mm: 100.0, across_mm: across };
            seen += usize::from(q.detect(d, &belt).is_some());
        }
        if let Some(id) = q.claim_next(now, &belt, |_, at| at >= 300.0) {
            // Picked at once, but for every third: left claimed, to be missed.
            if id % 3 != 0 && q.picked(id) {
                picked += 1;
            }
        }
        q.sweep(now, &belt);
    }
    let during = ALLOCATIONS.load(Ordering::Relaxed) - before;
    COUNTED.with(|c| c.set(false));
    assert_eq!(during, 0, "{during} allocations");
    assert!(seen > 400 && picked > 200, "the queue worked: {seen} seen, {picked} picked");
}

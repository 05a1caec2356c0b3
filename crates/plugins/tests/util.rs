//! Helpers for the loop's integration tests: a counting allocator (per thread), the
//! in-process hardware core, and settings.

use qmarc_config::Settings;
use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::path::Path;

/// Counts every allocation (alloc, alloc_zeroed, realloc) of the calling thread.
pub struct CountingAllocator;

thread_local! {
    static ALLOCATIONS: Cell<u64> = const { Cell::new(0) };
}

fn count() {
    // try_with: the thread-local may already be gone while the thread shuts down.
    let _ = ALLOCATIONS.try_with(|c| c.set(c.get() + 1));
}

// SAFETY: every method forwards to the system allocator unchanged; counting touches only a
// const-initialised thread-local Cell, which never allocates.
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: forwarded with the caller's guarantees.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// Allocations made by the calling thread so far.
pub fn allocations() -> u64 {
    ALLOCATIONS.with(Cell::get)
}

/// The shipped settings.
pub fn settings() -> Settings {
    settings_of("qmarc.toml")
}

/// The shipped settings file `config/<name>`.
pub fn settings_of(name: &str) -> Settings {
    let names = qmarc_config::Names {
        laws: qmarc_plugins::registry::law_names(),
        methods: qmarc_plugins::registry::path_generator_names(),
        any_plugin: false,
    };
    Settings::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config").join(name), &names)
        .unwrap()
}

/// A file of the repository's `knots/`.
pub fn knots(name: &str) -> std::path::PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../knots").join(name)
}

/// The hwserver's core with a lock-step simulated Deltabot, called in-process.
/// The hwserver's core around the simulated Deltabot: the loop's link inside this process.
pub fn sim_core(params: SimParams) -> HwCore {
    HwCore::new(Box::new(SimDeltabot::new(params).unwrap()))
}

/// What the calling thread has done in the kernel: read/write syscalls and blocking waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct ThreadCounters {
    /// Read-type syscalls (`syscr` of /proc/thread-self/io).
    pub syscr: u64,
    /// Write-type syscalls (`syscw`).
    pub syscw: u64,
    /// Times the thread blocked (waiting on a lock, I/O or sleep).
    pub voluntary_switches: u64,
}

fn field(text: &str, name: &str) -> u64 {
    text.lines()
        .find_map(|l| l.strip_prefix(name))
        .and_then(|v| v.trim_start_matches(':').trim().parse().ok())
        .unwrap_or_else(|| panic!("{name} missing"))
}

impl ThreadCounters {
    /// The counters now (reading them costs a few syscalls of its own).
    pub fn now() -> ThreadCounters {
        let io = std::fs::read_to_string("/proc/thread-self/io").unwrap();
        let status = std::fs::read_to_string("/proc/thread-self/status").unwrap();
        ThreadCounters {
            syscr: field(&io, "syscr"),
            syscw: field(&io, "syscw"),
            voluntary_switches: field(&status, "voluntary_ctxt_switches"),
        }
    }

    /// `later − self`.
    pub fn delta(self, later: ThreadCounters) -> ThreadCounters {
        ThreadCounters {
            syscr: later.syscr - self.syscr,
            syscw: later.syscw - self.syscw,
            voluntary_switches: later.voluntary_switches - self.voluntary_switches,
        }
    }
}

/// A private iceoryx2 prefix and root for one test, removed on drop even when the test fails.
pub struct IpcDir {
    /// The location.
    pub location: qmarc_proto::service::IpcLocation,
    dir: std::path::PathBuf,
}

impl IpcDir {
    /// A fresh location named after `test`.
    pub fn new(test: &str) -> IpcDir {
        let pid = std::process::id();
        let dir = std::env::temp_dir().join(format!("qmarc-ctl-{test}-{pid}"));
        let location = qmarc_proto::service::IpcLocation::checked(
            &format!("qc{pid}_{test}_"),
            &format!("{}/", dir.display()),
        )
        .unwrap();
        IpcDir { location, dir }
    }
}

impl Drop for IpcDir {
    fn drop(&mut self) {
        self.location.remove_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// A path of `samples` samples commanding `slope · n` counts to motor 1 at sample `n`.
pub struct Ramp {
    pub slope: f64,
    pub samples: u64,
}

impl qmarc_controller::traj::TrajectoryGenerator for Ramp {
    fn name(&self) -> &'static str {
        "ramp"
    }
    fn start(
        &mut self,
        _: &[f64; qmarc_proto::MAX_MOTORS],
    ) -> Result<(), qmarc_controller::traj::TrajStartError> {
        Ok(())
    }
    fn samples(&self) -> Option<u64> {
        Some(self.samples)
    }
    fn sample(
        &mut self,
        n: u64,
        cmd: &mut [f64; qmarc_proto::MAX_MOTORS],
    ) -> qmarc_controller::traj::Sample {
        if n >= self.samples {
            return qmarc_controller::traj::Sample::Done;
        }
        cmd[0] = self.slope * n as f64;
        qmarc_controller::traj::Sample::Ready
    }
}

/// Prepares `servo` on `link` and runs its first 10 cycles (what is allocated once is
/// allocated then, before anything is counted); returns the prepared move, to cycle on, and
/// what reading the thread's counters costs by itself, which the counted cycles' syscalls are
/// compared with.
pub fn warmed_up<'s>(
    servo: &'s mut qmarc_controller::servo::Servo,
    link: &mut HwCore,
    ticker: &mut qmarc_timer::ManualTicker,
) -> (qmarc_controller::servo::Cycling<'s>, ThreadCounters) {
    use qmarc_timer::Ticker;
    let mut moving = servo.prepare(link).unwrap();
    moving.set_t0(ticker.start().unwrap());
    for _ in 0..10 {
        let end = moving.cycle(link, &ticker.wait().unwrap());
        assert_eq!(end, qmarc_controller::servo::CycleEnd::Continue);
    }
    let (a, b) = (ThreadCounters::now(), ThreadCounters::now());
    (moving, a.delta(b))
}

/// The plan of a move of `n_motors` on a 400 µs period that holds 25 cycles on a starved
/// sample (what the loop's proofs run).
pub fn plan(n_motors: usize) -> qmarc_controller::plan::MovePlan {
    qmarc_controller::plan::MovePlan {
        starve_hold_cycles: 25,
        ..qmarc_controller::plan::MovePlan::new(qmarc_config::Mode::Step, n_motors, 400_000)
    }
}

/// The simulated Deltabot answering in lockstep with the loop.
pub fn lockstep() -> SimParams {
    SimParams { n_motors: 3, lockstep: true, ..SimParams::default() }
}

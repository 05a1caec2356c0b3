//! Real-time set-up of a thread: SCHED_FIFO priority, locked memory, pre-faulted stack.
//!
//! Every step is explicit because each can be refused. SCHED_FIFO needs `CAP_SYS_NICE` or an
//! `RLIMIT_RTPRIO` at least the priority; without it the thread runs SCHED_OTHER with a 1 ns
//! timer slack and [`RtStatus::degraded`] says so, so every result can be stamped "degraded"
//! (the LinuxCNC and ros2_control practice, `../shared/notes/realtime-linux.md`).

use std::fs::File;
use std::io::Write;

/// What a real-time thread asks for.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RtRequest {
    /// SCHED_FIFO priority (1‥99); `None` runs SCHED_OTHER on purpose (not degraded).
    pub priority: Option<i32>,
    /// `mlockall(MCL_CURRENT | MCL_FUTURE)` for the whole process.
    pub lock_memory: bool,
    /// Bytes of stack to touch before the loop so that it never page-faults.
    pub prefault_stack_bytes: usize,
    /// Pin the thread to this CPU (`sched_setaffinity`); `None`: wherever the scheduler puts it.
    pub cpu: Option<usize>,
}

impl Default for RtRequest {
    fn default() -> RtRequest {
        RtRequest {
            priority: Some(80),
            lock_memory: true,
            prefault_stack_bytes: 64 * 1024,
            cpu: None,
        }
    }
}

/// What a thread got.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RtStatus {
    /// The priority asked for, if SCHED_FIFO was asked for.
    pub requested_priority: Option<i32>,
    /// The SCHED_FIFO priority granted; `None` means SCHED_OTHER.
    pub fifo_priority: Option<i32>,
    /// Whether `mlockall` succeeded.
    pub memory_locked: bool,
    /// Why something was refused, with the fix; empty when all was granted.
    pub warnings: Vec<String>,
}

impl RtStatus {
    /// True when SCHED_FIFO was asked for and refused.
    pub fn degraded(&self) -> bool {
        self.requested_priority.is_some() && self.fifo_priority.is_none()
    }

    /// `SCHED_FIFO 80` or `SCHED_OTHER (degraded)`.
    pub fn policy(&self) -> String {
        match (self.fifo_priority, self.degraded()) {
            (Some(p), _) => format!("SCHED_FIFO {p}"),
            (None, true) => "SCHED_OTHER (degraded)".to_string(),
            (None, false) => "SCHED_OTHER".to_string(),
        }
    }
}

/// Locks all current and future pages of the process in RAM.
pub fn lock_memory() -> Result<(), i32> {
    use nix::sys::mman::{MlockAllFlags, mlockall};
    mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|e| e as i32)
}

/// Raises the soft `RLIMIT_RTPRIO` to the hard limit, as cyclictest does, so that an
/// unprivileged user with an `rtprio` entry in limits.conf gets SCHED_FIFO.
pub fn raise_rtprio_limit() {
    use nix::sys::resource::{Resource, getrlimit, setrlimit};
    if let Ok((soft, hard)) = getrlimit(Resource::RLIMIT_RTPRIO)
        && soft < hard
    {
        let _ = setrlimit(Resource::RLIMIT_RTPRIO, hard, hard);
    }
}

/// Makes the calling thread SCHED_FIFO at `priority`.
pub fn set_current_thread_fifo(priority: i32) -> Result<(), i32> {
    let param = libc::sched_param { sched_priority: priority };
    // SAFETY: pthread_self() is the calling thread; `param` is valid. (nix has no wrapper for
    // pthread_setschedparam.)
    let rc = unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) };
    if rc == 0 { Ok(()) } else { Err(rc) }
}

/// Sets the calling thread's timer slack (`PR_SET_TIMERSLACK`): 1 ns makes a SCHED_OTHER
/// sleeper wake on time instead of up to 50 µs late.
pub fn set_timer_slack_ns(ns: u64) {
    let _ = nix::sys::prctl::set_timerslack(ns as libc::c_ulong);
}

/// Touches `bytes` of stack (in 16 KiB frames) so that the loop never faults a stack page.
pub fn prefault_stack(bytes: usize) {
    const FRAME: usize = 16 * 1024;
    #[inline(never)]
    fn touch(remaining: usize) {
        let mut frame = [0u8; FRAME];
        std::hint::black_box(&mut frame);
        if remaining > FRAME {
            touch(remaining - FRAME);
        }
    }
    if bytes > 0 {
        touch(bytes);
    }
}

/// Pins the calling thread to `cpu` (`sched_setaffinity` on a stack `CpuSet`: no allocation,
/// so a child forked from a threaded process may call it too).
pub fn pin_current_thread(cpu: usize) -> nix::Result<()> {
    let mut set = nix::sched::CpuSet::new();
    set.set(cpu)?;
    nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set)
}

/// Applies `req` to the calling thread (and `mlockall` to the process) and reports what was
/// granted. Never fails: refusals become warnings and a degraded status.
pub fn apply_to_current_thread(req: &RtRequest) -> RtStatus {
    let mut status = RtStatus {
        requested_priority: req.priority,
        fifo_priority: None,
        memory_locked: false,
        warnings: Vec::new(),
    };
    if req.lock_memory {
        match lock_memory() {
            Ok(()) => status.memory_locked = true,
            Err(e) => status.warnings.push(format!(
                "mlockall failed (errno {e}): pages may fault in the loop; raise RLIMIT_MEMLOCK \
                 (`memlock` in /etc/security/limits.conf)"
            )),
        }
    }
    if let Some(prio) = req.priority {
        raise_rtprio_limit();
        match set_current_thread_fifo(prio) {
            Ok(()) => status.fifo_priority = Some(prio),
            Err(e) => {
                set_timer_slack_ns(1);
                status.warnings.push(format!(
                    "SCHED_FIFO {prio} refused (errno {e}): running SCHED_OTHER, results are \
                     degraded; fix: run as root, `setcap cap_sys_nice+ep` on the binary, an \
                     `rtprio` entry in /etc/security/limits.conf, or systemd `LimitRTPRIO=`"
                ));
            }
        }
    } else {
        set_timer_slack_ns(1);
    }
    if let Some(cpu) = req.cpu
        && let Err(e) = pin_current_thread(cpu)
    {
        status.warnings.push(format!(
            "cannot pin the thread to CPU {cpu} ({e}): it runs where the scheduler puts it"
        ));
    }
    prefault_stack(req.prefault_stack_bytes);
    status
}

/// RT throttling as the kernel has it: `Some((runtime_us, period_us))` when real-time tasks
/// may run only `runtime_us` of every `period_us` (Linux's default: 950 000 of 1 000 000), so a
/// SCHED_FIFO thread that never sleeps is stopped for the rest of each period; `None` when it
/// is off (`kernel.sched_rt_runtime_us = -1`) or cannot be read.
pub fn rt_throttling() -> Option<(i64, i64)> {
    let read = |f: &str| -> Option<i64> {
        std::fs::read_to_string(format!("/proc/sys/kernel/{f}")).ok()?.trim().parse().ok()
    };
    let runtime = read("sched_rt_runtime_us")?;
    (runtime >= 0).then_some((runtime, read("sched_rt_period_us")?))
}

/// Spawns a thread named `name` with a stack large enough for `req`, applies `req` in it and
/// runs `f` with the granted status.
pub fn spawn<F, T>(name: &str, req: RtRequest, f: F) -> std::io::Result<std::thread::JoinHandle<T>>
where
    F: FnOnce(RtStatus) -> T + Send + 'static,
    T: Send + 'static,
{
    std::thread::Builder::new()
        .name(name.to_string())
        .stack_size((req.prefault_stack_bytes + 1024 * 1024).next_power_of_two())
        .spawn(move || {
            let status = apply_to_current_thread(&req);
            f(status)
        })
}

/// Makes the calling thread SCHED_OTHER at nice 0, whatever it inherited.
pub fn set_current_thread_normal() -> Result<(), i32> {
    let param = libc::sched_param { sched_priority: 0 };
    // SAFETY: pthread_self() is the calling thread; `param` is valid. (nix has no wrapper for
    // pthread_setschedparam.)
    let rc =
        unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_OTHER, &param) };
    if rc == 0 { Ok(()) } else { Err(rc) }
}

/// Spawns a helper thread named `name` with normal scheduling, on the housekeeping CPUs
/// ([`crate::cpus::keep_off`]). Linux threads inherit their creator's policy and CPU, so a
/// helper spawned by the SCHED_FIFO servo thread (a knot reader) would otherwise compete with
/// it at real-time priority, on its CPU; only the servo thread runs real time.
pub fn spawn_normal<F, T>(name: &str, f: F) -> std::io::Result<std::thread::JoinHandle<T>>
where
    F: FnOnce() -> T + Send + 'static,
    T: Send + 'static,
{
    std::thread::Builder::new().name(name.to_string()).spawn(move || {
        // Refused only for a thread that is not ours to change: it then keeps what it had.
        let _ = set_current_thread_normal();
        crate::cpus::to_housekeeping();
        f()
    })
}

/// Holds `/dev/cpu_dma_latency` at 0 µs while alive (keeps the CPU out of deep C-states).
/// Root only; closing the file restores the default.
#[derive(Debug)]
pub struct DmaLatencyGuard {
    _file: File,
}

impl DmaLatencyGuard {
    /// Requests 0 µs wake-up latency; `None` where the file cannot be opened.
    pub fn request_zero() -> Option<DmaLatencyGuard> {
        let mut file = std::fs::OpenOptions::new().write(true).open("/dev/cpu_dma_latency").ok()?;
        file.write_all(&0i32.to_ne_bytes()).ok()?;
        Some(DmaLatencyGuard { _file: file })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn status_names_the_policy() {
        let mut s = RtStatus {
            requested_priority: Some(80),
            fifo_priority: Some(80),
            memory_locked: true,
            warnings: vec![],
        };
        assert_eq!(s.policy(), "SCHED_FIFO 80");
        assert!(!s.degraded());
        s.fifo_priority = None;
        assert_eq!(s.policy(), "SCHED_OTHER (degraded)");
        assert!(s.degraded());
        s.requested_priority = None;
        assert_eq!(s.policy(), "SCHED_OTHER");
        assert!(!s.degraded());
    }

    /// Issue 10, item 4: a helper spawned by a real-time thread runs SCHED_OTHER.
    #[test]
    fn helper_threads_run_normal_scheduling() {
        let policy = || {
            // SAFETY: sched_getscheduler(0) asks about the calling thread.
            unsafe { libc::sched_getscheduler(0) }
        };
        // As root the spawning thread really is SCHED_FIFO; elsewhere both are SCHED_OTHER.
        let req =
            RtRequest { priority: Some(1), lock_memory: false, prefault_stack_bytes: 0, cpu: None };
        let (parent, child) = spawn("rt-parent", req, move |_| {
            let helper = spawn_normal("helper", policy).unwrap().join().unwrap();
            (policy(), helper)
        })
        .unwrap()
        .join()
        .unwrap();
        assert_eq!(child, libc::SCHED_OTHER, "the helper (its creator: {parent})");
    }

    #[test]
    fn spawned_thread_reports_what_it_got() {
        // SCHED_OTHER on purpose: a unit test must not take the CPU from the other tests.
        let req = RtRequest {
            priority: None,
            lock_memory: false,
            prefault_stack_bytes: 128 * 1024,
            cpu: None,
        };
        let status = spawn("rt-test", req, |s| s).unwrap().join().unwrap();
        assert_eq!(status.fifo_priority, None);
        assert!(!status.degraded());
    }
}

//! Housekeeping CPUs: where the threads that are not real time run once the real-time ones
//! are pinned.
//!
//! Pinning the servo thread (and the hwserver) to a CPU gives them that CPU only if nothing
//! else of ours runs there. A SCHED_OTHER thread cannot preempt them, but on a kernel without
//! full preemption (this VM's `PREEMPT_DYNAMIC` booted as `none`, any non-RT kernel) its
//! system calls — a file written, a page faulted, a process started — hold the CPU until
//! they reach a preemption point, and the real-time thread's wake waits for them
//! (`../shared/notes/realtime-linux.md`). So, as `isolcpus=` does for the whole system, the
//! starter, the controller's main, telemetry and knot threads and the benchmark keep to the
//! other CPUs ([`keep_off`]); a machine with no other CPU keeps them where they were.

use nix::sched::{CpuSet, sched_getaffinity, sched_setaffinity};
use nix::unistd::Pid;
use std::sync::OnceLock;

/// The mask [`keep_off`] gave the process's non-real-time threads, for [`to_housekeeping`].
static HOUSEKEEPING: OnceLock<CpuSet> = OnceLock::new();

/// The CPUs of `set`, in order.
pub fn list(set: &CpuSet) -> Vec<usize> {
    (0..CpuSet::count()).filter(|&c| set.is_set(c).unwrap_or(false)).collect()
}

/// `allowed` without the real-time CPUs `rt`; `None` when that leaves no CPU (or `rt` takes
/// none of them), so the caller keeps `allowed`.
pub fn housekeeping(allowed: &CpuSet, rt: &[usize]) -> Option<CpuSet> {
    let mut rest = *allowed;
    for &cpu in rt {
        if rest.is_set(cpu).unwrap_or(false) {
            rest.unset(cpu).ok()?;
        }
    }
    (rest != *allowed && !list(&rest).is_empty()).then_some(rest)
}

/// Keeps the calling thread — and every thread and process it creates from now on, which
/// inherit its mask — off the real-time CPUs `rt` (`timer.servo_cpu`, `timer.hwserver_cpu`).
/// Call it before spawning anything. Returns the CPUs now allowed, or `None` when there is no
/// other CPU (or none is pinned) and nothing changed. The first call's mask is also the one
/// [`to_housekeeping`] restores in helper threads that a pinned thread spawns.
pub fn keep_off(rt: &[usize]) -> Result<Option<Vec<usize>>, nix::Error> {
    let allowed = sched_getaffinity(Pid::from_raw(0))?;
    let rest = housekeeping(&allowed, rt);
    let recorded = HOUSEKEEPING.get_or_init(|| rest.unwrap_or(allowed));
    match rest {
        Some(_) => {
            sched_setaffinity(Pid::from_raw(0), recorded)?;
            Ok(Some(list(recorded)))
        }
        None => Ok(None),
    }
}

/// Moves the calling thread to the housekeeping CPUs [`keep_off`] recorded (nothing when it
/// was never called). A helper spawned by the pinned servo thread would otherwise inherit its
/// CPU.
pub fn to_housekeeping() {
    if let Some(set) = HOUSEKEEPING.get() {
        let _ = sched_setaffinity(Pid::from_raw(0), set);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn set(cpus: &[usize]) -> CpuSet {
        let mut s = CpuSet::new();
        for &c in cpus {
            s.set(c).unwrap();
        }
        s
    }

    #[test]
    fn housekeeping_is_what_the_real_time_cpus_leave() {
        let two = set(&[0, 1]);
        assert_eq!(housekeeping(&two, &[0]).map(|s| list(&s)), Some(vec![1]));
        assert_eq!(housekeeping(&two, &[0, 0]).map(|s| list(&s)), Some(vec![1]));
        // The split pair on two CPUs leaves none: everything stays where it was.
        assert_eq!(housekeeping(&two, &[0, 1]), None);
        // Nothing pinned, or pinned outside the allowed set: nothing to change.
        assert_eq!(housekeeping(&two, &[]), None);
        assert_eq!(housekeeping(&two, &[5]), None);
        let four = set(&[0, 1, 2, 3]);
        assert_eq!(housekeeping(&four, &[2, 3]).map(|s| list(&s)), Some(vec![0, 1]));
        assert_eq!(list(&set(&[3, 1])), vec![1, 3]);
    }
}

//! [`Progress`]: how far a move has got, in a few bytes of shared memory that the controller
//! writes as it goes and the starter reads: to show homing as it happens, and to say what was
//! reached when the controller dies without a summary.
//!
//! The starter creates the file (`/dev/shm/<prefix>progress`, so it goes with the run's other
//! files) before it spawns the controller, which maps it. The loop only stores to atomics in
//! the mapping: no system call, no allocation, no lock.

use nix::sys::mman::{MapFlags, ProtFlags, mmap, munmap};
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Tells a progress file from anything else at its path.
const MAGIC: u64 = 0x514d_4152_4350_5232; // "QMARCPR2"

#[repr(C)]
struct Block {
    magic: AtomicU64,
    phase: AtomicU32,
    detail: AtomicU32,
    cycle: AtomicU64,
    t0_ns: AtomicU64,
}

/// What the progress file says.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Snapshot {
    /// The move's phase ([`crate::state::Phase::wire`]), 0 before it began.
    pub phase: u32,
    /// What the generator says about where it is (the controller's `TrajectoryGenerator::progress`).
    pub detail: u32,
    /// Servo cycles executed.
    pub cycle: u64,
    /// When tick 0 was due, ns of `CLOCK_MONOTONIC` (0 before the loop began): a telemetry
    /// sample's `time_ns` counts from it in a real-time run.
    pub t0_ns: u64,
}

/// A mapped progress file.
#[derive(Debug)]
pub struct Progress {
    block: NonNull<Block>,
}

// SAFETY: the mapping is only accessed through atomics; it lives until `drop` unmaps it.
unsafe impl Send for Progress {}
// SAFETY: as above: shared access is atomic.
unsafe impl Sync for Progress {}

impl Progress {
    /// The progress file of the run whose iceoryx2 prefix is `prefix`.
    pub fn path(prefix: &str) -> PathBuf {
        Path::new(crate::service::SHM_DIR).join(format!("{prefix}progress"))
    }

    /// What the progress file of the run whose iceoryx2 prefix is `prefix` says now, if it
    /// is there (a reader's one look: the file is mapped and unmapped again).
    pub fn snapshot(prefix: &str) -> Option<Snapshot> {
        Progress::open(&Progress::path(prefix)).ok().map(|p| p.read())
    }

    /// Creates (or clears) the file at `path` and maps it: the starter's side.
    pub fn create(path: &Path) -> std::io::Result<Progress> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)?;
        file.set_len(std::mem::size_of::<Block>() as u64)?;
        let p = Progress::map(&file)?;
        p.block().magic.store(MAGIC, Ordering::Release);
        Ok(p)
    }

    /// Maps an existing progress file: the controller's side.
    pub fn open(path: &Path) -> std::io::Result<Progress> {
        let file = std::fs::OpenOptions::new().read(true).write(true).open(path)?;
        if file.metadata()?.len() < std::mem::size_of::<Block>() as u64 {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "not a progress file",
            ));
        }
        let p = Progress::map(&file)?;
        if p.block().magic.load(Ordering::Acquire) != MAGIC {
            return Err(std::io::Error::new(
                std::io::ErrorKind::InvalidData,
                "not a progress file",
            ));
        }
        Ok(p)
    }

    fn map(file: &std::fs::File) -> std::io::Result<Progress> {
        let len = NonZeroUsize::new(std::mem::size_of::<Block>()).expect("non-empty block");
        // SAFETY: a fresh shared mapping of a file at least `len` bytes long; nothing else in
        // this process maps it, and every access goes through the atomics of `Block`, which
        // is page-aligned by mmap.
        let ptr = unsafe {
            mmap(
                None,
                len,
                ProtFlags::PROT_READ | ProtFlags::PROT_WRITE,
                MapFlags::MAP_SHARED,
                file,
                0,
            )
        }?;
        Ok(Progress { block: ptr.cast() })
    }

    fn block(&self) -> &Block {
        // SAFETY: `block` points into a live mapping of a whole `Block` (see `map`).
        unsafe { self.block.as_ref() }
    }

    /// Records the move's phase.
    #[inline]
    pub fn set_phase(&self, code: u32) {
        self.block().phase.store(code, Ordering::Relaxed);
    }

    /// Records the cycles executed and the generator's detail (one cycle's two stores).
    #[inline]
    pub fn set_cycle(&self, cycle: u64, detail: u32) {
        let b = self.block();
        b.cycle.store(cycle, Ordering::Relaxed);
        b.detail.store(detail, Ordering::Relaxed);
    }

    /// Records when tick 0 is due, ns of `CLOCK_MONOTONIC`.
    pub fn set_t0(&self, t0_ns: u64) {
        self.block().t0_ns.store(t0_ns, Ordering::Relaxed);
    }

    /// What the file says now.
    pub fn read(&self) -> Snapshot {
        let b = self.block();
        Snapshot {
            phase: b.phase.load(Ordering::Relaxed),
            detail: b.detail.load(Ordering::Relaxed),
            cycle: b.cycle.load(Ordering::Relaxed),
            t0_ns: b.t0_ns.load(Ordering::Relaxed),
        }
    }
}

impl Drop for Progress {
    fn drop(&mut self) {
        // SAFETY: unmaps the mapping made in `map`, which nothing uses any more.
        let _ = unsafe { munmap(self.block.cast(), std::mem::size_of::<Block>()) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn what_one_side_writes_the_other_reads() {
        let path = std::env::temp_dir().join(format!("qmarc-progress-{}", std::process::id()));
        let starter = Progress::create(&path).unwrap();
        assert_eq!(starter.read(), Snapshot::default());
        let controller = Progress::open(&path).unwrap();
        controller.set_phase(3);
        controller.set_cycle(1234, 0x0203);
        controller.set_t0(987_654_321);
        drop(controller);
        let read = starter.read();
        assert_eq!(read, Snapshot { phase: 3, detail: 0x0203, cycle: 1234, t0_ns: 987_654_321 });
        std::fs::write(&path, [0u8; 64]).unwrap();
        assert!(Progress::open(&path).is_err(), "no magic");
        let _ = std::fs::remove_file(&path);
    }
}

//! [`GatherPage`]: the shared-memory file a run's gathered rows live in
//! (`/dev/shm/<prefix>gather`), so that a controller killed mid-move (kill -9, a panic) does
//! not take them with it: its starter maps the file afterwards and writes the rows out, up to
//! the last cycle gathered.
//!
//! The controller creates the file when its move starts (sized for the move's rows, every
//! page touched then), and the loop only copies rows into it and stores to atomics of its
//! header: no system call, no allocation, no lock. The rows are the controller's
//! `GatherRow`, plain numbers (`repr(C)`); the header says their size and how many there are,
//! so a reader of another build refuses the file rather than misread it.

use nix::sys::mman::{MapFlags, ProtFlags, mmap, munmap};
use std::num::NonZeroUsize;
use std::path::{Path, PathBuf};
use std::ptr::NonNull;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering};

/// Tells a gather page from anything else at its path.
const MAGIC: u64 = 0x514d_4152_4347_4131; // "QMARCGA1"

/// The header, at the start of the file; the rows follow at [`ROWS_OFFSET`].
#[repr(C)]
#[derive(Debug)]
pub struct PageHeader {
    magic: AtomicU64,
    /// Size of one row, bytes.
    pub row_size: AtomicU64,
    /// Rows the file has room for.
    pub capacity: AtomicU64,
    /// Rows written (at most `capacity`).
    pub len: AtomicU64,
    /// A ring's oldest row (when it has wrapped), else 0.
    pub oldest: AtomicU64,
    /// Rows that did not fit, or that a ring overwrote.
    pub dropped: AtomicU64,
    /// Gather every N-th cycle.
    pub every: AtomicU32,
    /// Motors per row.
    pub n_motors: AtomicU32,
    /// Which fields the data files carry (the gatherer's bits).
    pub fields: AtomicU32,
    /// The rows are a ring (the last of a session kept).
    pub ring: AtomicU32,
}

/// Where the rows start in the file, bytes (past the header, cache-line aligned).
pub const ROWS_OFFSET: usize = 128;
const _: () = assert!(std::mem::size_of::<PageHeader>() <= ROWS_OFFSET);

/// A mapped gather page.
#[derive(Debug)]
pub struct GatherPage {
    base: NonNull<u8>,
    len: usize,
}

// SAFETY: the mapping lives until `drop` unmaps it; the header is accessed through atomics,
// the rows by the one owner that writes them (the loop) or, after the writer died, the one
// that reads them.
unsafe impl Send for GatherPage {}

impl GatherPage {
    /// The gather page of the run whose iceoryx2 prefix is `prefix`.
    pub fn path(prefix: &str) -> PathBuf {
        Path::new(crate::service::SHM_DIR).join(format!("{prefix}gather"))
    }

    /// Creates (or replaces) the file at `path` with room for `capacity` rows of `row_size`
    /// bytes and maps it, every page touched now: the controller's side, at the move's start.
    pub fn create(path: &Path, row_size: usize, capacity: usize) -> std::io::Result<GatherPage> {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(path)?;
        let len = capacity
            .checked_mul(row_size)
            .and_then(|b| b.checked_add(ROWS_OFFSET))
            .ok_or_else(|| std::io::Error::other("a gather page larger than memory"))?;
        file.set_len(len as u64)?;
        // Every byte given its memory now: a tmpfs file is sparse, and a page the loop
        // touched where /dev/shm had no room left would kill it with SIGBUS mid-move. Short
        // of room, the making fails here, before the move (which then gathers on the heap).
        nix::fcntl::posix_fallocate(&file, 0, len as i64)
            .map_err(|e| std::io::Error::other(format!("reserving {len} bytes: {e}")))?;
        // Populated: the loop never takes a page fault on it.
        let page = GatherPage::map(&file, len, MapFlags::MAP_SHARED | MapFlags::MAP_POPULATE)?;
        let h = page.header();
        h.row_size.store(row_size as u64, Ordering::Relaxed);
        h.capacity.store(capacity as u64, Ordering::Relaxed);
        h.magic.store(MAGIC, Ordering::Release);
        Ok(page)
    }

    /// Maps the existing file at `path` whose rows are `row_size` bytes: the starter's side,
    /// after its controller died. `InvalidData` when it is not a gather page of such rows.
    pub fn open(path: &Path, row_size: usize) -> std::io::Result<GatherPage> {
        let bad = |why: &str| std::io::Error::new(std::io::ErrorKind::InvalidData, why.to_string());
        let file = std::fs::OpenOptions::new().read(true).write(true).open(path)?;
        let len = usize::try_from(file.metadata()?.len()).map_err(|_| bad("too large"))?;
        if len < ROWS_OFFSET {
            return Err(bad("not a gather page"));
        }
        let page = GatherPage::map(&file, len, MapFlags::MAP_SHARED)?;
        let h = page.header();
        let capacity = h.capacity.load(Ordering::Acquire) as usize;
        if h.magic.load(Ordering::Acquire) != MAGIC {
            return Err(bad("not a gather page"));
        }
        if h.row_size.load(Ordering::Acquire) != row_size as u64 {
            return Err(bad("its rows are another build's"));
        }
        if capacity.checked_mul(row_size).and_then(|b| b.checked_add(ROWS_OFFSET)) != Some(len) {
            return Err(bad("its size is not its rows'"));
        }
        Ok(page)
    }

    fn map(file: &std::fs::File, len: usize, flags: MapFlags) -> std::io::Result<GatherPage> {
        let size = NonZeroUsize::new(len).ok_or_else(|| std::io::Error::other("empty page"))?;
        // SAFETY: a fresh shared mapping of a file exactly `len` bytes long; the header is
        // accessed through atomics, the rows as plain numbers by one party at a time.
        let ptr = unsafe {
            mmap(None, size, ProtFlags::PROT_READ | ProtFlags::PROT_WRITE, flags, file, 0)
        }?;
        Ok(GatherPage { base: ptr.cast(), len })
    }

    /// The header.
    pub fn header(&self) -> &PageHeader {
        // SAFETY: the mapping starts with a whole header (its size is checked at compile
        // time against ROWS_OFFSET, and every page is at least that long), page-aligned.
        unsafe { self.base.cast::<PageHeader>().as_ref() }
    }

    /// The rows' memory: [`PageHeader::capacity`] rows of [`PageHeader::row_size`] bytes,
    /// 64-byte aligned.
    pub fn rows(&self) -> NonNull<u8> {
        // SAFETY: ROWS_OFFSET is within the mapping (checked on create and open).
        unsafe { self.base.add(ROWS_OFFSET) }
    }

    /// Rows it has room for.
    pub fn capacity(&self) -> usize {
        self.header().capacity.load(Ordering::Relaxed) as usize
    }
}

impl Drop for GatherPage {
    fn drop(&mut self) {
        // SAFETY: `base` and `len` are the mapping made in `map`, unmapped once, here.
        let _ = unsafe { munmap(self.base.cast(), self.len) };
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_page_is_read_back_as_written_and_refused_when_it_is_another() {
        let path = std::env::temp_dir().join(format!("qmarc-gather-page-{}", std::process::id()));
        let page = GatherPage::create(&path, 24, 10).unwrap();
        // SAFETY: row 3 of 10 rows of 24 bytes, within the mapping.
        unsafe { page.rows().add(3 * 24).write_bytes(7, 24) };
        page.header().len.store(4, Ordering::Release);
        drop(page);
        let read = GatherPage::open(&path, 24).unwrap();
        assert_eq!((read.capacity(), read.header().len.load(Ordering::Acquire)), (10, 4));
        // SAFETY: as above.
        assert_eq!(unsafe { read.rows().add(3 * 24 + 5).read() }, 7);
        let other = GatherPage::open(&path, 32).unwrap_err();
        assert!(other.to_string().contains("another build"), "{other}");
        std::fs::write(&path, [0u8; 200]).unwrap();
        assert!(GatherPage::open(&path, 24).unwrap_err().to_string().contains("not a gather page"));
        let _ = std::fs::remove_file(&path);
    }
}

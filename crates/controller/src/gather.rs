//! Data gathering (thesis 3.4, 4.2): every N-th sample's time, command, actual position and
//! DAC per motor, into a buffer sized before the move (`qmarc-report` writes it to files
//! after it). The buffer is the run's gather page ([`GatherPage`], shared memory) when the
//! move has one, so that a controller killed mid-move leaves its rows to its starter
//! ([`Gather::salvage`]); else the heap.

use qmarc_config::GatherFields;
use qmarc_proto::MAX_MOTORS;
use qmarc_proto::gather_page::GatherPage;
use std::sync::atomic::Ordering;

/// One gathered servo cycle: plain numbers in a fixed layout (`repr(C)`), as the gather page
/// holds them.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
#[repr(C)]
pub struct GatherRow {
    /// Servo sample index n.
    pub cycle: u64,
    /// Time of the sample, s: n·T on the simulated clock, the wake time since tick 0 in real
    /// time.
    pub time_s: f64,
    /// Command position per motor, counts.
    pub cmd: [f64; MAX_MOTORS],
    /// Actual position per motor, counts.
    pub act: [f64; MAX_MOTORS],
    /// DAC code sent per motor.
    pub dac: [i32; MAX_MOTORS],
    /// The gripper's state ([`qmarc_proto::Gripper::code`]: 0 open, 1 closing, 2 closed,
    /// 3 opening, −1 none).
    pub grip: i8,
    /// The belt encoder's counts (the read response's [`qmarc_proto::HwMsg::belt`]).
    pub conv: i64,
}

/// Most memory the gather buffer may take, bytes (`mlockall` keeps it resident).
pub const GATHER_BUDGET_BYTES: u64 = 256 << 20;

/// The gathered rows of a move would not fit [`GATHER_BUDGET_BYTES`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error(
    "gathering every {every} of {samples} cycles needs {bytes} bytes, more than the {budget}-byte \
     budget: gather less often (--gather-every) or shorten the move"
)]
pub struct GatherBudgetError {
    /// Samples of the move.
    pub samples: u64,
    /// Gather every N cycles.
    pub every: u32,
    /// Bytes needed.
    pub bytes: u64,
    /// [`GATHER_BUDGET_BYTES`].
    pub budget: u64,
}

/// Checks that gathering every `every` of `samples` cycles fits the memory budget.
pub fn check_budget(samples: u64, every: u32) -> Result<(), GatherBudgetError> {
    let rows = samples.div_ceil(u64::from(every.max(1)));
    let bytes = rows.saturating_mul(std::mem::size_of::<GatherRow>() as u64);
    if bytes > GATHER_BUDGET_BYTES {
        return Err(GatherBudgetError { samples, every, bytes, budget: GATHER_BUDGET_BYTES });
    }
    Ok(())
}

/// Where the rows are: the heap, or a gather page (shared memory that outlives this process).
enum Rows {
    /// Every slot allocated when the buffer is made.
    Heap(Vec<GatherRow>),
    /// The run's gather page.
    Page(GatherPage),
}

/// The gather buffer. Its capacity is fixed when it is made; [`Gather::push`] never
/// allocates and drops (and counts) rows beyond it, so it can never overflow mid-move.
pub struct Gather {
    rows: Rows,
    /// Rows written.
    len: usize,
    /// Rows it has room for.
    capacity: usize,
    every: u32,
    /// The sample index the next row is due at: the next multiple of `every`.
    next_due: u64,
    n_motors: usize,
    dropped: u64,
    fields: GatherFields,
    /// Full, a row replaces the oldest ([`Gather::keeping_last`]); the oldest row's index.
    ring: Option<usize>,
}

impl std::fmt::Debug for Gather {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gather")
            .field("rows", &self.len)
            .field("capacity", &self.capacity)
            .field("in_page", &matches!(self.rows, Rows::Page(_)))
            .field("every", &self.every)
            .field("dropped", &self.dropped)
            .finish()
    }
}

impl Clone for Gather {
    /// A copy on the heap (a page's rows copied out).
    fn clone(&self) -> Gather {
        let mut rows = self.rows().to_vec();
        rows.resize(self.capacity, GatherRow::default());
        Gather { rows: Rows::Heap(rows), ..*self }
    }
}

impl PartialEq for Gather {
    /// The same rows and the same shape, wherever they are.
    fn eq(&self, other: &Gather) -> bool {
        self.rows() == other.rows()
            && (self.capacity, self.every, self.next_due, self.n_motors, self.dropped)
                == (other.capacity, other.every, other.next_due, other.n_motors, other.dropped)
            && (self.fields, self.ring) == (other.fields, other.ring)
    }
}

/// The fields as the gather page keeps them: one bit each.
fn field_bits(f: GatherFields) -> u32 {
    [f.time, f.cmd, f.act, f.dac, f.grip, f.conv]
        .iter()
        .enumerate()
        .map(|(k, &on)| u32::from(on) << k)
        .sum()
}

/// The fields of `bits` ([`field_bits`]).
fn fields_of(bits: u32) -> GatherFields {
    let on = |k: u32| bits >> k & 1 == 1;
    GatherFields { time: on(0), cmd: on(1), act: on(2), dac: on(3), grip: on(4), conv: on(5) }
}

impl Gather {
    /// A buffer for a move of `samples` servo cycles gathered every `every` cycles.
    pub fn for_move(samples: u64, every: u32, n_motors: usize) -> Gather {
        let every = every.max(1);
        let capacity = samples.div_ceil(u64::from(every)) as usize;
        Gather::with_rows(
            Rows::Heap(vec![GatherRow::default(); capacity]),
            capacity,
            every,
            n_motors,
        )
    }

    /// The same, its rows in a new gather page at `path` (the run's, [`GatherPage::path`]):
    /// they outlive this process. Made before the move (it maps and touches every page).
    pub fn in_page(
        path: &std::path::Path,
        samples: u64,
        every: u32,
        n_motors: usize,
    ) -> std::io::Result<Gather> {
        let every = every.max(1);
        let capacity = samples.div_ceil(u64::from(every)) as usize;
        let page = GatherPage::create(path, std::mem::size_of::<GatherRow>(), capacity)?;
        let g = Gather::with_rows(Rows::Page(page), capacity, every, n_motors);
        g.publish_shape();
        Ok(g)
    }

    fn with_rows(rows: Rows, capacity: usize, every: u32, n_motors: usize) -> Gather {
        Gather {
            rows,
            len: 0,
            capacity,
            every,
            next_due: 0,
            n_motors: n_motors.min(MAX_MOTORS),
            dropped: 0,
            // No gripper unless the move says one is wired, no belt unless it reads one
            // (`with_fields`).
            fields: GatherFields { grip: false, conv: false, ..GatherFields::default() },
            ring: None,
        }
    }

    /// The rows a dead controller left in the gather page at `path`, oldest first, on the
    /// heap; `None` if there is no such page (or it is not one this build reads).
    pub fn salvage(path: &std::path::Path) -> Option<Gather> {
        let page = GatherPage::open(path, std::mem::size_of::<GatherRow>()).ok()?;
        let h = page.header();
        let len = (h.len.load(Ordering::Acquire) as usize).min(page.capacity());
        // SAFETY: the page holds `capacity` rows of GatherRow's size, 64-byte aligned; its
        // writer is dead, and GatherRow is plain numbers (any bit pattern is one).
        let written =
            unsafe { std::slice::from_raw_parts(page.rows().as_ptr().cast::<GatherRow>(), len) };
        let mut g = Gather::with_rows(Rows::Heap(written.to_vec()), len, 1, 0);
        g.len = len;
        g.every = h.every.load(Ordering::Acquire).max(1);
        g.n_motors = (h.n_motors.load(Ordering::Acquire) as usize).min(MAX_MOTORS);
        g.dropped = h.dropped.load(Ordering::Acquire);
        g.fields = fields_of(h.fields.load(Ordering::Acquire));
        let oldest = (h.oldest.load(Ordering::Acquire) as usize).min(len);
        g.ring = (h.ring.load(Ordering::Acquire) == 1).then_some(oldest);
        g.in_order();
        // A ring that has wrapped writes each row over its oldest: the writer killed in that
        // copy leaves the first row half one row, half the next. Not kept.
        if g.dropped > 0 && g.ring.is_some() && g.len > 0 {
            if let Rows::Heap(v) = &mut g.rows {
                v.remove(0);
            }
            g.len -= 1;
            g.capacity -= 1;
            g.dropped += 1;
        }
        Some(g)
    }

    /// The page's header says the buffer's shape (a reader after a crash needs it).
    fn publish_shape(&self) {
        if let Rows::Page(p) = &self.rows {
            let h = p.header();
            h.every.store(self.every, Ordering::Relaxed);
            h.n_motors.store(self.n_motors as u32, Ordering::Relaxed);
            h.fields.store(field_bits(self.fields), Ordering::Relaxed);
            h.ring.store(u32::from(self.ring.is_some()), Ordering::Release);
        }
    }

    /// Whether the rows are in a gather page.
    pub fn in_a_page(&self) -> bool {
        matches!(self.rows, Rows::Page(_))
    }

    /// Every slot, written or not.
    #[inline]
    fn slots(&mut self) -> &mut [GatherRow] {
        match &mut self.rows {
            Rows::Heap(v) => v,
            // SAFETY: the page holds `capacity` rows of GatherRow's size, 64-byte aligned,
            // mapped while `self` lives; only this buffer writes them.
            Rows::Page(p) => unsafe {
                std::slice::from_raw_parts_mut(p.rows().as_ptr().cast::<GatherRow>(), self.capacity)
            },
        }
    }

    /// When full, keeps the last rows (a ring), counting the ones it overwrites as dropped.
    pub fn keeping_last(mut self, keep_last: bool) -> Gather {
        self.ring = keep_last.then_some(0);
        self.publish_shape();
        self
    }

    /// Puts a ring's rows in order, oldest first (after the move: it moves memory).
    pub fn in_order(&mut self) {
        if let Some(oldest) = self.ring.replace(0) {
            let len = self.len;
            self.slots()[..len].rotate_left(oldest);
            if let Rows::Page(p) = &self.rows {
                p.header().oldest.store(0, Ordering::Release);
            }
        }
    }

    /// Writes only `fields` (every row keeps all of them in memory).
    pub fn with_fields(mut self, fields: GatherFields) -> Gather {
        self.fields = fields;
        self.publish_shape();
        self
    }

    /// Gather every N-th cycle.
    pub fn every(&self) -> u32 {
        self.every
    }

    /// Motors per row.
    pub fn n_motors(&self) -> usize {
        self.n_motors
    }

    /// True if the cycle of sample `n` is gathered: the first cycle at or after each multiple
    /// of `every`. Rows stay on the sample grid when periods are missed (a stall that skips
    /// a multiple gathers the first sample after it, and the row says which sample it is);
    /// counting executed cycles instead would drift off it.
    #[inline]
    pub fn due(&self, n: u64) -> bool {
        n >= self.next_due
    }

    /// Stores a row if there is room (never allocates); counts it as dropped otherwise. The
    /// next row is due at the next multiple of `every` after this row's sample.
    #[inline]
    pub fn push(&mut self, row: GatherRow) {
        let every = u64::from(self.every);
        self.next_due = (row.cycle / every).saturating_add(1).saturating_mul(every);
        if self.len < self.capacity {
            let k = self.len;
            self.slots()[k] = row;
            self.len += 1;
        } else {
            self.dropped += 1;
            if let Some(mut oldest) = self.ring.filter(|_| self.len > 0) {
                self.slots()[oldest] = row;
                oldest = (oldest + 1) % self.len;
                self.ring = Some(oldest);
            }
        }
        // What a reader after a crash needs: stores only, no system call.
        if let Rows::Page(p) = &self.rows {
            let h = p.header();
            h.oldest.store(self.ring.unwrap_or(0) as u64, Ordering::Relaxed);
            h.dropped.store(self.dropped, Ordering::Relaxed);
            h.len.store(self.len as u64, Ordering::Release);
        }
    }

    /// The gathered rows (a ring's in memory order until [`Gather::in_order`]).
    pub fn rows(&self) -> &[GatherRow] {
        match &self.rows {
            Rows::Heap(v) => &v[..self.len],
            // SAFETY: as in `slots`; the first `len` rows are written.
            Rows::Page(p) => unsafe {
                std::slice::from_raw_parts(p.rows().as_ptr().cast::<GatherRow>(), self.len)
            },
        }
    }

    /// Rows that did not fit, or that a ring overwrote (0 unless the move ran longer than
    /// planned).
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// Which fields the data files carry.
    pub fn fields(&self) -> GatherFields {
        self.fields
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(cycle: u64) -> GatherRow {
        GatherRow {
            cycle,
            time_s: cycle as f64 * 0.0004,
            cmd: [1000.5, -3.0, 0.0, 0.0],
            act: [998.0, -1.0, 0.0, 0.0],
            dac: [12, -8191, 0, 0],
            grip: 0,
            conv: cycle as i64 * 7,
        }
    }

    #[test]
    fn a_ring_keeps_the_last_rows_in_order() {
        let mut g = Gather::for_move(3, 1, 1).keeping_last(true);
        for c in 0..8 {
            g.push(row(c));
        }
        assert_eq!(g.dropped(), 5);
        g.in_order();
        let cycles: Vec<u64> = g.rows().iter().map(|r| r.cycle).collect();
        assert_eq!(cycles, [5, 6, 7], "the last three, oldest first");
    }

    #[test]
    fn capacity_is_the_gathered_share_of_the_move() {
        let mut g = Gather::for_move(10, 4, 2);
        for k in 0..10 {
            if g.due(k) {
                g.push(row(k));
            }
        }
        assert_eq!((g.rows().len(), g.dropped()), (3, 0));
        g.push(row(99));
        assert_eq!((g.rows().len(), g.dropped()), (3, 1), "full: dropped, not grown");
    }

    /// Issue 42, item 10: rows in a gather page outlive their writer — what another process
    /// reads there after it died is every row written, a ring's oldest first, with the
    /// buffer's shape.
    #[test]
    fn a_pages_rows_are_salvaged_as_written() {
        let path = std::env::temp_dir().join(format!("qmarc-gather-{}", std::process::id()));
        let fields = GatherFields { dac: false, ..GatherFields::default() };
        let mut g = Gather::in_page(&path, 3, 1, 2).unwrap().with_fields(fields).keeping_last(true);
        assert!(g.in_a_page());
        for c in 0..5 {
            g.push(row(c));
        }
        let expected = {
            let mut heap = g.clone();
            heap.in_order();
            heap
        };
        std::mem::forget(g); // as if killed: nothing of the writer runs after its last row
        let salvaged = Gather::salvage(&path).expect("the page");
        let cycles: Vec<u64> = salvaged.rows().iter().map(|r| r.cycle).collect();
        // The wrapped ring's oldest row is left out (its writer may have died copying over
        // it): the last two, oldest first.
        assert_eq!(cycles, [3, 4], "the last rows but a wrapped ring's oldest, oldest first");
        assert_eq!(salvaged.rows(), &expected.rows()[1..]);
        assert_eq!((salvaged.dropped(), salvaged.every(), salvaged.n_motors()), (3, 1, 2));
        assert_eq!(salvaged.fields(), fields);
        assert_eq!(salvaged.rows()[0], row(3), "every number as written");
        let _ = std::fs::remove_file(&path);
        assert!(Gather::salvage(&path).is_none(), "no page, nothing salvaged");
    }

    /// Issue 10, item 13: with `--gather-every N`, rows follow the sample index, not the
    /// executed cycles: after missed periods they stay on the multiples of N (or the first
    /// sample after one the stall skipped), never N executed cycles after the last row.
    #[test]
    fn rows_stay_on_the_sample_grid_after_missed_periods() {
        let mut g = Gather::for_move(40, 4, 1);
        // Executed samples: 0‥5, a stall skips 6‥8, then 9‥13, a stall skips 14‥17, 18‥23.
        let executed = (0..6).chain(9..14).chain(18..24);
        for n in executed {
            if g.due(n) {
                g.push(row(n));
            }
        }
        let cycles: Vec<u64> = g.rows().iter().map(|r| r.cycle).collect();
        assert_eq!(cycles, [0, 4, 9, 12, 18, 20]);
    }
}

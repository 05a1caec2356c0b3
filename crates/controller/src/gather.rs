//! Data gathering (thesis 3.4, 4.2): every N-th sample's time, command, actual position and
//! DAC per motor, into a buffer sized before the move (`qmarc-report` writes it to files
//! after it).

use qmarc_config::GatherFields;
use qmarc_proto::MAX_MOTORS;

/// One gathered servo cycle.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
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

/// The gather buffer. Its capacity is fixed when it is made; [`Gather::push`] never
/// allocates and drops (and counts) rows beyond it, so it can never overflow mid-move.
#[derive(Debug, Clone, PartialEq)]
pub struct Gather {
    rows: Vec<GatherRow>,
    every: u32,
    /// The sample index the next row is due at: the next multiple of `every`.
    next_due: u64,
    n_motors: usize,
    dropped: u64,
    fields: GatherFields,
    /// Full, a row replaces the oldest ([`Gather::keeping_last`]); the oldest row's index.
    ring: Option<usize>,
}

impl Gather {
    /// A buffer for a move of `samples` servo cycles gathered every `every` cycles.
    pub fn for_move(samples: u64, every: u32, n_motors: usize) -> Gather {
        let every = every.max(1);
        let rows = samples.div_ceil(u64::from(every)) as usize;
        Gather {
            rows: Vec::with_capacity(rows),
            every,
            next_due: 0,
            n_motors: n_motors.min(MAX_MOTORS),
            dropped: 0,
            // No gripper unless the move says one is wired (`with_fields`).
            fields: GatherFields { grip: false, ..GatherFields::default() },
            ring: None,
        }
    }

    /// When full, keeps the last rows (a ring), counting the ones it overwrites as dropped.
    pub fn keeping_last(mut self, keep_last: bool) -> Gather {
        self.ring = keep_last.then_some(0);
        self
    }

    /// Puts a ring's rows in order, oldest first (after the move: it moves memory).
    pub fn in_order(&mut self) {
        if let Some(oldest) = self.ring.replace(0) {
            self.rows.rotate_left(oldest);
        }
    }

    /// Writes only `fields` (every row keeps all of them in memory).
    pub fn with_fields(mut self, fields: GatherFields) -> Gather {
        self.fields = fields;
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
        if self.rows.len() < self.rows.capacity() {
            self.rows.push(row);
            return;
        }
        self.dropped += 1;
        if let Some(oldest) = self.ring.as_mut().filter(|_| !self.rows.is_empty()) {
            self.rows[*oldest] = row;
            *oldest = (*oldest + 1) % self.rows.len();
        }
    }

    /// The gathered rows (a ring's in memory order until [`Gather::in_order`]).
    pub fn rows(&self) -> &[GatherRow] {
        &self.rows
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

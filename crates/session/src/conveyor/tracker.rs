//! [`BeltTracker`]: where the belt is, for the command — its encoder's counts followed by a
//! smooth estimate, as industrial conveyor tracking follows its master encoder through a
//! filter.
//!
//! The encoder reads whole counts (0.05 mm at the shipped belt), at the loop's read times,
//! which jitter. A command built on the raw counts steps by a count now and then, and the
//! law's feed-forward differentiates the command: Kaff·CA and Kjff·CJ (tuned for online moves,
//! `config/tuned.toml`) turn one such step into hundreds of DAC codes. So the picker commands
//! the estimate of a type-3 tracking loop whose corrections enter only at its jerk:
//!
//!   ĵ = ω⁴·∫e + 4ω³·e + 6ω²·(ż − v̂) − 4ω·â,   e = z − p̂,
//!
//! with p̂ (counts), v̂, â integrated from ĵ, z the counts read and ż their speed over the
//! last [`SPEED_CYCLES`] reads. The estimate's error obeys (s + ω)⁴ — critically damped —
//! and is zero at any constant speed and, through the integral, at any constant acceleration
//! (a belt changing speed). Since a count's step reaches p̂ only through three integrations,
//! p̂'s jerk carries it divided by about (1/ωT)³. [`TRACK_HZ`] sets ω: 15 Hz follows a change
//! of the belt's speed within a few tenths of a millimetre and keeps the quantisation out of
//! the command's jerk.

/// Reads over which the belt's speed is measured, ż.
pub const SPEED_CYCLES: usize = 32;

/// The tracking loop's bandwidth ω / 2π, Hz.
pub const TRACK_HZ: f64 = 15.0;

/// The largest ω·T the loop runs at: a longer servo period gets a lower bandwidth (the
/// discrete loop is stable only while a period is a small part of its time constant).
pub const MAX_OMEGA_PERIOD: f64 = 0.1;

/// Reads further apart than this many periods (a host stall) restart the loop at the count
/// read and its measured speed: the jerk held over the gap would carry the estimate away.
pub const RESTART_PERIODS: u64 = 8;

/// The belt's estimated position, speed and acceleration ([module docs](self)).
#[derive(Debug, Clone)]
pub struct BeltTracker {
    period_s: f64,
    /// ω⁴, 4ω³, 6ω², 4ω.
    gains: [f64; 4],
    /// The estimate at the last read: counts, counts/s, counts/s²; and the loop's jerk
    /// since, counts/s³.
    now: [f64; 3],
    jerk: f64,
    /// The position estimated at the read before, counts.
    before: f64,
    /// ∫e dt, counts·s.
    integral: f64,
    /// The last [`SPEED_CYCLES`] reads: the sample each was read at and its counts.
    reads: [(u64, i64); SPEED_CYCLES],
    n_reads: usize,
}

impl BeltTracker {
    /// A tracker for reads every `period_s`, at [`TRACK_HZ`] (or [`MAX_OMEGA_PERIOD`] /
    /// `period_s` at a long period).
    pub fn new(period_s: f64) -> BeltTracker {
        let w = (std::f64::consts::TAU * TRACK_HZ).min(MAX_OMEGA_PERIOD / period_s);
        BeltTracker {
            period_s,
            gains: [w.powi(4), 4.0 * w.powi(3), 6.0 * w * w, 4.0 * w],
            now: [0.0; 3],
            jerk: 0.0,
            before: 0.0,
            integral: 0.0,
            reads: [(0, 0); SPEED_CYCLES],
            n_reads: 0,
        }
    }

    /// The read `back` reads ago (0: this cycle's).
    fn read_at(&self, back: usize) -> (u64, i64) {
        let k = self.n_reads.saturating_sub(1 + back.min(self.n_reads.saturating_sub(1)));
        self.reads[k % SPEED_CYCLES]
    }

    /// The speed of the counts read, counts/s, over the last [`SPEED_CYCLES`] reads.
    pub fn measured_speed(&self) -> f64 {
        let span = self.n_reads.clamp(1, SPEED_CYCLES) - 1;
        // One read (span 0) is the same read twice: n1 = n0, no speed.
        let ((n1, c1), (n0, c0)) = (self.read_at(0), self.read_at(span));
        if n1 <= n0 {
            return 0.0;
        }
        (c1 - c0) as f64 / ((n1 - n0) as f64 * self.period_s)
    }

    /// The belt's position at the last read, counts (the estimate).
    pub fn position(&self) -> f64 {
        self.now[0]
    }

    /// The belt's position at the read before, counts (the estimate then).
    pub fn position_before(&self) -> f64 {
        self.before
    }

    /// The belt's speed at the last read, counts/s (the estimate).
    pub fn speed(&self) -> f64 {
        self.now[1]
    }

    /// The encoder's `counts`, read at sample `n` (after missed periods the reads are more
    /// than a period apart: the estimate is carried over the time between them). Until the
    /// speed can be measured (the first [`SPEED_CYCLES`] reads), and after a gap of more
    /// than [`RESTART_PERIODS`], the estimate restarts at the counts read, at their speed.
    #[inline]
    pub fn read(&mut self, n: u64, counts: i64) {
        let last_n = if self.n_reads == 0 { n } else { self.read_at(0).0 };
        self.reads[self.n_reads % SPEED_CYCLES] = (n, counts);
        self.n_reads += 1;
        let z = counts as f64;
        let speed = self.measured_speed();
        self.before = if self.n_reads == 1 { z } else { self.now[0] };
        let gap = n.saturating_sub(last_n);
        let sound = self.now.iter().chain([&self.jerk, &self.integral]).all(|x| x.is_finite());
        if self.n_reads <= SPEED_CYCLES || gap > RESTART_PERIODS || !sound {
            (self.now, self.jerk, self.integral) = ([z, speed, 0.0], 0.0, 0.0);
            return;
        }
        // The last estimate carried to this read by the loop's jerk; the read corrects the
        // jerk from here on.
        let t = gap as f64 * self.period_s;
        let ([p, v, a], j) = (self.now, self.jerk);
        self.now = [
            p + v * t + a * t * t / 2.0 + j * t * t * t / 6.0,
            v + a * t + j * t * t / 2.0,
            a + j * t,
        ];
        let [k0, k1, k2, k3] = self.gains;
        let e = z - self.now[0];
        self.integral += e * t;
        self.jerk = k0 * self.integral + k1 * e + k2 * (speed - self.now[1]) - k3 * self.now[2];
    }
}

#[cfg(test)]
mod tests;

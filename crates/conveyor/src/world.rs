//! The simulated world at the belt ([`PartFeed`]): a feeder upstream of the camera drops a
//! part on the belt at a steady rate, each at a random place across it and a random
//! orientation, and the belt ([`BeltMotion`]) carries it. Every part's place follows from the
//! feed's seed and the part's number alone, with no state: the simulated camera, and anyone
//! checking it, compute the same parts at any time.

use crate::BeltMotion;

/// The feeder: when parts drop, where, and how they are spread.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PartFeed {
    /// Parts a minute (0: none).
    pub parts_per_min: f64,
    /// The belt coordinate a part drops at, mm.
    pub drop_mm: f64,
    /// How far across the belt parts spread: uniform in ±`spread_mm`/2, mm.
    pub spread_mm: f64,
    /// The random seed.
    pub seed: u64,
}

/// One part as it truly is on the belt.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TruePart {
    /// Its number: 0 for the first the feeder drops.
    pub k: u64,
    /// Along the belt, mm (belt coordinates).
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
    /// Its orientation about the vertical, rad in [0, 2π).
    pub angle_rad: f64,
}

/// SplitMix64's finaliser: a well-mixed 64-bit value of `x`.
fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9e37_79b9_7f4a_7c15);
    x = (x ^ (x >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    x ^ (x >> 31)
}

/// A uniform number in [0, 1) from the stream `stream` of `seed`, draw `k`.
pub fn uniform(seed: u64, stream: u64, k: u64) -> f64 {
    let bits = mix(mix(seed ^ mix(stream)) ^ k) >> 11;
    bits as f64 / (1u64 << 53) as f64
}

/// A standard normal number from the stream `stream` of `seed`, draw `k` (Box–Muller).
pub fn normal(seed: u64, stream: u64, k: u64) -> f64 {
    let u1 = 1.0 - uniform(seed, stream, 2 * k); // (0, 1]: its logarithm is finite
    let u2 = uniform(seed, stream, 2 * k + 1);
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The streams of the feed's random numbers.
const ACROSS: u64 = 1;
const ANGLE: u64 = 2;

impl PartFeed {
    /// Seconds between two parts (∞ with none).
    pub fn interval_s(&self) -> f64 {
        60.0 / self.parts_per_min
    }

    /// Part `k` as it drops: at `drop_mm`, when the feeder drops it (its time, s).
    pub fn dropped(&self, k: u64) -> (f64, TruePart) {
        let across_mm = self.spread_mm * (uniform(self.seed, ACROSS, k) - 0.5);
        let angle_rad = std::f64::consts::TAU * uniform(self.seed, ANGLE, k);
        let part = TruePart { k, belt_mm: self.drop_mm, across_mm, angle_rad };
        (k as f64 * self.interval_s(), part)
    }

    /// Every part on the belt at `t_s` whose belt coordinate is within `[lo, hi]` mm, into
    /// `out` (cleared first), downstream first; allocates only to grow `out`. Parts still on the belt past `hi` are not
    /// looked at: a belt that runs backwards brings none back.
    pub fn on_belt(
        &self,
        belt: &BeltMotion,
        t_s: f64,
        [lo, hi]: [f64; 2],
        out: &mut Vec<TruePart>,
    ) {
        out.clear();
        if !(self.parts_per_min > 0.0 && t_s >= 0.0) {
            return;
        }
        let now = belt.at(t_s).0;
        let newest = (t_s / self.interval_s()).floor() as u64;
        // The newest part has travelled least: going back in time they lie farther down.
        for k in (0..=newest).rev() {
            let (t_k, mut part) = self.dropped(k);
            part.belt_mm += now - belt.at(t_k).0;
            if part.belt_mm > hi {
                break;
            }
            if part.belt_mm >= lo {
                out.push(part);
            }
        }
        out.reverse();
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn feed() -> PartFeed {
        PartFeed { parts_per_min: 120.0, drop_mm: 0.0, spread_mm: 100.0, seed: 7 }
    }

    #[test]
    fn parts_drop_at_the_rate_and_ride_the_belt() {
        let belt = BeltMotion::new(500.0, &[], 2_000.0);
        let mut parts = Vec::new();
        // At 2.1 s five parts have dropped (0, 0.5 … 2 s): 1050, 800, 550, 300 and 50 mm on.
        feed().on_belt(&belt, 2.1, [-1.0, 10_000.0], &mut parts);
        let at: Vec<(u64, f64)> = parts.iter().map(|p| (p.k, p.belt_mm)).collect();
        assert_eq!(at.len(), 5, "{at:?}");
        for ((k, x), (ek, ex)) in
            at.iter().zip([(0, 1050.0), (1, 800.0), (2, 550.0), (3, 300.0), (4, 50.0)])
        {
            assert_eq!(*k, ek);
            assert!((x - ex).abs() < 1e-9, "part {k} at {x}");
        }
        // A window sees only its own.
        feed().on_belt(&belt, 2.1, [200.0, 600.0], &mut parts);
        assert_eq!(parts.iter().map(|p| p.k).collect::<Vec<_>>(), [2, 3]);
        // Before the start, or with no feed, nothing.
        feed().on_belt(&belt, -0.1, [-1e9, 1e9], &mut parts);
        assert!(parts.is_empty());
        PartFeed { parts_per_min: 0.0, ..feed() }.on_belt(&belt, 5.0, [-1e9, 1e9], &mut parts);
        assert!(parts.is_empty());
    }

    #[test]
    fn a_part_is_the_same_part_whoever_asks() {
        let (a, b) = (feed().dropped(41).1, feed().dropped(41).1);
        assert_eq!(a, b);
        assert_ne!(a, feed().dropped(42).1);
        assert_ne!(a, PartFeed { seed: 8, ..feed() }.dropped(41).1);
    }

    /// Across the belt uniform in ±spread/2, the angle uniform in a turn; the noise normal.
    #[test]
    fn the_spreads_have_their_distributions() {
        let n = 20_000;
        let across: Vec<f64> = (0..n).map(|k| feed().dropped(k).1.across_mm).collect();
        assert!(across.iter().all(|a| (-50.0..50.0).contains(a)));
        let mean = across.iter().sum::<f64>() / n as f64;
        let var = across.iter().map(|a| (a - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(
            mean.abs() < 1.5 && (var.sqrt() - 100.0 / 12f64.sqrt()).abs() < 1.0,
            "{mean} {var}"
        );
        let normal: Vec<f64> = (0..n).map(|k| normal(3, 9, k)).collect();
        let mean = normal.iter().sum::<f64>() / n as f64;
        let sd = (normal.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64).sqrt();
        assert!(mean.abs() < 0.03 && (sd - 1.0).abs() < 0.03, "{mean} {sd}");
        let angles = (0..n).map(|k| feed().dropped(k).1.angle_rad);
        assert!(angles.clone().all(|a| (0.0..std::f64::consts::TAU).contains(&a)));
    }
}

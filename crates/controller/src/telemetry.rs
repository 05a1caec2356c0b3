//! The loop's side of the live telemetry: every `every`-th sample index, after the DAC write,
//! a [`TelemetrySample`] goes into a wait-free single-producer ring (rtrb). The loop never
//! waits for it and never fails on it: a full ring drops the sample and counts it. A thread
//! of the controller (`qmarc_telemetry::relay`) empties the ring and publishes the samples
//! over iceoryx2, so that iceoryx2's work — its loan, and opening a connection to a reader
//! that just arrived — never runs in the servo thread.

use qmarc_proto::telemetry::TelemetrySample;

/// Samples the ring holds: more than a second of samples at 2.5 kHz, every cycle.
pub const RING_SAMPLES: usize = 4096;

/// The loop's end of the telemetry ring.
pub struct Telemetry {
    tx: rtrb::Producer<TelemetrySample>,
    every: u64,
    seq: u64,
    dropped: u32,
    last_woke_ns: u64,
}

impl std::fmt::Debug for Telemetry {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Telemetry")
            .field("every", &self.every)
            .field("seq", &self.seq)
            .field("dropped", &self.dropped)
            .finish()
    }
}

/// A ring for a move's telemetry: the loop's end ([`Telemetry`], a sample every `every`-th
/// sample index) and the publisher's.
pub fn ring(every: u32) -> (Telemetry, rtrb::Consumer<TelemetrySample>) {
    let (tx, rx) = rtrb::RingBuffer::new(RING_SAMPLES);
    let t = Telemetry { tx, every: u64::from(every.max(1)), seq: 0, dropped: 0, last_woke_ns: 0 };
    (t, rx)
}

impl Telemetry {
    /// Whether sample index `n` is published.
    #[inline]
    pub fn due(&self, n: u64) -> bool {
        n.is_multiple_of(self.every)
    }

    /// Wake to wake since the previous cycle that reported its wake, ns (0 the first time).
    #[inline]
    pub fn period_ns(&mut self, woke_ns: u64) -> u32 {
        let p = if self.last_woke_ns == 0 { 0 } else { woke_ns.saturating_sub(self.last_woke_ns) };
        self.last_woke_ns = woke_ns;
        u32::try_from(p).unwrap_or(u32::MAX)
    }

    /// Hands `sample` over (its `seq` and `dropped` filled in here), or drops it when the ring
    /// is full. Never waits, never allocates.
    #[inline]
    pub fn offer(&mut self, mut sample: TelemetrySample) {
        sample.seq = self.seq;
        sample.dropped = self.dropped;
        self.seq += 1;
        if self.tx.push(sample).is_err() {
            self.dropped = self.dropped.saturating_add(1);
        }
    }

    /// Samples dropped because the ring was full.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_ring_drops_and_counts_and_every_sample_has_its_number() {
        let (mut t, mut rx) = ring(4);
        assert!(t.due(0) && !t.due(3) && t.due(8));
        for _ in 0..RING_SAMPLES + 5 {
            t.offer(TelemetrySample::default());
        }
        assert_eq!(t.dropped(), 5);
        assert_eq!(rx.slots(), RING_SAMPLES);
        assert_eq!(rx.pop().unwrap().seq, 0);
        // Room again: the next sample goes in, numbered after the dropped ones, which it
        // counts.
        t.offer(TelemetrySample::default());
        let last = (0..RING_SAMPLES).filter_map(|_| rx.pop().ok()).last().unwrap();
        assert_eq!((last.seq, last.dropped), (RING_SAMPLES as u64 + 5, 5));
        assert_eq!((t.period_ns(1_000), t.period_ns(1_400)), (0, 400));
    }
}

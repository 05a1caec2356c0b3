//! The live telemetry of a move ([`crate::telemetry`]): the sample of a cycle, handed to the
//! ring when due, and the last one when the move ends.

use super::Servo;
use qmarc_proto::state::FaultKind;
use qmarc_proto::telemetry::TelemetrySample;
use qmarc_timer::Tick;

impl Servo {
    /// The live sample of sample `n` to the telemetry ring, when it is due.
    #[inline]
    pub(super) fn publish(&mut self, n: u64, tick: &Tick, written_ns: u64, status: u32) {
        let Some(t) = &mut self.telemetry else { return };
        let period_ns = t.period_ns(tick.woke_ns);
        if !t.due(n) {
            return;
        }
        let sample = self.sample_of(n, tick, written_ns, status, period_ns);
        if let Some(t) = &mut self.telemetry {
            t.offer(sample);
        }
    }

    /// The telemetry sample of this cycle.
    #[inline]
    fn sample_of(
        &self,
        n: u64,
        tick: &Tick,
        written_ns: u64,
        status: u32,
        period_ns: u32,
    ) -> TelemetrySample {
        let ns = |v: u64| u32::try_from(v).unwrap_or(u32::MAX);
        TelemetrySample {
            cycle: n,
            time_ns: self.sample_time_ns(n, tick),
            cmd: self.cmd,
            act: self.act,
            following_error: self.last_error(),
            dac: self.dac,
            wake_latency_ns: ns(tick.latency_ns()),
            output_latency_ns: ns(written_ns.saturating_sub(tick.intended_ns)),
            period_ns,
            phase: self.phase.wire(),
            status,
            fault: FaultKind::wire(self.m.fault.map(|f| f.kind)),
            n_motors: self.plan.n_motors as u32,
            gripper: self.grip.0,
            outputs: self.outputs,
            ..TelemetrySample::default()
        }
    }

    /// The move has ended: a last sample with its end (phase, fault), then the ring is let
    /// go, which tells the publisher there is no more. [`Servo::run`] does it; later calls
    /// do nothing.
    pub fn end_telemetry(&mut self) {
        let now = self.clock.now_ns();
        let tick = Tick { index: self.m.last_sample, intended_ns: now, woke_ns: now, missed: 0 };
        let sample = self.sample_of(self.m.last_sample, &tick, 0, 0, 0);
        if let Some(mut t) = self.telemetry.take() {
            t.offer(TelemetrySample { wake_latency_ns: 0, output_latency_ns: 0, ..sample });
            self.telemetry_dropped = t.dropped();
        }
    }
}

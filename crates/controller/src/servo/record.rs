//! The move's record handed over when it ends ([`crate::record::MoveRecord`]).

use super::Servo;
use crate::record::{MoveRecord, Stretch};

impl Servo {
    /// What the move leaves, taken when it has ended: the loop is spent (its gather buffer
    /// and figures move into the record).
    pub fn into_record(self) -> MoveRecord {
        let report = self.generator.report();
        MoveRecord {
            generator: self.generator.name(),
            cycles: self.cycles(),
            planned_samples: self.m.planned_samples,
            fault: self.m.fault,
            failure: report.failure.filter(|_| self.generator_failed()),
            errors: self.m.errors,
            last_error: self.last_error(),
            end_velocity: self.generator.end_velocity(),
            approach: (self.m.lead_in > 0).then_some(Stretch {
                samples: self.m.lead_in,
                cycles: self.m.lead_executed,
                errors: self.m.lead_errors,
            }),
            settle: (self.m.settle_executed > 0).then_some(Stretch {
                samples: self.m.settle_executed,
                cycles: self.m.settle_executed,
                errors: self.m.settle_errors,
            }),
            started_wall_ns: self.t0_wall_ns,
            path_from: self.m.lead_in,
            settle_from: self.m.settle_from,
            homed: self.m.homed,
            homed_frame: report.homed_frame,
            findings: report.findings,
            telemetry_dropped: self.telemetry_dropped(),
            // Moved last: every field above reads the loop whole.
            timing: self.m.timing,
            gather: {
                let mut g = self.m.gather;
                g.in_order();
                g
            },
        }
    }
}

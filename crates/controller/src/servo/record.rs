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
            planned_samples: self.planned_samples,
            fault: self.fault,
            failure: self.failure(),
            errors: self.errors,
            last_error: self.last_error(),
            end_velocity: self.generator.end_velocity(),
            approach: (self.lead_in > 0).then_some(Stretch {
                samples: self.lead_in,
                cycles: self.lead_executed,
                errors: self.lead_errors,
            }),
            settle: (self.settle_executed > 0).then_some(Stretch {
                samples: self.settle_executed,
                cycles: self.settle_executed,
                errors: self.settle_errors,
            }),
            path_from: self.lead_in,
            settle_from: self.settle_from,
            homed: self.homed,
            homed_frame: report.homed_frame,
            findings: report.findings,
            telemetry_dropped: self.telemetry_dropped(),
            // Moved last: every field above reads the loop whole.
            timing: self.timing,
            gather: {
                let mut g = self.gather;
                g.in_order();
                g
            },
        }
    }
}

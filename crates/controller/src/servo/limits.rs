//! The checks of a cycle's command before it reaches the law: a finite number, within the
//! software position limits, and a following error (instantaneous and integrated) within its
//! limits. Each is a `Copy` [`Fault`] of numbers, decided in the cycle.

use super::Servo;
use crate::fault::{Fault, FaultKind};

impl Servo {
    /// A command that is not a finite number (every comparison with NaN is false: no limit
    /// would see it), this cycle; `None` when every motor's is finite.
    #[inline]
    pub(super) fn check_command(&self, n: u64) -> Option<Fault> {
        let m = (0..self.plan.n_motors).find(|&m| !self.cmd[m].is_finite())?;
        Some(Fault { motor: Some(m), value: self.cmd[m], ..Fault::new(FaultKind::BadCommand, n) })
    }

    /// The software position limits (on the command) and the following-error limits, this
    /// cycle; `None` when all hold.
    #[inline]
    pub(super) fn check_limits(&mut self, n: u64) -> Option<Fault> {
        let lim = &self.plan.limits;
        for m in 0..self.plan.n_motors {
            let c = self.cmd[m];
            if let Some(soft) = lim.soft.filter(|_| self.m.homed[m]) {
                let (min, max) = soft[m];
                if c < min || c > max {
                    let limit = if c < min { min } else { max };
                    return Some(Fault {
                        motor: Some(m),
                        value: c,
                        limit,
                        ..Fault::new(FaultKind::SoftwareLimit, n)
                    });
                }
            }
            let fe = c - self.act[m];
            if fe.abs() > lim.max_following_error[m] {
                let limit = lim.max_following_error[m];
                return Some(Fault {
                    motor: Some(m),
                    value: fe,
                    limit,
                    ..Fault::new(FaultKind::FollowingError, n)
                });
            }
            self.m.integrated_error[m] += fe;
            let ie = self.m.integrated_error[m];
            if ie.abs() > lim.max_integrated_error[m] {
                let limit = lim.max_integrated_error[m];
                return Some(Fault {
                    motor: Some(m),
                    value: ie,
                    limit,
                    integrated: true,
                    ..Fault::new(FaultKind::FollowingError, n)
                });
            }
        }
        None
    }
}

//! The simulator's rig for the conformance suite ([`SimRig`]): fresh lock-step robots whose
//! switches trip by driving a motor into them and whose emergency-stop button the rig presses.

use super::{SimDeltabot, SimParams};
use crate::backend::Backend;
use qmarc_proto::MAX_MOTORS;

/// The simulator's rig for the conformance suite: fresh lock-step robots, switches tripped
/// by driving the motor into them, the last robot's emergency-stop button at hand.
#[derive(Debug, Clone, Default)]
pub struct SimRig {
    estop: Option<std::sync::Arc<std::sync::atomic::AtomicBool>>,
}

impl crate::conformance::Rig for SimRig {
    fn backend(&mut self, n_motors: usize, start_counts: f64) -> Box<dyn Backend> {
        let p = SimParams {
            n_motors,
            lockstep: true,
            start_counts: [start_counts; MAX_MOTORS],
            ..SimParams::default()
        };
        let sim = SimDeltabot::new(p).expect("the rig's robot is valid");
        self.estop = Some(sim.estop_button());
        Box::new(sim)
    }

    fn estop(&mut self, open: bool) -> bool {
        let Some(button) = &self.estop else { return false };
        button.store(open, std::sync::atomic::Ordering::Relaxed);
        true
    }

    fn trip_switch(&mut self, core: &mut crate::HwCore, motor: usize, top: bool) {
        use qmarc_proto::{HwMsg, MotorFlags, MsgType};
        core.handle(&HwMsg::request(MsgType::DisableSafety));
        core.handle(&HwMsg::for_motor(MsgType::EnableMotor, motor as u32));
        let mut codes = [0; MAX_MOTORS];
        // The top switch lies toward negative counts on the default robot.
        codes[motor] = if top { -4000 } else { 4000 };
        core.handle(&HwMsg::write_all_dacs(&codes));
        for _ in 0..100_000 {
            let f = MotorFlags(core.handle(&HwMsg::read_all_encoders()).aux[motor]);
            if (top && f.top()) || (!top && f.bottom()) {
                break;
            }
        }
        core.handle(&HwMsg::for_motor(MsgType::DisableMotor, motor as u32));
    }
}

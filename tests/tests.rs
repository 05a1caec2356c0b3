//! End-to-end tests: the real three processes on the simulated Deltabot, plus the
//! repository's tidiness rules.

mod cell;
mod console;
mod conveyor;
mod counting;
mod deltabot;
mod e2e;
mod first_motion;
mod gripper;
mod hardware;
mod live;
mod mcap;
mod online;
mod readme;
mod robustness;
mod safety;
mod serve;
mod telemetry;
mod tidy;
mod trajectories;
mod tune;
mod vision;

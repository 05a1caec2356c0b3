//! The plug-ins of the servo loop: the trajectory generators (the thesis' step, the offline
//! natural cubic spline, the online PVT, homing, the jerk-limited moves from rest to rest —
//! jog and the approach to a path's start — and the open-loop check), the servo law (PID with feed-forward and a
//! notch, thesis eq. 3-1 and 3-2), the motion planner they share ([`motion`]), and the
//! [`registry`] that names them — the settings file, the command line and the console choose
//! from it. The traits they implement are the loop's (`qmarc_controller::traj`,
//! `qmarc_controller::law`); adding one is one type plus one registry line
//! (`docs/extending.md`).
//!
//! ```
//! use qmarc_plugins::registry;
//! assert_eq!(registry::path_generator_names(), ["step", "spline", "pvt", "pick"]);
//! assert!(registry::law("pidff").is_some());
//! ```
#![deny(missing_docs)]

#[doc = include_str!("../../../docs/extending.md")]
pub mod extending {}
pub mod check;
pub mod grip;
pub mod homing;
pub mod linear;
pub mod motion;
pub mod moveto;
pub mod online;
pub mod pick;
pub mod pidff;
pub mod pvt;
pub mod registry;
pub mod source;
pub mod spline;
pub mod step;

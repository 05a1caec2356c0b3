//! One row of the robot's data onto the [`Channels`]: what gather.mcap's writer does for each
//! gathered row and the live server for each telemetry sample — the row as `/qmarc/gather`'s
//! JSON, the joint states and the effector, and the scene when its period has passed.

use crate::channels::{Channels, effector_json, joint_states_cdr, json_integer, json_number};
use crate::scene::{self, BeltLook, PartAt};
use qmarc_config::{GatherFields, Settings};
use qmarc_controller::gather::GatherRow;
use qmarc_kinematics::Robot;
use qmarc_report::files::{Cell, cells_of, columns_of};

/// The scene's period in loop time, ns: 50 Hz (Foxglove plays it back smoothly; the issue
/// asks at least 25 Hz).
pub const SCENE_PERIOD_NS: u64 = 20_000_000;

/// Rows of one shape onto the channels, with what the last row left (the velocity's, the
/// scene's period).
pub struct RowPublisher {
    fields: GatherFields,
    n_motors: usize,
    /// Each column's key as a JSON object starts it: `{"cycle":`, `,"time_s":`, …
    keys: Vec<String>,
    counts_per_rad: f64,
    robot: Option<Robot>,
    text: String,
    /// The last row sampled (joint states, effector).
    last: Option<GatherRow>,
    next_scene_ns: u64,
}

impl RowPublisher {
    /// Rows with `fields` (gather.csv's columns) of the robot of `s`.
    pub fn new(s: &Settings, fields: GatherFields, n_motors: usize) -> RowPublisher {
        let keys = columns_of(fields, n_motors)
            .iter()
            .enumerate()
            .map(|(k, c)| format!("{}\"{c}\":", if k == 0 { "{" } else { "," }))
            .collect();
        RowPublisher {
            fields,
            n_motors,
            keys,
            counts_per_rad: s.counts_per_rad(),
            robot: s.robot(),
            text: String::with_capacity(512),
            last: None,
            next_scene_ns: 0,
        }
    }

    /// Row `r` on `/qmarc/gather` at `ns`: gather.csv's columns and values.
    pub fn gather(&mut self, ch: &Channels, r: &GatherRow, ns: u64) {
        let (out, keys) = (&mut self.text, &self.keys);
        out.clear();
        let mut k = 0;
        let _ = cells_of(self.fields, self.n_motors, r, |c| {
            out.push_str(&keys[k]);
            match c {
                Cell::Int(v) => json_integer(out, v),
                Cell::Float(v) => json_number(out, v),
            }
            k += 1;
            Ok(())
        });
        out.push('}');
        Channels::put(&ch.gather, out.as_bytes(), ns);
    }

    /// Row `r` as the joint states (velocities from the last row sampled) and the effector,
    /// at `ns`.
    pub fn sample(&mut self, ch: &Channels, r: &GatherRow, ns: u64) {
        let n = self.n_motors;
        let rate: Vec<f64> = (0..n)
            .map(|m| match &self.last {
                Some(p) if r.time_s > p.time_s => (r.act[m] - p.act[m]) / (r.time_s - p.time_s),
                _ => 0.0,
            })
            .collect();
        self.last = Some(*r);
        let js = joint_states_cdr(ns, self.counts_per_rad, &r.act[..n], &rate, &r.dac[..n]);
        Channels::put(&ch.joint_states, &js, ns);
        let Some(robot) = &self.robot else { return };
        let of = |c: &[f64; qmarc_proto::MAX_MOTORS]| robot.mm_of(&[c[0], c[1], c[2]]);
        if let (Ok(cmd), Ok(act)) = (of(&r.cmd), of(&r.act)) {
            effector_json(&mut self.text, cmd, act);
            Channels::put(&ch.effector, self.text.as_bytes(), ns);
        }
    }

    /// Whether the scene is due at `loop_ns` of loop time (`always`: the last row's); if so
    /// the next is a period on.
    pub fn scene_due(&mut self, loop_ns: u64, always: bool) -> bool {
        let due = loop_ns >= self.next_scene_ns || always;
        if due {
            self.next_scene_ns = loop_ns + SCENE_PERIOD_NS;
        }
        due
    }

    /// The scene of row `r` at `ns`: the robot, and the belt `belt` with its parts.
    pub fn scene(
        &self,
        ch: &Channels,
        r: &GatherRow,
        ns: u64,
        belt: Option<(&BeltLook, &[PartAt])>,
    ) {
        let Some(robot) = &self.robot else { return };
        let act = [r.act[0], r.act[1], r.act[2]];
        let grip = self.fields.grip.then_some(r.grip);
        let mut entities: Vec<_> = scene::deltabot(robot, &act, grip, ns).into_iter().collect();
        if let Some((look, parts)) = belt {
            let at = robot.mm_of(&act).ok().map(|p| p.map(|v| v / 1000.0));
            entities.push(look.entity(parts, at, ns));
        }
        ch.scene.log_with_time(&scene::update(entities), ns);
    }
}

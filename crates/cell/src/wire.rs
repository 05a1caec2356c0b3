//! What the cell's hosts say to each other, as JSON: the cell's belt ([`CellBelt`]), a part
//! ([`WirePart`]), a robot ([`WireMember`]) and its claims ([`WireClaim`]); and whether a
//! robot's settings agree with the cell's belt ([`disagreement`]).

use qmarc_config::Settings;
use qmarc_proto::cell::{CellKind, CellMsg};
use serde::{Deserialize, Serialize};

/// The cell's belt, as its camera's settings describe it: what every robot's must agree with.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CellBelt {
    /// The camera's name for the cell.
    pub cell: String,
    /// The belt's travel in the robots' frames (robots of a cell are mounted alike).
    pub direction: [f64; 3],
    /// The belt encoder's mm per count.
    pub mm_per_count: f64,
    /// The simulated belt: its speed, mm/s, its steps `[t_s, mm_s]` and its acceleration,
    /// mm/s² (a real belt's are not settings).
    pub speed_mm_s: f64,
    /// The simulated belt's speed steps.
    pub speed_steps: Vec<[f64; 2]>,
    /// The simulated belt's acceleration, mm/s².
    pub acceleration_mm_s2: f64,
    /// Where the camera's field ends on the cell's belt, mm: every robot's window is past it.
    pub field_end_mm: f64,
    /// When the cell's world began (the simulated belt at 0), ns of the system clock.
    pub epoch_ns: u64,
}

impl CellBelt {
    /// The belt of the camera's settings `s`, its world begun at `epoch_ns` (system clock).
    pub fn of(cell: &str, s: &Settings, epoch_ns: u64) -> CellBelt {
        let c = &s.conveyor;
        CellBelt {
            cell: cell.to_string(),
            direction: c.direction,
            mm_per_count: c.mm_per_count,
            speed_mm_s: c.speed_mm_s,
            speed_steps: c.speed_steps.clone(),
            acceleration_mm_s2: c.acceleration_mm_s2,
            field_end_mm: s.camera.field_mm[1],
            epoch_ns,
        }
    }
}

/// Why robot settings `s` cannot join the cell whose belt is `b`, if they cannot: the belt's
/// direction or its encoder's scale differ (the robot would place every part wrong); on the
/// simulated robot, the simulated belt differs too; or the robot's window begins before the
/// camera's field ends.
pub fn disagreement(s: &Settings, b: &CellBelt) -> Option<String> {
    let c = &s.conveyor;
    let differs = |a: f64, b: f64| (a - b).abs() > 1e-9 * a.abs().max(b.abs()).max(1.0);
    let here_there = |key: &str, here: String, there: String| {
        format!(
            "conveyor.{key} = {here} in {}, but {there} in cell {}'s belt (its camera's \
             settings): the robots of a cell share one belt",
            s.source.display(),
            b.cell
        )
    };
    if c.direction.iter().zip(b.direction).any(|(a, b)| differs(*a, b)) {
        let v = |d: [f64; 3]| format!("{d:?}");
        return Some(here_there("direction", v(c.direction), v(b.direction)));
    }
    if differs(c.mm_per_count, b.mm_per_count) {
        return Some(here_there(
            "mm_per_count",
            c.mm_per_count.to_string(),
            b.mm_per_count.to_string(),
        ));
    }
    if s.hwserver.backend == qmarc_config::BackendKind::Sim {
        let steps_differ = c.speed_steps.len() != b.speed_steps.len()
            || c.speed_steps
                .iter()
                .zip(&b.speed_steps)
                .any(|(x, y)| differs(x[0], y[0]) || differs(x[1], y[1]));
        if differs(c.speed_mm_s, b.speed_mm_s)
            || steps_differ
            || differs(c.acceleration_mm_s2, b.acceleration_mm_s2)
        {
            return Some(here_there(
                "speed_mm_s, speed_steps and acceleration_mm_s2",
                format!("{}, {:?}, {}", c.speed_mm_s, c.speed_steps, c.acceleration_mm_s2),
                format!("{}, {:?}, {}", b.speed_mm_s, b.speed_steps, b.acceleration_mm_s2),
            ));
        }
    }
    let starts = c.window_mm[0] + s.cell.belt_offset_mm;
    (starts < b.field_end_mm).then(|| {
        format!(
            "the window of {} begins at {starts} mm of cell {}'s belt (conveyor.window_mm[0] \
             + cell.belt_offset_mm), before the camera's field ends ({} mm): a robot of a cell \
             is downstream of its camera",
            s.source.display(),
            b.cell,
            b.field_end_mm
        )
    })
}

/// A part the cell's camera saw, once.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct WirePart {
    /// Its number in the cell, 1 up.
    pub id: u32,
    /// Its first exposure, ns of the system clock.
    pub t_ns: u64,
    /// Along the cell's belt then, mm.
    pub belt_mm: f64,
    /// Across the belt, mm.
    pub across_mm: f64,
}

impl WirePart {
    /// As the dispatcher takes it.
    pub fn msg(&self) -> CellMsg {
        let mut m = CellMsg::new(CellKind::Part, self.id, "", self.t_ns);
        (m.belt_mm, m.across_mm) = (self.belt_mm, self.across_mm);
        m
    }
}

/// A robot of the cell.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireMember {
    /// Its name.
    pub robot: String,
    /// Its belt coordinate 0 on the cell's belt, mm.
    pub offset_mm: f64,
    /// Its window, its own belt coordinates, mm.
    pub window_mm: [f64; 2],
}

impl WireMember {
    /// The robot of settings `s`.
    pub fn of(s: &Settings) -> WireMember {
        WireMember {
            robot: s.cell.robot.clone(),
            offset_mm: s.cell.belt_offset_mm,
            window_mm: s.conveyor.window_mm,
        }
    }

    /// As the dispatcher takes it.
    pub fn msg(&self) -> CellMsg {
        let mut m = CellMsg::new(CellKind::Member, 0, &self.robot, 0);
        (m.belt_mm, m.window_mm) = (self.offset_mm, self.window_mm);
        m
    }
}

/// A robot's claim, pick or give-up of a part, or its word that it lets the part pass.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct WireClaim {
    /// `claim`, `picked`, `released` or `passed`.
    pub kind: String,
    /// The part.
    pub part: u32,
    /// The robot.
    pub robot: String,
    /// When, ns of the system clock.
    pub t_ns: u64,
    /// A claim's grip, ns of the system clock.
    pub grip_by_ns: u64,
}

impl WireClaim {
    /// The claim a dispatcher's message says, if it is one.
    pub fn of(m: &CellMsg) -> Option<WireClaim> {
        let kind = match m.kind()? {
            CellKind::Claim => "claim",
            CellKind::Picked => "picked",
            CellKind::Released => "released",
            CellKind::Passed => "passed",
            _ => return None,
        };
        Some(WireClaim {
            kind: kind.into(),
            part: m.part,
            robot: m.robot().to_string(),
            t_ns: m.t_ns,
            grip_by_ns: m.grip_by_ns,
        })
    }

    /// As the dispatcher takes it, if its kind is one.
    pub fn msg(&self) -> Option<CellMsg> {
        let kind = match self.kind.as_str() {
            "claim" => CellKind::Claim,
            "picked" => CellKind::Picked,
            "released" => CellKind::Released,
            "passed" => CellKind::Passed,
            _ => return None,
        };
        let mut m = CellMsg::new(kind, self.part, &self.robot, self.t_ns);
        m.grip_by_ns = self.grip_by_ns;
        Some(m)
    }
}

#[cfg(test)]
mod tests;

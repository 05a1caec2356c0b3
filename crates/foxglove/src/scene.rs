//! The Deltabot drawn as Foxglove's 3-D primitives (`foxglove.SceneUpdate`), from its
//! kinematics at the motors' counts, in the robot's frame (`base`: z up, origin at the base
//! centre, m): the base plate, the three upper arms, each arm's parallelogram of two rods, the
//! effector plate and the gripper's two fingers, open or closed. With a belt: the belt's stretch
//! from the camera's field to past the window, and its parts.

use foxglove::messages::{
    Color, CubePrimitive, CylinderPrimitive, LinePrimitive, Point3, Pose, Quaternion, SceneEntity,
    SceneUpdate, Timestamp, Vector3, line_primitive,
};
use qmarc_config::Settings;
use qmarc_kinematics::{ARMS, Point, Robot};

/// The frame every entity is in.
pub const FRAME: &str = "base";
/// The robot's entity id.
pub const DELTABOT: &str = "deltabot";
/// The belt's entity id (its parts are in it).
pub const BELT: &str = "belt";

/// Half the spacing of a parallelogram's two rods, m.
pub const ROD_HALF_SPACING_M: f64 = 0.03;
/// An upper arm's drawn thickness, m.
pub const ARM_THICKNESS_M: f64 = 0.02;
/// A rod's drawn thickness, m.
pub const ROD_THICKNESS_M: f64 = 0.006;
/// The gripper's fingers: how far each is from the effector's axis, m, by the gripper's state
/// (gather.csv's `grip`: 0 open, 1 closing, 2 closed, 3 opening).
pub const FINGER_OFFSET_M: [f64; 4] = [0.018, 0.012, 0.006, 0.012];
/// A finger's size, m.
pub const FINGER_SIZE_M: [f64; 3] = [0.006, 0.012, 0.03];

/// The gripper's colour by state: green open, amber moving, red closed.
pub const GRIP_COLORS: [[f64; 3]; 4] =
    [[0.2, 0.8, 0.3], [1.0, 0.7, 0.1], [0.9, 0.15, 0.1], [1.0, 0.7, 0.1]];
/// The effector plate's colour.
pub const EFFECTOR_COLOR: [f64; 3] = [0.95, 0.5, 0.1];
/// The upper arms' colour.
pub const ARM_COLOR: [f64; 3] = [0.15, 0.35, 0.8];
/// The rods' colour.
pub const ROD_COLOR: [f64; 3] = [0.75, 0.75, 0.78];
/// A part's colour.
pub const PART_COLOR: [f64; 3] = [0.95, 0.85, 0.1];

fn color([r, g, b]: [f64; 3]) -> Option<Color> {
    Some(Color { r, g, b, a: 1.0 })
}

/// The base plate's colour: see-through, so that the effector shows from above.
pub const BASE_COLOR: Color = Color { r: 0.3, g: 0.3, b: 0.32, a: 0.35 };

fn pose(p: [f64; 3], yaw: f64) -> Option<Pose> {
    let (s, c) = (yaw / 2.0).sin_cos();
    Some(Pose {
        position: Some(Vector3 { x: p[0], y: p[1], z: p[2] }),
        orientation: Some(Quaternion { x: 0.0, y: 0.0, z: s, w: c }),
    })
}

fn size([x, y, z]: [f64; 3]) -> Option<Vector3> {
    Some(Vector3 { x, y, z })
}

fn point(p: &Point) -> Point3 {
    Point3 { x: p.x, y: p.y, z: p.z }
}

/// A timestamp of `ns` since the Unix epoch.
pub fn stamp(ns: u64) -> Timestamp {
    Timestamp::new((ns / 1_000_000_000) as u32, (ns % 1_000_000_000) as u32)
}

/// A flat disc of `radius_m` centred at `at`, `thick_m` thick.
fn disc(at: [f64; 3], radius_m: f64, thick_m: f64, rgb: [f64; 3]) -> CylinderPrimitive {
    CylinderPrimitive {
        pose: pose(at, 0.0),
        size: size([2.0 * radius_m, 2.0 * radius_m, thick_m]),
        bottom_scale: 1.0,
        top_scale: 1.0,
        color: color(rgb),
    }
}

fn lines(points: Vec<Point3>, thickness: f64, rgb: [f64; 3]) -> LinePrimitive {
    LinePrimitive {
        r#type: line_primitive::Type::LineList as i32,
        pose: pose([0.0; 3], 0.0),
        thickness,
        scale_invariant: false,
        points,
        color: color(rgb),
        ..Default::default()
    }
}

/// The Deltabot with its motors at `counts` and its gripper in state `grip` (none: no
/// gripper), stamped `ns`; none where the counts have no pose.
pub fn deltabot(
    robot: &Robot,
    counts: &[f64; ARMS],
    grip: Option<i8>,
    ns: u64,
) -> Option<SceneEntity> {
    let g = &robot.geometry;
    let theta = robot.frame.angles(counts);
    let p = g.forward(&theta).ok()?;
    let mut arms = Vec::with_capacity(2 * ARMS);
    let mut rods = Vec::with_capacity(4 * ARMS);
    for i in 0..ARMS {
        let [shoulder, elbow, wrist] = g.joints(i, theta[i], &p);
        arms.extend([point(&shoulder), point(&elbow)]);
        // The pair spans the arm's axis direction: horizontal, across the arm.
        let phi = g.arm_azimuth_rad[i];
        let side = Point::new(-phi.sin(), phi.cos(), 0.0) * ROD_HALF_SPACING_M;
        for s in [side, -side] {
            rods.extend([point(&(elbow + s)), point(&(wrist + s))]);
        }
    }
    let plate = 0.01;
    let base = CylinderPrimitive {
        color: Some(BASE_COLOR),
        ..disc([0.0, 0.0, plate / 2.0], g.base_radius_m + 0.04, plate, [0.0; 3])
    };
    let mut cylinders =
        vec![base, disc([p.x, p.y, p.z], g.effector_radius_m + 0.01, plate, EFFECTOR_COLOR)];
    let mut cubes = Vec::new();
    if let Some(state) = grip {
        let k = usize::try_from(state).unwrap_or(0).min(3);
        let z = p.z - plate / 2.0 - FINGER_SIZE_M[2] / 2.0;
        for sign in [1.0, -1.0] {
            cubes.push(CubePrimitive {
                pose: pose([p.x + sign * FINGER_OFFSET_M[k], p.y, z], 0.0),
                size: size(FINGER_SIZE_M),
                color: color(GRIP_COLORS[k]),
            });
        }
        // The gripper's body under the plate.
        cylinders.push(disc([p.x, p.y, p.z - plate], 0.012, plate, GRIP_COLORS[k]));
    }
    Some(SceneEntity {
        timestamp: Some(stamp(ns)),
        frame_id: FRAME.to_string(),
        id: DELTABOT.to_string(),
        frame_locked: true,
        lines: vec![
            lines(arms, ARM_THICKNESS_M, ARM_COLOR),
            lines(rods, ROD_THICKNESS_M, ROD_COLOR),
        ],
        cylinders,
        cubes,
        ..Default::default()
    })
}

/// How the belt and its parts are drawn: the conveyor's and the camera's settings.
#[derive(Debug, Clone, PartialEq)]
pub struct BeltLook {
    /// The settings' belt (direction, origin, encoder).
    pub conveyor: qmarc_config::ConveyorSettings,
    /// The stretch drawn, belt coordinates, mm: from the camera's field to past the window.
    pub along_mm: [f64; 2],
    /// Its width, mm.
    pub width_mm: f64,
    /// A part's size (along, across, up), mm.
    pub part_mm: [f64; 3],
}

/// Where a part is: along and across the belt, mm, or held by the gripper.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum PartAt {
    /// On the belt.
    Belt {
        /// Along, mm.
        along_mm: f64,
        /// Across, mm.
        across_mm: f64,
    },
    /// In the gripper.
    Held,
}

impl BeltLook {
    /// The belt of `s`.
    pub fn of(s: &Settings) -> BeltLook {
        let c = &s.conveyor;
        let start = s.camera.field_mm[0].min(c.window_mm[0]) - 100.0;
        BeltLook {
            conveyor: c.clone(),
            along_mm: [start, c.window_mm[1] + 200.0],
            width_mm: s.camera.spread_mm + 120.0,
            part_mm: [30.0, 30.0, s.camera.part_height_mm.max(1.0)],
        }
    }

    /// The belt's heading about z, rad.
    fn yaw(&self) -> f64 {
        self.conveyor.direction[1].atan2(self.conveyor.direction[0])
    }

    /// The belt and `parts` on it (held ones under `effector_m`), stamped `ns`.
    pub fn entity(&self, parts: &[PartAt], effector_m: Option<[f64; 3]>, ns: u64) -> SceneEntity {
        let m = |p: [f64; 3]| p.map(|v| v / 1000.0);
        let c = &self.conveyor;
        let [a, b] = self.along_mm;
        let thick = 20.0;
        let mut cubes = vec![CubePrimitive {
            pose: pose(m(c.point_mm((a + b) / 2.0, 0.0, -thick / 2.0)), self.yaw()),
            size: size(m([b - a, self.width_mm, thick])),
            color: Some(Color { r: 0.2, g: 0.22, b: 0.25, a: 1.0 }),
        }];
        let h = self.part_mm[2];
        for part in parts {
            let centre = match *part {
                PartAt::Belt { along_mm, across_mm } => m(c.point_mm(along_mm, across_mm, h / 2.0)),
                PartAt::Held => match effector_m {
                    Some(e) => [e[0], e[1], e[2] - FINGER_SIZE_M[2] / 2.0 - h / 2000.0],
                    None => continue,
                },
            };
            cubes.push(CubePrimitive {
                pose: pose(centre, self.yaw()),
                size: size(m(self.part_mm)),
                color: color(PART_COLOR),
            });
        }
        SceneEntity {
            timestamp: Some(stamp(ns)),
            frame_id: FRAME.to_string(),
            id: BELT.to_string(),
            frame_locked: true,
            cubes,
            ..Default::default()
        }
    }
}

/// A scene of `entities`.
pub fn update(entities: Vec<SceneEntity>) -> SceneUpdate {
    SceneUpdate { deletions: Vec::new(), entities }
}

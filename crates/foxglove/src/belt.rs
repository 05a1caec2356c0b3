//! The live view's belt and its parts in a conveyor session: what the camera reports (its
//! detection service, which the session's dispatcher reads too), merged into parts as the
//! session's queue merges them, carried along by the belt as the session's status says it
//! moves. The gripper closing with the effector on a part takes it off the belt until the
//! gripper opens again (at the place): a physical rule, true whichever robot's queue numbered
//! the part.

use crate::scene::{BeltLook, PartAt};
use qmarc_config::Settings;
use qmarc_conveyor::{Belt, Detection, PartQueue};
use qmarc_proto::camera::{PartDetection, open_camera_service};
use qmarc_proto::service::{IpcLocation, ServiceError, create_node};
use qmarc_session::wire::ConveyorStatus;
use std::time::Instant;

/// Parts the live view keeps (done ones make room).
const CAPACITY: usize = 256;
/// How close the effector must be to a part's grip point as the gripper closes for the part
/// to be taken as gripped, mm (the session grips within 0.5 mm; a sample or two of motion).
pub const HOLD_MM: f64 = 10.0;

type Subscriber =
    iceoryx2::port::subscriber::Subscriber<iceoryx2::prelude::ipc::Service, PartDetection, ()>;

/// The belt as the live view draws it.
pub struct LiveBelt {
    _node: iceoryx2::prelude::Node<iceoryx2::prelude::ipc::Service>,
    detections: Subscriber,
    queue: PartQueue,
    belt: Belt,
    /// How it is drawn.
    pub look: BeltLook,
    /// The part in the gripper.
    held: Option<u32>,
    /// Parts put down at the place (no longer on the belt), while the queue holds them.
    placed: Vec<u32>,
    /// The session's belt at its last status and when that came.
    status: Option<(ConveyorStatus, Instant)>,
}

impl LiveBelt {
    /// The belt of the session at `location` with the settings `s`: a reader of its camera.
    pub fn open(location: &IpcLocation, s: &Settings) -> Result<LiveBelt, ServiceError> {
        let node = create_node::<iceoryx2::prelude::ipc::Service>("qmarc-foxglove-belt", location)?;
        let service = open_camera_service(&node)?;
        let detections = service
            .subscriber_builder()
            .create()
            .map_err(|e| ServiceError::new("subscriber", qmarc_proto::camera::CAMERA_SERVICE, e))?;
        let merge_mm = (4.0 * s.camera.noise_mm).max(5.0);
        Ok(LiveBelt {
            _node: node,
            detections,
            queue: PartQueue::new(s.conveyor.window_mm, merge_mm, CAPACITY),
            belt: Belt { mm_per_count: s.conveyor.mm_per_count },
            look: BeltLook::of(s),
            held: None,
            placed: Vec::new(),
            status: None,
        })
    }

    /// The session's belt as its status says now.
    pub fn status(&mut self, c: ConveyorStatus) {
        self.status = Some((c, Instant::now()));
    }

    /// The belt's encoder now, counts: the last status carried on at its speed.
    fn counts_now(&self) -> Option<i64> {
        let (c, at) = self.status?;
        let mm = c.belt_mm + c.belt_mm_s * at.elapsed().as_secs_f64();
        Some((mm / self.belt.mm_per_count).round() as i64)
    }

    /// Takes the detections the camera has published (those with the belt's count latched at
    /// the exposure, as the simulated camera latches them) into the parts.
    pub fn receive(&mut self) {
        while let Ok(Some(d)) = self.detections.receive() {
            let d = *d;
            if !d.latched() {
                continue;
            }
            let seen = Detection {
                t_ns: d.exposure_ns,
                latched_counts: d.latched_counts,
                belt_mm: d.belt_mm,
                across_mm: d.across_mm,
            };
            let _ = self.queue.detect(seen, &self.belt);
        }
    }

    /// Where each part is now, with the effector at `effector_mm` (robot frame) and the
    /// gripper in state `grip` (gather.csv's code): on the belt, or held.
    pub fn parts(&mut self, effector_mm: Option<[f64; 3]>, grip: i8) -> Vec<PartAt> {
        let Some(now) = self.counts_now() else { return Vec::new() };
        let up = self.look.part_mm[2];
        let closing = matches!(grip, 1 | 2);
        match (self.held, closing) {
            (Some(id), false) => {
                // Opened: put down at the place.
                self.placed.push(id);
                self.held = None;
            }
            (None, true) => {
                self.held = effector_mm.and_then(|e| self.part_under(e, now, up));
            }
            _ => {}
        }
        self.queue.sweep(now, &self.belt);
        let queue = &self.queue;
        self.placed.retain(|id| queue.part(*id).is_some());
        let end = self.look.along_mm[1];
        self.queue
            .parts()
            .iter()
            .filter_map(|p| {
                if Some(p.id) == self.held {
                    return Some(PartAt::Held);
                }
                let along_mm = p.belt_mm(now, &self.belt);
                (!self.placed.contains(&p.id) && along_mm <= end)
                    .then_some(PartAt::Belt { along_mm, across_mm: p.seen.across_mm })
            })
            .collect()
    }

    /// The part whose grip point is within [`HOLD_MM`] of `effector_mm` with the belt at
    /// `now`.
    fn part_under(&self, effector_mm: [f64; 3], now: i64, up: f64) -> Option<u32> {
        let c = &self.look.conveyor;
        self.queue
            .parts()
            .iter()
            .filter(|p| !self.placed.contains(&p.id))
            .find(|p| {
                let grip = c.point_mm(p.belt_mm(now, &self.belt), p.seen.across_mm, up);
                (0..3).map(|k| (grip[k] - effector_mm[k]).powi(2)).sum::<f64>().sqrt() <= HOLD_MM
            })
            .map(|p| p.id)
    }
}

//! [`SimCamera`]: the simulated camera. It sees the run's world: the belt of `[conveyor]`
//! (the simulated robot's belt, from the same epoch), the parts a feeder drops on it
//! (`camera.parts_per_min`, `spread_mm`, `seed`: [`qmarc_conveyor::world::PartFeed`]), every
//! `1/rate_hz` a frame of the parts within `field_mm`, each position off by a normal error of
//! `noise_mm`, its results `latency_s` after the exposure. Its strobe latches the belt
//! encoder at the exposure ([`PartDetection::LATCHED`]): the count the simulated robot's
//! encoder reads at that point of the belt's travel (`conveyor.mm_per_count`, counts from the
//! belt's start), so a detection says where the part is whenever the encoder reads what —
//! whatever clock the robot runs on.

use crate::{CameraBackend, CameraError, Frame};
use qmarc_config::RunSpec;
use qmarc_conveyor::BeltMotion;
use qmarc_conveyor::world::{PartFeed, TruePart, normal};
use qmarc_proto::camera::PartDetection;
use qmarc_timer::clock::monotonic_now_ns;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// How far upstream of the camera's field the feeder drops the parts, mm: they come into
/// sight whole.
pub const DROP_BEFORE_FIELD_MM: f64 = 100.0;

/// The longest the camera sleeps before it looks at its stop flag again.
const NAP: Duration = Duration::from_millis(20);

/// The simulated camera.
#[derive(Debug, Clone)]
pub struct SimCamera {
    belt: BeltMotion,
    feed: PartFeed,
    field_mm: [f64; 2],
    frame_ns: f64,
    latency_ns: u64,
    noise_mm: f64,
    mm_per_count: f64,
    /// `CLOCK_MONOTONIC` ns of the world's start: the belt at 0, frame 0 exposed.
    epoch_ns: u64,
    next: u64,
    seen: Vec<TruePart>,
}

impl SimCamera {
    /// The camera of the run `spec`, its world from the run's epoch (now, if it has none).
    pub fn of(spec: &RunSpec) -> SimCamera {
        let (c, cam) = (&spec.settings.conveyor, &spec.settings.camera);
        let epoch_ns = if spec.epoch_ns == 0 { monotonic_now_ns() } else { spec.epoch_ns };
        SimCamera {
            belt: BeltMotion::new(c.speed_mm_s, &c.speed_steps, c.acceleration_mm_s2),
            feed: PartFeed {
                parts_per_min: cam.parts_per_min,
                drop_mm: cam.field_mm[0] - DROP_BEFORE_FIELD_MM,
                spread_mm: cam.spread_mm,
                seed: cam.seed,
            },
            field_mm: cam.field_mm,
            frame_ns: 1e9 / cam.rate_hz,
            latency_ns: (cam.latency_s * 1e9).round() as u64,
            noise_mm: cam.noise_mm,
            mm_per_count: c.mm_per_count,
            epoch_ns,
            next: 0,
            seen: Vec::new(),
        }
    }

    /// The parts frame `number` sees, into `out` (no waiting): exposed at its time, each
    /// position with its noise.
    pub fn frame(&mut self, number: u64, out: &mut Vec<PartDetection>) -> Frame {
        let mut seen = std::mem::take(&mut self.seen);
        let (frame, latched_counts) = self.truth(number, self.field_mm, &mut seen);
        out.clear();
        let seed = self.feed.seed;
        // Two noise streams per frame, one along the belt and one across, drawn per part.
        let (along, across) = (4 * number + 3, 4 * number + 4);
        for p in &seen {
            out.push(PartDetection {
                frame: number,
                exposure_ns: frame.exposure_ns,
                latched_counts,
                belt_mm: p.belt_mm + self.noise_mm * normal(seed, along, p.k),
                across_mm: p.across_mm + self.noise_mm * normal(seed, across, p.k),
                angle_rad: p.angle_rad,
                flags: PartDetection::LATCHED,
                in_frame: seen.len() as u32,
            });
        }
        self.seen = seen;
        frame
    }

    /// The parts within `[lo, hi]` mm of the belt when frame `number` was exposed, where they
    /// truly are, into `out`; the frame, and the belt's count latched at its exposure.
    pub fn truth(&self, number: u64, range: [f64; 2], out: &mut Vec<TruePart>) -> (Frame, i64) {
        let since_epoch_ns = (number as f64 * self.frame_ns).round() as u64;
        let frame = Frame { number, exposure_ns: self.epoch_ns + since_epoch_ns };
        let t_s = since_epoch_ns as f64 * 1e-9;
        self.feed.on_belt(&self.belt, t_s, range, out);
        // The encoder's count as the simulated robot's reads it (`SimBelt`).
        let latched_counts = (self.belt.at(t_s).0 / self.mm_per_count).floor() as i64;
        (frame, latched_counts)
    }

    /// Waits for the next frame's results (its exposure and the latency after it); its
    /// number, `None` if `stop` was set first.
    pub fn wait_next(&mut self, stop: &AtomicBool) -> Option<u64> {
        let number = self.next;
        let exposure_ns = self.epoch_ns + (number as f64 * self.frame_ns).round() as u64;
        if !wait_until(stop, exposure_ns + self.latency_ns) {
            return None;
        }
        self.next += 1;
        Some(number)
    }
}

/// Sleeps until `CLOCK_MONOTONIC` reads `at_ns`, looking at `stop` at least every 20 ms;
/// false if it was set first.
pub fn wait_until(stop: &AtomicBool, at_ns: u64) -> bool {
    loop {
        if stop.load(Ordering::Acquire) {
            return false;
        }
        let now = monotonic_now_ns();
        if now >= at_ns {
            return true;
        }
        std::thread::sleep(NAP.min(Duration::from_nanos(at_ns - now)));
    }
}

impl CameraBackend for SimCamera {
    fn name(&self) -> &'static str {
        "sim"
    }

    fn next_frame(
        &mut self,
        out: &mut Vec<PartDetection>,
        stop: &AtomicBool,
    ) -> Result<Option<Frame>, CameraError> {
        Ok(self.wait_next(stop).map(|number| self.frame(number, out)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_config::{Mode, Names, Settings};

    /// The run of a camera at `rate_hz` with the settings `extra` of `[camera]`.
    fn spec(rate_hz: f64, extra: &str) -> RunSpec {
        let toml = format!(
            "[general]\nn_motors = 1\n[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\n\
             kaff = 0.0\n[conveyor]\nspeed_mm_s = 500.0\n[camera]\nfield_mm = [50.0, 250.0]\n\
             rate_hz = {rate_hz}\nparts_per_min = 120.0\n{extra}"
        );
        RunSpec {
            settings: Settings::parse("q.toml".as_ref(), &toml, &Names::any()).unwrap(),
            mode: Mode::Conveyor,
            deterministic: false,
            unpaced: false,
            unhomed: false,
            iox_prefix: "t".into(),
            iox_root: "/tmp".into(),
            epoch_ns: 1_000_000_000,
        }
    }

    /// Parts drop 100 mm before the field every 0.5 s and ride at 500 mm/s: at 1 s (frame 10
    /// at 10 Hz) the parts dropped at 0.5 s and 1 s are at 200 and −50 mm: one in sight.
    #[test]
    fn a_frame_sees_the_parts_in_its_field_where_the_belt_has_carried_them() {
        let mut cam = SimCamera::of(&spec(10.0, "noise_mm = 0.0\n"));
        let mut out = Vec::new();
        let f = cam.frame(10, &mut out);
        assert_eq!(f, Frame { number: 10, exposure_ns: 2_000_000_000 });
        assert_eq!(out.len(), 1, "{out:?}");
        assert!((out[0].belt_mm - 200.0).abs() < 1e-9, "{out:?}");
        assert_eq!((out[0].frame, out[0].in_frame, out[0].latched()), (10, 1, true));
        // The belt has run 500 mm at the exposure: 10 000 counts of the default 0.05 mm.
        assert_eq!(out[0].latched_counts, 10_000);
        // Frame 13 (1.3 s): that part at 350 mm has left the field, the next is at 100 mm.
        cam.frame(13, &mut out);
        assert_eq!(out.len(), 1);
        assert!((out[0].belt_mm - 100.0).abs() < 1e-9, "{out:?}");
    }

    /// The noise is the setting's standard deviation, along and across, and never the same
    /// twice for one part.
    #[test]
    fn the_positions_carry_the_cameras_noise() {
        let mut cam = SimCamera::of(&spec(1000.0, "noise_mm = 0.5\n"));
        let (mut out, mut along, mut across) = (Vec::new(), Vec::new(), Vec::new());
        let mut truth = Vec::new();
        for n in 0..20_000 {
            cam.frame(n, &mut out);
            cam.feed.on_belt(&cam.belt, n as f64 * 1e-3, cam.field_mm, &mut truth);
            for (d, t) in out.iter().zip(&truth) {
                along.push(d.belt_mm - t.belt_mm);
                across.push(d.across_mm - t.across_mm);
            }
        }
        for e in [&along, &across] {
            let n = e.len() as f64;
            let mean = e.iter().sum::<f64>() / n;
            let sd = (e.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n).sqrt();
            assert!(
                n > 10_000.0 && mean.abs() < 0.02 && (sd - 0.5).abs() < 0.02,
                "{n} {mean} {sd}"
            );
        }
    }

    /// A camera waits for its frames' results and stops when told, whatever it waits for.
    #[test]
    fn the_camera_paces_its_frames_and_stops_when_told() {
        let mut s = spec(10.0, "latency_s = 0.02\n");
        s.epoch_ns = monotonic_now_ns();
        let mut cam = SimCamera::of(&s);
        let (stop, mut out) = (AtomicBool::new(false), Vec::new());
        let f = cam.next_frame(&mut out, &stop).unwrap().unwrap();
        assert_eq!(f.number, 0);
        assert!(monotonic_now_ns() >= f.exposure_ns + 20_000_000, "results before the latency");
        stop.store(true, Ordering::Release);
        assert_eq!(cam.next_frame(&mut out, &stop).unwrap(), None);
    }
}

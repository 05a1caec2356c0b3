//! `qmarc-camera` as a process: on a run file it publishes every frame's detections on the
//! run's `qmarc/camera` service — the simulated camera each where the simulated world says
//! the part is, with the belt's count latched; the `images` camera replaying a folder of
//! frames, each part found where it was drawn, at the frames' spacing — until a stop signal
//! ends it with exit 0 and what it saw; a bad run file is refused with 64 before anything is
//! opened.

use qmarc_config::{Mode, Names, RunSpec, Settings};
use qmarc_conveyor::BeltMotion;
use qmarc_proto::camera::{PartDetection, open_camera_service};
use qmarc_proto::service::{IpcLocation, create_node};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

fn camera_bin() -> PathBuf {
    PathBuf::from(env!("CARGO_BIN_EXE_qmarc-camera"))
}

/// A scratch folder of test `name`.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("qmarc-camera-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// Three motors and `camera`'s lines in `[camera]`.
fn settings(camera: &str) -> Settings {
    let motor = "[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n";
    let toml = format!("[general]\nn_motors = 3\n{}[camera]\n{camera}", motor.repeat(3));
    Settings::parse("q.toml".as_ref(), &toml, &Names::any()).unwrap()
}

/// The camera process on `settings` in `dir` until it has sent `want` detections (or 20 s
/// have passed), then stopped with SIGTERM: its detections with when each was received,
/// the run's epoch and what it said. Everything it made in /dev/shm is gone after.
fn serve(
    dir: &Path,
    settings: &Settings,
    want: usize,
) -> (Vec<(Instant, PartDetection)>, u64, String) {
    // Each test its own prefix (tests run in parallel).
    static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);
    let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let prefix = format!("qcamtest{}x{n}_", std::process::id());
    let root = dir.join("iox").display().to_string() + "/";
    let location = IpcLocation::checked(&prefix, &root).unwrap();
    let spec = RunSpec {
        settings: settings.clone(),
        mode: Mode::Conveyor,
        deterministic: false,
        unpaced: false,
        unhomed: false,
        iox_prefix: prefix.clone(),
        iox_root: root.clone(),
        epoch_ns: qmarc_timer::clock::monotonic_now_ns(),
    };
    let run = dir.join("run.json");
    spec.write(&run).unwrap();
    // The reader first: it makes the service the camera then opens.
    let node = create_node::<iceoryx2::prelude::ipc::Service>("camera-test", &location).unwrap();
    let subscriber = open_camera_service(&node).unwrap().subscriber_builder().create().unwrap();
    let mut child = Command::new(camera_bin())
        .arg(format!("--settings={}", run.display()))
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut seen = Vec::new();
    let started = Instant::now();
    while seen.len() < want && started.elapsed() < Duration::from_secs(20) {
        while let Ok(Some(s)) = subscriber.receive() {
            seen.push((Instant::now(), *s.payload()));
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = child.wait().unwrap();
    let mut stderr = String::new();
    std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
    assert_eq!(status.code(), Some(0), "{stderr}");
    assert!(
        stderr.contains("qmarc-camera: stopped:") && stderr.contains("detections sent"),
        "{stderr}"
    );
    drop(subscriber);
    drop(node);
    // iceoryx2 keeps the node's management file in /dev/shm under the prefix: removed too.
    location.remove_files();
    let left: Vec<_> = std::fs::read_dir(qmarc_proto::service::SHM_DIR)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.file_name())
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
    (seen, spec.epoch_ns, stderr)
}

#[test]
fn the_camera_publishes_the_worlds_parts_until_stopped() {
    let dir = scratch("publish");
    let settings =
        settings("rate_hz = 100.0\nparts_per_min = 600.0\nnoise_mm = 0.0\nlatency_s = 0.0\n");
    let (seen, epoch_ns, _) = serve(&dir, &settings, 20);
    let seen: Vec<PartDetection> = seen.into_iter().map(|(_, d)| d).collect();
    assert!(seen.len() >= 20, "{} detections in 20 s", seen.len());
    let c = &settings.conveyor;
    let belt = BeltMotion::new(c.speed_mm_s, &c.speed_steps, c.acceleration_mm_s2);
    for d in &seen {
        let [lo, hi] = settings.camera.field_mm;
        assert!((lo..=hi).contains(&d.belt_mm), "{d:?} outside the field");
        assert!(d.latched(), "the simulated strobe latches the belt");
        // The latched count is the belt's travel at the exposure, in encoder counts.
        let t = (d.exposure_ns - epoch_ns) as f64 * 1e-9;
        let counts = (belt.at(t).0 / c.mm_per_count).floor() as i64;
        assert_eq!(d.latched_counts, counts, "{d:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A folder of frames `<exposure_ns>.png` (drawn here, parts at known places, 200 ms apart)
/// replayed by the `images` camera: each frame's parts found where they were drawn, the
/// frames in order at their spacing, nothing latched (a folder has no encoder: the
/// controller places them by their exposure); the folder done, it waits for its stop.
#[test]
fn a_folder_of_frames_is_replayed_and_its_parts_found() {
    use qmarc_vision::render::{self, PartShape};
    let dir = scratch("replay");
    let frames = dir.join("frames");
    std::fs::create_dir_all(&frames).unwrap();
    let base = settings("backend = \"images\"\n");
    let model = qmarc_camera::images::camera_model(&base.camera.images);
    let look = qmarc_camera::images::sim_look(&base.camera.images, 5);
    let drawn: Vec<Vec<[f64; 3]>> = vec![
        vec![[100.0, 20.0, 10.0]],
        vec![[120.0, 20.0, 10.0], [200.0, -60.0, -45.0]],
        vec![[140.0, 20.0, 10.0], [220.0, -60.0, -45.0]],
    ];
    for (k, parts) in drawn.iter().enumerate() {
        let shapes: Vec<PartShape> = parts
            .iter()
            .map(|p| PartShape {
                at_mm: [p[0], p[1]],
                angle_rad: p[2].to_radians(),
                size_mm: base.camera.images.sim_part_mm,
                height_mm: base.camera.part_height_mm,
            })
            .collect();
        let exposure = 7_000_000_000u64 + 200_000_000 * k as u64;
        render::belt_frame(&model, &shapes, &look)
            .save(frames.join(format!("{exposure}.png")))
            .unwrap();
    }
    // The calibration from the camera's target, as `qmarc-camera calibrate` writes it.
    let cal = qmarc_camera::images::calibration(&base.camera).unwrap();
    let cal_file = dir.join("cal.toml");
    std::fs::write(&cal_file, cal.to_toml("test")).unwrap();
    let settings = settings(&format!(
        "backend = \"images\"\nsource = \"dir:{}\"\ncalibration = \"{}\"\n",
        frames.display(),
        cal_file.display()
    ));
    let (received, _, stderr) = serve(&dir, &settings, 5);
    let seen: Vec<PartDetection> = received.iter().map(|(_, d)| *d).collect();
    assert_eq!(seen.len(), 5, "{seen:?}");
    // Replayed at their pace: the last frame's parts arrive 400 ms of frames after the
    // first's, not all at once — less the first frame's reading and finding, which a loaded
    // machine can hold up by tens of milliseconds (measured: 22 ms under stress-ng).
    let took = received[4].0 - received[0].0;
    assert!(took >= Duration::from_millis(300), "the frames came {took:?} apart");
    assert!(stderr.contains("3 frames, 5 detections sent (images camera)"), "{stderr}");
    for d in &seen {
        let parts = &drawn[d.frame as usize];
        assert_eq!(d.in_frame as usize, parts.len());
        assert!(!d.latched(), "{d:?}");
        let near = parts.iter().any(|p| {
            let mut e = d.angle_rad.to_degrees() - p[2];
            e -= 180.0 * (e / 180.0).round();
            f64::hypot(d.belt_mm - p[0], d.across_mm - p[1]) < 0.5 && e.abs() < 2.0
        });
        assert!(near, "{d:?} is none of {parts:?}");
    }
    let spacing = seen.last().unwrap().exposure_ns - seen[0].exposure_ns;
    assert_eq!(spacing, 400_000_000, "replayed at the frames' spacing");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_bad_run_file_is_refused_with_64() {
    let dir = scratch("bad");
    let run = dir.join("run.json");
    std::fs::write(&run, "{\"not\": \"a run\"}").unwrap();
    let out =
        Command::new(camera_bin()).arg(format!("--settings={}", run.display())).output().unwrap();
    assert_eq!(out.status.code(), Some(64));
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("qmarc-camera: error: ") && stderr.contains("run.json"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

//! `qmarc-camera` as a process: on a run file it publishes every frame's detections on the
//! run's `qmarc/camera` service, each where the simulated world says the part is, with the
//! belt's count latched; a stop signal ends it with exit 0 and what it saw; a bad run file is
//! refused with 64 before anything is opened.

use qmarc_config::{Mode, Names, RunSpec, Settings};
use qmarc_conveyor::BeltMotion;
use qmarc_proto::camera::open_camera_service;
use qmarc_proto::service::{IpcLocation, create_node};
use std::path::PathBuf;
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

#[test]
fn the_camera_publishes_the_worlds_parts_until_stopped() {
    let dir = scratch("publish");
    let toml = "[general]\nn_motors = 3\n[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\n\
                kaff = 0.0\n[[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n\
                [[motor]]\nkp = 1.0\nki = 0.0\nkd = 0.0\nkvff = 0.0\nkaff = 0.0\n\
                [camera]\nrate_hz = 100.0\nparts_per_min = 600.0\nnoise_mm = 0.0\nlatency_s = 0.0\n";
    let settings = Settings::parse("q.toml".as_ref(), toml, &Names::any()).unwrap();
    let prefix = format!("qcamtest{}_", std::process::id());
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
    let c = &settings.conveyor;
    let belt = BeltMotion::new(c.speed_mm_s, &c.speed_steps, c.acceleration_mm_s2);
    let mut seen = Vec::new();
    let started = Instant::now();
    while seen.len() < 20 && started.elapsed() < Duration::from_secs(20) {
        while let Ok(Some(s)) = subscriber.receive() {
            seen.push(*s.payload());
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert!(seen.len() >= 20, "{} detections in 20 s", seen.len());
    for d in &seen {
        let [lo, hi] = settings.camera.field_mm;
        assert!((lo..=hi).contains(&d.belt_mm), "{d:?} outside the field");
        assert!(d.latched(), "the simulated strobe latches the belt");
        // The latched count is the belt's travel at the exposure, in encoder counts.
        let t = (d.exposure_ns - spec.epoch_ns) as f64 * 1e-9;
        let counts = (belt.at(t).0 / c.mm_per_count).floor() as i64;
        assert_eq!(d.latched_counts, counts, "{d:?}");
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
    let _ = std::fs::remove_dir_all(&dir);
    let left: Vec<_> = std::fs::read_dir(qmarc_proto::service::SHM_DIR)
        .unwrap()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with(&prefix))
        .map(|e| e.file_name())
        .collect();
    assert!(left.is_empty(), "left in /dev/shm: {left:?}");
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

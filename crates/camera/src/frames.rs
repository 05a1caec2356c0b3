//! Frames from files and devices: a folder of PNG frames named by their exposures, a PNG
//! read as 8-bit gray, a Video4Linux2 device checked.

use image::GrayImage;
use std::path::{Path, PathBuf};

/// The frames of folder `dir`: its files `<exposure_ns>.png`, in the order of their
/// exposures (ns of `CLOCK_MONOTONIC` when recorded; replayed at their spacing). Any other
/// file is refused, naming it; so is a folder with no frame.
pub fn in_folder(dir: &Path) -> Result<Vec<(u64, PathBuf)>, String> {
    let entries = std::fs::read_dir(dir).map_err(|e| format!("dir:{}: {e}", dir.display()))?;
    let mut frames = Vec::new();
    for entry in entries {
        let path = entry.map_err(|e| format!("dir:{}: {e}", dir.display()))?.path();
        let name = path.file_name().and_then(|n| n.to_str()).unwrap_or_default();
        let exposure = name.strip_suffix(".png").and_then(|n| n.parse::<u64>().ok());
        match exposure {
            Some(ns) => frames.push((ns, path)),
            None => {
                return Err(format!(
                    "dir:{}: `{name}` is not a frame: frames are named <exposure_ns>.png",
                    dir.display()
                ));
            }
        }
    }
    if frames.is_empty() {
        return Err(format!("dir:{}: no frames (<exposure_ns>.png) in the folder", dir.display()));
    }
    frames.sort();
    Ok(frames)
}

/// The PNG at `path` as 8-bit gray (a color frame's luma).
pub fn read_png(path: &Path) -> Result<GrayImage, String> {
    let img = image::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    Ok(img.to_luma8())
}

/// Why the Video4Linux2 device `dev` cannot be used: it does not exist, or (a build without
/// the `v4l2` feature) this program does not capture from devices.
pub fn v4l2_refused(dev: &Path) -> Option<String> {
    if !dev.exists() {
        Some(format!("v4l2:{}: no such device", dev.display()))
    } else if cfg!(feature = "v4l2") {
        None
    } else {
        Some(format!(
            "v4l2:{}: this qmarc-camera was built without V4L2 capture: build it with \
             `--features qmarc-camera/v4l2` (needs libclang: Debian's libclang-dev; docs/vision.md)",
            dev.display()
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_is_refused_when_it_is_not_there_or_not_built_in() {
        let missing = v4l2_refused(Path::new("/dev/video97"));
        assert_eq!(missing.as_deref(), Some("v4l2:/dev/video97: no such device"));
        let there = v4l2_refused(Path::new("/dev/null"));
        if cfg!(feature = "v4l2") {
            assert_eq!(there, None);
        } else {
            assert!(there.unwrap().contains("built without V4L2 capture"));
        }
    }

    #[test]
    fn a_folder_holds_frames_and_nothing_else() {
        let dir = std::env::temp_dir().join(format!("qmarc-frames-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let e = in_folder(&dir).unwrap_err();
        assert!(e.ends_with("no frames (<exposure_ns>.png) in the folder"), "{e}");
        for name in ["300.png", "20.png", "1000.png"] {
            std::fs::write(dir.join(name), b"").unwrap();
        }
        let frames: Vec<u64> = in_folder(&dir).unwrap().into_iter().map(|f| f.0).collect();
        assert_eq!(frames, [20, 300, 1000], "in the order of their exposures");
        std::fs::write(dir.join("notes.txt"), b"").unwrap();
        let e = in_folder(&dir).unwrap_err();
        assert!(e.contains("`notes.txt` is not a frame"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

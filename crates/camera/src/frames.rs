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

/// Why the Video4Linux2 device `dev` cannot be used: it does not exist, or this build does
/// not capture from devices yet.
pub fn v4l2_refused(dev: &Path) -> String {
    if dev.exists() {
        format!(
            "v4l2:{}: capturing from a V4L2 device is not built in yet (docs/vision.md)",
            dev.display()
        )
    } else {
        format!("v4l2:{}: no such device", dev.display())
    }
}

//! Frames from a Video4Linux2 camera (`source = "v4l2:/dev/videoN"`, the `v4l` crate; built
//! with `--features qmarc-camera/v4l2`): 8-bit gray frames (`GREY`, or the luma of `YUYV`)
//! of `[camera] image_px`, from memory-mapped buffers, each stamped by the driver — its
//! buffer's timestamp, `CLOCK_MONOTONIC` at the exposure (the start of the frame where the
//! driver says so) — as the controller's clock reads it.

use image::GrayImage;
use std::path::Path;
use std::time::Duration;
use v4l::buffer::{Flags, Type};
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

/// How long one wait for a frame lasts before the stop flag is looked at again.
const WAIT: Duration = Duration::from_millis(100);

/// A camera streaming frames.
pub struct V4l2Frames {
    stream: v4l::io::mmap::Stream<'static>,
    fourcc: FourCC,
    size: [u32; 2],
    stride: usize,
    name: String,
}

impl V4l2Frames {
    /// The camera at `dev`, streaming `size` frames; why not (the device named).
    pub fn open(dev: &Path, size: [u32; 2]) -> Result<V4l2Frames, String> {
        let name = format!("v4l2:{}", dev.display());
        let failed = |what: &str, e: std::io::Error| format!("{name}: {what}: {e}");
        if !dev.exists() {
            return Err(format!("{name}: no such device"));
        }
        let device = Device::with_path(dev).map_err(|e| failed("cannot open it", e))?;
        let mut format = None;
        for fourcc in [FourCC::new(b"GREY"), FourCC::new(b"YUYV")] {
            let f = device
                .set_format(&Format::new(size[0], size[1], fourcc))
                .map_err(|e| failed("cannot set its format", e))?;
            if f.fourcc == fourcc {
                format = Some(f);
                break;
            }
        }
        let Some(f) = format else {
            return Err(format!("{name}: it gives neither GREY nor YUYV frames"));
        };
        if [f.width, f.height] != size {
            return Err(format!(
                "{name}: it gives {}×{} frames, camera.image_px is {}×{}",
                f.width, f.height, size[0], size[1]
            ));
        }
        let mut stream = v4l::io::mmap::Stream::with_buffers(&device, Type::VideoCapture, 4)
            .map_err(|e| failed("cannot map its buffers", e))?;
        stream.set_timeout(WAIT);
        Ok(V4l2Frames { stream, fourcc: f.fourcc, size, stride: f.stride as usize, name })
    }

    /// The next frame and its exposure (ns of `CLOCK_MONOTONIC`); `None` when none came
    /// within [`WAIT`].
    pub fn next_frame(&mut self) -> Result<Option<(GrayImage, u64)>, String> {
        let (data, meta) = match self.stream.next() {
            Ok(f) => f,
            Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", self.name)),
        };
        if meta.flags & Flags::TIMESTAMP_MASK != Flags::TIMESTAMP_MONOTONIC {
            return Err(format!(
                "{}: its frames are not stamped on CLOCK_MONOTONIC (flags {})",
                self.name, meta.flags
            ));
        }
        let t = meta.timestamp;
        let exposure = (t.sec as u64) * 1_000_000_000 + (t.usec as u64) * 1_000;
        let [w, h] = self.size.map(|v| v as usize);
        let per_pixel = if self.fourcc == FourCC::new(b"YUYV") { 2 } else { 1 };
        let stride = self.stride.max(w * per_pixel);
        if data.len() < stride * (h - 1) + w * per_pixel {
            return Err(format!(
                "{}: a frame of {} bytes, short of {w}×{h}",
                self.name,
                data.len()
            ));
        }
        let img = GrayImage::from_fn(self.size[0], self.size[1], |x, y| {
            image::Luma([data[y as usize * stride + x as usize * per_pixel]])
        });
        Ok(Some((img, exposure)))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A device that does not exist, and one that is no camera, are refused naming them
    /// (no camera is needed: a machine without one still checks the refusals).
    #[test]
    fn what_is_not_a_camera_is_refused_naming_it() {
        let missing = V4l2Frames::open(Path::new("/dev/video97"), [640, 480]).err();
        assert_eq!(missing.as_deref(), Some("v4l2:/dev/video97: no such device"));
        let null = V4l2Frames::open(Path::new("/dev/null"), [640, 480]).err().unwrap_or_default();
        assert!(null.starts_with("v4l2:/dev/null: cannot "), "{null}");
    }
}

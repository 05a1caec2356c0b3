//! Frames from a Video4Linux2 camera (`source = "v4l2:/dev/videoN"`, the `v4l` crate; built
//! with `--features qmarc-camera/v4l2`): 8-bit gray frames (`GREY`, or the luma of `YUYV`)
//! of `[camera] image_px`, from four memory-mapped buffers, each stamped by the driver on
//! `CLOCK_MONOTONIC` — the controller's clock. A driver that stamps the start of exposure
//! gives the exposure; one that stamps the end of the frame (`V4L2_BUF_FLAG_TSTAMP_SRC_EOF`,
//! UVC's default) is taken back one frame period, the frame's readout. Frames the driver
//! flags as corrupted are skipped.
//!
//! The v4l stream queues the buffer it last gave back before it waits for the next: it must
//! not be called again after a wait that timed out (that buffer would be queued twice). So it
//! waits without a timeout, and is only called once `poll` says a frame is ready; the stop
//! flag is looked at between polls.

use image::GrayImage;
use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use v4l::buffer::{Flags, Type};
use v4l::device::Handle;
use v4l::io::traits::CaptureStream;
use v4l::video::Capture;
use v4l::{Device, Format, FourCC};

/// How long one poll for a frame lasts before the stop flag is looked at again, ms.
const POLL_MS: i32 = 100;

/// A camera streaming frames.
pub struct V4l2Frames {
    stream: v4l::io::mmap::Stream<'static>,
    handle: Arc<Handle>,
    started: bool,
    fourcc: FourCC,
    size: [u32; 2],
    stride: usize,
    /// A frame's period, ns: how far an end-of-frame stamp is after the exposure.
    readout_ns: u64,
    name: String,
}

impl V4l2Frames {
    /// The camera at `dev`, streaming `size` frames at `rate_hz`; why not (the device named).
    pub fn open(dev: &Path, size: [u32; 2], rate_hz: f64) -> Result<V4l2Frames, String> {
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
        let stream = v4l::io::mmap::Stream::with_buffers(&device, Type::VideoCapture, 4)
            .map_err(|e| failed("cannot map its buffers", e))?;
        Ok(V4l2Frames {
            handle: stream.handle(),
            stream,
            started: false,
            fourcc: f.fourcc,
            size,
            stride: f.stride as usize,
            readout_ns: (1e9 / rate_hz).round() as u64,
            name,
        })
    }

    /// The next frame and its exposure (ns of `CLOCK_MONOTONIC`); `None` when `stop` was set
    /// first (or no good frame came within a poll: ask again).
    pub fn next_frame(&mut self, stop: &AtomicBool) -> Result<Option<(GrayImage, u64)>, String> {
        if stop.load(Ordering::Acquire) {
            return Ok(None);
        }
        // Once streaming, a frame is waited for here, never inside the stream.
        if self.started {
            match self.handle.poll(libc::POLLIN, POLL_MS) {
                Ok(0) => return Ok(None),
                Ok(_) => {}
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => return Ok(None),
                Err(e) => return Err(format!("{}: {e}", self.name)),
            }
        }
        // The first call queues the buffers, starts the stream and waits for its first frame.
        self.started = true;
        let (data, meta) = match self.stream.next() {
            Ok(f) => f,
            Err(_) if stop.load(Ordering::Acquire) => return Ok(None),
            Err(e) => return Err(format!("{}: {e}", self.name)),
        };
        if meta.flags.contains(Flags::ERROR) {
            return Ok(None);
        }
        if meta.flags & Flags::TIMESTAMP_MASK != Flags::TIMESTAMP_MONOTONIC {
            return Err(format!(
                "{}: its frames are not stamped on CLOCK_MONOTONIC (flags {})",
                self.name, meta.flags
            ));
        }
        let t = meta.timestamp;
        let stamped = (t.sec as u64) * 1_000_000_000 + (t.usec as u64) * 1_000;
        let start_of_exposure = meta.flags & Flags::TSTAMP_SRC_MASK == Flags::TSTAMP_SRC_SOE;
        let exposure =
            if start_of_exposure { stamped } else { stamped.saturating_sub(self.readout_ns) };
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
        let missing = V4l2Frames::open(Path::new("/dev/video97"), [640, 480], 30.0).err();
        assert_eq!(missing.as_deref(), Some("v4l2:/dev/video97: no such device"));
        let null =
            V4l2Frames::open(Path::new("/dev/null"), [640, 480], 30.0).err().unwrap_or_default();
        assert!(null.starts_with("v4l2:/dev/null: cannot "), "{null}");
    }
}

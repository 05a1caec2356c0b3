//! [`Transport`]: where instruction lists run — [`Comedi`], a comedi device file through its
//! ioctls, or a fake of a driver ([`crate::fake::FakeS626`]) in tests.

use crate::list::InsnList;
use crate::uapi::{self, ComediDevinfo, ComediSubdinfo, ioctl};
use nix::errno::Errno;
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};

/// What `COMEDI_DEVINFO` says about a device.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct DevInfo {
    /// The driver's name (`s626`).
    pub driver: String,
    /// The board's name.
    pub board: String,
    /// Number of subdevices.
    pub n_subdevs: usize,
}

/// What `COMEDI_SUBDINFO` says about one subdevice.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SubdInfo {
    /// `uapi::SUBD_*`.
    pub kind: u32,
    /// Number of channels.
    pub n_chan: u32,
    /// Largest sample value.
    pub maxdata: u32,
}

/// Where instruction lists run. Real-time contract: [`Transport::run`] is one system call (or
/// none, for a fake) and never allocates; the other methods run before the loop.
pub trait Transport: Send {
    /// The device's driver, board and number of subdevices.
    fn devinfo(&mut self) -> Result<DevInfo, Errno>;
    /// Every subdevice's type, channels and largest sample.
    fn subdinfo(&mut self, n_subdevs: usize) -> Result<Vec<SubdInfo>, Errno>;
    /// Locks subdevice `subdev` for this file: no other process can use it meanwhile.
    fn lock(&mut self, subdev: u32) -> Result<(), Errno>;
    /// Runs every instruction of `list`, in order; returns how many completed (fewer than
    /// the list's length is a failure of the rest).
    fn run(&mut self, list: &mut InsnList) -> Result<usize, Errno>;
}

/// A comedi device could not be opened.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum ComediOpenError {
    /// No such file.
    #[error(
        "{path}: no such device: is the card in and its driver loaded (`sudo modprobe s626`)? \
         `ls /dev/comedi*` lists the comedi devices"
    )]
    Missing {
        /// The device.
        path: PathBuf,
    },
    /// The file exists but may not be opened; its group may use it.
    #[error(
        "{path}: permission denied: the device is for group `{group}`: add yourself \
         (`sudo usermod -aG {group} $USER`, then log in again)"
    )]
    Permission {
        /// The device.
        path: PathBuf,
        /// Its group.
        group: String,
    },
    /// The file exists but only root may open it.
    #[error(
        "{path}: permission denied: only root may use the device: install the udev rule of \
         docs/hardware.md (group `iocard`, mode 0660) and add yourself to that group"
    )]
    RootOnly {
        /// The device.
        path: PathBuf,
    },
    /// The file answers no comedi ioctl.
    #[error(
        "{path} is not a comedi device (COMEDI_DEVINFO: {errno}): give the card's /dev/comediN"
    )]
    NotComedi {
        /// The device.
        path: PathBuf,
        /// What the ioctl said.
        errno: Errno,
    },
    /// Another error.
    #[error("{path}: {errno}")]
    Os {
        /// The device.
        path: PathBuf,
        /// Why.
        errno: Errno,
    },
}

/// A comedi device file.
#[derive(Debug)]
pub struct Comedi {
    fd: OwnedFd,
    path: PathBuf,
}

impl Comedi {
    /// Opens `path` read-write and checks that it answers `COMEDI_DEVINFO`.
    pub fn open(path: &Path) -> Result<Comedi, ComediOpenError> {
        use nix::fcntl::{OFlag, open};
        use nix::sys::stat::Mode;
        let p = || path.to_path_buf();
        let fd =
            open(path, OFlag::O_RDWR | OFlag::O_CLOEXEC, Mode::empty()).map_err(|e| match e {
                Errno::ENOENT | Errno::ENODEV | Errno::ENXIO => {
                    ComediOpenError::Missing { path: p() }
                }
                Errno::EACCES | Errno::EPERM => match group_of(path) {
                    Some(group) => ComediOpenError::Permission { path: p(), group },
                    None => ComediOpenError::RootOnly { path: p() },
                },
                errno => ComediOpenError::Os { path: p(), errno },
            })?;
        let mut dev = Comedi { fd, path: p() };
        dev.devinfo().map_err(|errno| ComediOpenError::NotComedi { path: p(), errno })?;
        Ok(dev)
    }

    /// The device's path.
    pub fn path(&self) -> &Path {
        &self.path
    }
}

/// The group that may read and write `path` — the name of its group, when that is not root's
/// and has read-write permission (its number if it has no name) — or `None`: only root may.
fn group_of(path: &Path) -> Option<String> {
    use std::os::unix::fs::MetadataExt;
    let meta = std::fs::metadata(path).ok()?;
    let (gid, mode) = (meta.gid(), meta.mode());
    if gid == 0 || mode & 0o060 != 0o060 {
        return None;
    }
    let group = nix::unistd::Group::from_gid(nix::unistd::Gid::from_raw(gid)).ok().flatten();
    Some(group.map_or_else(|| gid.to_string(), |g| g.name))
}

/// A NUL-terminated C name as text.
fn name(raw: &[std::ffi::c_char]) -> String {
    let bytes: Vec<u8> = raw.iter().take_while(|&&c| c != 0).map(|&c| c as u8).collect();
    String::from_utf8_lossy(&bytes).into_owned()
}

impl Transport for Comedi {
    fn devinfo(&mut self) -> Result<DevInfo, Errno> {
        // SAFETY: all-zero is a valid `ComediDevinfo` (integers and chars).
        let mut info: ComediDevinfo = unsafe { std::mem::zeroed() };
        // SAFETY: `info` is a writable `comedi_devinfo`, as COMEDI_DEVINFO expects.
        unsafe { ioctl::devinfo(self.fd.as_raw_fd(), &mut info) }?;
        Ok(DevInfo {
            driver: name(&info.driver_name),
            board: name(&info.board_name),
            n_subdevs: info.n_subdevs as usize,
        })
    }

    fn subdinfo(&mut self, n_subdevs: usize) -> Result<Vec<SubdInfo>, Errno> {
        let mut all = vec![ComediSubdinfo::default(); n_subdevs];
        // SAFETY: one writable element per subdevice, as COMEDI_SUBDINFO expects.
        unsafe { ioctl::subdinfo(self.fd.as_raw_fd(), all.as_mut_ptr()) }?;
        Ok(all
            .iter()
            .map(|s| SubdInfo { kind: s.kind, n_chan: s.n_chan, maxdata: s.maxdata })
            .collect())
    }

    fn lock(&mut self, subdev: u32) -> Result<(), Errno> {
        // SAFETY: COMEDI_LOCK takes the subdevice index as its integer argument.
        unsafe { ioctl::lock(self.fd.as_raw_fd(), subdev as libc::c_int) }.map(drop)
    }

    #[inline]
    fn run(&mut self, list: &mut InsnList) -> Result<usize, Errno> {
        let mut raw = list.raw();
        // SAFETY: `raw` points at the list's instructions, whose `data` point at the list's
        // own buffers of `n` samples each; the list outlives the call.
        let n = unsafe { ioctl::insnlist(self.fd.as_raw_fd(), &mut raw) }?;
        Ok(n.max(0) as usize)
    }
}

// The ioctl numbers above come from the same macros as the calls; this keeps them in view.
const _: () = assert!(uapi::COMEDI_INSNLIST == 0x8010_640b);

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::{MetadataExt, PermissionsExt};

    #[test]
    fn permission_advice_names_the_group_only_where_it_helps() {
        let dir = std::env::temp_dir().join(format!("qmarc-perm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let node = dir.join("comedi9");
        std::fs::write(&node, b"").unwrap();
        std::fs::set_permissions(&node, std::fs::Permissions::from_mode(0o600)).unwrap();
        assert_eq!(group_of(&node), None, "0600: only its owner (root, for a device)");
        std::fs::set_permissions(&node, std::fs::Permissions::from_mode(0o660)).unwrap();
        let gid = std::fs::metadata(&node).unwrap().gid();
        assert_eq!(group_of(&node).is_some(), gid != 0, "0660 for a group other than root's");
        let _ = std::fs::remove_dir_all(&dir);
        let e = ComediOpenError::RootOnly { path: "/dev/comedi0".into() };
        assert!(e.to_string().contains("install the udev rule"), "{e}");
    }
}

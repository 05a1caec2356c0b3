//! The binding against the kernel's own header: a C probe compiled with the system's C
//! compiler (`cc`, or `$CC`) against `/usr/include/linux/comedi.h` prints every size, offset,
//! ioctl number and constant the binding transcribes, and each must match.

use qmarc_comedi::uapi::{self, ComediDevinfo, ComediInsn, ComediInsnlist, ComediSubdinfo};
use std::collections::HashMap;
use std::mem::{offset_of, size_of};
use std::path::Path;
use std::process::Command;

/// The header's own numbers, by name.
fn probe() -> HashMap<String, u64> {
    let header = Path::new("/usr/include/linux/comedi.h");
    assert!(
        header.is_file(),
        "{} is missing: install the kernel's UAPI headers (Debian: linux-libc-dev)",
        header.display()
    );
    let dir = std::env::temp_dir().join(format!("qmarc-comedi-probe-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let src = dir.join("probe.c");
    std::fs::write(&src, include_str!("probe.c")).unwrap();
    let exe = dir.join("probe");
    let cc = std::env::var("CC").unwrap_or_else(|_| "cc".into());
    let built = Command::new(&cc).arg("-o").arg(&exe).arg(&src).output().unwrap_or_else(|e| {
        panic!("cannot run the C compiler `{cc}` (the Rust toolchain links with it): {e}")
    });
    assert!(built.status.success(), "{}", String::from_utf8_lossy(&built.stderr));
    let out = Command::new(&exe).output().unwrap();
    let _ = std::fs::remove_dir_all(&dir);
    assert!(out.status.success());
    String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(|l| {
            let (k, v) = l.split_once(' ').unwrap();
            (k.to_string(), v.trim().parse().unwrap())
        })
        .collect()
}

#[test]
fn structs_ioctls_and_constants_match_the_kernel_header() {
    let c = probe();
    let ours: [(&str, u64); 38] = [
        ("insn.size", size_of::<ComediInsn>() as u64),
        ("insn.insn", offset_of!(ComediInsn, insn) as u64),
        ("insn.n", offset_of!(ComediInsn, n) as u64),
        ("insn.data", offset_of!(ComediInsn, data) as u64),
        ("insn.subdev", offset_of!(ComediInsn, subdev) as u64),
        ("insn.chanspec", offset_of!(ComediInsn, chanspec) as u64),
        ("insn.unused", offset_of!(ComediInsn, unused) as u64),
        ("insnlist.size", size_of::<ComediInsnlist>() as u64),
        ("insnlist.n_insns", offset_of!(ComediInsnlist, n_insns) as u64),
        ("insnlist.insns", offset_of!(ComediInsnlist, insns) as u64),
        ("devinfo.size", size_of::<ComediDevinfo>() as u64),
        ("devinfo.version_code", offset_of!(ComediDevinfo, version_code) as u64),
        ("devinfo.n_subdevs", offset_of!(ComediDevinfo, n_subdevs) as u64),
        ("devinfo.driver_name", offset_of!(ComediDevinfo, driver_name) as u64),
        ("devinfo.board_name", offset_of!(ComediDevinfo, board_name) as u64),
        ("devinfo.read_subdevice", offset_of!(ComediDevinfo, read_subdevice) as u64),
        ("devinfo.write_subdevice", offset_of!(ComediDevinfo, write_subdevice) as u64),
        ("subdinfo.size", size_of::<ComediSubdinfo>() as u64),
        ("subdinfo.type", offset_of!(ComediSubdinfo, kind) as u64),
        ("subdinfo.n_chan", offset_of!(ComediSubdinfo, n_chan) as u64),
        ("subdinfo.maxdata", offset_of!(ComediSubdinfo, maxdata) as u64),
        ("subdinfo.insn_bits_support", offset_of!(ComediSubdinfo, insn_bits_support) as u64),
        ("COMEDI_DEVINFO", uapi::COMEDI_DEVINFO),
        ("COMEDI_SUBDINFO", uapi::COMEDI_SUBDINFO),
        ("COMEDI_LOCK", uapi::COMEDI_LOCK),
        ("COMEDI_UNLOCK", uapi::COMEDI_UNLOCK),
        ("COMEDI_INSNLIST", uapi::COMEDI_INSNLIST),
        ("COMEDI_INSN", uapi::COMEDI_INSN),
        ("INSN_READ", u64::from(uapi::INSN_READ)),
        ("INSN_WRITE", u64::from(uapi::INSN_WRITE)),
        ("INSN_BITS", u64::from(uapi::INSN_BITS)),
        ("INSN_CONFIG", u64::from(uapi::INSN_CONFIG)),
        ("AREF_GROUND", u64::from(uapi::AREF_GROUND)),
        ("COMEDI_SUBD_AI", u64::from(uapi::SUBD_AI)),
        ("COMEDI_SUBD_AO", u64::from(uapi::SUBD_AO)),
        ("COMEDI_SUBD_DIO", u64::from(uapi::SUBD_DIO)),
        ("COMEDI_SUBD_COUNTER", u64::from(uapi::SUBD_COUNTER)),
        ("COMEDI_NAMELEN", uapi::COMEDI_NAMELEN as u64),
    ];
    for (name, value) in ours {
        assert_eq!(c.get(name), Some(&value), "{name}: the header says {:?}", c.get(name));
    }
    assert_eq!(c.len(), ours.len() + 1, "every probed value is compared");
    assert_eq!(c["CR_PACK_5_2_1"], u64::from(uapi::cr_pack(5, 2, 1)));
}

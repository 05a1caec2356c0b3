//! The Sensoray 626 as the kernel's `s626` comedi driver presents it
//! (`../shared/notes/s626-comedi.md`): its subdevices, its DAC code around the exact zero
//! `0x1fff`, its 24-bit counters, and the check that a device really is one.

use crate::device::{DevInfo, SubdInfo};
use crate::uapi::{SUBD_AI, SUBD_AO, SUBD_COUNTER, SUBD_DIO};

/// The driver's name in `COMEDI_DEVINFO`.
pub const DRIVER: &str = "s626";
/// Analog inputs (16 channels).
pub const SUBDEV_AI: u32 = 0;
/// Analog outputs (4 DACs, ±10 V).
pub const SUBDEV_AO: u32 = 1;
/// DIO bank 0 (DIO 0‥15): the thesis' enables and limit switches.
pub const SUBDEV_DIO0: u32 = 2;
/// Counters 0A, 1A, 2A, 0B, 1B, 2B.
pub const SUBDEV_COUNTER: u32 = 5;
/// Every subdevice: index, type, channels, largest sample.
pub const LAYOUT: [(u32, u32, u32, u32); 6] = [
    (SUBDEV_AI, SUBD_AI, 16, 0x3fff),
    (SUBDEV_AO, SUBD_AO, 4, 0x3fff),
    (SUBDEV_DIO0, SUBD_DIO, 16, 1),
    (3, SUBD_DIO, 16, 1),
    (4, SUBD_DIO, 16, 1),
    (SUBDEV_COUNTER, SUBD_COUNTER, 6, COUNTER_MASK),
];
/// The DAC code of exactly 0 V: the driver subtracts it and stores sign-magnitude.
pub const DAC_ZERO: u32 = 0x1fff;
/// Largest magnitude around [`DAC_ZERO`]: 13 bits, ±10 V (1 LSB = 10 V / 8191 ≈ 1.221 mV).
pub const DAC_SPAN: i32 = 0x1fff;
/// The counters' width: 24 bits.
pub const COUNTER_MASK: u32 = 0x00ff_ffff;

/// The driver's sample for a QMARC DAC code (`HwMsg`'s ±8191 = ±10 V scale, the same LSB):
/// `0x1fff + code`, clamped to ±[`DAC_SPAN`], so 0 V is exactly `0x1fff`. (comedilib's
/// `comedi_from_phys` would give 0 V as `0x2000`, one LSB high.)
#[inline]
pub fn dac_sample(code: i32) -> u32 {
    (DAC_ZERO as i32 + code.clamp(-DAC_SPAN, DAC_SPAN)) as u32
}

/// The volts the driver outputs for `sample`, as `s626_ao_insn_write` computes them:
/// `sample − 0x1fff` stored sign-magnitude, its magnitude clamped to `0x1fff`.
pub fn dac_volts(sample: u32) -> f64 {
    let d = (i64::from(sample) - i64::from(DAC_ZERO)).clamp(-0x1fff, 0x1fff);
    d as f64 * 10.0 / f64::from(DAC_SPAN)
}

/// What differs between a device and a 626 as its driver presents it, in one line naming
/// the device; `None` when it is one.
pub fn layout_problem(device: &str, info: &DevInfo, subs: &[SubdInfo]) -> Option<String> {
    if info.driver != DRIVER {
        return Some(format!(
            "{device} is driven by `{}` ({}), not `{DRIVER}`: give the Sensoray 626's device \
             (`cat /proc/comedi` lists them)",
            info.driver, info.board
        ));
    }
    for (idx, kind, n_chan, maxdata) in LAYOUT {
        let want = SubdInfo { kind, n_chan, maxdata };
        match subs.get(idx as usize) {
            Some(s) if *s == want => {}
            found => {
                return Some(format!(
                    "{device}: subdevice {idx} is {}, the 626 has {}: not the driver this \
                     backend was written for",
                    found.map_or("missing".into(), describe),
                    describe(&want)
                ));
            }
        }
    }
    None
}

fn describe(s: &SubdInfo) -> String {
    let kind = match s.kind {
        SUBD_AI => "analog inputs",
        SUBD_AO => "analog outputs",
        SUBD_DIO => "digital I/O",
        SUBD_COUNTER => "counters",
        _ => "another kind",
    };
    format!("{} {kind} of maxdata {:#x}", s.n_chan, s.maxdata)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_volts_is_exactly_0x1fff_and_the_ends_are_ten_volts() {
        assert_eq!(dac_sample(0), 0x1fff);
        assert_eq!(dac_volts(dac_sample(0)), 0.0);
        assert_eq!(dac_sample(8191), 0x3ffe);
        assert_eq!(dac_sample(-8191), 0);
        assert_eq!(dac_volts(0x3ffe), 10.0);
        assert_eq!(dac_volts(0), -10.0);
        // The clamp, in our code and in the driver's.
        assert_eq!(dac_sample(20_000), 0x3ffe);
        assert_eq!(dac_volts(0x3fff), 10.0);
        // comedilib's comedi_from_phys(0 V) with maxdata 0x3fff: 8192, one LSB (1.22 mV) high.
        let from_phys = (0.0f64 + 10.0) / 20.0 * f64::from(0x3fff) + 0.5;
        assert_eq!(from_phys as u32, 0x2000);
        assert!((dac_volts(0x2000) - 10.0 / 8191.0).abs() < 1e-12);
    }

    #[test]
    fn only_a_626_passes_the_layout_check() {
        let ok: Vec<SubdInfo> = LAYOUT
            .iter()
            .map(|&(_, kind, n_chan, maxdata)| SubdInfo { kind, n_chan, maxdata })
            .collect();
        let info =
            |driver: &str| DevInfo { driver: driver.into(), board: "b".into(), n_subdevs: 6 };
        assert_eq!(layout_problem("/dev/comedi0", &info("s626"), &ok), None);
        assert_eq!(
            layout_problem("/dev/comedi0", &info("comedi_test"), &ok).unwrap(),
            "/dev/comedi0 is driven by `comedi_test` (b), not `s626`: give the Sensoray 626's \
             device (`cat /proc/comedi` lists them)"
        );
        let mut odd = ok.clone();
        odd[5].n_chan = 3;
        assert_eq!(
            layout_problem("/dev/comedi0", &info("s626"), &odd).unwrap(),
            "/dev/comedi0: subdevice 5 is 3 counters of maxdata 0xffffff, the 626 has 6 \
             counters of maxdata 0xffffff: not the driver this backend was written for"
        );
        assert!(layout_problem("/dev/c", &info("s626"), &ok[..4]).unwrap().contains("is missing"));
    }
}

//! [`InsnList`]: a list of comedi instructions built once, with buffers of its own, run again
//! and again by one `COMEDI_INSNLIST` ioctl each time — nothing is allocated per run.

use crate::uapi::{AREF_GROUND, ComediInsn, ComediInsnlist, cr_pack};

/// Most samples one instruction of a list carries (`INSN_BITS` needs two).
pub const MAX_DATA: usize = 2;

/// One instruction of a list, as it is built.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Insn {
    /// `INSN_*`.
    pub insn: u32,
    /// Subdevice index.
    pub subdev: u32,
    /// Channel.
    pub chan: u32,
    /// Samples it reads or writes (1‥[`MAX_DATA`]).
    pub n: u32,
}

impl Insn {
    /// An instruction of one sample on `subdev`, channel `chan` (range 0, ground reference).
    pub const fn one(insn: u32, subdev: u32, chan: u32) -> Insn {
        Insn { insn, subdev, chan, n: 1 }
    }

    /// `INSN_BITS` on the DIO subdevice `subdev` (mask and bits).
    pub const fn bits(subdev: u32) -> Insn {
        Insn { insn: crate::uapi::INSN_BITS, subdev, chan: 0, n: 2 }
    }
}

/// Instructions and the sample buffers they point to, owned together so the pointers the
/// kernel follows stay valid for as long as the list lives (the buffers are boxed: moving the
/// list does not move them).
#[derive(Debug)]
pub struct InsnList {
    insns: Box<[ComediInsn]>,
    data: Box<[[u32; MAX_DATA]]>,
}

// SAFETY: the raw pointers in `insns` point into `data`, which this value owns and never
// shares; sending the list to another thread sends the buffers with it.
unsafe impl Send for InsnList {}

impl InsnList {
    /// The list of `items`, every sample 0. Allocates: build it before the loop.
    pub fn new(items: &[Insn]) -> InsnList {
        let mut data = vec![[0u32; MAX_DATA]; items.len()].into_boxed_slice();
        let insns = items
            .iter()
            .zip(data.iter_mut())
            .map(|(it, d)| ComediInsn {
                insn: it.insn,
                n: it.n.clamp(1, MAX_DATA as u32),
                data: d.as_mut_ptr(),
                subdev: it.subdev,
                chanspec: cr_pack(it.chan, 0, AREF_GROUND),
                unused: [0; 3],
            })
            .collect();
        InsnList { insns, data }
    }

    /// Number of instructions.
    pub fn len(&self) -> usize {
        self.insns.len()
    }

    /// True without instructions.
    pub fn is_empty(&self) -> bool {
        self.insns.is_empty()
    }

    /// Instruction `i` (its type, subdevice, chanspec; not its samples: [`InsnList::data`]).
    pub fn insn(&self, i: usize) -> &ComediInsn {
        &self.insns[i]
    }

    /// The samples of instruction `i`.
    pub fn data(&self, i: usize) -> &[u32] {
        &self.data[i][..self.insns[i].n as usize]
    }

    /// The samples of instruction `i`, to fill before a run or to take what a run returned.
    pub fn data_mut(&mut self, i: usize) -> &mut [u32] {
        let n = self.insns[i].n as usize;
        &mut self.data[i][..n]
    }

    /// The list as the `COMEDI_INSNLIST` ioctl takes it, every instruction pointing at its
    /// samples afresh (pointers derived now, from this borrow, so no earlier borrow of the
    /// buffers is relied on); valid until the list is used again.
    pub fn raw(&mut self) -> ComediInsnlist {
        for (insn, data) in self.insns.iter_mut().zip(self.data.iter_mut()) {
            insn.data = data.as_mut_ptr();
        }
        ComediInsnlist { n_insns: self.insns.len() as u32, insns: self.insns.as_mut_ptr() }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::uapi::{INSN_READ, INSN_WRITE};

    #[test]
    fn every_instruction_points_at_its_own_samples() {
        let mut list = InsnList::new(&[
            Insn::one(INSN_READ, 5, 2),
            Insn::bits(2),
            Insn::one(INSN_WRITE, 1, 0),
        ]);
        list.data_mut(1).copy_from_slice(&[0b1011, 0b0001]);
        let raw = list.raw();
        assert_eq!(raw.n_insns, 3);
        // SAFETY: the list lives; `raw` points into it.
        let insns = unsafe { std::slice::from_raw_parts(raw.insns, 3) };
        assert_eq!((insns[0].n, insns[1].n, insns[1].subdev), (1, 2, 2));
        assert_eq!(insns[0].chanspec, 2);
        // SAFETY: as above; instruction 1 has two samples.
        let bits = unsafe { std::slice::from_raw_parts(insns[1].data, 2) };
        assert_eq!(bits, [0b1011, 0b0001]);
        let mut moved = list; // the buffers do not move with the value
        assert_eq!(moved.data(1), [0b1011, 0b0001]);
        assert_eq!(moved.raw().insns, raw.insns);
    }
}

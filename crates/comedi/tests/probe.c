/* Prints what qmarc-comedi transcribes from the kernel's comedi UAPI header, one "name value"
 * per line; crates/comedi/tests/tests.rs compares each with the Rust binding. */
#include <stddef.h>
#include <stdio.h>
#include <linux/ioctl.h>
#include <linux/comedi.h>

#define SIZE(t, name) printf("%s.size %zu\n", name, sizeof(struct t))
#define OFF(t, name, f) printf("%s.%s %zu\n", name, #f, offsetof(struct t, f))
#define NUM(x) printf("%s %lu\n", #x, (unsigned long)(x))

int main(void) {
    SIZE(comedi_insn, "insn");
    OFF(comedi_insn, "insn", insn);
    OFF(comedi_insn, "insn", n);
    OFF(comedi_insn, "insn", data);
    OFF(comedi_insn, "insn", subdev);
    OFF(comedi_insn, "insn", chanspec);
    OFF(comedi_insn, "insn", unused);
    SIZE(comedi_insnlist, "insnlist");
    OFF(comedi_insnlist, "insnlist", n_insns);
    OFF(comedi_insnlist, "insnlist", insns);
    SIZE(comedi_devinfo, "devinfo");
    OFF(comedi_devinfo, "devinfo", version_code);
    OFF(comedi_devinfo, "devinfo", n_subdevs);
    OFF(comedi_devinfo, "devinfo", driver_name);
    OFF(comedi_devinfo, "devinfo", board_name);
    OFF(comedi_devinfo, "devinfo", read_subdevice);
    OFF(comedi_devinfo, "devinfo", write_subdevice);
    SIZE(comedi_subdinfo, "subdinfo");
    OFF(comedi_subdinfo, "subdinfo", type);
    OFF(comedi_subdinfo, "subdinfo", n_chan);
    OFF(comedi_subdinfo, "subdinfo", maxdata);
    OFF(comedi_subdinfo, "subdinfo", insn_bits_support);
    NUM(COMEDI_DEVINFO);
    NUM(COMEDI_SUBDINFO);
    NUM(COMEDI_LOCK);
    NUM(COMEDI_UNLOCK);
    NUM(COMEDI_INSNLIST);
    NUM(COMEDI_INSN);
    NUM(INSN_READ);
    NUM(INSN_WRITE);
    NUM(INSN_BITS);
    NUM(INSN_CONFIG);
    NUM(AREF_GROUND);
    NUM(COMEDI_SUBD_AI);
    NUM(COMEDI_SUBD_AO);
    NUM(COMEDI_SUBD_DIO);
    NUM(COMEDI_SUBD_COUNTER);
    NUM(COMEDI_NAMELEN);
    printf("CR_PACK_5_2_1 %lu\n", (unsigned long)CR_PACK(5, 2, 1));
    return 0;
}

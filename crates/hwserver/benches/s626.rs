//! The Sensoray 626 backend's share of a servo cycle, against the in-process fake of the
//! driver: building and reading back the read list (counters, switches) and the write list
//! (DACs, enables, charge pump), alone and through the server's core as a cycle's two
//! requests. On the card, add the kernel's ioctl (the selftest measures it there).

use criterion::{Criterion, criterion_group, criterion_main};
use qmarc_config::{Names, Settings};
use qmarc_hwserver::HwCore;
use qmarc_hwserver::backends::s626::S626;
use qmarc_proto::HwMsg;
use std::hint::black_box;
use std::path::Path;

fn fake_card() -> S626 {
    let names = Names::any();
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/s626.toml");
    let mut s = Settings::load(&path, &names).expect("the shipped settings for the 626");
    s.set_device(Path::new("fake")).expect("the fake card");
    S626::open(&s, false).expect("the fake card opens")
}

fn lists(c: &mut Criterion) {
    let mut card = fake_card();
    card.run_write_list().unwrap();
    c.bench_function("s626 read list (3 counters + DIO bank), fake driver", |b| {
        b.iter(|| card.run_read_list().unwrap())
    });
    c.bench_function("s626 write list (3 DACs + DIO bank), fake driver", |b| {
        b.iter(|| card.run_write_list().unwrap())
    });
    let mut core = HwCore::new(Box::new(fake_card()));
    let read = HwMsg::read_all_encoders();
    let write = HwMsg::write_all_dacs(&[120, -80, 40, 0]);
    c.bench_function("s626 cycle through HwCore (read + write requests), fake driver", |b| {
        b.iter(|| {
            black_box(core.handle(black_box(&read)));
            black_box(core.handle(black_box(&write)));
        })
    });
}

criterion_group!(benches, lists);
criterion_main!(benches);

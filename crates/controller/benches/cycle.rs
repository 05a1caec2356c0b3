//! Criterion benchmarks of the servo loop's pieces for 3 motors: one whole cycle against the
//! in-process hardware core (simulated Deltabot, so the figure includes the plant model and
//! excludes IPC), the law alone and the generator alone. Run with
//! `cargo bench -p qmarc-controller --bench cycle`.

use criterion::{Criterion, criterion_group, criterion_main};
use qmarc_controller::config::Settings;
use qmarc_controller::law::{PidFf, ServoInput, ServoLaw};
use qmarc_controller::link::{HwLink, LinkError};
use qmarc_controller::registry::GENERATORS;
use qmarc_controller::servo::{CycleEnd, MovePlan, Servo};
use qmarc_controller::traj::{Step, TrajectoryGenerator};
use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
use qmarc_proto::{HwMsg, MAX_MOTORS};
use qmarc_timer::{ManualTicker, MockClock, Ticker};
use std::hint::black_box;
use std::path::Path;

struct CoreLink(HwCore);

impl HwLink for CoreLink {
    fn exchange(&mut self, req: &HwMsg) -> Result<HwMsg, LinkError> {
        Ok(self.0.handle(req))
    }
}

fn settings() -> Settings {
    Settings::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml")).unwrap()
}

fn bench_cycle(c: &mut Criterion) {
    let s = settings();
    // A long step so the path never ends while criterion iterates.
    let mut s_long = s.clone();
    s_long.step.duration_s = 3_600.0;
    let plan = MovePlan {
        mode: "step".into(),
        n_motors: 3,
        period_ns: 400_000,
        gather_every: 4,
        deterministic: false,
    };
    let generator = (GENERATORS[0].build)(&s_long);
    let law = Box::new(PidFf::from_settings(&s));
    let mut servo = Servo::new(plan, generator, law, Box::new(MockClock::new(0)));
    let sim = SimDeltabot::new(SimParams { n_motors: 3, lockstep: true, ..SimParams::default() })
        .unwrap();
    let mut link = CoreLink(HwCore::new(Box::new(sim)));
    let mut ticker = ManualTicker::new(400_000);
    servo.prepare(&mut link).unwrap();
    servo.set_t0(ticker.start().unwrap());
    c.bench_function(
        "servo cycle, 3 motors, in-process sim (read, step, pidff, write, gather every 4)",
        |b| {
            b.iter(|| {
                let tick = ticker.wait().unwrap();
                let end = servo.cycle(&mut link, black_box(&tick));
                debug_assert_eq!(end, CycleEnd::Continue);
                black_box(end)
            })
        },
    );
}

fn bench_law(c: &mut Criterion) {
    let s = settings();
    let mut law = PidFf::from_settings(&s);
    law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
    let mut dac = [0; MAX_MOTORS];
    let mut n = 0u64;
    c.bench_function("pidff step, 3 motors", |b| {
        b.iter(|| {
            n += 1;
            let cmd = [n as f64, -(n as f64), 0.5 * n as f64, 0.0];
            let act = [n as f64 - 3.0, 2.0 - n as f64, 0.5 * n as f64 + 1.0, 0.0];
            law.step(black_box(&ServoInput { n, cmd: &cmd, act: &act }), &mut dac);
            black_box(dac)
        })
    });
}

fn bench_step_generator(c: &mut Criterion) {
    let mut g = Step::new(1000, 3_600.0, 0.0004, 3);
    g.start(&[0.0; MAX_MOTORS]).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    let mut n = 0u64;
    c.bench_function("step generator sample, 3 motors", |b| {
        b.iter(|| {
            n = (n + 1) % 1_000_000;
            black_box(g.sample(black_box(n), &mut cmd));
        })
    });
}

criterion_group!(benches, bench_cycle, bench_law, bench_step_generator);
criterion_main!(benches);

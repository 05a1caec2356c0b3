//! Criterion benchmarks of the servo loop's pieces for 3 motors: one whole cycle against the
//! in-process hardware core (simulated Deltabot: the figure includes the plant model and
//! excludes IPC), the law alone, one sample of each trajectory generator, and the natural
//! spline's O(N) solve for 10³…10⁶ knots. Run with `cargo bench -p qmarc-plugins --bench
//! cycle`.

use criterion::{BatchSize, BenchmarkId, Criterion, Throughput, criterion_group, criterion_main};
use qmarc_config::Settings;
use qmarc_controller::law::{ServoInput, ServoLaw};
use qmarc_controller::plan::MovePlan;
use qmarc_controller::servo::{CycleEnd, Servo};
use qmarc_controller::traj::{Sample, TrajectoryGenerator};
use qmarc_hwserver::{HwCore, SimDeltabot, SimParams};
use qmarc_knots::{OfflineKnots, PvtKnot};
use qmarc_plugins::pidff::PidFf;
use qmarc_plugins::pvt::Pvt;
use qmarc_plugins::registry::GENERATORS;
use qmarc_plugins::spline::{CubicSpline, NaturalSpline};
use qmarc_plugins::step::Step;
use qmarc_proto::MAX_MOTORS;
use qmarc_timer::{ManualTicker, MockClock, Ticker};
use std::hint::black_box;
use std::path::Path;

const PERIOD_S: f64 = 0.0004;

fn settings() -> Settings {
    let names = qmarc_config::Names {
        laws: qmarc_plugins::registry::law_names(),
        methods: qmarc_plugins::registry::path_generator_names(),
        any_plugin: false,
    };
    Settings::load(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/qmarc.toml"), &names)
        .unwrap()
}

fn bench_cycle(c: &mut Criterion) {
    let s = settings();
    // A long step so the path never ends while criterion iterates.
    let mut s_long = s.clone();
    s_long.step.duration_s = 3_600.0;
    let plan = MovePlan { gather_every: 4, ..MovePlan::new(qmarc_config::Mode::Step, 3, 400_000) };
    let generator = (GENERATORS[0].build)(&s_long).unwrap();
    let law = Box::new(PidFf::from_settings(&s));
    let mut servo = Servo::new(plan, generator, law, Box::new(MockClock::new(0)));
    let sim = SimDeltabot::new(SimParams { n_motors: 3, lockstep: true, ..SimParams::default() })
        .unwrap();
    let mut link = HwCore::new(Box::new(sim));
    let mut ticker = ManualTicker::new(400_000);
    let mut moving = servo.prepare(&mut link).unwrap();
    moving.set_t0(ticker.start().unwrap());
    c.bench_function(
        "servo cycle, 3 motors, in-process sim (read, step, pidff, write, gather every 4)",
        |b| {
            b.iter(|| {
                let tick = ticker.wait().unwrap();
                let end = moving.cycle(&mut link, black_box(&tick));
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
            law.step(black_box(&ServoInput { n, elapsed: 1, cmd: &cmd, act: &act }), &mut dac);
            black_box(dac)
        })
    });
}

/// A 3-motor sine path sampled every `dt` s for `seconds`.
fn sine(t: f64, m: usize) -> f64 {
    (1000.0 * (1.0 - (std::f64::consts::TAU * (1.0 + m as f64 * 0.5) * t).cos())).round()
}

fn offline_knots(seconds: f64, dt: f64) -> OfflineKnots {
    let n = (seconds / dt).round() as usize + 1;
    let times: Vec<f64> = (0..n).map(|i| i as f64 * dt).collect();
    let positions = times.iter().map(|&t| [sine(t, 0), sine(t, 1), sine(t, 2), 0.0]).collect();
    OfflineKnots { times, positions, n_motors: 3, ..OfflineKnots::default() }
}

fn pvt_knots(seconds: f64, dt: f64) -> Vec<PvtKnot> {
    let n = (seconds / dt).round() as usize + 1;
    (0..n)
        .map(|i| {
            let t = i as f64 * dt;
            let mut k = PvtKnot { dt_s: dt, ..PvtKnot::default() };
            for m in 0..3 {
                k.pos[m] = sine(t, m);
                let w = std::f64::consts::TAU * (1.0 + m as f64 * 0.5);
                k.vel[m] = 1000.0 * w * (w * t).sin();
            }
            k
        })
        .collect()
}

/// One sample of `g`, restarting the path when it ends (the restart is amortised over
/// hundreds of thousands of samples).
fn bench_generator(c: &mut Criterion, name: &str, mut g: Box<dyn TrajectoryGenerator>) {
    let start = [0.0; MAX_MOTORS];
    g.start(&start).unwrap();
    let mut cmd = [0.0; MAX_MOTORS];
    let mut n = 0u64;
    c.bench_function(&format!("{name} generator sample, 3 motors"), |b| {
        b.iter(|| {
            if g.sample(black_box(n), &mut cmd) != Sample::Ready {
                g.start(&start).unwrap();
                n = 0;
                g.sample(n, &mut cmd);
            }
            n += 1;
            black_box(cmd)
        })
    });
}

fn bench_generators(c: &mut Criterion) {
    bench_generator(c, "step", Box::new(Step::new(1000, 3_600.0, PERIOD_S, 3)));
    // 60 s of spline from 10 ms knots: 150 001 queued samples.
    let spline = CubicSpline::from_knots(&offline_knots(60.0, 0.01), PERIOD_S, 1.0).unwrap();
    bench_generator(c, "spline", Box::new(spline));
    // 1000 s of PVT from 10 ms knots, through the queue from the reader thread.
    let pvt = Pvt::from_knots(pvt_knots(1000.0, 0.01), 3, PERIOD_S, 1.0);
    bench_generator(c, "pvt", Box::new(pvt));
}

fn bench_spline_solve(c: &mut Criterion) {
    let mut group = c.benchmark_group("natural spline solve");
    group.sample_size(10);
    for n in [1_000usize, 10_000, 100_000, 1_000_000] {
        let t: Vec<f64> = (0..n).map(|i| i as f64 * 0.001 + (i % 7) as f64 * 1e-4).collect();
        let y: Vec<f64> = t.iter().map(|&t| sine(t, 0)).collect();
        group.throughput(Throughput::Elements(n as u64));
        group.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            // The knots' copies are made outside the timing: the solve only.
            b.iter_batched(
                || (t.clone(), y.clone()),
                |(t, y)| black_box(NaturalSpline::new(t, y).unwrap()),
                BatchSize::LargeInput,
            )
        });
    }
    group.finish();
}

criterion_group!(benches, bench_cycle, bench_law, bench_generators, bench_spline_solve);
criterion_main!(benches);

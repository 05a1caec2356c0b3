//! The online trajectory (thesis 3.12.2): position-velocity-time knots joined by cubics.
//!
//! Each segment is the cubic that meets position and velocity at both of its knots over the
//! segment time ([`Hermite`]; thesis eqs. 3-10/3-11 as printed have sign errors, see
//! `../shared/notes/deltabot.md`). Knots reach the servo loop through a bounded wait-free
//! queue filled by a reader thread, so they can come from a file, a pipe or a FIFO while the
//! robot moves (`--knots -` reads standard input). A file is checked completely before the
//! move; a stream knot by knot as it arrives. If the queue runs dry before the stream ends,
//! the generator reports [`Sample::Starved`].

use crate::source::{KnotSource, TrajBuildError, knots_failed};
use crate::spline::samples_between;
use qmarc_config::Settings;
use qmarc_controller::traj::{
    GeneratorReport, Sample, TrajStartError, TrajectoryGenerator, bounds_of, check_start,
};
use qmarc_knots::{
    KnotFileError, KnotRules, MAX_LINE_BYTES, MIN_PVT_KNOTS, PvtKnot, PvtLineParser, parse_pvt,
    read_knot_file, read_line_bounded,
};
use qmarc_proto::MAX_MOTORS;
use rtrb::{Consumer, Producer, PushError, RingBuffer};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// Knots the queue between the reader thread and the servo loop holds.
pub const PVT_QUEUE_CAPACITY: usize = 1024;

/// p(τ) = Aτ³ + Bτ² + Cτ + D on τ ∈ [0, T]: the cubic with p(0) = X₀, p′(0) = V₀,
/// p(T) = X₁, p′(T) = V₁ (a cubic Hermite segment; PMAC PVT moves are the same curve).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Hermite {
    /// τ³ coefficient.
    pub a: f64,
    /// τ² coefficient.
    pub b: f64,
    /// τ coefficient.
    pub c: f64,
    /// Constant.
    pub d: f64,
}

impl Hermite {
    /// The segment from (x0, v0) to (x1, v1) over `t` seconds. From the four end conditions:
    /// D = X₀, C = V₀, and p(T) = X₁, p′(T) = V₁ solved for A and B:
    /// B = 3(X₁ − X₀)/T² − (2V₀ + V₁)/T, A = 2(X₀ − X₁)/T³ + (V₀ + V₁)/T².
    #[inline]
    pub fn new(x0: f64, v0: f64, x1: f64, v1: f64, t: f64) -> Hermite {
        let (t2, t3) = (t * t, t * t * t);
        Hermite {
            a: 2.0 * (x0 - x1) / t3 + (v0 + v1) / t2,
            b: 3.0 * (x1 - x0) / t2 - (2.0 * v0 + v1) / t,
            c: v0,
            d: x0,
        }
    }

    /// Position at τ.
    #[inline]
    pub fn position(&self, tau: f64) -> f64 {
        ((self.a * tau + self.b) * tau + self.c) * tau + self.d
    }

    /// Velocity at τ.
    #[inline]
    pub fn velocity(&self, tau: f64) -> f64 {
        (3.0 * self.a * tau + 2.0 * self.b) * tau + self.c
    }

    /// The smallest and largest position over τ ∈ [0, t]: the ends and the roots of
    /// p′(τ) = 3Aτ² + 2Bτ + C inside the span.
    pub fn extremes(&self, t: f64) -> (f64, f64) {
        let mut lo = self.position(0.0).min(self.position(t));
        let mut hi = self.position(0.0).max(self.position(t));
        let (qa, qb, qc) = (3.0 * self.a, 2.0 * self.b, self.c);
        let mut roots = [f64::NAN; 2];
        if qa != 0.0 {
            let disc = qb * qb - 4.0 * qa * qc;
            if disc >= 0.0 {
                let r = disc.sqrt();
                roots = [(-qb - r) / (2.0 * qa), (-qb + r) / (2.0 * qa)];
            }
        } else if qb != 0.0 {
            roots[0] = -qc / qb;
        }
        for r in roots.into_iter().filter(|r| *r > 0.0 && *r < t) {
            let p = self.position(r);
            lo = lo.min(p);
            hi = hi.max(p);
        }
        (lo, hi)
    }

    /// Acceleration at τ.
    #[inline]
    pub fn acceleration(&self, tau: f64) -> f64 {
        6.0 * self.a * tau + 2.0 * self.b
    }
}

/// What travels through the queue.
#[derive(Debug, Clone, Copy)]
enum Feed {
    Knot(PvtKnot),
    /// The path has no more knots.
    End,
    /// The reader failed; the error is in the shared slot.
    Error,
}

/// Where the knots come from.
#[derive(Debug, Clone)]
enum PvtSource {
    /// A file, checked completely.
    Knots(Arc<Vec<PvtKnot>>),
    /// A stream, checked knot by knot.
    Stream(KnotSource),
}

/// The online PVT generator.
#[derive(Debug)]
#[doc(alias = "PVTOnlineTrajGen")]
pub struct Pvt {
    source: PvtSource,
    n_motors: usize,
    rules: KnotRules,
    period_s: f64,
    start_tolerance: f64,
    stream_wait: Duration,
    consumer: Option<Consumer<Feed>>,
    failure: Arc<Mutex<Option<KnotFileError>>>,
    seg: [Hermite; MAX_MOTORS],
    seg_start: f64,
    seg_len: f64,
    end_knot: PvtKnot,
    pending: Option<PvtKnot>,
    /// A file's knots: the index of the next one to enter (a known path needs no reader
    /// thread, so it can never starve).
    next_knot: usize,
    ended: bool,
    failed: bool,
    /// The first knots, when `first_command` read them before `start`.
    first: Vec<PvtKnot>,
}

/// Pushes `v`, waiting while the queue is full; false if the consumer is gone.
fn push_blocking(producer: &mut Producer<Feed>, mut v: Feed) -> bool {
    loop {
        match producer.push(v) {
            Ok(()) => return true,
            Err(PushError::Full(back)) => {
                if producer.is_abandoned() {
                    return false;
                }
                v = back;
                std::thread::sleep(Duration::from_micros(200));
            }
        }
    }
}

/// Reads a stream knot by knot into the queue (the reader thread's body). Lines are read
/// with a bounded buffer: a stream without line ends (`/dev/zero`) is an error, not a
/// growing allocation.
fn read_stream(
    source: &KnotSource,
    rules: &KnotRules,
    producer: &mut Producer<Feed>,
    failure: &Mutex<Option<KnotFileError>>,
) {
    let fail = |e: KnotFileError, producer: &mut Producer<Feed>| {
        if let Ok(mut slot) = failure.lock() {
            *slot = Some(e);
        }
        push_blocking(producer, Feed::Error);
    };
    let (name, mut reader) = match source.open() {
        Ok(r) => r,
        Err(e) => return fail(e, producer),
    };
    let mut parser = PvtLineParser::new(&name, rules);
    let mut buf = Vec::with_capacity(MAX_LINE_BYTES + 2);
    loop {
        match read_line_bounded(reader.as_mut(), &mut buf) {
            Ok(true) => {}
            Ok(false) => break,
            Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
                return fail(parser.too_long(), producer);
            }
            Err(e) => {
                return fail(
                    KnotFileError::Read { file: name.clone(), reason: e.to_string() },
                    producer,
                );
            }
        }
        let line = match std::str::from_utf8(&buf) {
            Ok(l) => l,
            Err(_) => {
                let line = parser.lines() + 1;
                let e = KnotFileError::Invalid {
                    file: name.clone(),
                    line,
                    column: 1,
                    message: "expected text (UTF-8), found a byte that is not".into(),
                };
                return fail(e, producer);
            }
        };
        match parser.parse_line(line) {
            Ok(Some(k)) => {
                if !push_blocking(producer, Feed::Knot(k)) {
                    return;
                }
            }
            Ok(None) => {}
            Err(e) => return fail(e, producer),
        }
    }
    if parser.knots() < MIN_PVT_KNOTS {
        return fail(parser.too_few(), producer);
    }
    push_blocking(producer, Feed::End);
}

impl Pvt {
    fn new(
        source: PvtSource,
        n_motors: usize,
        period_s: f64,
        start_tolerance: f64,
        stream_wait: Duration,
    ) -> Pvt {
        Pvt {
            source,
            n_motors,
            rules: KnotRules::new(n_motors),
            period_s,
            start_tolerance,
            stream_wait,
            consumer: None,
            failure: Arc::new(Mutex::new(None)),
            seg: [Hermite::default(); MAX_MOTORS],
            seg_start: 0.0,
            seg_len: 0.0,
            end_knot: PvtKnot::default(),
            pending: None,
            next_knot: 0,
            ended: false,
            failed: false,
            first: Vec::new(),
        }
    }

    /// The generator for knots already checked (at least [`MIN_PVT_KNOTS`]).
    pub fn from_knots(
        knots: Vec<PvtKnot>,
        n_motors: usize,
        period_s: f64,
        start_tolerance: f64,
    ) -> Pvt {
        Pvt::new(
            PvtSource::Knots(Arc::new(knots)),
            n_motors,
            period_s,
            start_tolerance,
            Duration::from_secs(10),
        )
    }

    /// The generator for a stream of knots (standard input, a FIFO), read as the move
    /// starts; the first [`MIN_PVT_KNOTS`] must arrive within `stream_wait`.
    pub fn from_stream(
        source: KnotSource,
        n_motors: usize,
        period_s: f64,
        start_tolerance: f64,
        stream_wait: Duration,
    ) -> Pvt {
        Pvt::new(PvtSource::Stream(source), n_motors, period_s, start_tolerance, stream_wait)
    }

    /// The generator of the settings: `trajectory.knots`, a file checked now or a stream.
    pub fn from_settings(s: &Settings) -> Result<Pvt, TrajBuildError> {
        let tol = s.trajectory.start_tolerance_counts;
        let wait = Duration::from_secs_f64(s.trajectory.stream_wait_s);
        let rules = KnotRules::from_settings(s);
        let pvt = match KnotSource::from_settings(s)? {
            KnotSource::File(path) => {
                let text = read_knot_file(&path)?;
                let knots = parse_pvt(&path.display().to_string(), &text, &rules)?;
                Pvt::new(PvtSource::Knots(Arc::new(knots)), s.n_motors, s.period_s(), tol, wait)
            }
            stream => Pvt::from_stream(stream, s.n_motors, s.period_s(), tol, wait),
        };
        Ok(Pvt { rules, ..pvt })
    }

    /// The first knots: a file's at once; a stream's through the reader thread, waited for.
    fn first_knots(&mut self) -> Result<Vec<PvtKnot>, TrajStartError> {
        let source = match &self.source {
            PvtSource::Knots(knots) => {
                let first: Vec<PvtKnot> = knots.iter().take(MIN_PVT_KNOTS).copied().collect();
                self.next_knot = first.len();
                return Ok(first);
            }
            PvtSource::Stream(source) => source.clone(),
        };
        let (mut producer, mut consumer) = RingBuffer::new(PVT_QUEUE_CAPACITY);
        let rules = self.rules;
        let failure = Arc::clone(&self.failure);
        qmarc_timer::rt::spawn_normal("qmarc-knots", move || {
            read_stream(&source, &rules, &mut producer, &failure)
        })
        .map_err(|e| {
            knots_failed(KnotFileError::Read {
                file: self.source_name(),
                reason: format!("reader thread: {e}"),
            })
        })?;
        let started = Instant::now();
        let mut first = Vec::with_capacity(MIN_PVT_KNOTS);
        while first.len() < MIN_PVT_KNOTS {
            match consumer.pop() {
                Ok(Feed::Knot(k)) => first.push(k),
                Ok(Feed::End) => break,
                Ok(Feed::Error) => return Err(knots_failed(self.stored_failure())),
                Err(_) if qmarc_timer::stop::requested() => {
                    return Err(TrajStartError::Interrupted { stream: self.source_name() });
                }
                Err(_) if started.elapsed() < self.stream_wait => {
                    std::thread::sleep(Duration::from_millis(1))
                }
                Err(_) => {
                    return Err(TrajStartError::NoKnots {
                        stream: self.source_name(),
                        got: first.len(),
                        needed: MIN_PVT_KNOTS,
                        waited_s: self.stream_wait.as_secs_f64(),
                    });
                }
            }
        }
        self.consumer = Some(consumer);
        Ok(first)
    }

    /// The next knot: a file's from memory, a stream's from the queue (`None`: none yet).
    #[inline]
    fn next_feed(&mut self) -> Option<Feed> {
        match &self.source {
            PvtSource::Knots(knots) => {
                let feed = knots.get(self.next_knot).map_or(Feed::End, |k| Feed::Knot(*k));
                self.next_knot += 1;
                Some(feed)
            }
            PvtSource::Stream(_) => self.consumer.as_mut().and_then(|c| c.pop().ok()),
        }
    }

    fn source_name(&self) -> String {
        match &self.source {
            PvtSource::Knots(_) => "knots".into(),
            PvtSource::Stream(s) => s.name(),
        }
    }

    fn stored_failure(&self) -> KnotFileError {
        self.failure.lock().ok().and_then(|f| f.clone()).unwrap_or(KnotFileError::Read {
            file: self.source_name(),
            reason: "the knot reader failed".into(),
        })
    }

    fn enter_segment(&mut self, next: PvtKnot) {
        let from = self.end_knot;
        self.seg_start += self.seg_len;
        self.seg_len = from.dt_s;
        for (m, seg) in self.seg.iter_mut().enumerate().take(self.n_motors) {
            *seg = Hermite::new(from.pos[m], from.vel[m], next.pos[m], next.vel[m], from.dt_s);
        }
        self.end_knot = next;
    }

    /// Why it failed, in words, after a failed sample.
    pub fn failure(&self) -> Option<String> {
        self.failed.then(|| self.stored_failure().to_string())
    }
}

impl TrajectoryGenerator for Pvt {
    fn name(&self) -> &'static str {
        "pvt"
    }

    /// The first knot (a stream's first knots are read for it, and kept for `start`).
    fn first_command(&mut self) -> Result<Option<[f64; MAX_MOTORS]>, TrajStartError> {
        if self.first.is_empty() {
            self.first = self.first_knots()?;
        }
        Ok(Some(self.first[0].pos))
    }

    fn start(&mut self, start: &[f64; MAX_MOTORS]) -> Result<(), TrajStartError> {
        let first = match std::mem::take(&mut self.first) {
            read if !read.is_empty() => read,
            _ => self.first_knots()?,
        };
        check_start(start, &first[0].pos, self.n_motors, self.start_tolerance)?;
        self.seg_start = 0.0;
        self.seg_len = 0.0;
        self.end_knot = first[0];
        self.enter_segment(first[1]);
        self.seg_start = 0.0;
        self.pending = first.get(2).copied();
        self.ended = false;
        self.failed = false;
        Ok(())
    }

    fn samples(&self) -> Option<u64> {
        match &self.source {
            PvtSource::Knots(k) => {
                let total: f64 = k[..k.len() - 1].iter().map(|k| k.dt_s).sum();
                Some(samples_between(0.0, total, self.period_s))
            }
            PvtSource::Stream(_) => None,
        }
    }

    #[inline]
    fn sample(&mut self, n: u64, cmd: &mut [f64; MAX_MOTORS]) -> Sample {
        let t = n as f64 * self.period_s;
        while t > self.seg_start + self.seg_len + 1e-9 {
            if self.ended {
                return Sample::Done;
            }
            if self.failed {
                return Sample::Failed;
            }
            let next = match self.pending.take() {
                Some(k) => k,
                None => match self.next_feed() {
                    Some(Feed::Knot(k)) => k,
                    Some(Feed::End) => {
                        self.ended = true;
                        return Sample::Done;
                    }
                    Some(Feed::Error) => {
                        self.failed = true;
                        return Sample::Failed;
                    }
                    None => return Sample::Starved,
                },
            };
            self.enter_segment(next);
        }
        let tau = t - self.seg_start;
        for (c, seg) in cmd.iter_mut().zip(&self.seg).take(self.n_motors) {
            *c = seg.position(tau);
        }
        Sample::Ready
    }

    /// A file's last knot; a stream's once it has ended.
    fn end_velocity(&self) -> Option<[f64; MAX_MOTORS]> {
        match &self.source {
            PvtSource::Knots(k) => k.last().map(|k| k.vel),
            PvtSource::Stream(_) => self.ended.then_some(self.end_knot.vel),
        }
    }

    /// From a file: the extremes of every segment's cubic over its whole span (the cubics
    /// can overshoot their knots), found from the roots of its derivative: O(knots), however
    /// long the path. They bound every sample, so a path is never passed that a sample breaks.
    fn path_bounds(&self) -> Option<[(f64, f64); MAX_MOTORS]> {
        let PvtSource::Knots(knots) = &self.source else { return None };
        let mut b = bounds_of(knots.iter().map(|k| &k.pos));
        for w in knots.windows(2) {
            for (m, bm) in b.iter_mut().enumerate().take(self.n_motors) {
                let seg =
                    Hermite::new(w[0].pos[m], w[0].vel[m], w[1].pos[m], w[1].vel[m], w[0].dt_s);
                let (lo, hi) = seg.extremes(w[0].dt_s);
                *bm = (bm.0.min(lo), bm.1.max(hi));
            }
        }
        Some(b)
    }

    fn report(&self) -> GeneratorReport {
        GeneratorReport { failure: self.failure(), ..GeneratorReport::default() }
    }
}

#[cfg(test)]
mod tests;

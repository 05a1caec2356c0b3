//! [`PidFf`]: the thesis' law — PID with velocity and acceleration feed-forward, PMAC form
//! (eq. 3-1), then the notch of eq. 3-2.

use qmarc_config::{MotorGains, Settings};
use qmarc_controller::law::{ServoInput, ServoLaw, to_dac_code};
use qmarc_proto::MAX_MOTORS;

/// The biquad notch of thesis eq. 3-2 (PMAC Ix36–Ix39):
/// H(z) = (1 + n1·z⁻¹ + n2·z⁻²) / (1 + d1·z⁻¹ + d2·z⁻²). All-zero coefficients pass the
/// signal unchanged.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Notch {
    /// `[n1, n2, d1, d2]`.
    pub coeffs: [f64; 4],
    x1: f64,
    x2: f64,
    y1: f64,
    y2: f64,
}

impl Notch {
    /// A notch with coefficients `[n1, n2, d1, d2]` and zero state.
    pub fn new(coeffs: [f64; 4]) -> Notch {
        Notch { coeffs, ..Notch::default() }
    }

    /// Filters one sample: y(n) = x(n) + n1·x(n−1) + n2·x(n−2) − d1·y(n−1) − d2·y(n−2).
    #[inline]
    pub fn filter(&mut self, x: f64) -> f64 {
        let [n1, n2, d1, d2] = self.coeffs;
        let y = x + n1 * self.x1 + n2 * self.x2 - d1 * self.y1 - d2 * self.y2;
        self.x2 = self.x1;
        self.x1 = x;
        self.y2 = self.y1;
        self.y1 = y;
        y
    }

    /// Zeroes the state.
    pub fn reset(&mut self) {
        *self = Notch::new(self.coeffs);
    }
}

/// Per-motor state of [`PidFf`].
#[derive(Debug, Clone, Copy, Default, PartialEq)]
struct AxisState {
    prev_cmd: f64,
    /// CV of the previous cycle, counts per period.
    prev_cv: f64,
    /// CA of the previous cycle, counts per period², and the periods between the midpoints
    /// of the velocity spans it was taken over.
    prev_ca: f64,
    prev_ca_span: f64,
    /// Periods the previous cycle's differences spanned (0 before the first cycle).
    prev_elapsed: u64,
    prev_act: f64,
    /// FE of the previous cycle, held over the periods until this one.
    prev_fe: f64,
    /// IE(n) = Σ_{j<n} FE(j).
    ie: f64,
    notch: Notch,
}

/// 2⁻¹⁹, the PMAC output scale.
const TWO_POW_M19: f64 = 1.0 / 524_288.0;
/// 2²³, the PMAC integrator scale.
const TWO_POW_23: f64 = 8_388_608.0;

/// PID with velocity and acceleration feed-forward, PMAC form (thesis eq. 3-1), divided by 4
/// for the 626's 14-bit DAC, then the notch of eq. 3-2, then clamped to ±8191 and rounded to a
/// DAC code:
///
/// DAC(n) = 2⁻¹⁹·Kp·(s·FE + (Kvff·CV + Kaff·CA + Kjff·CJ)/128 + s·Ki·IE/2²³ − Kd·AV/128) / 4
///
/// where s is `general.fe_scale`: 96 (PMAC's Ix08 kept on the error terms, not on the
/// feed-forward nor on Kd) is the reading under which the thesis' Table 5-1 gains give its
/// step (Fig. 5-1) and its path errors (Table 5-2) on one plant; s = 1 is eq. 3-1 read
/// literally (docs/deltabot.md, "Which eq. 3-1").
///
/// with FE = CP(n) − AP(n), CV = CP(n) − CP(n−1), CA = CV(n) − CV(n−1),
/// CJ = CA(n) − CA(n−1), AV = AP(n) − AP(n−1) and IE(n) = Σ_{j<n} FE(j), all in counts per
/// servo period. The jerk feed-forward Kjff·CJ is not the thesis' (Kjff = 0 is eq. 3-1): a
/// velocity-mode amplifier with a second-order velocity loop (ωn, ζ) turns the voltage for
/// v + (2ζ/ωn)·a + j/ωn² into the velocity v, so Kvff and Kaff alone leave a lag of
/// Δa/ωn² at every change of acceleration (docs/tuning.md, "Jerk feed-forward").
///
/// After missed periods (the previous cycle was k = [`ServoInput::elapsed`] periods ago) the
/// differences span k periods: CV and AV are divided by k, CA by the periods between the
/// midpoints of the two velocity spans, CJ by the periods between the midpoints of the two
/// acceleration spans, and the integral counts the previous FE k times (the
/// DAC held its output meanwhile). A late cycle thus outputs what a punctual one would, not
/// a feed-forward kick k times too large.
#[derive(Debug, Clone, PartialEq)]
#[doc(alias = "PIDffCtrl")]
pub struct PidFf {
    n_motors: usize,
    fe_scale: f64,
    gains: [MotorGains; MAX_MOTORS],
    state: [AxisState; MAX_MOTORS],
}

impl PidFf {
    /// The law for the first `gains.len()` motors (at most [`MAX_MOTORS`]), eq. 3-1 read
    /// literally (`fe_scale` 1: see [`PidFf::with_fe_scale`]).
    pub fn new(gains: &[MotorGains]) -> PidFf {
        PidFf::with_fe_scale(gains, 1.0)
    }

    /// The law with the following-error and integral terms scaled by `fe_scale`
    /// (`general.fe_scale`: 96, PMAC's Ix08, for the thesis' gains).
    pub fn with_fe_scale(gains: &[MotorGains], fe_scale: f64) -> PidFf {
        let n_motors = gains.len().min(MAX_MOTORS);
        let mut g = [MotorGains::default(); MAX_MOTORS];
        g[..n_motors].copy_from_slice(&gains[..n_motors]);
        let mut state = [AxisState::default(); MAX_MOTORS];
        for (s, gains) in state.iter_mut().zip(&g) {
            s.notch = Notch::new(gains.notch);
        }
        PidFf { n_motors, fe_scale, gains: g, state }
    }

    /// The law with the gains of the motors in use, rescaled to the servo period
    /// ([`Settings::effective_gains`]).
    pub fn from_settings(settings: &Settings) -> PidFf {
        let gains: Vec<MotorGains> =
            (0..settings.n_motors).map(|m| settings.effective_gains(m)).collect();
        PidFf::with_fe_scale(&gains, settings.fe_scale)
    }

    /// The output of eq. 3-1 / 4 for one motor, before the notch (DAC codes, unclamped),
    /// the following error `fe` and integrated error `ie` already scaled by `fe_scale`.
    #[inline]
    pub fn pmac_output(g: &MotorGains, fe: f64, cv: f64, ca: f64, ie: f64, av: f64) -> f64 {
        PidFf::output(g, fe, [cv, ca, 0.0], ie, av)
    }

    /// [`PidFf::pmac_output`] with the jerk feed-forward: `ff` is `[CV, CA, CJ]`.
    #[inline]
    pub fn output(g: &MotorGains, fe: f64, ff: [f64; 3], ie: f64, av: f64) -> f64 {
        let [cv, ca, cj] = ff;
        TWO_POW_M19
            * g.kp
            * (fe + (g.kvff * cv + g.kaff * ca + g.kjff * cj) / 128.0 + g.ki * ie / TWO_POW_23
                - g.kd * av / 128.0)
            / 4.0
    }
}

impl ServoLaw for PidFf {
    fn name(&self) -> &'static str {
        "pidff"
    }

    fn reset(&mut self, cmd: &[f64; MAX_MOTORS], act: &[f64; MAX_MOTORS]) {
        for m in 0..MAX_MOTORS {
            let s = &mut self.state[m];
            *s = AxisState {
                prev_cmd: cmd[m],
                prev_act: act[m],
                notch: s.notch,
                ..AxisState::default()
            };
            s.notch.reset();
        }
    }

    #[inline]
    fn step(&mut self, input: &ServoInput<'_>, dac: &mut [i32; MAX_MOTORS]) {
        let k = input.elapsed.max(1);
        let span = k as f64;
        let axes = self.gains.iter().zip(self.state.iter_mut()).zip(dac.iter_mut());
        for (m, ((g, s), out)) in axes.enumerate().take(self.n_motors) {
            let (cp, ap) = (input.cmd[m], input.act[m]);
            // IE(n) = Σ_{j<n} FE(j): the previous error held over the periods since.
            s.ie += s.prev_fe * span;
            let fe = cp - ap;
            let cv = (cp - s.prev_cmd) / span;
            // Periods between the midpoints of this velocity's span and the previous one's.
            let ca_span = (k + s.prev_elapsed.max(1)) as f64 / 2.0;
            let ca = (cv - s.prev_cv) / ca_span;
            // Periods between the midpoints of this acceleration's span and the previous one's.
            let cj_span = (ca_span + s.prev_ca_span.max(1.0)) / 2.0;
            let cj = (ca - s.prev_ca) / cj_span;
            let av = (ap - s.prev_act) / span;
            let ff = [cv, ca, cj];
            let u = PidFf::output(g, self.fe_scale * fe, ff, self.fe_scale * s.ie, av);
            s.prev_fe = fe;
            s.prev_cmd = cp;
            s.prev_cv = cv;
            s.prev_ca = ca;
            s.prev_ca_span = ca_span;
            s.prev_elapsed = k;
            s.prev_act = ap;
            *out = to_dac_code(s.notch.filter(u));
        }
        for d in &mut dac[self.n_motors..] {
            *d = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use qmarc_controller::law::NOT_A_CODE;

    fn thesis_motor_1() -> MotorGains {
        MotorGains {
            kp: 182_000.0,
            ki: 100.0,
            kd: 3_000.0,
            kvff: 119_000.0,
            kaff: 100.0,
            kjff: 0.0,
            notch: [0.0; 4],
        }
    }

    fn run(law: &mut PidFf, cmd: f64, act: f64) -> i32 {
        let mut c = [0.0; MAX_MOTORS];
        let mut a = [0.0; MAX_MOTORS];
        c[0] = cmd;
        a[0] = act;
        let mut dac = [7; MAX_MOTORS];
        law.step(&ServoInput { n: 0, elapsed: 1, cmd: &c, act: &a }, &mut dac);
        assert_eq!(&dac[1..], &[0; MAX_MOTORS - 1], "unused motors get 0");
        dac[0]
    }

    /// Two cycles of eq. 3-1 with Table 5-1's motor-1 gains, worked by hand:
    ///
    /// cycle 1: CP 0→10, AP 0→2: FE 8, CV 10, CA 10, AV 2, IE 0.
    ///   inner = 8 + (119000·10 + 100·10)/128 + 0 − 3000·2/128 = 8 + 9304.6875 − 46.875
    ///         = 9265.8125; DAC = 182000 · 9265.8125 / 2¹⁹ / 4 = 804.128 → 804.
    /// cycle 2: CP 10→15, AP 2→5: FE 10, CV 5, CA −5, AV 3, IE 8.
    ///   inner = 10 + (595000 − 500)/128 + 100·8/2²³ − 9000/128
    ///         = 10 + 4644.53125 + 0.0000953674 − 70.3125 = 4584.2188454;
    ///   DAC = 182000 · 4584.2188454 / 2¹⁹ / 4 = 397.838… → 398.
    #[test]
    fn eq_3_1_matches_the_hand_computation() {
        let mut law = PidFf::new(&[thesis_motor_1()]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        let inner1: f64 = 8.0 + 9_304.687_5 - 46.875;
        assert_eq!(inner1, 9_265.812_5);
        let u1 = 182_000.0 * inner1 / 524_288.0 / 4.0;
        assert!((u1 - 804.127_6).abs() < 1e-3, "{u1}");
        assert_eq!(run(&mut law, 10.0, 2.0), 804);
        let inner2: f64 = 10.0 + 4_644.531_25 + 800.0 / 8_388_608.0 - 70.312_5;
        let u2 = 182_000.0 * inner2 / 524_288.0 / 4.0;
        assert!((u2 - 397.838).abs() < 1e-3, "{u2}");
        assert_eq!(run(&mut law, 15.0, 5.0), 398);
        let g = thesis_motor_1();
        assert_eq!(PidFf::pmac_output(&g, 10.0, 5.0, -5.0, 8.0, 3.0), u2);
    }

    /// `fe_scale` multiplies the following error and the integral, nothing else: the same
    /// cycle 2 as above with s = 96: inner = 96·10 + 4644.53125 + 96·100·8/2²³ − 70.3125.
    #[test]
    fn fe_scale_multiplies_the_error_terms_only() {
        let mut law = PidFf::with_fe_scale(&[thesis_motor_1()], 96.0);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        let inner1: f64 = 96.0 * 8.0 + 9_304.687_5 - 46.875;
        assert_eq!(run(&mut law, 10.0, 2.0), (182_000.0 * inner1 / 524_288.0 / 4.0).round() as i32);
        let inner2: f64 = 960.0 + 4_644.531_25 + 96.0 * 800.0 / 8_388_608.0 - 70.312_5;
        let u2 = 182_000.0 * inner2 / 524_288.0 / 4.0;
        assert!((u2 - 480.284).abs() < 1e-3, "{u2}");
        assert_eq!(run(&mut law, 15.0, 5.0), 480);
    }

    #[test]
    fn output_is_clamped_to_the_14_bit_range_and_rounded() {
        let mut law = PidFf::new(&[thesis_motor_1()]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        assert_eq!(run(&mut law, 1_000.0, 0.0), 8191, "the step's velocity kick saturates");
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        assert_eq!(run(&mut law, -1_000.0, 0.0), -8191);
        for (u, code) in [
            (0.49, 0),
            (0.5, 1),
            (-0.5, -1),
            (8190.6, 8191),
            (1e300, 8191),
            (f64::NAN, NOT_A_CODE),
            (f64::INFINITY, NOT_A_CODE),
        ] {
            assert_eq!(to_dac_code(u), code, "{u}");
        }
    }

    #[test]
    fn proportional_term_alone_is_kp_fe_over_2_pow_21() {
        let g = MotorGains { kp: 2_097_152.0, ..MotorGains::default() }; // 2²¹: 1 code per count
        let mut law = PidFf::new(&[g]);
        law.reset(&[100.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        assert_eq!(run(&mut law, 100.0, 0.0), 100);
        assert_eq!(run(&mut law, 100.0, 60.0), 40);
    }

    #[test]
    fn integrator_sums_past_errors_only() {
        // Ki alone: IE(n) = Σ_{j<n} FE(j); Kp·Ki/2^19/2^23/4 = 1 code per count·cycle.
        let g = MotorGains { kp: 1.0, ki: (1u64 << 44) as f64, ..MotorGains::default() };
        let mut law = PidFf::new(&[g]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        // FE = 5 every cycle; the P term is 5·2⁻²¹ ≈ 0, invisible after rounding.
        assert_eq!(run(&mut law, 5.0, 0.0), 0);
        assert_eq!(run(&mut law, 5.0, 0.0), 5);
        assert_eq!(run(&mut law, 5.0, 0.0), 10);
    }

    #[test]
    fn notch_is_the_biquad_of_eq_3_2() {
        let c = [-1.6, 0.8, -1.2, 0.5];
        let mut n = Notch::new(c);
        let x = [1.0, 2.0, -1.0, 0.5];
        let y0 = 1.0;
        let y1 = 2.0 + (-1.6) * 1.0 - (-1.2) * y0;
        let y2 = -1.0 + (-1.6) * 2.0 + 0.8 * 1.0 - (-1.2) * y1 - 0.5 * y0;
        let y3 = 0.5 + (-1.6) * -1.0 + 0.8 * 2.0 - (-1.2) * y2 - 0.5 * y1;
        for (xi, yi) in x.iter().zip([y0, y1, y2, y3]) {
            assert_eq!(n.filter(*xi), yi);
        }
        n.reset();
        assert_eq!(n.filter(3.0), 3.0);
        let mut off = Notch::new([0.0; 4]);
        for v in [1.0, -7.5, 1e6] {
            assert_eq!(off.filter(v), v, "all-zero coefficients pass the signal");
        }
    }

    #[test]
    fn notch_follows_the_law_before_clamping() {
        let g =
            MotorGains { kp: 2_097_152.0, notch: [0.0, 0.0, -0.5, 0.0], ..MotorGains::default() };
        let mut law = PidFf::new(&[g]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        // u = FE = 100 each cycle; y(n) = u + 0.5·y(n−1): 100, 150, 175.
        assert_eq!(run(&mut law, 100.0, 0.0), 100);
        assert_eq!(run(&mut law, 100.0, 0.0), 150);
        assert_eq!(run(&mut law, 100.0, 0.0), 175);
    }

    /// Issue 9, item 1: after missed periods the sample index skips, and one late cycle must
    /// output what a punctual one would. A 17 counts/sample ramp followed with a constant lag:
    /// a punctual loop and one that misses 3 periods before sample 8 give the same DAC code
    /// at sample 8 (before the fix, CV, CA and AV spanned 4 periods: 5353 instead of ≈ 1338).
    #[test]
    fn missed_periods_do_not_kick_the_feed_forward() {
        let g = thesis_motor_1();
        let ramp = |n: u64| 17.0 * n as f64;
        let lag = 3.0;
        let at = |law: &mut PidFf, n: u64, elapsed: u64| -> i32 {
            let mut c = [0.0; MAX_MOTORS];
            let mut a = [0.0; MAX_MOTORS];
            c[0] = ramp(n);
            a[0] = ramp(n) - lag;
            let mut dac = [0; MAX_MOTORS];
            law.step(&ServoInput { n, elapsed, cmd: &c, act: &a }, &mut dac);
            dac[0]
        };
        let start = |law: &mut PidFf| {
            let mut a = [0.0; MAX_MOTORS];
            a[0] = -lag;
            law.reset(&[0.0; MAX_MOTORS], &a);
        };
        let mut punctual = PidFf::new(&[g]);
        start(&mut punctual);
        let mut late = PidFf::new(&[g]);
        start(&mut late);
        let mut expected = 0;
        for n in 1..=8 {
            expected = at(&mut punctual, n, 1);
        }
        for n in 1..=4 {
            at(&mut late, n, 1);
        }
        let got = at(&mut late, 8, 4);
        // The integrator saw the same (constant) error for the same number of periods.
        assert_eq!(got, expected, "late cycle {got}, punctual {expected}");
        assert!((1300..1400).contains(&expected), "{expected}");
        // And the next punctual cycle is unaffected as well.
        assert_eq!(at(&mut late, 9, 1), at(&mut punctual, 9, 1));
    }

    /// Issue 32: `reset` is where a move starts — at the robot's position, wherever that is.
    /// A law reset there and held there outputs nothing: no feed-forward or derivative kick
    /// from a previous position, no integral, no notch state left from the last move.
    #[test]
    fn a_law_reset_away_from_zero_starts_without_a_kick() {
        let notched = MotorGains { notch: [0.0, 0.0, -0.5, 0.0], ki: 1e6, ..thesis_motor_1() };
        let mut law = PidFf::new(&[notched, thesis_motor_1(), thesis_motor_1()]);
        assert_eq!(law.name(), "pidff", "the name settings and results know it by");
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        // A previous move that ended with an error: integral and notch state built up.
        let (mut c, mut a) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS]);
        let mut dac = [0; MAX_MOTORS];
        for n in 1..50 {
            c[..3].copy_from_slice(&[20.0 * n as f64, -7.0 * n as f64, 3.0]);
            a[..3].copy_from_slice(&[c[0] - 40.0, c[1] + 9.0, -30.0]);
            law.step(&ServoInput { n, elapsed: 1, cmd: &c, act: &a }, &mut dac);
        }
        assert!(dac[..3].iter().all(|&d| d != 0), "{dac:?}");
        // The next move starts where the robot rests, each motor elsewhere, command on it.
        let here = [5_000.0, -3_000.0, 123_456.0, 0.0];
        law.reset(&here, &here);
        for n in 1..4 {
            law.step(&ServoInput { n, elapsed: 1, cmd: &here, act: &here }, &mut dac);
            assert_eq!(dac, [0; MAX_MOTORS], "cycle {n} after the reset");
        }
        // Reset with the robot off its command: the first cycle sees that error and nothing
        // else (no velocity from 0 to here, no acceleration, no integral yet).
        let act = here.map(|h| h - 10.0);
        law.reset(&here, &act);
        law.step(&ServoInput { n: 1, elapsed: 1, cmd: &here, act: &act }, &mut dac);
        let g = thesis_motor_1();
        let p = PidFf::pmac_output(&g, 10.0, 0.0, 0.0, 0.0, 0.0).round() as i32;
        assert_eq!(&dac[..3], &[p, p, p]);
    }

    /// Issue 32: after missed periods the integral counts the previous error once per period
    /// it was held (the DAC held its output meanwhile): one late cycle after 4 periods sums
    /// what 4 punctual ones do.
    #[test]
    fn the_integral_counts_a_held_error_once_per_missed_period() {
        // Ki alone, 1 code per count·period (as `integrator_sums_past_errors_only`).
        let g = MotorGains { kp: 1.0, ki: (1u64 << 44) as f64, ..MotorGains::default() };
        let at = |law: &mut PidFf, n: u64, elapsed: u64| {
            let (mut c, a) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS]);
            c[0] = 5.0;
            let mut dac = [0; MAX_MOTORS];
            law.step(&ServoInput { n, elapsed, cmd: &c, act: &a }, &mut dac);
            dac[0]
        };
        let (mut punctual, mut late) = (PidFf::new(&[g]), PidFf::new(&[g]));
        let mut c0 = [0.0; MAX_MOTORS];
        c0[0] = 5.0;
        punctual.reset(&c0, &[0.0; MAX_MOTORS]);
        late.reset(&c0, &[0.0; MAX_MOTORS]);
        let expected: Vec<i32> = (1..=6).map(|n| at(&mut punctual, n, 1)).collect();
        assert_eq!(expected, [0, 5, 10, 15, 20, 25]);
        assert_eq!(at(&mut late, 1, 1), 0);
        assert_eq!(at(&mut late, 5, 4), 20, "4 periods of FE 5 held");
        assert_eq!(at(&mut late, 6, 1), 25);
    }

    /// The shipped settings of one robot at both count scales: `config/qmarc.toml` at 4×
    /// (the thesis' counts) and `config/s626.toml` at the 626's 1×.
    fn shipped_at_both_scales() -> (Settings, Settings) {
        let names = qmarc_config::Names {
            laws: crate::registry::law_names(),
            methods: crate::registry::path_generator_names(),
            any_plugin: false,
        };
        let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config");
        let load = |f: &str| Settings::load(&dir.join(f), &names).expect("shipped settings");
        (load("qmarc.toml"), load("s626.toml"))
    }

    proptest::proptest! {
        /// Issue 27: every term inside eq. 3-1's bracket (FE, CV, CA, IE, AV) is in counts, so
        /// one physical motion counted 4× and 1× gives the same volts only when Kp alone
        /// carries the factor of 4. The shipped files' laws, fed the same motion in each
        /// file's counts (1× = 4× / 4), output the same DAC code every cycle (rounding apart).
        #[test]
        fn the_shipped_626_gains_are_the_4x_loop_at_1x_counting(
            motion in proptest::collection::vec((-60.0f64..60.0, -30.0f64..30.0), 2..200),
        ) {
            let (at4, at1) = shipped_at_both_scales();
            proptest::prop_assert_eq!(at1.counts_per_rev * 4.0, at4.counts_per_rev);
            let (mut law4, mut law1) = (PidFf::from_settings(&at4), PidFf::from_settings(&at1));
            let zero = [0.0; MAX_MOTORS];
            law4.reset(&zero, &zero);
            law1.reset(&zero, &zero);
            // A path of random velocities (counts/period at 4×) and a following error.
            let (mut cmd4, mut act4) = ([0.0; MAX_MOTORS], [0.0; MAX_MOTORS]);
            for (n, (v, fe)) in motion.iter().enumerate() {
                for m in 0..at4.n_motors {
                    cmd4[m] += v * (1.0 + m as f64 / 4.0);
                    act4[m] = cmd4[m] - fe;
                }
                let (cmd1, act1) = (cmd4.map(|c| c / 4.0), act4.map(|a| a / 4.0));
                let (mut dac4, mut dac1) = ([0; MAX_MOTORS], [0; MAX_MOTORS]);
                let n = n as u64 + 1;
                law4.step(&ServoInput { n, elapsed: 1, cmd: &cmd4, act: &act4 }, &mut dac4);
                law1.step(&ServoInput { n, elapsed: 1, cmd: &cmd1, act: &act1 }, &mut dac1);
                for m in 0..at4.n_motors {
                    proptest::prop_assert!(
                        (dac4[m] - dac1[m]).abs() <= 1,
                        "cycle {n} motor {}: {} at 4×, {} at 1×", m + 1, dac4[m], dac1[m]
                    );
                }
            }
        }
    }

    /// On an accelerating path, CA after a skip is the acceleration per period², not k
    /// times it: c(n) = n², so CA is 2 counts/period² whatever the spacing of the cycles.
    #[test]
    fn acceleration_feed_forward_is_per_period_after_a_skip() {
        let g = MotorGains { kp: 2_097_152.0, kaff: 128.0, ..MotorGains::default() };
        let mut law = PidFf::new(&[g]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        let step = |law: &mut PidFf, n: u64, elapsed: u64| {
            let mut c = [0.0; MAX_MOTORS];
            c[0] = (n * n) as f64;
            let mut dac = [0; MAX_MOTORS];
            // act = cmd: FE = 0 and AV does not enter (Kd = 0); the output is Kaff·CA/128 = CA.
            law.step(&ServoInput { n, elapsed, cmd: &c, act: &c }, &mut dac);
            dac[0]
        };
        step(&mut law, 1, 1);
        assert_eq!(step(&mut law, 2, 1), 2);
        assert_eq!(step(&mut law, 6, 4), 2, "skipped 3 periods");
        assert_eq!(step(&mut law, 7, 1), 2);
    }

    /// Kjff·CJ/128 is added inside the bracket, CJ = CA(n) − CA(n−1): the hand computation's
    /// cycle 2 (CA 10 then −5, so CJ = −15) with Kjff = 12 800 outputs 2⁻²¹·Kp·(−1500) more
    /// than with Kjff = 0 (eq. 3-1, which the other tests check).
    #[test]
    fn jerk_feed_forward_is_kjff_times_cj_over_128() {
        let with = |kjff: f64| {
            let mut law = PidFf::new(&[MotorGains { kjff, ..thesis_motor_1() }]);
            law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
            run(&mut law, 10.0, 2.0);
            run(&mut law, 15.0, 5.0)
        };
        let extra: f64 = 182_000.0 * (12_800.0 * -15.0 / 128.0) / 524_288.0 / 4.0;
        assert_eq!(extra.round(), -130.0);
        assert_eq!(with(12_800.0) - with(0.0), -130);
        let g = MotorGains { kjff: 12_800.0, ..thesis_motor_1() };
        let u = PidFf::output(&g, 10.0, [5.0, -5.0, -15.0], 8.0, 3.0);
        assert!((u - PidFf::pmac_output(&g, 10.0, 5.0, -5.0, 8.0, 3.0) - extra).abs() < 1e-9);
    }

    /// On a cubic path c(n) = n³ the third difference CJ is 6 counts/period³; after missed
    /// periods it is taken over the periods between the acceleration spans' midpoints, so
    /// a late cycle outputs about 6 (not k³ or 1/k times it) and the loop is back on 6 three
    /// punctual cycles later. Kp = 2²¹, Kjff = 1280: the output is 10·CJ.
    #[test]
    fn jerk_feed_forward_is_per_period_after_a_skip() {
        let g = MotorGains { kp: 2_097_152.0, kjff: 1_280.0, ..MotorGains::default() };
        let mut law = PidFf::new(&[g]);
        law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
        let step = |law: &mut PidFf, n: u64, elapsed: u64| {
            let mut c = [0.0; MAX_MOTORS];
            c[0] = (n * n * n) as f64;
            let mut dac = [0; MAX_MOTORS];
            law.step(&ServoInput { n, elapsed, cmd: &c, act: &c }, &mut dac);
            dac[0]
        };
        for n in 1..=4 {
            step(&mut law, n, 1);
        }
        assert_eq!(step(&mut law, 5, 1), 60);
        let late = step(&mut law, 9, 4);
        assert!((55..=70).contains(&late), "skipped 3 periods: {late}");
        for n in 10..=11 {
            let d = step(&mut law, n, 1);
            assert!((45..=70).contains(&d), "{n}: {d}");
        }
        assert_eq!(step(&mut law, 12, 1), 60);
    }

    /// Kjff × (T₀/T)³ at another period: one physical cubic motion, c(t) = (t / 400 µs)³,
    /// at 400 µs with the gains as tuned and at 200 µs with them rescaled (`gains_period_us`
    /// 400) outputs the same jerk feed-forward — CJ per period³ is (T/T₀)³ as large there.
    #[test]
    fn the_jerk_feed_forward_is_rescaled_with_the_period() {
        let (mut s, _) = shipped_at_both_scales();
        for g in &mut s.motors {
            *g = MotorGains { kp: 2_097_152.0, kjff: 1_280.0, ..MotorGains::default() };
        }
        let at = |s: &Settings| {
            let mut law = PidFf::from_settings(s);
            law.reset(&[0.0; MAX_MOTORS], &[0.0; MAX_MOTORS]);
            let per = s.period_us as f64 / 400.0;
            let mut dac = [0; MAX_MOTORS];
            for n in 1..=(8.0 / per) as u64 {
                let c = [(n as f64 * per).powi(3); MAX_MOTORS];
                law.step(&ServoInput { n, elapsed: 1, cmd: &c, act: &c }, &mut dac);
            }
            dac[0]
        };
        assert_eq!(s.gains_period_us, 400);
        assert_eq!(at(&s), 60);
        s.period_us = 200;
        assert_eq!(at(&s), 60, "at 200 µs");
    }
}

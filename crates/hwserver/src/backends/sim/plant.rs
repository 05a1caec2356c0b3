//! The amplifier and motor of one simulated axis (`../shared/notes/deltabot.md`, "Plant"):
//! a velocity-mode amplifier whose velocity loop follows the commanded velocity ω* either as
//! a first-order lag τ, or as a second-order loop (ωn, ζ) — ω̈ = ωn²(ω* − ω) − 2ζωn·ω̇ — and
//! the position x = ∫ω. Both are advanced exactly, in closed form, for a command held over
//! the step (zero-order hold), whatever the step.

/// The velocity loop of an enabled amplifier.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum VelocityLoop {
    /// ω/ω* = 1/(τs + 1).
    FirstOrder {
        /// τ, s.
        tau_s: f64,
    },
    /// ω/ω* = ωn²/(s² + 2ζωn·s + ωn²), underdamped (0 < ζ < 1).
    SecondOrder {
        /// ωn, rad/s.
        wn: f64,
        /// ζ.
        zeta: f64,
    },
}

impl VelocityLoop {
    /// A second-order loop of `hz` Hz and damping `zeta` (< 1), or with `hz` 0 the
    /// first-order lag `tau_s`.
    pub fn new(hz: f64, zeta: f64, tau_s: f64) -> VelocityLoop {
        if hz > 0.0 {
            VelocityLoop::SecondOrder { wn: std::f64::consts::TAU * hz, zeta }
        } else {
            VelocityLoop::FirstOrder { tau_s }
        }
    }

    /// Advances the state `s` of an enabled axis by `dt` s with the velocity command
    /// `target` (counts/s) held.
    pub fn advance(&self, s: &mut AxisState, target: f64, dt: f64) {
        match *self {
            VelocityLoop::FirstOrder { tau_s } => first_order(s, target, tau_s, dt),
            VelocityLoop::SecondOrder { wn, zeta } => second_order(s, target, wn, zeta, dt),
        }
    }
}

/// The state of one axis: position (counts), velocity (counts/s), and the velocity's rate
/// (counts/s², the second-order loop's; 0 with the first-order lag).
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct AxisState {
    /// Position, counts.
    pub x: f64,
    /// Velocity, counts/s.
    pub v: f64,
    /// dv/dt, counts/s².
    pub a: f64,
}

/// The first-order lag over `dt`: ω ← ω* + (ω − ω*)·e^(−dt/τ), x ← x + ω*·dt + (ω − ω*)·τ·(1 −
/// e^(−dt/τ)). Also how a disabled motor coasts to rest (ω* = 0, its own τ).
pub fn first_order(s: &mut AxisState, target: f64, tau: f64, dt: f64) {
    let decay = (-dt / tau).exp();
    let dv = s.v - target;
    s.x += target * dt + dv * tau * (1.0 - decay);
    s.v = target + dv * decay;
    s.a = 0.0;
}

/// The underdamped second-order loop over `dt`, in closed form (a few exponentials and
/// sines, cheap in any build). With e = ω − ω*, σ = ζωn and ωd = ωn√(1 − ζ²):
/// e(t) = e^(−σt)(C1·cos ωd·t + C2·sin ωd·t), C1 = e(0), C2 = (ė(0) + σ·e(0))/ωd; ė is the
/// state's `a`; and x(t) = x(0) + ω*·t + Re(K·(e^(zt) − 1)/z) with K = C1 − i·C2,
/// z = −σ + i·ωd (the integral of e).
pub fn second_order(s: &mut AxisState, target: f64, wn: f64, zeta: f64, dt: f64) {
    let (sigma, wd) = (zeta * wn, wn * (1.0 - zeta * zeta).sqrt());
    let e0 = s.v - target;
    let (c1, c2) = (e0, (s.a + sigma * e0) / wd);
    let decay = (-sigma * dt).exp();
    let (sin, cos) = (wd * dt).sin_cos();
    let e = decay * (c1 * cos + c2 * sin);
    let de = decay * ((wd * c2 - sigma * c1) * cos - (sigma * c2 + wd * c1) * sin);
    // K·(e^(zt) − 1) = P + iQ; divided by z its real part is (−σP + ωd·Q)/ωn².
    let (nr, ni) = (decay * cos - 1.0, decay * sin);
    let (p, q) = (c1 * nr + c2 * ni, c1 * ni - c2 * nr);
    s.x += target * dt + (wd * q - sigma * p) / (wn * wn);
    s.v = target + e;
    s.a = de;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A fine RK4 integration of the same equations, as an independent reference.
    fn rk4(s: AxisState, target: f64, wn: f64, zeta: f64, dt: f64) -> AxisState {
        let f = |y: [f64; 3]| [y[1], y[2], wn * wn * (target - y[1]) - 2.0 * zeta * wn * y[2]];
        let mut y = [s.x, s.v, s.a];
        let n = 2000;
        let h = dt / f64::from(n);
        for _ in 0..n {
            let add = |y: [f64; 3], k: [f64; 3], c: f64| std::array::from_fn(|i| y[i] + c * k[i]);
            let k1 = f(y);
            let k2 = f(add(y, k1, h / 2.0));
            let k3 = f(add(y, k2, h / 2.0));
            let k4 = f(add(y, k3, h));
            y = std::array::from_fn(|i| {
                y[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])
            });
        }
        AxisState { x: y[0], v: y[1], a: y[2] }
    }

    #[test]
    fn the_second_order_step_is_the_exact_solution() {
        let (wn, zeta) = (std::f64::consts::TAU * 61.6, 0.48);
        for dt in [400e-6, 3.7e-3, 0.05] {
            let mut s = AxisState { x: 10.0, v: -300.0, a: 5.0e4 };
            let want = rk4(s, 20_000.0, wn, zeta, dt);
            second_order(&mut s, 20_000.0, wn, zeta, dt);
            assert!((s.x - want.x).abs() < 1e-8, "{dt}: {s:?} {want:?}");
            assert!((s.v - want.v).abs() < 1e-6 && (s.a - want.a).abs() < 1e-3, "{s:?} {want:?}");
        }
        // Two half steps are one whole step: the solution holds for any step.
        let (mut a, mut b) = (AxisState::default(), AxisState::default());
        second_order(&mut a, 1000.0, wn, zeta, 200e-6);
        second_order(&mut a, 1000.0, wn, zeta, 200e-6);
        second_order(&mut b, 1000.0, wn, zeta, 400e-6);
        assert!((a.x - b.x).abs() < 1e-9 && (a.v - b.v).abs() < 1e-7, "{a:?} {b:?}");
    }

    /// A step of the commanded velocity overshoots by e^(−πζ/√(1−ζ²)) (17.9 % at ζ 0.48) and
    /// settles at the command.
    #[test]
    fn a_velocity_step_overshoots_as_its_damping_says() {
        let (wn, zeta) = (std::f64::consts::TAU * 61.6, 0.48);
        let mut s = AxisState::default();
        let mut peak = 0.0f64;
        for _ in 0..20_000 {
            second_order(&mut s, 1000.0, wn, zeta, 10e-6);
            peak = peak.max(s.v);
        }
        let want =
            1000.0 * (1.0 + (-std::f64::consts::PI * zeta / (1.0 - zeta * zeta).sqrt()).exp());
        assert!((peak - want).abs() < 0.5, "{peak} {want}");
        assert!((s.v - 1000.0).abs() < 1e-6 && s.a.abs() < 1e-3, "{s:?}");
    }

    #[test]
    fn the_first_order_lag_decays_by_e_each_tau() {
        let mut s = AxisState { x: 0.0, v: 0.0, a: 3.0 };
        first_order(&mut s, 100.0, 0.004, 0.004);
        assert!((s.v - 100.0 * (1.0 - (-1.0f64).exp())).abs() < 1e-9 && s.a == 0.0, "{s:?}");
        assert!((s.x - 100.0 * 0.004 * (-1.0f64).exp()).abs() < 1e-9, "{s:?}");
    }
}

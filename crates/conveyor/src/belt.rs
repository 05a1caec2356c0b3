//! The belt's motion: where the belt is and how fast it goes at any time, from its speed at
//! the start and its speed changes (`conveyor.speed_mm_s`, `speed_steps`,
//! `acceleration_mm_s2`). The simulated robot's belt encoder and the simulated camera's parts
//! both follow it: one belt, one world.

/// A belt that starts at a speed and changes speed at given times, at its own acceleration.
#[derive(Debug, Clone, PartialEq)]
pub struct BeltMotion {
    speed_mm_s: f64,
    steps: Vec<[f64; 2]>,
    acceleration_mm_s2: f64,
}

impl BeltMotion {
    /// A belt at `speed_mm_s` from time 0 that turns to `mm_s` at each `[t_s, mm_s]` of
    /// `steps` (times rising), at `acceleration_mm_s2` (> 0).
    pub fn new(speed_mm_s: f64, steps: &[[f64; 2]], acceleration_mm_s2: f64) -> BeltMotion {
        BeltMotion { speed_mm_s, steps: steps.to_vec(), acceleration_mm_s2 }
    }

    /// Where the belt is (mm travelled since time 0) and its speed (mm/s) at `t_s` ≥ 0.
    /// Allocates nothing.
    pub fn at(&self, t_s: f64) -> (f64, f64) {
        let t_s = t_s.max(0.0);
        let (mut x, mut v, mut target, mut from) = (0.0, self.speed_mm_s, self.speed_mm_s, 0.0);
        for &[step_t, step_v] in &self.steps {
            if step_t >= t_s {
                break;
            }
            (x, v) = self.go(x, v, target, step_t - from);
            (target, from) = (step_v, step_t);
        }
        self.go(x, v, target, t_s - from)
    }

    /// From `x` at speed `v`, `dt` seconds turning to `target` at the acceleration.
    fn go(&self, x: f64, v: f64, target: f64, dt: f64) -> (f64, f64) {
        let a = self.acceleration_mm_s2;
        let ramp = ((target - v).abs() / a).min(dt);
        let v_end = if target > v { v + a * ramp } else { v - a * ramp };
        // The ramp, then (when it ends within `dt`) the cruise at the target.
        (x + (v + v_end) / 2.0 * ramp + v_end * (dt - ramp), v_end)
    }
}

#[cfg(test)]
mod tests {
    use super::BeltMotion;

    fn close(a: (f64, f64), b: (f64, f64)) -> bool {
        (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9
    }

    #[test]
    fn a_steady_belt_travels_its_speed_times_the_time() {
        let b = BeltMotion::new(500.0, &[], 2_000.0);
        assert!(close(b.at(0.0), (0.0, 500.0)));
        assert!(close(b.at(2.5), (1_250.0, 500.0)));
        assert!(close(b.at(-1.0), (0.0, 500.0)), "nothing before the start");
    }

    /// A stop at 1 s: 0.25 s of ramp (500 mm/s at 2000 mm/s²), 62.5 mm on the way, then still.
    #[test]
    fn a_speed_change_ramps_at_the_belts_acceleration() {
        let b = BeltMotion::new(500.0, &[[1.0, 0.0]], 2_000.0);
        assert!(close(b.at(1.0), (500.0, 500.0)));
        assert!(close(b.at(1.125), (500.0 + 62.5 - 15.625, 250.0)), "{:?}", b.at(1.125));
        assert!(close(b.at(1.25), (562.5, 0.0)));
        assert!(close(b.at(3.0), (562.5, 0.0)));
        // And up again from rest.
        let c = BeltMotion::new(0.0, &[[0.0, 1_000.0]], 1_000.0);
        assert!(close(c.at(0.5), (125.0, 500.0)));
        assert!(close(c.at(2.0), (500.0 + 1_000.0, 1_000.0)));
    }

    /// A step that comes while the last one still ramps turns from the speed then.
    #[test]
    fn a_step_during_a_ramp_turns_from_where_the_ramp_is() {
        let b = BeltMotion::new(0.0, &[[0.0, 1_000.0], [0.25, 0.0]], 1_000.0);
        // 0.25 s up to 250 mm/s (31.25 mm), then 0.25 s down to 0 (31.25 mm).
        assert!(close(b.at(0.25), (31.25, 250.0)));
        assert!(close(b.at(0.5), (62.5, 0.0)));
        assert!(close(b.at(5.0), (62.5, 0.0)));
    }

    /// The position never jumps and the speed never exceeds what the acceleration allows.
    #[test]
    fn the_motion_is_continuous() {
        let b = BeltMotion::new(300.0, &[[0.2, 800.0], [0.3, 100.0], [1.0, 600.0]], 1_500.0);
        let dt = 1e-4;
        let mut last = b.at(0.0);
        for k in 1..20_000 {
            let now = b.at(k as f64 * dt);
            assert!((now.1 - last.1).abs() <= 1_500.0 * dt + 1e-9, "speed jumps at {k}");
            // The mean of the two speeds is exact but where a ramp ends inside the step (by at
            // most a·dt²/8).
            let mean = (now.1 + last.1) / 2.0 * dt;
            assert!(
                (now.0 - last.0 - mean).abs() <= 1_500.0 * dt * dt / 8.0 + 1e-9,
                "x jumps at {k}"
            );
            last = now;
        }
    }
}

//! Entry points for the fuzz targets (`fuzz/`) and their corpus replay test: parse
//! arbitrary bytes and check what a successful parse promises.

use super::{KnotRules, MAX_POSITION_COUNTS, MIN_PVT_KNOTS, parse_offline, parse_pvt};
use qmarc_proto::MAX_MOTORS;

fn motors_and_text(data: &[u8]) -> Option<(usize, String)> {
    let (&first, rest) = data.split_first()?;
    Some((usize::from(first % MAX_MOTORS as u8) + 1, String::from_utf8(rest.to_vec()).ok()?))
}

/// Offline parser: never panics; a success has the declared count, ≥ 2 knots, strictly
/// increasing finite times and in-range whole positions.
pub fn offline(data: &[u8]) {
    let Some((n, text)) = motors_and_text(data) else { return };
    if let Ok(k) = parse_offline("fuzz", &text, &KnotRules::new(n)) {
        assert!(k.times.len() >= 2 && k.times.len() == k.positions.len());
        assert!(k.times.windows(2).all(|w| w[0] < w[1] && w[1].is_finite()));
        for p in &k.positions {
            assert!(
                p[..n].iter().all(|v| v.fract() == 0.0 && v.abs() <= MAX_POSITION_COUNTS as f64)
            );
            assert!(p[n..].iter().all(|&v| v == 0.0));
        }
    }
}

/// PVT parser: never panics; a success has ≥ 3 knots with positive finite segment times,
/// finite velocities and in-range whole positions.
pub fn pvt(data: &[u8]) {
    let Some((n, text)) = motors_and_text(data) else { return };
    if let Ok(ks) = parse_pvt("fuzz", &text, &KnotRules::new(n)) {
        assert!(ks.len() >= MIN_PVT_KNOTS);
        for k in &ks {
            assert!(k.dt_s > 0.0 && k.dt_s.is_finite());
            assert!(k.vel.iter().all(|v| v.is_finite()));
            assert!(
                k.pos[..n]
                    .iter()
                    .all(|v| v.fract() == 0.0 && v.abs() <= MAX_POSITION_COUNTS as f64)
            );
        }
    }
}

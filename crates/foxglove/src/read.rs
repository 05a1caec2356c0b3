//! gather.mcap read back: its scenes, decoded (the picture of `qmarc-foxglove scene` and the
//! tests' check of what was written).

use foxglove::Decode;
use foxglove::messages::SceneUpdate;

/// The scenes of the MCAP file `bytes` with their log times (ns since the Unix epoch), in the
/// file's order.
pub fn scenes(bytes: &[u8]) -> Result<Vec<(u64, SceneUpdate)>, String> {
    let mut out = Vec::new();
    for m in mcap::MessageStream::new(bytes).map_err(|e| e.to_string())? {
        let m = m.map_err(|e| e.to_string())?;
        if m.channel.topic == crate::channels::SCENE {
            let scene = SceneUpdate::decode(&m.data[..]).map_err(|e| e.to_string())?;
            out.push((m.log_time, scene));
        }
    }
    Ok(out)
}

/// The scene of `scenes` at `t_s` seconds after the first (the last one before or at it; the
/// last one past the end).
pub fn scene_at(scenes: &[(u64, SceneUpdate)], t_s: f64) -> Option<&(u64, SceneUpdate)> {
    let t0 = scenes.first()?.0;
    let at = t0.saturating_add((t_s.max(0.0) * 1e9) as u64);
    let k = scenes.partition_point(|(t, _)| *t <= at);
    scenes.get(k.saturating_sub(1))
}

//! The homed frame kept between runs, the way a card whose counters keep counting while it is
//! powered keeps it: one line `homed 1 0 1` in a file on a tmpfs, which a reboot clears as a
//! power cycle clears the counters.

use qmarc_proto::MAX_MOTORS;
use std::path::Path;

/// Which of `n_motors` motors `path` says are homed; none when it cannot be read (a fresh
/// machine) or says nothing.
pub fn load_homed(path: &Path, n_motors: usize) -> [bool; MAX_MOTORS] {
    let mut homed = [false; MAX_MOTORS];
    let text = qmarc_config::read_bounded(path, 4096).ok().flatten();
    if let Some(text) = text.and_then(|raw| String::from_utf8(raw).ok()) {
        let kept = text.strip_prefix("homed").map(|rest| rest.split_whitespace());
        for (m, flag) in kept.into_iter().flatten().enumerate().take(n_motors.min(MAX_MOTORS)) {
            homed[m] = flag == "1";
        }
    }
    homed
}

/// Writes `homed` to `path` (its folder made if missing); nothing is kept when it cannot be
/// written.
pub fn save_homed(path: &Path, homed: &[bool]) {
    if let Some(dir) = path.parent() {
        let _ = std::fs::create_dir_all(dir);
    }
    let flags: Vec<&str> = homed.iter().map(|&h| if h { "1" } else { "0" }).collect();
    let _ = std::fs::write(path, format!("homed {}\n", flags.join(" ")));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homed_flags_round_trip_and_a_missing_file_homes_nothing() {
        let dir = std::env::temp_dir().join(format!("qmarc-state-{}", std::process::id()));
        let path = dir.join("sub/s.state");
        assert_eq!(load_homed(&path, 3), [false; MAX_MOTORS]);
        save_homed(&path, &[true, false, true]);
        assert_eq!(load_homed(&path, 3)[..3], [true, false, true]);
        assert_eq!(load_homed(&path, 2)[..3], [true, false, false], "only the motors asked for");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

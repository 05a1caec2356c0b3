//! The homed frame kept between runs, the way a card whose counters keep counting while it is
//! powered keeps it: a small file on a tmpfs, which a reboot clears as a power cycle clears
//! the counters —
//!
//! ```text
//! homed 1 0 1
//! card /dev/comedi0 ino 412 ctime 1763900000.123456789 counters [0, 1, 2] signs [1, 1, 1]
//! ```
//!
//! — whose second line names what the frame belongs to: a frame is kept only while that is
//! still the same (a reloaded driver makes a new device node; other wiring, another frame).

use qmarc_proto::MAX_MOTORS;
use std::path::Path;

/// Which of `n_motors` motors `path` says are homed for `identity`; none when it cannot be
/// read (a fresh machine), says nothing, or was written for something else.
pub fn load_homed(path: &Path, n_motors: usize, identity: &str) -> [bool; MAX_MOTORS] {
    read_homed(path, n_motors, identity).unwrap_or([false; MAX_MOTORS])
}

/// [`load_homed`], but a file that is there and cannot be read is an error naming it (what a
/// reader that must not guess says: the console at rest); a missing file, none homed.
pub fn read_homed(
    path: &Path,
    n_motors: usize,
    identity: &str,
) -> Result<[bool; MAX_MOTORS], String> {
    let mut homed = [false; MAX_MOTORS];
    let text = match qmarc_config::read_bounded(path, 4096) {
        Ok(text) => text,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(homed),
        Err(e) => return Err(format!("{}: {e}", path.display())),
    };
    let Some(text) = text.and_then(|raw| String::from_utf8(raw).ok()) else { return Ok(homed) };
    let mut lines = text.lines();
    let flags = lines.next().and_then(|l| l.strip_prefix("homed"));
    let card = lines.next().and_then(|l| l.strip_prefix("card "));
    if card != Some(identity) {
        return Ok(homed);
    }
    let flags = flags.into_iter().flat_map(str::split_whitespace);
    for (h, flag) in homed.iter_mut().zip(flags).take(n_motors) {
        *h = flag == "1";
    }
    Ok(homed)
}

/// Checks, without touching a frame kept there, that `path` can keep one: not a folder, its
/// folder made if missing and writable, the file itself writable if it exists. A homing whose
/// frame could not be kept would be forgotten at once.
pub fn check_keepable(path: &Path) -> std::io::Result<()> {
    if path.is_dir() {
        return Err(std::io::Error::new(std::io::ErrorKind::IsADirectory, "it is a folder"));
    }
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    check_folder(dir)?;
    if path.exists() {
        std::fs::OpenOptions::new().append(true).open(path)?;
    }
    Ok(())
}

/// Checks that files can be made in `dir` (made if missing): a probe file written and
/// removed.
pub fn check_folder(dir: &Path) -> std::io::Result<()> {
    let probe = dir.join(format!(".qmarc-probe-{}", std::process::id()));
    let written = std::fs::create_dir_all(dir).and_then(|()| std::fs::write(&probe, b"qmarc"));
    let _ = std::fs::remove_file(&probe);
    written
}

/// Why the setting `key` = `path` cannot keep a homed frame ([`check_keepable`]), if it is
/// set and cannot.
pub fn keep_problem(key: &str, path: Option<&Path>) -> Option<String> {
    let path = path?;
    check_keepable(path).err().map(|e| {
        format!(
            "{key} = {}: cannot keep the homed frame there ({e}): give a file in a writable \
             folder, or \"\" to keep none",
            path.display()
        )
    })
}

/// Writes `homed` for `identity` to `path`, its folder made if missing.
pub fn save_homed(path: &Path, homed: &[bool], identity: &str) -> std::io::Result<()> {
    if let Some(dir) = path.parent() {
        std::fs::create_dir_all(dir)?;
    }
    let flags: Vec<&str> = homed.iter().map(|&h| if h { "1" } else { "0" }).collect();
    std::fs::write(path, format!("homed {}\ncard {identity}\n", flags.join(" ")))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn homed_flags_round_trip_for_the_same_card_only() {
        let dir = std::env::temp_dir().join(format!("qmarc-state-{}", std::process::id()));
        let path = dir.join("sub/s.state");
        assert_eq!(load_homed(&path, 3, "a"), [false; MAX_MOTORS]);
        save_homed(&path, &[true, false, true], "a").unwrap();
        assert_eq!(load_homed(&path, 3, "a")[..3], [true, false, true]);
        assert_eq!(
            load_homed(&path, 2, "a")[..3],
            [true, false, false],
            "only the motors asked for"
        );
        assert_eq!(load_homed(&path, 3, "b"), [false; MAX_MOTORS], "another card: not homed");
        std::fs::write(&path, "homed 1 1 1\n").unwrap();
        assert_eq!(load_homed(&path, 3, "a"), [false; MAX_MOTORS], "a file of unknown origin");
        let _ = std::fs::remove_dir_all(&dir);
    }
}

//! Integration tests of the starter library: the clean-up of iceoryx2 files that dead
//! starters left behind.

use qmarc_starter::remove_stale_files;
use std::path::PathBuf;
use std::process::Command;

fn shm(name: &str) -> PathBuf {
    PathBuf::from(qmarc_proto::service::SHM_DIR).join(name)
}

#[test]
fn files_of_dead_starters_are_removed_and_files_in_use_are_kept() {
    // A pid that existed and is gone.
    let mut gone = Command::new("true").spawn().unwrap();
    let dead_pid = gone.id();
    gone.wait().unwrap();
    // A process still using a dead starter's prefix (an orphaned child shutting down).
    let mut orphan_pid = Command::new("true").spawn().unwrap();
    let orphan_starter = orphan_pid.id();
    orphan_pid.wait().unwrap();
    let in_use = format!("qmarc_{orphan_starter}_");
    // `sh -c SCRIPT NAME`: NAME (the prefix) stays in the shell's command line.
    let mut orphan =
        Command::new("sh").args(["-c", "while :; do sleep 0.05; done", &in_use]).spawn().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(20));
    // A live starter: this test process.
    let live = format!("qmarc_{}_", std::process::id());

    let root = std::env::temp_dir().join(format!("qmarc-stale-{}", std::process::id()));
    std::fs::create_dir_all(root.join("services")).unwrap();
    let dead = format!("qmarc_{dead_pid}_");
    let files = [
        shm(&format!("{dead}x_node.0_10_0.global_mgmt")),
        shm(&format!("{in_use}x_node.0_10_0.global_mgmt")),
        shm(&format!("{live}x_node.0_10_0.global_mgmt")),
        root.join("services").join(format!("{dead}abc.service")),
    ];
    for f in &files {
        std::fs::write(f, b"x").unwrap();
    }
    let removed = remove_stale_files(&format!("{}/", root.display()));
    let exists: Vec<bool> = files.iter().map(|f| f.exists()).collect();
    let _ = orphan.kill();
    let _ = orphan.wait();
    for f in &files {
        let _ = std::fs::remove_file(f);
    }
    let _ = std::fs::remove_dir_all(&root);
    assert_eq!(exists, [false, true, true, false], "dead removed, in-use and live kept");
    assert_eq!(removed, 2);
}

//! Helpers for the hwserver integration tests: start the real binary with a private prefix
//! and root, connect to it, and clean up after it.

use qmarc_proto::link::{IoxLink, LinkTimeouts};
use qmarc_proto::service::IpcLocation;
use std::process::{Child, Command, Stdio};
use std::sync::atomic::{AtomicU32, Ordering};
use std::time::{Duration, Instant};

static COUNTER: AtomicU32 = AtomicU32::new(0);

/// A running `qmarc-hwserver` of one test.
pub struct Server {
    /// The process.
    pub child: Child,
    /// Where its services are.
    pub location: IpcLocation,
    dir: std::path::PathBuf,
}

impl Server {
    /// Starts the server on the settings file `text` (SCHED_OTHER, no mlock, lock-step sim).
    pub fn start(test: &str, text: &str) -> Server {
        Server::start_with(test, text, true)
    }

    /// Starts the server on the settings file `text` (SCHED_OTHER, no mlock), its simulated
    /// robot in lock-step or in real time. Its watchdog is 2500 periods unless `text` sets
    /// one: the test thread is no real-time loop, and a short watchdog would fire whenever it
    /// is descheduled between two requests.
    pub fn start_with(test: &str, text: &str, lockstep: bool) -> Server {
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let pid = std::process::id();
        let dir = std::env::temp_dir().join(format!("qmarc-hw-{pid}-{n}-{test}"));
        std::fs::create_dir_all(&dir).expect("scratch dir");
        let location = IpcLocation::new(&format!("qh{pid}_{n}_"), &format!("{}/", dir.display()));
        let mut spec = qmarc_hwserver::backends::standalone_run(text, &location, lockstep)
            .expect("test settings");
        let s = &mut spec.settings;
        (s.timer.hwserver_priority, s.timer.servo_priority, s.timer.lock_memory) = (0, 0, false);
        s.sim.state_file = None;
        if !s.explicit.watchdog_periods {
            s.hwserver.watchdog_periods = 2500;
        }
        let file = dir.join("run.json");
        spec.write(&file).expect("run file");
        let child = Command::new(env!("CARGO_BIN_EXE_qmarc-hwserver"))
            .arg(format!("--settings={}", file.display()))
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn qmarc-hwserver");
        Server { child, location, dir }
    }

    /// Connects the controller's end of the link.
    pub fn connect(&self) -> IoxLink {
        let timeouts =
            LinkTimeouts { deadline_ns: 100_000_000, give_up_ns: 2_000_000_000, spin_ns: 0 };
        IoxLink::connect(&self.location, timeouts, Duration::from_secs(10), None).expect("connect")
    }

    /// Connects a link that polls for each response up to 1 s before it blocks, to a server
    /// that spins (`hwserver.wait = "spin"`): no request is notified.
    pub fn connect_polling(&self) -> IoxLink {
        let timeouts = LinkTimeouts {
            deadline_ns: 100_000_000,
            give_up_ns: 2_000_000_000,
            spin_ns: 1_000_000_000,
        };
        IoxLink::connect(&self.location, timeouts, Duration::from_secs(10), None)
            .expect("connect")
            .to_spinning_server()
    }

    /// Waits up to `timeout` for the process to end; its exit code and stderr.
    pub fn wait(&mut self, timeout: Duration) -> (Option<i32>, String) {
        let started = Instant::now();
        loop {
            if let Some(status) = self.child.try_wait().expect("wait") {
                let mut err = String::new();
                if let Some(mut e) = self.child.stderr.take() {
                    use std::io::Read;
                    let _ = e.read_to_string(&mut err);
                }
                return (status.code(), err);
            }
            assert!(started.elapsed() < timeout, "qmarc-hwserver did not exit within {timeout:?}");
            std::thread::sleep(Duration::from_millis(5));
        }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
        self.location.remove_files();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

//! Integration tests of `qmarc-hwserver`: the real binary answering over iceoryx2.

mod conformance;
mod util;

use qmarc_proto::link::HwLink;
use qmarc_proto::{HwMsg, MsgType, Status};
use std::time::Duration;
use util::Server;

#[test]
fn unknown_message_types_get_a_status_bit_and_the_server_carries_on() {
    let mut server = Server::start("unknown", "");
    let mut link = server.connect();
    for raw in [0, 14, 4242] {
        let resp = link.exchange(&HwMsg { msg_type: raw, ..HwMsg::default() }).unwrap();
        assert_eq!(resp.status(), Status::UNKNOWN_MESSAGE, "type {raw}");
        assert_eq!(resp.msg_type, raw, "echoed");
    }
    let resp = link.exchange(&HwMsg::for_motor(MsgType::EnableMotor, 7)).unwrap();
    assert_eq!(resp.status(), Status::BAD_MOTOR);
    let resp = link.exchange(&HwMsg::read_all_encoders()).unwrap();
    assert!(resp.status().is_ok());
    assert_eq!(&resp.data[..3], &[0.0, 0.0, 0.0]);
    let resp = link.exchange(&HwMsg::request(MsgType::Exit)).unwrap();
    assert!(resp.status().is_ok());
    let (code, _) = server.wait(Duration::from_secs(10));
    assert_eq!(code, Some(0));
}

/// Issue 14: a controller that polls for its responses, with a hwserver that spins for its
/// requests: no wake-up is notified or read on either side while they poll, yet every
/// request of thousands in a row is answered, in order, and the server still ends on Exit.
#[test]
fn a_polling_controller_and_a_spinning_hwserver_answer_every_request() {
    let mut server = Server::start("polled", "[hwserver]\nwait = \"spin\"\n");
    let mut link = server.connect_polling();
    for i in 0..5_000 {
        let resp = link.exchange(&HwMsg::read_all_encoders());
        assert!(resp.as_ref().is_ok_and(|r| r.status().is_ok()), "exchange {i}: {resp:?}");
    }
    assert!(link.exchange(&HwMsg::request(MsgType::Exit)).unwrap().status().is_ok());
    let (code, err) = server.wait(Duration::from_secs(10));
    assert_eq!(code, Some(0), "{err}");
}

#[test]
fn all_twelve_messages_are_served() {
    let mut server =
        Server::start("twelve", "[general]\nn_motors = 2\n[sim]\nstart_counts = [100, -40]\n");
    let mut link = server.connect();
    let mut ask = |m: HwMsg| link.exchange(&m).unwrap();
    assert_eq!(&ask(HwMsg::read_all_encoders()).data[..2], &[100.0, -40.0]);
    assert_eq!(ask(HwMsg::for_motor(MsgType::ReadEncoder, 1)).data[1], -40.0);
    assert!(ask(HwMsg::for_motor(MsgType::EnableMotor, 0)).status().is_ok());
    let mut codes = [0; 4];
    codes[0] = 2000;
    assert!(ask(HwMsg::write_all_dacs(&codes)).status().is_ok());
    let mut one = HwMsg::for_motor(MsgType::WriteDac, 0);
    one.aux[0] = 2000;
    assert!(ask(one).status().is_ok());
    for _ in 0..20 {
        ask(HwMsg::read_all_encoders());
    }
    assert!(ask(HwMsg::read_all_encoders()).data[0] > 110.0, "motor 1 moved");
    let st = ask(HwMsg::for_motor(MsgType::DisableMotor, 0)).status();
    assert!(st.is_ok(), "{st}");
    assert!(ask(HwMsg::request(MsgType::DisableAll)).status().is_ok());
    assert!(ask(HwMsg::for_motor(MsgType::ResetEncoderZero, HwMsg::ALL_MOTORS)).status().is_ok());
    assert_eq!(ask(HwMsg::for_motor(MsgType::ReadEncoder, 1)).data[1], 0.0);
    assert!(ask(HwMsg::request(MsgType::EnableSafety)).status().is_ok());
    assert!(ask(HwMsg::request(MsgType::DisableSafety)).status().is_ok());
    assert!(ask(HwMsg::request(MsgType::ClearSafetyStatus)).status().is_ok());
    assert!(ask(HwMsg::request(MsgType::Exit)).status().is_ok());
    assert_eq!(server.wait(Duration::from_secs(10)).0, Some(0));
}

#[test]
fn watchdog_disables_the_motors_when_the_controller_falls_silent() {
    // Real time: silence is measured on the wall clock.
    let mut server = Server::start_with("watchdog", "[hwserver]\nwatchdog_periods = 50\n", false);
    let mut link = server.connect();
    assert!(link.exchange(&HwMsg::for_motor(MsgType::EnableMotor, 0)).unwrap().status().is_ok());
    // Silence: the server must give up on us by itself.
    let (code, stderr) = server.wait(Duration::from_secs(10));
    assert_eq!(code, Some(2), "{stderr}");
    assert!(stderr.contains("watchdog: controller silent for"), "{stderr}");
    assert!(stderr.contains("its process still runs"), "{stderr}");
    assert!(stderr.contains("raise hwserver.watchdog_periods"), "{stderr}");
    assert!(stderr.contains("all motors disabled"), "{stderr}");
}

/// Issue 9, item 6: in lock-step time is simulated, so a silent controller whose process
/// lives (a host stall) does not trip the watchdog; it is still served afterwards.
#[test]
fn in_lock_step_a_living_silent_controller_does_not_trip_the_watchdog() {
    let mut server = Server::start("lockwd", "[hwserver]\nwatchdog_periods = 10\n");
    let mut link = server.connect();
    assert!(link.exchange(&HwMsg::for_motor(MsgType::EnableMotor, 0)).unwrap().status().is_ok());
    // 300 ms of silence: 750 periods, 75 watchdogs of wall time.
    std::thread::sleep(Duration::from_millis(300));
    let resp = link.exchange(&HwMsg::read_all_encoders()).unwrap();
    assert!(resp.status().is_ok(), "{}", resp.status());
    assert!(link.exchange(&HwMsg::request(MsgType::Exit)).unwrap().status().is_ok());
    let (code, stderr) = server.wait(Duration::from_secs(10));
    assert_eq!(code, Some(0), "{stderr}");
}

#[test]
fn sigterm_disables_the_motors_and_refuses_to_enable_them() {
    let mut server = Server::start("sigterm", "");
    let mut link = server.connect();
    assert!(link.exchange(&HwMsg::for_motor(MsgType::EnableMotor, 0)).unwrap().status().is_ok());
    let pid = nix::unistd::Pid::from_raw(server.child.id() as i32);
    nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGTERM).expect("SIGTERM our child");
    // Until the signal shows (30 s at most: a loaded machine delivers it late).
    let deadline = std::time::Instant::now() + Duration::from_secs(30);
    let mut status = Status::OK;
    while std::time::Instant::now() < deadline {
        status = link.exchange(&HwMsg::read_all_encoders()).unwrap().status();
        if !status.is_ok() {
            break;
        }
        std::thread::sleep(Duration::from_millis(5));
    }
    assert_eq!(status, Status::SHUTDOWN);
    let resp = link.exchange(&HwMsg::for_motor(MsgType::EnableMotor, 0)).unwrap();
    assert!(resp.status().contains(Status::SHUTDOWN));
    link.exchange(&HwMsg::request(MsgType::Exit)).unwrap();
    let (code, stderr) = server.wait(Duration::from_secs(10));
    assert_eq!(code, Some(0), "{stderr}");
}

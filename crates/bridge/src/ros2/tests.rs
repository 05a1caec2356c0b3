//! rmw_zenoh's formats, against its own documented examples (rmw_zenoh `docs/design.md`, the
//! Jazzy sources) and a payload rosbags' CDR codec wrote.

use super::*;
use crate::msgs::{Header, JointState, SetBoolRequest, Time, TriggerRequest};

#[test]
fn type_names_are_the_dds_ones() {
    assert_eq!(JOINT_STATE.dds_name(), "sensor_msgs::msg::dds_::JointState_");
    assert_eq!(TRIGGER.dds_name(), "std_srvs::srv::dds_::Trigger_");
    assert_eq!(POINT_STAMPED.dds_name(), "geometry_msgs::msg::dds_::PointStamped_");
}

#[test]
fn data_key_expressions_put_the_domain_first_and_keep_inner_slashes() {
    assert_eq!(
        data_keyexpr(0, "/joint_states", &JOINT_STATE),
        "0/joint_states/sensor_msgs::msg::dds_::JointState_/\
         RIHS01_a13ee3a330e346c9d87b5aa18d24e11690752bd33a0350f11c5882bc9179260e"
    );
    let ns = qualified("/robot1", "qmarc/stop");
    assert_eq!(ns, "/robot1/qmarc/stop");
    assert_eq!(
        data_keyexpr(7, &ns, &TRIGGER),
        "7/robot1/qmarc/stop/std_srvs::srv::dds_::Trigger_/\
         RIHS01_eeff2cd6fa5ad9d27cdf4dec64818317839b62f212a91e6b5304b634b2062c5f"
    );
    assert_eq!(qualified("", "joint_states"), "/joint_states");
    assert_eq!(qualified("/", "joint_states"), "/joint_states");
    assert_eq!(qualified("/robot1", "/diagnostics"), "/diagnostics", "absolute stays");
}

#[test]
fn qos_strings_leave_rmw_zenohs_defaults_empty() {
    assert_eq!(Qos::DEFAULT.keyexpr(), "::,10:,:,:,,");
    assert_eq!(Qos::SENSOR_DATA.keyexpr(), "2::,5:,:,:,,");
    let latched = Qos { reliable: true, transient_local: true, depth: 1 };
    assert_eq!(latched.keyexpr(), ":1:,1:,:,:,,");
    assert_eq!(Qos { depth: 42, ..Qos::DEFAULT }.keyexpr(), "::,:,:,:,,");
}

/// rmw_zenoh's design.md, domain 2: a listener node and its subscription to /chatter.
#[test]
fn liveliness_tokens_are_rmw_zenohs() {
    let node = NodeInfo {
        domain: 2,
        zid: "aac3178e146ba6f1fc6e6a4085e77f21".into(),
        id: 0,
        namespace: "/".into(),
        name: "listener".into(),
    };
    assert_eq!(
        node.node_token(),
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
    );
    // Issue 42, item 3: what a second node of this name looks for matches the first's token,
    // from any session, and no other node's.
    let alive = zenoh::key_expr::KeyExpr::try_from(node.same_node_tokens()).unwrap();
    let token = |t: String| zenoh::key_expr::KeyExpr::try_from(t).unwrap();
    let other_session = NodeInfo { zid: "1234".into(), id: 3, ..node.clone() };
    assert!(alive.intersects(&token(other_session.node_token())));
    for other in [
        NodeInfo { name: "talker".into(), ..node.clone() },
        NodeInfo { namespace: "/robot2".into(), ..node.clone() },
        NodeInfo { domain: 3, ..node.clone() },
    ] {
        assert!(!alive.intersects(&token(other.node_token())), "{other:?}");
    }
    let string_sub = node.entity_token(
        10,
        EntityKind::Subscription,
        "/chatter",
        &RosType {
            name: "std_msgs/msg/String",
            hash: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
        },
        &Qos::DEFAULT,
    );
    assert!(!alive.intersects(&token(string_sub)), "an entity's token is not the node's");
    let string = RosType {
        name: "std_msgs/msg/String",
        hash: "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18",
    };
    assert_eq!(
        node.entity_token(10, EntityKind::Subscription, "/chatter", &string, &Qos::DEFAULT),
        "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/\
         std_msgs::msg::dds_::String_/\
         RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,10:,:,:,,"
    );
    let robot1 = NodeInfo { namespace: "/robot1".into(), name: "qmarc".into(), ..node };
    assert_eq!(
        robot1.entity_token(
            3,
            EntityKind::Publisher,
            "/robot1/joint_states",
            &JOINT_STATE,
            &Qos::SENSOR_DATA
        ),
        format!(
            "@ros2_lv/2/aac3178e146ba6f1fc6e6a4085e77f21/0/3/MP/%/%robot1/qmarc/%robot1%joint_states/\
             sensor_msgs::msg::dds_::JointState_/{}/2::,5:,:,:,,",
            JOINT_STATE.hash
        )
    );
}

/// eclipse-zenoh's `z_serialize((Int64(1), Int64(1700000000123456789), bytes(range(16))))`.
#[test]
fn the_attachment_is_33_bytes_as_zenoh_cpp_writes_it() {
    let gid: [u8; 16] = std::array::from_fn(|i| i as u8);
    let a = attachment(1, 1_700_000_000_123_456_789, &gid);
    let bytes = a.to_bytes();
    let hex: String = bytes.iter().map(|b| format!("{b:02x}")).collect();
    assert_eq!(
        hex,
        "0100000000000000\
         15cd853dfe9c9717\
         10\
         000102030405060708090a0b0c0d0e0f"
    );
    assert_eq!(read_attachment(&a), Some((1, 1_700_000_000_123_456_789, gid)));
    assert_eq!(read_attachment(&zenoh::bytes::ZBytes::from(vec![1u8, 2, 3])), None);
    assert_ne!(gid_of("a"), gid_of("b"));
    assert_eq!(gid_of("a"), gid_of("a"));
}

/// rosbags' `serialize_cdr` of a JointState: stamp (1 s, 2 ns), frame `base`, one joint `j1`
/// at 0.5 rad.
#[test]
fn cdr_payloads_are_byte_for_byte_rosbags_ones() {
    let js = JointState {
        header: Header { stamp: Time { sec: 1, nanosec: 2 }, frame_id: "base".into() },
        name: vec!["j1".into()],
        position: vec![0.5],
        velocity: vec![],
        effort: vec![],
    };
    let hex = |b: &[u8]| b.iter().map(|b| format!("{b:02x}")).collect::<String>();
    let expected =
        "00010000 01000000 02000000 05000000 62617365 00 000000 01000000 03000000 6a3100 00 \
                    01000000 00000000 000000000000e03f 00000000 00000000"
            .replace(' ', "");
    let bytes = to_cdr(&js).unwrap();
    assert_eq!(hex(&bytes), expected);
    assert_eq!(from_cdr::<JointState>(&bytes, "JointState"), Ok(js));
    // An empty request is one byte; a bool one byte.
    assert_eq!(hex(&to_cdr(&TriggerRequest::default()).unwrap()), "0001000000");
    assert_eq!(
        from_cdr::<SetBoolRequest>(&[0, 1, 0, 0, 1], "SetBool"),
        Ok(SetBoolRequest { data: true })
    );
    // Big-endian is read too.
    assert_eq!(
        from_cdr::<SetBoolRequest>(&[0, 0, 0, 0, 1], "SetBool"),
        Ok(SetBoolRequest { data: true })
    );
}

#[test]
fn malformed_and_oversized_payloads_are_refused() {
    let big = vec![0u8; MAX_PAYLOAD_BYTES + 1];
    assert_eq!(from_cdr::<SetBoolRequest>(&big, "SetBool"), Err(PayloadError::TooBig(big.len())));
    assert_eq!(from_cdr::<SetBoolRequest>(&[0, 1], "SetBool"), Err(PayloadError::NoHeader));
    assert_eq!(
        from_cdr::<SetBoolRequest>(&[9, 9, 0, 0, 1], "SetBool"),
        Err(PayloadError::NoHeader)
    );
    assert!(matches!(
        from_cdr::<SetBoolRequest>(&[0, 1, 0, 0], "SetBool"),
        Err(PayloadError::Malformed("SetBool", _))
    ));
    // A sequence that says it holds 2³² − 1 strings, with nothing after it.
    let lying = [0, 1, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 0, 0, 0, 0, 0xff, 0xff, 0xff, 0xff];
    assert!(matches!(
        from_cdr::<JointState>(&lying, "JointState"),
        Err(PayloadError::Malformed(..))
    ));
}

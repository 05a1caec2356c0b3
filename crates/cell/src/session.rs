//! The cell's Zenoh session: the bridge's (rmw_zenoh's defaults, or the file of
//! `--zenoh-config`, opened and linked as the bridge's is), and the few calls the cell makes
//! on it.

pub use qmarc_bridge::node::failed;
use qmarc_bridge::node::{ZenohError, open_linked, session_config};
use std::path::Path;
use std::time::Duration;
use zenoh::Wait;

/// Opens the session `file` describes (`None`: rmw_zenoh's default), linked to a router or
/// a peer as the bridge's is ([`open_linked`]).
pub fn open(file: Option<&Path>) -> Result<zenoh::Session, ZenohError> {
    open_linked(session_config(file)?)
}

/// The keys of the live tokens matching `key`, asked for `timeout`.
pub fn alive(
    session: &zenoh::Session,
    key: &str,
    timeout: Duration,
) -> Result<Vec<String>, ZenohError> {
    let replies = session
        .liveliness()
        .get(key)
        .timeout(timeout)
        .wait()
        .map_err(failed(format!("asking for {key}")))?;
    Ok(replies.iter().filter_map(|r| r.result().ok().map(|s| s.key_expr().to_string())).collect())
}

/// The JSON replies to a query of `key`, asked for `timeout` (those that do not parse are
/// skipped).
pub fn query<T: serde::de::DeserializeOwned>(
    session: &zenoh::Session,
    key: &str,
    timeout: Duration,
) -> Result<Vec<T>, ZenohError> {
    let replies =
        session.get(key).timeout(timeout).wait().map_err(failed(format!("asking {key}")))?;
    Ok(replies
        .iter()
        .filter_map(|r| {
            r.result().ok().and_then(|s| serde_json::from_slice(&s.payload().to_bytes()).ok())
        })
        .collect())
}

/// `value` as JSON bytes.
pub fn json<T: serde::Serialize>(value: &T) -> Vec<u8> {
    // Plain data of strings and numbers: serializing it cannot fail.
    serde_json::to_vec(value).unwrap_or_default()
}

/// A Zenoh router listening on `endpoints`, until a stop signal: no multicast scouting (the
/// hosts it links are those that connect to it); gossip on, so that the peers that connect
/// to it (rmw_zenoh's default session) learn of each other and link directly, as with
/// zenohd. Clients (`mode: "client"`) go through it for everything.
pub fn route(endpoints: &[String]) -> anyhow::Result<()> {
    qmarc_timer::stop::install()?;
    let mut c = zenoh::Config::default();
    let set = |c: &mut zenoh::Config, k: &str, v: &str| {
        c.insert_json5(k, v).map_err(|e| anyhow::anyhow!("zenoh: setting {k}: {e}"))
    };
    set(&mut c, "mode", r#""router""#)?;
    set(&mut c, "listen/endpoints", &serde_json::to_string(endpoints)?)?;
    set(&mut c, "scouting/multicast/enabled", "false")?;
    let session = zenoh::open(c).wait().map_err(failed("opening the router"))?;
    eprintln!("qmarc-cell router: listening on {}", endpoints.join(", "));
    while !qmarc_timer::stop::requested() {
        std::thread::sleep(Duration::from_millis(20));
    }
    drop(session);
    Ok(())
}

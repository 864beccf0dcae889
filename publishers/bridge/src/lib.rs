//! Field mirrors over Zenoh (feature `zenoh`; docs/mirror-wire.md): `Bridge` publishes a
//! field's inputs, configuration, checksums and keyframes from its host; `Mirror` runs the same
//! `Stepper` on another host (or iceoryx2 domain) and publishes bit-identical frames there.
//! `codec` holds the bytes both exchange; `run` their loops (`pheromone bridge`, `pheromone
//! field --mirror`).

#[allow(clippy::module_inception)]
mod batches;
mod bridge;
pub mod codec;
mod journal;
mod mirror;
pub mod owner;
pub mod run;
mod security;

use std::time::Duration;

pub use batches::RESEND_AFTER;
pub use bridge::{Bridge, BridgeOptions, BridgeStats, FramesOptions};
pub use journal::path_for as journal_path;
pub use mirror::{Mirror, MirrorOptions, MirrorStats};
pub use security::{refusal, try_connect, Security};
/// The Zenoh crate this build uses (tests and benches speak to bridges with it).
pub use zenoh;

/// A failed bridge or mirror operation.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    #[error(transparent)]
    Shm(#[from] pheromone_field::shm::ShmError),
    #[error("zenoh: {action}: {detail}")]
    Zenoh { action: String, detail: String },
    #[error("the bridge's record of handed-over batches {path}: {detail}")]
    Journal { path: String, detail: String },
    #[error("the configuration the origin sent is invalid: {0}")]
    Config(String),
    #[error("{0}")]
    Timeout(String),
    /// A security file that cannot be used (an unreadable password file, a Zenoh
    /// configuration file that does not parse).
    #[error("{0}")]
    Security(String),
    /// The bridge refused a mirror's connection for good (a certificate, CA or password it
    /// does not accept).
    #[error("mirror '{field}': {endpoint} refused the connection: {why}")]
    Refused {
        field: String,
        endpoint: String,
        why: String,
    },
}

pheromone_field::from_shm_errors!(BridgeError);

pub(crate) fn zerr(action: &str, e: impl std::fmt::Display) -> BridgeError {
    BridgeError::Zenoh {
        action: action.to_string(),
        detail: e.to_string(),
    }
}

/// The Zenoh key expressions of field `F`.
#[derive(Debug, Clone)]
pub struct Keys {
    pub inputs: String,
    pub config: String,
    pub checksum: String,
    pub keyframe: String,
    pub deposit: String,
    pub deposit_ack: String,
    pub frames: String,
}

impl Keys {
    pub fn of(field: &str) -> Self {
        let k = |s: &str| format!("pheromone/{field}/{s}");
        Self {
            inputs: k("inputs"),
            config: k("config"),
            checksum: k("checksum"),
            keyframe: k("keyframe"),
            deposit: k("deposit"),
            deposit_ack: k("deposit_ack"),
            frames: k("frames"),
        }
    }
}

/// A peer session without multicast scouting or gossip: it listens on `listen` and connects to
/// `connect`, retrying a lost or refused connection every 100–500 ms.
pub fn session_config(listen: &[String], connect: &[String]) -> Result<zenoh::Config, BridgeError> {
    session_config_as("peer", listen, connect)
}

/// As [`session_config`], in zenoh mode `mode` (`peer`, or `client`: a dashboard or a test
/// whose messages the bridge's peer routes on to its mirrors).
pub fn session_config_as(
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, BridgeError> {
    session_config_with(&Security::default(), mode, listen, connect)
}

/// As [`session_config_as`] without the owner key, even on loopback: for a session that stands
/// for another ecosystem's node (a ROS 2 subscriber that `pheromone ros2` connects to with
/// rmw_zenoh's settings, which present no key), never for one that carries a field's deposits.
pub fn plain_session_config(
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, BridgeError> {
    session_config_base(&Security::default(), mode, listen, connect)
}

/// As [`session_config_as`], over the base configuration of `security` (TLS, credentials,
/// access control): its mode, scouting, endpoints and connection retry are the ones set here.
/// On loopback endpoints only, without credentials of its own, the session uses this user's
/// owner key ([`owner`]): other local users' sessions cannot open one with it.
pub fn session_config_with(
    security: &Security,
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, BridgeError> {
    let mut c = session_config_base(security, mode, listen, connect)?;
    owner::apply(&mut c, listen, connect)?;
    Ok(c)
}

/// The session's configuration without the owner key.
fn session_config_base(
    security: &Security,
    mode: &str,
    listen: &[String],
    connect: &[String],
) -> Result<zenoh::Config, BridgeError> {
    let mut c = security.base_config()?;
    let mut set = |k: &str, v: String| {
        c.insert_json5(k, &v)
            .map_err(|e| zerr(&format!("config {k} = {v}"), e))
    };
    set("mode", format!("\"{mode}\""))?;
    set("scouting/multicast/enabled", "false".into())?;
    set("scouting/gossip/enabled", "false".into())?;
    set(
        "listen/endpoints",
        serde_json::to_string(listen).expect("strings"),
    )?;
    set(
        "connect/endpoints",
        serde_json::to_string(connect).expect("strings"),
    )?;
    set(
        "connect/retry",
        "{period_init_ms: 100, period_max_ms: 500, period_increase_factor: 2}".into(),
    )?;
    Ok(c)
}

/// Turns on the session's admin space, read-only (`@/<zid>/<mode>/…`): what
/// [`listen_locators`] reads to learn the ports a session listens on (`tcp/127.0.0.1:0`).
pub fn with_admin_space(mut c: zenoh::Config) -> Result<zenoh::Config, BridgeError> {
    for (k, v) in [
        ("adminspace/enabled", "true"),
        ("adminspace/permissions/read", "true"),
        ("adminspace/permissions/write", "false"),
    ] {
        c.insert_json5(k, v)
            .map_err(|e| zerr(&format!("config {k} = {v}"), e))?;
    }
    Ok(c)
}

/// The endpoints a peer session opened with [`with_admin_space`] listens on, with the ports the
/// system chose (e.g. `tcp/127.0.0.1:41234`), from its own admin space.
pub fn listen_locators(session: &zenoh::Session) -> Result<Vec<String>, BridgeError> {
    use zenoh::Wait;
    let zid = session.info().zid().wait();
    let key = format!("@/{zid}/peer");
    let replies = session
        .get(key.clone())
        .timeout(REQUEST_TIMEOUT)
        .wait()
        .map_err(|e| zerr(&format!("get {key}"), e))?;
    while let Ok(reply) = replies.recv() {
        let Ok(sample) = reply.result() else {
            continue;
        };
        let bytes = sample.payload().to_bytes();
        let v: serde_json::Value =
            serde_json::from_slice(&bytes).map_err(|e| zerr(&format!("parse {key}"), e))?;
        if let Some(l) = v["locators"].as_array() {
            return Ok(l
                .iter()
                .filter_map(|l| l.as_str().map(str::to_string))
                .collect());
        }
    }
    Err(BridgeError::Timeout(format!(
        "the session's admin space ({key}) did not list its locators"
    )))
}

/// How long a mirror's keyframe or configuration request stays open (its replies are polled,
/// never waited for).
pub const REQUEST_TIMEOUT: Duration = Duration::from_secs(2);

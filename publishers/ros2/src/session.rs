//! The Zenoh session of a ROS 2 node of ours, opened as rmw_zenoh_cpp opens a node's session
//! (`rmw_zenoh_cpp/src/detail/zenoh_config.cpp`): the configuration file named by
//! `ZENOH_SESSION_CONFIG_URI` if set, else rmw_zenoh's default session settings
//! (`config/rmw_zenoh_session.json5`, taken from its `DEFAULT_RMW_ZENOH_SESSION_CONFIG.json5`:
//! a peer that connects to the router at `tcp/localhost:7447`, listens on an ephemeral
//! localhost port, multicast scouting off, gossip scouting on). `--zenoh-config FILE` names
//! the file on the command line and wins over the variable. The command's flags are written
//! over the file and change only what they name: `--connect`/`--listen` the endpoints, the TLS
//! and credential flags their keys, `--print-address` the admin space it reads.

use std::path::{Path, PathBuf};

use thiserror::Error;

use crate::deps::{with_admin_space, Security};

/// The environment variable rmw_zenoh_cpp reads for a node's session configuration file.
pub const SESSION_CONFIG_ENV: &str = "ZENOH_SESSION_CONFIG_URI";

/// rmw_zenoh's default session settings (see the file's header for the upstream file).
pub const RMW_ZENOH_SESSION_CONFIG: &str = include_str!("../config/rmw_zenoh_session.json5");

/// How a ROS 2 session is configured.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SessionSettings {
    /// `--zenoh-config` (in `config_file`), TLS and credentials.
    pub security: Security,
    /// The value of [`SESSION_CONFIG_ENV`], if set and not empty.
    pub env_file: Option<PathBuf>,
    /// `--listen` endpoints; empty: the file's.
    pub listen: Vec<String>,
    /// `--connect` endpoints; empty: the file's.
    pub connect: Vec<String>,
    /// Turn on the admin space read-only (`--print-address` reads the listening ports there).
    pub admin_space: bool,
}

/// A session configuration that cannot be built; the message names the file or key.
#[derive(Debug, Error)]
pub enum SessionConfigError {
    #[error("{origin}{}: {detail}", path.display())]
    File {
        /// `--zenoh-config ` or `ZENOH_SESSION_CONFIG_URI=`.
        origin: &'static str,
        path: PathBuf,
        detail: String,
    },
    #[error("zenoh session config: {key} = {value}: {detail}")]
    Key {
        key: String,
        value: String,
        detail: String,
    },
    #[error("{0}")]
    Security(String),
}

impl SessionSettings {
    /// Reads [`SESSION_CONFIG_ENV`] from the environment into `env_file` (an empty value is
    /// unset, as for rmw_zenoh).
    pub fn with_env(mut self) -> Self {
        self.env_file = std::env::var_os(SESSION_CONFIG_ENV)
            .filter(|v| !v.is_empty())
            .map(PathBuf::from);
        self
    }

    /// Where the base configuration comes from, for messages: the file, or rmw_zenoh's
    /// defaults.
    pub fn origin(&self) -> String {
        match (&self.security.config_file, &self.env_file) {
            (Some(f), _) => format!("--zenoh-config {}", f.display()),
            (None, Some(f)) => format!("{SESSION_CONFIG_ENV}={}", f.display()),
            (None, None) => "rmw_zenoh's default session settings".into(),
        }
    }

    /// The session's configuration (see the module documentation).
    pub fn config(&self) -> Result<zenoh::Config, SessionConfigError> {
        let base = match (&self.security.config_file, &self.env_file) {
            (Some(f), _) => from_file("--zenoh-config ", f)?,
            (None, Some(f)) => from_file("ZENOH_SESSION_CONFIG_URI=", f)?,
            (None, None) => rmw_zenoh_default(),
        };
        let security = Security {
            config_file: None,
            ..self.security.clone()
        };
        let mut c = security
            .over(base)
            .map_err(|e| SessionConfigError::Security(e.to_string()))?;
        for (key, endpoints) in [
            ("listen/endpoints", &self.listen),
            ("connect/endpoints", &self.connect),
        ] {
            if !endpoints.is_empty() {
                let value = serde_json::to_string(endpoints).expect("strings");
                c.insert_json5(key, &value)
                    .map_err(|e| SessionConfigError::Key {
                        key: key.into(),
                        value,
                        detail: e.to_string(),
                    })?;
            }
        }
        if self.admin_space {
            c = with_admin_space(c).map_err(|e| SessionConfigError::Security(e.to_string()))?;
        }
        Ok(c)
    }
}

fn from_file(origin: &'static str, path: &Path) -> Result<zenoh::Config, SessionConfigError> {
    zenoh::Config::from_file(path).map_err(|e| SessionConfigError::File {
        origin,
        path: path.to_path_buf(),
        detail: e.to_string(),
    })
}

/// rmw_zenoh's default session settings as a Zenoh configuration.
pub fn rmw_zenoh_default() -> zenoh::Config {
    zenoh::Config::from_json5(RMW_ZENOH_SESSION_CONFIG)
        .expect("config/rmw_zenoh_session.json5 is a valid Zenoh configuration (tested)")
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get(c: &zenoh::Config, key: &str) -> serde_json::Value {
        serde_json::from_str(&c.get_json(key).unwrap()).unwrap()
    }

    #[test]
    fn by_default_a_session_is_an_rmw_zenoh_peer() {
        let c = SessionSettings::default().config().unwrap();
        assert_eq!(get(&c, "mode"), "peer");
        assert_eq!(
            get(&c, "connect/endpoints"),
            serde_json::json!(["tcp/localhost:7447"])
        );
        assert_eq!(
            get(&c, "listen/endpoints"),
            serde_json::json!(["tcp/localhost:0"])
        );
        assert_eq!(get(&c, "scouting/multicast/enabled"), false);
        assert_eq!(get(&c, "scouting/gossip/enabled"), true);
        assert_eq!(
            get(&c, "scouting/gossip/target"),
            serde_json::json!({"router": ["router", "peer"], "peer": ["router"]})
        );
        assert_eq!(get(&c, "transport/shared_memory/enabled"), false);
        assert_eq!(
            get(&c, "timestamping/enabled"),
            serde_json::json!({"router": true, "peer": true, "client": true})
        );
    }

    #[test]
    fn flags_override_only_what_they_name_and_a_file_sets_anything() {
        let dir = std::env::temp_dir().join(format!("ros2-session-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("session.json5");
        std::fs::write(
            &file,
            r#"{ mode: "peer", scouting: { gossip: { enabled: false }, multicast: { enabled: false } },
                 connect: { endpoints: ["tcp/127.0.0.1:9"] }, listen: { endpoints: [] } }"#,
        )
        .unwrap();
        let s = SessionSettings {
            security: Security {
                config_file: Some(file.clone()),
                ..Security::default()
            },
            env_file: Some(dir.join("ignored: --zenoh-config wins")),
            listen: vec!["tcp/127.0.0.1:0".into()],
            ..SessionSettings::default()
        };
        let c = s.config().unwrap();
        assert_eq!(get(&c, "scouting/gossip/enabled"), false);
        assert_eq!(
            get(&c, "connect/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:9"])
        );
        assert_eq!(
            get(&c, "listen/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:0"])
        );
        let env = SessionSettings {
            env_file: Some(file.clone()),
            connect: vec!["tcp/127.0.0.1:7448".into()],
            ..SessionSettings::default()
        };
        let c = env.config().unwrap();
        assert_eq!(get(&c, "scouting/gossip/enabled"), false);
        assert_eq!(
            get(&c, "connect/endpoints"),
            serde_json::json!(["tcp/127.0.0.1:7448"])
        );
        std::fs::write(&file, "{ mode: \"peer\", ").unwrap();
        let e = env.config().unwrap_err().to_string();
        assert!(
            e.starts_with(&format!("ZENOH_SESSION_CONFIG_URI={}: ", file.display())),
            "{e}"
        );
        let missing = SessionSettings {
            security: Security {
                config_file: Some(dir.join("missing.json5")),
                ..Security::default()
            },
            ..SessionSettings::default()
        };
        let e = missing.config().unwrap_err().to_string();
        assert!(e.starts_with("--zenoh-config "), "{e}");
        assert!(e.contains("missing.json5"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! The Zenoh security flags of `bridge`, `field --mirror` and `ros2` (docs/mirrors.md,
//! "Security"): every file is checked while the command line is parsed.

use std::path::PathBuf;

use clap::Args;

/// TLS, credentials and access control of a Zenoh session.
#[derive(Args, Debug, Clone, Default)]
pub struct ZenohArgs {
    /// Zenoh's own JSON5 configuration file (as rmw_zenoh uses): TLS (transport.link.tls),
    /// credentials (transport.auth.usrpwd), access control (access_control) and any other
    /// Zenoh setting. For `ros2` (and `sim --ros2`'s child) the file is the whole session
    /// configuration, as rmw_zenoh's ZENOH_SESSION_CONFIG_URI (which it wins over): mode and
    /// scouting included, only the flags given override what they name. For `bridge` and
    /// `field --mirror` the mode, scouting, endpoints and connection retry are the command's.
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file())]
    pub zenoh_config: Option<PathBuf>,
    /// PEM certificate of the CA that signed the other side's certificate (tls/ endpoints).
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file())]
    pub tls_root_ca: Option<PathBuf>,
    /// PEM certificate this side presents (a listener's on tls/ endpoints; a connector's with
    /// mutual TLS, enable_mtls in --zenoh-config).
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file(), requires = "tls_key")]
    pub tls_cert: Option<PathBuf>,
    /// PEM private key of --tls-cert.
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file(), requires = "tls_cert")]
    pub tls_key: Option<PathBuf>,
    /// User name this side presents when it connects (with --password-file).
    #[arg(long, value_name = "NAME", requires = "password_file")]
    pub user: Option<String>,
    /// File whose first line is --user's password.
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file(), requires = "user")]
    pub password_file: Option<PathBuf>,
    /// `user:password` lines: a listening side refuses peers that present none of them.
    #[arg(long, value_name = "FILE", value_parser = super::check::in_file())]
    pub users_file: Option<PathBuf>,
}

impl ZenohArgs {
    /// Whether any of the flags is given.
    pub fn any(&self) -> bool {
        self.zenoh_config.is_some()
            || self.tls_root_ca.is_some()
            || self.tls_cert.is_some()
            || self.tls_key.is_some()
            || self.user.is_some()
            || self.password_file.is_some()
            || self.users_file.is_some()
    }

    /// The flags as a command line, for a child that takes them too (`sim --ros2` passes them
    /// to its `ros2` child); paths made absolute.
    pub fn to_args(&self) -> Vec<String> {
        let files = [
            ("--zenoh-config", &self.zenoh_config),
            ("--tls-root-ca", &self.tls_root_ca),
            ("--tls-cert", &self.tls_cert),
            ("--tls-key", &self.tls_key),
            ("--password-file", &self.password_file),
            ("--users-file", &self.users_file),
        ];
        let mut v = Vec::new();
        for (flag, path) in files {
            if let Some(p) = path {
                let p = std::path::absolute(p).unwrap_or_else(|_| p.clone());
                v.extend([flag.to_string(), p.to_string_lossy().into_owned()]);
            }
        }
        if let Some(u) = &self.user {
            v.extend(["--user".to_string(), u.clone()]);
        }
        v
    }

    /// The bridge library's settings (the files are read when the session opens).
    #[cfg(feature = "zenoh")]
    pub fn security(&self) -> pheromone_bridge::Security {
        pheromone_bridge::Security {
            config_file: self.zenoh_config.clone(),
            tls_root_ca: self.tls_root_ca.clone(),
            tls_cert: self.tls_cert.clone(),
            tls_key: self.tls_key.clone(),
            user: self.user.clone(),
            password_file: self.password_file.clone(),
            users_file: self.users_file.clone(),
        }
    }
}

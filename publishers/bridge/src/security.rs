//! TLS, credentials and access control for the Zenoh sessions of bridges, mirrors and the ROS 2
//! node (docs/mirrors.md, "Security"): Zenoh's own JSON5 configuration file as a base, plus
//! the few keys most deployments need as plain options.

use std::path::PathBuf;

use zenoh::Wait;

use super::{zerr, BridgeError};

/// Where a session's security settings come from. Paths only: secrets are read when the
/// session's configuration is built, never kept here (nor printed by `Debug`).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Security {
    /// Zenoh's JSON5 configuration file (`transport.link.tls`, `transport.auth.usrpwd`,
    /// `access_control`, …): the base the session's own keys (mode, scouting, endpoints,
    /// connection retry) are written over.
    pub config_file: Option<PathBuf>,
    /// PEM certificate(s) of the CA the other side's certificate must be signed by
    /// (`transport/link/tls/root_ca_certificate`).
    pub tls_root_ca: Option<PathBuf>,
    /// PEM certificate this side presents: to connecting peers when it listens on `tls/…`, and
    /// to the listener with mutual TLS (`listen_certificate`, `connect_certificate`).
    pub tls_cert: Option<PathBuf>,
    /// The PEM private key of `tls_cert` (`listen_private_key`, `connect_private_key`).
    pub tls_key: Option<PathBuf>,
    /// The user name this side presents when it connects (`transport/auth/usrpwd/user`).
    pub user: Option<String>,
    /// A file holding that user's password (its first line).
    pub password_file: Option<PathBuf>,
    /// The `user:password` lines a listening side accepts (`usrpwd/dictionary_file`): a peer
    /// that presents none of them is refused.
    pub users_file: Option<PathBuf>,
}

fn set(c: &mut zenoh::Config, key: &str, value: &str) -> Result<(), BridgeError> {
    c.insert_json5(key, value)
        .map_err(|e| zerr(&format!("config {key}"), e))
}

fn path_json(p: &std::path::Path) -> String {
    serde_json::to_string(&p.to_string_lossy()).expect("a string")
}

impl Security {
    /// Whether any setting is given (else a session uses Zenoh's defaults: plain TCP, no
    /// authentication).
    pub fn is_set(&self) -> bool {
        *self != Self::default()
    }

    /// The base Zenoh configuration: the file (if any, else Zenoh's defaults), then the TLS and
    /// credential options ([`Self::over`]).
    pub fn base_config(&self) -> Result<zenoh::Config, BridgeError> {
        let c = match &self.config_file {
            Some(f) => zenoh::Config::from_file(f).map_err(|e| {
                BridgeError::Security(format!("--zenoh-config {}: {e}", f.display()))
            })?,
            None => zenoh::Config::default(),
        };
        self.over(c)
    }

    /// `c` with the TLS and credential options written over it (`config_file` is not read:
    /// the caller chose the base, e.g. the ROS 2 node's rmw_zenoh defaults).
    pub fn over(&self, mut c: zenoh::Config) -> Result<zenoh::Config, BridgeError> {
        if let Some(ca) = &self.tls_root_ca {
            set(
                &mut c,
                "transport/link/tls/root_ca_certificate",
                &path_json(ca),
            )?;
        }
        if let Some(cert) = &self.tls_cert {
            for k in ["listen_certificate", "connect_certificate"] {
                set(&mut c, &format!("transport/link/tls/{k}"), &path_json(cert))?;
            }
        }
        if let Some(key) = &self.tls_key {
            for k in ["listen_private_key", "connect_private_key"] {
                set(&mut c, &format!("transport/link/tls/{k}"), &path_json(key))?;
            }
        }
        if let Some(user) = &self.user {
            let json = serde_json::to_string(user).expect("a string");
            set(&mut c, "transport/auth/usrpwd/user", &json)?;
        }
        if let Some(f) = &self.password_file {
            let text = std::fs::read_to_string(f).map_err(|e| {
                BridgeError::Security(format!("--password-file {}: {e}", f.display()))
            })?;
            let password = text.lines().next().unwrap_or_default();
            if password.is_empty() {
                return Err(BridgeError::Security(format!(
                    "--password-file {}: the first line (the password) is empty",
                    f.display()
                )));
            }
            let json = serde_json::to_string(password).expect("a string");
            set(&mut c, "transport/auth/usrpwd/password", &json)?;
        }
        if let Some(f) = &self.users_file {
            set(
                &mut c,
                "transport/auth/usrpwd/dictionary_file",
                &path_json(f),
            )?;
        }
        Ok(c)
    }
}

/// Why a connection to a bridge was refused for good (a wrong certificate, CA or password:
/// retrying cannot help), or `None` for a failure that may pass (nothing listening yet, no
/// route, a timeout).
pub fn refusal(zenoh_error: &str) -> Option<String> {
    let e = zenoh_error.to_ascii_lowercase();
    let tls = [
        ("unknownissuer", "the bridge's certificate is not signed by the CA given (--tls-root-ca, or root_ca_certificate in --zenoh-config)"),
        ("notvalidforname", "the bridge's certificate is not valid for the address connected to (its subjectAltName must name that IP or host)"),
        ("expired", "the bridge's certificate has expired"),
        ("certificate", "TLS: the certificates do not match"),
        ("handshake", "the TLS handshake failed"),
    ];
    if let Some((_, why)) = tls.iter().find(|(k, _)| e.contains(k)) {
        return Some(format!("{why} ({zenoh_error})"));
    }
    if e.contains("recv openack. expected extension") {
        return Some(format!(
            "the bridge asks for no credentials but this side presents some (--user): a bridge \
             without --users-file, or another Zenoh peer ({zenoh_error})"
        ));
    }
    let auth = e.contains("usrpwd")
        || e.contains("close message")
        || e.contains("invalid user")
        || e.contains("invalid password");
    auth.then(|| {
        format!(
            "the bridge refused this side's credentials (a wrong --user or --password-file, \
             credentials missing where the bridge requires them, or a loopback bridge of another \
             user: it admits only sessions with its user's owner key) ({zenoh_error})"
        )
    })
}

/// One attempt to open a Zenoh link to `endpoint` with `security`, without retrying: `Ok` when
/// it opened (it is closed again), else Zenoh's error text. It blocks as long as the attempt
/// takes (a TCP connect to an unreachable host: the kernel's SYN retries, ~2 min; a TLS
/// handshake: at most 10 s): call it from a thread of its own.
pub fn try_connect(security: &Security, endpoint: &str) -> Result<(), String> {
    let mut c = security.base_config().map_err(|e| e.to_string())?;
    let json = serde_json::to_string(&[endpoint]).expect("strings");
    for (k, v) in [
        ("mode", "\"peer\""),
        ("scouting/multicast/enabled", "false"),
        ("scouting/gossip/enabled", "false"),
        ("listen/endpoints", "[]"),
        ("connect/endpoints", json.as_str()),
        ("connect/timeout_ms", "0"),
        ("connect/exit_on_failure", "true"),
    ] {
        c.insert_json5(k, v).map_err(|e| e.to_string())?;
    }
    super::owner::apply(&mut c, &[], &[endpoint.to_string()]).map_err(|e| e.to_string())?;
    let session = zenoh::open(c).wait().map_err(|e| e.to_string())?;
    let _ = session.close().wait();
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::refusal;

    #[test]
    fn refusals_for_good_are_told_apart_from_failures_that_may_pass() {
        // Zenoh 1.10's texts, as the tests in tests/mirror/secure.rs saw them.
        let ca = "Can not create a new TLS link bound to IpAddress(..): invalid peer certificate: UnknownIssuer at …";
        assert!(refusal(ca).unwrap().contains("not signed by the CA given"));
        let pw = "Received a close message (reason GENERIC) in response to an OpenSyn on: …";
        assert!(refusal(pw)
            .unwrap()
            .contains("refused this side's credentials"));
        let none = "Received a close message (reason 0) in response to an InitSyn on: …";
        assert!(refusal(none)
            .unwrap()
            .contains("refused this side's credentials"));
        let extra = "UsrPwd extension - Recv OpenAck. Expected extension.";
        assert!(refusal(extra).unwrap().contains("asks for no credentials"));
        let name = "invalid peer certificate: NotValidForName";
        assert!(refusal(name).unwrap().contains("not valid for the address"));
        for passing in [
            "Can not create a new TCP link bound to 127.0.0.1:9: Connection refused (os error 111)",
            "Unable to connect to any of [tcp/10.0.0.1:7447]! ",
            "No route to host (os error 113)",
        ] {
            assert_eq!(refusal(passing), None, "{passing}");
        }
    }
}

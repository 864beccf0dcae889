//! Loopback is a user boundary (docs/mirrors.md, "Security"): a Zenoh session of ours whose
//! endpoints are all loopback and that has no credentials of its own proves it runs as the same
//! user as the other side, with a key only that user can read.
//!
//! The key is one `user:password` line in `$TMPDIR/pheromone-<uid>/zenoh/owner.key` (mode 0600
//! in two 0700 directories, made and checked by `pheromone_field::outfile`): the user is
//! `pheromone-u<uid>`, the password 32 random bytes from `/dev/urandom` in hex, made by the first
//! session that needs it. A listener takes the file as Zenoh's `usrpwd` dictionary, a connector
//! presents its line; Zenoh's handshake sends an HMAC of a nonce, never the password. Another
//! local user's session presents another user's key, or none, and is refused; root can read any
//! user's key and pass it with `--user`/`--password-file`.

use std::io::{Read, Write};
use std::net::IpAddr;
use std::path::{Path, PathBuf};

use pheromone_field::outfile;

use super::BridgeError;

/// The key file's name in the user's state directory `zenoh`.
pub const KEY_FILE: &str = "owner.key";

/// The largest key file read (a line is `pheromone-u<uid>:` and 64 hex digits).
const KEY_FILE_MAX_BYTES: u64 = 256;

/// Whether a Zenoh endpoint (`tcp/127.0.0.1:7447`, `tls/[::1]:0`, `tcp/localhost:7447`, with
/// or without `?…`/`#…` metadata) names a loopback address only.
pub fn is_loopback(endpoint: &str) -> bool {
    let Some((_, address)) = endpoint.split_once('/') else {
        return false;
    };
    let address = address.split(['?', '#']).next().unwrap_or_default();
    let Some((host, _port)) = address.rsplit_once(':') else {
        return false;
    };
    let host = host.trim_start_matches('[').trim_end_matches(']');
    host.eq_ignore_ascii_case("localhost")
        || host.parse::<IpAddr>().is_ok_and(|ip| ip.is_loopback())
}

/// Whether the owner key applies to a session on these endpoints: at least one, all loopback.
pub fn applies_to(listen: &[String], connect: &[String]) -> bool {
    let mut all = listen.iter().chain(connect).peekable();
    all.peek().is_some() && all.all(|e| is_loopback(e))
}

/// Where this user's key is (made by [`key`]).
pub fn key_path() -> PathBuf {
    outfile::user_state_base().join("zenoh").join(KEY_FILE)
}

/// Whom a listening session admits, from its configuration.
#[derive(Debug, Clone, PartialEq)]
pub enum Admits {
    /// Sessions that present this user's owner key (the file).
    Owner(PathBuf),
    /// Sessions that present a user and password of the `usrpwd` dictionary (`--users-file`,
    /// or `--zenoh-config`).
    Dictionary,
    /// Anyone who reaches its endpoints.
    Anyone,
}

/// Whom a listening session with configuration `c` admits.
pub fn admits(c: &zenoh::Config) -> Admits {
    match c.get_json("transport/auth/usrpwd/dictionary_file") {
        Ok(v) if v != "null" => {
            let owner = key_path();
            let quoted = serde_json::to_string(&owner.to_string_lossy()).expect("a string");
            if v == quoted {
                Admits::Owner(owner)
            } else {
                Admits::Dictionary
            }
        }
        _ => Admits::Anyone,
    }
}

/// This user's key: `(path, user, password)`, made if missing.
pub fn key() -> Result<(PathBuf, String, String), BridgeError> {
    let err = |e: outfile::OutputError| BridgeError::Security(format!("the owner key: {e}"));
    let dir = outfile::user_state_dir("zenoh").map_err(err)?;
    let path = dir.join(KEY_FILE);
    debug_assert_eq!(path, key_path());
    let user = format!("pheromone-u{}", nix::unistd::geteuid().as_raw());
    if !outfile::check_destination(&path).map_err(err)? {
        create(&dir, &path, &user)?;
    }
    let password = read(&path, &user)?;
    Ok((path, user, password))
}

/// Writes a new key under a temporary name and links it to `path` unless another process made
/// one first (then that one is used).
fn create(dir: &Path, path: &Path, user: &str) -> Result<(), BridgeError> {
    let io = |what: &str, e: std::io::Error| {
        BridgeError::Security(format!("the owner key {}: {what}: {e}", path.display()))
    };
    let mut random = [0u8; 32];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut random))
        .map_err(|e| io("read /dev/urandom", e))?;
    let password: String = random.iter().map(|b| format!("{b:02x}")).collect();
    // tempfile creates the file with O_EXCL and mode 0600.
    let mut tmp = tempfile::Builder::new()
        .prefix(".owner.key.")
        .tempfile_in(dir)
        .map_err(|e| io("create a temporary file", e))?;
    writeln!(tmp, "{user}:{password}").map_err(|e| io("write", e))?;
    match tmp.persist_noclobber(path) {
        Ok(_) => Ok(()),
        Err(e) if e.error.kind() == std::io::ErrorKind::AlreadyExists => Ok(()),
        Err(e) => Err(io("link", e.error)),
    }
}

/// Reads the key's password, checking that the file is a regular file of this user that
/// nobody else may read, holding one `user:password` line for `user`.
fn read(path: &Path, user: &str) -> Result<String, BridgeError> {
    let bad = |why: String| {
        BridgeError::Security(format!(
            "the owner key {}: {why} (remove it: the next session makes a new one)",
            path.display()
        ))
    };
    let file = outfile::open_private_read(path).map_err(|e| bad(e.to_string()))?;
    let meta = file.metadata().map_err(|e| bad(e.to_string()))?;
    use std::os::unix::fs::MetadataExt;
    let me = nix::unistd::geteuid().as_raw();
    if meta.uid() != me {
        return Err(bad(format!("owned by uid {}, not by uid {me}", meta.uid())));
    }
    if meta.mode() & 0o077 != 0 {
        return Err(bad(format!(
            "mode {:o} lets group or others read it (expected 600)",
            meta.mode() & 0o7777
        )));
    }
    let mut text = String::new();
    file.take(KEY_FILE_MAX_BYTES)
        .read_to_string(&mut text)
        .map_err(|e| bad(e.to_string()))?;
    let line = text.lines().next().unwrap_or_default();
    match line.split_once(':') {
        Some((u, password))
            if u == user
                && password.len() == 64
                && password.bytes().all(|b| b.is_ascii_hexdigit()) =>
        {
            Ok(password.to_string())
        }
        _ => Err(bad(format!(
            "not one `{user}:<64 hex digits>` line ({} bytes)",
            text.len()
        ))),
    }
}

/// Writes the owner key into `c` when it applies (see [`applies_to`]) and `c` has no
/// credentials of its own: a listener requires it (`usrpwd/dictionary_file`), a connector
/// presents it (`usrpwd/user`, `…/password`). Returns the key file's path when it did.
pub fn apply(
    c: &mut zenoh::Config,
    listen: &[String],
    connect: &[String],
) -> Result<Option<PathBuf>, BridgeError> {
    if !applies_to(listen, connect) || has_credentials(c) {
        return Ok(None);
    }
    let (path, user, password) = key()?;
    let mut set = |k: &str, v: &str| {
        let json = serde_json::to_string(v).expect("a string");
        c.insert_json5(k, &json)
            .map_err(|e| super::zerr(&format!("config {k}"), e))
    };
    if !listen.is_empty() {
        set(
            "transport/auth/usrpwd/dictionary_file",
            &path.to_string_lossy(),
        )?;
    }
    if !connect.is_empty() {
        set("transport/auth/usrpwd/user", &user)?;
        set("transport/auth/usrpwd/password", &password)?;
    }
    Ok(Some(path))
}

/// Whether `c` already names a user, password or dictionary (from `--user`, `--users-file` or
/// `--zenoh-config`).
fn has_credentials(c: &zenoh::Config) -> bool {
    ["user", "password", "dictionary_file"].iter().any(|k| {
        c.get_json(&format!("transport/auth/usrpwd/{k}"))
            .is_ok_and(|v| v != "null")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn loopback_endpoints_are_told_from_the_others() {
        for e in [
            "tcp/127.0.0.1:7447",
            "tcp/127.0.0.1:0",
            "tls/127.8.9.1:7447",
            "tcp/[::1]:7447",
            "tcp/localhost:7447",
            "tcp/127.0.0.1:7447#iface=lo",
        ] {
            assert!(is_loopback(e), "{e}");
        }
        for e in [
            "tcp/0.0.0.0:7447",
            "tcp/[::]:7447",
            "tcp/10.0.0.1:7447",
            "tls/robot.example:7447",
            "tcp/127.0.0.1",
            "127.0.0.1:7447",
        ] {
            assert!(!is_loopback(e), "{e}");
        }
        let s = |v: &[&str]| v.iter().map(|e| e.to_string()).collect::<Vec<_>>();
        assert!(applies_to(&s(&["tcp/127.0.0.1:0"]), &[]));
        assert!(applies_to(&[], &s(&["tcp/[::1]:7447"])));
        assert!(!applies_to(&[], &[]));
        assert!(!applies_to(
            &s(&["tcp/127.0.0.1:7447", "tcp/0.0.0.0:7448"]),
            &[]
        ));
    }

    #[test]
    fn explicit_credentials_win_over_the_owner_key() {
        let mut c = zenoh::Config::default();
        c.insert_json5("transport/auth/usrpwd/user", "\"robot\"")
            .unwrap();
        let listen = vec!["tcp/127.0.0.1:0".to_string()];
        assert_eq!(apply(&mut c, &listen, &[]).unwrap(), None);
        assert_eq!(
            c.get_json("transport/auth/usrpwd/dictionary_file").unwrap(),
            "null"
        );
    }

    #[test]
    fn the_key_is_private_stable_and_a_tampered_one_is_refused() {
        let tmp = tempfile::tempdir().unwrap();
        let dir = tmp.path().join("zenoh");
        std::fs::create_dir(&dir).unwrap();
        let path = dir.join(KEY_FILE);
        let user = "pheromone-u4242";
        create(&dir, &path, user).unwrap();
        let first = read(&path, user).unwrap();
        assert_eq!(first.len(), 64);
        // A second creation keeps the first key.
        create(&dir, &path, user).unwrap();
        assert_eq!(read(&path, user).unwrap(), first);
        use std::os::unix::fs::PermissionsExt;
        let mode = std::fs::metadata(&path).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode, 0o600);
        // Another user's name in it, a readable mode, a symbolic link: refused, named.
        let e = read(&path, "pheromone-u1").unwrap_err().to_string();
        assert!(e.contains("pheromone-u1:<64 hex digits>"), "{e}");
        std::fs::set_permissions(&path, std::fs::Permissions::from_mode(0o644)).unwrap();
        let e = read(&path, user).unwrap_err().to_string();
        assert!(e.contains("mode 644"), "{e}");
        let link = dir.join("link.key");
        std::os::unix::fs::symlink(&path, &link).unwrap();
        let e = read(&link, user).unwrap_err().to_string();
        assert!(e.contains("symbolic link"), "{e}");
    }

    #[test]
    fn a_listener_requires_the_key_and_a_connector_presents_it() {
        let lo = vec!["tcp/127.0.0.1:0".to_string()];
        let mut listener = zenoh::Config::default();
        let path = apply(&mut listener, &lo, &[]).unwrap().expect("applied");
        assert!(listener
            .get_json("transport/auth/usrpwd/dictionary_file")
            .unwrap()
            .contains(&*path.to_string_lossy()));
        assert_eq!(admits(&listener), Admits::Owner(path.clone()));
        let mut connector = zenoh::Config::default();
        apply(&mut connector, &[], &lo).unwrap().expect("applied");
        let user = connector.get_json("transport/auth/usrpwd/user").unwrap();
        assert!(user.contains("pheromone-u"), "{user}");
        let mut open = zenoh::Config::default();
        let any = vec!["tcp/0.0.0.0:0".to_string()];
        assert_eq!(apply(&mut open, &any, &[]).unwrap(), None);
        assert_eq!(admits(&open), Admits::Anyone);
    }
}

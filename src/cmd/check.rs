//! Clap value parsers for the flags that name a place: addresses, Zenoh endpoints, the iceoryx2
//! domain, output directories and files. A bad one is refused while the command line is parsed
//! (clap prints `invalid value 'V' for '--flag <V>': …` and exits with status 2), before any
//! process, node or field starts.

use std::net::SocketAddr;
use std::path::{Path, PathBuf};

/// A clap value parser from a check: a refused value is `--flag VALUE: reason` (exit status 2).
#[derive(Clone, Copy)]
pub struct Place<T>(fn(&str) -> Result<T, String>);

impl<T: Clone + Send + Sync + 'static> clap::builder::TypedValueParser for Place<T> {
    type Value = T;

    fn parse_ref(
        &self,
        cmd: &clap::Command,
        arg: Option<&clap::Arg>,
        value: &std::ffi::OsStr,
    ) -> Result<T, clap::Error> {
        let text = value.to_string_lossy();
        (self.0)(&text).map_err(|reason| super::flag_error(cmd, arg, &text, &reason))
    }
}

/// The value parser of [`parse_iox_domain`].
pub fn iox_domain() -> Place<String> {
    Place(parse_iox_domain)
}

/// The value parser of [`parse_socket_addr`].
pub fn socket_addr() -> Place<String> {
    Place(parse_socket_addr)
}

/// The value parser of [`parse_zenoh_endpoint`].
pub fn zenoh_endpoint() -> Place<String> {
    Place(parse_zenoh_endpoint)
}

/// The value parser of [`parse_mirror_endpoint`].
pub fn mirror_endpoint() -> Place<String> {
    Place(parse_mirror_endpoint)
}

/// The value parser of [`parse_in_file`].
pub fn in_file() -> Place<PathBuf> {
    Place(parse_in_file)
}

/// The value parser of [`parse_out_dir`].
pub fn out_dir() -> Place<PathBuf> {
    Place(parse_out_dir)
}

/// The value parser of [`parse_out_file`].
pub fn out_file() -> Place<PathBuf> {
    Place(parse_out_file)
}

/// `--iox-domain D`: empty (iceoryx2's own domain) or a name giving a valid file prefix.
pub fn parse_iox_domain(s: &str) -> Result<String, String> {
    // The field-name rules make `<D>_iox2_` a valid iceoryx2 prefix (`domain_config_of`);
    // checked without loading iceoryx2's configuration (which logs before --verbose applies).
    if s.is_empty() {
        return Ok(String::new());
    }
    pheromone_field::shm::check_name(s)
        .map(|()| s.to_owned())
        .map_err(|e| e.to_string())
}

/// `IP:PORT` or `localhost:PORT` (a socket to bind or to send to).
pub fn parse_socket_addr(s: &str) -> Result<String, String> {
    if s.parse::<SocketAddr>().is_ok() {
        return Ok(s.to_owned());
    }
    match s.strip_prefix("localhost:").map(str::parse::<u16>) {
        Some(Ok(_)) => Ok(s.to_owned()),
        _ => Err("expected IP:PORT (e.g. 127.0.0.1:8080, [::1]:8080) or localhost:PORT".into()),
    }
}

/// A Zenoh endpoint `PROTOCOL/ADDRESS[?METADATA][#CONFIG]`; for tcp, udp, tls, quic and ws the
/// address is `HOST:PORT`.
pub fn parse_zenoh_endpoint(s: &str) -> Result<String, String> {
    let expected = "expected a Zenoh endpoint PROTOCOL/HOST:PORT, e.g. tcp/127.0.0.1:7447";
    let (proto, rest) = s.split_once('/').ok_or(expected)?;
    let address = rest.split(['?', '#']).next().unwrap_or_default();
    let proto_ok =
        !proto.is_empty() && proto.chars().all(|c| c.is_ascii_alphanumeric() || c == '-');
    if !proto_ok || address.is_empty() {
        return Err(expected.into());
    }
    if ["tcp", "udp", "tls", "quic", "ws"].contains(&proto) {
        let port = address.rsplit_once(':').map(|(host, port)| {
            (
                host.trim_start_matches('[').trim_end_matches(']'),
                port.parse::<u16>(),
            )
        });
        match port {
            Some((host, Ok(_))) if !host.is_empty() => {}
            _ => {
                return Err(format!(
                    "{proto}: the address must be HOST:PORT; {expected}"
                ))
            }
        }
    }
    Ok(s.to_owned())
}

/// `zenoh:ENDPOINT` (a mirror's origin).
pub fn parse_mirror_endpoint(s: &str) -> Result<String, String> {
    let endpoint = s
        .strip_prefix("zenoh:")
        .ok_or("expected zenoh:ENDPOINT, e.g. zenoh:tcp/10.0.0.1:7447")?;
    parse_zenoh_endpoint(endpoint).map(|_| s.to_owned())
}

/// The nearest ancestor of `path` that exists (`.` for a relative path with none).
fn existing_ancestor(path: &Path) -> PathBuf {
    path.ancestors()
        .find(|a| !a.as_os_str().is_empty() && a.exists())
        .map_or_else(|| PathBuf::from("."), Path::to_path_buf)
}

/// A directory to write into: an existing directory, or one that can be created (its nearest
/// existing ancestor is a directory).
pub fn parse_out_dir(s: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(s);
    if s.is_empty() {
        return Err("expected a directory".into());
    }
    if path.exists() && !path.is_dir() {
        return Err("exists and is not a directory".into());
    }
    let ancestor = existing_ancestor(&path);
    if !ancestor.is_dir() {
        return Err(format!(
            "cannot be created: {} is not a directory",
            ancestor.display()
        ));
    }
    Ok(path)
}

/// A file to read (a certificate, a key, a password): an existing regular file this process
/// can open.
pub fn parse_in_file(s: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(s);
    if s.is_empty() {
        return Err("expected a file".into());
    }
    match std::fs::metadata(&path) {
        Err(e) => return Err(format!("cannot read it: {e}")),
        Ok(m) if !m.is_file() => return Err("is not a regular file".into()),
        Ok(_) => {}
    }
    std::fs::File::open(&path).map_err(|e| format!("cannot open it: {e}"))?;
    Ok(path)
}

/// A file to write: a regular file or a new path (never a symbolic link, FIFO or device:
/// `pheromone_field::outfile`), in a directory that exists.
pub fn parse_out_file(s: &str) -> Result<PathBuf, String> {
    let path = PathBuf::from(s);
    if s.is_empty() || path.is_dir() || s.ends_with('/') {
        return Err("expected a file name, not a directory".into());
    }
    pheromone_field::outfile::check_destination(&path).map_err(|e| match e {
        pheromone_field::outfile::OutputError::NotRegular { kind, .. } => {
            format!("is {kind}, not a regular file: refusing to write there")
        }
        other => other.to_string(),
    })?;
    let parent = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p.to_path_buf(),
        _ => PathBuf::from("."),
    };
    if !parent.is_dir() {
        return Err(format!("its directory {} does not exist", parent.display()));
    }
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn places_are_checked_before_anything_starts() {
        assert!(parse_iox_domain("").is_ok() && parse_iox_domain("lab_2").is_ok());
        assert!(parse_iox_domain("a b").is_err() && parse_iox_domain(&"x".repeat(65)).is_err());
        for ok in ["127.0.0.1:0", "[::1]:8080", "0.0.0.0:80", "localhost:7402"] {
            assert_eq!(parse_socket_addr(ok).as_deref(), Ok(ok));
        }
        for bad in [
            "",
            "nonsense",
            "999.1.1.1:80",
            "127.0.0.1",
            "127.0.0.1:70000",
            "host:1",
        ] {
            assert!(parse_socket_addr(bad).is_err(), "{bad}");
        }
        for ok in [
            "tcp/127.0.0.1:7447",
            "tcp/[::1]:7447",
            "udp/robot.local:7447",
            "tcp/10.0.0.1:7447#iface=eth0",
            "unixsock-stream//tmp/z.sock",
        ] {
            assert_eq!(parse_zenoh_endpoint(ok).as_deref(), Ok(ok));
        }
        for bad in [
            "",
            "nonsense",
            "tcp/",
            "tcp/host",
            "tcp/:80",
            "tcp/h:99999",
            "/x",
        ] {
            assert!(parse_zenoh_endpoint(bad).is_err(), "{bad}");
        }
        assert!(parse_mirror_endpoint("zenoh:tcp/127.0.0.1:7447").is_ok());
        assert!(parse_mirror_endpoint("tcp/127.0.0.1:7447").is_err());
        assert!(parse_mirror_endpoint("zenoh:tcp/nonsense").is_err());
        let tmp = std::env::temp_dir();
        let file = tmp.join(format!("pheromone-check-{}", std::process::id()));
        std::fs::write(&file, b"x").unwrap();
        let s = |p: &Path| p.to_string_lossy().into_owned();
        assert!(parse_out_dir(&s(&tmp)).is_ok());
        assert!(parse_out_dir(&s(&tmp.join("new/deeper"))).is_ok());
        assert!(parse_out_dir(&s(&file)).is_err());
        assert!(parse_out_dir(&s(&file.join("sub"))).is_err());
        assert!(parse_out_dir("").is_err());
        assert!(parse_out_file(&s(&tmp.join("x.npy"))).is_ok());
        assert!(parse_out_file("x.npy").is_ok());
        assert!(parse_out_file(&s(&tmp)).is_err());
        assert!(parse_out_file(&s(&tmp.join("no-such-dir/x.npy"))).is_err());
        assert!(parse_out_file(&s(&file.join("x.npy"))).is_err());
        assert!(parse_in_file(&s(&file)).is_ok());
        assert!(parse_in_file(&s(&tmp)).is_err());
        assert!(parse_in_file(&s(&tmp.join("no-such-file.pem"))).is_err());
        assert!(parse_in_file("").is_err());
        std::fs::remove_file(&file).unwrap();
    }
}

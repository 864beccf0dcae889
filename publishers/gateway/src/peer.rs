//! Which local user sent a loopback datagram: the owner of the UDP socket bound to its source
//! address, from the kernel's socket tables (`/proc/net/udp`, `/proc/net/udp6`). On loopback a
//! client ID is no credential (any local process may send under any ID), but the source
//! socket's owner is: another user cannot send from a socket that is not theirs.

use std::collections::HashMap;
use std::net::{IpAddr, SocketAddr};

/// How long a looked-up owner is kept (ns): a client's socket keeps its owner while it lives.
const OWNER_TTL_NS: u64 = 1_000_000_000;
/// Owners kept at most; past it the table is emptied (a lookup costs one read of the tables).
const MAX_OWNERS: usize = 4096;

/// Which local users a gateway serves from loopback sources (`--local-users`).
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum LocalUsers {
    /// Any local user (loopback is then no boundary at all).
    Any,
    /// These uids only (the default: the gateway's own user, and root).
    Only(Vec<u32>),
}

impl LocalUsers {
    /// The gateway's own user and root.
    pub fn owner() -> Self {
        let me = nix::unistd::geteuid().as_raw();
        LocalUsers::Only(if me == 0 { vec![0] } else { vec![me, 0] })
    }
}

/// Looked-up owners of loopback source sockets, kept [`OWNER_TTL_NS`].
#[derive(Default)]
pub(crate) struct Owners(HashMap<SocketAddr, (Option<u32>, u64)>);

impl Owners {
    /// The uid owning the UDP socket bound to `from` (a loopback address), if the kernel's
    /// tables name one.
    pub(crate) fn of(&mut self, from: SocketAddr, now_ns: u64) -> Option<u32> {
        if let Some(&(uid, at)) = self.0.get(&from) {
            if now_ns.saturating_sub(at) < OWNER_TTL_NS {
                return uid;
            }
        }
        if self.0.len() >= MAX_OWNERS {
            self.0.clear();
        }
        let uid = udp_owner(from);
        self.0.insert(from, (uid, now_ns));
        uid
    }
}

/// The uid of the UDP socket bound to `addr`: bound to that address exactly, or to the
/// wildcard address of its family, on its port.
pub fn udp_owner(addr: SocketAddr) -> Option<u32> {
    let table = match addr.ip() {
        IpAddr::V4(_) => "/proc/net/udp",
        IpAddr::V6(_) => "/proc/net/udp6",
    };
    let text = std::fs::read_to_string(table).ok()?;
    let mut wildcard = None;
    for line in text.lines().skip(1) {
        let cols: Vec<&str> = line.split_whitespace().collect();
        let (Some(local), Some(uid)) = (cols.get(1), cols.get(7)) else {
            continue;
        };
        let Some((ip, port)) = parse_local(local) else {
            continue;
        };
        if port != addr.port() {
            continue;
        }
        let uid = uid.parse().ok();
        if ip == addr.ip() {
            return uid;
        }
        if ip.is_unspecified() {
            wildcard = uid;
        }
    }
    wildcard
}

/// `0100007F:1F90`: the address as the kernel prints it (each 32-bit word of the network-order
/// bytes printed as a native integer: one word for IPv4, four for IPv6), and the port in hex.
fn parse_local(s: &str) -> Option<(IpAddr, u16)> {
    let (ip, port) = s.split_once(':')?;
    let port = u16::from_str_radix(port, 16).ok()?;
    let word = |w: &str| u32::from_str_radix(w, 16).ok().map(u32::to_ne_bytes);
    let ip = match ip.len() {
        8 => IpAddr::from(word(ip)?),
        32 => {
            let mut bytes = [0u8; 16];
            for (i, chunk) in bytes.chunks_mut(4).enumerate() {
                chunk.copy_from_slice(&word(ip.get(i * 8..i * 8 + 8)?)?);
            }
            IpAddr::from(bytes)
        }
        _ => return None,
    };
    Some((ip, port))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_kernels_address_forms_parse() {
        assert_eq!(
            parse_local("0100007F:1F90"),
            Some(("127.0.0.1".parse().unwrap(), 8080))
        );
        assert_eq!(
            parse_local("00000000000000000000000001000000:0035"),
            Some(("::1".parse().unwrap(), 53))
        );
        assert_eq!(parse_local("zz:1"), None);
    }

    #[test]
    fn a_socket_of_this_process_is_found_with_its_owner() {
        let s = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let me = nix::unistd::geteuid().as_raw();
        assert_eq!(udp_owner(s.local_addr().unwrap()), Some(me));
        let mut owners = Owners::default();
        assert_eq!(owners.of(s.local_addr().unwrap(), 1), Some(me));
        drop(s);
    }
}

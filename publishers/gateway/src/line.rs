//! Where `pheromone gateway` serves: a serial line or a UDP socket, opened before the field is
//! waited for (a bad path, rate or address fails first), then served until Ctrl-C/SIGTERM.

use std::fs::File;
use std::net::UdpSocket;

use iceoryx2::node::Node;
use pheromone_field::shm::Svc;

use super::{serial, udp, Gateway, GatewayCounters, GatewayError};

/// An opened serial line or a bound UDP socket.
#[derive(Debug)]
pub enum Line {
    Serial { path: String, baud: u32, file: File },
    Udp(UdpSocket),
}

impl Line {
    /// Opens the serial line `path` at `baud` (raw, 8N1; a standard termios rate, see
    /// [`serial::baud_rate`]).
    pub fn serial(path: &str, baud: u32) -> Result<Self, GatewayError> {
        Ok(Line::Serial {
            path: path.to_string(),
            baud,
            file: serial::open(path, baud)?,
        })
    }

    /// Binds the UDP `address` (e.g. `127.0.0.1:7402`; port 0: the system chooses).
    pub fn udp(address: &str) -> Result<Self, GatewayError> {
        Ok(Line::Udp(udp::bind(address)?))
    }

    /// The socket's address as `udp://HOST:PORT` (`None` for a serial line).
    pub fn udp_url(&self) -> Result<Option<String>, std::io::Error> {
        match self {
            Line::Serial { .. } => Ok(None),
            Line::Udp(socket) => Ok(Some(format!("udp://{}", socket.local_addr()?))),
        }
    }

    /// Where it serves, for the log: `serial PATH at B baud` or `udp://HOST:PORT`.
    pub fn describe(&self) -> Result<String, std::io::Error> {
        match self {
            Line::Serial { path, baud, .. } => Ok(format!("serial {path} at {baud} baud")),
            Line::Udp(_) => Ok(self.udp_url()?.unwrap_or_default()),
        }
    }

    /// Serves `gateway` until the node sees a termination request (Ctrl-C, SIGTERM), writing
    /// the counters' status line on stderr once a second and at the end.
    pub fn serve(&mut self, node: &Node<Svc>, gateway: &mut Gateway) -> Result<(), GatewayError> {
        let log = |c: &GatewayCounters| eprintln!("{}", c.status_line());
        match self {
            Line::Serial { path, file, .. } => serial::serve(node, gateway, file, path, log),
            Line::Udp(socket) => udp::serve(node, gateway, socket, log),
        }
    }
}

//! The gateway on a UDP socket: one DLE/CRC frame per datagram, each answered to its sender.

use std::net::{SocketAddr, UdpSocket};
use std::time::Duration;

use iceoryx2::node::Node;
use pheromone_field::process::run::Housekeeping;
use pheromone_field::shm::{now_ns, Svc};
use pheromone_gateway_codec::{decode, MAX_ENCODED_BYTES, MAX_WIRE_BYTES};

use super::{Gateway, GatewayCounters, GatewayError, LOG_EVERY};

/// How long one receive waits before the loop looks at Ctrl-C and the log clock.
const RECEIVE_SLICE: Duration = Duration::from_millis(100);

/// Binds `address` (loopback unless told otherwise, e.g. `127.0.0.1:7402`).
pub fn bind(address: &str) -> Result<UdpSocket, GatewayError> {
    let socket = UdpSocket::bind(address).map_err(|source| GatewayError::Socket {
        address: address.to_string(),
        action: "bind",
        source,
    })?;
    socket
        .set_read_timeout(Some(RECEIVE_SLICE))
        .map_err(|source| GatewayError::Socket {
            address: address.to_string(),
            action: "set the receive timeout",
            source,
        })?;
    Ok(socket)
}

/// Serves `gateway` on `socket` until the node sees a termination request (Ctrl-C, SIGTERM);
/// calls `log` with the counters once a second. A datagram longer than any frame is counted
/// as too long (it is cut by the receive buffer, never parsed as a shorter frame).
pub fn serve(
    node: &Node<Svc>,
    gateway: &mut Gateway,
    socket: &UdpSocket,
    mut log: impl FnMut(&GatewayCounters),
) -> Result<(), GatewayError> {
    let address = socket
        .local_addr()
        .map(|a| a.to_string())
        .unwrap_or_else(|_| "?".into());
    // One byte more than the longest valid frame tells an over-long datagram apart.
    let mut datagram = [0u8; MAX_WIRE_BYTES + 1];
    let mut out = [0u8; MAX_ENCODED_BYTES];
    let mut chores = Housekeeping::new(LOG_EVERY);
    while chores.running(node) {
        if chores.due(node) {
            log(gateway.counters());
        }
        let (n, from): (usize, SocketAddr) = match socket.recv_from(&mut datagram) {
            Ok(got) => got,
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock
                        | std::io::ErrorKind::TimedOut
                        | std::io::ErrorKind::Interrupted
                ) =>
            {
                continue
            }
            Err(source) => {
                return Err(GatewayError::Socket {
                    address,
                    action: "receive",
                    source,
                })
            }
        };
        let reply = if n > MAX_WIRE_BYTES {
            gateway.rejected(&pheromone_gateway_codec::DecodeError::TooLong)
        } else {
            match decode(&datagram[..n]) {
                None => {
                    gateway.rejected(&pheromone_gateway_codec::DecodeError::Truncated { len: n })
                }
                Some(Err(e)) => gateway.rejected(&e),
                Some(Ok(frame)) => gateway.handle_from(frame, now_ns(), Some(from))?,
            }
        };
        if let Some(reply) = reply {
            // Every reply fits: it is a message the codec itself bounds.
            let len = reply
                .encode(&mut out)
                .expect("a reply fits MAX_ENCODED_BYTES");
            if let Err(source) = socket.send_to(&out[..len], from) {
                // A client that went away is no failure of the gateway: count and go on.
                gateway.counters.dropped += 1;
                eprintln!("gateway: reply to {from} not sent: {source}");
            }
        }
    }
    log(gateway.counters());
    Ok(())
}

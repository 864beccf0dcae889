//! `--allow ID@ADDR`: a client ID served only from the UDP source it is bound to.
//!
//! Client 3 is bound to 127.0.0.2: the same bytes from 127.0.0.1 get reason 6, from 127.0.0.2
//! an answer; client 4 (not bound, on the list) is served from anywhere, client 5 (not listed)
//! nowhere.

use std::net::UdpSocket;
use std::time::Duration;

use super::*;

/// A client whose socket has the local address `ip`.
fn client_from(ip: &str, port: u16) -> Client {
    let socket = UdpSocket::bind((ip, 0)).unwrap();
    socket.connect(("127.0.0.1", port)).unwrap();
    socket
        .set_read_timeout(Some(Duration::from_millis(500)))
        .unwrap();
    Client { socket }
}

#[test]
fn a_client_id_bound_to_an_address_is_served_only_from_it() {
    let field = unique("gw-bound");
    let field_proc = start_field(&field);
    let port = free_port();
    let (gateway, _ready) = start_gateway(&field, port, &["--allow", "1,4,3@127.0.0.2"]);
    let elsewhere = client_from("127.0.0.1", port);
    let bound = client_from("127.0.0.2", port);
    // PING from client 3: 0xFF reason 6 from 127.0.0.1, a status from 127.0.0.2.
    assert_eq!(elsewhere.ask(3, 0x03, &[]), (3, 0xFF, vec![6]));
    let (id, op, _) = bound.ask(3, 0x03, &[]);
    assert_eq!((id, op), (3, 0x83));
    // Not bound: from anywhere.
    assert_eq!(elsewhere.ask(4, 0x03, &[]).1, 0x83);
    assert_eq!(bound.ask(4, 0x03, &[]).1, 0x83);
    // Not listed: nowhere.
    assert_eq!(bound.ask(5, 0x03, &[]), (5, 0xFF, vec![6]));
    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "gateway: {}", stderr(&out));
    assert_eq!(json(&out)["errors_sent"][6], 2);
    field_proc.interrupt();
    field_proc.wait_exit(Duration::from_secs(30));
    // Refused at the start: a bad address, and a binding on a serial line.
    let o = run(&["gateway", "--field", &field, "--allow", "3@nowhere"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("'nowhere' is not an IP address"),
        "{}",
        stderr(&o)
    );
    let o = run(&[
        "gateway",
        "--field",
        &field,
        "--serial",
        "/dev/null",
        "--allow",
        "3@127.0.0.1",
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("serial line has no source address"),
        "{}",
        stderr(&o)
    );
}

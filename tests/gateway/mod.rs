//! `pheromone gateway` over UDP loopback, from a client that knows only docs/gateway-wire.md.
//!
//! `pheromone gateway` end to end over UDP loopback, with a real field process, from a client
//! that knows only the documented bytes of docs/gateway-wire.md (MODELS.md M3): it builds and
//! parses frames by hand — DLE STX, client ID, opcode, little-endian data, CRC-16/ARC written out
//! here from its parameters, DLE stuffing, DLE ETX — and uses nothing of the codec crate.

mod backup;
mod bound;
mod follower_backup;
mod radio;
mod refusals;
mod remote;
mod serial;
mod sources;

use std::net::UdpSocket;
use std::time::Duration;

use crate::harness::*;

const DLE: u8 = 0x10;

/// CRC-16/ARC as documented: poly 0x8005 reflected (0xA001), init 0, no final xor.
fn crc16_arc(bytes: &[u8]) -> u16 {
    let mut crc = 0u16;
    for &b in bytes {
        crc ^= b as u16;
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xA001
            } else {
                crc >> 1
            };
        }
    }
    crc
}

/// `0x10 0x02 | body stuffed | 0x10 0x03`, body = ID, opcode, data, CRC lo, CRC hi.
fn frame(id: u8, op: u8, data: &[u8]) -> Vec<u8> {
    let mut body = vec![id, op];
    body.extend_from_slice(data);
    let crc = crc16_arc(&body);
    body.extend_from_slice(&crc.to_le_bytes());
    let mut out = vec![DLE, 0x02];
    for b in body {
        out.push(b);
        if b == DLE {
            out.push(DLE);
        }
    }
    out.extend_from_slice(&[DLE, 0x03]);
    out
}

/// The reply's (ID, opcode, data), its delimiters, stuffing and CRC checked.
fn parse(wire: &[u8]) -> (u8, u8, Vec<u8>) {
    assert_eq!(&wire[..2], &[DLE, 0x02], "starts with DLE STX: {wire:02x?}");
    assert_eq!(&wire[wire.len() - 2..], &[DLE, 0x03], "ends with DLE ETX");
    let mut body = Vec::new();
    let mut i = 2;
    while i < wire.len() - 2 {
        body.push(wire[i]);
        if wire[i] == DLE {
            assert_eq!(wire[i + 1], DLE, "a DLE in the body is doubled");
            i += 1;
        }
        i += 1;
    }
    let (msg, crc) = body.split_at(body.len() - 2);
    assert_eq!(crc16_arc(msg), u16::from_le_bytes([crc[0], crc[1]]));
    (msg[0], msg[1], msg[2..].to_vec())
}

fn f32s(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

fn f32_at(data: &[u8], at: usize) -> f32 {
    f32::from_le_bytes(data[at..at + 4].try_into().unwrap())
}

fn pir(x_m: f32, y_m: f32, theta_rad: f32, half_base_m: f32, channel: u8) -> Vec<u8> {
    let mut d = f32s(&[x_m, y_m, theta_rad, half_base_m]);
    d.push(channel);
    d
}

fn deposit(seq: u8, x_m: f32, y_m: f32, amount: f32, channel: u8) -> Vec<u8> {
    let mut d = vec![seq];
    d.extend(f32s(&[x_m, y_m, amount]));
    d.push(channel);
    d
}

struct Client {
    socket: UdpSocket,
}

impl Client {
    fn new(port: u16) -> Self {
        let socket = UdpSocket::bind("127.0.0.1:0").unwrap();
        socket.connect(("127.0.0.1", port)).unwrap();
        socket
            .set_read_timeout(Some(Duration::from_millis(500)))
            .unwrap();
        Self { socket }
    }

    fn send(&self, bytes: &[u8]) {
        self.socket.send(bytes).unwrap();
    }

    /// The next reply, or `None` if none comes within the read timeout.
    fn reply(&self) -> Option<(u8, u8, Vec<u8>)> {
        let mut buf = [0u8; 1024];
        let deadline = std::time::Instant::now() + Duration::from_millis(500);
        loop {
            match self.socket.recv(&mut buf) {
                Ok(n) => return Some(parse(&buf[..n])),
                // A datagram sent before the gateway bound its port came back refused.
                Err(e)
                    if e.kind() == std::io::ErrorKind::ConnectionRefused
                        && std::time::Instant::now() < deadline =>
                {
                    std::thread::park_timeout(Duration::from_millis(10));
                }
                Err(_) => return None,
            }
        }
    }

    fn ask(&self, id: u8, op: u8, data: &[u8]) -> (u8, u8, Vec<u8>) {
        self.send(&frame(id, op, data));
        self.reply()
            .unwrap_or_else(|| panic!("no reply to op {op:#04x}"))
    }
}

/// A field of 100×100 cells of 0.1 m, no evaporation, 50 Hz, that prints its summary at exit.
fn start_field(name: &str) -> Proc {
    Proc::spawn(
        &Cmd::field(name)
            .grid(100, 100)
            .cell_size(0.1)
            .model("none")
            .tick_hz(50)
            .json()
            .argv(),
    )
}

/// A UDP port free a moment ago (the gateway binds it next).
fn free_port() -> u16 {
    UdpSocket::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

fn start_gateway(field: &str, port: u16, extra: &[&str]) -> (Proc, Client) {
    let udp = format!("127.0.0.1:{port}");
    let mut args = vec!["gateway", "--field", field, "--udp", &udp, "--json"];
    args.extend_from_slice(extra);
    let proc = Proc::spawn(&args);
    let client = Client::new(port);
    // Ready once it answers a ping.
    eventually(
        Duration::from_secs(30),
        "the gateway to answer a ping",
        || {
            client.send(&frame(1, 0x03, &[]));
            client.reply()
        },
    );
    (proc, client)
}

#[test]
fn a_thin_client_reads_antennas_deposits_once_and_gets_each_documented_error() {
    let field = unique("gw");
    let field_proc = start_field(&field);
    let (gateway, c) = start_gateway(
        &field,
        free_port(),
        &["--allow", "1-5,16", "--rate-hz", "0"],
    );

    // PING: 0x83 frame_seq u32, field_time_s f32, channels u8.
    let (id, op, data) = c.ask(1, 0x03, &[]);
    assert_eq!((id, op, data.len()), (1, 0x83, 9));
    assert_eq!(data[8], 1, "one channel");

    // DEPOSIT seq 7 at (5.0, 5.3): 0x82 seq, status 0. Client ID 0x10 is stuffed both ways.
    let (id, op, data) = c.ask(0x10, 0x02, &deposit(7, 5.0, 5.3, 1.0, 0));
    assert_eq!((id, op, data), (0x10, 0x82, vec![7, 0]));
    // The same seq again (a retry): answered as applied, not applied twice.
    let (_, op, data) = c.ask(0x10, 0x02, &deposit(7, 5.0, 5.3, 1.0, 0));
    assert_eq!((op, data), (0x82, vec![7, 0]));

    // PIR at (5.0, 5.0) facing +x, half base 0.3: the left antenna (5.0, 5.3) sits on the
    // deposit, the right one (5.0, 4.7) beside it.
    let (p_left, p_right) = eventually(Duration::from_secs(10), "the deposit in a PIR", || {
        let (id, op, data) = c.ask(1, 0x01, &pir(5.0, 5.0, 0.0, 0.3, 0));
        assert_eq!((id, op, data.len()), (1, 0x81, 12));
        let (l, r) = (f32_at(&data, 0), f32_at(&data, 4));
        (l > 0.0).then_some((l, r))
    });
    assert!((p_left - 1.0).abs() < 1e-3, "on the plateau: {p_left}");
    assert!(p_right < p_left, "right {p_right} < left {p_left}");

    // Errors with a valid CRC: 0xFF reason.
    let reason = |id, op, data: &[u8]| {
        let (rid, rop, rdata) = c.ask(id, op, data);
        assert_eq!((rid, rop, rdata.len()), (id, 0xFF, 1), "op {op:#04x}");
        rdata[0]
    };
    assert_eq!(reason(1, 0x07, &[]), 1, "unknown opcode");
    assert_eq!(
        reason(1, 0x01, &pir(5.0, 5.0, 0.0, 0.3, 0)[..16]),
        2,
        "bad length"
    );
    assert_eq!(reason(1, 0x01, &pir(f32::NAN, 5.0, 0.0, 0.3, 0)), 3, "NaN");
    assert_eq!(
        reason(1, 0x01, &pir(5.0, 5.0, 0.0, -1.0, 0)),
        3,
        "half base"
    );
    assert_eq!(reason(1, 0x01, &pir(5.0, 5.0, 0.0, 0.3, 9)), 4, "channel");
    assert_eq!(reason(9, 0x03, &[]), 6, "client 9 is not on the allow-list");
    // A deposit on an unknown channel or off the grid: status = the reason, not applied.
    assert_eq!(c.ask(2, 0x02, &deposit(1, 5.0, 5.0, 1.0, 3)).2, vec![1, 4]);
    assert_eq!(
        c.ask(2, 0x02, &deposit(2, 500.0, 5.0, 1.0, 0)).2,
        vec![2, 3]
    );

    // A bad CRC gets no reply: the next reply is the following ping's.
    let mut corrupt = frame(1, 0x03, &[]);
    corrupt[4] ^= 0x01;
    c.send(&corrupt);
    let (_, op, _) = c.ask(1, 0x03, &[]);
    assert_eq!(op, 0x83, "the corrupt frame was not answered");

    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "gateway: {}", stderr(&out));
    let counters = json(&out);
    assert_eq!(counters["deposits"], 1, "{counters}");
    assert_eq!(counters["deposits_repeated"], 1, "{counters}");
    assert_eq!(counters["rejected"]["bad_crc"], 1, "{counters}");
    assert_eq!(counters["dropped"], 1, "{counters}");

    field_proc.interrupt();
    let out = field_proc.wait_exit(Duration::from_secs(30));
    let summary = json(&out);
    assert_eq!(summary["deposits_applied"], 1, "applied once: {summary}");
}

#[test]
fn a_flood_under_a_clients_id_from_another_socket_does_not_starve_it() {
    let field = unique("gw-flood");
    let field_proc = Proc::spawn(&Cmd::field(&field).tick_hz(20).argv());
    let (gateway, c) = start_gateway(&field, free_port(), &["--rate-hz", "20"]);
    let port = c.socket.peer_addr().unwrap().port();
    let stop = std::sync::Arc::new(std::sync::atomic::AtomicBool::new(false));
    let flood = {
        let stop = stop.clone();
        std::thread::spawn(move || {
            let s = UdpSocket::bind("127.0.0.1:0").unwrap();
            let ping = frame(3, 0x03, &[]);
            let mut sent = 0u64;
            while !stop.load(std::sync::atomic::Ordering::Relaxed) {
                let _ = s.send_to(&ping, ("127.0.0.1", port));
                sent += 1;
                if sent.is_multiple_of(64) {
                    std::thread::yield_now();
                }
            }
            sent
        })
    };
    // The real client of ID 3 asks about 5 times a second, well under its 20, and retries a
    // request whose reply does not come (as the thin client does, up to 3 tries): the flood
    // fills the socket's queue, which drops datagrams of every sender alike.
    let (mut answered, mut limited) = (0, 0);
    for _ in 0..10 {
        std::thread::park_timeout(Duration::from_millis(200));
        for _ in 0..3 {
            c.send(&frame(3, 0x03, &[]));
            match c.reply() {
                Some((_, 0xFF, data)) if data == vec![5] => limited += 1,
                Some((_, op, _)) if op != 0xFF => {
                    answered += 1;
                    break;
                }
                _ => {}
            }
        }
    }
    stop.store(true, std::sync::atomic::Ordering::Relaxed);
    let sent = flood.join().unwrap();
    println!("flood of {sent} datagrams: {answered} of 10 answered, {limited} rate-limited");
    assert!(sent > 1000, "the flood sent only {sent}");
    assert_eq!(
        limited, 0,
        "the flood's requests took the real client's bucket"
    );
    assert!(
        answered >= 8,
        "{answered} of 10 answered during a flood of {sent}"
    );
    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert!(
        json(&out)["errors_sent"][5].as_u64().unwrap() > 0,
        "the flood was limited"
    );
    field_proc.interrupt();
    field_proc.wait_exit(Duration::from_secs(30));
}

#[test]
fn a_client_over_its_rate_is_told_so() {
    let field = unique("gw-rate");
    let field_proc = Proc::spawn(&Cmd::field(&field).tick_hz(20).argv());
    // 1 request per second: a burst of 1 (the ready ping takes it), then one a second.
    let (gateway, c) = start_gateway(&field, free_port(), &["--rate-hz", "1"]);
    let limited = (0..10)
        .filter(|_| {
            let (_, op, data) = c.ask(3, 0x03, &[]);
            op == 0xFF && data == vec![5]
        })
        .count();
    assert!(limited >= 5, "{limited} of 10 requests were rate limited");
    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert_eq!(json(&out)["errors_sent"][5], limited, "counted");
    field_proc.interrupt();
    field_proc.wait_exit(Duration::from_secs(30));
}

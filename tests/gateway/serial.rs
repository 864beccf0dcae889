//! `pheromone gateway --serial` end to end over a pseudo-terminal pair, with a real field.
//!
//! `pheromone gateway --serial` end to end over a pseudo-terminal pair, with a real field
//! process: the gateway opens the pty's slave (`/dev/pts/N`) at 9600 baud, the test's
//! `GatewayClient` talks on the master side. A pty does not enforce the baud rate, so the
//! capacity figure is printed twice: measured on the pty, and the bound the bytes give at 9600.

use std::fs::File;
use std::io::Write;
use std::time::{Duration, Instant};

use pheromone_gateway::client::{ClientConfig, GatewayClient, Transport};
use pheromone_gateway_codec::{encoded_len, Message, PirReply, PirRequest};

use crate::harness::*;

#[test]
fn a_client_on_a_pty_pings_deposits_and_reads_the_deposit_through_a_serial_gateway() {
    let field = unique("gw-serial");
    let field_proc = super::start_field(&field);
    let pty = nix::pty::openpty(None, None).expect("openpty");
    // The test keeps the slave open too: the master never sees a hang-up while the gateway
    // starts or stops.
    let slave_path = nix::unistd::ttyname(&pty.slave).expect("ttyname");
    let slave_path = slave_path.to_str().expect("a UTF-8 pty path").to_string();
    pheromone_gateway::serial::configure(&pty.slave, nix::sys::termios::BaudRate::B9600)
        .expect("raw slave");
    let gateway = Proc::spawn(&[
        "gateway",
        "--field",
        &field,
        "--serial",
        &slave_path,
        "--baud",
        "9600",
        "--rate-hz",
        "0",
        "--json",
    ]);
    let mut raw = File::from(pty.master.try_clone().expect("dup master"));
    let transport = Transport::serial_fd(pty.master, &slave_path).expect("master");
    let mut client = GatewayClient::new(
        transport,
        ClientConfig {
            client_id: 3,
            timeout: Duration::from_millis(300),
            retries: 2,
            ..Default::default()
        },
    );

    // Ready once it answers a ping.
    let status = eventually(Duration::from_secs(30), "a ping over the pty", || {
        client.ping().ok()
    });
    assert_eq!(status.channels, 1);

    // Garbage, then a frame with a bad CRC on the line: dropped and counted, no reply; the
    // next request is still answered.
    raw.write_all(&[0x00, 0x55, 0x10, 0x03, 0xAA]).unwrap();
    raw.write_all(&[0x10, 0x02, 0x03, 0x03, 0x00, 0x00, 0x10, 0x03])
        .unwrap();
    assert!(client.ping().is_ok(), "answered after the garbage");

    let seq = client.deposit(5.0, 5.3, 1.0, 0).expect("deposit");
    assert_eq!(seq, 0);
    let reading = eventually(Duration::from_secs(10), "the deposit in a PIR", || {
        let r = client.pir(5.0, 5.0, 0.0, 0.3, 0).expect("PIR");
        (r.p_left > 0.0).then_some(r)
    });
    assert!((reading.p_left - 1.0).abs() < 1e-3, "{reading:?}");
    assert!(reading.p_right < reading.p_left, "{reading:?}");

    // Capacity: PIR round trips for 5 s on the half-duplex line (one request, one reply).
    let request = Message::Pir(PirRequest {
        x_m: 5.0,
        y_m: 5.0,
        theta_rad: 0.0,
        half_wheel_base_m: 0.3,
        channel: 0,
    });
    let reply = Message::PirReply(PirReply {
        p_left: reading.p_left,
        p_right: reading.p_right,
        frame_seq: reading.frame_seq,
    });
    let bytes = encoded_len(&request, 3) + encoded_len(&reply, 3);
    let (t0, mut n) = (Instant::now(), 0u64);
    while t0.elapsed() < Duration::from_secs(5) {
        client.pir(5.0, 5.0, 0.0, 0.3, 0).expect("PIR");
        n += 1;
    }
    let measured = n as f64 / t0.elapsed().as_secs_f64();
    // 8N1: 10 bits on the line per byte.
    let bound: f64 = 9600.0 / 10.0 / bytes as f64;
    println!(
        "serial capacity: {bytes} bytes per PIR round trip on the wire; at 9600 baud 8N1 \
         ({} bytes/s) one half-duplex line carries at most {bound:.1} PIR/s = {} robots at 10 Hz \
         (before radio turnaround); measured on the pty (no baud limit): {measured:.0} PIR/s \
         ({n} in 5 s)",
        9600 / 10,
        (bound / 10.0).floor()
    );
    assert!(n > 0);

    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "gateway: {}", stderr(&out));
    let counters = json(&out);
    assert_eq!(counters["deposits"], 1, "{counters}");
    assert_eq!(counters["rejected"]["bad_crc"], 1, "{counters}");
    assert!(counters["pirs"].as_u64().unwrap() > n, "{counters}");

    field_proc.interrupt();
    let out = field_proc.wait_exit(Duration::from_secs(30));
    assert_eq!(json(&out)["deposits_applied"], 1, "applied once");
    drop(pty.slave);
}

#[test]
fn a_bad_baud_rate_exits_2_naming_it() {
    let out = run(&["gateway", "--serial", "/dev/null", "--baud", "12345"]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("12345"), "{}", stderr(&out));
    let out = run(&["gateway", "--serial", "/dev/null", "--udp", "127.0.0.1:0"]);
    assert_eq!(
        out.status.code(),
        Some(2),
        "--serial and --udp: {}",
        stderr(&out)
    );
}

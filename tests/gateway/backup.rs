//! A gateway client fails over from a SIGKILLed primary to its backup; no deposit twice.
//!
//! A client with a primary and a backup gateway (two `pheromone gateway` processes on one
//! field): the primary is SIGKILLed mid-run, the client switches to the backup and keeps getting
//! PIR answers, and the deposit sent to the dead primary is applied once, by the backup.

use std::time::{Duration, Instant};

use pheromone_gateway::client::{ClientConfig, GatewayClient, Transport, Which};

use super::free_port;
use crate::harness::*;

fn spawn_gateway(field: &str, port: u16) -> Proc {
    let udp = format!("127.0.0.1:{port}");
    Proc::spawn(&[
        "gateway",
        "--field",
        field,
        "--udp",
        &udp,
        "--rate-hz",
        "0",
        "--json",
    ])
}

#[test]
fn the_client_switches_to_the_backup_when_the_primary_is_killed_and_deposits_apply_once() {
    let field = unique("gw-backup");
    let field_proc = super::start_field(&field);
    let (p_port, b_port) = (free_port(), free_port());
    let mut primary = spawn_gateway(&field, p_port);
    let backup = spawn_gateway(&field, b_port);
    let ready = |port: u16| {
        let mut probe = GatewayClient::new(
            Transport::udp(&format!("127.0.0.1:{port}")).unwrap(),
            ClientConfig {
                client_id: 9,
                ..Default::default()
            },
        );
        eventually(
            Duration::from_secs(30),
            "a gateway to answer a ping",
            || probe.ping().ok(),
        );
    };
    ready(p_port);
    ready(b_port);

    let timeout = Duration::from_millis(100);
    let mut client = GatewayClient::new(
        Transport::udp(&format!("127.0.0.1:{p_port}")).unwrap(),
        ClientConfig {
            client_id: 4,
            timeout,
            retries: 1,
            ..Default::default()
        },
    )
    .with_backup(Transport::udp(&format!("127.0.0.1:{b_port}")).unwrap());

    // Following on the primary; one deposit through it.
    for _ in 0..20 {
        client
            .pir(5.0, 5.0, 0.0, 0.3, 0)
            .expect("PIR from the primary");
    }
    assert_eq!(client.deposit(5.0, 5.3, 1.0, 0).expect("deposit 1"), 0);
    assert_eq!(client.active(), Which::Primary);
    // The field has taken deposit 1 (a deposit still queued when its gateway is SIGKILLed can
    // be lost with the dead publisher's samples: "at most once", see docs/gateway-wire.md).
    eventually(Duration::from_secs(30), "deposit 1 in a PIR", || {
        let r = client
            .pir(5.0, 5.0, 0.0, 0.3, 0)
            .expect("PIR from the primary");
        (r.p_left > 0.5).then_some(())
    });
    assert_eq!(client.active(), Which::Primary);

    primary.kill();
    let killed = Instant::now();
    eventually(Duration::from_secs(10), "the primary to die", || {
        (!primary.is_running()).then_some(())
    });
    let dead = Instant::now();
    // The next deposit goes to the dead primary, is retried across the switch, and the backup
    // applies it.
    assert_eq!(client.deposit(5.0, 4.7, 1.0, 0).expect("deposit 2"), 1);
    let (switch, after_dead) = (killed.elapsed(), dead.elapsed());
    assert_eq!(client.active(), Which::Backup);
    assert!(client.active_address().ends_with(&b_port.to_string()));

    // Still following, on the backup; it sees both deposits (left and right antenna).
    let reading = eventually(Duration::from_secs(30), "both deposits in a PIR", || {
        let r = client
            .pir(5.0, 5.0, 0.0, 0.3, 0)
            .expect("PIR from the backup");
        (r.p_left > 0.5 && r.p_right > 0.5).then_some(r)
    });
    for _ in 0..20 {
        client
            .pir(5.0, 5.0, 0.0, 0.3, 0)
            .expect("PIR from the backup");
    }
    assert_eq!(client.active(), Which::Backup);
    assert!((reading.p_left - 1.0).abs() < 1e-3, "{reading:?}");
    assert!((reading.p_right - 1.0).abs() < 1e-3, "{reading:?}");
    println!(
        "backup switch: {:.1} ms from SIGKILL of the primary to the backup's answer, {:.2} ms \
         of it from the request to the dead primary (loopback refuses the dead port at once; a \
         silent primary costs (1 + retries) × timeout = {} ms before the switch)",
        switch.as_secs_f64() * 1e3,
        after_dead.as_secs_f64() * 1e3,
        2 * timeout.as_millis()
    );

    backup.interrupt();
    let out = backup.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "backup: {}", stderr(&out));
    let counters = json(&out);
    assert_eq!(
        counters["deposits"], 1,
        "the backup applied deposit 2: {counters}"
    );
    assert_eq!(counters["deposits_repeated"], 0, "{counters}");

    field_proc.interrupt();
    let out = field_proc.wait_exit(Duration::from_secs(30));
    assert_eq!(
        json(&out)["deposits_applied"],
        2,
        "each deposit applied exactly once"
    );
}

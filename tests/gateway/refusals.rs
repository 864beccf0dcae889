//! A deposit the field would refuse is refused by the gateway with the field's own checks.
//!
//! From a client that knows only the documented bytes: an amount beyond the field's limits
//! (1e30), a negative amount on an unsigned channel, both answered with status 3 and never sent
//! (the field counts no rejection); the same negative amount on a field whose channel is
//! `--signed` is applied (status 0), so the gateway checks with the field's configuration.

use std::time::Duration;

use super::*;

/// Waits until the gateway has seen two frames newer than the first one it answers with: the
/// field has published its configuration to the gateway's subscriber by then.
pub(super) fn wait_config(c: &Client) {
    let seq = |c: &Client| {
        let (_, op, data) = c.ask(1, 0x03, &[]);
        assert_eq!(op, 0x83);
        u32::from_le_bytes(data[..4].try_into().unwrap())
    };
    let first = seq(c);
    eventually(Duration::from_secs(30), "two newer frames", || {
        (seq(c) >= first + 2).then_some(())
    });
}

/// Stops the gateway and the field; their summaries.
fn stop(gateway: Proc, field: Proc) -> (serde_json::Value, serde_json::Value) {
    gateway.interrupt();
    let g = gateway.wait_exit(Duration::from_secs(30));
    assert!(g.status.success(), "gateway: {}", stderr(&g));
    field.interrupt();
    let f = field.wait_exit(Duration::from_secs(30));
    (json(&g), json(&f))
}

#[test]
fn deposits_the_field_would_refuse_get_status_3_and_never_reach_it() {
    let field = unique("gw-refuse");
    let field_proc = start_field(&field);
    let (gateway, c) = start_gateway(&field, free_port(), &["--rate-hz", "0"]);
    wait_config(&c);
    // 0x82 seq, status: 3 (a bad value) for what the field refuses, 0 for a good deposit.
    assert_eq!(c.ask(2, 0x02, &deposit(1, 5.0, 5.0, 1e30, 0)).2, vec![1, 3]);
    assert_eq!(c.ask(2, 0x02, &deposit(2, 5.0, 5.0, -1.0, 0)).2, vec![2, 3]);
    assert_eq!(c.ask(2, 0x02, &deposit(3, 5.0, 5.0, 1.0, 0)).2, vec![3, 0]);
    // The field's limit is 1e6 (its default): just below passes.
    assert_eq!(c.ask(2, 0x02, &deposit(4, 5.0, 5.0, 9e5, 0)).2, vec![4, 0]);
    let (g, f) = stop(gateway, field_proc);
    assert_eq!(g["deposits"], 2, "{g}");
    assert_eq!(g["deposits_refused"]["out_of_limits"], 1, "{g}");
    assert_eq!(g["deposits_refused"]["negative_on_unsigned"], 1, "{g}");
    assert_eq!(g["errors_sent"][3], 2, "{g}");
    assert_eq!(f["deposits_applied"], 2, "{f}");
    let rejected: u64 = f["deposits_rejected"]
        .as_object()
        .unwrap()
        .values()
        .map(|v| v.as_u64().unwrap())
        .sum();
    assert_eq!(rejected, 0, "the field saw none of the refused: {f}");
}

#[test]
fn a_negative_deposit_on_a_signed_channel_is_applied() {
    let field = unique("gw-signed");
    let field_proc = Proc::spawn(
        &Cmd::field(&field)
            .grid(100, 100)
            .cell_size(0.1)
            .model("none")
            .tick_hz(50)
            .arg("--signed")
            .json()
            .argv(),
    );
    let (gateway, c) = start_gateway(&field, free_port(), &["--rate-hz", "0"]);
    wait_config(&c);
    assert_eq!(c.ask(2, 0x02, &deposit(1, 5.0, 5.0, -1.0, 0)).2, vec![1, 0]);
    let (g, f) = stop(gateway, field_proc);
    assert_eq!(g["deposits"], 1, "{g}");
    assert_eq!(f["deposits_applied"], 1, "{f}");
}

//! A gateway on a source channel (MODELS.md M3): a DEPOSIT adds one quantum to the nearest node's
//! counter, whatever its amount, and a PIR reads eq. 4 with directional antennas.
//!
//! The field runs a configuration file with one channel `sources = { plateau_m = 0.05,
//! slope_m = 0.25 }` (quantum Q = 1, τ long enough to lose nothing during the test); a client
//! that knows only the documented bytes deposits amount 5 at (2.02, 2.0) m (nearest node (2, 2))
//! and reads P_L = P_R = μ(√0.02) = 1 − (0.1414 − 0.05)/0.25 ≈ 0.634 with the source ahead, and
//! 0 with the same source behind the antennas.

use std::time::Duration;

use super::*;

const CONFIG: &str = r#"width = 80
height = 80
cell_size_m = 0.05
tick_hz = 50.0

[[channel]]
name = "trail"
evaporation = { model = "quantum", quantum = 1.0, tau_s = 100000.0 }
sources = { plateau_m = 0.05, slope_m = 0.25 }
"#;

#[test]
fn a_source_channel_takes_one_quantum_per_deposit_and_hides_sources_behind_the_antennas() {
    let field = unique("gw-src");
    let path = std::env::temp_dir().join(format!("{field}.toml"));
    std::fs::write(&path, CONFIG).unwrap();
    let field_proc = Proc::spawn(&[
        "field",
        "--name",
        &field,
        "--config",
        path.to_str().unwrap(),
        "--json",
    ]);
    let (gateway, c) = start_gateway(&field, free_port(), &["--rate-hz", "0"]);
    // The gateway knows the field's channels once the field has published its configuration.
    super::refusals::wait_config(&c);
    std::fs::remove_file(&path).unwrap();

    let (_, op, data) = c.ask(1, 0x02, &deposit(1, 2.02, 2.0, 5.0, 0));
    assert_eq!((op, data), (0x82, vec![1, 0]));
    let mu = 1.0 - (0.02f32.sqrt() - 0.05) / 0.25;
    // Robot at (1.9, 2.0) heading +x, half base 0.1: the antennas (1.9, 2.1), (1.9, 1.9) see
    // the source ahead, one quantum (not 5) at d = √0.02.
    let (l, r) = eventually(Duration::from_secs(10), "the deposit in a PIR", || {
        let (_, op, data) = c.ask(1, 0x01, &pir(1.9, 2.0, 0.0, 0.1, 0));
        assert_eq!(op, 0x81);
        let (l, r) = (f32_at(&data, 0), f32_at(&data, 4));
        (l > 0.0).then_some((l, r))
    });
    assert!(
        (l - mu).abs() < 1e-4 && (r - mu).abs() < 1e-4,
        "{l} {r}, want {mu}"
    );
    // From (2.1, 2.0): heading +x the source is behind the antennas, heading −x it is ahead.
    let read = |theta: f32| {
        let (_, op, data) = c.ask(1, 0x01, &pir(2.1, 2.0, theta, 0.1, 0));
        assert_eq!(op, 0x81);
        (f32_at(&data, 0), f32_at(&data, 4))
    };
    assert_eq!(read(0.0), (0.0, 0.0), "a source behind is invisible");
    let (l, r) = read(std::f32::consts::PI);
    assert!((l - mu).abs() < 1e-4 && (r - mu).abs() < 1e-4, "{l} {r}");
    // Nearest node (80, 40) lies on the far border, which is not stored: status 3, not applied.
    assert_eq!(c.ask(1, 0x02, &deposit(2, 3.99, 2.0, 1.0, 0)).2, vec![2, 3]);

    gateway.interrupt();
    let out = gateway.wait_exit(Duration::from_secs(30));
    assert!(out.status.success(), "gateway: {}", stderr(&out));
    field_proc.interrupt();
    let out = field_proc.wait_exit(Duration::from_secs(30));
    assert_eq!(json(&out)["deposits_applied"], 1, "{}", stderr(&out));
}

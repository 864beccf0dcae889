//! A mirror over TLS with a user and password, across network namespaces (as netns.rs): the
//! test makes a CA, a certificate for the bridge's address and a second, untrusted CA with the
//! `openssl` CLI; the mirror with the right CA and password becomes bit-identical, mirrors with
//! a wrong password, no credentials or the untrusted CA exit non-zero saying what failed.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use pheromone_bridge::zenoh::Wait;

use super::netns::{Link, ADDR_A};
use super::{assert_identical, deposit, origin_field, CleanDomains, Hosts, MIRROR, ORIGIN};
use crate::harness::*;

/// A private temporary directory with the test's keys and certificates, removed when dropped.
struct Pki {
    dir: PathBuf,
}

impl Drop for Pki {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

fn openssl(dir: &Path, args: &[&str]) -> Result<(), String> {
    let o = Command::new("openssl")
        .args(args)
        .current_dir(dir)
        .output()
        .map_err(|e| format!("openssl {}: {e}", args.join(" ")))?;
    if o.status.success() {
        Ok(())
    } else {
        Err(format!(
            "openssl {}: {}",
            args.join(" "),
            String::from_utf8_lossy(&o.stderr).trim()
        ))
    }
}

/// A self-signed CA `NAME.pem` / `NAME.key` (EC P-256, one day).
fn make_ca(dir: &Path, name: &str) -> Result<(), String> {
    let (pem, key, subj) = (
        format!("{name}.pem"),
        format!("{name}.key"),
        format!("/CN={name}"),
    );
    openssl(
        dir,
        &[
            "req",
            "-x509",
            "-newkey",
            "ec",
            "-pkeyopt",
            "ec_paramgen_curve:P-256",
            "-nodes",
            "-keyout",
            &key,
            "-out",
            &pem,
            "-days",
            "1",
            "-subj",
            &subj,
            "-addext",
            "basicConstraints=critical,CA:TRUE",
            "-addext",
            "keyUsage=critical,keyCertSign,cRLSign",
        ],
    )
}

impl Pki {
    /// `ca.pem`, `bridge.pem`/`bridge.key` (signed by it, valid for `ip`), `other-ca.pem`,
    /// the bridge's `users.txt` (robot:s3cret) and the password files `right.txt`, `wrong.txt`.
    fn make(ip: &str) -> Result<Self, String> {
        let dir = std::env::temp_dir().join(unique("mirtls"));
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        let pki = Self { dir };
        let d = pki.dir.as_path();
        make_ca(d, "ca")?;
        make_ca(d, "other-ca")?;
        openssl(
            d,
            &[
                "req",
                "-newkey",
                "ec",
                "-pkeyopt",
                "ec_paramgen_curve:P-256",
                "-nodes",
                "-keyout",
                "bridge.key",
                "-out",
                "bridge.csr",
                "-subj",
                "/CN=bridge",
            ],
        )?;
        let ext = format!(
            "subjectAltName=IP:{ip}\nbasicConstraints=CA:FALSE\nkeyUsage=digitalSignature\n\
             extendedKeyUsage=serverAuth,clientAuth\n"
        );
        std::fs::write(d.join("bridge.ext"), ext).map_err(|e| e.to_string())?;
        openssl(
            d,
            &[
                "x509",
                "-req",
                "-in",
                "bridge.csr",
                "-CA",
                "ca.pem",
                "-CAkey",
                "ca.key",
                "-CAcreateserial",
                "-out",
                "bridge.pem",
                "-days",
                "1",
                "-extfile",
                "bridge.ext",
            ],
        )?;
        for (f, text) in [
            ("users.txt", "robot:s3cret\n"),
            ("right.txt", "s3cret\n"),
            ("wrong.txt", "guess\n"),
        ] {
            std::fs::write(d.join(f), text).map_err(|e| e.to_string())?;
        }
        Ok(pki)
    }

    fn path(&self, f: &str) -> String {
        self.dir.join(f).to_string_lossy().into_owned()
    }
}

/// The namespaces and the certificates, or `None` (said on stderr) where either cannot be made.
fn setup(tag: &str) -> Option<(Link, Pki)> {
    let link = match Link::make(tag) {
        Ok(l) => l,
        Err(why) => {
            eprintln!("skipped: network namespaces cannot be made here ({why})");
            return None;
        }
    };
    match Pki::make(ADDR_A) {
        Ok(p) => Some((link, p)),
        Err(why) => {
            eprintln!("skipped: the openssl CLI cannot make the test's certificates ({why})");
            None
        }
    }
}

/// The bridge of field `name` in namespace A on `tls/ADDR_A:7447`, requiring the test's user.
fn tls_bridge(link: &Link, pki: &Pki, name: &str, endpoint: &str) -> Proc {
    let mut args = super::bridge_args(name, endpoint).to_vec();
    // A checksum with every frame: the test stops the mirror after a few dozen frames, and a
    // mirror that applies them in bursts under load records its own sum only at a burst's end
    // (one run of CI matched none of every 5th).
    let every = args.iter().position(|a| *a == "--checksum-every").unwrap() + 1;
    args[every] = "1";
    let (cert, key, users) = (
        pki.path("bridge.pem"),
        pki.path("bridge.key"),
        pki.path("users.txt"),
    );
    args.extend([
        "--tls-cert",
        &cert,
        "--tls-key",
        &key,
        "--users-file",
        &users,
    ]);
    link.spawn_in(&link.a, "bridge", &args)
}

/// A mirror of `name` in namespace B connecting to `endpoint` with the extra `security` flags.
fn tls_mirror(link: &Link, name: &str, endpoint: &str, security: &[&str]) -> Proc {
    let origin = format!("zenoh:{endpoint}");
    let mut args = vec![
        "field",
        "--iox-domain",
        MIRROR,
        "--name",
        name,
        "--mirror",
        &origin,
        "--stale-after-s",
        "0.5",
        "--duration",
        "120",
        "--json",
    ];
    args.extend_from_slice(security);
    link.spawn_in(&link.b, "mirror", &args)
}

#[test]
fn a_mirror_over_tls_with_a_password_is_bit_identical_to_its_origin() {
    let _clean = CleanDomains;
    let tag = format!("pt{}", std::process::id() % 100_000);
    let Some((link, pki)) = setup(&tag) else {
        return;
    };
    let name = unique("mirtls");
    let _field = origin_field(&name);
    let endpoint = format!("tls/{ADDR_A}:7447");
    let _bridge = tls_bridge(&link, &pki, &name, &endpoint);
    let (ca, pw) = (pki.path("ca.pem"), pki.path("right.txt"));
    let started = Instant::now();
    let mirror = tls_mirror(
        &link,
        &name,
        &endpoint,
        &[
            "--tls-root-ca",
            &ca,
            "--user",
            "robot",
            "--password-file",
            &pw,
        ],
    );
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(10, |_| true));
    let first = started.elapsed();
    deposit(ORIGIN, &name, "2.5", "2.5");
    assert_identical(&hosts.common(10, |f| super::value_at(f, 2.5, 2.5) > 0.1));
    let node = pheromone_field::shm::create_node_in(&unique("mirtls-watch"), Some(MIRROR)).unwrap();
    super::netns::until_mirror(&node, &name, false);
    println!(
        "TLS + password mirror: 10 bit-identical frames {:.2} s after it started",
        first.as_secs_f64()
    );
    let j = super::mirror_exit(mirror);
    assert_eq!(j["mirror"]["checksum_mismatches"], 0, "{j}");
    assert!(
        j["mirror"]["checksums_matched"].as_u64().unwrap() >= 1,
        "{j}"
    );
}

#[test]
fn mirrors_with_a_wrong_password_no_credentials_or_an_untrusted_ca_are_refused_saying_why() {
    let _clean = CleanDomains;
    let tag = format!("pr{}", std::process::id() % 100_000);
    let Some((link, pki)) = setup(&tag) else {
        return;
    };
    let name = unique("mirtlsno");
    let _field = origin_field(&name);
    let endpoint = format!("tls/{ADDR_A}:7447");
    let _bridge = tls_bridge(&link, &pki, &name, &endpoint);
    let (ca, other, right, wrong) = (
        pki.path("ca.pem"),
        pki.path("other-ca.pem"),
        pki.path("right.txt"),
        pki.path("wrong.txt"),
    );
    let cases: [(&str, Vec<&str>, &str); 3] = [
        (
            "wrong password",
            vec![
                "--tls-root-ca",
                &ca,
                "--user",
                "robot",
                "--password-file",
                &wrong,
            ],
            "refused this side's credentials",
        ),
        (
            "no credentials",
            vec!["--tls-root-ca", &ca],
            "refused this side's credentials",
        ),
        (
            "untrusted CA",
            vec![
                "--tls-root-ca",
                &other,
                "--user",
                "robot",
                "--password-file",
                &right,
            ],
            "not signed by the CA given",
        ),
    ];
    // One after the other: they would share the mirror's services (same field, same domain).
    for (what, flags, says) in &cases {
        let started = Instant::now();
        let out = tls_mirror(&link, &name, &endpoint, flags).wait_exit(Duration::from_secs(30));
        let err = stderr(&out);
        assert!(!out.status.success(), "{what}: the mirror exited 0: {err}");
        assert!(
            err.contains("refused the connection") && err.contains(says),
            "{what}: the mirror's error does not say '{says}': {err}"
        );
        println!(
            "{what}: refused after {:.2} s: {}",
            started.elapsed().as_secs_f64(),
            err.lines().last().unwrap_or_default()
        );
    }
}

/// Each security file is checked while the command line is parsed: a missing one exits with
/// status 2 naming the flag and the path; the flags are a mirror's, not a plain field's; an
/// empty password file is refused before the session opens.
#[test]
fn security_files_are_checked_before_anything_starts() {
    let missing = std::env::temp_dir().join(unique("no-such-cert"));
    let missing = missing.to_str().unwrap();
    for args in [
        vec![
            "bridge",
            "--field",
            "x",
            "--tls-cert",
            missing,
            "--tls-key",
            missing,
        ],
        vec!["bridge", "--field", "x", "--zenoh-config", missing],
        vec![
            "ros2",
            "--field",
            "x",
            "--connect",
            "tcp/127.0.0.1:9",
            "--users-file",
            missing,
        ],
        vec![
            "field",
            "--name",
            "x",
            "--mirror",
            "zenoh:tls/127.0.0.1:9",
            "--tls-root-ca",
            missing,
        ],
    ] {
        let out = run(&args);
        let err = stderr(&out);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {err}");
        assert!(
            err.contains(missing) && err.contains("--"),
            "{args:?}: {err}"
        );
    }
    let dir = std::env::temp_dir().join(unique("mirtls-empty"));
    std::fs::create_dir_all(&dir).unwrap();
    let empty = dir.join("empty.txt");
    std::fs::write(&empty, "").unwrap();
    let empty = empty.to_str().unwrap();
    let plain = run(&[
        "field",
        "--name",
        "x",
        "--tls-root-ca",
        empty,
        "--duration",
        "1",
    ]);
    let err = stderr(&plain);
    assert_eq!(plain.status.code(), Some(2), "{err}");
    assert!(err.contains("--mirror"), "{err}");
    let name = unique("mirtls-pw");
    let origin = "zenoh:tcp/127.0.0.1:9";
    let args = [
        "field",
        "--iox-domain",
        MIRROR,
        "--name",
        &name,
        "--mirror",
        origin,
        "--user",
        "robot",
        "--password-file",
        empty,
        "--duration",
        "5",
    ];
    let out = run(&args);
    let err = stderr(&out);
    std::fs::remove_dir_all(&dir).unwrap();
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("--password-file") && err.contains("empty"),
        "{err}"
    );
}

/// Access control from `--zenoh-config` (Zenoh's own `access_control` section): the bridge
/// denies puts on `pheromone/*/deposit` from the user `viewer`. That mirror still follows its
/// origin bit-identically, but its host's deposit never reaches the field, while the origin's
/// own deposits still reach the mirror.
#[test]
fn an_access_control_rule_keeps_a_viewer_mirror_from_depositing() {
    let _clean = CleanDomains;
    let dir = Pki {
        dir: std::env::temp_dir().join(unique("miracl")),
    };
    std::fs::create_dir_all(&dir.dir).unwrap();
    let acl = r#"{
  access_control: {
    enabled: true,
    default_permission: "allow",
    rules: [{ id: "no-deposits", messages: ["put"], flows: ["ingress", "egress"],
              permission: "deny", key_exprs: ["pheromone/*/deposit"] }],
    subjects: [{ id: "viewers", usernames: ["viewer"] }],
    policies: [{ rules: ["no-deposits"], subjects: ["viewers"] }],
  },
}
"#;
    for (f, text) in [
        ("acl.json5", acl),
        ("users.txt", "viewer:look\nrobot:s3cret\n"),
        ("viewer.txt", "look\n"),
    ] {
        std::fs::write(dir.dir.join(f), text).unwrap();
    }
    let (acl, users, pw) = (
        dir.path("acl.json5"),
        dir.path("users.txt"),
        dir.path("viewer.txt"),
    );
    let name = unique("miracl");
    let _field = origin_field(&name);
    let extra = [
        "--users-file",
        users.as_str(),
        "--zenoh-config",
        acl.as_str(),
    ];
    let b = super::bridge_with(&name, "tcp/127.0.0.1:0", &extra);
    let viewer = ["--user", "viewer", "--password-file", pw.as_str()];
    let m = super::mirror_with(&name, &b.endpoint, &viewer);
    let mut hosts = Hosts::attach(&name);
    assert_identical(&hosts.common(5, |_| true));
    // Taken by the mirror and put on Zenoh; the bridge's access control drops it.
    deposit(MIRROR, &name, "2.0", "3.0");
    deposit(ORIGIN, &name, "4.5", "1.5");
    assert_identical(&hosts.common(20, |f| super::value_at(f, 4.5, 1.5) > 0.1));
    // The mirror sends an unanswered batch again after `RESEND_AFTER`: follow the origin (50 Hz)
    // for three of those before asking whether it did (20 frames, 0.4 s, were not always one).
    let frames_per_resend = (pheromone_bridge::RESEND_AFTER.as_secs_f64() * 50.0).ceil() as usize;
    assert_identical(&hosts.common(3 * frames_per_resend, |_| true));
    let o = hosts.origin.frame().unwrap();
    assert_eq!(
        super::value_at(&o, 2.0, 3.0),
        0.0,
        "the viewer's deposit was applied"
    );
    let s = super::mirror_summary(m);
    assert_eq!(s["deposits_forwarded"], 1, "{s}");
    // Never answered, so still kept and said: not dropped in silence.
    assert_eq!(s["deposits_confirmed"], 0, "{s}");
    assert_eq!(s["deposits_unconfirmed"], 1, "{s}");
    assert!(s["deposit_batches_resent"].as_u64().unwrap() >= 1, "{s}");
    let j = b.exit_json();
    assert_eq!(j["bridge"]["deposits_forwarded"], 0, "{j}");
}

/// `pheromone ros2` with the same flags: listening on `tls/127.0.0.1:PORT` with a certificate
/// and a users file, it serves a Zenoh peer that presents the CA, user and password (a sample
/// of the field's topics arrives), and refuses one with a wrong password.
#[test]
fn the_ros2_node_listens_over_tls_and_asks_for_credentials() {
    let _clean = CleanDomains;
    let pki = match Pki::make("127.0.0.1") {
        Ok(p) => p,
        Err(why) => {
            eprintln!("skipped: the openssl CLI cannot make the test's certificates ({why})");
            return;
        }
    };
    let name = unique("ros2tls");
    let _field = origin_field(&name);
    let (cert, key, users) = (
        pki.path("bridge.pem"),
        pki.path("bridge.key"),
        pki.path("users.txt"),
    );
    let args = [
        "ros2",
        "--iox-domain",
        ORIGIN,
        "--field",
        &name,
        "--listen",
        "tls/127.0.0.1:0",
        "--print-address",
        "--tls-cert",
        &cert,
        "--tls-key",
        &key,
        "--users-file",
        &users,
        "--duration",
        "60",
    ];
    let mut sup = pheromone_supervisor::Supervisor::new(&bin());
    let id = sup
        .spawn(pheromone_supervisor::ChildSpec::new(
            "ros2",
            None,
            args.iter().map(|a| a.to_string()).collect(),
        ))
        .expect("spawn pheromone ros2");
    let endpoint = sup
        .next_line(id, Duration::from_secs(30))
        .expect("the node runs")
        .expect("the node prints its endpoint within 30 s")
        .trim()
        .to_string();
    assert!(endpoint.starts_with("tls/127.0.0.1:"), "{endpoint}");
    let security = |password: &str| pheromone_bridge::Security {
        tls_root_ca: Some(pki.dir.join("ca.pem")),
        user: Some("robot".into()),
        password_file: Some(pki.dir.join(password)),
        ..Default::default()
    };
    let wrong = pheromone_bridge::try_connect(&security("wrong.txt"), &endpoint).unwrap_err();
    assert!(
        pheromone_bridge::refusal(&wrong).is_some_and(|w| w.contains("credentials")),
        "{wrong}"
    );
    let config =
        pheromone_bridge::session_config_with(&security("right.txt"), "peer", &[], &[endpoint])
            .unwrap();
    let session = pheromone_bridge::zenoh::open(config).wait().unwrap();
    let sub = session.declare_subscriber("**").wait().unwrap();
    let sample = sub.recv_timeout(Duration::from_secs(20)).unwrap();
    assert!(
        sample.is_some(),
        "no sample from the ROS 2 node over TLS in 20 s"
    );
    let _ = session.close().wait();
    sup.signal(id, nix::sys::signal::Signal::SIGINT);
    assert!(
        sup.wait_exit(id, Duration::from_secs(20)),
        "the ROS 2 node exits"
    );
}

/// `sim --ros2` passes the security flags on to its `ros2` child: a `--zenoh-config` file that
/// exists (so `sim` accepts it) but is no JSON5 fails the child's session, and the run ends with
/// the child's error naming the flag and the file's absolute path, given relative to `sim`'s
/// working directory. Without `--ros2` the flags are refused (exit 2).
#[test]
fn sim_passes_the_security_flags_to_its_ros2_child() {
    let dir = std::env::temp_dir().join(unique("simros2"));
    std::fs::create_dir_all(&dir).unwrap();
    let _rm = RemoveDir(dir.clone());
    std::fs::write(dir.join("bad.json5"), "{ this is not json5").unwrap();
    let sim = |extra: &[&str]| {
        pheromone_testkit::Cli::new(&bin())
            .args(["sim", "trail", "--no-out", "--zenoh-config", "bad.json5"])
            .args(extra)
            .current_dir(&dir)
            .output()
    };
    let out = sim(&["--ros2", "tcp/127.0.0.1:9"]);
    let said = stderr(&out);
    let abs = dir.join("bad.json5");
    assert_eq!(out.status.code(), Some(1), "{said}");
    assert!(
        said.contains("ros2 failed") && said.contains(&format!("--zenoh-config {}", abs.display())),
        "{said}"
    );
    let out = sim(&[]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert!(stderr(&out).contains("--zenoh-config"), "{}", stderr(&out));
}

/// Removes a test's directory when dropped.
struct RemoveDir(PathBuf);

impl Drop for RemoveDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

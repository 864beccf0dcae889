//! Issue 54 item 4: a second local user (made with `useradd` here, removed after) runs
//! `pheromone` beside root's field and cannot disturb root's nodes; a management segment
//! another user planted in a domain is refused, naming it. Item 5: a loopback gateway and a
//! loopback bridge serve only their own user. Needs root (CI runs as root): as another user it
//! says so and checks nothing.

use std::os::unix::fs::{MetadataExt, PermissionsExt};
use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::time::Duration;

use super::Scratch;
use crate::harness::*;

/// A system user of this test, with no home and no shell; deleted, with every iceoryx2 entry of
/// theirs, when dropped.
struct TestUser {
    name: String,
    uid: u32,
    gid: u32,
}

impl TestUser {
    fn add() -> Self {
        // One user per test, even for tests of one process running at once.
        static NEXT: std::sync::atomic::AtomicU32 = std::sync::atomic::AtomicU32::new(0);
        let n = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        let name = format!("phmu{}x{n}", std::process::id() % 100_000);
        let o = Command::new("useradd")
            .args([
                "--system",
                "--no-create-home",
                "--shell",
                "/usr/sbin/nologin",
            ])
            .arg(&name)
            .output()
            .expect("useradd");
        assert!(o.status.success(), "useradd {name}: {}", stderr(&o));
        let id = |flag: &str| -> u32 {
            let o = Command::new("id").args([flag, &name]).output().unwrap();
            stdout(&o).trim().parse().unwrap()
        };
        let (uid, gid) = (id("-u"), id("-g"));
        Self { name, uid, gid }
    }

    /// `program ARGS` as this user (`setpriv`: their uid and gid, no supplementary group of
    /// root's), with /tmp as TMPDIR and nothing else of root's environment.
    fn command(&self, program: &std::path::Path) -> Command {
        let mut c = Command::new("setpriv");
        c.env_clear()
            .env("PATH", "/usr/bin:/bin")
            .env("TMPDIR", "/tmp")
            .arg(format!("--reuid={}", self.uid))
            .arg(format!("--regid={}", self.gid))
            .arg("--clear-groups")
            .arg("--")
            .arg(program);
        c
    }

    fn output(&self, program: &std::path::Path, args: &[&str]) -> Output {
        self.command(program).args(args).output().unwrap()
    }
}

impl Drop for TestUser {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(format!("/tmp/iceoryx2-u{}", self.uid));
        // Their state under TMPDIR (the owner key of their Zenoh sessions).
        let _ = std::fs::remove_dir_all(format!("/tmp/pheromone-{}", self.uid));
        let prefix = format!("iox2u{}_", self.uid);
        for entry in shm_entries() {
            if entry.starts_with(&prefix) {
                let _ = std::fs::remove_file(PathBuf::from("/dev/shm").join(entry));
            }
        }
        let _ = Command::new("userdel").arg(&self.name).output();
    }
}

/// A child killed and reaped when dropped.
struct Killed(Child);

impl Drop for Killed {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Root's management segments of iceoryx2's default domain (`iox2_…global_mgmt`).
fn root_management_segments() -> Vec<PathBuf> {
    shm_entries()
        .into_iter()
        .filter(|n| n.starts_with("iox2_") && n.ends_with(".global_mgmt"))
        .map(|n| PathBuf::from("/dev/shm").join(n))
        .collect()
}

#[test]
fn a_second_user_runs_beside_root_and_cannot_write_to_roots_domain() {
    if !nix::unistd::geteuid().is_root() {
        eprintln!("needs root (useradd); not checked as another user");
        return;
    }
    let user = TestUser::add();
    // The binary, where the other user can run it (the build directory may be private).
    let dir = Scratch::new("mu-bin");
    std::fs::set_permissions(&dir.0, std::fs::Permissions::from_mode(0o755)).unwrap();
    let theirs = dir.join("pheromone");
    std::fs::copy(bin(), &theirs).unwrap();
    std::fs::set_permissions(&theirs, std::fs::Permissions::from_mode(0o755)).unwrap();

    let ours = unique("mu-root");
    let _field = Proc::spawn(
        &Cmd::field(&ours)
            .grid(16, 16)
            .tick_hz(20)
            .duration(120)
            .argv(),
    );
    let o = run(&Cmd::probe(&ours).timeout(30).json().argv());
    assert!(o.status.success(), "root's probe: {}", stderr(&o));

    // Root's management segment is root's alone: the other user cannot write a byte into it.
    let segments = root_management_segments();
    assert!(
        !segments.is_empty(),
        "no iox2_ management segment in /dev/shm"
    );
    for s in &segments {
        let mode = std::fs::metadata(s).unwrap().mode() & 0o777;
        assert_eq!(mode, 0o600, "{} is mode {mode:o}", s.display());
        let dd = user.output(
            std::path::Path::new("/bin/dd"),
            &[
                "if=/dev/zero",
                &format!("of={}", s.display()),
                "bs=16",
                "count=1",
                "conv=notrunc",
            ],
        );
        assert!(
            !dd.status.success(),
            "the other user wrote into {}",
            s.display()
        );
    }

    // The other user runs a field of their own, in their own domain, and reads it.
    let theirs_name = unique("mu-user");
    let field = user
        .command(&theirs)
        .args(
            Cmd::field(&theirs_name)
                .grid(16, 16)
                .tick_hz(20)
                .duration(120)
                .argv(),
        )
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut field = Killed(field);
    let probe = Cmd::probe(&theirs_name).timeout(30).json();
    let o = user.output(&theirs, &probe.argv());
    assert!(o.status.success(), "the other user's probe: {}", stderr(&o));
    let root_dir = std::fs::symlink_metadata(format!("/tmp/iceoryx2-u{}", user.uid)).unwrap();
    assert!(root_dir.is_dir() && root_dir.uid() == user.uid);
    assert_eq!(root_dir.mode() & 0o777, 0o700);
    // Two users share no iceoryx2 resource: root's field is not theirs to see.
    let o = user.output(
        &theirs,
        &["probe", "--field", &ours, "--timeout", "1", "--json"],
    );
    assert!(!o.status.success(), "the other user saw root's field");

    // Root's field still serves root.
    let o = run(&Cmd::probe(&ours).timeout(30).json().argv());
    assert!(o.status.success(), "root's probe after: {}", stderr(&o));
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(field.0.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = eventually(Duration::from_secs(20), "their field to stop", || {
        field.0.try_wait().unwrap()
    });
    // A field stopped by SIGTERM exits 143 (128 + 15), as every long-running command.
    assert_eq!(status.code(), Some(143), "their field: {status}");
}

#[test]
fn a_management_segment_planted_by_another_user_is_refused_naming_it() {
    if !nix::unistd::geteuid().is_root() {
        eprintln!("needs root (useradd); not checked as another user");
        return;
    }
    let user = TestUser::add();
    let domain = format!("squat{}", std::process::id() % 100_000);
    let planted = PathBuf::from(format!(
        "/dev/shm/{domain}_iox2_planted_node.0_10_0.global_mgmt"
    ));
    let touch = user.output(
        std::path::Path::new("/usr/bin/touch"),
        &[&planted.display().to_string()],
    );
    assert!(
        touch.status.success(),
        "touch as the user: {}",
        stderr(&touch)
    );
    let o = run(&[
        "--iox-domain",
        &domain,
        "probe",
        "--field",
        "x",
        "--timeout",
        "1",
    ]);
    let _ = std::fs::remove_file(&planted);
    let err = stderr(&o);
    assert!(!o.status.success(), "{err}");
    assert!(
        err.contains(&planted.display().to_string())
            && err.contains(&format!("belongs to uid {}", user.uid)),
        "{err}"
    );
}

/// One PING from a loopback socket of `user` (Python, as that user; `None`: as this process's
/// user) to the gateway at `port`: the reply decoded, `None` if none came within 2 s.
fn ping_as(user: Option<&TestUser>, port: u16) -> Option<pheromone_gateway_codec::Message> {
    let mut buf = [0u8; pheromone_gateway_codec::MAX_ENCODED_BYTES];
    let n = pheromone_gateway_codec::encode(&pheromone_gateway_codec::Message::Ping, 3, &mut buf)
        .unwrap();
    let hex: String = buf[..n].iter().map(|b| format!("{b:02x}")).collect();
    let script = "import socket, sys\n\
                  s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)\n\
                  s.bind(('127.0.0.1', 0)); s.settimeout(2)\n\
                  s.sendto(bytes.fromhex(sys.argv[1]), ('127.0.0.1', int(sys.argv[2])))\n\
                  try: print(s.recv(512).hex())\n\
                  except OSError: print('none')\n";
    let python = std::path::Path::new("/usr/bin/python3");
    let args = ["-c", script, &hex, &port.to_string()];
    let o = match user {
        Some(user) => user.output(python, &args),
        None => Command::new(python).args(args).output().unwrap(),
    };
    assert!(o.status.success(), "python3 as the user: {}", stderr(&o));
    let reply = stdout(&o).trim().to_string();
    if reply == "none" {
        return None;
    }
    let bytes: Vec<u8> = (0..reply.len() / 2)
        .map(|i| u8::from_str_radix(&reply[2 * i..2 * i + 2], 16).unwrap())
        .collect();
    Some(pheromone_gateway_codec::decode(&bytes)?.ok()?.message)
}

#[test]
fn a_loopback_gateway_serves_its_own_user_and_refuses_another_users_socket() {
    if !nix::unistd::geteuid().is_root() {
        eprintln!("needs root (useradd); not checked as another user");
        return;
    }
    use pheromone_gateway_codec::{ErrorReason, Message};
    let user = TestUser::add();
    let field = unique("mu-gw");
    let _field = Proc::spawn(
        &Cmd::field(&field)
            .grid(16, 16)
            .tick_hz(20)
            .duration(120)
            .argv(),
    );
    let gateway = |extra: &[&str]| -> (Proc, u16) {
        let port = std::net::UdpSocket::bind("127.0.0.1:0")
            .unwrap()
            .local_addr()
            .unwrap()
            .port();
        let udp = format!("127.0.0.1:{port}");
        let mut args = vec!["gateway", "--field", &field, "--udp", &udp];
        args.extend_from_slice(extra);
        (Proc::spawn(&args), port)
    };
    // Root's own ping is served (once the gateway is up)...
    let (_owner_only, port) = gateway(&[]);
    let served = eventually(
        Duration::from_secs(30),
        "the gateway to answer root",
        || ping_as(None, port),
    );
    assert!(!matches!(served, Message::Error(_)), "{served:?}");
    // ...the other user's, from a socket of theirs, is refused with reason 6.
    let refused = ping_as(Some(&user), port).expect("a reply to the other user");
    assert!(
        matches!(refused, Message::Error(ErrorReason::ClientNotAllowed)),
        "{refused:?}"
    );
    // A gateway told to serve that user does.
    let uids = format!("0,{}", user.uid);
    let (_both, port) = gateway(&["--local-users", &uids]);
    let served = eventually(
        Duration::from_secs(30),
        "the gateway to answer the user",
        || ping_as(Some(&user), port),
    );
    assert!(!matches!(served, Message::Error(_)), "{served:?}");
}

/// Issue 54 item 5: a bridge on loopback without `--users-file` admits only its own user's
/// sessions (the owner key, `pheromone_bridge::owner`). Root's mirror goes live; another local
/// user's mirror is refused for good, the refusal naming the owner key, and never goes live.
#[cfg(feature = "zenoh")]
#[test]
fn a_loopback_bridge_admits_its_own_users_mirror_and_refuses_another_users() {
    use pheromone_supervisor::{ChildSpec, Supervisor};
    if !nix::unistd::geteuid().is_root() {
        eprintln!("needs root (useradd); not checked as another user");
        return;
    }
    let user = TestUser::add();
    let field = unique("mu-br");
    let _field = Proc::spawn(
        &Cmd::field(&field)
            .grid(16, 16)
            .tick_hz(20)
            .duration(120)
            .argv(),
    );
    let mut sup = Supervisor::new(&bin());
    let args = [
        "bridge",
        "--field",
        &field,
        "--listen",
        "tcp/127.0.0.1:0",
        "--print-address",
        "--duration",
        "120",
    ];
    let id = sup
        .spawn(ChildSpec::new(
            "bridge",
            None,
            args.iter().map(|a| a.to_string()).collect(),
        ))
        .expect("spawn the bridge");
    let endpoint = sup
        .next_line(id, Duration::from_secs(30))
        .expect("the bridge runs")
        .expect("the bridge prints its endpoint within 30 s")
        .trim()
        .to_string();
    let mirror_args = |domain: Option<&'static str>| {
        let mut v = vec!["field".to_string(), "--name".into(), field.clone()];
        if let Some(d) = domain {
            v.extend(["--iox-domain".into(), d.into()]);
        }
        v.extend(["--mirror".into(), format!("zenoh:{endpoint}")]);
        v.extend(["--duration".into(), "10".into(), "--json".into()]);
        v
    };
    // Root's mirror (another iceoryx2 domain: the field's name is taken in root's) goes live.
    let own = Command::new(bin())
        .args(mirror_args(Some("mutestB")))
        .output()
        .unwrap();
    let own_err = stderr(&own);
    assert!(own.status.success(), "{own_err}");
    assert!(own_err.contains("live at frame"), "{own_err}");
    // The other user's mirror (their own domain) is refused, naming why.
    let args = mirror_args(None);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let theirs = user.output(&bin(), &args);
    let err = stderr(&theirs);
    assert!(!theirs.status.success(), "{err}");
    assert!(
        err.contains("refused the connection") && err.contains("owner key"),
        "{err}"
    );
    assert!(!err.contains("live at frame"), "{err}");
}

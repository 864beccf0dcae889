//! A hostile or careless local user (issue 54): output paths naming a FIFO, a symbolic link or a directory, write errors and closed pipes, bad names.
//!
//! Every path is in a directory of the test's own (`scratch`); no real device node is touched.

use std::os::unix::fs::FileTypeExt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::harness::*;

mod users;

/// A fresh directory of this test, removed when dropped.
pub struct Scratch(pub PathBuf);

impl Scratch {
    pub fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(unique(tag));
        std::fs::create_dir_all(&dir).unwrap();
        Self(dir)
    }

    pub fn join(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn mkfifo(path: &Path) {
    nix::unistd::mkfifo(path, nix::sys::stat::Mode::from_bits_truncate(0o600)).unwrap();
}

fn is_fifo(path: &Path) -> bool {
    std::fs::symlink_metadata(path)
        .map(|m| m.file_type().is_fifo())
        .unwrap_or(false)
}

/// A victim file, a symbolic link to it, and a FIFO, in `dir`.
fn traps(dir: &Scratch) -> (PathBuf, PathBuf, PathBuf) {
    let victim = dir.join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    let link = dir.join("link");
    std::os::unix::fs::symlink(&victim, &link).unwrap();
    let fifo = dir.join("fifo");
    mkfifo(&fifo);
    (victim, link, fifo)
}

#[test]
fn every_output_file_flag_refuses_a_fifo_and_a_symlink_with_exit_2_before_anything_starts() {
    let dir = Scratch::new("out-traps");
    let (victim, link, fifo) = traps(&dir);
    let field = unique("never");
    let mut failures = Vec::new();
    for (path, kind) in [(&link, "symbolic link"), (&fifo, "FIFO")] {
        let p = path.display().to_string();
        let cases: [(Vec<&str>, &str); 4] = [
            (
                vec![
                    "field",
                    "--name",
                    &field,
                    "--ticks",
                    "1",
                    "--checkpoint",
                    &p,
                ],
                "--checkpoint",
            ),
            (vec!["export", "--field", &field, "--out", &p], "--out"),
            (
                vec![
                    "sim",
                    "trail",
                    "--single-process",
                    "--no-out",
                    "--record",
                    &p,
                ],
                "--record",
            ),
            (vec!["record", "--field", &field, "--mcap", &p], "--mcap"),
        ];
        for (argv, flag) in cases {
            let o = run(&argv);
            let e = stderr(&o);
            if o.status.code() != Some(2) || !e.contains(flag) || !e.contains(kind) {
                failures.push(format!("{}: {:?}: {e}", argv.join(" "), o.status));
            }
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
    assert!(std::fs::symlink_metadata(&link)
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(is_fifo(&fifo), "the FIFO was replaced");
}

#[test]
fn a_checkpoint_path_turned_into_a_fifo_while_the_field_runs_is_left_a_fifo() {
    let dir = Scratch::new("ckpt-fifo");
    let file = dir.join("field.ckpt");
    let field = Proc::spawn(
        &Cmd::field(&unique("ckfifo"))
            .grid(16, 16)
            .tick_hz(50)
            .duration(60)
            .opt("--checkpoint", file.display())
            .opt("--checkpoint-every", 0.2)
            .json()
            .argv(),
    );
    eventually(Duration::from_secs(20), "a first checkpoint", || {
        file.is_file().then_some(())
    });
    std::fs::remove_file(&file).unwrap();
    mkfifo(&file);
    field.interrupt();
    let o = field.wait_exit(Duration::from_secs(20));
    assert!(is_fifo(&file), "the FIFO was replaced: {}", stderr(&o));
    assert_eq!(o.status.code(), Some(1), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("FIFO") && stderr(&o).contains("field.ckpt"),
        "{}",
        stderr(&o)
    );
    // No temporary file is left beside it.
    let left: Vec<_> = std::fs::read_dir(&dir.0)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(left.len(), 1, "{left:?}");
}

#[test]
fn a_run_does_not_write_through_a_symlink_planted_in_its_output_directory() {
    let dir = Scratch::new("out-link");
    let victim = dir.join("victim");
    std::fs::write(&victim, b"precious").unwrap();
    let out = dir.join("out");
    std::fs::create_dir(&out).unwrap();
    std::os::unix::fs::symlink(&victim, out.join("metrics.json")).unwrap();
    let o = run(&Cmd::new("sim")
        .arg("trail")
        .arg("--single-process")
        .duration(1)
        .opt("--out", out.display())
        // A non-empty --out needs --force (issue 51); forced, the link is still not followed.
        .arg("--force")
        .argv());
    assert!(!o.status.success());
    let e = stderr(&o);
    assert!(
        e.contains("metrics.json") && e.contains("symbolic link"),
        "{e}"
    );
    assert_eq!(std::fs::read(&victim).unwrap(), b"precious");
}

/// Runs `pheromone ARGS` with stdout and stderr on pipes whose reading ends are closed at once
/// (as `… 2>&1 | head -0` would), until it exits.
fn run_into_closed_pipes(args: &[&str]) -> std::process::ExitStatus {
    use std::process::{Command, Stdio};
    let mut child = Command::new(bin())
        .args(args)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    drop(child.stderr.take());
    eventually(Duration::from_secs(300), "the run to end", || {
        child.try_wait().unwrap()
    })
}

#[test]
fn a_run_whose_stdout_and_stderr_readers_are_gone_still_writes_its_files_and_exits_0() {
    let dir = Scratch::new("epipe");
    let out = dir.join("D");
    let status = run_into_closed_pipes(&[
        "sim",
        "trail",
        "--json",
        "--out",
        &out.display().to_string(),
    ]);
    assert_eq!(status.code(), Some(0), "{status:?}");
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    assert!(metrics.contains("\"trail\""), "{metrics}");
}

#[test]
fn a_write_error_leaves_whole_files_or_none_and_no_temporary_file() {
    // A file size limit of 20 blocks (SIGXFSZ ignored, so a write past it fails with EFBIG, as
    // on a full disk): metrics.json fits, robot_0.csv does not.
    let dir = Scratch::new("efbig");
    let out = dir.join("D");
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg("trap '' XFSZ; ulimit -f 20; exec \"$0\" sim trail --single-process --out \"$1\"")
        .arg(bin())
        .arg(&out)
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(e.contains("robot_0.csv") && !e.contains("panicked"), "{e}");
    assert!(!out.join("robot_0.csv").exists(), "a truncated CSV is left");
    for entry in std::fs::read_dir(&out).unwrap() {
        let entry = entry.unwrap();
        let name = entry.file_name().to_string_lossy().into_owned();
        assert!(!name.ends_with(".tmp"), "{name} left behind");
        assert!(entry.metadata().unwrap().len() > 0, "{name} is empty");
    }
    let metrics = std::fs::read_to_string(out.join("metrics.json")).unwrap();
    serde_json::from_str::<serde_json::Value>(&metrics).expect("metrics.json is whole");
}

#[test]
fn an_mcap_recording_cut_by_a_write_error_is_left_as_partial_not_under_its_name() {
    // As above, 40 blocks: the recording's first frames pass the limit.
    let dir = Scratch::new("efbig-mcap");
    let rec = dir.join("run.mcap");
    let o = std::process::Command::new("sh")
        .arg("-c")
        .arg(
            "trap '' XFSZ; ulimit -f 40; \
             exec \"$0\" sim trail --single-process --record \"$1\" --no-out",
        )
        .arg(bin())
        .arg(&rec)
        .output()
        .unwrap();
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{e}");
    assert!(!e.contains("panicked"), "{e}");
    let partial = dir.join("run.mcap.partial");
    assert!(e.contains(&partial.display().to_string()), "{e}");
    assert!(
        !rec.exists(),
        "an incomplete recording is left under the name asked for"
    );
    assert!(std::fs::metadata(&partial).unwrap().len() > 0);
}

#[test]
fn an_out_dir_that_cannot_be_made_merge_without_peers_and_bad_field_names_exit_2_before_running() {
    // /proc refuses new directories, even root's: refused before the run, not after it.
    let o = run(&["sim", "trail", "--out", "/proc/nonexistent/x"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(
        e.contains("--out /proc/nonexistent/x") && !e.contains("done"),
        "{e}"
    );
    // --merge in a world of one robot would merge nothing.
    let o = run(&["sim", "trail", "--single-process", "--no-out", "--merge"]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("--merge") && e.contains("1 robot"), "{e}");
    // A name outside the naming rules is bad input wherever it is given.
    let dir = Scratch::new("names");
    let npy = dir.join("x.npy").display().to_string();
    let cases: [&[&str]; 4] = [
        &["probe", "--field", "a/b", "--x", "0", "--y", "0"],
        &[
            "deposit", "--field", "a b", "--x", "0", "--y", "0", "--amount", "1",
        ],
        &["export", "--field", "a/b", "--out", &npy],
        &["field", "--name", "a/b", "--ticks", "1"],
    ];
    for argv in cases {
        let o = run(argv);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{}: {e}", argv.join(" "));
        assert!(e.contains("invalid name"), "{}: {e}", argv.join(" "));
    }
}

#[test]
fn files_that_claim_too_much_or_nothing_are_refused_with_exit_2_naming_what() {
    let dir = Scratch::new("limits");
    let trail = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("examples/scenarios/trail.toml"),
    )
    .unwrap();
    let many: String = (1..300)
        .map(|i| format!("\n[[world.robots]]\nid = {i}\nstart = {{ x_m = 1.0, y_m = 2.5, theta_rad = 0.0 }}\n"))
        .collect();
    let cases = [
        (
            trail.replacen("name = \"trail\"", "name = \"tr\\u0000ail\"", 1),
            "control characters",
        ),
        (trail.replacen("t_s = 0.0", "t_s = -5.0", 1), "t_s"),
        (format!("{trail}{many}"), "300 robots"),
        (
            "name = \"nothing\"\nduration_s = 1.0\n[world]\ndt_s = 0.02\n".to_string(),
            "0 robots and no [[deposit]]",
        ),
    ];
    for (i, (text, says)) in cases.iter().enumerate() {
        assert_ne!(text, &trail, "case {i} changed nothing");
        let path = dir.join(&format!("s{i}.toml"));
        std::fs::write(&path, text).unwrap();
        let p = path.display().to_string();
        let o = run(&["sim", &p, "--single-process", "--no-out"]);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "case {i}: {e}");
        assert!(e.contains(says) && e.contains(&p), "case {i}: {e}");
    }
    // A device or a file over its limit is never read into memory: --config, --map, --restore.
    let big = dir.join("big.toml");
    std::fs::File::create(&big)
        .unwrap()
        .set_len((16 << 20) + 1)
        .unwrap();
    let big = big.display().to_string();
    let name = unique("lim");
    let cases: [(Vec<&str>, &str); 4] = [
        (
            vec![
                "field",
                "--name",
                &name,
                "--ticks",
                "1",
                "--config",
                "/dev/zero",
            ],
            "character device",
        ),
        (
            vec!["field", "--name", &name, "--ticks", "1", "--config", &big],
            "limit of 16777216 bytes",
        ),
        (
            vec![
                "field",
                "--name",
                &name,
                "--ticks",
                "1",
                "--restore",
                "/dev/zero",
            ],
            "character device",
        ),
        (
            vec![
                "sim",
                "trail",
                "--single-process",
                "--no-out",
                "--map",
                &big,
            ],
            "limit of 16777216 bytes",
        ),
    ];
    for (argv, says) in cases {
        let o = run(&argv);
        let e = stderr(&o);
        assert_eq!(o.status.code(), Some(2), "{}: {e}", argv.join(" "));
        assert!(e.contains(says), "{}: {e}", argv.join(" "));
    }
}

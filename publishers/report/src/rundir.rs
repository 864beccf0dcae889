//! Where one invocation writes its files, so two runs never share a directory: by default
//! `pheromone-out/<scenario>/<run-id>/` ([`RunDir::unique`]; the run id is the UTC time to the
//! second and a short random tag, the directory made exclusively so a run in the same second
//! takes another tag), with `pheromone-out/latest` and `pheromone-out/<scenario>/latest`
//! symbolic links to the newest; or a directory the user names ([`RunDir::named`]), refused when
//! it holds anything unless forced. Each gets `run.json` ([`RunInfo`]): the command line, the
//! version, the scenario, the seeds, the start and end times and the files the run wrote.

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use pheromone_field::outfile::{self, OutputError};

/// The directory under which run directories go by default, relative to the working directory.
pub const ROOT: &str = "pheromone-out";

/// A run directory could not be used.
#[derive(Debug, thiserror::Error)]
pub enum RunDirError {
    /// A named directory holds files and the run was not forced.
    #[error(
        "{}: the directory is not empty ({entries} entr{}, e.g. {example}): give another \
         directory, or --force to write into it anyway (files of an earlier run that this run \
         does not write are left there; run.json lists this run's)",
        path.display(), if *entries == 1 { "y" } else { "ies" }
    )]
    NotEmpty {
        /// The directory.
        path: PathBuf,
        /// How many entries it holds.
        entries: usize,
        /// One of them.
        example: String,
    },
    /// Creating or reading a directory failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The directory.
        path: PathBuf,
        /// What was being done.
        action: &'static str,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
    /// Writing `run.json` or a `latest` link failed.
    #[error(transparent)]
    Output(#[from] OutputError),
    /// `run.json` could not be serialized.
    #[error("run.json: {0}")]
    Json(#[from] serde_json::Error),
}

/// One invocation's output directory.
#[derive(Debug)]
pub struct RunDir {
    path: PathBuf,
    /// For a default directory: the root, the scenario's directory name and the run id, which
    /// the `latest` links name.
    latest: Option<(PathBuf, String, String)>,
}

/// What `run.json` says about a run.
#[derive(Debug, Clone, serde::Serialize)]
pub struct RunInfo {
    /// The whole command line, the program first.
    pub command: Vec<String>,
    /// The command line after the subcommand: the scenario and every flag as given.
    pub flags: Vec<String>,
    /// The program's version.
    pub version: String,
    /// The scenario's name.
    pub scenario: String,
    /// The random seed(s) of the run (one per trial or sweep seed).
    pub seeds: Vec<u64>,
    /// When the run started and ended, UTC (RFC 3339).
    pub started_utc: String,
    /// See `started_utc`.
    pub ended_utc: String,
    /// `done`, `interrupted` or `failed`.
    pub status: String,
    /// The files of the directory when the run ended (run.json included), sorted.
    pub files: Vec<String>,
}

impl RunDir {
    /// A directory the user named: refused if it holds anything unless `force`; created (with
    /// its parents) if missing.
    pub fn named(dir: &Path, force: bool) -> Result<Self, RunDirError> {
        Self::check_named(dir, force)?;
        std::fs::create_dir_all(dir).map_err(|source| RunDirError::Io {
            path: dir.to_path_buf(),
            action: "create the directory",
            source,
        })?;
        Ok(Self {
            path: dir.to_path_buf(),
            latest: None,
        })
    }

    /// What [`named`](Self::named) refuses, without creating anything.
    pub fn check_named(dir: &Path, force: bool) -> Result<(), RunDirError> {
        let entries = match std::fs::read_dir(dir) {
            Ok(e) => e,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(source) => {
                return Err(RunDirError::Io {
                    path: dir.to_path_buf(),
                    action: "read the directory",
                    source,
                })
            }
        };
        let names: Vec<String> = entries
            .filter_map(Result::ok)
            .map(|e| e.file_name().to_string_lossy().into_owned())
            .collect();
        match names.first() {
            Some(first) if !force => Err(RunDirError::NotEmpty {
                path: dir.to_path_buf(),
                entries: names.len(),
                example: first.clone(),
            }),
            _ => Ok(()),
        }
    }

    /// A new directory `<root>/<scenario>/<run-id>/`, made exclusively: a run id another run
    /// took (same second, same tag) is drawn again.
    pub fn unique(root: &Path, scenario: &str, now: SystemTime) -> Result<Self, RunDirError> {
        let name = dir_name(scenario);
        let parent = root.join(&name);
        std::fs::create_dir_all(&parent).map_err(|source| RunDirError::Io {
            path: parent.clone(),
            action: "create the directory",
            source,
        })?;
        let mut attempt = 0u32;
        loop {
            let id = run_id(now, tag(attempt));
            let path = parent.join(&id);
            match std::fs::create_dir(&path) {
                Ok(()) => {
                    return Ok(Self {
                        path,
                        latest: Some((root.to_path_buf(), name, id)),
                    })
                }
                Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && attempt < 1000 => {
                    attempt += 1;
                }
                Err(source) => {
                    return Err(RunDirError::Io {
                        path,
                        action: "create the directory",
                        source,
                    })
                }
            }
        }
    }

    /// The directory.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes `run.json` (with `info.files` filled in from the directory) and, for a default
    /// directory, points the `latest` links at it. Returns `run.json`'s path.
    pub fn finish(&self, mut info: RunInfo) -> Result<PathBuf, RunDirError> {
        let json = self.path.join("run.json");
        let mut files = list(&self.path)?;
        if !files.iter().any(|f| f == "run.json") {
            files.push("run.json".into());
            files.sort();
        }
        info.files = files;
        let text = serde_json::to_string_pretty(&info)?;
        outfile::write_file(&json, text.as_bytes())?;
        if let Some((root, scenario, id)) = &self.latest {
            outfile::replace_symlink(&root.join(scenario).join("latest"), Path::new(id))?;
            outfile::replace_symlink(&root.join("latest"), &Path::new(scenario).join(id))?;
        }
        Ok(json)
    }
}

/// The files of `dir` (not its temporary files), sorted.
fn list(dir: &Path) -> Result<Vec<String>, RunDirError> {
    let entries = std::fs::read_dir(dir).map_err(|source| RunDirError::Io {
        path: dir.to_path_buf(),
        action: "read the directory",
        source,
    })?;
    let mut v: Vec<String> = entries
        .filter_map(Result::ok)
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| !(n.starts_with('.') && n.ends_with(".tmp")))
        .collect();
    v.sort();
    Ok(v)
}

/// A scenario's name as one path component: letters, digits, `.`, `_` and `-` kept, anything
/// else `_`; `.`, `..` and `latest` (the link's name) get a trailing `_`.
pub fn dir_name(scenario: &str) -> String {
    let mut s: String = scenario
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || matches!(c, '.' | '_' | '-') {
                c
            } else {
                '_'
            }
        })
        .collect();
    if s.is_empty() || s == "." || s == ".." || s == "latest" {
        s.push('_');
    }
    s
}

/// The run id at `now` with `tag`: `20261207T153504Z-3fa2` (sorted by time as text).
pub fn run_id(now: SystemTime, tag: u16) -> String {
    let (date, time) = civil(now);
    format!(
        "{:04}{:02}{:02}T{:02}{:02}{:02}Z-{tag:04x}",
        date.0, date.1, date.2, time.0, time.1, time.2
    )
}

/// A short tag for attempt `n`: from the process id, the clock's nanoseconds and `n`.
fn tag(n: u32) -> u16 {
    let nanos = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_nanos());
    let x = std::process::id()
        .wrapping_mul(0x9E37_79B1)
        .wrapping_add(nanos)
        .wrapping_add(n.wrapping_mul(0x85EB_CA6B));
    ((x >> 16) ^ x) as u16
}

/// `t` as RFC 3339 UTC to the millisecond: `2026-12-07T15:35:04.123Z`.
pub fn utc(t: SystemTime) -> String {
    let (date, time) = civil(t);
    let ms = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.subsec_millis());
    format!(
        "{:04}-{:02}-{:02}T{:02}:{:02}:{:02}.{ms:03}Z",
        date.0, date.1, date.2, time.0, time.1, time.2
    )
}

/// The UTC date (year, month, day) and time (h, min, s) of `t` (before 1970: the epoch).
fn civil(t: SystemTime) -> ((i64, u32, u32), (u64, u64, u64)) {
    let secs = t
        .duration_since(SystemTime::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let (days, rest) = (secs / 86_400, secs % 86_400);
    // Howard Hinnant's days-to-civil, for days since 1970-01-01.
    let z = days as i64 + 719_468;
    let era = z.div_euclid(146_097);
    let doe = z - era * 146_097;
    let yoe = (doe - doe / 1460 + doe / 36_524 - doe / 146_096) / 365;
    let doy = doe - (365 * yoe + yoe / 4 - yoe / 100);
    let mp = (5 * doy + 2) / 153;
    let day = (doy - (153 * mp + 2) / 5 + 1) as u32;
    let month = if mp < 10 { mp + 3 } else { mp - 9 } as u32;
    let year = yoe + era * 400 + i64::from(month <= 2);
    (
        (year, month, day),
        (rest / 3600, rest % 3600 / 60, rest % 60),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::time::Duration;

    fn at(secs: u64) -> SystemTime {
        SystemTime::UNIX_EPOCH + Duration::from_secs(secs)
    }

    #[test]
    fn utc_and_run_id_name_the_calendar_time() {
        assert_eq!(utc(at(0)), "1970-01-01T00:00:00.000Z");
        // 2000-02-29 (a leap day of a century leap year), 2026-12-07 15:35:04.
        assert_eq!(utc(at(951_782_400)), "2000-02-29T00:00:00.000Z");
        assert_eq!(
            utc(at(1_796_657_704) + Duration::from_millis(250)),
            "2026-12-07T15:35:04.250Z"
        );
        assert_eq!(run_id(at(1_796_657_704), 0x3fa2), "20261207T153504Z-3fa2");
    }

    #[test]
    fn dir_name_is_one_safe_component() {
        assert_eq!(dir_name("wrong-area"), "wrong-area");
        assert_eq!(dir_name("../x/y"), ".._x_y");
        assert_eq!(dir_name(".."), ".._");
        assert_eq!(dir_name("latest"), "latest_");
        assert_eq!(dir_name(""), "_");
    }

    fn scratch(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("rundir-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        d
    }

    fn info() -> RunInfo {
        RunInfo {
            command: vec!["pheromone".into(), "sim".into()],
            flags: Vec::new(),
            version: "0".into(),
            scenario: "s".into(),
            seeds: vec![7],
            started_utc: utc(at(0)),
            ended_utc: utc(at(1)),
            status: "done".into(),
            files: Vec::new(),
        }
    }

    #[test]
    fn runs_in_the_same_second_get_their_own_directories_and_latest_the_newest() {
        let root = scratch("unique");
        let now = at(1_796_657_704);
        let dirs: Vec<RunDir> = (0..20)
            .map(|_| RunDir::unique(&root, "s", now).unwrap())
            .collect();
        let mut paths: Vec<&Path> = dirs.iter().map(RunDir::path).collect();
        paths.sort();
        paths.dedup();
        assert_eq!(paths.len(), 20);
        for d in &dirs {
            std::fs::write(d.path().join("metrics.json"), b"{}").unwrap();
            d.finish(info()).unwrap();
        }
        let last = dirs.last().unwrap().path();
        let id = last.file_name().unwrap();
        assert_eq!(
            std::fs::read_link(root.join("s/latest")).unwrap(),
            Path::new(id)
        );
        assert_eq!(
            std::fs::read_link(root.join("latest")).unwrap(),
            Path::new("s").join(id)
        );
        let json: serde_json::Value =
            serde_json::from_slice(&std::fs::read(root.join("latest/run.json")).unwrap()).unwrap();
        assert_eq!(
            json["files"],
            serde_json::json!(["metrics.json", "run.json"])
        );
        assert_eq!(json["seeds"], serde_json::json!([7]));
        std::fs::remove_dir_all(&root).unwrap();
    }

    #[test]
    fn a_named_directory_with_files_is_refused_unless_forced() {
        let dir = scratch("named");
        RunDir::named(&dir, false).unwrap();
        RunDir::named(&dir, false).unwrap();
        std::fs::write(dir.join("old.csv"), b"x").unwrap();
        let e = RunDir::named(&dir, false).unwrap_err().to_string();
        assert!(
            e.contains(&dir.display().to_string()) && e.contains("--force"),
            "{e}"
        );
        assert!(e.contains("old.csv"), "{e}");
        let d = RunDir::named(&dir, true).unwrap();
        d.finish(info()).unwrap();
        assert!(!dir.join("latest").exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

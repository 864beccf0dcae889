//! The bridge's record of the mirror batches it handed to the field, in a file, so that a bridge
//! restarted after a crash (SIGKILL, OOM) still answers a batch the crashed one handed over
//! without handing it over twice.
//!
//! A mirror sends a batch again until it is answered (`batches`). Without this file a bridge
//! killed after handing a batch to the field and before its answer reached the mirror left no
//! trace of it, and its successor applied the resent batch a second time.
//!
//! The file is `$TMPDIR/pheromone-<uid>/bridge-batches/<iceoryx2 prefix><field>` (one per user,
//! field and iceoryx2 domain, shared by the bridges of that field). Both directories are
//! private (`pheromone_field::outfile::private_dir`: mode 0700, owned by the user, checked when
//! they exist), the file is never followed through a symbolic link and is rewritten through a
//! temporary file beside it (`outfile::write_file`), so another user can neither plant a link
//! that makes a bridge truncate someone else's file nor read or edit the record. It is a sequence
//! of 32-byte little-endian
//! records `[mirror u64][batch u64][kind u32][forwarded u32][refused u32][0 u32]`:
//! - kind 0, *handing*: written before the first deposit of the batch goes to the field;
//! - kind 1, *handed*: written after the last, with the answer;
//! - kind 2, *floor*: every batch of that mirror below `batch` was handed (a compacted file);
//! - kind 3, *not handed*: after *handing*, no deposit of it reached the field (no field took
//!   it); the mirror sends it again.
//!
//! A batch with *handing* and no *handed* was interrupted by the crash: some of its deposits may
//! have reached the field. It is not handed over again (at most once), and the bridge says so.
//! A bridge that stops (Ctrl-C, SIGTERM, an error) removes the file; a crashed one leaves it
//! for its successor. Two bridges of one field in one domain share the file, and the first to
//! stop removes it: run one bridge per field and host.

use std::fs::File;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

use pheromone_field::outfile;

use crate::batches::{Known, Seen};

const RECORD_BYTES: usize = 32;
const HANDING: u32 = 0;
const HANDED: u32 = 1;
const FLOOR: u32 = 2;
const NOT_HANDED: u32 = 3;
/// Appended records after which the file is rewritten from what it means.
const COMPACT_AFTER: u64 = 65_536;

/// One record of the file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
struct Record {
    mirror_id: u64,
    batch: u64,
    kind: u32,
    forwarded: u32,
    refused: u32,
}

impl Record {
    fn new(kind: u32, mirror_id: u64, batch: u64, (forwarded, refused): (u32, u32)) -> Self {
        Self {
            mirror_id,
            batch,
            kind,
            forwarded,
            refused,
        }
    }

    fn bytes(&self) -> [u8; RECORD_BYTES] {
        let mut b = [0u8; RECORD_BYTES];
        b[0..8].copy_from_slice(&self.mirror_id.to_le_bytes());
        b[8..16].copy_from_slice(&self.batch.to_le_bytes());
        b[16..20].copy_from_slice(&self.kind.to_le_bytes());
        b[20..24].copy_from_slice(&self.forwarded.to_le_bytes());
        b[24..28].copy_from_slice(&self.refused.to_le_bytes());
        b
    }

    fn parse(b: &[u8]) -> Self {
        let u64_at = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
        let u32_at = |i: usize| u32::from_le_bytes(b[i..i + 4].try_into().expect("4 bytes"));
        Self {
            mirror_id: u64_at(0),
            batch: u64_at(8),
            kind: u32_at(16),
            forwarded: u32_at(20),
            refused: u32_at(24),
        }
    }
}

/// What a bridge learnt from the file its predecessor left.
#[derive(Debug, Default)]
pub struct Recovered {
    /// Batches handed over (answers kept).
    pub handed: u64,
    /// Batches whose handing over the crash interrupted: (mirror, batch).
    pub interrupted: Vec<(u64, u64)>,
}

/// The open file.
#[derive(Debug)]
pub struct Journal {
    path: PathBuf,
    file: File,
    appended: u64,
}

/// Where the bridges of `field` in the iceoryx2 domain of `prefix` keep their record.
pub fn path_for(prefix: &str, field: &str) -> PathBuf {
    let escaped: String = format!("{prefix}{field}")
        .bytes()
        .map(|c| match c {
            b'A'..=b'Z' | b'a'..=b'z' | b'0'..=b'9' | b'.' | b'_' | b'-' => (c as char).to_string(),
            _ => format!("%{c:02X}"),
        })
        .collect();
    pheromone_field::outfile::user_state_base()
        .join("bridge-batches")
        .join(escaped)
}

impl Journal {
    /// Opens (creating) the file at `path`, loads what it holds into `seen` and rewrites it
    /// compacted. The file's directory and the one above it are made private (or refused when
    /// they are not: another user's, open to others, a symbolic link); the file must be a
    /// regular file or missing.
    pub fn open(path: &Path, seen: &mut Seen) -> std::io::Result<(Self, Recovered)> {
        let dir = path.parent().unwrap_or(Path::new("."));
        if let Some(base) = dir.parent().filter(|b| !b.as_os_str().is_empty()) {
            outfile::private_dir(base).map_err(std::io::Error::other)?;
        }
        outfile::private_dir(dir).map_err(std::io::Error::other)?;
        let mut bytes = Vec::new();
        if outfile::check_destination(path).map_err(std::io::Error::other)? {
            outfile::open_private_read(path)
                .map_err(std::io::Error::other)?
                .read_to_end(&mut bytes)?;
        }
        // A record cut short by the crash is dropped (its batch is then not known).
        let records = bytes.chunks_exact(RECORD_BYTES).map(Record::parse);
        let recovered = load(records, seen);
        let mut j = Self {
            path: path.to_path_buf(),
            file: outfile::open_private_append(path).map_err(std::io::Error::other)?,
            appended: 0,
        };
        j.compact(seen)?;
        Ok((j, recovered))
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Writes that `batch` of `mirror_id` is about to be handed to the field.
    pub fn handing(&mut self, mirror_id: u64, batch: u64) -> std::io::Result<()> {
        self.append(Record::new(HANDING, mirror_id, batch, (0, 0)))
    }

    /// Writes that no deposit of `batch` of `mirror_id` reached the field after all.
    pub fn not_handed(&mut self, mirror_id: u64, batch: u64) -> std::io::Result<()> {
        self.append(Record::new(NOT_HANDED, mirror_id, batch, (0, 0)))
    }

    /// Writes that `batch` of `mirror_id` was handed over with this answer; compacts now and
    /// then (from `seen`, which already holds it).
    pub fn handed(
        &mut self,
        mirror_id: u64,
        batch: u64,
        answer: (u32, u32),
        seen: &Seen,
    ) -> std::io::Result<()> {
        self.append(Record::new(HANDED, mirror_id, batch, answer))?;
        if self.appended >= COMPACT_AFTER {
            self.compact(seen)?;
        }
        Ok(())
    }

    fn append(&mut self, r: Record) -> std::io::Result<()> {
        self.appended += 1;
        // One write per record: a SIGKILL cannot cut a write the kernel has taken.
        self.file.write_all(&r.bytes())
    }

    /// Rewrites the file with what `seen` holds (a temporary file renamed over it).
    fn compact(&mut self, seen: &Seen) -> std::io::Result<()> {
        let mut out = Vec::new();
        for k in seen.known() {
            let r = match k {
                Known::Below(m, below) => Record::new(FLOOR, m, below, (0, 0)),
                Known::Handed(m, b, f, r) => Record::new(HANDED, m, b, (f, r)),
            };
            out.extend_from_slice(&r.bytes());
        }
        outfile::write_file(&self.path, &out).map_err(std::io::Error::other)?;
        self.file = outfile::open_private_append(&self.path).map_err(std::io::Error::other)?;
        self.appended = 0;
        Ok(())
    }
}

/// A bridge that stops (cleanly, on an error or a panic; a SIGKILL runs no code) removes the
/// file: every batch it handed over was answered on its session.
impl Drop for Journal {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.path);
    }
}

/// Loads records into `seen`; a batch handed over in part is taken as handed, with no answer.
fn load(records: impl Iterator<Item = Record>, seen: &mut Seen) -> Recovered {
    let mut open = std::collections::BTreeSet::new();
    let mut r = Recovered::default();
    for rec in records {
        match rec.kind {
            HANDING => {
                open.insert((rec.mirror_id, rec.batch));
            }
            HANDED => {
                open.remove(&(rec.mirror_id, rec.batch));
                seen.record(rec.mirror_id, rec.batch, rec.forwarded, rec.refused);
                r.handed += 1;
            }
            NOT_HANDED => {
                open.remove(&(rec.mirror_id, rec.batch));
            }
            FLOOR => seen.floor(rec.mirror_id, rec.batch),
            _ => {}
        }
    }
    for &(m, b) in &open {
        seen.record(m, b, 0, 0);
    }
    r.interrupted = open.into_iter().collect();
    r
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `<temp>/pheromone-journal-test-<pid>-<name>/j/journal`: its directories private, as the
    /// journal wants them (the test removes the top one, [`base_of`]).
    fn temp(name: &str) -> PathBuf {
        std::env::temp_dir()
            .join(format!(
                "pheromone-journal-test-{}-{name}",
                std::process::id()
            ))
            .join("j")
            .join("journal")
    }

    fn base_of(path: &Path) -> &Path {
        path.parent().and_then(Path::parent).unwrap()
    }

    #[test]
    fn a_planted_symlink_or_a_directory_open_to_others_is_refused_and_nothing_is_truncated() {
        use std::os::unix::fs::PermissionsExt;
        let path = temp("planted");
        let dir = path.parent().unwrap();
        // A first bridge makes the directories; the link is planted after it stopped.
        drop(Journal::open(&path, &mut Seen::default()).unwrap());
        let victim = dir.parent().unwrap().join("victim");
        std::fs::write(&victim, b"someone else's file").unwrap();
        std::os::unix::fs::symlink(&victim, &path).unwrap();
        let e = Journal::open(&path, &mut Seen::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("symbolic link") && e.contains("journal"), "{e}");
        assert_eq!(std::fs::read(&victim).unwrap(), b"someone else's file");
        std::fs::remove_file(&path).unwrap();
        // The journal's directory opened to every user: refused, naming its mode.
        std::fs::set_permissions(dir, std::fs::Permissions::from_mode(0o777)).unwrap();
        let e = Journal::open(&path, &mut Seen::default())
            .unwrap_err()
            .to_string();
        assert!(e.contains("mode 777"), "{e}");
        assert!(!path.exists());
        std::fs::remove_dir_all(base_of(&path)).unwrap();
    }

    #[test]
    fn a_successor_answers_what_its_predecessor_handed_and_names_what_it_interrupted() {
        let path = temp("successor");
        let mut seen = Seen::default();
        let (mut j, r) = Journal::open(&path, &mut seen).unwrap();
        assert_eq!(r.handed, 0);
        for b in 1..=3 {
            j.handing(7, b).unwrap();
            seen.record(7, b, b as u32, 0);
            j.handed(7, b, (b as u32, 0), &seen).unwrap();
        }
        // No field took batch 4: the mirror sends it again, and a successor must hand it over.
        j.handing(7, 4).unwrap();
        j.not_handed(7, 4).unwrap();
        // Killed while handing batch 5 over (SIGKILL: no drop).
        j.handing(7, 5).unwrap();
        std::mem::forget(j);
        let mut next = Seen::default();
        let (j, r) = Journal::open(&path, &mut next).unwrap();
        assert_eq!(r.interrupted, vec![(7, 5)]);
        assert_eq!(next.earlier(7, 2), Some((2, 0)), "answered as before");
        assert_eq!(
            next.earlier(7, 4),
            None,
            "never handed over: handed over now"
        );
        assert_eq!(next.earlier(7, 5), Some((0, 0)), "not handed over twice");
        assert_eq!(next.earlier(7, 6), None);
        assert_eq!(next.earlier(8, 1), None, "another mirror's batch");
        // Compacted: a third bridge reads the same, and nothing is interrupted any more (the
        // second bridge is killed: its file stays).
        std::mem::forget(j);
        let mut third = Seen::default();
        let (j, r) = Journal::open(&path, &mut third).unwrap();
        assert!(r.interrupted.is_empty());
        assert_eq!(third.earlier(7, 3), Some((3, 0)));
        assert_eq!(third.earlier(7, 4), None);
        assert_eq!(third.earlier(7, 5), Some((0, 0)));
        drop(j);
        assert!(!path.exists(), "removed on a clean stop");
        std::fs::remove_dir_all(base_of(&path)).unwrap();
    }

    #[test]
    fn a_record_cut_short_is_dropped_and_names_are_escaped() {
        let path = temp("cut");
        let mut bytes = Record::new(HANDED, 1, 1, (5, 0)).bytes().to_vec();
        bytes.extend_from_slice(&[1, 2, 3]);
        outfile::private_dir(path.parent().unwrap().parent().unwrap()).unwrap();
        outfile::private_dir(path.parent().unwrap()).unwrap();
        std::fs::write(&path, bytes).unwrap();
        let mut seen = Seen::default();
        let (j, r) = Journal::open(&path, &mut seen).unwrap();
        assert_eq!(r.handed, 1);
        assert_eq!(seen.earlier(1, 1), Some((5, 0)));
        drop(j);
        let p = path_for("lab_iox2_", "a/b c");
        assert_eq!(p.file_name().unwrap(), "lab_iox2_a%2Fb%20c");
        std::fs::remove_dir_all(base_of(&path)).unwrap();
    }
}

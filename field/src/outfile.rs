//! Output files and state directories opened safely, for every writer of the workspace (a field's
//! checkpoint, `export`, a run's metrics, CSV, pictures, `.npy`, MCAP records, the bridge's
//! journal).
//!
//! - A destination is written only when it is a **regular file or a new path**: a symbolic link,
//!   a FIFO, a device, a socket or a directory there is refused ([`OutputError::NotRegular`]),
//!   never replaced nor written through (as root, `--checkpoint /dev/null` would otherwise have
//!   replaced `/dev/null` with a regular file).
//! - A whole file ([`OutFile`], [`write_file`]) is written to a temporary file **in the
//!   destination's directory**, created with `O_CREAT | O_EXCL | O_NOFOLLOW` under a random name
//!   (`.NAME.XXXXXX.tmp`, through `tempfile`'s `Builder::make_in`, which retries on a name taken),
//!   flushed, fsynced and renamed over the destination, then the directory is fsynced. The
//!   destination is checked again just before the rename; a destination that did not exist is
//!   renamed with `RENAME_NOREPLACE`, so a path planted in between is refused, not replaced. A
//!   writer that fails or is dropped before [`OutFile::commit`] removes its temporary file: no
//!   half-written or 0-byte file is left under the destination's name.
//! - A file written in place ([`open_in_place`], for records a crashed writer should leave
//!   readable) is opened with `O_NOFOLLOW | O_NONBLOCK` (a FIFO does not block the open) and
//!   checked with `fstat` to be a regular file before it is truncated.
//! - State kept under `$TMPDIR` lives in a **private directory** ([`private_dir`],
//!   [`user_state_dir`]: `$TMPDIR/pheromone-<uid>/…`): created with mode 0700, and when it exists,
//!   used only if it is a directory (not a link to one) owned by this process's effective user
//!   with no permission for group or others; anything else is refused naming the path and why.
//!
//! Limits: a file's directory must be trusted by its writer: another user who may write into
//! that directory (a non-sticky shared one) can still swap names between the last check and
//! the rename. The temporary file and the destination are in the same directory, hence the same
//! file system.

use std::fs::{File, OpenOptions};
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

/// Writing an output file or preparing a state directory failed. Names the path.
#[derive(Debug, thiserror::Error)]
pub enum OutputError {
    /// The path names something that is not a regular file: it is not replaced.
    #[error("{}: is {kind}, not a regular file: refusing to write there", path.display())]
    NotRegular {
        /// The destination.
        path: PathBuf,
        /// What it is (`a symbolic link`, `a FIFO`, `a character device`, …).
        kind: &'static str,
    },
    /// A link to repoint ([`replace_symlink`]) is something else: it is not replaced.
    #[error("{}: is {kind}, not a symbolic link: refusing to replace it", path.display())]
    NotSymlink {
        /// The link's path.
        path: PathBuf,
        /// What is there (`a directory`, `a regular file`, …).
        kind: &'static str,
    },
    /// A state directory is not private to this user.
    #[error("{}: {reason}: refusing to keep state there", path.display())]
    NotPrivate {
        /// The directory.
        path: PathBuf,
        /// Which check it fails (owner, mode, kind).
        reason: String,
    },
    /// A file system call failed.
    #[error("{}: cannot {action}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// What was being done (`create the temporary file`, `write`, `fsync`, `rename`…).
        action: &'static str,
        /// The system's error.
        #[source]
        source: std::io::Error,
    },
}

impl OutputError {
    fn io<'a>(path: &'a Path, action: &'static str) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |source| Self::Io {
            path: path.to_path_buf(),
            action,
            source,
        }
    }
}

/// What a file type is, in words, for [`OutputError::NotRegular`].
fn kind_of(t: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if t.is_symlink() {
        "a symbolic link"
    } else if t.is_dir() {
        "a directory"
    } else if t.is_file() {
        "a regular file"
    } else if t.is_fifo() {
        "a FIFO"
    } else if t.is_char_device() {
        "a character device"
    } else if t.is_block_device() {
        "a block device"
    } else if t.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

/// Whether `path` may be written: `Ok(true)` if a regular file is there, `Ok(false)` if nothing
/// is; a symbolic link (even to a regular file), FIFO, device, socket or directory is refused.
pub fn check_destination(path: &Path) -> Result<bool, OutputError> {
    match std::fs::symlink_metadata(path) {
        Ok(m) if m.file_type().is_file() => Ok(true),
        Ok(m) => Err(OutputError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(m.file_type()),
        }),
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(OutputError::io(path, "inspect")(e)),
    }
}

/// The directory a path is in (`.` for a bare file name).
fn directory_of(path: &Path) -> &Path {
    match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    }
}

/// A whole output file being written: a temporary file beside the destination, renamed over it
/// by [`OutFile::commit`]; dropped without it, the temporary file is removed.
pub struct OutFile {
    path: PathBuf,
    tmp: BufWriter<tempfile::NamedTempFile>,
}

impl OutFile {
    /// Starts writing `path` (checked by [`check_destination`]).
    pub fn create(path: &Path) -> Result<Self, OutputError> {
        check_destination(path)?;
        let name = path.file_name().ok_or_else(|| OutputError::NotRegular {
            path: path.to_path_buf(),
            kind: "a directory",
        })?;
        let mut prefix = std::ffi::OsString::from(".");
        prefix.push(name);
        prefix.push(".");
        let tmp = tempfile::Builder::new()
            .prefix(&prefix)
            .suffix(".tmp")
            .make_in(directory_of(path), |p| {
                OpenOptions::new()
                    .read(true)
                    .write(true)
                    .create_new(true)
                    .mode(0o666)
                    .custom_flags(libc::O_NOFOLLOW | libc::O_CLOEXEC)
                    .open(p)
            })
            .map_err(OutputError::io(path, "create a temporary file beside"))?;
        Ok(Self {
            path: path.to_path_buf(),
            tmp: BufWriter::new(tmp),
        })
    }

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Flushes, fsyncs and renames the file over its destination (checked again), then fsyncs
    /// the directory. Returns the bytes written.
    pub fn commit(self) -> Result<u64, OutputError> {
        let path = self.path;
        let tmp = self
            .tmp
            .into_inner()
            .map_err(|e| OutputError::io(&path, "write")(e.into_error()))?;
        tmp.as_file()
            .sync_all()
            .map_err(OutputError::io(&path, "fsync"))?;
        let bytes = tmp
            .as_file()
            .metadata()
            .map_err(OutputError::io(&path, "inspect"))?
            .len();
        let existed = check_destination(&path)?;
        let persisted = if existed {
            tmp.persist(&path)
        } else {
            tmp.persist_noclobber(&path)
        };
        // On an error the temporary file is dropped with the error, hence removed.
        persisted.map_err(|e| OutputError::io(&path, "rename the temporary file over")(e.error))?;
        sync_directory(directory_of(&path))
            .map_err(OutputError::io(&path, "fsync the directory of"))?;
        Ok(bytes)
    }
}

fn sync_directory(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

impl Write for OutFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.tmp.write(buf)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.tmp.flush()
    }
}

impl Seek for OutFile {
    fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
        self.tmp.seek(pos)
    }
}

/// Writes `bytes` as the whole file `path` ([`OutFile`]): a reader sees the old file or the new
/// one, never half of one. Returns the bytes written.
pub fn write_file(path: &Path, bytes: &[u8]) -> Result<u64, OutputError> {
    let mut out = OutFile::create(path)?;
    out.write_all(bytes)
        .map_err(OutputError::io(path, "write"))?;
    out.commit()
}

/// Opens `path` with `options` plus `O_NOFOLLOW | O_NONBLOCK | O_CLOEXEC` (a symbolic link is
/// refused, a FIFO planted there does not block the open), then checks with `fstat` that what
/// was opened is a regular file.
fn open_regular(path: &Path, options: &mut OpenOptions) -> Result<File, OutputError> {
    let file = options
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_CLOEXEC)
        .open(path)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ELOOP) => OutputError::NotRegular {
                path: path.to_path_buf(),
                kind: "a symbolic link",
            },
            _ => OutputError::io(path, "open")(e),
        })?;
    let meta = file.metadata().map_err(OutputError::io(path, "inspect"))?;
    if !meta.file_type().is_file() {
        return Err(OutputError::NotRegular {
            path: path.to_path_buf(),
            kind: kind_of(meta.file_type()),
        });
    }
    Ok(file)
}

/// Opens `path` to be written in place from its start (a new file, or a regular file truncated):
/// for a record that a writer killed midway should leave readable up to where it got. Refuses
/// what [`check_destination`] refuses, also when it appears between the check and the open
/// (`O_NOFOLLOW`, then `fstat`).
pub fn open_in_place(path: &Path) -> Result<File, OutputError> {
    check_destination(path)?;
    let file = open_regular(
        path,
        OpenOptions::new().write(true).create(true).mode(0o666),
    )?;
    file.set_len(0).map_err(OutputError::io(path, "truncate"))?;
    Ok(file)
}

/// Opens a file of a private directory for appending, creating it (mode 0600) if it is not
/// there; a symbolic link or anything but a regular file is refused.
pub fn open_private_append(path: &Path) -> Result<File, OutputError> {
    check_destination(path)?;
    open_regular(
        path,
        OpenOptions::new().append(true).create(true).mode(0o600),
    )
}

/// Opens a regular file to read without following a symbolic link (`O_NOFOLLOW`, then `fstat`;
/// `O_NONBLOCK`, so a FIFO planted there does not block the open).
pub fn open_private_read(path: &Path) -> Result<File, OutputError> {
    open_regular(path, OpenOptions::new().read(true))
}

/// Points the symbolic link `link` at `target` (a path relative to the link's directory): a new
/// link made under a random name beside it (`.NAME.XXXXXX.tmp`), then renamed over `link`, so a
/// reader sees the old target or the new one. Anything at `link` but a symbolic link (a
/// directory, a regular file) is refused, not replaced.
pub fn replace_symlink(link: &Path, target: &Path) -> Result<(), OutputError> {
    match std::fs::symlink_metadata(link) {
        Ok(m) if !m.file_type().is_symlink() => {
            return Err(OutputError::NotSymlink {
                path: link.to_path_buf(),
                kind: kind_of(m.file_type()),
            })
        }
        Ok(_) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(OutputError::io(link, "inspect")(e)),
    }
    let mut prefix = std::ffi::OsString::from(".");
    prefix.push(link.file_name().unwrap_or_default());
    prefix.push(".");
    let tmp = tempfile::Builder::new()
        .prefix(&prefix)
        .suffix(".tmp")
        .make_in(directory_of(link), |p| {
            std::os::unix::fs::symlink(target, p)
        })
        .map_err(OutputError::io(link, "create a temporary link beside"))?;
    // On an error the temporary link is dropped with the error, hence removed.
    tmp.persist(link)
        .map_err(|e| OutputError::io(link, "rename a new link over")(e.error))?;
    Ok(())
}

/// This process's effective user id.
fn effective_uid() -> u32 {
    nix::unistd::geteuid().as_raw()
}

/// Creates the directory `path` with mode 0700 if it is missing (its parent must exist), and
/// checks that it is private: a directory (not a symbolic link to one), owned by this process's
/// effective user, with no permission for group or others.
pub fn private_dir(path: &Path) -> Result<(), OutputError> {
    match std::fs::DirBuilder::new().mode(0o700).create(path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(OutputError::io(path, "create the directory")(e)),
    }
    let not_private = |reason: String| OutputError::NotPrivate {
        path: path.to_path_buf(),
        reason,
    };
    let m = std::fs::symlink_metadata(path).map_err(OutputError::io(path, "inspect"))?;
    if !m.file_type().is_dir() {
        return Err(not_private(format!(
            "is {}, not a directory",
            kind_of(m.file_type())
        )));
    }
    let me = effective_uid();
    if m.uid() != me {
        return Err(not_private(format!(
            "owned by uid {}, not by this user (uid {me})",
            m.uid()
        )));
    }
    if m.mode() & 0o077 != 0 {
        return Err(not_private(format!(
            "mode {:o} lets group or others in (expected 700)",
            m.mode() & 0o7777
        )));
    }
    Ok(())
}

/// `$TMPDIR/pheromone-<uid>`: where this user's state under `$TMPDIR` goes (not created; see
/// [`user_state_dir`]).
pub fn user_state_base() -> PathBuf {
    std::env::temp_dir().join(format!("pheromone-{}", effective_uid()))
}

/// `$TMPDIR/pheromone-<uid>/<sub>`: this user's state directory for `sub`, both levels made and
/// checked by [`private_dir`].
pub fn user_state_dir(sub: &str) -> Result<PathBuf, OutputError> {
    let base = user_state_base();
    private_dir(&base)?;
    let dir = base.join(sub);
    private_dir(&dir)?;
    Ok(dir)
}

#[cfg(test)]
mod tests;

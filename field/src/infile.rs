//! Input files read with a bound: a regular file or a pipe, at most a given number of bytes.
//! `--config /dev/zero`, `--map`, `--restore` and scenario files used to be read until memory
//! ran out; now a device, directory or socket is refused and a file (or a pipe's stream) longer
//! than its limit is refused naming the limit, before it is parsed.

use std::io::Read;
use std::os::unix::fs::FileTypeExt;
use std::path::Path;

/// The largest configuration, scenario or map-YAML text read (bytes).
pub const MAX_TEXT_BYTES: u64 = 16 << 20;
/// The largest map image read (bytes): a 16384 × 16384 8-bit PGM and its header.
pub const MAX_IMAGE_BYTES: u64 = (16384 * 16384) + 4096;

/// Reads at most `limit` bytes of `path` (a regular file or a FIFO); anything else, or more
/// bytes than `limit`, is an `InvalidInput` error saying which.
pub fn read_bounded(path: &Path, limit: u64) -> std::io::Result<Vec<u8>> {
    let file = std::fs::File::open(path)?;
    let meta = file.metadata()?;
    let t = meta.file_type();
    if !(t.is_file() || t.is_fifo()) {
        let kind = if t.is_dir() {
            "a directory"
        } else if t.is_char_device() {
            "a character device"
        } else if t.is_block_device() {
            "a block device"
        } else {
            "a socket"
        };
        return Err(invalid(format!(
            "is {kind}: only a regular file or a pipe is read"
        )));
    }
    if t.is_file() && meta.len() > limit {
        return Err(too_long(meta.len(), limit));
    }
    let mut bytes = Vec::new();
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_long(bytes.len() as u64, limit));
    }
    Ok(bytes)
}

/// As [`read_bounded`], as UTF-8 text.
pub fn read_text_bounded(path: &Path, limit: u64) -> std::io::Result<String> {
    String::from_utf8(read_bounded(path, limit)?)
        .map_err(|e| std::io::Error::new(std::io::ErrorKind::InvalidData, e))
}

fn invalid(msg: String) -> std::io::Error {
    std::io::Error::new(std::io::ErrorKind::InvalidInput, msg)
}

fn too_long(len: u64, limit: u64) -> std::io::Error {
    invalid(format!(
        "{len} bytes or more: over the limit of {limit} bytes for this file"
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_device_is_refused_and_a_file_over_its_limit_too() {
        let e = read_bounded(Path::new("/dev/zero"), 16)
            .unwrap_err()
            .to_string();
        assert!(e.contains("character device"), "{e}");
        let e = read_bounded(Path::new("/"), 16).unwrap_err().to_string();
        assert!(e.contains("directory"), "{e}");
        let path = std::env::temp_dir().join(format!("infile-{}", std::process::id()));
        std::fs::write(&path, b"0123456789").unwrap();
        assert_eq!(read_bounded(&path, 10).unwrap(), b"0123456789");
        let e = read_bounded(&path, 9).unwrap_err().to_string();
        assert!(e.contains("limit of 9 bytes"), "{e}");
        std::fs::remove_file(&path).unwrap();
    }
}

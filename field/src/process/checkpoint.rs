//! Checkpoint files: one frame (header and planes) on disk, so a field can resume after a crash
//! or a restart (`pheromone field --checkpoint FILE` / `--restore FILE`).
//!
//! Format, version 1, every number little-endian:
//!
//! | bytes | what |
//! | --- | --- |
//! | 8 | magic `PHRMCKPT` |
//! | 4 | format version (`FORMAT_VERSION`) |
//! | 4 | message layout version (`messages::LAYOUT_VERSION`) |
//! | 4 × 3 | width, height, channels |
//! | 4 × 4 | cell size (m), origin x (m), origin y (m), dt (s) — `f32` |
//! | 4 | number R of rejection reasons |
//! | 8 × 4 | sequence, sim time (s, `f64`), stamp (ns), deposits applied |
//! | 8 × R | deposits rejected, by reason |
//! | 4 + L | length L and the field configuration as TOML (informative) |
//! | 8 + 4 × N | number N of cells (= width × height × channels), the cells as `f32`, planes `channel, y, x` |
//! | 8 | FNV-1a 64 checksum of every byte before it |
//!
//! A file is written to a temporary file beside it (`crate::outfile`), synced, renamed over `FILE`
//! (a regular file or a new path, never a link, FIFO or device) and the directory synced, so a
//! crash leaves either the previous checkpoint or the new one, never a torn file. Reading checks
//! the magic, both versions, the sizes, the checksum and that every cell is finite; a restore
//! also checks the geometry and channels against the configuration (`Checkpoint::check_against`).

use std::path::{Path, PathBuf};

use crate::deposit::REJECT_REASONS;
use crate::engine::FieldConfig;
use crate::messages::{FrameHeader, LAYOUT_VERSION};

/// First bytes of every checkpoint file.
pub const MAGIC: [u8; 8] = *b"PHRMCKPT";
/// Version of the file format described in the module documentation.
pub const FORMAT_VERSION: u32 = 1;
/// Largest configuration text accepted (a sanity bound against corrupt lengths).
const MAX_CONFIG_BYTES: u32 = 1 << 20;

/// What is wrong with a checkpoint's bytes.
#[derive(Debug, thiserror::Error, Clone, PartialEq)]
pub enum FormatError {
    /// The file ends before a part the format requires (a cut-off write or a wrong file).
    #[error("truncated: {len} bytes, the {what} needs at least {needed}")]
    Truncated {
        /// Length of the file (bytes).
        len: usize,
        /// Length the missing part needs the file to have at least (bytes).
        needed: usize,
        /// The part that is missing (e.g. `checksum`, `configuration`).
        what: &'static str,
    },
    /// The file does not start with [`MAGIC`]: not a checkpoint.
    #[error("not a pheromone checkpoint (the first bytes are {found:02x?}, expected 'PHRMCKPT')")]
    Magic {
        /// The file's first bytes (at most 8).
        found: Vec<u8>,
    },
    /// The file was written in a format version this build does not read.
    #[error("format version {found}, this build reads version {FORMAT_VERSION}")]
    Version {
        /// The file's format version.
        found: u32,
    },
    /// The file was written by a build of another message layout version.
    #[error("message layout version {found}, this build speaks v{LAYOUT_VERSION}")]
    Layout {
        /// The file's layout version.
        found: u32,
    },
    /// The stored checksum does not match the bytes: the file is corrupted.
    #[error("checksum mismatch (stored {stored:#018x}, computed {computed:#018x}): the file is corrupted")]
    Checksum {
        /// The checksum the file ends with.
        stored: u64,
        /// FNV-1a 64 of the bytes before it.
        computed: u64,
    },
    /// A value is out of range: a size that does not match, a length beyond its bound, a
    /// non-finite time or cell.
    #[error("{what} = {value}: {reason}")]
    Invalid {
        /// The value at fault (e.g. `cell count`, `sim_time_s`).
        what: &'static str,
        /// The value, formatted.
        value: String,
        /// The rule it breaks.
        reason: String,
    },
    /// Bytes follow the checksum: the file is longer than its contents say.
    #[error("{extra} unexpected bytes after the checksum")]
    Trailing {
        /// Number of extra bytes.
        extra: usize,
    },
}

/// A checkpoint problem, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum CheckpointError {
    /// Reading or writing the file (or its temporary, or syncing its directory) failed.
    #[error("checkpoint '{path}': {action}: {source}")]
    Io {
        /// The checkpoint file.
        path: PathBuf,
        /// What was being done (`read`, `write`, `fsync`, `rename the temporary file`…).
        action: &'static str,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// Writing the file failed, or its path names something other than a regular file.
    #[error("checkpoint {0}")]
    Output(#[from] crate::outfile::OutputError),
    /// The file's bytes are not a valid checkpoint.
    #[error("checkpoint '{path}' is refused: {source}")]
    Format {
        /// The checkpoint file.
        path: PathBuf,
        /// What is wrong with its bytes.
        source: FormatError,
    },
    /// The checkpoint is valid but does not fit the field's configuration (another grid or
    /// channel count, or a cell outside its channel's range).
    #[error("checkpoint '{path}' does not fit the configuration: {detail}")]
    Mismatch {
        /// The checkpoint file.
        path: PathBuf,
        /// What differs.
        detail: String,
    },
}

/// One frame read back from a checkpoint.
#[derive(Debug, Clone, PartialEq)]
pub struct Checkpoint {
    /// The frame's header: geometry, sequence, field time and deposit counters.
    pub header: FrameHeader,
    /// The configuration the field ran with, as TOML (for people and tools; not enforced).
    pub config_toml: String,
    /// The frame's cells, planes `channel, y, x`; every one finite.
    pub cells: Vec<f32>,
}

/// FNV-1a, 64 bits.
pub fn fnv1a64(bytes: &[u8]) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for &b in bytes {
        h ^= b as u64;
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Encodes a frame as checkpoint bytes.
pub fn encode(header: &FrameHeader, config: &FieldConfig, cells: &[f32]) -> Vec<u8> {
    let config_toml = toml::to_string(config).unwrap_or_default();
    let mut b = Vec::with_capacity(128 + config_toml.len() + cells.len() * 4);
    b.extend_from_slice(&MAGIC);
    for v in [
        FORMAT_VERSION,
        LAYOUT_VERSION,
        header.width,
        header.height,
        header.channels,
    ] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    for v in [
        header.cell_size_m,
        header.origin_x_m,
        header.origin_y_m,
        header.dt_s,
    ] {
        b.extend_from_slice(&v.to_le_bytes());
    }
    b.extend_from_slice(&(REJECT_REASONS as u32).to_le_bytes());
    b.extend_from_slice(&header.sequence.to_le_bytes());
    b.extend_from_slice(&header.sim_time_s.to_le_bytes());
    b.extend_from_slice(&header.stamp_ns.to_le_bytes());
    b.extend_from_slice(&header.deposits_applied.to_le_bytes());
    for r in header.deposits_rejected {
        b.extend_from_slice(&r.to_le_bytes());
    }
    b.extend_from_slice(&(config_toml.len() as u32).to_le_bytes());
    b.extend_from_slice(config_toml.as_bytes());
    b.extend_from_slice(&(cells.len() as u64).to_le_bytes());
    for v in cells {
        b.extend_from_slice(&v.to_le_bytes());
    }
    let sum = fnv1a64(&b);
    b.extend_from_slice(&sum.to_le_bytes());
    b
}

/// Reads fields in order, failing with `Truncated` naming the part that is missing.
struct Cursor<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> Cursor<'a> {
    fn take(&mut self, n: usize, what: &'static str) -> Result<&'a [u8], FormatError> {
        let end = self.at.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.at..end];
                self.at = end;
                Ok(s)
            }
            None => Err(FormatError::Truncated {
                len: self.bytes.len(),
                needed: self.at.saturating_add(n),
                what,
            }),
        }
    }
    fn u32(&mut self, what: &'static str) -> Result<u32, FormatError> {
        Ok(u32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn f32(&mut self, what: &'static str) -> Result<f32, FormatError> {
        Ok(f32::from_le_bytes(self.take(4, what)?.try_into().unwrap()))
    }
    fn u64(&mut self, what: &'static str) -> Result<u64, FormatError> {
        Ok(u64::from_le_bytes(self.take(8, what)?.try_into().unwrap()))
    }
}

/// Decodes checkpoint bytes, checking magic, versions, sizes, checksum and finiteness.
pub fn decode(bytes: &[u8]) -> Result<Checkpoint, FormatError> {
    let mut c = Cursor { bytes, at: 0 };
    let layout = decode_versions(&mut c)?;
    let header = decode_header(&mut c, layout)?;
    let config_len = c.u32("configuration length")?;
    if config_len > MAX_CONFIG_BYTES {
        return Err(FormatError::Invalid {
            what: "configuration length",
            value: config_len.to_string(),
            reason: format!("exceeds {MAX_CONFIG_BYTES} bytes"),
        });
    }
    let config_toml =
        String::from_utf8_lossy(c.take(config_len as usize, "configuration")?).into_owned();
    let raw = take_cells(&mut c, &header)?;
    let body_end = c.at;
    let stored = c.u64("checksum")?;
    if c.at != bytes.len() {
        return Err(FormatError::Trailing {
            extra: bytes.len() - c.at,
        });
    }
    let computed = fnv1a64(&bytes[..body_end]);
    if stored != computed {
        return Err(FormatError::Checksum { stored, computed });
    }
    let cells = finite_cells(raw)?;
    if !header.sim_time_s.is_finite() || header.sim_time_s < 0.0 {
        return Err(FormatError::Invalid {
            what: "sim_time_s",
            value: header.sim_time_s.to_string(),
            reason: "must be finite and ≥ 0".into(),
        });
    }
    Ok(Checkpoint {
        header,
        config_toml,
        cells,
    })
}

/// The magic, the format version and the layout version (returned), each checked.
fn decode_versions(c: &mut Cursor) -> Result<u32, FormatError> {
    let magic = c.take(8, "magic")?;
    if magic != MAGIC {
        return Err(FormatError::Magic {
            found: magic.to_vec(),
        });
    }
    let version = c.u32("format version")?;
    if version != FORMAT_VERSION {
        return Err(FormatError::Version { found: version });
    }
    let layout = c.u32("layout version")?;
    if layout != LAYOUT_VERSION {
        return Err(FormatError::Layout { found: layout });
    }
    Ok(layout)
}

/// The frame header: geometry, clock and counters (`sim_time_s` is checked by the caller, after
/// the checksum).
fn decode_header(c: &mut Cursor, layout: u32) -> Result<FrameHeader, FormatError> {
    let width = c.u32("header")?;
    let height = c.u32("header")?;
    let channels = c.u32("header")?;
    let cell_size_m = c.f32("header")?;
    let origin_x_m = c.f32("header")?;
    let origin_y_m = c.f32("header")?;
    let dt_s = c.f32("header")?;
    let reasons = c.u32("header")?;
    if reasons as usize != REJECT_REASONS {
        return Err(FormatError::Invalid {
            what: "rejection reasons",
            value: reasons.to_string(),
            reason: format!("this build counts {REJECT_REASONS}"),
        });
    }
    let sequence = c.u64("header")?;
    let sim_time_s = f64::from_bits(c.u64("header")?);
    let stamp_ns = c.u64("header")?;
    let deposits_applied = c.u64("header")?;
    let mut deposits_rejected = [0u64; REJECT_REASONS];
    for r in &mut deposits_rejected {
        *r = c.u64("header")?;
    }
    Ok(FrameHeader {
        layout_version: layout,
        channels,
        width,
        height,
        sequence,
        stamp_ns,
        sim_time_s,
        cell_size_m,
        origin_x_m,
        origin_y_m,
        dt_s,
        tick_compute_ns: 0,
        deposits_applied,
        deposits_rejected,
        deposits_this_tick: 0,
        _reserved: 0,
    })
}

/// The cells' bytes, after their count, which must be the header's width × height × channels.
fn take_cells<'a>(c: &mut Cursor<'a>, header: &FrameHeader) -> Result<&'a [u8], FormatError> {
    let (width, height, channels) = (header.width, header.height, header.channels);
    let n = c.u64("cell count")?;
    let expected = width as u64 * height as u64 * channels as u64;
    if n != expected {
        return Err(FormatError::Invalid {
            what: "cell count",
            value: n.to_string(),
            reason: format!("the header says {width}×{height}×{channels} = {expected}"),
        });
    }
    let cell_bytes = usize::try_from(n)
        .ok()
        .and_then(|n| n.checked_mul(4))
        .ok_or(FormatError::Invalid {
            what: "cell count",
            value: n.to_string(),
            reason: "too large".into(),
        })?;
    c.take(cell_bytes, "cells")
}

/// The cells as f32, every one finite.
fn finite_cells(raw: &[u8]) -> Result<Vec<f32>, FormatError> {
    let cells: Vec<f32> = raw
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes(b.try_into().unwrap()))
        .collect();
    if let Some(i) = cells.iter().position(|v| !v.is_finite()) {
        return Err(FormatError::Invalid {
            what: "cell",
            value: format!("{} at index {i}", cells[i]),
            reason: "must be finite".into(),
        });
    }
    Ok(cells)
}

/// Writes a checkpoint atomically ([`crate::outfile::OutFile`]: a temporary file beside `FILE`,
/// fsync, rename over `FILE`, fsync the directory); `FILE` must be a regular file or a new path.
/// Returns the bytes written.
pub fn write_atomic(
    path: &Path,
    header: &FrameHeader,
    config: &FieldConfig,
    cells: &[f32],
) -> Result<u64, CheckpointError> {
    Ok(crate::outfile::write_file(
        path,
        &encode(header, config, cells),
    )?)
}

/// The largest checkpoint read (bytes): 4 GiB, a billion cells.
pub const MAX_CHECKPOINT_BYTES: u64 = 4 << 30;

/// Reads and checks a checkpoint file.
pub fn read(path: &Path) -> Result<Checkpoint, CheckpointError> {
    // A checkpoint of the largest grid of `FieldConfig` is larger; this bounds what a pipe or a
    // wrong file can make the field read (a device is refused).
    let bytes = crate::infile::read_bounded(path, MAX_CHECKPOINT_BYTES).map_err(|source| {
        CheckpointError::Io {
            path: path.to_path_buf(),
            action: "read",
            source,
        }
    })?;
    decode(&bytes).map_err(|source| CheckpointError::Format {
        path: path.to_path_buf(),
        source,
    })
}

impl Checkpoint {
    /// Checks that the checkpoint's grid and channels are the configuration's, and that every
    /// cell lies in its channel's value range. The evaporation models may differ (a restart may
    /// retune them); the geometry may not.
    pub fn check_against(&self, path: &Path, config: &FieldConfig) -> Result<(), CheckpointError> {
        let h = &self.header;
        let g = config.geometry();
        let mismatch = |detail: String| CheckpointError::Mismatch {
            path: path.to_path_buf(),
            detail,
        };
        if (h.width, h.height, h.channels as usize) != (g.width, g.height, config.channels.len())
            || h.cell_size_m != g.cell_size_m
            || h.origin_x_m != g.origin_x_m
            || h.origin_y_m != g.origin_y_m
        {
            return Err(mismatch(format!(
                "it holds {}×{} cells × {} channel(s) of {} m at ({}, {}), the configuration has \
                 {}×{} × {} of {} m at ({}, {}); start the field with the checkpoint's geometry",
                h.width,
                h.height,
                h.channels,
                h.cell_size_m,
                h.origin_x_m,
                h.origin_y_m,
                g.width,
                g.height,
                config.channels.len(),
                g.cell_size_m,
                g.origin_x_m,
                g.origin_y_m
            )));
        }
        let n = g.cells();
        for (c, spec) in config.channels.iter().enumerate() {
            let (lo, hi) = spec.value_range();
            let plane = &self.cells[c * n..(c + 1) * n];
            if let Some(i) = plane.iter().position(|v| *v < lo || *v > hi) {
                return Err(mismatch(format!(
                    "cell {i} of channel '{}' is {}, outside the channel's range [{lo}, {hi}]",
                    spec.name, plane[i]
                )));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::engine::OwnedField;
    use crate::{Deposit, DepositMsg, Kernel};

    fn sample() -> (FieldConfig, FrameHeader, Vec<f32>) {
        let config = FieldConfig {
            width: 16,
            height: 8,
            cell_size_m: 0.1,
            origin_x_m: -0.5,
            ..FieldConfig::default()
        };
        let mut f = OwnedField::new(config.clone()).unwrap();
        f.offer(&DepositMsg::from(Deposit {
            channel: 0,
            x_m: 0.3,
            y_m: 0.4,
            kernel: Kernel::Ellipse {
                tau: 0.2,
                cov_m2: [0.01, 0.0, 0.01],
                range_m: 1.0,
                gamma_max: 100.0,
            },
        }))
        .unwrap();
        let r = f.tick();
        f.tick();
        let mut header = f.stepper.header(42, 7, &r);
        header.deposits_rejected[2] = 3;
        (config, header, f.cells().to_vec())
    }

    #[test]
    fn a_checkpoint_round_trips_bit_for_bit() {
        let (config, header, cells) = sample();
        assert!(cells.iter().any(|v| *v > 0.0));
        let cp = decode(&encode(&header, &config, &cells)).unwrap();
        assert_eq!(cp.cells, cells);
        assert_eq!(cp.header.sequence, 2);
        assert_eq!(cp.header.sim_time_s, header.sim_time_s);
        assert_eq!(cp.header.deposits_applied, 1);
        assert_eq!(cp.header.deposits_rejected, header.deposits_rejected);
        assert_eq!(cp.header.geometry(), config.geometry());
        assert_eq!(FieldConfig::from_toml(&cp.config_toml).unwrap(), config);
        cp.check_against(Path::new("x"), &config).unwrap();
    }

    #[test]
    fn every_truncation_is_refused() {
        let (config, header, cells) = sample();
        let bytes = encode(&header, &config, &cells);
        for len in 0..bytes.len() {
            let e = decode(&bytes[..len]).unwrap_err();
            assert!(
                matches!(
                    e,
                    FormatError::Truncated { .. } | FormatError::Invalid { .. }
                ),
                "length {len}: {e}"
            );
        }
        let mut longer = bytes.clone();
        longer.push(0);
        assert_eq!(
            decode(&longer).unwrap_err(),
            FormatError::Trailing { extra: 1 }
        );
    }

    #[test]
    fn every_flipped_byte_is_refused() {
        let (config, header, cells) = sample();
        let bytes = encode(&header, &config, &cells);
        for i in 0..bytes.len() {
            let mut b = bytes.clone();
            b[i] ^= 0x10;
            assert!(decode(&b).is_err(), "flipping byte {i} went unnoticed");
        }
    }

    #[test]
    fn versions_and_magic_are_checked_before_the_rest() {
        let (config, header, cells) = sample();
        let bytes = encode(&header, &config, &cells);
        let mut b = bytes.clone();
        b[0] = b'X';
        assert!(matches!(decode(&b), Err(FormatError::Magic { .. })));
        let mut b = bytes.clone();
        b[8..12].copy_from_slice(&2u32.to_le_bytes());
        assert_eq!(decode(&b), Err(FormatError::Version { found: 2 }));
        let mut b = bytes;
        b[12..16].copy_from_slice(&(LAYOUT_VERSION + 1).to_le_bytes());
        assert_eq!(
            decode(&b),
            Err(FormatError::Layout {
                found: LAYOUT_VERSION + 1
            })
        );
    }

    #[test]
    fn a_non_finite_cell_with_a_valid_checksum_is_still_refused() {
        let (config, header, mut cells) = sample();
        cells[5] = f32::NAN;
        let e = decode(&encode(&header, &config, &cells)).unwrap_err();
        assert!(e.to_string().contains("index 5"), "{e}");
    }

    #[test]
    fn another_geometry_or_an_out_of_range_cell_does_not_fit() {
        let (config, header, mut cells) = sample();
        let cp = decode(&encode(&header, &config, &cells)).unwrap();
        let other = FieldConfig {
            width: 32,
            ..config.clone()
        };
        let e = cp.check_against(Path::new("f.ckpt"), &other).unwrap_err();
        assert!(
            e.to_string().contains("f.ckpt") && e.to_string().contains("16×8"),
            "{e}"
        );
        cells[3] = -1.0; // the default channel is unsigned
        let cp = decode(&encode(&header, &config, &cells)).unwrap();
        let e = cp.check_against(Path::new("f.ckpt"), &config).unwrap_err();
        assert!(e.to_string().contains("cell 3"), "{e}");
    }

    #[test]
    fn writing_is_atomic_and_leaves_no_temporary_file() {
        let (config, header, cells) = sample();
        let dir = std::env::temp_dir().join(format!("ckpt-unit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("field.ckpt");
        std::fs::write(&path, b"old").unwrap();
        let n = write_atomic(&path, &header, &config, &cells).unwrap();
        assert_eq!(n, std::fs::metadata(&path).unwrap().len());
        assert_eq!(
            std::fs::read_dir(&dir).unwrap().count(),
            1,
            "a temporary file is left"
        );
        assert_eq!(read(&path).unwrap().cells, cells);
        std::fs::write(&path, b"PHRMCKPT").unwrap();
        let e = read(&path).unwrap_err().to_string();
        assert!(e.contains("field.ckpt") && e.contains("truncated"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

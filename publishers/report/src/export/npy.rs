//! NumPy `.npy` format version 1.0 (numpy.org/doc/stable/reference/generated/numpy.lib.format):
//! the magic `\x93NUMPY`, version 1.0, a little-endian `u16` header length, an ASCII Python
//! dict `{'descr': '<f4', 'fortran_order': False, 'shape': (C, H, W), }` padded with spaces
//! and ended by `\n` so that the data starts at a multiple of 64 bytes, then the cells as
//! little-endian `f32`, C order. Written by hand (40 lines): a crate (`npyz`, `ndarray-npy`)
//! would bring its own dependencies for a fixed header and a byte copy.

use std::path::Path;

use super::{write_atomically, ExportError};

/// The bytes of a `.npy` file holding `cells` as a `float32` array of `shape` (C order).
pub fn npy_bytes(shape: &[usize], cells: &[f32]) -> Vec<u8> {
    let dims: Vec<String> = shape.iter().map(|d| d.to_string()).collect();
    let shape_text = match dims.len() {
        1 => format!("({},)", dims[0]),
        _ => format!("({})", dims.join(", ")),
    };
    let mut header = format!("{{'descr': '<f4', 'fortran_order': False, 'shape': {shape_text}, }}");
    // magic (6) + version (2) + header length (2) + header + '\n' ≡ 0 (mod 64)
    let unpadded = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - unpadded % 64) % 64));
    header.push('\n');
    let mut out = Vec::with_capacity(10 + header.len() + 4 * cells.len());
    out.extend_from_slice(b"\x93NUMPY\x01\x00");
    // A shape of a few numbers keeps the header far below 65535 bytes.
    out.extend_from_slice(&(header.len() as u16).to_le_bytes());
    out.extend_from_slice(header.as_bytes());
    for v in cells {
        out.extend_from_slice(&v.to_le_bytes());
    }
    out
}

/// Writes planes `channel, y, x` as a `(channels, height, width)` `float32` `.npy` file.
pub fn write_npy(
    path: &Path,
    channels: usize,
    height: usize,
    width: usize,
    cells: &[f32],
) -> Result<(), ExportError> {
    if channels * height * width != cells.len() {
        return Err(ExportError::Shape {
            len: cells.len(),
            channels,
            height,
            width,
        });
    }
    write_atomically(path, &npy_bytes(&[channels, height, width], cells))
}

/// Writes `dir/field_final.npy`: every channel of a run's last snapshot (`pheromone sim --out`).
pub fn write_snapshot(
    dir: &Path,
    snap: &pheromone_sim::recording::Snapshot,
) -> Result<std::path::PathBuf, ExportError> {
    let path = dir.join("field_final.npy");
    write_npy(
        &path,
        snap.channels.len(),
        snap.height as usize,
        snap.width as usize,
        &snap.planes,
    )?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_header_is_numpys_and_the_data_starts_on_64_bytes() {
        let cells: Vec<f32> = (0..24).map(|i| i as f32 * 0.5 - 3.0).collect();
        let b = npy_bytes(&[2, 3, 4], &cells);
        assert_eq!(&b[..8], b"\x93NUMPY\x01\x00");
        let len = u16::from_le_bytes([b[8], b[9]]) as usize;
        assert_eq!((10 + len) % 64, 0);
        let header = std::str::from_utf8(&b[10..10 + len]).unwrap();
        assert!(
            header.starts_with("{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3, 4), }")
        );
        assert!(header.ends_with(" \n"));
        let data = &b[10 + len..];
        assert_eq!(data.len(), 24 * 4);
        assert_eq!(&data[4..8], &(-2.5f32).to_le_bytes());
        assert_eq!(
            std::str::from_utf8(&npy_bytes(&[5], &[0.0; 5])[10..]).unwrap()[..60].trim_end(),
            "{'descr': '<f4', 'fortran_order': False, 'shape': (5,), }"
        );
    }

    #[test]
    fn a_shape_that_the_cells_do_not_fill_is_refused() {
        let dir = std::env::temp_dir();
        let e = write_npy(&dir.join("never.npy"), 2, 3, 4, &[0.0; 23]).unwrap_err();
        assert!(e.to_string().contains("23 values for 2 × 3 × 4"), "{e}");
        assert!(!dir.join("never.npy").exists());
    }
}

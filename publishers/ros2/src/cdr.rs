//! CDR (XCDR1, little endian), the serialization ROS 2 and `rmw_zenoh_cpp` use: a 4-byte
//! encapsulation header `00 01 00 00`, then every primitive aligned to its own size counted
//! from the end of that header, strings as a `u32` length (NUL included) and the bytes with
//! their NUL, sequences as a `u32` count and the elements.
//!
//! Written by hand, not with a serde-based crate such as `cdr-encoding`, for the bulk of the
//! messages: a GridMap layer is the field's plane read back to front (grid_map's column-major
//! order), an OccupancyGrid is the plane on its occupancy scale. [`CdrWriter::f32_seq_from`] writes
//! such a transform straight from the shared frame into a buffer sized once in advance,
//! without building a `Vec<f32>` (or a serde sequence) of the layer first; the rest of the
//! format needed here (seven primitive kinds, strings, sequences) is this page.

use thiserror::Error;

/// The CDR little-endian encapsulation header (`CDR_LE`, options 0).
pub const ENCAPSULATION_LE: [u8; 4] = [0x00, 0x01, 0x00, 0x00];

/// A CDR message under construction.
#[derive(Debug, Clone)]
pub struct CdrWriter {
    buf: Vec<u8>,
}

impl Default for CdrWriter {
    fn default() -> Self {
        Self::with_capacity(64)
    }
}

impl CdrWriter {
    /// A writer holding the encapsulation header, with room for `capacity` bytes in all.
    pub fn with_capacity(capacity: usize) -> Self {
        let mut buf = Vec::with_capacity(capacity.max(4));
        buf.extend_from_slice(&ENCAPSULATION_LE);
        Self { buf }
    }

    /// Bytes written, the header included.
    pub fn len(&self) -> usize {
        self.buf.len()
    }

    /// Whether nothing but the header was written.
    pub fn is_empty(&self) -> bool {
        self.buf.len() == 4
    }

    fn align(&mut self, n: usize) {
        let pos = self.buf.len() - 4;
        let pad = (n - pos % n) % n;
        self.buf.resize(self.buf.len() + pad, 0);
    }

    pub fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }

    pub fn u16(&mut self, v: u16) {
        self.align(2);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn i32(&mut self, v: i32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn u32(&mut self, v: u32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f32(&mut self, v: f32) {
        self.align(4);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    pub fn f64(&mut self, v: f64) {
        self.align(8);
        self.buf.extend_from_slice(&v.to_le_bytes());
    }

    /// A string: `u32` length with the NUL, the bytes, the NUL.
    pub fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }

    /// A sequence's element count.
    pub fn seq_len(&mut self, n: usize) {
        self.u32(n as u32);
    }

    /// A `float32[]` of `n` elements, element `k` = `at(k)`, written in place.
    pub fn f32_seq_from(&mut self, n: usize, mut at: impl FnMut(usize) -> f32) {
        self.seq_len(n);
        let start = self.buf.len();
        self.buf.resize(start + 4 * n, 0);
        for (k, dst) in self.buf[start..].chunks_exact_mut(4).enumerate() {
            dst.copy_from_slice(&at(k).to_le_bytes());
        }
    }

    /// An `int8[]` (or `uint8[]`) of `n` bytes, written in place by `fill`.
    pub fn byte_seq_with(&mut self, n: usize, fill: impl FnOnce(&mut [u8])) {
        self.seq_len(n);
        let start = self.buf.len();
        self.buf.resize(start + n, 0);
        fill(&mut self.buf[start..]);
    }

    /// The finished message.
    pub fn finish(self) -> Vec<u8> {
        self.buf
    }
}

/// Why a CDR message could not be read.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum CdrError {
    #[error("truncated CDR: {what} needs {need} bytes at offset {at}, the message has {len}")]
    Truncated {
        what: &'static str,
        at: usize,
        need: usize,
        len: usize,
    },
    #[error("CDR encapsulation {0:02x?}: only little-endian CDR (00 01) is read")]
    Encapsulation([u8; 2]),
    #[error("CDR string {what}: {detail}")]
    BadString { what: &'static str, detail: String },
}

/// Reads a little-endian CDR message.
#[derive(Debug)]
pub struct CdrReader<'a> {
    body: &'a [u8],
    pos: usize,
}

impl<'a> CdrReader<'a> {
    /// Checks the encapsulation header; the reader starts after it.
    pub fn new(msg: &'a [u8]) -> Result<Self, CdrError> {
        if msg.len() < 4 {
            return Err(CdrError::Truncated {
                what: "encapsulation header",
                at: 0,
                need: 4,
                len: msg.len(),
            });
        }
        if msg[0..2] != ENCAPSULATION_LE[0..2] {
            return Err(CdrError::Encapsulation([msg[0], msg[1]]));
        }
        Ok(Self {
            body: &msg[4..],
            pos: 0,
        })
    }

    fn take(&mut self, what: &'static str, align: usize, n: usize) -> Result<&'a [u8], CdrError> {
        let start = self.pos.div_ceil(align) * align;
        if start + n > self.body.len() {
            return Err(CdrError::Truncated {
                what,
                at: start + 4,
                need: n,
                len: self.body.len() + 4,
            });
        }
        self.pos = start + n;
        Ok(&self.body[start..start + n])
    }

    pub fn i32(&mut self, what: &'static str) -> Result<i32, CdrError> {
        let b = self.take(what, 4, 4)?;
        Ok(i32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn u32(&mut self, what: &'static str) -> Result<u32, CdrError> {
        let b = self.take(what, 4, 4)?;
        Ok(u32::from_le_bytes([b[0], b[1], b[2], b[3]]))
    }

    pub fn f64(&mut self, what: &'static str) -> Result<f64, CdrError> {
        let b = self.take(what, 8, 8)?;
        let mut a = [0u8; 8];
        a.copy_from_slice(b);
        Ok(f64::from_le_bytes(a))
    }

    /// A string (its NUL checked and dropped).
    pub fn string(&mut self, what: &'static str) -> Result<String, CdrError> {
        let n = self.u32(what)? as usize;
        if n == 0 {
            return Err(CdrError::BadString {
                what,
                detail: "length 0 (a CDR string holds at least its NUL)".into(),
            });
        }
        let b = self.take(what, 1, n)?;
        if b[n - 1] != 0 {
            return Err(CdrError::BadString {
                what,
                detail: "no terminating NUL".into(),
            });
        }
        String::from_utf8(b[..n - 1].to_vec()).map_err(|e| CdrError::BadString {
            what,
            detail: e.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn primitives_are_aligned_from_the_end_of_the_header() {
        let mut w = CdrWriter::default();
        w.u8(1);
        w.f64(2.0);
        w.string("ab");
        w.u16(3);
        let b = w.finish();
        assert_eq!(&b[..4], &ENCAPSULATION_LE);
        assert_eq!(b[4], 1);
        assert_eq!(&b[5..12], &[0; 7]);
        assert_eq!(&b[12..20], &2.0f64.to_le_bytes());
        assert_eq!(&b[20..24], &3u32.to_le_bytes());
        assert_eq!(&b[24..27], b"ab\0");
        assert_eq!(b[27], 0);
        assert_eq!(&b[28..30], &3u16.to_le_bytes());
    }

    #[test]
    fn reader_reads_what_the_writer_wrote_and_refuses_truncation() {
        let mut w = CdrWriter::default();
        w.i32(-5);
        w.string("map");
        w.f64(1.5);
        let b = w.finish();
        let mut r = CdrReader::new(&b).unwrap();
        assert_eq!(r.i32("a").unwrap(), -5);
        assert_eq!(r.string("b").unwrap(), "map");
        assert_eq!(r.f64("c").unwrap(), 1.5);
        for cut in 0..b.len() {
            let short = &b[..cut];
            let res = CdrReader::new(short).and_then(|mut r| {
                r.i32("a")?;
                r.string("b")?;
                r.f64("c")
            });
            assert!(res.is_err(), "cut at {cut}");
        }
        assert!(matches!(
            CdrReader::new(&[0, 0, 0, 0]),
            Err(CdrError::Encapsulation(_))
        ));
    }
}

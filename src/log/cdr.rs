//! A minimal, zero-copy reader for ROS 2's CDR (XCDR1) serialisation.
//!
//! A payload starts with a 4-byte encapsulation header (`00 01` little-endian, `00 00` big
//! endian); primitives are aligned to their size, counted from the end of that header. Strings
//! are a u32 length (including the terminating NUL) and bytes; sequences are a u32 count and
//! elements. Every read is bounds-checked and returns a [`DecodeError`] naming what was read.

use super::error::{DecodeError, DecodeResult};

pub struct CdrReader<'a> {
    data: &'a [u8],
    pos: usize,
    little_endian: bool,
}

impl<'a> CdrReader<'a> {
    pub fn new(payload: &'a [u8]) -> DecodeResult<Self> {
        if payload.len() < 4 {
            return Err(DecodeError::new(
                "CDR payload shorter than its 4-byte header",
            ));
        }
        let little_endian = match (payload[0], payload[1]) {
            (0, 1) => true,
            (0, 0) => false,
            (a, b) => {
                return Err(DecodeError::new(format!(
                    "unsupported CDR encapsulation {a:02x} {b:02x} (expected plain CDR 00 00 or 00 01)"
                )));
            }
        };
        Ok(Self {
            data: &payload[4..],
            pos: 0,
            little_endian,
        })
    }

    fn align(&mut self, n: usize) {
        let rem = self.pos % n;
        if rem != 0 {
            self.pos += n - rem;
        }
    }

    fn take(&mut self, n: usize, what: &str) -> DecodeResult<&'a [u8]> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.data.len())
            .ok_or_else(|| {
                DecodeError::new(format!(
                    "truncated CDR: {what} needs {n} bytes at offset {} of {}",
                    self.pos,
                    self.data.len()
                ))
            })?;
        let s = &self.data[self.pos..end];
        self.pos = end;
        Ok(s)
    }

    fn fixed<const N: usize>(&mut self, what: &str) -> DecodeResult<[u8; N]> {
        self.align(N);
        let s = self.take(N, what)?;
        let mut b = [0u8; N];
        b.copy_from_slice(s);
        if !self.little_endian {
            b.reverse();
        }
        Ok(b)
    }

    pub fn u8(&mut self, what: &str) -> DecodeResult<u8> {
        Ok(self.take(1, what)?[0])
    }
    pub fn bool(&mut self, what: &str) -> DecodeResult<bool> {
        Ok(self.u8(what)? != 0)
    }
    pub fn u32(&mut self, what: &str) -> DecodeResult<u32> {
        Ok(u32::from_le_bytes(self.fixed::<4>(what)?))
    }
    pub fn i32(&mut self, what: &str) -> DecodeResult<i32> {
        Ok(i32::from_le_bytes(self.fixed::<4>(what)?))
    }
    pub fn f64(&mut self, what: &str) -> DecodeResult<f64> {
        Ok(f64::from_le_bytes(self.fixed::<8>(what)?))
    }

    pub fn string(&mut self, what: &str) -> DecodeResult<String> {
        let len = self.u32(what)? as usize;
        let bytes = self.take(len, what)?;
        let bytes = bytes.strip_suffix(&[0]).unwrap_or(bytes);
        String::from_utf8(bytes.to_vec())
            .map_err(|_| DecodeError::new(format!("{what} is not UTF-8")))
    }

    /// A `sequence<uint8>` / `uint8[]`, borrowed.
    pub fn bytes(&mut self, what: &str) -> DecodeResult<&'a [u8]> {
        let len = self.u32(what)? as usize;
        self.take(len, what)
    }

    pub fn f64_array<const N: usize>(&mut self, what: &str) -> DecodeResult<[f64; N]> {
        let mut out = [0.0; N];
        for v in out.iter_mut() {
            *v = self.f64(what)?;
        }
        Ok(out)
    }

    pub fn f64_seq(&mut self, what: &str) -> DecodeResult<Vec<f64>> {
        let n = self.seq_len_of(what, 8)?;
        (0..n).map(|_| self.f64(what)).collect()
    }

    /// A sequence's element count, each element at least `min_wire_bytes` on the wire: a count
    /// the bytes remaining cannot hold is an error before anything is allocated for it.
    pub fn seq_len_of(&mut self, what: &str, min_wire_bytes: usize) -> DecodeResult<usize> {
        let n = self.u32(what)? as usize;
        let remaining = self.data.len().saturating_sub(self.pos);
        if n > remaining / min_wire_bytes.max(1) {
            return Err(DecodeError::new(format!(
                "{what}: sequence length {n} exceeds the {remaining} bytes left in the payload"
            )));
        }
        Ok(n)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_sequence_count_is_bounded_by_the_bytes_left() {
        // Header, then a count of 3 elements of at least 8 bytes with 16 bytes left.
        let mut p = vec![0, 1, 0, 0, 3, 0, 0, 0];
        p.extend_from_slice(&[0; 16]);
        let mut r = CdrReader::new(&p).unwrap();
        let e = r.seq_len_of("poses", 8).unwrap_err();
        assert!(
            e.0.contains("poses: sequence length 3 exceeds the 16 bytes"),
            "{e:?}"
        );
        let mut r = CdrReader::new(&p).unwrap();
        assert_eq!(r.seq_len_of("poses", 4).unwrap(), 3);
    }

    #[test]
    fn reads_aligned_little_endian() {
        // header, u8, pad to 4, u32 = 7, pad to 8, f64 = 1.5, string "ab"
        let mut p = vec![0, 1, 0, 0, 9, 0, 0, 0, 7, 0, 0, 0];
        p.extend_from_slice(&1.5f64.to_le_bytes());
        p.extend_from_slice(&[3, 0, 0, 0, b'a', b'b', 0]);
        let mut r = CdrReader::new(&p).unwrap();
        assert_eq!(r.u8("a").unwrap(), 9);
        assert_eq!(r.u32("b").unwrap(), 7);
        assert_eq!(r.f64("c").unwrap(), 1.5);
        assert_eq!(r.string("d").unwrap(), "ab");
        assert!(r.u32("e").unwrap_err().0.contains("truncated"));
    }

    #[test]
    fn reads_big_endian() {
        let p = [0, 0, 0, 0, 0, 0, 0, 7];
        assert_eq!(CdrReader::new(&p).unwrap().u32("x").unwrap(), 7);
        assert!(CdrReader::new(&[1, 2]).is_err());
        assert!(CdrReader::new(&[0, 9, 0, 0]).is_err());
    }
}

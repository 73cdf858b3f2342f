//! A minimal protobuf wire-format reader: enough to walk the fields of Foxglove's messages.
//!
//! Each field is a key varint (`number << 3 | wire type`) followed by a varint, a fixed 64/32-bit
//! value or a length-delimited slice. Unknown fields are skipped, so newer schema versions that
//! add fields still decode.

use super::error::{DecodeError, DecodeResult};

#[derive(Clone, Copy, Debug)]
pub enum Value<'a> {
    Varint(u64),
    Fixed64(u64),
    Fixed32(u32),
    Bytes(&'a [u8]),
}

impl<'a> Value<'a> {
    pub fn as_u64(self) -> u64 {
        match self {
            Value::Varint(v) | Value::Fixed64(v) => v,
            Value::Fixed32(v) => v as u64,
            Value::Bytes(_) => 0,
        }
    }
    pub fn as_f64(self) -> f64 {
        match self {
            Value::Fixed64(v) => f64::from_bits(v),
            Value::Fixed32(v) => f32::from_bits(v) as f64,
            Value::Varint(v) => v as f64,
            Value::Bytes(_) => f64::NAN,
        }
    }
    pub fn as_bytes(self) -> &'a [u8] {
        match self {
            Value::Bytes(b) => b,
            _ => &[],
        }
    }
    pub fn as_string(self) -> String {
        String::from_utf8_lossy(self.as_bytes()).into_owned()
    }
    /// A repeated double, packed or a single unpacked element.
    pub fn as_f64s(self) -> Vec<f64> {
        match self {
            Value::Bytes(b) => b
                .chunks_exact(8)
                .map(|c| f64::from_le_bytes(c.try_into().unwrap_or([0; 8])))
                .collect(),
            other => vec![other.as_f64()],
        }
    }
}

fn varint(buf: &[u8], pos: &mut usize) -> DecodeResult<u64> {
    let mut v = 0u64;
    for shift in (0..64).step_by(7) {
        let b = *buf
            .get(*pos)
            .ok_or_else(|| DecodeError::new("truncated protobuf varint"))?;
        *pos += 1;
        v |= ((b & 0x7f) as u64) << shift;
        if b & 0x80 == 0 {
            return Ok(v);
        }
    }
    Err(DecodeError::new("protobuf varint longer than 10 bytes"))
}

/// All fields of a message, in order: (field number, value).
pub fn fields(buf: &[u8]) -> DecodeResult<Vec<(u32, Value<'_>)>> {
    let mut out = Vec::new();
    let mut pos = 0usize;
    while pos < buf.len() {
        let key = varint(buf, &mut pos)?;
        let number = (key >> 3) as u32;
        let take = |pos: &mut usize, n: usize| -> DecodeResult<&[u8]> {
            let end = pos
                .checked_add(n)
                .filter(|&e| e <= buf.len())
                .ok_or_else(|| DecodeError::new(format!("truncated protobuf field {number}")))?;
            let s = &buf[*pos..end];
            *pos = end;
            Ok(s)
        };
        let value = match key & 7 {
            0 => Value::Varint(varint(buf, &mut pos)?),
            1 => Value::Fixed64(u64::from_le_bytes(
                take(&mut pos, 8)?.try_into().unwrap_or([0; 8]),
            )),
            2 => {
                let len = varint(buf, &mut pos)? as usize;
                Value::Bytes(take(&mut pos, len)?)
            }
            5 => Value::Fixed32(u32::from_le_bytes(
                take(&mut pos, 4)?.try_into().unwrap_or([0; 4]),
            )),
            w => {
                return Err(DecodeError::new(format!(
                    "unsupported protobuf wire type {w} in field {number}"
                )));
            }
        };
        out.push((number, value));
    }
    Ok(out)
}

/// Last value of field `n` (protobuf's rule for repeated non-repeated fields).
pub fn get<'a>(f: &[(u32, Value<'a>)], n: u32) -> Option<Value<'a>> {
    f.iter().rev().find(|(k, _)| *k == n).map(|(_, v)| *v)
}

pub fn all<'a, 'f>(f: &'f [(u32, Value<'a>)], n: u32) -> impl Iterator<Item = Value<'a>> + 'f {
    f.iter().filter(move |(k, _)| *k == n).map(|(_, v)| *v)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_each_wire_type() {
        // field 1 varint 150; field 2 bytes "hi"; field 3 double 1.5; field 4 fixed32 7
        let mut b = vec![0x08, 0x96, 0x01, 0x12, 2, b'h', b'i', 0x19];
        b.extend_from_slice(&1.5f64.to_le_bytes());
        b.extend_from_slice(&[0x25, 7, 0, 0, 0]);
        let f = fields(&b).unwrap();
        assert_eq!(get(&f, 1).unwrap().as_u64(), 150);
        assert_eq!(get(&f, 2).unwrap().as_string(), "hi");
        assert_eq!(get(&f, 3).unwrap().as_f64(), 1.5);
        assert_eq!(get(&f, 4).unwrap().as_u64(), 7);
        assert!(fields(&[0x12, 5, 1]).is_err());
    }
}

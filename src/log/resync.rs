//! Finding one's place again in a damaged MCAP: the next chunk record after a bad one.
//!
//! How it works: a walk over the top-level records that meets a length which cannot be right (it
//! runs past the end of the file) or an opcode of 0 has lost its place, but the chunks after the
//! damage are usually intact. [`next_chunk_after`] scans forward block by block for a byte
//! 0x06 (the chunk opcode) whose record length and chunk header agree with each other: a
//! compression of "", "lz4" or "zstd", a start time not after the end time, and the records'
//! length plus the header's fixed fields equal to the record length, all within the file.
//! Compressed bytes pass those checks together by chance with vanishing probability, and a
//! chunk's own records never contain a chunk, so a match is a chunk.

use mcap::records::op;

/// Bytes scanned per read.
const BLOCK_BYTES: u64 = 1 << 20;
/// The opcode and length prefix plus a chunk header's fixed fields (start and end time,
/// uncompressed size and CRC, the compression string's length).
const FIXED_HEAD: usize = 9 + 8 + 8 + 8 + 4 + 4;
/// The longest chunk header checked: the fixed part, "zstd" and the records' length.
const LONGEST_HEAD: usize = FIXED_HEAD + 4 + 8;

/// The offset of the first chunk record that starts after `from` and fits in the file, read
/// through `read_at(offset, len)`; `None` if there is none (or the file cannot be read).
pub(super) fn next_chunk_after(
    read_at: impl Fn(u64, u64) -> std::io::Result<Vec<u8>>,
    from: u64,
    file_len: u64,
) -> Option<u64> {
    let mut block_start = from.checked_add(1)?;
    while block_start < file_len {
        let len = (BLOCK_BYTES + LONGEST_HEAD as u64).min(file_len - block_start);
        let block = read_at(block_start, len).ok()?;
        let scanned = (BLOCK_BYTES as usize).min(block.len());
        for i in 0..scanned {
            if block[i] == op::CHUNK && is_chunk_head(&block[i..], block_start + i as u64, file_len)
            {
                return Some(block_start + i as u64);
            }
        }
        block_start += BLOCK_BYTES;
    }
    None
}

/// Whether `head` (the bytes from a candidate opcode on) starts a chunk record at `offset` that
/// ends within `file_len`.
fn is_chunk_head(head: &[u8], offset: u64, file_len: u64) -> bool {
    let u64_at = |at: usize| -> Option<u64> {
        head.get(at..at + 8)
            .and_then(|b| b.try_into().ok())
            .map(u64::from_le_bytes)
    };
    let (Some(record_len), Some(start_time), Some(end_time)) = (u64_at(1), u64_at(9), u64_at(17))
    else {
        return false;
    };
    if offset.saturating_add(9).saturating_add(record_len) > file_len || start_time > end_time {
        return false;
    }
    let Some(compression_len) = head
        .get(FIXED_HEAD - 4..FIXED_HEAD)
        .and_then(|b| b.try_into().ok())
        .map(u32::from_le_bytes)
    else {
        return false;
    };
    let compression_len = compression_len as usize;
    let compression = head.get(FIXED_HEAD..FIXED_HEAD + compression_len.min(4));
    if !matches!(compression, Some(b"" | b"lz4" | b"zstd")) || compression_len > 4 {
        return false;
    }
    let Some(records_len) = u64_at(FIXED_HEAD + compression_len) else {
        return false;
    };
    // The chunk body is its fixed fields, the compression string and the records.
    let body_fixed = (FIXED_HEAD - 9 + compression_len + 8) as u64;
    body_fixed.checked_add(records_len) == Some(record_len)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A chunk record with `records` as its (uncompressed) records.
    fn chunk(records: &[u8], compression: &str) -> Vec<u8> {
        let mut body = Vec::new();
        body.extend(1u64.to_le_bytes());
        body.extend(2u64.to_le_bytes());
        body.extend((records.len() as u64).to_le_bytes());
        body.extend(0u32.to_le_bytes());
        body.extend((compression.len() as u32).to_le_bytes());
        body.extend(compression.as_bytes());
        body.extend((records.len() as u64).to_le_bytes());
        body.extend(records);
        let mut out = vec![op::CHUNK];
        out.extend((body.len() as u64).to_le_bytes());
        out.extend(body);
        out
    }

    fn reader(bytes: &[u8]) -> impl Fn(u64, u64) -> std::io::Result<Vec<u8>> + '_ {
        |offset, len| {
            let (a, b) = (offset as usize, (offset + len) as usize);
            bytes
                .get(a..b)
                .map(<[u8]>::to_vec)
                .ok_or_else(|| std::io::Error::other("past the end"))
        }
    }

    #[test]
    fn the_next_chunk_is_found_past_noise_that_holds_chunk_opcodes() {
        // Noise full of 0x06 bytes with lengths that run past the end, then a real chunk.
        let mut bytes = vec![0x06u8; 300];
        bytes[100] = 0x06;
        let at = bytes.len() as u64;
        bytes.extend(chunk(b"\x06\x06\x06records", "zstd"));
        bytes.extend(chunk(b"more", ""));
        let len = bytes.len() as u64;
        assert_eq!(next_chunk_after(reader(&bytes), 0, len), Some(at));
        // From the first chunk on, the second is next.
        let second = at + chunk(b"\x06\x06\x06records", "zstd").len() as u64;
        assert_eq!(next_chunk_after(reader(&bytes), at, len), Some(second));
        assert_eq!(next_chunk_after(reader(&bytes), second, len), None);
    }

    #[test]
    fn a_chunk_that_would_run_past_the_end_or_names_another_compression_is_not_one() {
        // Each after one byte, where the search (from byte 0, so starting at 1) looks first.
        let after_a_byte = |record: Vec<u8>| [vec![0u8], record].concat();
        let whole = after_a_byte(chunk(b"records", "lz4"));
        let len = whole.len() as u64;
        assert_eq!(next_chunk_after(reader(&whole), 0, len), Some(1));
        // The file one byte shorter than the record needs.
        assert_eq!(next_chunk_after(reader(&whole), 0, len - 1), None);
        assert_eq!(
            next_chunk_after(reader(&whole[..whole.len() - 1]), 0, len - 1),
            None
        );
        let odd = after_a_byte(chunk(b"records", "gzip"));
        assert_eq!(next_chunk_after(reader(&odd), 0, odd.len() as u64), None);
        // A records length one short of what the record length says.
        let mut short = after_a_byte(chunk(b"records", ""));
        let at = 1 + FIXED_HEAD;
        let records_len = u64::from_le_bytes(short[at..at + 8].try_into().unwrap());
        short[at..at + 8].copy_from_slice(&(records_len - 1).to_le_bytes());
        assert_eq!(
            next_chunk_after(reader(&short), 0, short.len() as u64),
            None
        );
    }
}

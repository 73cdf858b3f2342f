//! The MCAP container: channels, chunk locations and random access to single messages.
//!
//! How it works: [`McapContainer::open`] reads only the summary section (channels, schemas, chunk
//! indexes) when the file has one; otherwise it walks the top-level records once, skipping chunk
//! bodies except to pick up channel and schema records. [`McapContainer::scan`] then
//! decompresses chunks in parallel (one at a time per thread, so memory stays bounded) and hands
//! every message to a visitor, which keeps only what it needs plus a [`MessageRef`] to fetch the
//! payload again later through a small LRU cache of decompressed chunks.
//!
//! A truncated or corrupt region ends the walk with a [`Problem`]; whatever came before it stays
//! usable. Nothing here panics on bad input.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::ops::Deref;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use mcap::records::{Record, op};
use rayon::prelude::*;

use super::error::{LogError, Problem, Problems};

const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";
/// Bytes of decompressed chunks kept for reading payloads again (least recently used first out).
const CHUNK_CACHE_BYTES: usize = 256 << 20;
/// Refuse single records larger than this (a corrupt length would otherwise allocate wildly).
const MAX_RECORD_BYTES: u64 = 4 << 30;
/// Output reserved up front when decompressing: the declared size, up to this bound (a corrupt
/// header cannot make us reserve more; larger chunks grow as they really decompress).
const PREALLOCATE_BYTES: usize = 256 << 20;

#[derive(Clone, Debug, PartialEq)]
pub struct ChannelInfo {
    pub id: u16,
    pub topic: String,
    pub message_encoding: String,
    pub schema_name: String,
    pub schema_encoding: String,
    pub schema_data: Arc<Vec<u8>>,
}

/// Where a chunk record lives in the file.
#[derive(Clone, Copy, Debug)]
pub struct ChunkLoc {
    /// Offset of the chunk record's opcode.
    pub offset: u64,
    /// Length of the whole record, including its 9-byte opcode + length prefix.
    pub length: u64,
}

/// Where one message's payload lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Location {
    /// Inside decompressed chunk `chunk`, payload bytes `[start, end)`.
    Chunk { chunk: u32, start: u32, end: u32 },
    /// A message record outside chunks; payload bytes `[start, end)` of the file.
    File { start: u64, end: u64 },
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MessageRef {
    pub channel_id: u16,
    pub log_time_nanos: u64,
    pub publish_time_nanos: u64,
    pub location: Location,
}

/// A message payload: a slice of a shared decompressed chunk (or an owned buffer).
#[derive(Clone, Debug)]
pub struct MessageBytes {
    buf: Arc<Vec<u8>>,
    start: usize,
    end: usize,
}

impl Deref for MessageBytes {
    type Target = [u8];
    fn deref(&self) -> &[u8] {
        &self.buf[self.start..self.end]
    }
}

/// A chunk or message the index points at that cannot be read (out of the file, not a chunk,
/// not decompressible); the drive reports it as a problem of that message.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct RecordError(String);

impl From<String> for RecordError {
    fn from(what: String) -> Self {
        Self(what)
    }
}

pub struct McapContainer {
    path: PathBuf,
    file: Mutex<File>,
    pub file_len: u64,
    pub channels: BTreeMap<u16, ChannelInfo>,
    pub chunks: Vec<ChunkLoc>,
    loose: Vec<(u16, u64, u64, Location)>,
    /// Whether the summary section (chunk indexes) was used to find the chunks.
    pub used_summary: bool,
    pub library: Option<String>,
    pub profile: Option<String>,
    pub problems: Problems,
    cache: Mutex<ByteLru<u32, Vec<u8>>>,
}

impl std::fmt::Debug for McapContainer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapContainer")
            .field("path", &self.path)
            .field("channels", &self.channels.len())
            .field("chunks", &self.chunks.len())
            .finish_non_exhaustive()
    }
}

impl McapContainer {
    pub fn open(path: &Path) -> Result<Self, LogError> {
        let io = |source| LogError::Io {
            path: path.to_path_buf(),
            source,
        };
        let not_mcap = |what: String| LogError::NotMcap {
            path: path.to_path_buf(),
            what,
        };
        // One look before opening: opening a named pipe blocks until something writes to it.
        let kind = std::fs::metadata(path).map(|m| (m.is_dir(), m.is_file()));
        if let Ok((true, _)) = kind {
            // A rosbag2 folder holds its .mcap files and a metadata.yaml.
            let mcaps: Vec<String> = std::fs::read_dir(path)
                .map(|entries| {
                    entries
                        .filter_map(|e| e.ok())
                        .map(|e| e.file_name().to_string_lossy().into_owned())
                        .filter(|n| n.ends_with(".mcap"))
                        .collect()
                })
                .unwrap_or_default();
            return Err(not_mcap(if mcaps.is_empty() {
                "it is a directory, not a file".into()
            } else {
                format!(
                    "it is a directory (a rosbag2 folder?); give one of its MCAP files: {}",
                    mcaps.join(", ")
                )
            }));
        }
        if let Ok((_, false)) = kind {
            return Err(not_mcap(
                "it is not a regular file (a pipe or device); an MCAP is read by seeking".into(),
            ));
        }
        let mut file = File::open(path).map_err(io)?;
        let file_len = file.metadata().map_err(io)?.len();
        if file_len == 0 {
            return Err(not_mcap("the file is empty".into()));
        }
        let mut magic = [0u8; 8];
        if file_len < 8 || file.read_exact(&mut magic).is_err() || &magic != MAGIC {
            return Err(not_mcap(
                "the file does not start with the MCAP magic bytes".into(),
            ));
        }
        let mut c = Self {
            path: path.to_path_buf(),
            file: Mutex::new(file),
            file_len,
            channels: BTreeMap::new(),
            chunks: Vec::new(),
            loose: Vec::new(),
            used_summary: false,
            library: None,
            profile: None,
            problems: Problems::new(),
            cache: Mutex::new(ByteLru::new(CHUNK_CACHE_BYTES)),
        };
        c.read_header();
        if !c.try_summary() {
            c.linear_walk()?;
        }
        Ok(c)
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    fn read_at(&self, offset: u64, len: u64) -> std::io::Result<Vec<u8>> {
        if offset.saturating_add(len) > self.file_len || len > MAX_RECORD_BYTES {
            return Err(std::io::Error::new(
                std::io::ErrorKind::UnexpectedEof,
                "record runs past the end of the file",
            ));
        }
        let mut f = self
            .file
            .lock()
            .map_err(|_| std::io::Error::other("file lock poisoned"))?;
        f.seek(SeekFrom::Start(offset))?;
        let mut buf = vec![0u8; len as usize];
        f.read_exact(&mut buf)?;
        Ok(buf)
    }

    fn read_header(&mut self) {
        // The header record follows the magic: opcode 0x01, then profile and library strings.
        let Ok(prefix) = self.read_at(8, 9) else {
            return;
        };
        if prefix[0] != op::HEADER {
            return;
        }
        let len = u64::from_le_bytes(prefix[1..9].try_into().unwrap_or([0; 8]));
        if let Ok(body) = self.read_at(17, len)
            && let Ok(Record::Header(h)) = mcap::parse_record(op::HEADER, &body)
        {
            self.profile = Some(h.profile);
            self.library = Some(h.library);
        }
    }

    /// Channels and chunk locations from the summary section; false if it is absent or unusable.
    fn try_summary(&mut self) -> bool {
        use mcap::sans_io::{SummaryReadEvent, SummaryReader, SummaryReaderOptions};
        // A damaged closing magic in front of which the footer record is intact: read the
        // summary as if the magic were right (the chunk offsets are still checked below).
        let patch_end_magic = self.end_magic_damaged_before_a_footer();
        let end_magic_at = self.file_len - MAGIC.len() as u64;
        let Ok(mut guard) = self.file.lock() else {
            return false;
        };
        let file: &mut File = &mut guard;
        let mut reader = SummaryReader::new_with_options(
            SummaryReaderOptions::default().with_file_size(self.file_len),
        );
        let mut position = 0u64;
        while let Some(event) = reader.next_event() {
            match event {
                Ok(SummaryReadEvent::ReadRequest(n)) => {
                    let buf = reader.insert(n);
                    match file.read(buf) {
                        Ok(read) => {
                            if patch_end_magic {
                                overwrite_end_magic(&mut buf[..read], position, end_magic_at);
                            }
                            position += read as u64;
                            reader.notify_read(read)
                        }
                        Err(_) => return false,
                    }
                }
                Ok(SummaryReadEvent::SeekRequest(to)) => match file.seek(to) {
                    Ok(pos) => {
                        position = pos;
                        reader.notify_seeked(pos)
                    }
                    Err(_) => return false,
                },
                Err(e) => {
                    drop(guard);
                    self.problems.push(Problem::file(format!(
                        "its summary section is unusable ({e}), so it was read from the start"
                    )));
                    return false;
                }
            }
        }
        drop(guard);
        let Some(summary) = reader.finish() else {
            return false;
        };
        // Messages outside chunks (or a summary without statistics, which the spec allows and
        // which then cannot say there are none): only a linear walk finds them.
        let may_have_messages = summary.stats.as_ref().is_none_or(|s| s.message_count > 0);
        if summary.chunk_indexes.is_empty() && may_have_messages {
            return false;
        }
        for (id, ch) in &summary.channels {
            self.channels.insert(
                *id,
                channel_info(ch.id, &ch.topic, &ch.message_encoding, ch.schema.as_deref()),
            );
        }
        let mut chunks: Vec<ChunkLoc> = summary
            .chunk_indexes
            .iter()
            .map(|ci| ChunkLoc {
                offset: ci.chunk_start_offset,
                length: ci.chunk_length,
            })
            .collect();
        chunks.sort_by_key(|c| c.offset);
        for c in &chunks {
            if c.offset.saturating_add(c.length) > self.file_len {
                return false;
            }
        }
        if patch_end_magic {
            self.problems.push(Problem::file(
                "its closing magic bytes are damaged; the summary before them was used",
            ));
        }
        self.chunks = chunks;
        self.used_summary = true;
        true
    }

    /// Whether the file's last 8 bytes are not the MCAP magic while a footer record (opcode
    /// 0x02, 20 bytes long) sits right before them.
    fn end_magic_damaged_before_a_footer(&self) -> bool {
        const FOOTER_RECORD: u64 = 9 + 20;
        let Some(footer_at) = self
            .file_len
            .checked_sub(FOOTER_RECORD + MAGIC.len() as u64)
        else {
            return false;
        };
        match self.read_at(footer_at, FOOTER_RECORD + MAGIC.len() as u64) {
            Ok(tail) => {
                &tail[FOOTER_RECORD as usize..] != MAGIC
                    && tail[0] == op::FOOTER
                    && tail[1..9] == 20u64.to_le_bytes()
            }
            Err(_) => false,
        }
    }

    /// Walk the top-level records from the start; stop at the footer or at the first damage.
    fn linear_walk(&mut self) -> Result<(), LogError> {
        let mut offset = 8u64;
        let mut schemas: BTreeMap<u16, (String, String, Arc<Vec<u8>>)> = BTreeMap::new();
        let mut raw_channels: Vec<mcap::records::Channel> = Vec::new();
        loop {
            if offset == self.file_len {
                self.problems
                    .push(Problem::file("the file ends without a footer (truncated?)"));
                break;
            }
            let prefix = match self.read_at(offset, 9) {
                Ok(p) => p,
                Err(_) => {
                    self.problems.push(Problem::file(format!(
                        "truncated record header at byte {offset}"
                    )));
                    break;
                }
            };
            let opcode = prefix[0];
            let len = u64::from_le_bytes(prefix[1..9].try_into().unwrap_or([0; 8]));
            let body_offset = offset + 9;
            if body_offset.saturating_add(len) > self.file_len {
                let what = format!(
                    "record (opcode {opcode:#04x}) at byte {offset} claims {len} bytes but the file ends first (truncated)"
                );
                match self.resync(offset, what) {
                    Some(next) => {
                        offset = next;
                        continue;
                    }
                    None => break,
                }
            }
            match opcode {
                op::SCHEMA | op::CHANNEL | op::CHUNK => {
                    let body = self
                        .read_at(body_offset, len)
                        .map_err(|e| self.corrupt(offset, e.to_string()))?;
                    if opcode == op::CHUNK {
                        self.chunks.push(ChunkLoc {
                            offset,
                            length: len + 9,
                        });
                        match decompress_chunk(&body) {
                            Ok(data) => {
                                // The message walk reports a chunk's damage; here only the
                                // definitions are collected.
                                let _ = for_each_record(&data, |op, body, _| {
                                    collect_definition(op, body, &mut schemas, &mut raw_channels)
                                });
                            }
                            Err(what) => self
                                .problems
                                .push(Problem::file(format!("chunk at byte {offset}: {what}"))),
                        }
                    } else {
                        collect_definition(opcode, &body, &mut schemas, &mut raw_channels);
                    }
                }
                op::MESSAGE => {
                    if len >= 22 {
                        let body = self
                            .read_at(body_offset, 22)
                            .map_err(|e| self.corrupt(offset, e.to_string()))?;
                        let channel_id = u16::from_le_bytes([body[0], body[1]]);
                        let log_time = u64::from_le_bytes(body[6..14].try_into().unwrap_or([0; 8]));
                        let publish_time =
                            u64::from_le_bytes(body[14..22].try_into().unwrap_or([0; 8]));
                        let location = Location::File {
                            start: body_offset + 22,
                            end: body_offset + len,
                        };
                        self.loose
                            .push((channel_id, log_time, publish_time, location));
                    } else {
                        self.problems.push(Problem::file(format!(
                            "message record at byte {offset} is too short"
                        )));
                    }
                }
                // The summary section after the data end repeats every schema and channel: a
                // walk that skipped a damaged chunk (or met one that defined them) finds them
                // there.
                op::FOOTER => break,
                0 => {
                    let what = format!("invalid opcode 0 at byte {offset}");
                    match self.resync(offset, what) {
                        Some(next) => {
                            offset = next;
                            continue;
                        }
                        None => break,
                    }
                }
                _ => {}
            }
            offset = body_offset + len;
        }
        for ch in raw_channels {
            let schema = schemas.get(&ch.schema_id);
            let info = ChannelInfo {
                id: ch.id,
                topic: ch.topic.clone(),
                message_encoding: ch.message_encoding.clone(),
                schema_name: schema.map(|s| s.0.clone()).unwrap_or_default(),
                schema_encoding: schema.map(|s| s.1.clone()).unwrap_or_default(),
                schema_data: schema.map(|s| s.2.clone()).unwrap_or_default(),
            };
            self.channels.insert(ch.id, info);
        }
        if self.channels.is_empty() && self.chunks.is_empty() && self.loose.is_empty() {
            // Every reason, in the order met: why the summary was not used, then where the
            // walk from the start stopped.
            let what = if self.problems.is_empty() {
                "no records".to_string()
            } else {
                let reasons: Vec<&str> = self.problems.iter().map(|p| p.what.as_str()).collect();
                reasons.join("; ")
            };
            return Err(LogError::Unusable {
                path: self.path.clone(),
                what: format!("no channels or messages found: {what}"),
            });
        }
        Ok(())
    }

    /// After damage at `offset` (described by `what`): the next chunk's offset, recorded with
    /// the bytes skipped, or `None` (recorded as where reading stopped).
    fn resync(&mut self, offset: u64, what: String) -> Option<u64> {
        let next =
            super::resync::next_chunk_after(|at, len| self.read_at(at, len), offset, self.file_len);
        self.problems.push(Problem::file(match next {
            Some(next) => format!(
                "{what}; skipped {} bytes to the next chunk at byte {next}",
                next - offset
            ),
            None => format!("{what}; no chunk follows, so reading stopped there"),
        }));
        next
    }

    fn corrupt(&self, offset: u64, what: String) -> LogError {
        LogError::Corrupt {
            path: self.path.clone(),
            offset,
            what,
        }
    }

    /// Empty the cache of decompressed chunks.
    pub fn release_cache(&self) {
        if let Ok(mut cache) = self.cache.lock() {
            cache.clear();
        }
    }

    /// Decompressed records of chunk `index`, through the LRU cache.
    pub fn chunk_data(&self, index: u32) -> Result<Arc<Vec<u8>>, RecordError> {
        if let Ok(mut cache) = self.cache.lock()
            && let Some(hit) = cache.get(&index)
        {
            return Ok(hit);
        }
        let data = Arc::new(self.load_chunk(index)?);
        if let Ok(mut cache) = self.cache.lock() {
            cache.put(index, data.clone(), data.len());
        }
        Ok(data)
    }

    fn load_chunk(&self, index: u32) -> Result<Vec<u8>, RecordError> {
        let loc = self
            .chunks
            .get(index as usize)
            .ok_or_else(|| format!("no chunk {index}"))?;
        let record = self
            .read_at(loc.offset, loc.length)
            .map_err(|e| format!("chunk at byte {}: {e}", loc.offset))?;
        if record.first() != Some(&op::CHUNK) || record.len() < 9 {
            return Err(format!(
                "the index points at byte {} but no chunk is there",
                loc.offset
            )
            .into());
        }
        decompress_chunk(&record[9..])
            .map_err(|e| format!("chunk at byte {}: {e}", loc.offset).into())
    }

    /// The payload of one message.
    pub fn message_bytes(&self, r: &MessageRef) -> Result<MessageBytes, RecordError> {
        match r.location {
            Location::Chunk { chunk, start, end } => {
                let buf = self.chunk_data(chunk)?;
                if end as usize > buf.len() || start > end {
                    return Err(RecordError("message location outside its chunk".into()));
                }
                Ok(MessageBytes {
                    buf,
                    start: start as usize,
                    end: end as usize,
                })
            }
            Location::File { start, end } => {
                let buf = self
                    .read_at(start, end - start)
                    .map_err(|e| RecordError(e.to_string()))?;
                let len = buf.len();
                Ok(MessageBytes {
                    buf: Arc::new(buf),
                    start: 0,
                    end: len,
                })
            }
        }
    }

    /// Visit every message once, chunks in parallel; `visit` returns what to keep. Results come
    /// back in file order. Damaged chunks become problems.
    pub fn scan<T, F>(&self, visit: F) -> (Vec<(MessageRef, T)>, Problems)
    where
        T: Send,
        F: Fn(&MessageRef, &ChannelInfo, &[u8]) -> Option<T> + Sync,
    {
        let per_chunk: Vec<(Vec<(MessageRef, T)>, Problems)> = (0..self.chunks.len() as u32)
            .into_par_iter()
            .map(|index| {
                let mut kept = Vec::new();
                let mut problems = Problems::new();
                let data = match self.load_chunk(index) {
                    Ok(d) => d,
                    Err(what) => {
                        problems.push(Problem::file(what.0));
                        return (kept, problems);
                    }
                };
                let damage = for_each_record(&data, |opcode, body, body_start| {
                    if opcode != op::MESSAGE || body.len() < 22 {
                        return;
                    }
                    let channel_id = u16::from_le_bytes([body[0], body[1]]);
                    let log_time = u64::from_le_bytes(body[6..14].try_into().unwrap_or([0; 8]));
                    let publish_time =
                        u64::from_le_bytes(body[14..22].try_into().unwrap_or([0; 8]));
                    let Some(channel) = self.channels.get(&channel_id) else {
                        problems.push(Problem::file(format!(
                            "message on unknown channel id {channel_id}"
                        )));
                        return;
                    };
                    let r = MessageRef {
                        channel_id,
                        log_time_nanos: log_time,
                        publish_time_nanos: publish_time,
                        location: Location::Chunk {
                            chunk: index,
                            start: (body_start + 22) as u32,
                            end: (body_start + body.len()) as u32,
                        },
                    };
                    if let Some(t) = visit(&r, channel, &body[22..]) {
                        kept.push((r, t));
                    }
                });
                if let Some(what) = damage {
                    problems.push(Problem::file(format!("chunk {index}: {what}")));
                }
                (kept, problems)
            })
            .collect();
        let mut kept = Vec::new();
        let mut problems = Problems::new();
        for (k, p) in per_chunk {
            kept.extend(k);
            problems.append(p);
        }
        for &(channel_id, log_time, publish_time, location) in &self.loose {
            let r = MessageRef {
                channel_id,
                log_time_nanos: log_time,
                publish_time_nanos: publish_time,
                location,
            };
            let Some(channel) = self.channels.get(&channel_id) else {
                problems.push(Problem::file(format!(
                    "message on unknown channel id {channel_id}"
                )));
                continue;
            };
            match self.message_bytes(&r) {
                Ok(bytes) => {
                    if let Some(t) = visit(&r, channel, &bytes) {
                        kept.push((r, t));
                    }
                }
                Err(what) => problems.push(Problem::message(&channel.topic, log_time, what.0)),
            }
        }
        (kept, problems)
    }
}

/// Write the MCAP magic over the bytes of `buf` (read from file offset `position`) that fall in
/// the file's last 8 bytes, which start at `end_magic_at`.
fn overwrite_end_magic(buf: &mut [u8], position: u64, end_magic_at: u64) {
    for (i, byte) in buf.iter_mut().enumerate() {
        let at = position + i as u64;
        if at >= end_magic_at
            && let Some(&m) = MAGIC.get((at - end_magic_at) as usize)
        {
            *byte = m;
        }
    }
}

fn channel_info(
    id: u16,
    topic: &str,
    message_encoding: &str,
    schema: Option<&mcap::Schema<'_>>,
) -> ChannelInfo {
    ChannelInfo {
        id,
        topic: topic.to_string(),
        message_encoding: message_encoding.to_string(),
        schema_name: schema.map(|s| s.name.clone()).unwrap_or_default(),
        schema_encoding: schema.map(|s| s.encoding.clone()).unwrap_or_default(),
        schema_data: Arc::new(schema.map(|s| s.data.to_vec()).unwrap_or_default()),
    }
}

fn collect_definition(
    opcode: u8,
    body: &[u8],
    schemas: &mut BTreeMap<u16, (String, String, Arc<Vec<u8>>)>,
    channels: &mut Vec<mcap::records::Channel>,
) {
    match (opcode, mcap::parse_record(opcode, body)) {
        (op::SCHEMA, Ok(Record::Schema { header, data })) => {
            schemas.insert(
                header.id,
                (header.name, header.encoding, Arc::new(data.into_owned())),
            );
        }
        (op::CHANNEL, Ok(Record::Channel(ch))) if !channels.iter().any(|c| c.id == ch.id) => {
            channels.push(ch);
        }
        _ => {}
    }
}

/// Call `f(opcode, body, body_offset)` for each record in a decompressed chunk; stops quietly at
/// a record that runs past the end (the caller sees fewer messages, never a panic).
/// Call `f(opcode, body, body_start)` for each record of a chunk's records. Returns what
/// was wrong where the walk had to stop before the end (a record running past the chunk, or
/// a few bytes too short for a record's prefix), so the records it lost are reported.
fn for_each_record(data: &[u8], mut f: impl FnMut(u8, &[u8], usize)) -> Option<String> {
    let mut pos = 0usize;
    while pos + 9 <= data.len() {
        let opcode = data[pos];
        let len = u64::from_le_bytes(data[pos + 1..pos + 9].try_into().unwrap_or([0; 8]));
        let start = pos + 9;
        let end = usize::try_from(len).ok().and_then(|l| start.checked_add(l));
        match end {
            Some(end) if end <= data.len() => {
                f(opcode, &data[start..end], start);
                pos = end;
            }
            _ => {
                return Some(format!(
                    "a record at byte {pos} of the chunk's {} claims {len} bytes, past the chunk's end: the {} bytes after it are skipped",
                    data.len(),
                    data.len() - pos
                ));
            }
        }
    }
    (pos < data.len()).then(|| {
        format!(
            "the chunk's last {} bytes are too few for a record: skipped",
            data.len() - pos
        )
    })
}

/// Decompress a chunk record body (without its 9-byte prefix) into its records.
fn decompress_chunk(body: &[u8]) -> Result<Vec<u8>, String> {
    let header = match mcap::parse_record(op::CHUNK, body) {
        Ok(Record::Chunk { header, data }) => (header, data),
        Ok(_) => return Err("not a chunk".into()),
        Err(e) => return Err(format!("cannot parse chunk: {e}")),
    };
    let (header, data) = header;
    if header.uncompressed_size > MAX_RECORD_BYTES {
        return Err(format!(
            "chunk claims {} uncompressed bytes",
            header.uncompressed_size
        ));
    }
    let size = header.uncompressed_size as usize;
    let out = match header.compression.as_str() {
        "" => data.into_owned(),
        // Streaming decoders bounded by the declared size: a corrupt header cannot make us
        // allocate more than the data actually expands to.
        // Usual case: one-shot decompression into exactly the declared size.
        "zstd" if size <= PREALLOCATE_BYTES => {
            let mut out = Vec::with_capacity(size);
            zstd::bulk::Decompressor::new()
                .and_then(|mut d| d.decompress_to_buffer(&data[..], &mut out))
                .map_err(|e| format!("zstd: {e}"))?;
            out
        }
        "zstd" => {
            let mut out = Vec::with_capacity(PREALLOCATE_BYTES);
            zstd::stream::Decoder::new(&data[..])
                .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
                .map_err(|e| format!("zstd: {e}"))?;
            out
        }
        "lz4" => {
            let mut out = Vec::with_capacity(size.min(PREALLOCATE_BYTES));
            lz4::Decoder::new(&data[..])
                .and_then(|d| d.take(size as u64 + 1).read_to_end(&mut out))
                .map_err(|e| format!("lz4: {e}"))?;
            out
        }
        other => return Err(format!("unsupported chunk compression '{other}'")),
    };
    if out.len() != size {
        return Err(format!(
            "chunk decompressed to {} bytes, header says {size}",
            out.len()
        ));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32(&out);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "chunk CRC mismatch (stored {:08x}, computed {crc:08x})",
                header.uncompressed_crc
            ));
        }
    }
    Ok(out)
}

/// CRC-32 (IEEE), as MCAP uses for chunk contents (SIMD where the CPU has it).
fn crc32(data: &[u8]) -> u32 {
    crc32fast::hash(data)
}

use super::byte_lru::ByteLru;

#[cfg(test)]
mod tests;

//! The container's cache of decompressed chunks: least recently used first out, bounded by
//! the bytes it holds (a chunk larger than the budget is still kept, alone).

use std::collections::VecDeque;
use std::sync::Arc;

/// Least-recently-used decompressed chunks, bounded by total bytes.
pub(super) struct ChunkCache {
    budget_bytes: usize,
    used_bytes: usize,
    entries: VecDeque<(u32, Arc<Vec<u8>>)>,
}

impl ChunkCache {
    pub(super) fn new(budget_bytes: usize) -> Self {
        Self {
            budget_bytes,
            used_bytes: 0,
            entries: VecDeque::new(),
        }
    }

    pub(super) fn get(&mut self, index: u32) -> Option<Arc<Vec<u8>>> {
        let pos = self.entries.iter().position(|(i, _)| *i == index)?;
        let entry = self.entries.remove(pos)?;
        let data = entry.1.clone();
        self.entries.push_back(entry);
        Some(data)
    }

    pub(super) fn put(&mut self, index: u32, data: Arc<Vec<u8>>) {
        self.used_bytes += data.len();
        self.entries.push_back((index, data));
        while self.used_bytes > self.budget_bytes && self.entries.len() > 1 {
            if let Some((_, old)) = self.entries.pop_front() {
                self.used_bytes -= old.len();
            }
        }
    }
}

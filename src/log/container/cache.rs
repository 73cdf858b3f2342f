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

    /// Drop every chunk (they are decompressed again when asked for).
    pub(super) fn clear(&mut self) {
        self.entries.clear();
        self.used_bytes = 0;
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

#[cfg(test)]
mod tests {
    use super::*;

    /// The budget holds the most recent chunks (one larger than it alone); a cleared cache
    /// holds none and counts nothing, so the budget is whole again.
    #[test]
    fn the_budget_keeps_the_latest_chunks_and_clear_empties_it() {
        let chunk = |n: usize| Arc::new(vec![0u8; n]);
        let mut cache = ChunkCache::new(10);
        cache.put(1, chunk(4));
        cache.put(2, chunk(4));
        assert!(cache.get(1).is_some());
        cache.put(3, chunk(4));
        assert!(cache.get(2).is_none(), "the least recently used goes first");
        assert!(cache.get(1).is_some() && cache.get(3).is_some());
        cache.put(4, chunk(30));
        assert!(cache.get(4).is_some() && cache.get(1).is_none());
        cache.clear();
        assert!(cache.get(4).is_none());
        assert_eq!(cache.used_bytes, 0);
        cache.put(5, chunk(6));
        cache.put(6, chunk(4));
        assert!(cache.get(5).is_some() && cache.get(6).is_some());
    }
}

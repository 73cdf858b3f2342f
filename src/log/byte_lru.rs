//! A cache bounded by the bytes it holds, least recently used first out: the log's one cache
//! mechanism, for the container's decompressed chunks and the drive's decoded images.
//!
//! Entries are shared (`Arc`), so an evicted entry stays alive for whoever still holds it. The
//! newest entry is kept even when it alone is larger than the budget (a caller asked for it and
//! may ask again). Lookups scan the entries: the image cache holds about ten, the chunk cache
//! up to a few hundred (its 256 MB in chunks of a megabyte or more, as MCAP writers make them).

use std::collections::VecDeque;
use std::sync::Arc;

/// Least-recently-used values of type `V` under keys `K`, bounded by total bytes.
pub(crate) struct ByteLru<K, V> {
    budget_bytes: usize,
    used_bytes: usize,
    /// Oldest use first; each entry with the bytes it was counted as.
    entries: VecDeque<(K, Arc<V>, usize)>,
}

impl<K: PartialEq, V> ByteLru<K, V> {
    pub(crate) fn new(budget_bytes: usize) -> Self {
        Self {
            budget_bytes,
            used_bytes: 0,
            entries: VecDeque::new(),
        }
    }

    /// The value under `key`, now the most recently used.
    pub(crate) fn get(&mut self, key: &K) -> Option<Arc<V>> {
        let pos = self.entries.iter().position(|(k, _, _)| k == key)?;
        let entry = self.entries.remove(pos)?;
        let value = Arc::clone(&entry.1);
        self.entries.push_back(entry);
        Some(value)
    }

    /// Keep `value` (counted as `bytes`) under `key`, replacing what was there, then drop the
    /// least recently used entries until the budget holds (or only this one is left).
    pub(crate) fn put(&mut self, key: K, value: Arc<V>, bytes: usize) {
        if let Some(pos) = self.entries.iter().position(|(k, _, _)| *k == key)
            && let Some((_, _, old_bytes)) = self.entries.remove(pos)
        {
            self.used_bytes -= old_bytes;
        }
        self.used_bytes += bytes;
        self.entries.push_back((key, value, bytes));
        while self.used_bytes > self.budget_bytes && self.entries.len() > 1 {
            if let Some((_, _, old_bytes)) = self.entries.pop_front() {
                self.used_bytes -= old_bytes;
            }
        }
    }

    /// Drop every entry; what is asked for later is made again by the caller.
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
        self.used_bytes = 0;
    }

    /// Bytes the entries are counted as.
    #[cfg(test)]
    fn used_bytes(&self) -> usize {
        self.used_bytes
    }

    #[cfg(test)]
    fn len(&self) -> usize {
        self.entries.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn blob(n: usize) -> Arc<Vec<u8>> {
        Arc::new(vec![0u8; n])
    }

    fn put(cache: &mut ByteLru<u32, Vec<u8>>, key: u32, n: usize) {
        cache.put(key, blob(n), n);
    }

    /// The budget holds the most recently used entries (one larger than it alone); a cleared
    /// cache holds none and counts nothing, so the budget is whole again.
    #[test]
    fn the_budget_keeps_the_latest_used_entries_and_clear_empties_it() {
        let mut cache = ByteLru::new(10);
        put(&mut cache, 1, 4);
        put(&mut cache, 2, 4);
        assert!(cache.get(&1).is_some());
        put(&mut cache, 3, 4);
        assert!(
            cache.get(&2).is_none(),
            "the least recently used goes first"
        );
        assert!(cache.get(&1).is_some() && cache.get(&3).is_some());
        assert_eq!((cache.len(), cache.used_bytes()), (2, 8));
        put(&mut cache, 4, 30);
        assert!(cache.get(&4).is_some() && cache.get(&1).is_none());
        assert_eq!((cache.len(), cache.used_bytes()), (1, 30));
        cache.clear();
        assert!(cache.get(&4).is_none());
        assert_eq!((cache.len(), cache.used_bytes()), (0, 0));
        put(&mut cache, 5, 6);
        put(&mut cache, 6, 4);
        assert!(cache.get(&5).is_some() && cache.get(&6).is_some());
    }

    /// Putting a key again replaces its value and its count instead of holding it twice.
    #[test]
    fn a_key_put_again_is_held_once() {
        let mut cache = ByteLru::new(100);
        put(&mut cache, 7, 10);
        put(&mut cache, 7, 25);
        assert_eq!((cache.len(), cache.used_bytes()), (1, 25));
        assert_eq!(cache.get(&7).map(|v| v.len()), Some(25));
    }
}

//! Where a table keeps its observations: compact entries, each stored once
//! and shared by reference count.
//!
//! Entries are appended to 1 MiB chunks; a chunk is freed when its last
//! entry is. Because the table evicts items first-in first-out, chunks
//! empty in roughly the order they were filled, so memory follows the
//! table's size and does not grow without bound. An observation sent again
//! soon after (the next state of one batch's last transition is the state
//! of the next batch's first) is found through a small window of recent
//! content hashes and shared instead of stored twice. The window does not
//! refresh on a hit, so no entry pins its chunk for longer than the
//! window's span.

use std::collections::HashMap;
use std::collections::VecDeque;
use std::hash::{BuildHasher, BuildHasherDefault, DefaultHasher};

/// Bytes per chunk; larger entries get a chunk of their own.
const CHUNK_BYTES: usize = 1 << 20;
/// Recent entries looked up for sharing.
const DEDUP_WINDOW: usize = 4096;

/// Content hash of an encoded observation, computed before taking the
/// table's lock.
pub fn content_hash(bytes: &[u8]) -> u64 {
    BuildHasherDefault::<DefaultHasher>::default().hash_one(bytes)
}

#[derive(Debug, Clone, Copy)]
struct Entry {
    chunk: u32,
    offset: u32,
    len: u32,
    /// 0 for a free slot.
    refs: u32,
}

#[derive(Debug)]
struct Chunk {
    data: Vec<u8>,
    live: u32,
}

/// Reference-counted compact observations. Not thread-safe; the table
/// holds it behind its lock. Every call is O(1) amortized except
/// [`intern`](Self::intern)'s byte comparison on a hash hit.
#[derive(Debug, Default)]
pub struct ObservationStore {
    entries: Vec<Entry>,
    free_entries: Vec<u32>,
    chunks: Vec<Option<Chunk>>,
    free_chunks: Vec<u32>,
    current: Option<u32>,
    recent: VecDeque<(u64, u32)>,
    by_hash: HashMap<u64, u32>,
    live_entries: usize,
    shared_hits: u64,
}

impl ObservationStore {
    /// An empty store.
    pub fn new() -> Self {
        Self::default()
    }

    /// Live entries.
    pub fn len(&self) -> usize {
        self.live_entries
    }

    /// Whether no entry is live.
    pub fn is_empty(&self) -> bool {
        self.live_entries == 0
    }

    /// Times an insert found its observation already stored.
    pub fn shared_hits(&self) -> u64 {
        self.shared_hits
    }

    /// Bytes held: chunk buffers, entry table and the sharing window.
    pub fn bytes(&self) -> usize {
        let chunks: usize = self
            .chunks
            .iter()
            .flatten()
            .map(|c| c.data.capacity())
            .sum();
        chunks
            + self.entries.capacity() * size_of::<Entry>()
            + self.free_entries.capacity() * 4
            + self.chunks.capacity() * size_of::<Option<Chunk>>()
            + self.recent.capacity() * 16
            + self.by_hash.capacity() * 16
    }

    /// The bytes of live entry `id`.
    pub fn get(&self, id: u32) -> &[u8] {
        let e = self.entries[id as usize];
        match &self.chunks[e.chunk as usize] {
            Some(c) => &c.data[e.offset as usize..(e.offset + e.len) as usize],
            None => &[],
        }
    }

    /// Stores `bytes` (whose [`content_hash`] is `hash`) or finds it among
    /// the recent entries; returns its id with one more reference.
    pub fn intern(&mut self, bytes: &[u8], hash: u64) -> u32 {
        if let Some(&id) = self.by_hash.get(&hash)
            && self.entries.get(id as usize).is_some_and(|e| e.refs > 0)
            && self.get(id) == bytes
        {
            self.entries[id as usize].refs += 1;
            self.shared_hits += 1;
            return id;
        }
        let id = self.append(bytes);
        if self.recent.len() == DEDUP_WINDOW
            && let Some((old_hash, old_id)) = self.recent.pop_front()
            && self.by_hash.get(&old_hash) == Some(&old_id)
        {
            self.by_hash.remove(&old_hash);
        }
        self.recent.push_back((hash, id));
        self.by_hash.insert(hash, id);
        id
    }

    /// One more reference to live entry `id`.
    pub fn retain(&mut self, id: u32) {
        self.entries[id as usize].refs += 1;
    }

    /// One reference fewer to live entry `id`; frees it (and its chunk, if
    /// that was the chunk's last entry) at zero.
    pub fn release(&mut self, id: u32) {
        let e = &mut self.entries[id as usize];
        debug_assert!(e.refs > 0);
        e.refs -= 1;
        if e.refs > 0 {
            return;
        }
        let chunk = e.chunk;
        self.free_entries.push(id);
        self.live_entries -= 1;
        if let Some(c) = self.chunks[chunk as usize].as_mut() {
            c.live -= 1;
            if c.live == 0 && self.current != Some(chunk) {
                self.chunks[chunk as usize] = None;
                self.free_chunks.push(chunk);
            }
        }
    }

    fn append(&mut self, bytes: &[u8]) -> u32 {
        let need = bytes.len();
        let fits = self
            .current
            .and_then(|c| self.chunks[c as usize].as_ref())
            .is_some_and(|c| c.data.len() + need <= c.data.capacity());
        if !fits {
            // Retire the current chunk; free it now if nothing lives in it.
            if let Some(old) = self.current.take()
                && self.chunks[old as usize]
                    .as_ref()
                    .is_some_and(|c| c.live == 0)
            {
                self.chunks[old as usize] = None;
                self.free_chunks.push(old);
            }
            let chunk = Chunk {
                data: Vec::with_capacity(need.max(CHUNK_BYTES)),
                live: 0,
            };
            let index = match self.free_chunks.pop() {
                Some(i) => {
                    self.chunks[i as usize] = Some(chunk);
                    i
                }
                None => {
                    self.chunks.push(Some(chunk));
                    (self.chunks.len() - 1) as u32
                }
            };
            self.current = Some(index);
        }
        let chunk_index = self.current.unwrap_or_default();
        // The current chunk is allocated above; `get_or_insert_with` keeps
        // this total without a panic path.
        let c = self.chunks[chunk_index as usize].get_or_insert_with(|| Chunk {
            data: Vec::with_capacity(need.max(CHUNK_BYTES)),
            live: 0,
        });
        let offset = c.data.len() as u32;
        c.data.extend_from_slice(bytes);
        c.live += 1;
        let entry = Entry {
            chunk: chunk_index,
            offset,
            len: need as u32,
            refs: 1,
        };
        self.live_entries += 1;
        match self.free_entries.pop() {
            Some(id) => {
                self.entries[id as usize] = entry;
                id
            }
            None => {
                self.entries.push(entry);
                (self.entries.len() - 1) as u32
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shares_recent_duplicates_and_frees_chunks() {
        let mut s = ObservationStore::new();
        let a = s.intern(b"alpha", content_hash(b"alpha"));
        let b = s.intern(b"alpha", content_hash(b"alpha"));
        assert_eq!(a, b);
        assert_eq!(s.len(), 1);
        assert_eq!(s.shared_hits(), 1);
        s.release(a);
        assert_eq!(s.get(a), b"alpha", "one reference left");
        s.release(a);
        assert_eq!(s.len(), 0);

        // Fill several chunks, then free everything: only the current chunk
        // stays allocated.
        let big = vec![7u8; 300 << 10];
        let ids: Vec<u32> = (0..10u8)
            .map(|i| {
                let mut v = big.clone();
                v[0] = i;
                s.intern(&v, content_hash(&v))
            })
            .collect();
        assert!(s.bytes() > 3 * CHUNK_BYTES);
        for id in ids {
            s.release(id);
        }
        assert!(s.bytes() < 2 * CHUNK_BYTES, "{}", s.bytes());
    }

    #[test]
    fn a_hash_collision_is_not_shared() {
        let mut s = ObservationStore::new();
        let a = s.intern(b"one", 42);
        let b = s.intern(b"two", 42);
        assert_ne!(a, b);
        assert_eq!(s.get(a), b"one");
        assert_eq!(s.get(b), b"two");
    }
}

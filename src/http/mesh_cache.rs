//! Encoded mesh downloads kept in memory. A shape's mesh never changes, so a download in a
//! given format and unit is the same bytes every time; encoding it (decode the stored blob,
//! transform, write the format) costs milliseconds of CPU, serving a cached copy does not.
//! Bounded by total bytes, oldest entry out first.

use std::collections::{HashMap, VecDeque};
use std::sync::Mutex;

use axum::body::Bytes;

/// What identifies one encoded download. The cohort id and content digest are part of the
/// key so a shape id reused after a deletion never serves the old bytes.
#[derive(Debug, Clone, PartialEq, Eq, Hash)]
pub struct MeshKey {
    /// Shape id.
    pub shape_id: i64,
    /// Owning cohort.
    pub cohort_id: i64,
    /// SHA-256 of the stored mesh.
    pub mesh_sha256: String,
    /// File extension of the format.
    pub format: &'static str,
    /// `mm` or `unit`.
    pub units: &'static str,
}

/// A byte-bounded cache of encoded meshes, shared by all requests.
#[derive(Debug)]
pub struct MeshCache {
    budget: usize,
    inner: Mutex<Inner>,
}

#[derive(Debug, Default)]
struct Inner {
    entries: HashMap<MeshKey, Bytes>,
    order: VecDeque<MeshKey>,
    bytes: usize,
}

impl MeshCache {
    /// A cache holding at most `budget` bytes (0 disables it).
    pub fn new(budget: usize) -> Self {
        Self {
            budget,
            inner: Mutex::new(Inner::default()),
        }
    }

    /// The cached download, if present.
    pub fn get(&self, key: &MeshKey) -> Option<Bytes> {
        self.lock().entries.get(key).cloned()
    }

    /// Stores a download, evicting the oldest entries beyond the budget. A download larger
    /// than the whole budget is not kept.
    pub fn insert(&self, key: MeshKey, bytes: Bytes) {
        if bytes.len() > self.budget {
            return;
        }
        let mut inner = self.lock();
        if inner.entries.contains_key(&key) {
            return;
        }
        while inner.bytes + bytes.len() > self.budget {
            let Some(old) = inner.order.pop_front() else {
                break;
            };
            if let Some(b) = inner.entries.remove(&old) {
                inner.bytes -= b.len();
            }
        }
        inner.bytes += bytes.len();
        inner.order.push_back(key.clone());
        inner.entries.insert(key, bytes);
    }

    /// Bytes held.
    pub fn bytes(&self) -> usize {
        self.lock().bytes
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Inner> {
        // The cache holds no invariant a panicking holder could break half-way that matters
        // more than serving: recover from poisoning.
        self.inner.lock().unwrap_or_else(|e| e.into_inner())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn key(shape_id: i64) -> MeshKey {
        MeshKey {
            shape_id,
            cohort_id: 1,
            mesh_sha256: "ab".into(),
            format: "glb",
            units: "mm",
        }
    }

    #[test]
    fn the_oldest_entries_leave_when_the_budget_is_exceeded() {
        let cache = MeshCache::new(10);
        cache.insert(key(1), Bytes::from_static(b"aaaa"));
        cache.insert(key(2), Bytes::from_static(b"bbbb"));
        assert_eq!(cache.bytes(), 8);
        cache.insert(key(3), Bytes::from_static(b"cccc"));
        assert_eq!(cache.get(&key(1)), None);
        assert_eq!(cache.get(&key(2)).as_deref(), Some(&b"bbbb"[..]));
        assert_eq!(cache.get(&key(3)).as_deref(), Some(&b"cccc"[..]));
        assert_eq!(cache.bytes(), 8);
    }

    #[test]
    fn a_download_larger_than_the_budget_or_a_zero_budget_keeps_nothing() {
        let cache = MeshCache::new(3);
        cache.insert(key(1), Bytes::from_static(b"aaaa"));
        assert_eq!(cache.get(&key(1)), None);
        let off = MeshCache::new(0);
        off.insert(key(1), Bytes::from_static(b"a"));
        assert_eq!(off.get(&key(1)), None);
        assert_eq!(off.bytes(), 0);
    }

    #[test]
    fn another_cohort_or_digest_is_another_entry() {
        let cache = MeshCache::new(100);
        cache.insert(key(1), Bytes::from_static(b"old"));
        let mut reused = key(1);
        reused.cohort_id = 2;
        assert_eq!(cache.get(&reused), None);
        let mut changed = key(1);
        changed.mesh_sha256 = "cd".into();
        assert_eq!(cache.get(&changed), None);
    }
}

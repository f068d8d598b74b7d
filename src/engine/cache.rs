//! The engine's in-memory caches (loaded models, novelty references): bounded, least
//! recently used out first, and keyed by what a model directory holds, not only by its
//! path, so a model deleted and trained again under the same id is never served from the
//! old one's entry.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::Path;

/// What a model directory holds, as far as a reload would see: the names, sizes and
/// modification times of its files (not its subdirectories, such as training inputs).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct DirStamp(u64);

impl DirStamp {
    /// The stamp of `dir` now.
    pub fn of(dir: &Path) -> std::io::Result<Self> {
        let mut files = Vec::new();
        for entry in std::fs::read_dir(dir)? {
            let entry = entry?;
            let meta = entry.metadata()?;
            if !meta.is_file() {
                continue;
            }
            let modified = meta
                .modified()
                .ok()
                .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
                .map_or(0, |d| d.as_nanos());
            files.push((entry.file_name(), meta.len(), modified));
        }
        files.sort();
        let mut hasher = std::collections::hash_map::DefaultHasher::new();
        files.hash(&mut hasher);
        Ok(Self(hasher.finish()))
    }
}

/// A map that keeps at most `capacity` entries, dropping the least recently used.
#[derive(Debug)]
pub struct BoundedCache<K, V> {
    capacity: usize,
    clock: u64,
    entries: HashMap<K, (u64, V)>,
}

impl<K: Eq + Hash + Clone, V: Clone> BoundedCache<K, V> {
    /// An empty cache of at most `capacity` (≥ 1) entries.
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity: capacity.max(1),
            clock: 0,
            entries: HashMap::new(),
        }
    }

    /// The entry of `key`, marked as just used.
    pub fn get(&mut self, key: &K) -> Option<V> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(key).map(|(used, v)| {
            *used = clock;
            v.clone()
        })
    }

    /// Stores `value` under `key`, dropping the least recently used entries beyond the
    /// capacity.
    pub fn insert(&mut self, key: K, value: V) {
        self.clock += 1;
        self.entries.insert(key, (self.clock, value));
        while self.entries.len() > self.capacity {
            let oldest = self
                .entries
                .iter()
                .min_by_key(|(_, (used, _))| *used)
                .map(|(k, _)| k.clone());
            match oldest {
                Some(k) => self.entries.remove(&k),
                None => break,
            };
        }
    }

    /// Entries held.
    #[cfg(test)]
    fn len(&self) -> usize {
        self.entries.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_least_recently_used_entry_goes_first() {
        let mut cache = BoundedCache::new(2);
        cache.insert("a", 1);
        cache.insert("b", 2);
        assert_eq!(cache.get(&"a"), Some(1));
        cache.insert("c", 3);
        assert_eq!(cache.len(), 2);
        assert_eq!(cache.get(&"b"), None, "b was used least recently");
        assert_eq!((cache.get(&"a"), cache.get(&"c")), (Some(1), Some(3)));
        for k in ["d", "e", "f", "g"] {
            cache.insert(k, 0);
        }
        assert_eq!(cache.len(), 2);
    }

    #[test]
    fn a_directory_rewritten_under_the_same_path_has_another_stamp() {
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("manifest.json"), b"{\"v\": 1}").unwrap();
        std::fs::create_dir(dir.path().join("input")).unwrap();
        let first = DirStamp::of(dir.path()).unwrap();
        assert_eq!(DirStamp::of(dir.path()).unwrap(), first);
        // Files under a subdirectory do not count.
        std::fs::write(dir.path().join("input/0000.stl"), b"x").unwrap();
        assert_eq!(DirStamp::of(dir.path()).unwrap(), first);
        // The model deleted and another written in its place.
        std::fs::remove_file(dir.path().join("manifest.json")).unwrap();
        std::fs::write(dir.path().join("manifest.json"), b"{\"v\": 22}").unwrap();
        assert_ne!(DirStamp::of(dir.path()).unwrap(), first);
        std::fs::write(dir.path().join("weights.bin"), b"w").unwrap();
        assert_ne!(DirStamp::of(dir.path()).unwrap(), first);
    }
}

//! Scale-out: assigning streams to node instances.
//!
//! Several node instances on one zenoh network share the input streams: an
//! instance configured with `shard {index, count}` processes a stream iff
//! `xxh3_64(stream key) mod count == index`. The hash is stable across
//! processes, machines and versions (XXH3 with the default seed), so every
//! stream is owned by exactly one instance without coordination. The stream
//! key is the input topic (labelled objects of one cloud stay together).

use serde::{Deserialize, Serialize};
use thiserror::Error;

/// Invalid shard settings.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum ShardError {
    /// `count` is 0 or `index >= count`.
    #[error("shard index {index} is not below shard count {count} (count must be ≥ 1)")]
    Range {
        /// Configured index.
        index: u32,
        /// Configured count.
        count: u32,
    },
}

/// This instance's shard (`node.shard`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Shard {
    /// This instance's index, `0..count`.
    pub index: u32,
    /// Number of instances sharing the streams.
    pub count: u32,
}

impl Shard {
    /// Check `index < count`.
    ///
    /// # Errors
    /// [`ShardError::Range`] otherwise.
    pub fn validate(&self) -> Result<(), ShardError> {
        if self.count == 0 || self.index >= self.count {
            return Err(ShardError::Range {
                index: self.index,
                count: self.count,
            });
        }
        Ok(())
    }

    /// The shard owning `key`.
    pub fn of(key: &str, count: u32) -> u32 {
        let h = xxhash_rust::xxh3::xxh3_64(key.as_bytes());
        // count ≥ 1 after validate(); guard anyway.
        u32::try_from(h % u64::from(count.max(1))).unwrap_or(0)
    }

    /// Whether this instance owns `key`.
    pub fn owns(&self, key: &str) -> bool {
        Self::of(key, self.count) == self.index
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shards_partition_keys_without_overlap_or_gap() {
        for count in 1..5u32 {
            let shards: Vec<Shard> = (0..count).map(|index| Shard { index, count }).collect();
            let mut per = vec![0usize; count as usize];
            for i in 0..1000 {
                let key = format!("/robot/obj{i}/points");
                let owners: Vec<&Shard> = shards.iter().filter(|s| s.owns(&key)).collect();
                assert_eq!(owners.len(), 1, "{key}");
                per[owners[0].index as usize] += 1;
            }
            // Every shard gets a fair share (hash spreads keys).
            for n in per {
                assert!(n > 1000 / count as usize / 2, "{count}: {n}");
            }
        }
        assert!(Shard { index: 2, count: 2 }.validate().is_err());
        assert!(Shard { index: 0, count: 0 }.validate().is_err());
    }

    #[test]
    fn hash_is_the_documented_xxh3() {
        // xxh3_64("") = 0x2d06800538d394c2 (xxHash test vector).
        assert_eq!(xxhash_rust::xxh3::xxh3_64(b""), 0x2d06_8005_38d3_94c2);
        assert_eq!(Shard::of("", 7), (0x2d06_8005_38d3_94c2u64 % 7) as u32);
    }
}

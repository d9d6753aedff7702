//! rmw_zenoh's 33-byte sample attachment and entity GIDs.
//!
//! Every sample an rmw_zenoh publisher puts carries this attachment (the
//! subscriber drops samples without it), written with zenoh's serializer:
//!
//! | bytes | field | encoding |
//! |---|---|---|
//! | 0–7 | sequence number | i64 LE, 1 for the first put, +1 per put |
//! | 8–15 | source timestamp | i64 LE, ns since the Unix epoch |
//! | 16 | GID length | LEB128 varint = 0x10 |
//! | 17–32 | source GID | 16 bytes |
//!
//! The publisher's GID is the XXH3-128 hash of its liveliness key
//! expression, low 64 bits then high 64 bits, each little-endian
//! (`Entity::Entity` in rmw_zenoh's `liveliness_utils.cpp`).

use thiserror::Error;

/// Size of the encoded attachment.
pub const ATTACHMENT_LEN: usize = 33;

/// Errors while decoding an attachment.
#[derive(Debug, Clone, Error, PartialEq, Eq)]
pub enum AttachmentError {
    /// The attachment is shorter or longer than 33 bytes.
    #[error("attachment has {0} bytes, expected 33 (seq i64, timestamp i64, 0x10, 16-byte GID)")]
    Length(usize),
    /// The GID length byte is not 16.
    #[error("attachment GID length byte is {0:#04x}, expected 0x10")]
    GidLength(u8),
}

/// The decoded attachment of one sample.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    /// Publisher sequence number (starts at 1).
    pub sequence: i64,
    /// Source timestamp, ns since the Unix epoch.
    pub timestamp_ns: i64,
    /// Publisher GID.
    pub gid: [u8; 16],
}

impl Attachment {
    /// Encode to the 33-byte wire form.
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut out = [0u8; ATTACHMENT_LEN];
        out[0..8].copy_from_slice(&self.sequence.to_le_bytes());
        out[8..16].copy_from_slice(&self.timestamp_ns.to_le_bytes());
        out[16] = 0x10;
        out[17..33].copy_from_slice(&self.gid);
        out
    }

    /// Decode the 33-byte wire form.
    ///
    /// # Errors
    /// [`AttachmentError`] for a wrong length or GID length byte.
    pub fn decode(bytes: &[u8]) -> Result<Self, AttachmentError> {
        if bytes.len() != ATTACHMENT_LEN {
            return Err(AttachmentError::Length(bytes.len()));
        }
        if bytes[16] != 0x10 {
            return Err(AttachmentError::GidLength(bytes[16]));
        }
        let mut seq = [0u8; 8];
        seq.copy_from_slice(&bytes[0..8]);
        let mut ts = [0u8; 8];
        ts.copy_from_slice(&bytes[8..16]);
        let mut gid = [0u8; 16];
        gid.copy_from_slice(&bytes[17..33]);
        Ok(Self {
            sequence: i64::from_le_bytes(seq),
            timestamp_ns: i64::from_le_bytes(ts),
            gid,
        })
    }
}

/// The GID of an entity: XXH3-128 of its liveliness key, low64 then high64 (LE).
pub fn gid_of_liveliness_key(key: &str) -> [u8; 16] {
    xxhash_rust::xxh3::xxh3_128(key.as_bytes()).to_le_bytes()
}

/// Nanoseconds since the Unix epoch now (0 if the clock is before 1970).
pub fn now_ns() -> i64 {
    std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
        .unwrap_or(0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layout_is_the_rmw_zenoh_one() {
        let a = Attachment {
            sequence: 1,
            timestamp_ns: 0x0102_0304_0506_0708,
            gid: [0xAB; 16],
        };
        let b = a.encode();
        // Bytes written out by hand from the layout table (independent of encode()).
        let mut expected = vec![1, 0, 0, 0, 0, 0, 0, 0, 8, 7, 6, 5, 4, 3, 2, 1, 0x10];
        expected.extend_from_slice(&[0xAB; 16]);
        assert_eq!(b.as_slice(), expected.as_slice());
        assert_eq!(Attachment::decode(&b).unwrap(), a);
    }

    #[test]
    fn malformed_attachments_are_typed_errors() {
        assert_eq!(
            Attachment::decode(&[0; 32]),
            Err(AttachmentError::Length(32))
        );
        let mut b = [0u8; 33];
        b[16] = 0x18;
        assert_eq!(
            Attachment::decode(&b),
            Err(AttachmentError::GidLength(0x18))
        );
    }

    #[test]
    fn gid_is_xxh3_128_low_then_high() {
        let key = "@ros2_lv/0/abc/0/1/MP/%/%/n/%t/std_msgs::msg::dds_::String_/h/::,10:,:,:,,";
        let h = xxhash_rust::xxh3::xxh3_128(key.as_bytes());
        let gid = gid_of_liveliness_key(key);
        assert_eq!(
            &gid[..8],
            &((h & u128::from(u64::MAX)) as u64).to_le_bytes()
        );
        assert_eq!(&gid[8..], &((h >> 64) as u64).to_le_bytes());
        // XXH3-128 of the empty input, a published test vector of xxHash:
        // 0x99aa06d3014798d86001c324468d497f.
        let empty = gid_of_liveliness_key("");
        assert_eq!(
            u128::from_le_bytes(empty),
            0x99aa_06d3_0147_98d8_6001_c324_468d_497f
        );
    }
}

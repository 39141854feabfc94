//! Flow control between the hosts of a deployment: a consuming host acknowledges how far it has
//! taken each stream, and the producer keeps at most a window of samples unacknowledged per
//! consuming host (docs/streams.md, "Start, flow and end").
//!
//! A subscription never blocks zenoh: what arrives is queued at once (a queue the window bounds),
//! so a slow consumer never stalls the link it shares with everything else (other streams, tokens,
//! queries, the end), and zenoh never closes a link because a blocked publisher waited too long.
//! The producer waits for credit instead.
//!
//! An acknowledgment is a small message on `STREAM/@ack/HOST` ([`crate::keys::ack`]) with an
//! envelope ([`crate::envelope`]) naming the consuming host, tagged with the deployment's secret
//! when it has keys, so a stranger can neither fake a consumer nor its progress:
//!
//! | bytes | field |
//! |---|---|
//! | 0..3 | `KPA` |
//! | 3 | version: 1 |
//! | 4 | flags: bit 0 the consumer has the end of the producer's run below; bit 1 a run follows |
//! | 5..13 | the producer's incarnation the position is of, u64 |
//! | 13..21 | the position: one past the highest sequence number taken from that run, u64 |
//!
//! The envelope's incarnation is the consuming host's own (random for each run of its receiver),
//! its sequence number counts the acknowledgments it sent.

use std::time::Duration;

const MAGIC: &[u8; 3] = b"KPA";
const VERSION: u8 = 1;
const FLAG_END: u8 = 1;
const FLAG_RUN: u8 = 2;
/// The length of an acknowledgment's payload.
pub const ACK_LEN: usize = 21;

/// How often a consuming host acknowledges even when nothing changed (it is alive and subscribed).
pub const HEARTBEAT: Duration = Duration::from_millis(500);
/// A consuming host not heard from for this long is not waited for (frozen, or its link is down).
pub const STALE: Duration = Duration::from_secs(3);

/// What a consuming host has of a stream.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Ack {
    /// The producer's run (incarnation) and how far the consumer took it; `None` before its first
    /// message.
    pub run: Option<(u64, u64)>,
    /// The consumer has the end of that run.
    pub end: bool,
}

impl Ack {
    pub fn encode(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(ACK_LEN);
        out.extend_from_slice(MAGIC);
        out.push(VERSION);
        let mut flags = 0;
        if self.end {
            flags |= FLAG_END;
        }
        if self.run.is_some() {
            flags |= FLAG_RUN;
        }
        out.push(flags);
        let (incarnation, position) = self.run.unwrap_or((0, 0));
        out.extend_from_slice(&incarnation.to_le_bytes());
        out.extend_from_slice(&position.to_le_bytes());
        out
    }

    /// `None` when the bytes are not an acknowledgment.
    pub fn decode(bytes: &[u8]) -> Option<Ack> {
        if bytes.len() != ACK_LEN || &bytes[..3] != MAGIC || bytes[3] != VERSION {
            return None;
        }
        let flags = bytes[4];
        let u64_at =
            |at: usize| -> Option<u64> { Some(u64::from_le_bytes(bytes.get(at..at + 8)?.try_into().ok()?)) };
        let run = (flags & FLAG_RUN != 0).then_some((u64_at(5)?, u64_at(13)?));
        Some(Ack { run, end: flags & FLAG_END != 0 })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    #[test]
    fn acks_round_trip_and_garbage_is_none() {
        for ack in [
            Ack::default(),
            Ack { run: Some((0xfeed, 41)), end: false },
            Ack { run: Some((u64::MAX, u64::MAX)), end: true },
        ] {
            assert_eq!(Ack::decode(&ack.encode()), Some(ack));
        }
        assert_eq!(Ack::decode(b"KPA"), None);
        assert_eq!(Ack::decode(&[0; ACK_LEN]), None);
        let mut other_version = Ack::default().encode();
        other_version[3] = 2;
        assert_eq!(Ack::decode(&other_version), None);
    }
}

//! The envelope of a message between the hosts of a deployment: who sent it, which run of the
//! producer, its place in the stream, and (with keys) an authentication tag. It travels as the
//! zenoh attachment of each message, beside the payload of [`crate::codec`], so the payload format
//! stays the same for programs outside a spec (docs/streams.md, "Envelope").
//!
//! | bytes | field |
//! |---|---|
//! | 0..3 | `KPE` |
//! | 3 | version: 1 |
//! | 4 | flags: bit 0 set on the end of a stream whose producer was interrupted (not finished); bit 1 set when a tag follows |
//! | 5..13 | incarnation: u64, random for each run of the producing host |
//! | 13..21 | sequence: u64, the sample's number in its stream from 0; on the end, the number of samples published |
//! | 21 | length of the host's name, n |
//! | 22..22+n | the producing host's name, UTF-8 |
//! | 22+n..54+n | with keys: HMAC-SHA256, with the deployment's secret, of `kpl-envelope-1`, the key expression, a zero byte, the envelope before the tag, and the payload |
//!
//! The receiver ([`Sequence`]) accepts a message only if its envelope names the host the spec
//! places the stream's producer on, its tag verifies (with keys), and its sequence number moves
//! forward within its incarnation; a new incarnation is the producer starting again. Gaps are
//! samples lost on the way (published while this host was down, or before it subscribed).

use crate::credentials::Secret;

const MAGIC: &[u8; 3] = b"KPE";
const VERSION: u8 = 1;
const FLAG_UNFINISHED: u8 = 1;
const FLAG_TAGGED: u8 = 2;
const TAG_LEN: usize = 32;
const CONTEXT: &[u8] = b"kpl-envelope-1";

/// What an envelope says.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Envelope {
    pub host: String,
    pub incarnation: u64,
    pub sequence: u64,
    /// On an end: the producer was interrupted, it did not finish the stream.
    pub unfinished: bool,
}

impl Envelope {
    /// The attachment bytes of this envelope for a message with `payload` on `key_expr`, tagged
    /// when a secret is given.
    pub fn seal(&self, key_expr: &str, payload: &[u8], secret: Option<&Secret>) -> Vec<u8> {
        let host = self.host.as_bytes();
        let host_len = u8::try_from(host.len()).unwrap_or(u8::MAX);
        let mut out = Vec::with_capacity(22 + usize::from(host_len) + TAG_LEN);
        out.extend_from_slice(MAGIC);
        out.push(VERSION);
        let mut flags = 0;
        if self.unfinished {
            flags |= FLAG_UNFINISHED;
        }
        if secret.is_some() {
            flags |= FLAG_TAGGED;
        }
        out.push(flags);
        out.extend_from_slice(&self.incarnation.to_le_bytes());
        out.extend_from_slice(&self.sequence.to_le_bytes());
        out.push(host_len);
        out.extend_from_slice(&host[..usize::from(host_len)]);
        if let Some(secret) = secret {
            let tag = tag(secret, key_expr, &out, payload);
            out.extend_from_slice(tag.as_ref());
        }
        out
    }

    /// Reads and checks an attachment: the envelope, if it is well formed and its tag verifies
    /// with `secret` (a tag is required with a secret and refused without one).
    pub fn open(
        attachment: Option<&[u8]>,
        key_expr: &str,
        payload: &[u8],
        secret: Option<&Secret>,
    ) -> Result<Envelope, Refusal> {
        let bytes = attachment.ok_or(Refusal::NoEnvelope)?;
        if bytes.len() < 22 || &bytes[..3] != MAGIC {
            return Err(Refusal::NoEnvelope);
        }
        if bytes[3] != VERSION {
            return Err(Refusal::Malformed(format!("envelope version {} (this kpl reads 1)", bytes[3])));
        }
        let flags = bytes[4];
        let u64_at = |at: usize| -> u64 {
            let mut word = [0u8; 8];
            word.copy_from_slice(&bytes[at..at + 8]);
            u64::from_le_bytes(word)
        };
        let incarnation = u64_at(5);
        let sequence = u64_at(13);
        let host_end = 22 + usize::from(bytes[21]);
        let host = bytes
            .get(22..host_end)
            .and_then(|h| std::str::from_utf8(h).ok())
            .ok_or_else(|| Refusal::Malformed("the envelope's host name is cut short or not UTF-8".into()))?
            .to_string();
        let tagged = flags & FLAG_TAGGED != 0;
        let rest = &bytes[host_end..];
        match (secret, tagged) {
            (Some(secret), true) => {
                if rest.len() != TAG_LEN {
                    return Err(Refusal::BadTag);
                }
                let expected = tag(secret, key_expr, &bytes[..host_end], payload);
                if !same_bytes(expected.as_ref(), rest) {
                    return Err(Refusal::BadTag);
                }
            }
            (Some(_), false) => return Err(Refusal::Untagged),
            (None, true) => return Err(Refusal::UnexpectedTag),
            (None, false) if !rest.is_empty() => {
                return Err(Refusal::Malformed("bytes after the envelope".into()));
            }
            (None, false) => {}
        }
        Ok(Envelope { host, incarnation, sequence, unfinished: flags & FLAG_UNFINISHED != 0 })
    }
}

/// Compares in time that does not depend on where the bytes differ.
fn same_bytes(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |differ, (x, y)| differ | (x ^ y)) == 0
}

fn tag(secret: &Secret, key_expr: &str, envelope: &[u8], payload: &[u8]) -> ring::hmac::Tag {
    let mut context = ring::hmac::Context::with_key(secret.key());
    context.update(CONTEXT);
    context.update(key_expr.as_bytes());
    context.update(&[0]);
    context.update(envelope);
    context.update(payload);
    context.sign()
}

/// Why a message was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum Refusal {
    #[error("no KPL envelope: not sent by a host of this deployment")]
    NoEnvelope,
    #[error("{0}")]
    Malformed(String),
    #[error("the authentication tag does not verify: not sent with this deployment's keys")]
    BadTag,
    #[error("no authentication tag, and this deployment has keys")]
    Untagged,
    #[error(
        "an authentication tag, and this host has no keys (start every host of the deployment with --keys)"
    )]
    UnexpectedTag,
    #[error("from host `{from}`; the spec places the producer on host `{expected}`")]
    WrongHost { from: String, expected: String },
    #[error("sequence number {sequence} again (incarnation {incarnation:016x}): replayed or duplicated")]
    Replayed { incarnation: u64, sequence: u64 },
    #[error("from an earlier run of the producer (incarnation {0:016x}): replayed")]
    OldIncarnation(u64),
}

/// What a stream's receiver makes of an accepted envelope.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Accepted {
    /// Samples of this incarnation that never arrived before this message.
    pub lost: u64,
    /// The producer started again (a new incarnation after another one).
    pub restarted: bool,
}

/// The sequence numbers a receiver has seen of one stream.
#[derive(Debug, Clone, Default)]
pub struct Sequence {
    incarnation: Option<u64>,
    next: u64,
    /// Incarnations the producer has left behind: their messages are replays.
    retired: Vec<u64>,
}

/// How many earlier incarnations a receiver remembers.
const RETIRED: usize = 64;

impl Sequence {
    /// Checks the place of a message (a sample, or an end with `is_end`) in its stream.
    pub fn accept(&mut self, envelope: &Envelope, is_end: bool) -> Result<Accepted, Refusal> {
        let mut restarted = false;
        if self.incarnation != Some(envelope.incarnation) {
            if self.retired.contains(&envelope.incarnation) {
                return Err(Refusal::OldIncarnation(envelope.incarnation));
            }
            if let Some(previous) = self.incarnation {
                restarted = true;
                if self.retired.len() == RETIRED {
                    self.retired.remove(0);
                }
                self.retired.push(previous);
            }
            self.incarnation = Some(envelope.incarnation);
            self.next = 0;
        }
        if envelope.sequence < self.next {
            return Err(Refusal::Replayed { incarnation: envelope.incarnation, sequence: envelope.sequence });
        }
        let lost = envelope.sequence - self.next;
        // An end carries the count of samples published, the number the next sample would have.
        self.next = if is_end { envelope.sequence } else { envelope.sequence.saturating_add(1) };
        Ok(Accepted { lost, restarted })
    }

    /// The incarnation of the producer as last seen.
    pub fn incarnation(&self) -> Option<u64> {
        self.incarnation
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    fn envelope(incarnation: u64, sequence: u64) -> Envelope {
        Envelope { host: "uav".into(), incarnation, sequence, unfinished: false }
    }

    #[test]
    fn sealed_envelopes_open_only_with_their_key_expression_payload_and_secret() {
        let secret = Secret::from_bytes(&[7; 32]);
        let e = envelope(0xfeed, 41);
        let sealed = e.seal("kpl/d/s/p", b"payload", Some(&secret));
        assert_eq!(Envelope::open(Some(&sealed), "kpl/d/s/p", b"payload", Some(&secret)), Ok(e.clone()));
        let refuse = |sealed: &[u8], key: &str, payload: &[u8], secret: Option<&Secret>| {
            Envelope::open(Some(sealed), key, payload, secret).unwrap_err()
        };
        assert_eq!(refuse(&sealed, "kpl/d/s/q", b"payload", Some(&secret)), Refusal::BadTag);
        assert_eq!(refuse(&sealed, "kpl/d/s/p", b"payloaD", Some(&secret)), Refusal::BadTag);
        assert_eq!(
            refuse(&sealed, "kpl/d/s/p", b"payload", Some(&Secret::from_bytes(&[8; 32]))),
            Refusal::BadTag
        );
        assert_eq!(refuse(&sealed, "kpl/d/s/p", b"payload", None), Refusal::UnexpectedTag);
        // Every byte of the envelope is covered.
        for i in 0..sealed.len() {
            let mut bent = sealed.clone();
            bent[i] ^= 0x10;
            assert!(Envelope::open(Some(&bent), "kpl/d/s/p", b"payload", Some(&secret)).is_err(), "byte {i}");
        }
        let plain = e.seal("kpl/d/s/p", b"payload", None);
        assert_eq!(Envelope::open(Some(&plain), "kpl/d/s/p", b"payload", None), Ok(e));
        assert_eq!(refuse(&plain, "kpl/d/s/p", b"payload", Some(&secret)), Refusal::Untagged);
        assert_eq!(Envelope::open(None, "k", b"", None), Err(Refusal::NoEnvelope));
        assert_eq!(refuse(b"KPL\x01S", "k", b"", None), Refusal::NoEnvelope);
        assert!(matches!(refuse(&sealed[..23], "kpl/d/s/p", b"payload", None), Refusal::Malformed(_)));
    }

    #[test]
    fn sequences_count_gaps_restarts_and_refuse_replays() {
        let mut s = Sequence::default();
        assert_eq!(s.accept(&envelope(1, 0), false), Ok(Accepted { lost: 0, restarted: false }));
        assert_eq!(s.accept(&envelope(1, 1), false), Ok(Accepted { lost: 0, restarted: false }));
        assert_eq!(s.accept(&envelope(1, 5), false), Ok(Accepted { lost: 3, restarted: false }));
        assert!(matches!(s.accept(&envelope(1, 5), false), Err(Refusal::Replayed { .. })));
        assert!(matches!(s.accept(&envelope(1, 2), false), Err(Refusal::Replayed { .. })));
        // The producer starts again.
        assert_eq!(s.accept(&envelope(2, 0), false), Ok(Accepted { lost: 0, restarted: true }));
        assert_eq!(s.accept(&envelope(1, 9), false), Err(Refusal::OldIncarnation(1)));
        // The end carries the count published: two samples missed before it.
        assert_eq!(s.accept(&envelope(2, 3), true), Ok(Accepted { lost: 2, restarted: false }));
        // A subscriber that came late counts what it missed.
        let mut late = Sequence::default();
        assert_eq!(late.accept(&envelope(3, 1000), false), Ok(Accepted { lost: 1000, restarted: false }));
    }

    proptest::proptest! {
        #[test]
        fn any_envelope_round_trips(
            host in "[a-z_][a-z0-9_]{0,30}",
            incarnation: u64,
            sequence: u64,
            unfinished: bool,
            payload in proptest::collection::vec(proptest::num::u8::ANY, 0..64),
            tagged: bool,
        ) {
            let secret = tagged.then(|| Secret::from_bytes(b"0123456789abcdef0123456789abcdef"));
            let e = Envelope { host, incarnation, sequence, unfinished };
            let sealed = e.seal("kpl/x", &payload, secret.as_ref());
            proptest::prop_assert_eq!(Envelope::open(Some(&sealed), "kpl/x", &payload, secret.as_ref()), Ok(e));
        }

        #[test]
        fn garbage_never_panics(bytes in proptest::collection::vec(proptest::num::u8::ANY, 0..80)) {
            let secret = Secret::from_bytes(&[1; 32]);
            let _ = Envelope::open(Some(&bytes), "k", b"", Some(&secret));
            let _ = Envelope::open(Some(&bytes), "k", b"", None);
        }
    }
}

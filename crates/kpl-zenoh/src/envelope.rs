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
//! The receiver accepts a message only if its envelope names the host the spec places the
//! stream's producer on and its tag verifies (with keys); [`Sequence`] then refuses what it has
//! accepted before (a replay or a duplicate). A new incarnation is the producer starting again;
//! gaps are samples that never arrived (published while this host was down, or before it
//! subscribed). Nothing a sender claims (a far sequence number, a new incarnation) shuts the
//! producer's own messages out.

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
}

/// What a stream's receiver makes of an accepted envelope.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Accepted {
    /// The producer started again: the first message of an incarnation seen after another one.
    pub restarted: bool,
    /// The message's sequence number is not right after the last one of its incarnation (a gap:
    /// samples that never arrived; or it fills an earlier gap).
    pub out_of_line: bool,
}

/// What a receiver has seen of one run (incarnation) of a stream's producer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Run {
    pub incarnation: u64,
    /// The sequence number the first accepted message had: samples before it were published
    /// before this host subscribed (or while it was away).
    pub joined_at: u64,
    /// Samples accepted.
    pub received: u64,
    /// One past the highest sequence number accepted (the count of samples published so far,
    /// as far as this host knows); with the end, the count the end says.
    pub frontier: u64,
    /// Whether the end of this run arrived (then `frontier` is the count published).
    pub ended: bool,
    /// Accepted sequence numbers, as sorted disjoint ranges `[start, end)`.
    seen: Vec<(u64, u64)>,
    /// The order of last activity among the runs (to forget the least recent).
    touched: u64,
}

impl Run {
    /// Samples of this run that never arrived: published (as far as this host knows) and not
    /// received.
    pub fn lost(&self) -> u64 {
        self.frontier.saturating_sub(self.received)
    }

    fn contains(&self, sequence: u64) -> bool {
        let i = self.seen.partition_point(|(_, end)| *end <= sequence);
        self.seen.get(i).is_some_and(|(start, _)| *start <= sequence)
    }

    /// Records `sequence`; false when it was seen before.
    fn insert(&mut self, sequence: u64) -> bool {
        let i = self.seen.partition_point(|(_, end)| *end < sequence);
        // `i`: the first range that ends at or after `sequence`.
        if let Some((start, end)) = self.seen.get(i).copied() {
            if start <= sequence && sequence < end {
                return false;
            }
            if end == sequence {
                // Extends range i upwards; it may now touch range i + 1.
                self.seen[i].1 = sequence + 1;
                if let Some((next_start, next_end)) = self.seen.get(i + 1).copied()
                    && next_start == sequence + 1
                {
                    self.seen[i].1 = next_end;
                    self.seen.remove(i + 1);
                }
                return true;
            }
            if start == sequence + 1 {
                self.seen[i].0 = sequence;
                return true;
            }
        }
        self.seen.insert(i, (sequence, sequence + 1));
        if self.seen.len() > RANGES {
            // The highest ranges are the least likely to be the producer's (its numbers grow one
            // by one from where it is): forget the highest.
            self.seen.pop();
        }
        true
    }
}

/// The sequence numbers a receiver has seen of one stream, per run of its producer.
///
/// A message is accepted unless its (incarnation, sequence number) was accepted before: a replay
/// or a duplicate. Nothing a sender claims can shut the producer out: a message with a huge
/// sequence number, or of a new incarnation, does not make the producer's next messages look
/// old; they are still accepted (in a deployment without keys anyone can send well-formed
/// messages, and only the counts show it).
#[derive(Debug, Clone, Default)]
pub struct Sequence {
    runs: Vec<Run>,
    /// The incarnation of the last accepted message.
    current: Option<u64>,
    /// Samples lost and received of runs forgotten (more than [`RUNS`] of them).
    forgotten_lost: u64,
    forgotten_received: u64,
    clock: u64,
}

/// How many runs of a producer a receiver remembers.
const RUNS: usize = 16;
/// How many disjoint ranges of sequence numbers a run keeps.
const RANGES: usize = 1024;

impl Sequence {
    /// Checks the place of a message (a sample, or an end with `is_end`) in its stream.
    pub fn accept(&mut self, envelope: &Envelope, is_end: bool) -> Result<Accepted, Refusal> {
        self.clock += 1;
        let index = match self.runs.iter().position(|r| r.incarnation == envelope.incarnation) {
            Some(i) => i,
            None => {
                if self.runs.len() == RUNS {
                    // Forget the run least recently active.
                    if let Some(oldest) = (0..self.runs.len()).min_by_key(|i| self.runs[*i].touched) {
                        let run = self.runs.remove(oldest);
                        self.forgotten_lost += run.lost();
                        self.forgotten_received += run.received;
                    }
                }
                self.runs.push(Run {
                    incarnation: envelope.incarnation,
                    joined_at: envelope.sequence,
                    received: 0,
                    frontier: 0,
                    ended: false,
                    seen: Vec::new(),
                    touched: self.clock,
                });
                self.runs.len() - 1
            }
        };
        let restarted = self.runs[index].received == 0
            && !self.runs[index].ended
            && self.current.is_some_and(|c| c != envelope.incarnation);
        let run = &mut self.runs[index];
        if is_end {
            // An end carries the count of samples published: the number the next sample would
            // have had. A second end of the same run is a replay.
            if run.ended {
                return Err(Refusal::Replayed {
                    incarnation: envelope.incarnation,
                    sequence: envelope.sequence,
                });
            }
            run.ended = true;
            let out_of_line = envelope.sequence != run.frontier;
            run.frontier = run.frontier.max(envelope.sequence);
            run.touched = self.clock;
            self.current = Some(envelope.incarnation);
            return Ok(Accepted { restarted, out_of_line });
        }
        if run.contains(envelope.sequence) || !run.insert(envelope.sequence) {
            return Err(Refusal::Replayed { incarnation: envelope.incarnation, sequence: envelope.sequence });
        }
        let out_of_line = envelope.sequence != run.frontier;
        run.received += 1;
        run.frontier = run.frontier.max(envelope.sequence.saturating_add(1));
        run.touched = self.clock;
        self.current = Some(envelope.incarnation);
        Ok(Accepted { restarted, out_of_line })
    }

    /// The incarnation of the producer as last seen.
    pub fn incarnation(&self) -> Option<u64> {
        self.current
    }

    /// The run of the producer as last seen.
    pub fn current(&self) -> Option<&Run> {
        let current = self.current?;
        self.runs.iter().find(|r| r.incarnation == current)
    }

    /// The runs of the producer this receiver remembers, in the order they were first seen.
    pub fn runs(&self) -> &[Run] {
        &self.runs
    }

    /// Samples that never arrived, over every run of the producer.
    pub fn lost(&self) -> u64 {
        self.forgotten_lost + self.runs.iter().map(Run::lost).sum::<u64>()
    }

    /// How often the producer started again (runs after the first).
    pub fn restarts(&self) -> u64 {
        self.runs.len().saturating_sub(1) as u64
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
        let ok = |restarted, out_of_line| Ok(Accepted { restarted, out_of_line });
        assert_eq!(s.accept(&envelope(1, 0), false), ok(false, false));
        assert_eq!(s.accept(&envelope(1, 1), false), ok(false, false));
        assert_eq!(s.accept(&envelope(1, 5), false), ok(false, true));
        assert_eq!(s.lost(), 3);
        assert!(matches!(s.accept(&envelope(1, 5), false), Err(Refusal::Replayed { .. })));
        assert!(matches!(s.accept(&envelope(1, 1), false), Err(Refusal::Replayed { .. })));
        // A late sample fills its gap: it was counted lost, it is not any more.
        assert_eq!(s.accept(&envelope(1, 2), false), ok(false, true));
        assert_eq!(s.lost(), 2);
        // The producer starts again.
        assert_eq!(s.accept(&envelope(2, 0), false), ok(true, false));
        assert_eq!(s.restarts(), 1);
        // The end carries the count published: two samples missed before it.
        assert_eq!(s.accept(&envelope(2, 3), true), ok(false, true));
        assert!(matches!(s.accept(&envelope(2, 3), true), Err(Refusal::Replayed { .. })));
        assert_eq!(s.lost(), 4);
        assert_eq!(s.runs()[1], Run { seen: vec![(0, 1)], touched: 8, ..s.runs()[1].clone() });
        assert_eq!((s.runs()[1].received, s.runs()[1].frontier, s.runs()[1].ended), (1, 3, true));
        // A subscriber that came late counts what it missed, and where it joined.
        let mut late = Sequence::default();
        assert_eq!(late.accept(&envelope(3, 1000), false), ok(false, true));
        assert_eq!((late.lost(), late.runs()[0].joined_at), (1000, 1000));
    }

    #[test]
    fn a_forged_sequence_number_or_incarnation_never_shuts_the_producer_out() {
        let mut s = Sequence::default();
        for k in 0..10 {
            s.accept(&envelope(1, k), false).unwrap();
        }
        // A forger's far sequence number, and a forger's new incarnation ...
        s.accept(&envelope(1, u64::MAX - 1), false).unwrap();
        s.accept(&envelope(99, 5), false).unwrap();
        // ... and the producer's next samples are still accepted, once each.
        for k in 10..2000 {
            assert!(s.accept(&envelope(1, k), false).is_ok(), "sample {k}");
        }
        assert!(matches!(s.accept(&envelope(1, 1500), false), Err(Refusal::Replayed { .. })));
        // Ranges are bounded: a forger's scattered numbers are forgotten first, the producer's kept.
        for k in 0..5000u64 {
            let _ = s.accept(&envelope(1, 1_000_000 + 2 * k), false);
        }
        assert!(s.runs()[0].seen.len() <= RANGES);
        assert!(matches!(s.accept(&envelope(1, 42), false), Err(Refusal::Replayed { .. })));
        assert!(s.accept(&envelope(1, 2000), false).is_ok());
        // Many forged incarnations: the producer's active run is kept.
        for i in 100..200 {
            s.accept(&envelope(i, 0), false).unwrap();
            s.accept(&envelope(1, 2001 + i), false).unwrap();
        }
        assert!(s.runs().iter().any(|r| r.incarnation == 1));
        assert!(matches!(s.accept(&envelope(1, 7), false), Err(Refusal::Replayed { .. })));
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

//! rmw_zenoh's wire, apart from zenoh itself: the key expression of a topic's data, the 33-byte
//! attachment every message carries, the liveliness tokens that make a node and its publishers
//! and subscriptions visible to ROS 2 tools, and the QoS written in them (rmw_zenoh's
//! `docs/design.md`).
//!
//! ```
//! use kpl_ros2::wire::{self, Attachment};
//! let key = wire::topic_key(0, "/tracker/markers", "visualization_msgs::msg::dds_::MarkerArray_", "RIHS01_00");
//! assert_eq!(key, "0/tracker/markers/visualization_msgs::msg::dds_::MarkerArray_/RIHS01_00");
//! let a = Attachment { sequence_number: 1, source_timestamp: 2, gid: [3; 16] };
//! assert_eq!(Attachment::decode(&a.encode()), Ok(a));
//! ```

use std::fmt::Write;

/// The prefix of every liveliness token of the ROS 2 graph.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// rmw_zenoh's default: a router on this host.
pub const DEFAULT_ROUTER: &str = "tcp/localhost:7447";

/// The key of a topic's data: `<domain>/<topic without its leading slash>/<DDS type>/<hash>`.
pub fn topic_key(domain: u32, topic: &str, dds_type: &str, type_hash: &str) -> String {
    format!("{domain}/{}/{dds_type}/{type_hash}", topic.trim_start_matches('/'))
}

/// A name in a liveliness token: `/` becomes `%`; empty (or `/`) is `%`.
pub fn mangle(name: &str) -> String {
    if name.is_empty() || name == "/" { "%".to_string() } else { name.replace('/', "%") }
}

/// The inverse of [`mangle`] for a topic: `%a%b` is `/a/b`.
pub fn demangle(name: &str) -> String {
    if name == "%" {
        return "/".to_string();
    }
    let out = name.replace('%', "/");
    if out.starts_with('/') { out } else { format!("/{out}") }
}

/// The attachment of every message: the publisher's sequence number, the source time stamp
/// (nanoseconds since the epoch) and the publisher's GID. On the wire: `i64` LE, `i64` LE, the
/// GID's length (16) as one byte, the 16 bytes: 33 bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Attachment {
    pub sequence_number: i64,
    pub source_timestamp: i64,
    pub gid: [u8; 16],
}

/// Why an attachment is not rmw_zenoh's.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AttachmentError {
    #[error("no attachment")]
    Missing,
    #[error("an attachment of {0} bytes (33 expected)")]
    Length(usize),
    #[error("an attachment whose GID has {0} bytes (16 expected)")]
    GidLength(u8),
}

impl Attachment {
    pub const LEN: usize = 33;

    pub fn encode(&self) -> [u8; 33] {
        let mut out = [0u8; 33];
        out[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        out[8..16].copy_from_slice(&self.source_timestamp.to_le_bytes());
        out[16] = 16;
        out[17..].copy_from_slice(&self.gid);
        out
    }

    pub fn decode(bytes: &[u8]) -> Result<Attachment, AttachmentError> {
        if bytes.len() != Self::LEN {
            return Err(AttachmentError::Length(bytes.len()));
        }
        if bytes[16] != 16 {
            return Err(AttachmentError::GidLength(bytes[16]));
        }
        let mut seq = [0u8; 8];
        let mut ts = [0u8; 8];
        let mut gid = [0u8; 16];
        seq.copy_from_slice(&bytes[..8]);
        ts.copy_from_slice(&bytes[8..16]);
        gid.copy_from_slice(&bytes[17..]);
        Ok(Attachment {
            sequence_number: i64::from_le_bytes(seq),
            source_timestamp: i64::from_le_bytes(ts),
            gid,
        })
    }
}

/// What an endpoint is, in its token.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum EntityKind {
    Node,
    Publisher,
    Subscription,
}

impl EntityKind {
    pub fn code(self) -> &'static str {
        match self {
            EntityKind::Node => "NN",
            EntityKind::Publisher => "MP",
            EntityKind::Subscription => "MS",
        }
    }
}

/// A ROS 2 node as the graph sees it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Node {
    pub domain: u32,
    /// The zenoh session's id, as zenoh prints it.
    pub session_id: String,
    pub node_id: u64,
    /// The namespace, `/` or `/a/b`.
    pub namespace: String,
    pub name: String,
}

impl Node {
    /// The node's token: `@ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/%/<ns>/<name>`.
    pub fn token(&self) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{}/NN/%/{}/{}",
            self.domain,
            self.session_id,
            self.node_id,
            self.node_id,
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }

    /// A publisher's or subscription's token: the node's fields, then the topic, its DDS type,
    /// its type hash and its QoS.
    pub fn endpoint_token(
        &self,
        entity_id: u64,
        kind: EntityKind,
        topic: &str,
        dds_type: &str,
        type_hash: &str,
        qos: &Qos,
    ) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{entity_id}/{}/%/{}/{}/{}/{dds_type}/{type_hash}/{}",
            self.domain,
            self.session_id,
            self.node_id,
            kind.code(),
            mangle(&self.namespace),
            mangle(&self.name),
            mangle(topic),
            qos.encode()
        )
    }
}

/// The DDS type and type hash that a publisher's or subscription's liveliness token
/// ([`Node::endpoint_token`]) declares: its 11th and 12th chunks. `None` for a node's token or a
/// key that is not a token.
pub fn token_type(token: &str) -> Option<(&str, &str)> {
    let mut chunks = token.split('/');
    if chunks.next()? != ADMIN_SPACE {
        return None;
    }
    let mut rest = chunks.skip(4);
    if !matches!(rest.next()?, "MP" | "MS") {
        return None;
    }
    let mut rest = rest.skip(4);
    let (dds_type, hash) = (rest.next()?, rest.next()?);
    (!dds_type.is_empty() && !hash.is_empty()).then_some((dds_type, hash))
}

/// The QoS that a ROS 2 endpoint declares (the parts rmw_zenoh writes in tokens).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    pub reliable: bool,
    pub transient_local: bool,
    /// `None`: keep all.
    pub depth: Option<u32>,
}

impl Default for Qos {
    /// ROS 2's default profile: reliable, volatile, keep last 10.
    fn default() -> Qos {
        Qos { reliable: true, transient_local: false, depth: Some(10) }
    }
}

impl Qos {
    /// rmw_zenoh's compact form,
    /// `<reliability>:<durability>:<history>,<depth>:<deadline>:<lifespan>:<liveliness>`, with
    /// the fields equal to ROS 2's defaults left empty (deadline, lifespan and liveliness always
    /// are: kpl declares none).
    pub fn encode(&self) -> String {
        let mut out = String::new();
        if !self.reliable {
            out.push('2');
        }
        out.push(':');
        if self.transient_local {
            out.push('1');
        }
        out.push(':');
        match self.depth {
            Some(depth) => {
                let _ = write!(out, ",{depth}");
            }
            None => out.push_str("2,"),
        }
        out.push_str(":,:,:,,");
        out
    }

    /// Reads the compact form; empty fields are the defaults.
    pub fn decode(text: &str) -> Option<Qos> {
        let parts: Vec<&str> = text.split(':').collect();
        if parts.len() < 6 {
            return None;
        }
        let reliable = match parts[0] {
            "" | "0" | "1" => true,
            "2" => false,
            _ => return None,
        };
        let transient_local = match parts[1] {
            "" | "0" | "2" => false,
            "1" => true,
            _ => return None,
        };
        let (kind, depth) = parts[2].split_once(',').unwrap_or((parts[2], ""));
        let depth = match kind {
            "" | "0" | "1" => Some(if depth.is_empty() { 10 } else { depth.parse().ok()? }),
            "2" => None,
            _ => return None,
        };
        Some(Qos { reliable, transient_local, depth })
    }
}

/// A 16-byte GID for an endpoint: the first bytes of the SHA-256 of the session id and the
/// endpoint's id (stable for one session, different between endpoints).
pub fn gid(session_id: &str, entity_id: u64) -> [u8; 16] {
    let mut input = session_id.as_bytes().to_vec();
    input.extend_from_slice(&entity_id.to_le_bytes());
    let digest = ring::digest::digest(&ring::digest::SHA256, &input);
    let mut gid = [0u8; 16];
    gid.copy_from_slice(&digest.as_ref()[..16]);
    gid
}

/// A topic name that ROS 2 accepts: `/`-separated tokens of letters, digits and `_`, none empty,
/// none starting with a digit, no `__`; relative names (without `/`) resolve in the namespace.
pub fn check_topic(name: &str) -> Result<(), String> {
    let body = name.strip_prefix('/').unwrap_or(name);
    if body.is_empty() {
        return Err("a topic needs a name".into());
    }
    if name.contains("__") {
        return Err(format!("`{name}`: a ROS 2 name cannot contain `__`"));
    }
    for token in body.split('/') {
        let mut chars = token.chars();
        match chars.next() {
            None => return Err(format!("`{name}`: an empty token (`//` or a trailing `/`)")),
            Some(c) if c.is_ascii_digit() => {
                return Err(format!("`{name}`: a token cannot start with a digit"));
            }
            _ => {}
        }
        if !token.chars().all(|c| c.is_ascii_alphanumeric() || c == '_') {
            return Err(format!("`{name}`: only letters, digits, `_` and `/` are allowed"));
        }
    }
    Ok(())
}

/// The fully qualified name of a topic in a namespace (`markers` in `/robot` is `/robot/markers`).
pub fn qualify(namespace: &str, topic: &str) -> String {
    if topic.starts_with('/') {
        topic.to_string()
    } else {
        format!("{}/{topic}", namespace.trim_end_matches('/'))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qos_round_trips_and_defaults_are_empty() {
        assert_eq!(Qos::default().encode(), "::,10:,:,:,,");
        for qos in [
            Qos::default(),
            Qos { reliable: false, transient_local: true, depth: Some(1) },
            Qos { reliable: true, transient_local: false, depth: None },
        ] {
            assert_eq!(Qos::decode(&qos.encode()), Some(qos));
        }
    }

    #[test]
    fn topics() {
        assert!(check_topic("/tracker/markers").is_ok());
        assert!(check_topic("markers").is_ok());
        for bad in ["/", "/a//b", "/a/", "/2a", "/a b", "/a__b"] {
            assert!(check_topic(bad).is_err(), "{bad}");
        }
        assert_eq!(qualify("/robot", "markers"), "/robot/markers");
        assert_eq!(qualify("/", "markers"), "/markers");
        assert_eq!(demangle(&mangle("/tracker/markers")), "/tracker/markers");
    }

    #[test]
    fn attachments_of_other_lengths_are_refused() {
        assert_eq!(Attachment::decode(&[0; 17]), Err(AttachmentError::Length(17)));
        assert_eq!(Attachment::decode(&[0; 33]), Err(AttachmentError::GidLength(0)));
    }

    #[test]
    fn a_tokens_type_and_hash_are_its_eleventh_and_twelfth_chunks() {
        let node =
            Node { domain: 3, session_id: "aa".into(), node_id: 1, namespace: "/a".into(), name: "n".into() };
        let token = node.endpoint_token(
            7,
            EntityKind::Publisher,
            "/t/x",
            "pkg::msg::dds_::M_",
            "RIHS01_ab",
            &Qos::default(),
        );
        assert_eq!(token_type(&token), Some(("pkg::msg::dds_::M_", "RIHS01_ab")));
        assert_eq!(token_type(&node.token()), None);
        assert_eq!(token_type("other/3/aa/1/7/MP/%/%a/n/%t%x/T/H/q"), None);
        assert_eq!(token_type("@ros2_lv/3/aa/1/7/MP/%/%a/n"), None);
    }
}

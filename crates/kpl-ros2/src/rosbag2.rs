//! rosbag2's metadata, as `ros2 bag record` (rosbag2 with its MCAP storage, metadata version 9)
//! writes it: the bag folder's `metadata.yaml`, the same mapping in the MCAP file's `rosbag2`
//! metadata record (`serialized_metadata`), and the offered QoS profiles of a topic (a YAML list,
//! also in each channel's `offered_qos_profiles`). Text only: the MCAP file is `kpl-mcap`'s.
//!
//! ```
//! use kpl_ros2::rosbag2::{Bag, BagFile, BagTopic};
//! use kpl_ros2::wire::Qos;
//! let bag = Bag {
//!     files: vec![BagFile { path: "cars_0.mcap".into(), start: 1_000, end: 3_000, message_count: 2 }],
//!     start: 1_000,
//!     end: 3_000,
//!     topics: vec![BagTopic {
//!         name: "/kpl/cars".into(),
//!         type_name: "visualization_msgs/msg/MarkerArray".into(),
//!         type_hash: "RIHS01_00".into(),
//!         qos: Qos::default(),
//!         message_count: 2,
//!     }],
//! };
//! let yaml = bag.metadata_yaml();
//! assert!(yaml.starts_with("rosbag2_bagfile_information:\n  version: 9\n"));
//! assert!(yaml.contains("  message_count: 2\n"));
//! ```

use std::fmt::Write;

use crate::wire::Qos;

/// The metadata version rosbag2 writes since Jazzy (QoS profiles as a YAML list).
pub const VERSION: u32 = 9;

/// A bag: its MCAP files in order (one, unless the recording was split), the first and last
/// message's receive time (nanoseconds since the epoch) and its topics.
#[derive(Debug, Clone, PartialEq)]
pub struct Bag {
    pub files: Vec<BagFile>,
    pub start: u64,
    pub end: u64,
    pub topics: Vec<BagTopic>,
}

/// A file of a bag: its name in the folder, its first and last message's receive time
/// (nanoseconds since the epoch) and how many messages it holds.
#[derive(Debug, Clone, PartialEq)]
pub struct BagFile {
    pub path: String,
    pub start: u64,
    pub end: u64,
    pub message_count: u64,
}

/// A topic of a bag: its name, type (`pkg/msg/Name`), RIHS01 hash, QoS and message count.
#[derive(Debug, Clone, PartialEq)]
pub struct BagTopic {
    pub name: String,
    pub type_name: String,
    pub type_hash: String,
    pub qos: Qos,
    pub message_count: u64,
}

/// A YAML double-quoted scalar (JSON's escapes are YAML's).
fn quoted(s: &str) -> String {
    serde_json::Value::String(s.to_string()).to_string()
}

/// `RMW_DURATION_INFINITE` as rosbag2 writes it: seconds and nanoseconds of `i64::MAX` ns.
const INFINITE: (i64, i64) = (9_223_372_036, 854_775_807);

/// The offered QoS profiles of a topic (one: kpl's publisher), as a YAML list indented by
/// `indent` spaces.
pub fn qos_profiles(qos: &Qos, indent: usize) -> String {
    let pad = " ".repeat(indent);
    let (sec, nsec) = INFINITE;
    let mut out = String::new();
    let lines = [
        format!("history: {}", if qos.depth.is_some() { "keep_last" } else { "keep_all" }),
        format!("depth: {}", qos.depth.unwrap_or(0)),
        format!("reliability: {}", if qos.reliable { "reliable" } else { "best_effort" }),
        format!("durability: {}", if qos.transient_local { "transient_local" } else { "volatile" }),
        format!("deadline:\n{pad}    sec: {sec}\n{pad}    nsec: {nsec}"),
        format!("lifespan:\n{pad}    sec: {sec}\n{pad}    nsec: {nsec}"),
        "liveliness: automatic".to_string(),
        format!("liveliness_lease_duration:\n{pad}    sec: {sec}\n{pad}    nsec: {nsec}"),
        "avoid_ros_namespace_conventions: false".to_string(),
    ];
    for (i, line) in lines.iter().enumerate() {
        let lead = if i == 0 { "- " } else { "  " };
        let _ = writeln!(out, "{pad}{lead}{line}");
    }
    out
}

impl Bag {
    pub fn message_count(&self) -> u64 {
        self.topics.iter().map(|t| t.message_count).sum()
    }

    fn duration(&self) -> u64 {
        self.end.saturating_sub(self.start)
    }

    /// The bag's information, each line indented by `indent` spaces (2 in `metadata.yaml`, 0 in
    /// the MCAP file's `serialized_metadata`).
    pub fn information(&self, indent: usize) -> String {
        let p = " ".repeat(indent);
        let mut out = String::new();
        let _ = writeln!(out, "{p}version: {VERSION}");
        let _ = writeln!(out, "{p}storage_identifier: mcap");
        let _ = writeln!(out, "{p}duration:\n{p}  nanoseconds: {}", self.duration());
        let _ = writeln!(out, "{p}starting_time:\n{p}  nanoseconds_since_epoch: {}", self.start);
        let _ = writeln!(out, "{p}message_count: {}", self.message_count());
        if self.topics.is_empty() {
            let _ = writeln!(out, "{p}topics_with_message_count: []");
        } else {
            let _ = writeln!(out, "{p}topics_with_message_count:");
        }
        for topic in &self.topics {
            let _ = writeln!(out, "{p}  - topic_metadata:");
            let _ = writeln!(out, "{p}      name: {}", quoted(&topic.name));
            let _ = writeln!(out, "{p}      type: {}", quoted(&topic.type_name));
            let _ = writeln!(out, "{p}      serialization_format: cdr");
            let _ = writeln!(out, "{p}      offered_qos_profiles:");
            out.push_str(&qos_profiles(&topic.qos, indent + 8));
            let _ = writeln!(out, "{p}      type_description_hash: {}", quoted(&topic.type_hash));
            let _ = writeln!(out, "{p}    message_count: {}", topic.message_count);
        }
        let _ = writeln!(out, "{p}compression_format: \"\"");
        let _ = writeln!(out, "{p}compression_mode: \"\"");
        let _ = writeln!(out, "{p}relative_file_paths:");
        for file in &self.files {
            let _ = writeln!(out, "{p}  - {}", quoted(&file.path));
        }
        let _ = writeln!(out, "{p}files:");
        for file in &self.files {
            let _ = writeln!(out, "{p}  - path: {}", quoted(&file.path));
            let _ = writeln!(out, "{p}    starting_time:\n{p}      nanoseconds_since_epoch: {}", file.start);
            let _ = writeln!(
                out,
                "{p}    duration:\n{p}      nanoseconds: {}",
                file.end.saturating_sub(file.start)
            );
            let _ = writeln!(out, "{p}    message_count: {}", file.message_count);
        }
        let _ = writeln!(out, "{p}custom_data: ~");
        let _ = writeln!(out, "{p}ros_distro: kpl");
        out
    }

    /// The bag folder's `metadata.yaml`.
    pub fn metadata_yaml(&self) -> String {
        format!("rosbag2_bagfile_information:\n{}", self.information(2))
    }
}

/// The type hash a bag's `metadata.yaml` records for `topic`
/// (`topics_with_message_count[].topic_metadata.type_description_hash`, as `ros2 bag record`
/// writes it from Jazzy on; rosbags folds a long value onto the next, more indented line):
/// `None` when the topic or its hash is not there (bags before Jazzy).
pub fn recorded_type_hash(metadata_yaml: &str, topic: &str) -> Option<String> {
    recorded_type_hashes(metadata_yaml).remove(topic)
}

/// The type hashes a bag's `metadata.yaml` records, by topic ([`recorded_type_hash`]).
pub fn recorded_type_hashes(metadata_yaml: &str) -> std::collections::BTreeMap<String, String> {
    let mut hashes = std::collections::BTreeMap::new();
    let lines: Vec<&str> = metadata_yaml.lines().collect();
    let indent = |line: &str| line.len() - line.trim_start().len();
    // A plain or quoted scalar after `key:`, with its folded continuation lines.
    let scalar = |i: usize, rest: &str| {
        let mut value = rest.trim().to_string();
        for next in lines.iter().skip(i + 1) {
            if next.trim().is_empty() || indent(next) <= indent(lines[i]) {
                break;
            }
            if !value.is_empty() {
                value.push(' ');
            }
            value.push_str(next.trim());
        }
        let unquoted = value
            .strip_prefix('\'')
            .and_then(|v| v.strip_suffix('\''))
            .or_else(|| value.strip_prefix('"').and_then(|v| v.strip_suffix('"')))
            .unwrap_or(&value);
        unquoted.to_string()
    };
    let mut topics: Option<usize> = None;
    let mut entry: Option<usize> = None;
    let mut name: Option<String> = None;
    for (i, line) in lines.iter().enumerate() {
        let (at, text) = (indent(line), line.trim());
        if text.is_empty() || text.starts_with('#') {
            continue;
        }
        let Some(list) = topics else {
            if text == "topics_with_message_count:" {
                topics = Some(at);
            }
            continue;
        };
        if at < list || (at == list && !text.starts_with("- ")) {
            break;
        }
        if text.starts_with("- ") && entry.is_none_or(|e| e == at) {
            entry = Some(at);
            name = None;
        }
        let key = text.trim_start_matches("- ");
        if let Some(rest) = key.strip_prefix("name:") {
            name = Some(scalar(i, rest));
        } else if let Some(rest) = key.strip_prefix("type_description_hash:")
            && let Some(name) = name.take()
        {
            let hash = scalar(i, rest);
            if !hash.is_empty() {
                hashes.insert(name, hash);
            }
        }
    }
    hashes
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_recorded_type_hash_of_a_topic() {
        // As rosbags writes it (specs/ros2/tracker/metadata.yaml): the value folded.
        let rosbags = std::fs::read_to_string(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../../specs/ros2/tracker/metadata.yaml"
        ))
        .unwrap();
        assert_eq!(
            recorded_type_hash(&rosbags, "/tracker/markers").as_deref(),
            Some("RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf")
        );
        assert_eq!(recorded_type_hash(&rosbags, "/other"), None);
        // As `ros2 bag record` (Jazzy) writes it: entries open with `topic_metadata`, the QoS
        // profiles (a list) between the name and the hash, two topics.
        let record = "rosbag2_bagfile_information:\n  version: 9\n  topics_with_message_count:\n    - topic_metadata:\n        name: /a\n        type: std_msgs/msg/String\n        serialization_format: cdr\n        offered_qos_profiles:\n          - history: keep_last\n            depth: 10\n        type_description_hash: RIHS01_aaaa\n      message_count: 3\n    - topic_metadata:\n        name: \"/b\"\n        type: std_msgs/msg/String\n        offered_qos_profiles:\n          - history: keep_last\n        type_description_hash: 'RIHS01_bbbb'\n      message_count: 1\n  compression_format: \"\"\n";
        assert_eq!(recorded_type_hash(record, "/a").as_deref(), Some("RIHS01_aaaa"));
        assert_eq!(recorded_type_hash(record, "/b").as_deref(), Some("RIHS01_bbbb"));
        assert_eq!(recorded_type_hash(record, "/c"), None);
        let all = recorded_type_hashes(record);
        assert_eq!(all.keys().collect::<Vec<_>>(), ["/a", "/b"]);
        // Before Jazzy: no hash.
        assert_eq!(
            recorded_type_hash("topics_with_message_count:\n- topic_metadata:\n    name: /a\n", "/a"),
            None
        );
    }

    #[test]
    fn qos_is_a_yaml_list_of_rosbag2s_fields() {
        let qos = Qos { reliable: false, transient_local: true, depth: Some(5) };
        let text = qos_profiles(&qos, 0);
        assert!(text.starts_with("- history: keep_last\n  depth: 5\n  reliability: best_effort\n"));
        assert!(text.contains("  durability: transient_local\n"));
        assert!(text.contains("  deadline:\n    sec: 9223372036\n    nsec: 854775807\n"));
        assert_eq!(text.lines().count(), 15);
    }
}

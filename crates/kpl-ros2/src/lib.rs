//! ROS 2's wire, without ROS and without zenoh: what KPL needs to speak to ROS 2 nodes over
//! rmw_zenoh and to read and write their rosbag2 recordings. Pure (no I/O but reading a user's
//! `.msg` folder, no clock, no zenoh), so it is tested against ROS 2's own libraries and fuzzed.
//!
//! - [`msg`]: `.msg` definitions parsed into a model; [`Definitions`]: the shipped packages and a
//!   user's folders; [`Schema`]: one type with everything it uses, resolved;
//! - [`hash`]: RIHS01 type hashes;
//! - [`cdr`]: the dynamic CDR codec (with the encapsulation header), [`json`]: messages as JSON;
//! - [`mapping`]: fields of messages into KPL values and back, as a spec declares it, run by
//!   compiled plans (`plan`) that go between values and CDR without building the message;
//! - [`topic`]: a topic's type and mapping as a spec's call declares them, checked the same
//!   way by `kpl check` and a run;
//! - [`wire`]: rmw_zenoh's keys, attachment, liveliness tokens and QoS;
//! - [`rosbag2`]: a bag's `metadata.yaml` and the QoS profiles of its topics.
//!
//! The sources and sinks that use a zenoh session live in `kpl-zenoh`; docs/ros2.md describes
//! the whole.

mod builtin;
pub mod cdr;
pub mod definitions;
pub mod hash;
pub mod json;
pub mod mapping;
pub mod msg;
mod plan;
pub mod rosbag2;
pub mod topic;
pub mod wire;

pub use cdr::MsgValue;
pub use definitions::{DefError, Definitions, Schema};
pub use msg::TypeName;

//! MCAP recordings of KPL streams (docs/streams.md, "MCAP files"): what robotics tools (Foxglove,
//! the `mcap` command-line tool, the `mcap` Python package) open.
//!
//! - [`schema`]: the JSON schema of a KPL type, and of a sample of it.
//! - [`write::Recorder`]: one channel per stream, JSON messages `{"valid", "available",
//!   "value"}` described by their schema, the MCAP log time the available time and the publish
//!   time the valid time.
//! - [`read::Reader`]: the messages of a file in file order, filtered by stream before they are
//!   decoded, typed like a JSON-lines replay.
//! - [`builtins`]: the `file.mcap` sink and replay source.
//! - [`foxglove`]: the streams as Foxglove's well-known schemas (objects as scene entities,
//!   percepts as points, verdicts as logs, the [`scene`]'s roads, occluders and camera), written
//!   beside each stream's own channel so Foxglove's 3D panel draws a recording as it is.
//! - [`recover`]: what a file cut short by a killed run still holds.
//! - [`bag_sink`]: the `ros2.bag` sink: a stream recorded as a topic of a rosbag2 bag while the run goes.
//! - [`replay_ros2`]: the `ros2.replay` source: a bag's topic through a `ros2.subscribe` mapping.
//! - [`rosbag2`]: rosbag2 bags (a folder with `metadata.yaml` and the MCAP file) of the topics a
//!   spec's `ros2.publish` sinks declare.
//!
//! A recording converts to JSON lines and back without losing anything: the stream's name is the
//! channel's topic and the sample is the line's `valid`, `available` and `value`.
//!
//! ```
//! use kpl_core::{Value, ValueType};
//! use kpl_mcap::read::{Event, Reader};
//! use kpl_mcap::write::{Compression, Recorder};
//! use kpl_runtime::Sample;
//! use kpl_runtime::builtins::StreamFilter;
//!
//! let path = std::env::temp_dir().join(format!("kpl-mcap-doc-{}.mcap", std::process::id()));
//! let mut recorder = Recorder::create(&path, Compression::Zstd)?;
//! let speed = recorder.add_stream("speed", &ValueType::Float)?;
//! recorder.write(speed, &Sample::new(1_000, 1_200, Value::Float(12.5)))?;
//! recorder.finish()?;
//!
//! let mut reader = Reader::open(&path)?;
//! let mut filter = StreamFilter::new("speed");
//! match reader.next_event(&mut filter, &ValueType::Float) {
//!     Some(Event::Sample { stream, sample, .. }) => {
//!         assert_eq!(&*stream, "speed");
//!         assert_eq!(sample, Sample::new(1_000, 1_200, Value::Float(12.5)));
//!     }
//!     other => panic!("{other:?}"),
//! }
//! assert!(reader.next_event(&mut filter, &ValueType::Float).is_none());
//! # std::fs::remove_file(&path).ok();
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod bag_sink;
pub mod builtins;
pub mod foxglove;
pub mod read;
pub mod recover;
pub mod replay_ros2;
pub mod rosbag2;
pub mod scene;
pub mod schema;
pub mod write;

pub use builtins::register;

/// Channel metadata key that marks a channel written by KPL: its messages are sample envelopes
/// (`{"valid", "available", "value"}`); the value is the envelope format's version.
pub const SAMPLE_KEY: &str = "kpl.sample";
/// The envelope format version written in [`SAMPLE_KEY`].
pub const SAMPLE_VERSION: &str = "1";
/// Channel metadata key holding the stream's KPL type (`list<VisionPercept>`).
pub const TYPE_KEY: &str = "kpl.type";
/// Channel metadata key that marks a channel KPL writes for viewers beside a stream's own channel
/// (Foxglove's schemas, [`crate::foxglove`]); the value is the stream it shows. Readers of
/// samples skip these channels.
pub const VIEW_KEY: &str = "kpl.view";

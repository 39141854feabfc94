//! The ROS 2 cases of the zenoh benchmark (`kpl bench ros2`): a `geometry_msgs/msg/PoseStamped`
//! and a 100-marker `visualization_msgs/msg/MarkerArray` through kpl's own ROS 2 path, the code
//! of `ros2.publish` and `ros2.subscribe` (`crate::ros2`): a KPL value mapped into the message
//! and encoded as CDR, put on rmw_zenoh's key with the 33-byte attachment, by a publisher with its
//! node's and its own liveliness tokens; on the other side the attachment and type hash checked,
//! the CDR decoded and mapped back into a KPL value. Bare zenoh sends the CDR bytes of the same
//! message.
//!
//! One difference from a run: a run's subscription keeps the last `depth` messages (a ring that
//! drops the oldest when the run is busy), the benchmark's a FIFO that holds the sender back, as
//! the bare subscriber's does, so that every message arrives and both sides count the same.

use std::sync::Arc;
use std::time::Duration;

use kpl_core::{FieldType, Record, RecordType, Time, Value, ValueType};
use kpl_ros2::mapping::{InMap, InSpec, OutMap, OutSpec, workloads};
use zenoh::handlers::FifoChannelHandler;
use zenoh::liveliness::LivelinessToken;
use zenoh::pubsub::Subscriber;
use zenoh::sample::Sample;

use super::{BenchError, Payload, failed};
use crate::ros2::{self as path, Common, Open, Refused, Ros2Session};
use kpl_ros2::wire::EntityKind;

/// The benchmark's topics.
pub(super) const THROUGHPUT: &str = "/bench/throughput";
pub(super) const PING: &str = "/bench/ping";
pub(super) const PONG: &str = "/bench/pong";

/// The node of the benchmark's endpoints.
const NODE: &str = "kpl_bench";
/// The valid time of the first sample (a date in 2023, as a robot's stamps are).
const VALID: Time = 1_700_000_000_000_000;

/// A ROS 2 message of the benchmark: its type, the KPL value a sample carries, and the mappings
/// both ways (those of `specs/ros2/markers.kpl` for the markers).
pub(super) struct Message {
    type_name: &'static str,
    ty: ValueType,
    value: Value,
    out: OutSpec,
    into: InSpec,
}

fn record_type(name: &str, symbol: &str, fields: &[(&str, ValueType)]) -> Arc<RecordType> {
    let fields = fields.iter().map(|(n, ty)| FieldType { name: (*n).into(), ty: ty.clone() }).collect();
    Arc::new(RecordType { name: name.into(), parent: None, symbol: symbol.into(), fields })
}

fn record(id: Option<String>, fields: Vec<(&str, Value)>) -> Value {
    let fields = fields.into_iter().map(|(n, v)| (Arc::from(n), v)).collect();
    Value::Record(Arc::new(Record { id: id.map(Into::into), fields }))
}

fn entries(list: &[&str]) -> Vec<String> {
    list.iter().map(|e| (*e).to_string()).collect()
}

/// The ROS 2 message a payload stands for (none for the payloads of KPL's own streams).
pub(super) fn message(payload: Payload) -> Option<Message> {
    match payload {
        Payload::String | Payload::Floats => None,
        Payload::PoseStamped => {
            let ty = record_type(
                "Pose",
                "po",
                &[
                    ("pos", ValueType::Vec2),
                    ("z", ValueType::Float),
                    ("yaw_z", ValueType::Float),
                    ("yaw_w", ValueType::Float),
                ],
            );
            let value = record(
                None,
                vec![
                    ("pos", Value::Vec2([412.25, -37.5])),
                    ("z", Value::Float(1.25)),
                    ("yaw_z", Value::Float(0.3826834)),
                    ("yaw_w", Value::Float(0.9238795)),
                ],
            );
            Some(Message {
                type_name: "geometry_msgs/msg/PoseStamped",
                ty: ValueType::Record(ty),
                value,
                out: OutSpec { each: None, entries: entries(workloads::POSE_STAMPED) },
                into: InSpec {
                    each: None,
                    identity: None,
                    stamp: None,
                    entries: entries(workloads::POSE_OF_POSE_STAMPED),
                },
            })
        }
        Payload::MarkerArray => {
            let car = record_type("Car", "co", &[("pos", ValueType::Vec2), ("size", ValueType::Float)]);
            let cars = (0..100)
                .map(|i| {
                    record(
                        Some(format!("co{i}")),
                        vec![
                            ("pos", Value::Vec2([100.0 + i as f64 * 3.5, -40.0 + i as f64 * 0.25])),
                            ("size", Value::Float(4.5 + (i % 3) as f64)),
                        ],
                    )
                })
                .collect();
            Some(Message {
                type_name: "visualization_msgs/msg/MarkerArray",
                ty: ValueType::List(Box::new(ValueType::Record(car))),
                value: Value::List(cars),
                out: OutSpec { each: Some("markers".into()), entries: entries(workloads::MARKERS_OF_CARS) },
                into: InSpec {
                    each: Some("markers".into()),
                    identity: Some("id".into()),
                    stamp: None,
                    entries: entries(workloads::PERCEPTS_OF_MARKERS),
                },
            })
        }
    }
}

impl Message {
    /// The KPL value of the `i`th sample and its valid time.
    pub(super) fn sample(&self, i: usize) -> (Time, Value) {
        (VALID + i as Time * 1_000, self.value.clone())
    }

    fn common(&self, topic: &str, depth: u32) -> Result<Common, BenchError> {
        Common::shipped(topic, self.type_name, NODE, depth).map_err(BenchError::Failed)
    }

    /// The CDR message kpl puts on the wire for the first sample: what bare zenoh sends.
    pub(super) fn cdr(&self) -> Result<Vec<u8>, BenchError> {
        let common = self.common("/bench", 1)?;
        let mut map =
            OutMap::compile(common.schema().clone(), &self.out, &self.ty).map_err(|e| failed(e.message))?;
        let mut bytes = Vec::new();
        let (valid, value) = self.sample(0);
        path::encode(&common, &mut map, valid, &value, &mut bytes).map_err(failed)?;
        Ok(bytes)
    }

    /// Whether `value` is the value the samples carry (what came back is what was sent).
    pub(super) fn is_sent(&self, value: &Value) -> bool {
        *value == self.value
    }
}

/// `ros2.publish`'s path on a topic.
pub(super) struct Writer {
    common: Common,
    map: OutMap,
    open: Open,
    buffer: Vec<u8>,
}

impl Writer {
    pub(super) async fn declare(
        session: &Arc<Ros2Session>,
        topic: &str,
        message: &Message,
    ) -> Result<Writer, BenchError> {
        let common = message.common(topic, 10)?;
        let map = OutMap::compile(common.schema().clone(), &message.out, &message.ty)
            .map_err(|e| failed(e.message))?;
        let open = Open::declare(session.clone(), &common).await.map_err(failed)?;
        Ok(Writer { common, map, open, buffer: Vec::new() })
    }

    pub(super) fn publisher(&self) -> &zenoh::pubsub::Publisher<'static> {
        self.open.publisher()
    }

    /// Maps, encodes and puts one sample (its valid time is also its source time stamp).
    pub(super) async fn send(&mut self, valid: Time, value: &Value) -> Result<(), BenchError> {
        path::encode(&self.common, &mut self.map, valid, value, &mut self.buffer).map_err(failed)?;
        self.open.put(&self.buffer, valid).await.map_err(failed)
    }
}

/// `ros2.subscribe`'s path on a topic (with a FIFO: the module's doc).
pub(super) struct Reader {
    common: Common,
    map: InMap,
    subscriber: Subscriber<FifoChannelHandler<Sample>>,
    _token: LivelinessToken,
}

impl Reader {
    pub(super) async fn declare(
        session: &Arc<Ros2Session>,
        topic: &str,
        message: &Message,
        queue: usize,
    ) -> Result<Reader, BenchError> {
        let common = message.common(topic, 10)?;
        let map =
            InMap::compile(common.schema(), &message.into, &message.ty).map_err(|e| failed(e.message))?;
        let subscriber = session
            .session
            .declare_subscriber(common.data_key())
            .with(zenoh::handlers::FifoChannel::new(queue))
            .await
            .map_err(failed)?;
        let (_, token) = session.endpoint_token(&common, EntityKind::Subscription).await.map_err(failed)?;
        Ok(Reader { common, map, subscriber, _token: token })
    }

    /// The next sample (its valid time and value); `None` if none came within `wait`, an error
    /// for a message kpl refuses.
    pub(super) async fn recv(&self, wait: Duration) -> Result<Option<(Time, Value)>, BenchError> {
        let Ok(Ok(message)) = tokio::time::timeout(wait, self.subscriber.recv_async()).await else {
            return Ok(None);
        };
        match path::take(&self.common, &self.map, &message, 0).1 {
            Ok(taken) => Ok(Some(taken)),
            Err(Refused::Attachment(e) | Refused::TypeHash(e) | Refused::Malformed(e)) => {
                Err(BenchError::Failed(e))
            }
        }
    }
}

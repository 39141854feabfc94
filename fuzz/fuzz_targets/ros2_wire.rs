//! ROS 2's wire from the network never panics: arbitrary bytes decoded as CDR of a few shipped
//! types (and re-encoded when they decode), as an rmw_zenoh attachment, and as a `.msg` text.
//! `cd fuzz && cargo fuzz run -s none ros2_wire`
#![no_main]

use std::sync::OnceLock;

use kpl_ros2::{Definitions, Schema, cdr, msg, wire};
use libfuzzer_sys::fuzz_target;

fn schemas() -> &'static [std::sync::Arc<Schema>] {
    static SCHEMAS: OnceLock<Vec<std::sync::Arc<Schema>>> = OnceLock::new();
    SCHEMAS.get_or_init(|| {
        let defs = Definitions::builtin();
        ["visualization_msgs/msg/MarkerArray", "sensor_msgs/msg/PointCloud2", "nav_msgs/msg/Odometry", "vision_msgs/msg/Detection2DArray"]
            .iter()
            .filter_map(|t| defs.schema_of(t).ok())
            .collect()
    })
}

fuzz_target!(|data: &[u8]| {
    for schema in schemas() {
        if let Ok(value) = cdr::decode(schema, data) {
            let _ = cdr::encode(schema, &value);
        }
    }
    let _ = wire::Attachment::decode(data);
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = msg::parse("fuzz_msgs", "Fuzz", text);
    }
});

//! A ROS 2 topic as a spec's call declares it (`ros2.subscribe`, `ros2.publish`, `ros2.replay`,
//! and the topics `kpl convert` writes into a rosbag2 bag): its message type, from the shipped
//! packages or the call's `msgs` folder, and its mapping, read from the call's parameters. One
//! reading for `kpl check` and for the runtime, so both find the same problems.
//!
//! ```
//! use std::collections::BTreeMap;
//! use kpl_core::{FieldType, RecordType, Value, ValueType};
//! let params = BTreeMap::from([
//!     ("type".to_string(), Value::str("geometry_msgs/msg/PoseStamped")),
//!     ("map".to_string(), Value::List(vec![Value::str("pose.position = pos")].into())),
//! ]);
//! let fields = vec![FieldType { name: "pos".into(), ty: ValueType::Vec2 }];
//! let pose = RecordType { name: "Pose".into(), parent: None, symbol: "pose".into(), fields };
//! assert!(kpl_ros2::topic::check_out(&params, &ValueType::Record(pose.into()), None).is_ok());
//! ```

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::Arc;

use kpl_core::{Value, ValueType};
use kpl_semantic::registry::ParamProblem;

use crate::definitions::{Definitions, Schema};
use crate::mapping::{InMap, InSpec, MapError, OutMap, OutSpec};

/// A text parameter (`""` when absent).
pub fn text<'a>(params: &'a BTreeMap<String, Value>, name: &str) -> &'a str {
    params.get(name).and_then(Value::as_str).unwrap_or("")
}

fn non_empty(params: &BTreeMap<String, Value>, name: &str) -> Option<String> {
    Some(text(params, name)).filter(|s| !s.is_empty()).map(String::from)
}

fn list(params: &BTreeMap<String, Value>, name: &str) -> Vec<String> {
    match params.get(name) {
        Some(Value::List(items)) => items.iter().filter_map(|v| v.as_str().map(String::from)).collect(),
        _ => Vec::new(),
    }
}

/// The mapping into KPL that `each`, `identity`, `stamp` and `map` declare.
pub fn in_spec(params: &BTreeMap<String, Value>) -> InSpec {
    InSpec {
        each: non_empty(params, "each"),
        identity: non_empty(params, "identity"),
        stamp: non_empty(params, "stamp"),
        entries: list(params, "map"),
    }
}

/// The mapping out of KPL that `each` and `map` declare.
pub fn out_spec(params: &BTreeMap<String, Value>) -> OutSpec {
    OutSpec { each: non_empty(params, "each"), entries: list(params, "map") }
}

fn problem(param: &'static str, message: String, hint: Option<String>) -> MapError {
    MapError { param, entry: None, range: (0, 0), message, hint }
}

/// The schema of the call's `type`: a shipped type, or one of its `msgs` folder read from the
/// spec's folder `dir`. `Ok(None)` when the type is not shipped and the folder cannot be read
/// because the spec has no folder (`dir` is `None`: standard input); the run reads it then.
pub fn schema(params: &BTreeMap<String, Value>, dir: Option<&Path>) -> Result<Option<Arc<Schema>>, MapError> {
    let msgs = text(params, "msgs");
    let ty = text(params, "type");
    let user;
    let defs = match (msgs.is_empty(), dir) {
        (true, _) => Definitions::shipped(),
        (false, None) => return Ok(Definitions::shipped().schema_of(ty).ok()),
        (false, Some(dir)) => {
            let mut defs = Definitions::shipped().clone();
            if let Err(errors) = defs.add_folder(&dir.join(msgs)) {
                let list: Vec<String> = errors.iter().map(ToString::to_string).collect();
                let hint = "a folder of `<package>/msg/<Name>.msg` files, relative to the spec";
                return Err(problem("msgs", list.join("; "), Some(hint.into())));
            }
            user = defs;
            &user
        }
    };
    defs.schema_of(ty).map(Some).map_err(|e| {
        let hint = e.hint().map(String::from).unwrap_or_else(|| {
            if msgs.is_empty() {
                "a shipped type (docs/ros2.md), or name a folder of your own `.msg` files in `msgs`".into()
            } else {
                format!("a shipped type (docs/ros2.md) or one of `{msgs}`")
            }
        });
        problem("type", e.to_string(), Some(hint))
    })
}

/// The schema of the call's `type` when a run or a conversion starts: the spec's folder is known.
pub fn schema_in(params: &BTreeMap<String, Value>, dir: &Path) -> Result<Arc<Schema>, MapError> {
    schema(params, Some(dir))?.ok_or_else(|| problem("type", "no message type".into(), None))
}

/// Checks a mapping into KPL (a subscription, a replay) against the message type and the
/// stream's type `output`.
pub fn check_in(
    params: &BTreeMap<String, Value>,
    output: &ValueType,
    dir: Option<&Path>,
) -> Result<(), MapError> {
    match schema(params, dir)? {
        Some(schema) => InMap::compile(&schema, &in_spec(params), output).map(|_| ()),
        None => Ok(()),
    }
}

/// Checks a mapping out of KPL (a publication) against the message type and the input's type.
pub fn check_out(
    params: &BTreeMap<String, Value>,
    input: &ValueType,
    dir: Option<&Path>,
) -> Result<(), MapError> {
    match schema(params, dir)? {
        Some(schema) => OutMap::compile(schema, &out_spec(params), input).map(|_| ()),
        None => Ok(()),
    }
}

/// A mapping problem as `kpl check` reports it (for `ros2.subscribe`, `ros2.publish`,
/// `ros2.replay` and `ros2.bag` alike): in the entry of `map` it names, or else the parameter.
pub fn param_problem(e: MapError) -> ParamProblem {
    let (param, element) = match e.entry {
        Some(i) => ("map".to_string(), Some(i)),
        None => (e.param.to_string(), None),
    };
    ParamProblem { param, element, range: e.range, message: e.message, hint: e.hint }
}

/// A mapping problem as one line (for a run or a conversion): the part of the `map` entry (or
/// the parameter) that is wrong, the problem and the hint.
pub fn describe(params: &BTreeMap<String, Value>, e: &MapError) -> String {
    let entries = list(params, "map");
    let at = match e.entry.and_then(|i| entries.get(i)) {
        Some(entry) => format!("`{}` of `map` (\"{entry}\")", entry.get(e.range.0..e.range.1).unwrap_or("")),
        None => format!("`{}`", e.param),
    };
    let hint = e.hint.as_ref().map(|h| format!("; {h}")).unwrap_or_default();
    format!("{at}: {}{hint}", e.message)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(pairs: &[(&str, Value)]) -> BTreeMap<String, Value> {
        pairs.iter().map(|(k, v)| (k.to_string(), v.clone())).collect()
    }

    fn folder() -> std::path::PathBuf {
        let dir = std::env::temp_dir().join(format!("kpl-ros2-topic-{}", std::process::id()));
        let msg = dir.join("msgs/fleet_msgs/msg");
        std::fs::create_dir_all(&msg).unwrap();
        std::fs::write(msg.join("Vehicle.msg"), "uint32 track_id\ngeometry_msgs/Point position\n").unwrap();
        dir
    }

    #[test]
    fn a_user_type_is_checked_where_the_spec_is() {
        let dir = folder();
        let fields = vec![kpl_core::FieldType { name: "pos".into(), ty: ValueType::Vec2 }];
        let ty = kpl_core::RecordType { name: "Pose".into(), parent: None, symbol: "pose".into(), fields };
        let output = ValueType::Record(ty.into());
        let good = params(&[
            ("type", Value::str("fleet_msgs/msg/Vehicle")),
            ("msgs", Value::str("msgs")),
            ("map", Value::List(vec![Value::str("pos = position")].into())),
        ]);
        assert_eq!(check_in(&good, &output, Some(&dir)), Ok(()));
        // Without the spec's folder the user's type waits for the run.
        assert_eq!(check_in(&good, &output, None), Ok(()));
        let mut bad = good.clone();
        bad.insert("map".into(), Value::List(vec![Value::str("pos = positon")].into()));
        let e = check_in(&bad, &output, Some(&dir)).unwrap_err();
        assert_eq!((e.entry, e.hint.as_deref()), (Some(0), Some("did you mean `position`?")));
        let mut missing = good.clone();
        missing.insert("msgs".into(), Value::str("nowhere"));
        assert_eq!(check_in(&missing, &output, Some(&dir)).unwrap_err().param, "msgs");
        let mut unknown = good;
        unknown.insert("type".into(), Value::str("fleet_msgs/msg/Truck"));
        let e = check_in(&unknown, &output, Some(&dir)).unwrap_err();
        assert_eq!(e.param, "type");
        assert_eq!(e.hint.as_deref(), Some("a shipped type (docs/ros2.md) or one of `msgs`"));
        std::fs::remove_dir_all(dir).ok();
    }
}

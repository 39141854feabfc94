//! Time, durations and dynamically typed values shared by every KPL layer.
//!
//! Everything above this crate (syntax, semantic analysis, the MTL engine, the runtime, anchoring)
//! speaks of time as integer microseconds ([`Time`]) and of data as [`Value`]s whose shape is given
//! by a [`ValueType`]. This crate has no clock; its only I/O is [`read`]: reading the files users
//! give with caps on their size and their lines, which every reader of the workspace shares.
//!
//! ```
//! use kpl_core::{TimeUnit, Value};
//! assert_eq!(TimeUnit::Ms.to_micros(250), Some(250_000));
//! let v = Value::vec2(3.0, 4.0);
//! assert_eq!(v.as_vec2(), Some([3.0, 4.0]));
//! ```

pub mod read;
pub mod suggest;
mod time;
mod value;

pub use suggest::{closest, did_you_mean};
pub use time::{Time, TimeUnit, format_micros, parse_duration};
pub use value::{
    BBox, FieldHint, FieldType, JsonError, OBJECT_STATUS, Record, RecordType, Value, ValueType,
    object_status_type,
};

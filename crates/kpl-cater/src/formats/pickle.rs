//! OPNet's per-video perception pickles, `<video>.pkl`: `{"bb": [frame boxes], "labels": [frame
//! labels]}` with, per frame, the boxes `[x1, y1, x2, y2]` and OPNet's class indices of the objects
//! perceived. OPNet's detector writes numpy arrays (`astype(np.int)`, `pickle.HIGHEST_PROTOCOL`),
//! its perfect perception lists of boxes and numpy label arrays.
//!
//! The pickle is decoded by `serde-pickle` (no Python objects are built): a numpy array arrives as
//! its restore state, `(1, shape, dtype, fortran, raw bytes)` for protocols 2 to 4 or `(raw bytes,
//! dtype, shape, order)` for protocol 5. The dtype is either its type string (`"i8"`, `"<f4"`) or,
//! for the first array of a pickle, only its state (byte order, no type): the element type is then
//! told from the item size and the values, integers unless they only make sense as IEEE floats
//! (integers read from a float array's bits are at least 2^23 for 4-byte and 2^52 for 8-byte
//! items, never pixel coordinates or class indices).

use std::path::Path;

use serde_pickle::{DeOptions, HashableValue, SerOptions, Value};

use super::{MAX_PICKLE_BYTES, pickle_guard, read_capped};
use crate::error::CaterError;

/// Per frame, `(label, [x1, y1, x2, y2])` for each object perceived.
pub type PickleFrames = Vec<Vec<(i64, [f64; 4])>>;

/// Reads a perception pickle's frames.
pub fn read_perception_pickle(path: &Path) -> Result<PickleFrames, CaterError> {
    let bytes = read_capped(path, MAX_PICKLE_BYTES)?;
    // Refuse what would overflow the decoder's stack or expand beyond any perception's size before
    // decoding (see `pickle_guard`).
    pickle_guard::check(&bytes).map_err(|reason| {
        CaterError::invalid(path, format!("not a pickle of OPNet's perception: {reason}"))
    })?;
    let value = serde_pickle::value_from_slice(
        &bytes,
        DeOptions::new().keep_restore_state().replace_unresolved_globals(),
    )
    .map_err(|e| CaterError::invalid(path, format!("not a pickle serde-pickle can read: {e}")))?;
    let bad = |reason: String| CaterError::invalid(path, reason);
    let Value::Dict(map) = value else {
        return Err(bad("expected a dict with `bb` and `labels`".into()));
    };
    let field = |name: &str| {
        map.get(&HashableValue::String(name.to_owned())).ok_or_else(|| {
            bad(format!("no `{name}` in the pickle (OPNet's perception has `bb` and `labels`)"))
        })
    };
    let bb = sequence(field("bb")?).ok_or_else(|| bad("`bb` is not a list of frames".into()))?;
    let labels = sequence(field("labels")?).ok_or_else(|| bad("`labels` is not a list of frames".into()))?;
    if bb.len() != labels.len() {
        return Err(bad(format!("{} frames of boxes but {} of labels", bb.len(), labels.len())));
    }
    let mut frames = Vec::with_capacity(bb.len());
    for (frame, (boxes, labels)) in bb.iter().zip(labels).enumerate() {
        let boxes = numbers(boxes).map_err(|e| bad(format!("frame {frame}: boxes: {e}")))?;
        let labels = numbers(labels).map_err(|e| bad(format!("frame {frame}: labels: {e}")))?;
        if boxes.values.len() != labels.values.len() * 4 {
            return Err(bad(format!(
                "frame {frame}: {} labels but {} box coordinates (4 per box)",
                labels.values.len(),
                boxes.values.len()
            )));
        }
        let mut detections = Vec::with_capacity(labels.values.len());
        for (k, label) in labels.values.iter().enumerate() {
            if label.fract() != 0.0 || label.abs() > 1e9 {
                return Err(bad(format!("frame {frame}: label {label} is not a class index")));
            }
            let b = &boxes.values[4 * k..4 * k + 4];
            detections.push((*label as i64, [b[0], b[1], b[2], b[3]]));
        }
        frames.push(detections);
    }
    Ok(frames)
}

/// Writes a perception pickle in OPNet's layout, `{"bb": [frame boxes], "labels": [frame labels]}`,
/// as plain lists of integers (what OPNet's perfect perception script writes for boxes; OPNet's
/// readers turn labels into numpy arrays either way).
pub fn write_perception_pickle(path: &Path, frames: &[Vec<(i64, [i64; 4])>]) -> Result<(), CaterError> {
    let bb = frames
        .iter()
        .map(|f| {
            Value::List(
                f.iter().map(|(_, b)| Value::List(b.iter().map(|v| Value::I64(*v)).collect())).collect(),
            )
        })
        .collect();
    let labels =
        frames.iter().map(|f| Value::List(f.iter().map(|(l, _)| Value::I64(*l)).collect())).collect();
    let value = Value::Dict(
        [
            (HashableValue::String("bb".into()), Value::List(bb)),
            (HashableValue::String("labels".into()), Value::List(labels)),
        ]
        .into_iter()
        .collect(),
    );
    let bytes = serde_pickle::value_to_vec(&value, SerOptions::new())
        .map_err(|e| CaterError::invalid(path, format!("encoding the pickle: {e}")))?;
    std::fs::write(path, bytes).map_err(|source| CaterError::Io { path: path.to_owned(), source })
}

fn sequence(value: &Value) -> Option<&[Value]> {
    match value {
        Value::List(items) | Value::Tuple(items) => Some(items),
        _ => None,
    }
}

/// The numbers of a (possibly nested) list or a numpy array, flattened in C order.
#[derive(Debug)]
struct Numbers {
    values: Vec<f64>,
}

fn numbers(value: &Value) -> Result<Numbers, String> {
    if let Some(array) = numpy_array(value)? {
        return Ok(array);
    }
    let mut values = Vec::new();
    flatten(value, &mut values, 0)?;
    Ok(Numbers { values })
}

fn flatten(value: &Value, out: &mut Vec<f64>, depth: usize) -> Result<(), String> {
    if depth > 3 {
        return Err("nested too deeply".into());
    }
    match value {
        Value::I64(v) => out.push(*v as f64),
        Value::F64(v) => out.push(*v),
        Value::Bool(b) => out.push(f64::from(u8::from(*b))),
        Value::List(items) | Value::Tuple(items) => {
            for item in items {
                if let Some(array) = numpy_array(item)? {
                    out.extend(array.values);
                } else {
                    flatten(item, out, depth + 1)?;
                }
            }
        }
        Value::Int(_) => return Err("an integer too large for 64 bits".into()),
        other => return Err(format!("expected numbers, found {}", kind(other))),
    }
    Ok(())
}

fn kind(value: &Value) -> &'static str {
    match value {
        Value::None => "None",
        Value::Bool(_) => "a bool",
        Value::I64(_) | Value::Int(_) => "an integer",
        Value::F64(_) => "a float",
        Value::Bytes(_) => "bytes",
        Value::String(_) => "a string",
        Value::List(_) => "a list",
        Value::Tuple(_) => "a tuple",
        Value::Set(_) | Value::FrozenSet(_) => "a set",
        Value::Dict(_) => "a dict",
    }
}

/// A numpy array's restore state, if `value` is one: `(1, shape, dtype, fortran, bytes)` (protocols
/// 2 to 4) or `(bytes, dtype, shape, order)` (protocol 5).
fn numpy_array(value: &Value) -> Result<Option<Numbers>, String> {
    let Value::Tuple(items) = value else { return Ok(None) };
    let (shape, dtype, fortran, raw) = match items.as_slice() {
        [Value::I64(1), Value::Tuple(shape), dtype @ Value::Tuple(_), Value::Bool(fortran), raw] => {
            (shape, dtype, *fortran, raw)
        }
        [raw @ Value::Bytes(_), dtype @ Value::Tuple(_), Value::Tuple(shape), Value::String(order)] => {
            (shape, dtype, order == "F", raw)
        }
        // `_reconstruct`'s arguments: a second reference to an array the pickle already holds, which
        // serde-pickle gives back as it was before its data was set.
        [Value::None, Value::Tuple(_), Value::Bytes(b)] if b.as_slice() == b"b" => {
            return Err("the same numpy array object appears twice (shared arrays are not supported)".into());
        }
        _ => return Ok(None),
    };
    let dims: Vec<usize> = shape
        .iter()
        .map(|d| match d {
            Value::I64(n) => usize::try_from(*n).map_err(|_| format!("negative dimension {n}")),
            other => Err(format!("a dimension is {}", kind(other))),
        })
        .collect::<Result<_, _>>()?;
    let count = dims.iter().try_fold(1usize, |acc, d| acc.checked_mul(*d)).ok_or("array too large")?;
    let bytes: &[u8] = match raw {
        Value::Bytes(b) => b,
        // An empty array's data may be an empty tuple.
        Value::Tuple(t) if t.is_empty() => &[],
        Value::List(_) => return Err("numpy arrays of Python objects are not supported".into()),
        other => return Err(format!("array data is {}", kind(other))),
    };
    if fortran && dims.len() > 1 && count > 0 {
        return Err("Fortran-ordered arrays are not supported".into());
    }
    if count == 0 {
        if !bytes.is_empty() {
            return Err("an empty array with data".into());
        }
        return Ok(Some(Numbers { values: Vec::new() }));
    }
    if !bytes.len().is_multiple_of(count) {
        return Err(format!("{} bytes for {count} elements", bytes.len()));
    }
    let item = bytes.len() / count;
    let (declared, big_endian) = describe_dtype(dtype);
    let values = decode_elements(bytes, item, declared, big_endian)?;
    Ok(Some(Numbers { values }))
}

/// What a dtype says: the type letter when known (`i`, `u`, `f`, `b`) and whether it is
/// big-endian.
fn describe_dtype(dtype: &Value) -> (Option<char>, bool) {
    let Value::Tuple(items) = dtype else { return (None, false) };
    match items.first() {
        // The REDUCE arguments: ("i8", False, True).
        Some(Value::String(code)) => {
            let big = code.starts_with('>');
            let letter = code.trim_start_matches(['<', '>', '=', '|']).chars().next();
            (letter, big)
        }
        // The state: (3, "<", ...): only the byte order.
        Some(Value::I64(_)) => (None, matches!(items.get(1), Some(Value::String(s)) if s == ">")),
        _ => (None, false),
    }
}

fn decode_elements(bytes: &[u8], item: usize, letter: Option<char>, big: bool) -> Result<Vec<f64>, String> {
    let word = |chunk: &[u8]| -> u64 {
        let mut v = 0u64;
        if big {
            for b in chunk {
                v = (v << 8) | u64::from(*b);
            }
        } else {
            for b in chunk.iter().rev() {
                v = (v << 8) | u64::from(*b);
            }
        }
        v
    };
    let words: Vec<u64> = bytes.chunks_exact(item).map(word).collect();
    let signed = |w: u64| -> i64 {
        let bits = 8 * item as u32;
        if bits >= 64 { w as i64 } else { ((w << (64 - bits)) as i64) >> (64 - bits) }
    };
    let as_float = |w: u64| -> Option<f64> {
        match item {
            8 => Some(f64::from_bits(w)),
            4 => Some(f64::from(f32::from_bits(w as u32))),
            _ => None,
        }
    };
    let letter = match letter {
        Some(l) => l,
        None => {
            // Integers unless only floats make sense (see the module docs).
            let limit: i64 = if item >= 8 {
                1 << 40
            } else if item == 4 {
                1 << 23
            } else {
                i64::MAX
            };
            if words.iter().all(|w| signed(*w).abs() < limit) { 'i' } else { 'f' }
        }
    };
    match letter {
        'i' => Ok(words.iter().map(|w| signed(*w) as f64).collect()),
        'u' | 'b' => Ok(words.iter().map(|w| *w as f64).collect()),
        'f' => words
            .iter()
            .map(|w| {
                as_float(*w)
                    .filter(|v| v.is_finite())
                    .ok_or_else(|| format!("{item}-byte items that are not finite floats"))
            })
            .collect(),
        other => Err(format!("unsupported numpy type `{other}`")),
    }
}

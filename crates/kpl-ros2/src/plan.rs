//! Compiled plans that go between KPL values and CDR bytes without building a [`MsgValue`]
//! tree: what [`OutMap::encode_into`](crate::mapping::OutMap::encode_into) and
//! [`InMap::decode`](crate::mapping::InMap::decode) run per message.
//!
//! An [`EncodePlan`] is the layout of the output message as a list of operations, compiled once
//! per (schema, mapping): the runs of fields the mapping does not set are precomputed as bytes,
//! one version per start offset modulo 8 (a run's padding depends only on that: no primitive is
//! aligned to more than 8), and the fields it sets are written from the sample's values, aligned
//! as the codec ([`crate::cdr`]) aligns them. A sample's entries are evaluated in the mapping's
//! order before its fields are written, as `OutMap::apply` does, so a field set twice keeps the
//! last value and `number` counts symbols in the same order.
//!
//! A [`DecodePlan`] walks the CDR of a message and reads only the fields the mapping uses;
//! everything else is skipped by size (runs of fixed-size fields, one length per start offset
//! modulo 8) or by its length prefix, and still checked as [`crate::cdr::decode`] checks it (a
//! bool is 0 or 1, a string has its NUL and is UTF-8, a sequence keeps its bound and fits in what
//! is left), so that a message is refused by the plan exactly when the codec refuses it. Nothing
//! is allocated but the KPL values themselves.
//!
//! Both plans are an optimization of the tree path (`cdr::encode(OutMap::apply(..))` and
//! `InMap::apply(cdr::decode(..))`), which stays the reference: a mapping the plans do not cover
//! (an entry that sets a whole message or array, a fixed-size `each` array, a `wstring`, a
//! redefined `builtin_interfaces/Time`) has no plan, and when a plan fails on a message the tree
//! path runs again to give its exact error. The differential tests (tests/plans.rs) check both
//! against each other.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::sync::{Arc, Mutex};

use rustc_hash::FxHashMap;

use kpl_core::{Record, RecordType, Time, Value, ValueType};

use crate::cdr::MsgValue;
use crate::definitions::{Schema, SchemaBase};
use crate::mapping::{End, Path, Source, number_of, number_value, time_value};
use crate::msg::{ArrayKind, Primitive};

/// One primitive's value as the tree path would hold it (the same variants as [`MsgValue`]).
#[derive(Debug, Clone)]
enum Leaf {
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    Str(Arc<str>),
}

impl Leaf {
    fn scalar(&self) -> Scalar<'_> {
        match self {
            Leaf::Bool(b) => Scalar::Bool(*b),
            Leaf::Int(i) => Scalar::Int(*i),
            Leaf::UInt(u) => Scalar::UInt(*u),
            Leaf::Float(x) => Scalar::Float(*x),
            Leaf::Str(s) => Scalar::Str(s),
        }
    }

    fn of(v: &MsgValue) -> Option<Leaf> {
        Some(match v {
            MsgValue::Bool(b) => Leaf::Bool(*b),
            MsgValue::Int(i) => Leaf::Int(*i),
            MsgValue::UInt(u) => Leaf::UInt(*u),
            MsgValue::Float(x) => Leaf::Float(*x),
            MsgValue::Str(s) => Leaf::Str(Arc::from(s.as_str())),
            _ => return None,
        })
    }
}

/// A primitive's value as the tree path would hold it, borrowing its string: read from a message,
/// or to be written.
#[derive(Debug, Clone, Copy)]
enum Scalar<'a> {
    Bool(bool),
    Int(i64),
    UInt(u64),
    Float(f64),
    Str(&'a str),
}

impl<'a> Scalar<'a> {
    fn of(v: &'a MsgValue) -> Option<Scalar<'a>> {
        Some(match v {
            MsgValue::Bool(b) => Scalar::Bool(*b),
            MsgValue::Int(i) => Scalar::Int(*i),
            MsgValue::UInt(u) => Scalar::UInt(*u),
            MsgValue::Float(x) => Scalar::Float(*x),
            MsgValue::Str(s) => Scalar::Str(s),
            _ => return None,
        })
    }

    /// The same value without a borrow (`None` for a string).
    fn owned<'b>(self) -> Option<Scalar<'b>> {
        Some(match self {
            Scalar::Bool(b) => Scalar::Bool(b),
            Scalar::Int(i) => Scalar::Int(i),
            Scalar::UInt(u) => Scalar::UInt(u),
            Scalar::Float(x) => Scalar::Float(x),
            Scalar::Str(_) => return None,
        })
    }
}

/// Which value a field of the output gets: the valid time (sec or nanosec), or an entry's value
/// (its first or second part: x and y of a vec2, sec and nanosec of a time).
#[derive(Debug, Clone, Copy, PartialEq)]
enum From {
    Stamp(u8),
    Entry(usize, u8),
    /// A literal entry's value.
    Literal(usize),
}

/// Which value each field (by its path of field indices) gets, where not its default.
type Assign = HashMap<Vec<usize>, From>;

#[derive(Debug, Clone)]
enum EOp {
    /// Fields at their defaults: the bytes for each start offset modulo 8.
    Default(Box<[Box<[u8]>; 8]>),
    Leaf(Primitive, From),
    /// The `each` array: its bound, and the layout of one element.
    Each(Option<usize>, Vec<EOp>),
}

/// A field whose bytes do not depend on the sample (at its default or set by a literal entry),
/// for precomputing a run of them.
#[derive(Debug, Clone)]
enum Item {
    /// Alignment and length.
    Fixed(usize, usize),
    /// An empty string: aligned 4, length 1, the NUL.
    Str,
    /// An empty sequence: aligned 4, count 0.
    Seq,
    /// A primitive set by a literal entry.
    Literal(Primitive, Leaf),
}

/// The padding before a field aligned to `align` (1, 2, 4 or 8: CDR aligns a primitive to its
/// size) at `pos`. A mask rather than `%`: `align` is not a constant here, and two divisions per
/// field were a tenth of the plans' time.
fn pad(pos: usize, align: usize) -> usize {
    debug_assert!(align.is_power_of_two());
    pos.wrapping_neg() & (align - 1)
}

/// The bytes of a run of items for each start offset modulo 8; `None` if a literal does not fit
/// its field (the tree path gives the error).
fn precompute(items: &[Item]) -> Option<Box<[Box<[u8]>; 8]>> {
    let mut runs: [Box<[u8]>; 8] = Default::default();
    for (start, run) in runs.iter_mut().enumerate() {
        let mut buf = vec![0u8; start];
        for item in items {
            let (align, bytes): (usize, &[u8]) = match item {
                Item::Fixed(align, len) => {
                    buf.resize(buf.len() + pad(buf.len(), *align) + len, 0);
                    continue;
                }
                Item::Literal(p, leaf) => {
                    write_leaf(&mut buf, 0, *p, leaf.scalar()).ok()?;
                    continue;
                }
                Item::Str => (4, &[1, 0, 0, 0, 0]),
                Item::Seq => (4, &[0, 0, 0, 0]),
            };
            buf.resize(buf.len() + pad(buf.len(), align), 0);
            buf.extend_from_slice(bytes);
        }
        *run = buf.split_off(start).into_boxed_slice();
    }
    Some(Box::new(runs))
}

/// Whether the struct at `index` is `builtin_interfaces/Time` (or `Duration`) as the plans read
/// and write it: `int32 sec`, `uint32 nanosec`.
fn is_time_struct(schema: &Schema, index: usize) -> bool {
    let def = schema.get(index);
    def.fields.len() == 2
        && def.fields[0].array == ArrayKind::Single
        && def.fields[1].array == ArrayKind::Single
        && def.fields[0].base == SchemaBase::Primitive(Primitive::Int32)
        && def.fields[1].base == SchemaBase::Primitive(Primitive::UInt32)
}

/// The struct that a path's last index points into, and the struct the path ends on.
fn end_struct(schema: &Schema, start: usize, indices: &[usize]) -> Option<usize> {
    let mut s = start;
    for &i in indices {
        match schema.get(s).fields.get(i)?.base {
            SchemaBase::Struct(next) => s = next,
            SchemaBase::Primitive(_) => return None,
        }
    }
    Some(s)
}

/// The leaves (paths to primitives, from `start`) a path writes or reads, with their part
/// (0 or 1); `None` for a path the plans do not cover.
fn leaves(schema: &Schema, start: usize, path: &Path) -> Option<Vec<(Vec<usize>, u8)>> {
    let with = |extra: usize| {
        let mut p = path.indices.clone();
        p.push(extra);
        p
    };
    match path.end {
        End::Primitive(Primitive::WString(_)) => None,
        End::Primitive(_) => Some(vec![(path.indices.clone(), 0)]),
        End::Xy(x, y, _) => Some(vec![(with(x), 0), (with(y), 1)]),
        End::Time | End::Duration => {
            let s = end_struct(schema, start, &path.indices)?;
            is_time_struct(schema, s).then(|| vec![(with(0), 0), (with(1), 1)])
        }
        End::Struct(_) | End::Array(_) => None,
    }
}

/// The primitive at a leaf.
fn leaf_primitive(schema: &Schema, start: usize, leaf: &[usize]) -> Option<Primitive> {
    let (last, parents) = leaf.split_last()?;
    let s = end_struct(schema, start, parents)?;
    match schema.get(s).fields.get(*last)?.base {
        SchemaBase::Primitive(p) => Some(p),
        SchemaBase::Struct(_) => None,
    }
}

/// Compiles the layout of struct `index` (at `prefix`) into `ops`; `None` where the plan does
/// not cover the schema or the mapping.
struct LayoutBuilder<'a> {
    schema: &'a Schema,
    /// Per entry, its value when it is a literal: precomputed with the defaults around it.
    literals: &'a [Option<Leaf>],
    /// The `each` array's path from the root, with the element's assignments.
    each: Option<(&'a [usize], &'a Assign)>,
}

impl LayoutBuilder<'_> {
    fn flush(pending: &mut Vec<Item>, ops: &mut Vec<EOp>) -> Option<()> {
        if !pending.is_empty() {
            ops.push(EOp::Default(precompute(pending)?));
            pending.clear();
        }
        Some(())
    }

    fn walk(
        &self,
        index: usize,
        prefix: &mut Vec<usize>,
        assign: &Assign,
        at_root: bool,
        ops: &mut Vec<EOp>,
        pending: &mut Vec<Item>,
    ) -> Option<()> {
        let def = self.schema.get(index);
        if def.fields.is_empty() {
            pending.push(Item::Fixed(1, 1));
            return Some(());
        }
        for (fi, field) in def.fields.iter().enumerate() {
            prefix.push(fi);
            match field.array {
                ArrayKind::Single => match field.base {
                    SchemaBase::Primitive(Primitive::WString(_)) => return None,
                    SchemaBase::Primitive(p) => match assign.get(prefix.as_slice()) {
                        Some(From::Literal(k)) => {
                            pending.push(Item::Literal(p, self.literals.get(*k)?.clone()?));
                        }
                        Some(from) => {
                            Self::flush(pending, ops)?;
                            ops.push(EOp::Leaf(p, *from));
                        }
                        None => pending.push(match p.size() {
                            Some(size) => Item::Fixed(size, size),
                            None => Item::Str,
                        }),
                    },
                    SchemaBase::Struct(s) => self.walk(s, prefix, assign, at_root, ops, pending)?,
                },
                array => {
                    if let Some((each, element_assign)) = self.each
                        && at_root
                        && each == prefix.as_slice()
                    {
                        let bound = match array {
                            ArrayKind::Unbounded => None,
                            ArrayKind::Bounded(n) => Some(n as usize),
                            _ => return None,
                        };
                        let SchemaBase::Struct(element) = field.base else { return None };
                        let mut body = Vec::new();
                        let mut body_pending = Vec::new();
                        self.walk(
                            element,
                            &mut Vec::new(),
                            element_assign,
                            false,
                            &mut body,
                            &mut body_pending,
                        )?;
                        Self::flush(&mut body_pending, &mut body)?;
                        Self::flush(pending, ops)?;
                        ops.push(EOp::Each(bound, body));
                    } else if assign.keys().any(|k| k.starts_with(prefix)) {
                        return None;
                    } else {
                        self.default_array(field.base, array, pending)?;
                    }
                }
            }
            prefix.pop();
        }
        Some(())
    }

    fn default_array(&self, base: SchemaBase, array: ArrayKind, pending: &mut Vec<Item>) -> Option<()> {
        let ArrayKind::Fixed(n) = array else {
            pending.push(Item::Seq);
            return Some(());
        };
        match base {
            SchemaBase::Primitive(Primitive::WString(_)) => return None,
            SchemaBase::Primitive(p) => match p.size() {
                Some(size) => pending.push(Item::Fixed(size, size * n as usize)),
                None => pending.extend((0..n).map(|_| Item::Str)),
            },
            SchemaBase::Struct(s) => {
                let none = HashMap::new();
                let mut ops = Vec::new();
                for _ in 0..n {
                    self.walk(s, &mut Vec::new(), &none, false, &mut ops, pending)?;
                }
                if !ops.is_empty() {
                    return None;
                }
            }
        }
        Some(())
    }
}

/// An [`OutMap`](crate::mapping::OutMap)'s layout, compiled: see the module's doc.
#[derive(Debug, Clone)]
pub(crate) struct EncodePlan {
    ops: Vec<EOp>,
    /// The entries that are not literals: evaluated per sample.
    dynamic: Vec<usize>,
    /// Per entry, whether its parts go into float fields (a vec2's x and y).
    float_parts: Vec<[bool; 2]>,
    has_each: bool,
}

impl EncodePlan {
    /// The plan of a mapping: `each` the array's path and element struct, `entries` the
    /// mapping's entries, `root_stamp` / `element_stamp` the header stamps that get the valid time.
    pub(crate) fn compile(
        schema: &Schema,
        each: Option<&(Vec<usize>, usize)>,
        entries: &[(Path, Source)],
        root_stamp: Option<&Vec<usize>>,
        element_stamp: Option<&Vec<usize>>,
    ) -> Option<EncodePlan> {
        let root = schema.root_index();
        let element = each.map_or(root, |(_, s)| *s);
        let stamp_leaves = |start: usize, path: &Vec<usize>| -> Option<Vec<(Vec<usize>, From)>> {
            let s = end_struct(schema, start, path)?;
            if !is_time_struct(schema, s) {
                return None;
            }
            Some((0..2u8).map(|c| ([path.as_slice(), &[usize::from(c)]].concat(), From::Stamp(c))).collect())
        };
        let mut root_assign = HashMap::new();
        if let Some(stamp) = root_stamp {
            root_assign.extend(stamp_leaves(root, stamp)?);
        }
        let mut element_assign = HashMap::new();
        if let Some(stamp) = element_stamp
            && each.is_some()
        {
            element_assign.extend(stamp_leaves(element, stamp)?);
        }
        let mut literals = Vec::with_capacity(entries.len());
        let mut dynamic = Vec::new();
        let mut float_parts = Vec::with_capacity(entries.len());
        for (k, (path, source)) in entries.iter().enumerate() {
            let literal = match source {
                Source::Literal(lit) => Some(Leaf::of(lit)?),
                _ => None,
            };
            let parts = leaves(schema, element, path)?;
            let mut floats = [false; 2];
            for (leaf, part) in parts {
                let p = leaf_primitive(schema, element, &leaf)?;
                floats[usize::from(part)] = matches!(p, Primitive::Float32 | Primitive::Float64);
                let target = if each.is_some() { &mut element_assign } else { &mut root_assign };
                let from = if literal.is_some() { From::Literal(k) } else { From::Entry(k, part) };
                target.insert(leaf, from);
            }
            float_parts.push(floats);
            if literal.is_none() {
                dynamic.push(k);
            }
            literals.push(literal);
        }
        let builder = LayoutBuilder {
            schema,
            literals: &literals,
            each: each.map(|(p, _)| (p.as_slice(), &element_assign)),
        };
        let mut ops = Vec::new();
        let mut pending = Vec::new();
        builder.walk(root, &mut Vec::new(), &root_assign, true, &mut ops, &mut pending)?;
        LayoutBuilder::flush(&mut pending, &mut ops)?;
        let has_each = ops.iter().any(|op| matches!(op, EOp::Each(..)));
        Some(EncodePlan { ops, dynamic, float_parts, has_each })
    }

    /// Writes the message of `value` at `valid` into `out` (cleared first, with the CDR header);
    /// `Err(())` where the tree path has an error (it runs again for the message).
    pub(crate) fn encode(
        &self,
        entries: &[(Path, Source)],
        numbers: &mut FxHashMap<Arc<str>, i64>,
        valid: Time,
        value: &Value,
        out: &mut Vec<u8>,
    ) -> Result<(), ()> {
        out.clear();
        out.extend_from_slice(&[0, 1, 0, 0]);
        let stamp = match time_value(valid) {
            MsgValue::Struct(f) => match (&f[0], &f[1]) {
                (MsgValue::Int(sec), MsgValue::UInt(nanosec)) => [Scalar::Int(*sec), Scalar::UInt(*nanosec)],
                _ => return Err(()),
            },
            _ => return Err(()),
        };
        let single;
        let items: &[Value] = match value {
            _ if !self.has_each => &[],
            Value::List(items) => items,
            other => {
                single = [other.clone()];
                &single
            }
        };
        let mut parts: Vec<[Scalar<'_>; 2]> = vec![[Scalar::Bool(false); 2]; entries.len()];
        if !self.has_each {
            self.evaluate(entries, numbers, value, &mut parts)?;
        }
        let mut w = Writes { out, stamp };
        for op in &self.ops {
            match op {
                EOp::Each(bound, body) => {
                    if bound.is_some_and(|n| items.len() > n) {
                        return Err(());
                    }
                    w.out.extend_from_slice(&[0; 3][..pad(w.out.len() - 4, 4)]);
                    w.out.extend_from_slice(&(items.len() as u32).to_le_bytes());
                    for item in items {
                        self.evaluate(entries, numbers, item, &mut parts)?;
                        for op in body {
                            w.op(op, &parts)?;
                        }
                    }
                }
                op => w.op(op, &parts)?,
            }
        }
        Ok(())
    }

    /// The values of a sample's entries that are not literals, in the mapping's order (as
    /// `OutMap::fill` computes them).
    fn evaluate<'v>(
        &self,
        entries: &[(Path, Source)],
        numbers: &mut FxHashMap<Arc<str>, i64>,
        value: &'v Value,
        parts: &mut [[Scalar<'v>; 2]],
    ) -> Result<(), ()> {
        let record = value.as_record();
        let none = Scalar::Bool(false);
        for &k in &self.dynamic {
            let (path, source) = &entries[k];
            parts[k] = match source {
                Source::Literal(_) => return Err(()),
                Source::Symbol => [Scalar::Str(record.and_then(|r| r.id.as_deref()).unwrap_or("")), none],
                Source::Number => {
                    let n = number_of(record.and_then(|r| r.id.as_deref()).unwrap_or(""), numbers);
                    [Scalar::of(&number_value(n as f64, path.end)).and_then(Scalar::owned).ok_or(())?, none]
                }
                Source::Attribute(a) => match (record, &**a) {
                    (Some(r), "id") if r.id.is_some() => match (path.end, r.id.as_deref()) {
                        (End::Primitive(Primitive::String(_)), Some(id)) => [Scalar::Str(id), none],
                        _ => return Err(()),
                    },
                    (Some(r), a) => attribute(r.get(a).ok_or(())?, path.end, self.float_parts[k]).ok_or(())?,
                    (None, a) => {
                        let v = value.field(a).ok_or(())?;
                        let [x, y] = attribute(&v, path.end, self.float_parts[k]).ok_or(())?;
                        [x.owned().ok_or(())?, y.owned().ok_or(())?]
                    }
                },
            };
        }
        Ok(())
    }
}

/// As `mapping::to_msg`, then as `OutMap::fill` writes a vec2 into x and y.
fn attribute(v: &Value, end: End, floats: [bool; 2]) -> Option<[Scalar<'_>; 2]> {
    let none = Scalar::Bool(false);
    Some(match (end, v) {
        (End::Xy(..), Value::Vec2(xy)) => {
            let part = |i: usize| if floats[i] { Scalar::Float(xy[i]) } else { Scalar::Int(xy[i] as i64) };
            [part(0), part(1)]
        }
        (End::Time, Value::Int(t)) | (End::Duration, Value::Duration(t)) => {
            let MsgValue::Struct(f) = time_value(*t) else { return None };
            [Scalar::of(&f[0])?.owned()?, Scalar::of(&f[1])?.owned()?]
        }
        (End::Primitive(Primitive::Float32 | Primitive::Float64), v) => [Scalar::Float(v.as_f64()?), none],
        (
            End::Primitive(Primitive::Int8 | Primitive::Int16 | Primitive::Int32 | Primitive::Int64),
            Value::Int(i),
        ) => [Scalar::Int(*i), none],
        (End::Primitive(p), Value::Int(i)) if p.size().is_some() => {
            [Scalar::UInt(u64::try_from(*i).ok()?), none]
        }
        (End::Primitive(Primitive::Bool), Value::Bool(b)) => [Scalar::Bool(*b), none],
        (End::Primitive(Primitive::String(_)), Value::Str(s)) => [Scalar::Str(s), none],
        _ => return None,
    })
}

struct Writes<'a> {
    out: &'a mut Vec<u8>,
    stamp: [Scalar<'static>; 2],
}

impl Writes<'_> {
    fn op(&mut self, op: &EOp, parts: &[[Scalar<'_>; 2]]) -> Result<(), ()> {
        match op {
            EOp::Default(bytes) => {
                self.out.extend_from_slice(&bytes[(self.out.len() - 4) % 8]);
                Ok(())
            }
            EOp::Leaf(p, from) => {
                let leaf = match *from {
                    From::Stamp(c) => self.stamp[usize::from(c)],
                    From::Entry(k, c) => parts[k][usize::from(c)],
                    // Literals are in the precomputed runs (`LayoutBuilder::walk`).
                    From::Literal(_) => return Err(()),
                };
                write_leaf(self.out, 4, *p, leaf)
            }
            EOp::Each(..) => Err(()),
        }
    }
}

/// As the codec's `write_primitive`: the same variants fit, the same ranges. `base` is where the
/// CDR body starts in `out` (alignment counts from there).
fn write_leaf(out: &mut Vec<u8>, base: usize, p: Primitive, leaf: Scalar<'_>) -> Result<(), ()> {
    use Primitive::*;
    let align = |out: &mut Vec<u8>, n: usize| {
        let pad = pad(out.len() - base, n);
        out.resize(out.len() + pad, 0);
    };
    if let String(bound) = p {
        let Scalar::Str(s) = leaf else { return Err(()) };
        if bound.is_some_and(|n| s.len() > n as usize) || s.contains('\0') {
            return Err(());
        }
        align(out, 4);
        out.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
        out.extend_from_slice(s.as_bytes());
        out.push(0);
        return Ok(());
    }
    let size = p.size().ok_or(())?;
    align(out, size);
    match (p, leaf) {
        (Bool, Scalar::Bool(b)) => out.push(u8::from(b)),
        (Float32, Scalar::Float(x)) => out.extend_from_slice(&(x as f32).to_le_bytes()),
        (Float64, Scalar::Float(x)) => out.extend_from_slice(&x.to_le_bytes()),
        (Int8 | Int16 | Int32 | Int64, Scalar::Int(i)) => {
            let bits = size as u32 * 8;
            if bits < 64 && (i < -(1i64 << (bits - 1)) || i >= 1i64 << (bits - 1)) {
                return Err(());
            }
            out.extend_from_slice(&i.to_le_bytes()[..size]);
        }
        (Byte | Char | UInt8 | UInt16 | UInt32 | UInt64, Scalar::UInt(u)) => {
            let bits = size as u32 * 8;
            if bits < 64 && u >= 1u64 << bits {
                return Err(());
            }
            out.extend_from_slice(&u.to_le_bytes()[..size]);
        }
        _ => return Err(()),
    }
    Ok(())
}

// ---------------------------------------------------------------------------------------------
// Decoding.

#[derive(Debug, Clone)]
enum DOp {
    /// Fixed-size fields without bools: how far they reach, per start offset modulo 8.
    Skip([u32; 8]),
    Bool,
    Str(Option<u32>),
    /// A `wstring`, which the codec refuses.
    Refuse,
    /// An array or sequence the mapping does not read: its kind and one element.
    Array(ArrayKind, Elem),
    /// A primitive the mapping reads, into this slot.
    Read(Primitive, usize),
    /// The `each` array: its kind and the layout of one element.
    Each(ArrayKind, Vec<DOp>),
}

#[derive(Debug, Clone)]
enum Elem {
    Octet,
    Fixed(usize),
    Ops(Vec<DOp>),
}

impl Scalar<'_> {
    fn as_f64(self) -> Option<f64> {
        match self {
            Scalar::Float(x) => Some(x),
            Scalar::Int(i) => Some(i as f64),
            Scalar::UInt(u) => Some(u as f64),
            _ => None,
        }
    }
}

/// How an attribute is read from slots.
#[derive(Debug, Clone, Copy)]
enum Read {
    One(usize),
    Two(usize, usize),
}

struct DecodeBuilder<'a> {
    schema: &'a Schema,
}

impl DecodeBuilder<'_> {
    fn flush(run: &mut Vec<(usize, usize)>, ops: &mut Vec<DOp>) {
        if run.is_empty() {
            return;
        }
        let mut reach = [0u32; 8];
        for (start, r) in reach.iter_mut().enumerate() {
            let mut pos = start;
            for &(align, len) in run.iter() {
                pos += pad(pos, align) + len;
            }
            *r = (pos - start) as u32;
        }
        ops.push(DOp::Skip(reach));
        run.clear();
    }

    /// The layout of struct `index` at `prefix`: `slots` are the leaves read; `each` the array
    /// (from the root) whose elements have the layout `element`.
    fn walk(
        &self,
        index: usize,
        prefix: &mut Vec<usize>,
        slots: &HashMap<Vec<usize>, usize>,
        each: Option<(&[usize], &[DOp])>,
        ops: &mut Vec<DOp>,
        run: &mut Vec<(usize, usize)>,
    ) -> Option<()> {
        let def = self.schema.get(index);
        if def.fields.is_empty() {
            run.push((1, 1));
            return Some(());
        }
        for (fi, field) in def.fields.iter().enumerate() {
            prefix.push(fi);
            match (field.array, field.base) {
                (ArrayKind::Single, SchemaBase::Struct(s)) => self.walk(s, prefix, slots, each, ops, run)?,
                (ArrayKind::Single, SchemaBase::Primitive(p)) => {
                    if let Some(&slot) = slots.get(prefix.as_slice()) {
                        Self::flush(run, ops);
                        ops.push(DOp::Read(p, slot));
                    } else {
                        self.skip_primitive(p, ops, run);
                    }
                }
                (array, base) => {
                    if let Some((path, element)) = each
                        && path == prefix.as_slice()
                    {
                        Self::flush(run, ops);
                        ops.push(DOp::Each(array, element.to_vec()));
                    } else if let (ArrayKind::Fixed(n), SchemaBase::Primitive(p)) = (array, base)
                        && let Some(size) = p.size()
                        && p != Primitive::Bool
                    {
                        run.push((size, size * n as usize));
                    } else {
                        let elem = match base {
                            SchemaBase::Primitive(p) if p.is_octet() => Elem::Octet,
                            SchemaBase::Primitive(p) if p != Primitive::Bool && p.size().is_some() => {
                                Elem::Fixed(p.size().unwrap_or(1))
                            }
                            base => {
                                let mut body = Vec::new();
                                let mut body_run = Vec::new();
                                match base {
                                    SchemaBase::Primitive(p) => {
                                        self.skip_primitive(p, &mut body, &mut body_run)
                                    }
                                    SchemaBase::Struct(s) => self.walk(
                                        s,
                                        &mut Vec::new(),
                                        &HashMap::new(),
                                        None,
                                        &mut body,
                                        &mut body_run,
                                    )?,
                                }
                                Self::flush(&mut body_run, &mut body);
                                Elem::Ops(body)
                            }
                        };
                        Self::flush(run, ops);
                        ops.push(DOp::Array(array, elem));
                    }
                }
            }
            prefix.pop();
        }
        Some(())
    }

    fn skip_primitive(&self, p: Primitive, ops: &mut Vec<DOp>, run: &mut Vec<(usize, usize)>) {
        match p {
            Primitive::Bool => {
                Self::flush(run, ops);
                ops.push(DOp::Bool);
            }
            Primitive::String(bound) => {
                Self::flush(run, ops);
                ops.push(DOp::Str(bound));
            }
            Primitive::WString(_) => {
                Self::flush(run, ops);
                ops.push(DOp::Refuse);
            }
            p => {
                let size = p.size().unwrap_or(1);
                run.push((size, size));
            }
        }
    }
}

/// Slots for the leaves a level reads: the leaf's path to its slot.
#[derive(Default)]
struct Slots {
    index: HashMap<Vec<usize>, usize>,
}

impl Slots {
    fn of(&mut self, leaf: Vec<usize>) -> usize {
        let n = self.index.len();
        *self.index.entry(leaf).or_insert(n)
    }
}

/// An [`InMap`](crate::mapping::InMap)'s reading, compiled: see the module's doc.
#[derive(Debug, Clone)]
pub(crate) struct DecodePlan {
    ops: Vec<DOp>,
    root_slots: usize,
    element_slots: usize,
    attributes: Vec<(Arc<str>, End, ValueType, Read)>,
    identity: Option<usize>,
    /// The symbols made of integer identities, kept from message to message (a tracker sends the
    /// same ids again and again).
    symbols: Symbols,
    /// The stamp's slots (sec, nanosec), and whether they are in the root.
    stamp: Option<(bool, usize, usize)>,
    ty: Arc<RecordType>,
}

impl DecodePlan {
    pub(crate) fn compile(
        schema: &Schema,
        each: Option<&Vec<usize>>,
        ty: &Arc<RecordType>,
        attributes: &[(Arc<str>, Path, ValueType)],
        identity: Option<&Path>,
        stamp: Option<&(bool, Path)>,
    ) -> Option<DecodePlan> {
        let root = schema.root_index();
        let element = match each {
            Some(path) => {
                let (last, parents) = path.split_last()?;
                match schema.get(end_struct(schema, root, parents)?).fields.get(*last)?.base {
                    SchemaBase::Struct(s) => s,
                    SchemaBase::Primitive(_) => return None,
                }
            }
            None => root,
        };
        let mut root_slots = Slots::default();
        let mut element_slots = Slots::default();
        let mut reads = Vec::with_capacity(attributes.len());
        for (name, path, vty) in attributes {
            let parts = leaves(schema, element, path)?;
            let target = if each.is_some() { &mut element_slots } else { &mut root_slots };
            let read = match parts.as_slice() {
                [(a, _)] => Read::One(target.of(a.clone())),
                [(a, _), (b, _)] => Read::Two(target.of(a.clone()), target.of(b.clone())),
                _ => return None,
            };
            reads.push((name.clone(), path.end, vty.clone(), read));
        }
        let identity = match identity {
            Some(path) => {
                let [(leaf, _)] = leaves(schema, element, path)?.try_into().ok()?;
                let target = if each.is_some() { &mut element_slots } else { &mut root_slots };
                Some(target.of(leaf))
            }
            None => None,
        };
        let stamp = match stamp {
            Some((at_root, path)) => {
                let start = if *at_root { root } else { element };
                let [(sec, _), (nanosec, _)] = leaves(schema, start, path)?.try_into().ok()?;
                let target = if *at_root || each.is_none() { &mut root_slots } else { &mut element_slots };
                Some((*at_root || each.is_none(), target.of(sec), target.of(nanosec)))
            }
            None => None,
        };
        let builder = DecodeBuilder { schema };
        let mut element_ops = Vec::new();
        if each.is_some() {
            let mut run = Vec::new();
            builder.walk(element, &mut Vec::new(), &element_slots.index, None, &mut element_ops, &mut run)?;
            DecodeBuilder::flush(&mut run, &mut element_ops);
        }
        let mut ops = Vec::new();
        let mut run = Vec::new();
        builder.walk(
            root,
            &mut Vec::new(),
            &root_slots.index,
            each.map(|p| (p.as_slice(), element_ops.as_slice())),
            &mut ops,
            &mut run,
        )?;
        DecodeBuilder::flush(&mut run, &mut ops);
        Some(DecodePlan {
            ops,
            root_slots: root_slots.index.len(),
            element_slots: element_slots.index.len(),
            attributes: reads,
            identity,
            symbols: Symbols::default(),
            stamp,
            ty: ty.clone(),
        })
    }

    /// The valid time and KPL value of a CDR message; `Err(())` where the tree path has an error
    /// (it runs again for the message).
    pub(crate) fn decode(&self, bytes: &[u8]) -> Result<(Option<Time>, Value), ()> {
        let little = match bytes {
            [0, 1, _, _, ..] => true,
            [0, 0, _, _, ..] => false,
            _ => return Err(()),
        };
        let mut cur = Cursor { data: &bytes[4..], pos: 0, little };
        let mut root = vec![Scalar::Bool(false); self.root_slots];
        let mut element = vec![Scalar::Bool(false); self.element_slots];
        let mut records: Option<Vec<Value>> = None;
        let mut id = String::new();
        let mut symbols = self.symbols.0.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        let mut first_stamp = None;
        for op in &self.ops {
            if let DOp::Each(kind, body) = op {
                let count = cur.count(*kind)?;
                let mut list = Vec::with_capacity(count);
                for i in 0..count {
                    for op in body {
                        cur.op(op, &mut element)?;
                    }
                    if i == 0
                        && let Some((false, sec, nanosec)) = self.stamp
                    {
                        first_stamp = time_of(element[sec], element[nanosec]);
                    }
                    list.push(self.record(&element, &mut id, &mut symbols)?);
                }
                records = Some(list);
            } else {
                cur.op(op, &mut root)?;
            }
        }
        let valid = match self.stamp {
            Some((true, sec, nanosec)) => time_of(root[sec], root[nanosec]),
            Some((false, ..)) => first_stamp,
            None => None,
        };
        let value = match records {
            Some(list) => Value::List(list.into()),
            None => self.record(&root, &mut id, &mut symbols)?,
        };
        Ok((valid, value))
    }

    /// How many symbols the plan keeps now.
    #[cfg(test)]
    pub(crate) fn symbols_held(&self) -> usize {
        self.symbols.0.lock().map_or(0, |symbols| symbols.len())
    }

    fn record(
        &self,
        slots: &[Scalar<'_>],
        id: &mut String,
        symbols: &mut FxHashMap<Identity, Arc<str>>,
    ) -> Result<Value, ()> {
        let mut fields = Vec::with_capacity(self.attributes.len());
        for (name, end, ty, read) in &self.attributes {
            let value = match (*read, end) {
                (Read::Two(a, b), End::Xy(..)) => Value::Vec2([
                    finite(slots[a].as_f64().ok_or(())?)?,
                    finite(slots[b].as_f64().ok_or(())?)?,
                ]),
                (Read::Two(a, b), End::Time) => Value::Int(time_of(slots[a], slots[b]).ok_or(())?),
                (Read::Two(a, b), End::Duration) => Value::Duration(time_of(slots[a], slots[b]).ok_or(())?),
                (Read::One(a), _) => match (ty, slots[a]) {
                    (ValueType::Float, v) => Value::Float(finite(v.as_f64().ok_or(())?)?),
                    (ValueType::Int | ValueType::Any, Scalar::Int(i)) => Value::Int(i),
                    (ValueType::Int | ValueType::Any, Scalar::UInt(u)) => {
                        Value::Int(i64::try_from(u).map_err(|_| ())?)
                    }
                    (ValueType::Any, Scalar::Float(x)) => Value::Float(finite(x)?),
                    (_, Scalar::Bool(b)) => Value::Bool(b),
                    (_, Scalar::Str(s)) => Value::str(s),
                    _ => return Err(()),
                },
                _ => return Err(()),
            };
            fields.push((name.clone(), value));
        }
        let id = match self.identity {
            Some(slot) => {
                let key = match slots[slot] {
                    Scalar::Int(i) => Some(Identity::Int(i)),
                    Scalar::UInt(u) => Some(Identity::UInt(u)),
                    Scalar::Str(_) => None,
                    _ => return Err(()),
                };
                if let Some(symbol) = key.and_then(|key| symbols.get(&key)) {
                    Some(symbol.clone())
                } else {
                    id.clear();
                    id.push_str(&self.ty.symbol);
                    match slots[slot] {
                        Scalar::Int(i) => write!(id, "{i}").map_err(|_| ())?,
                        Scalar::UInt(u) => write!(id, "{u}").map_err(|_| ())?,
                        Scalar::Str(s) => id.push_str(s),
                        _ => return Err(()),
                    }
                    let symbol: Arc<str> = Arc::from(id.as_str());
                    if let Some(key) = key {
                        if symbols.len() >= Symbols::MAX {
                            symbols.clear();
                        }
                        symbols.insert(key, symbol.clone());
                    }
                    Some(symbol)
                }
            }
            None => None,
        };
        Ok(Value::Record(Arc::new(Record { id, fields })))
    }
}

/// An integer identity read from a message.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Identity {
    Int(i64),
    UInt(u64),
}

/// A decode plan's symbols of integer identities. Bounded: emptied when it holds
/// [`Symbols::MAX`], so ids that only ever grow (a long run, or a sender that makes them up)
/// cost one symbol each time, never memory without bound.
#[derive(Debug, Default)]
pub(crate) struct Symbols(Mutex<FxHashMap<Identity, Arc<str>>>);

impl Symbols {
    pub(crate) const MAX: usize = 4096;
}

impl Clone for Symbols {
    /// A clone starts empty: the cache is an optimization, not state.
    fn clone(&self) -> Symbols {
        Symbols::default()
    }
}

fn finite(x: f64) -> Result<f64, ()> {
    if x.is_finite() { Ok(x) } else { Err(()) }
}

/// As `mapping::time_of`.
fn time_of(sec: Scalar<'_>, nanosec: Scalar<'_>) -> Option<Time> {
    let (Scalar::Int(sec), Scalar::UInt(nanosec)) = (sec, nanosec) else { return None };
    sec.checked_mul(1_000_000)?.checked_add(nanosec as i64 / 1000)
}

struct Cursor<'a> {
    data: &'a [u8],
    pos: usize,
    little: bool,
}

impl<'a> Cursor<'a> {
    fn align(&mut self, n: usize) -> Result<(), ()> {
        let at = self.pos + pad(self.pos, n);
        if at > self.data.len() {
            return Err(());
        }
        self.pos = at;
        Ok(())
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], ()> {
        if n > self.data.len() - self.pos {
            return Err(());
        }
        let bytes = &self.data[self.pos..self.pos + n];
        self.pos += n;
        Ok(bytes)
    }

    fn fixed<const N: usize>(&mut self) -> Result<[u8; N], ()> {
        self.align(N)?;
        let mut out = [0u8; N];
        out.copy_from_slice(self.take(N)?);
        if !self.little {
            out.reverse();
        }
        Ok(out)
    }

    fn u32(&mut self) -> Result<usize, ()> {
        Ok(u32::from_le_bytes(self.fixed::<4>()?) as usize)
    }

    /// An array's element count (read for a sequence), checked as the codec checks it.
    fn count(&mut self, kind: ArrayKind) -> Result<usize, ()> {
        let count = match kind {
            ArrayKind::Single => return Err(()),
            ArrayKind::Fixed(n) => n as usize,
            ArrayKind::Bounded(n) => {
                let count = self.u32()?;
                if count > n as usize {
                    return Err(());
                }
                count
            }
            ArrayKind::Unbounded => self.u32()?,
        };
        if count > self.data.len() - self.pos {
            return Err(());
        }
        Ok(count)
    }

    fn string(&mut self, bound: Option<u32>) -> Result<&'a str, ()> {
        let len = self.u32()?;
        if len == 0 {
            return Err(());
        }
        if len == 1 {
            // The empty string: most of what a mapping skips.
            return if self.take(1)? == [0] { Ok("") } else { Err(()) };
        }
        let bytes = self.take(len)?;
        let (text, nul) = bytes.split_at(len - 1);
        if nul != [0] || text.contains(&0) || bound.is_some_and(|n| text.len() > n as usize) {
            return Err(());
        }
        std::str::from_utf8(text).map_err(|_| ())
    }

    /// The operations of a nested array's element (not inlined: [`Cursor::op`] is, into the
    /// loops over a message's and an `each` element's operations, which is where the time goes).
    #[inline(never)]
    fn ops(&mut self, body: &[DOp], slots: &mut [Scalar<'a>]) -> Result<(), ()> {
        for op in body {
            self.op(op, slots)?;
        }
        Ok(())
    }

    #[inline(always)]
    fn op(&mut self, op: &DOp, slots: &mut [Scalar<'a>]) -> Result<(), ()> {
        match op {
            DOp::Skip(reach) => {
                let at = self.pos + reach[self.pos % 8] as usize;
                if at > self.data.len() {
                    return Err(());
                }
                self.pos = at;
            }
            DOp::Bool => {
                if self.take(1)?[0] > 1 {
                    return Err(());
                }
            }
            DOp::Str(bound) => {
                self.string(*bound)?;
            }
            DOp::Refuse | DOp::Each(..) => return Err(()),
            DOp::Read(p, slot) => slots[*slot] = self.read(*p)?,
            DOp::Array(kind, elem) => {
                let count = self.count(*kind)?;
                match elem {
                    Elem::Octet => {
                        self.take(count)?;
                    }
                    Elem::Fixed(size) => {
                        if count > 0 {
                            self.align(*size)?;
                            self.take(count * size)?;
                        }
                    }
                    Elem::Ops(body) => {
                        for _ in 0..count {
                            self.ops(body, slots)?;
                        }
                    }
                }
            }
        }
        Ok(())
    }

    fn read(&mut self, p: Primitive) -> Result<Scalar<'a>, ()> {
        use Primitive::*;
        Ok(match p {
            Bool => match self.take(1)?[0] {
                0 => Scalar::Bool(false),
                1 => Scalar::Bool(true),
                _ => return Err(()),
            },
            Byte | Char | UInt8 => Scalar::UInt(u64::from(self.take(1)?[0])),
            Int8 => Scalar::Int(i64::from(self.take(1)?[0] as i8)),
            Int16 => Scalar::Int(i64::from(i16::from_le_bytes(self.fixed()?))),
            UInt16 => Scalar::UInt(u64::from(u16::from_le_bytes(self.fixed()?))),
            Int32 => Scalar::Int(i64::from(i32::from_le_bytes(self.fixed()?))),
            UInt32 => Scalar::UInt(u64::from(u32::from_le_bytes(self.fixed()?))),
            Int64 => Scalar::Int(i64::from_le_bytes(self.fixed()?)),
            UInt64 => Scalar::UInt(u64::from_le_bytes(self.fixed()?)),
            Float32 => Scalar::Float(f64::from(f32::from_le_bytes(self.fixed()?))),
            Float64 => Scalar::Float(f64::from_le_bytes(self.fixed()?)),
            String(bound) => Scalar::Str(self.string(bound)?),
            WString(_) => return Err(()),
        })
    }
}

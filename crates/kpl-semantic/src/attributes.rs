//! Attributes that nothing sets (W0204): an object type's attribute that none of the processes
//! producing its objects computes keeps its default forever (`Car.speed` stays 0 when the link
//! unit making cars only copies what an on-road object has), so a formula reading it is silently
//! wrong. What a link unit sets comes from its registry signature ([`Computes`]).
//!
//! Parameters that act on nothing (W0207): a link unit's parameter that acts on attributes of the
//! linked-to type ([`crate::registry::Param::acts_on`]: `anchor.kalman`'s `smooth` sets
//! `smoothed_pos` and `smoothed_vel`), given a value other than its default where the type
//! declares none of them.

use kpl_syntax::Diagnostic;
use kpl_syntax::ast::{self, Span};

use crate::diagnostics as diag;
use crate::hir;
use crate::registry::{Computes, EntryKind, Registry};

/// One process that produces objects of a type, and what it sets of them.
struct Producer<'a> {
    process: &'a hir::Process,
    entry_name: &'a str,
    computes: Computes,
    /// The attributes of the linked-from type (for units that copy shared attributes).
    from_attributes: Vec<&'a str>,
}

/// The warnings for every attribute of a declared object type that no producer of its objects
/// sets. Types with no producer at all are left to the other checks.
pub fn unset(spec: &ast::Spec, checked: &hir::Spec, registry: &Registry) -> Vec<Diagnostic> {
    let decls: Vec<&ast::TypeDecl> = spec
        .items
        .iter()
        .filter_map(|item| match item {
            ast::Item::Type(decl) => Some(decl),
            _ => None,
        })
        .collect();
    let mut out = Vec::new();
    for decl in &decls {
        let ty = decl.name.name.as_str();
        let Some(record) = checked.types.get(ty) else { continue };
        let producers = producers(checked, registry, ty);
        let Some(first) = producers.first() else { continue };
        for field in &record.fields {
            let attribute = &*field.name;
            if producers.iter().any(|p| p.computes.sets(attribute, &p.from_attributes)) {
                continue;
            }
            let Some(span) = declaration(&decls, ty, attribute) else { continue };
            let sets: Vec<String> = record
                .fields
                .iter()
                .map(|f| f.name.to_string())
                .filter(|a| first.computes.sets(a, &first.from_attributes))
                .collect();
            out.push(diag::unset_attribute(
                span,
                ty,
                attribute,
                (first.process.span, &first.process.name),
                first.entry_name,
                &sets,
            ));
        }
    }
    out
}

/// The warnings for every link unit parameter that acts on attributes its linked-to type does
/// not declare.
pub fn ineffective_params(spec: &ast::Spec, checked: &hir::Spec, registry: &Registry) -> Vec<Diagnostic> {
    let mut out = Vec::new();
    for item in &spec.items {
        let ast::Item::Link(decl) = item else { continue };
        let Some(process) = checked.processes.iter().find(|p| p.name == decl.name.name) else { continue };
        let hir::ProcessKind::Link(link) = &process.kind else { continue };
        let (Some(entry), Some(to)) =
            (registry.entry(EntryKind::Link, &link.via.entry), checked.types.get(&link.to_type))
        else {
            continue;
        };
        for (name, _) in decl.via.params() {
            let Some(param) = entry.params.iter().find(|p| p.name == name.name) else { continue };
            let given = link.via.params.get(&param.name);
            if param.acts_on.is_empty() || given.is_none() || given == param.default.as_ref() {
                continue;
            }
            if !to.fields.iter().any(|f| param.acts_on.iter().any(|a| *a == *f.name)) {
                out.push(diag::param_ineffective(
                    name.span,
                    &param.name,
                    &link.via.entry,
                    &link.to_type,
                    &param.acts_on,
                ));
            }
        }
    }
    out
}

/// The processes whose output carries objects of exactly type `ty`.
fn producers<'a>(checked: &'a hir::Spec, registry: &Registry, ty: &str) -> Vec<Producer<'a>> {
    let carries = |t: &kpl_core::ValueType| match t {
        kpl_core::ValueType::List(item) => {
            matches!(&**item, kpl_core::ValueType::Record(r) if &*r.name == ty)
        }
        kpl_core::ValueType::Record(r) => &*r.name == ty,
        _ => false,
    };
    let mut out = Vec::new();
    for process in &checked.processes {
        let (kind, call, from_type) = match &process.kind {
            hir::ProcessKind::Link(link) if link.to_type == ty => {
                (EntryKind::Link, &link.via, Some(&link.from_type))
            }
            hir::ProcessKind::Source(call) if process.output.as_ref().is_some_and(carries) => {
                (EntryKind::Source, call, None)
            }
            hir::ProcessKind::Compute(call) if process.output.as_ref().is_some_and(carries) => {
                (EntryKind::Compute, call, None)
            }
            _ => continue,
        };
        let computes = registry.entry(kind, &call.entry).map(|e| e.computes.clone()).unwrap_or_default();
        let from_attributes = from_type
            .and_then(|t| checked.types.get(t))
            .map(|r| r.fields.iter().map(|f| &*f.name).collect())
            .unwrap_or_default();
        out.push(Producer { process, entry_name: &call.entry, computes, from_attributes });
    }
    out
}

/// Where an attribute of `ty` is declared: on `ty` or the nearest parent that declares it.
fn declaration(decls: &[&ast::TypeDecl], ty: &str, attribute: &str) -> Option<Span> {
    let mut current = Some(ty.to_string());
    for _ in 0..=decls.len() {
        let decl = decls.iter().find(|d| Some(&d.name.name) == current.as_ref())?;
        if let Some(field) = decl.fields.iter().find(|f| f.name.name == attribute) {
            return Some(field.name.span);
        }
        current = decl.parent.as_ref().map(|p| p.name.clone());
    }
    None
}

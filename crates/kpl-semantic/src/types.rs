//! Object types: single inheritance without cycles, fields flattened with inherited ones first,
//! symbol prefixes, and resolution of type expressions (`float`, `list<Detection>`).

use std::collections::BTreeMap;
use std::sync::Arc;

use kpl_core::{FieldType, RecordType, ValueType};
use kpl_syntax::Diagnostic;
use kpl_syntax::ast::{self, Span};

use crate::diagnostics as diag;
use crate::hir::TypeTable;

/// The built-in value types, by the name a spec writes.
pub const BUILTIN_TYPES: [(&str, ValueType); 7] = [
    ("bool", ValueType::Bool),
    ("int", ValueType::Int),
    ("float", ValueType::Float),
    ("string", ValueType::Str),
    ("vec2", ValueType::Vec2),
    ("box", ValueType::BBox),
    ("duration", ValueType::Duration),
];

pub fn builtin(name: &str) -> Option<ValueType> {
    BUILTIN_TYPES.iter().find(|(n, _)| *n == name).map(|(_, t)| t.clone())
}

/// The default symbol prefix: the lower-cased initials of the name's words
/// (`VisionPercept` -> `vp`, `Car` -> `c`).
pub fn default_symbol(name: &str) -> String {
    let chars: Vec<char> = name.chars().collect();
    let mut out = String::new();
    for (i, c) in chars.iter().enumerate() {
        let previous_upper = i > 0 && chars[i - 1].is_uppercase();
        let next_lower = chars.get(i + 1).is_some_and(|n| n.is_lowercase());
        if i == 0 || (c.is_uppercase() && (!previous_upper || next_lower)) {
            out.extend(c.to_lowercase());
        }
    }
    out
}

/// Builds the type table from the `type` declarations, reporting unknown parents and field
/// types, cycles, duplicates and clashing symbol prefixes.
pub(crate) fn collect(decls: &[&ast::TypeDecl], diagnostics: &mut Vec<Diagnostic>) -> TypeTable {
    let mut by_name: BTreeMap<&str, &ast::TypeDecl> = BTreeMap::new();
    let mut order: Vec<&ast::TypeDecl> = Vec::new();
    for decl in decls {
        if builtin(&decl.name.name).is_some() || decl.name.name == "list" {
            diagnostics.push(diag::builtin_type(decl.name.span, &decl.name.name));
            continue;
        }
        if let Some(first) = by_name.get(decl.name.name.as_str()) {
            diagnostics.push(diag::duplicate(decl.name.span, "type", &decl.name.name, first.name.span));
            continue;
        }
        by_name.insert(&decl.name.name, decl);
        order.push(decl);
    }
    let names: Vec<&str> = order.iter().map(|d| d.name.name.as_str()).collect();

    // Resolve in dependency order (parent and record-typed fields first); what is on the stack
    // when reached again is a cycle.
    let mut built: BTreeMap<String, Arc<RecordType>> = BTreeMap::new();
    let mut failed: Vec<String> = Vec::new();
    for decl in &order {
        let mut stack = Vec::new();
        build(decl, &by_name, &names, &mut built, &mut failed, &mut stack, diagnostics);
    }

    let mut table = TypeTable::default();
    let mut symbols: BTreeMap<String, (&str, Span)> = BTreeMap::new();
    for decl in &order {
        let Some(ty) = built.get(&decl.name.name) else { continue };
        let span = decl.symbol.as_ref().map_or(decl.name.span, |s| s.span);
        if let Some((other, first)) = symbols.get(&*ty.symbol) {
            diagnostics.push(diag::duplicate_symbol(span, &ty.symbol, &decl.name.name, other, *first));
        } else {
            symbols.insert(ty.symbol.to_string(), (&decl.name.name, span));
        }
        table.insert(ty.clone());
    }
    table
}

fn build(
    decl: &ast::TypeDecl,
    by_name: &BTreeMap<&str, &ast::TypeDecl>,
    names: &[&str],
    built: &mut BTreeMap<String, Arc<RecordType>>,
    failed: &mut Vec<String>,
    stack: &mut Vec<String>,
    diagnostics: &mut Vec<Diagnostic>,
) -> Option<Arc<RecordType>> {
    let name = decl.name.name.as_str();
    if let Some(ty) = built.get(name) {
        return Some(ty.clone());
    }
    if failed.iter().any(|f| f == name) {
        return None;
    }
    if let Some(pos) = stack.iter().position(|s| s == name) {
        let mut cycle: Vec<String> = stack[pos..].to_vec();
        cycle.push(name.to_string());
        // Report once, at the declaration where the cycle closes.
        diagnostics.push(diag::type_cycle(decl.name.span, &cycle));
        for member in &stack[pos..] {
            failed.push(member.clone());
        }
        return None;
    }
    stack.push(name.to_string());
    let mut fields: Vec<FieldType> = Vec::new();
    let mut ok = true;
    if let Some(parent) = &decl.parent {
        match by_name.get(parent.name.as_str()) {
            Some(parent_decl) => {
                match build(parent_decl, by_name, names, built, failed, stack, diagnostics) {
                    Some(parent_ty) => fields.extend(parent_ty.fields.iter().cloned()),
                    None => ok = false,
                }
            }
            None => {
                diagnostics.push(diag::unknown_type(parent.span, &parent.name, names));
                ok = false;
            }
        }
    }
    let inherited = fields.len();
    let mut own_spans: Vec<(&str, Span)> = Vec::new();
    for field in &decl.fields {
        if let Some((_, first)) = own_spans.iter().find(|(n, _)| *n == field.name.name) {
            diagnostics.push(diag::duplicate(field.name.span, "attribute", &field.name.name, *first));
            continue;
        }
        if fields[..inherited].iter().any(|f| *f.name == field.name.name) {
            diagnostics.push(diag::inherited_attribute(field.name.span, &field.name.name));
            continue;
        }
        if let Some(meaning) = reserved_meaning(&field.name.name) {
            diagnostics.push(diag::reserved_attribute(field.name.span, &field.name.name, meaning));
            continue;
        }
        own_spans.push((&field.name.name, field.name.span));
        match resolve_type_expr(&field.ty, &mut |n| {
            by_name.get(n).and_then(|d| build(d, by_name, names, built, failed, stack, diagnostics))
        }) {
            Ok(ty) => fields.push(FieldType { name: field.name.name.as_str().into(), ty }),
            Err(TypeError::Unknown(id)) => {
                if by_name.contains_key(id.name.as_str()) {
                    ok = false; // part of a reported cycle
                } else {
                    diagnostics.push(diag::unknown_type(id.span, &id.name, names));
                }
            }
        }
    }
    stack.pop();
    if !ok {
        failed.push(name.to_string());
        return None;
    }
    let symbol = decl.symbol.as_ref().map_or_else(|| default_symbol(name), |s| s.name.clone());
    let ty = Arc::new(RecordType {
        name: name.into(),
        parent: decl.parent.as_ref().map(|p| p.name.as_str().into()),
        symbol: symbol.into(),
        fields,
    });
    built.insert(name.to_string(), ty.clone());
    Some(ty)
}

pub(crate) enum TypeError<'a> {
    Unknown(&'a ast::Ident),
}

/// Resolves a type expression, looking record types up with `record`.
/// What an attribute every object has means (`id` is the symbol; the others are
/// `kpl_core::OBJECT_STATUS`), or `None` for a name a type may declare.
pub(crate) fn reserved_meaning(name: &str) -> Option<&'static str> {
    match name {
        "measured" => Some("whether the object's state was measured at this state"),
        "predicted_since" => Some("since when the object's state has not been measured"),
        "likelihood" => Some("how likely a predicted branch is"),
        "branch_of" => Some("the object a predicted branch object branches from"),
        _ => None,
    }
}

pub(crate) fn resolve_type_expr<'a>(
    ty: &'a ast::TypeExpr,
    record: &mut dyn FnMut(&str) -> Option<Arc<RecordType>>,
) -> Result<ValueType, TypeError<'a>> {
    match ty {
        ast::TypeExpr::List(item, _) => Ok(ValueType::List(Box::new(resolve_type_expr(item, record)?))),
        ast::TypeExpr::Named(id) => {
            if let Some(t) = builtin(&id.name) {
                return Ok(t);
            }
            if id.name == "any" {
                return Ok(ValueType::Any);
            }
            record(&id.name).map(ValueType::Record).ok_or(TypeError::Unknown(id))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_symbols_are_initials() {
        assert_eq!(default_symbol("VisionPercept"), "vp");
        assert_eq!(default_symbol("WorldObject"), "wo");
        assert_eq!(default_symbol("Car"), "c");
        assert_eq!(default_symbol("UAVState"), "us");
    }
}

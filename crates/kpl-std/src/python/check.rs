//! What `kpl check` can tell about a Python unit without running Python: that its module is a
//! file beside the spec (or in the active virtual environment), that the file defines the
//! function or class at its top level, and that the function takes the parameters the spec
//! gives it and as many inputs. The worker checks the same again, exactly, when it loads the
//! unit (`inspect.signature`).

use std::path::{Path, PathBuf};

use kpl_semantic::registry::{CallTypes, ParamProblem};

/// The `python.unit` entry's parameter check (E0118).
pub(super) fn check(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let text = |name: &str| call.params.get(name).and_then(|v| v.as_str()).unwrap_or_default().to_string();
    let (module, function) = (text("module"), text("function"));
    let mut problems = Vec::new();
    if !is_module_name(&module) {
        problems.push(problem(
            "module",
            format!("`{module}` is not a Python module name"),
            "dotted identifiers, such as `vehicle_kind` or `detectors.boxes`",
        ));
        return problems;
    }
    if !is_identifier(&function) {
        problems.push(problem(
            "function",
            format!("`{function}` is not a Python name"),
            "the name of a function or class defined in the module",
        ));
        return problems;
    }
    let Some(dir) = call.dir else { return problems };
    let Some(file) = find_module(dir, &module) else {
        problems.push(problem(
            "module",
            format!(
                "no module `{module}` beside the spec ({}) nor in the active virtual environment",
                dir.display()
            ),
            &format!(
                "kpl looks for {}.py or {}/__init__.py beside the spec",
                module.replace('.', "/"),
                module.replace('.', "/")
            ),
        ));
        return problems;
    };
    let Ok(source) = kpl_core::read::read_file(&file, 4 << 20) else { return problems };
    let source = String::from_utf8_lossy(&source);
    let defined = top_level_definitions(&source);
    let Some(definition) = defined.iter().find(|d| d.name == function) else {
        // Defined some other way (imported, assigned): only the worker can tell.
        if mentions(&source, &function) {
            return problems;
        }
        let names: Vec<&str> = defined.iter().map(|d| d.name.as_str()).collect();
        let hint = match kpl_core::closest(&function, &names) {
            Some(near) => format!("did you mean `{near}`?"),
            None if names.is_empty() => "it defines no function or class at its top level".to_string(),
            None => format!("it defines: {}", names.join(", ")),
        };
        problems.push(problem(
            "function",
            format!("{} has no function or class `{function}`", file.display()),
            &hint,
        ));
        return problems;
    };
    let Some(params) = &definition.params else { return problems };
    let own: Vec<&String> = super::own_params(&super::entry(), call.params).map(|(name, _)| name).collect();
    for name in own {
        if !params.keywords.contains(name) && !params.any_keyword {
            let known: Vec<&str> = params.keywords.iter().map(String::as_str).collect();
            let hint = match kpl_core::closest(name, &known) {
                Some(near) => format!("did you mean `{near}`?"),
                None => format!(
                    "`{function}` takes the parameters: {}",
                    if known.is_empty() { "none".to_string() } else { known.join(", ") }
                ),
            };
            problems.push(problem(name, format!("`{function}` has no parameter `{name}`"), &hint));
        }
    }
    let inputs = call.inputs.len();
    if inputs > params.positional && !params.any_positional {
        problems.push(problem(
            "function",
            format!("`{function}` takes {} input(s), but the spec gives it {inputs}", params.positional),
            "the function takes the unit's inputs as its first positional parameters, in the order of the spec",
        ));
    } else if inputs < params.required {
        problems.push(problem(
            "function",
            format!("`{function}` needs {} input(s), but the spec gives it {inputs}", params.required),
            "the function takes the unit's inputs as its first positional parameters, in the order of the spec",
        ));
    }
    problems
}

/// The `process.unit` entry's parameter check (E0118): a command, whose program exists when
/// it is a path (a bare name is the PATH's, found when the run starts).
pub(super) fn check_process(call: &CallTypes<'_>) -> Vec<ParamProblem> {
    let command: Vec<&str> = match call.params.get("command") {
        Some(kpl_core::Value::List(items)) => items.iter().filter_map(|v| v.as_str()).collect(),
        _ => Vec::new(),
    };
    let Some(program) = command.first() else {
        return vec![problem(
            "command",
            "`command` is empty".to_string(),
            "name the worker's program and its arguments: command: [\"./worker\", \"--fast\"]",
        )];
    };
    let Some(dir) = call.dir else { return Vec::new() };
    if program.contains('/') {
        let path = super::program_path(program, dir);
        if !path.is_file() {
            return vec![problem(
                "command",
                format!("no program {} ({program} beside the spec)", path.display()),
                "a path with a `/` is relative to the spec's folder; a bare name is looked up on the PATH",
            )];
        }
    }
    Vec::new()
}

fn problem(param: &str, message: String, hint: &str) -> ParamProblem {
    ParamProblem { param: param.into(), element: None, range: (0, 0), message, hint: Some(hint.into()) }
}

fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars.next().is_some_and(|c| c.is_alphabetic() || c == '_')
        && chars.all(|c| c.is_alphanumeric() || c == '_')
}

fn is_module_name(name: &str) -> bool {
    !name.is_empty() && name.split('.').all(is_identifier)
}

/// The module's file beside the spec, else in `$VIRTUAL_ENV`'s site-packages.
fn find_module(dir: &Path, module: &str) -> Option<PathBuf> {
    let relative = module.replace('.', "/");
    let candidates =
        |root: &PathBuf| [root.join(format!("{relative}.py")), root.join(&relative).join("__init__.py")];
    let mut roots = vec![dir.to_path_buf()];
    if let Some(env) = std::env::var_os("VIRTUAL_ENV")
        && let Ok(entries) = std::fs::read_dir(Path::new(&env).join("lib"))
    {
        for entry in entries.flatten() {
            roots.push(entry.path().join("site-packages"));
        }
    }
    roots.iter().flat_map(candidates).find(|p| p.is_file())
}

/// A function's parameters as far as a look at its `def` tells.
#[derive(Debug, Default, PartialEq)]
struct Params {
    /// Parameters that can take an input (positional), and how many have no default.
    positional: usize,
    required: usize,
    any_positional: bool,
    /// Names a keyword argument can have.
    keywords: Vec<String>,
    any_keyword: bool,
}

#[derive(Debug)]
struct Definition {
    name: String,
    /// `None` for a class (its `__init__` is not looked at).
    params: Option<Params>,
}

/// Top-level `def NAME(...)` and `class NAME` of a module's source.
fn top_level_definitions(source: &str) -> Vec<Definition> {
    let mut found = Vec::new();
    for (at, line) in line_starts(source) {
        let rest = line.strip_prefix("async ").unwrap_or(line);
        if let Some(rest) = rest.strip_prefix("def ") {
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            let open = at + (line.len() - rest.len()) + name.len();
            let params =
                source[open..].trim_start().strip_prefix('(').and_then(parameter_list).map(parse_params);
            found.push(Definition {
                name,
                params: Some(params.unwrap_or(Params {
                    any_positional: true,
                    any_keyword: true,
                    ..Params::default()
                })),
            });
        } else if let Some(rest) = line.strip_prefix("class ") {
            let name: String = rest.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
            found.push(Definition { name, params: None });
        }
    }
    found
}

/// Lines that start at column 0, with their byte offset.
fn line_starts(source: &str) -> impl Iterator<Item = (usize, &str)> {
    let mut at = 0;
    source.split_inclusive('\n').map(move |line| {
        let start = at;
        at += line.len();
        (start, line)
    })
}

/// The text between `(` (already consumed) and its `)`.
fn parameter_list(text: &str) -> Option<&str> {
    let mut depth = 0usize;
    let mut quote: Option<char> = None;
    for (i, c) in text.char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '\'' | '"') => quote = Some(c),
            (None, '(' | '[' | '{') => depth += 1,
            (None, ')') if depth == 0 => return Some(&text[..i]),
            (None, ')' | ']' | '}') => depth = depth.saturating_sub(1),
            _ => {}
        }
    }
    None
}

fn parse_params(list: &str) -> Params {
    let mut params = Params::default();
    let mut keyword_only = false;
    for item in split_top_level(list) {
        let item = item.trim();
        if item.is_empty() || item == "/" {
            continue;
        }
        if item == "*" {
            keyword_only = true;
            continue;
        }
        if let Some(rest) = item.strip_prefix("**") {
            let _ = rest;
            params.any_keyword = true;
            continue;
        }
        if item.starts_with('*') {
            params.any_positional = true;
            keyword_only = true;
            continue;
        }
        let name: String = item.chars().take_while(|c| c.is_alphanumeric() || *c == '_').collect();
        let has_default = item.contains('=');
        if name == "self" {
            continue;
        }
        if !keyword_only {
            params.positional += 1;
            if !has_default {
                params.required += 1;
            }
        }
        params.keywords.push(name);
    }
    params
}

fn split_top_level(list: &str) -> Vec<&str> {
    let mut items = Vec::new();
    let (mut depth, mut start, mut quote) = (0usize, 0usize, None::<char>);
    for (i, c) in list.char_indices() {
        match (quote, c) {
            (Some(q), c) if c == q => quote = None,
            (Some(_), _) => {}
            (None, '\'' | '"') => quote = Some(c),
            (None, '(' | '[' | '{') => depth += 1,
            (None, ')' | ']' | '}') => depth = depth.saturating_sub(1),
            (None, ',') if depth == 0 => {
                items.push(&list[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&list[start..]);
    items
}

/// Whether `name` appears in the source as a word (imported or assigned, perhaps).
fn mentions(source: &str, name: &str) -> bool {
    source.match_indices(name).any(|(i, _)| {
        let before = source[..i].chars().next_back();
        let after = source[i + name.len()..].chars().next();
        let word = |c: Option<char>| c.is_some_and(|c| c.is_alphanumeric() || c == '_');
        !word(before)
            && !word(after)
            && source[..i]
                .rsplit('\n')
                .next()
                .is_some_and(|l| l.starts_with("from ") || l.starts_with("import ") || !l.starts_with(' '))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reads_what_a_def_takes() {
        let source = "import numpy as np\n\ndef classify(tracks, speeds=None, *, truck_length: float = 7.5, **rest):\n    pass\nclass Detector:\n    def __init__(self, threshold=0.5):\n        pass\ndef two(a, b,\n        c=(1, 2)):\n    return a\n";
        let defs = top_level_definitions(source);
        let names: Vec<&str> = defs.iter().map(|d| d.name.as_str()).collect();
        assert_eq!(names, ["classify", "Detector", "two"]);
        let classify = defs[0].params.as_ref().unwrap();
        assert_eq!((classify.positional, classify.required), (2, 1));
        assert_eq!(classify.keywords, ["tracks", "speeds", "truck_length"]);
        assert!(classify.any_keyword && !classify.any_positional);
        assert!(defs[1].params.is_none());
        let two = defs[2].params.as_ref().unwrap();
        assert_eq!((two.positional, two.required, two.keywords.len()), (3, 2, 3));
    }

    #[test]
    fn module_names() {
        assert!(is_module_name("a.b_c"));
        assert!(!is_module_name("a/b.py"));
        assert!(!is_module_name(""));
        assert!(!is_identifier("1x"));
    }
}

//! `kpl explain`: the documentation of a diagnostic code (`kpl explain E0130`), taken from
//! `docs/diagnostics.md` as it was when `kpl` was built, so it is the same text as on the page.

use std::io::Write;
use std::process::ExitCode;

use clap::Args as ClapArgs;

/// docs/diagnostics.md, built into the binary.
const DIAGNOSTICS_MD: &str = include_str!("../../../docs/diagnostics.md");

#[derive(Debug, ClapArgs)]
#[command(
    after_help = "Examples:\n  kpl explain E0130\n  kpl explain w0203\n  kpl explain            # every code with its title"
)]
pub struct Args {
    /// A diagnostic code such as E0101 (case does not matter); without one, every code is listed.
    pub code: Option<String>,
}

/// The sections of the page: (code, title, body) for every `## CODE: Title` heading.
pub fn sections() -> Vec<(&'static str, &'static str, &'static str)> {
    let mut out = Vec::new();
    let mut rest = DIAGNOSTICS_MD;
    while let Some(at) = rest.find("\n## ") {
        let section = &rest[at + 4..];
        let end = section.find("\n## ").map_or(section.len(), |e| e + 1);
        let (heading, body) = section[..end].split_once('\n').unwrap_or((&section[..end], ""));
        if let Some((code, title)) = heading.split_once(": ") {
            out.push((code.trim(), title.trim(), body.trim()));
        }
        rest = &section[end.saturating_sub(1)..];
    }
    out
}

pub fn run(args: Args) -> ExitCode {
    let sections = sections();
    let mut stdout = std::io::stdout().lock();
    let Some(code) = args.code else {
        for (code, title, _) in &sections {
            let _ = writeln!(stdout, "{code}  {title}");
        }
        return ExitCode::SUCCESS;
    };
    let wanted = code.trim().to_ascii_uppercase();
    match sections.iter().find(|(c, ..)| *c == wanted) {
        Some((code, title, body)) => {
            let _ = writeln!(stdout, "{code}: {title}\n\n{body}");
            ExitCode::SUCCESS
        }
        None => {
            let known: Vec<&str> = sections.iter().map(|(c, ..)| *c).collect();
            let close = known
                .iter()
                .filter(|c| strsim_like(c, &wanted))
                .take(3)
                .map(|c| format!("`{c}`"))
                .collect::<Vec<_>>();
            let hint = if close.is_empty() {
                "`kpl explain` lists every code".to_string()
            } else {
                format!("did you mean {}? (`kpl explain` lists every code)", close.join(" or "))
            };
            eprintln!("error: no diagnostic has the code `{code}`; {hint}");
            ExitCode::from(2)
        }
    }
}

/// Codes that differ from `wanted` in one character (a typo in one digit).
fn strsim_like(code: &str, wanted: &str) -> bool {
    code.len() == wanted.len() && code.chars().zip(wanted.chars()).filter(|(a, b)| a != b).count() == 1
}

#[cfg(test)]
mod tests {
    use super::sections;

    #[test]
    fn every_section_has_a_code_title_and_text() {
        let sections = sections();
        assert!(sections.len() > 40, "{}", sections.len());
        let e0130 = sections.iter().find(|(c, ..)| *c == "E0130").expect("E0130 documented");
        assert_eq!(e0130.1, "Cycle in the stream graph");
        assert!(e0130.2.contains("with feedback"), "{}", e0130.2);
        assert!(!e0130.2.contains("## "), "one section only");
        for (code, title, body) in &sections {
            assert!(code.len() == 5 && !title.is_empty() && !body.is_empty(), "{code}");
        }
    }
}

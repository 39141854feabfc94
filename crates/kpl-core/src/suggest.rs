//! "Did you mean ...?" hints from the names that exist: the one implementation every layer uses
//! (names in specs, formulas, streams of a recording, plots).

/// The closest candidate to `name`, if one is close enough to be a likely typo.
pub fn closest<'a>(name: &str, candidates: &[&'a str]) -> Option<&'a str> {
    let limit = (name.chars().count() / 3).max(1);
    candidates
        .iter()
        .filter(|c| **c != name)
        .map(|c| (strsim::damerau_levenshtein(&name.to_lowercase(), &c.to_lowercase()), *c))
        .filter(|(distance, _)| *distance <= limit)
        .min()
        .map(|(_, c)| c)
}

/// `Some("did you mean `x`?")` when a candidate is close to `name`.
pub fn did_you_mean(name: &str, candidates: &[&str]) -> Option<String> {
    closest(name, candidates).map(|c| format!("did you mean `{c}`?"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn suggests_close_names_only() {
        let names = ["percepts", "tracker", "world_onroad"];
        assert_eq!(closest("percept", &names), Some("percepts"));
        assert_eq!(closest("Tracker", &names), Some("tracker"));
        assert_eq!(closest("world_onraod", &names), Some("world_onroad"));
        assert_eq!(closest("zzz", &names), None);
        assert_eq!(closest("a", &["b"]), Some("b"));
    }
}

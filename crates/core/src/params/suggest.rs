//! Close matches of a misspelt parameter name, for the unknown-name error.

/// Levenshtein distance of two names, in characters.
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut previous: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut current = vec![i + 1; b.len() + 1];
        for (j, cb) in b.iter().enumerate() {
            let substitution = previous[j] + usize::from(ca != *cb);
            current[j + 1] = substitution.min(previous[j + 1] + 1).min(current[j] + 1);
        }
        previous = current;
    }
    previous[b.len()]
}

/// Up to 3 of `known` that `name` was probably meant to be, closest first:
/// within a third of the name's length in edits (at least 2), or
/// containing it (a prefix such as `init_`).
pub fn close_matches<'a>(name: &str, known: impl Iterator<Item = &'a str>) -> Vec<String> {
    let limit = (name.chars().count() / 3).max(2);
    let mut scored: Vec<(usize, &str)> = known
        .filter_map(|k| {
            let d = edit_distance(name, k);
            (d <= limit || (name.len() >= 3 && k.contains(name))).then_some((d, k))
        })
        .collect();
    scored.sort();
    scored.into_iter().take(3).map(|(_, k)| k.to_string()).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn typos_find_their_parameter() {
        let known = ["gate_sigmas", "q", "max_hypotheses", "init_max_hypotheses", "motion"];
        assert_eq!(close_matches("gate_sigma", known.into_iter())[0], "gate_sigmas");
        assert_eq!(close_matches("max_hypothesis", known.into_iter())[0], "max_hypotheses");
        assert!(close_matches("completely_different", known.into_iter()).is_empty());
        assert_eq!(edit_distance("kitten", "sitting"), 3);
    }
}

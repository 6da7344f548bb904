//! The actors that asked the server for an index (`JoinActor`): a scaled
//! deployment (compose `--scale`, a Kubernetes Deployment) gives its actors
//! no ordinal of their own, so the replay server they all reach hands them
//! out, in order of first request, stable per name.

use std::collections::HashMap;
use std::sync::Mutex;

/// Longest accepted name (a DNS name's limit).
pub const MAX_NAME_LEN: usize = 253;

/// Names to indices.
#[derive(Debug, Default)]
pub struct Roster {
    names: Mutex<HashMap<String, u32>>,
}

impl Roster {
    /// The index of `name` (a new one when the name is new) and how many
    /// names have joined; for a bad name, what is wrong with it.
    pub fn join(&self, name: &str) -> Result<(u32, u32), String> {
        check_name(name)?;
        let mut names = self.names.lock().unwrap_or_else(|e| e.into_inner());
        let next = u32::try_from(names.len()).map_err(|_| "the roster is full".to_owned())?;
        let index = *names.entry(name.to_owned()).or_insert(next);
        Ok((index, u32::try_from(names.len()).unwrap_or(u32::MAX)))
    }
}

fn check_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > MAX_NAME_LEN {
        return Err(format!(
            "{} characters; an actor's name has 1 to {MAX_NAME_LEN}",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_')))
    {
        return Err(format!(
            "{c:?} in {name:?}; an actor's name has letters, digits, '.', '-' and '_'"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn indices_in_order_of_first_join_and_stable_per_name() {
        let roster = Roster::default();
        assert_eq!(roster.join("a1b2c3"), Ok((0, 1)));
        assert_eq!(roster.join("crossroads-actor-7"), Ok((1, 2)));
        assert_eq!(
            roster.join("a1b2c3"),
            Ok((0, 2)),
            "a restart keeps its index"
        );
        assert_eq!(roster.join("pod_x.local"), Ok((2, 3)));
    }

    #[test]
    fn bad_names_are_refused_and_take_no_index() {
        let roster = Roster::default();
        let long = "x".repeat(MAX_NAME_LEN + 1);
        for (name, needle) in [
            ("", "0 characters"),
            (long.as_str(), "254"),
            ("a b", "' '"),
            ("ä", "'ä'"),
        ] {
            let e = roster.join(name).unwrap_err();
            assert!(e.contains(needle), "{name:?}: {e}");
        }
        assert_eq!(roster.join("ok"), Ok((0, 1)));
    }
}

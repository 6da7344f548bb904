//! What a checkpoint id is: the name of the checkpoint's folder, so the
//! learner's store and a client that downloads a checkpoint agree on which
//! names are safe to put in a path.

/// Checks that `id` is a plain checkpoint name: 1 to 128 of ASCII letters,
/// digits, `-`, `_`, `.`, not starting with a dot (so not `.`, `..` or a
/// temporary folder). Returns what is wrong with it otherwise.
pub fn check_checkpoint_id(id: &str) -> Result<(), &'static str> {
    if id.is_empty() || id.len() > 128 {
        return Err("must be 1 to 128 characters");
    }
    if id.contains(['/', '\\']) || id.contains("..") {
        return Err("must not contain path separators or '..'");
    }
    if id.starts_with('.') {
        return Err("must not start with '.'");
    }
    if !id
        .chars()
        .all(|c| c.is_ascii_alphanumeric() || "-_.".contains(c))
    {
        return Err("may only hold ASCII letters, digits, '-', '_' and '.'");
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_plain_folder_names_pass() {
        for good in ["ckpt-000000000001", "best", "a.b_c-1"] {
            assert_eq!(check_checkpoint_id(good), Ok(()), "{good:?}");
        }
        for bad in ["../x", "..", ".", "a/b", "ckpt\\1", ".tmp-ckpt", "", "a b"] {
            assert!(check_checkpoint_id(bad).is_err(), "{bad:?}");
        }
        assert!(check_checkpoint_id(&"x".repeat(129)).is_err());
    }
}

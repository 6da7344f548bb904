//! Configuration loading (`ConfigLoader`) of untrusted text: a TOML file
//! layered over the defaults, or, when the input starts with `--set\n`,
//! one `--set section.key=value` override per line.
//!
//! Asserts: a loaded config is valid (`Config::validate` finds nothing),
//! and its effective TOML (`Config::to_toml`, what `crossroads config
//! show` prints and roles log) loads back to the same config.
#![no_main]

use crossroads_config::ConfigLoader;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    let loader = match text.strip_prefix("--set\n") {
        Some(sets) => ConfigLoader::new().without_env().sets(sets.lines()),
        None => ConfigLoader::new().without_env().base("fuzz.toml", text),
    };
    let Ok((config, _notes)) = loader.load_with_notes() else {
        return;
    };
    assert!(config.validate().is_empty());
    let shown = config.to_toml();
    let again = ConfigLoader::new()
        .without_env()
        .base("shown.toml", shown.as_str())
        .load()
        .unwrap_or_else(|e| panic!("the shown config does not load: {e}\n{shown}"));
    assert_eq!(again, config, "{shown}");
});

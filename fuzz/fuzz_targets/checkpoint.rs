//! A checkpoint's manifest and files as the learner's `CheckpointStore::load`
//! checks them before building any tensor (`Manifest::parse`,
//! `Manifest::check_files`). Input: a flags byte, then four sections
//! (`crossroads_fuzz::sections`): `manifest.json`, the online and target
//! weights and the optimizer state. Flag bit 0 rewrites the manifest's
//! file entries to the sections' sizes and checksums, so the fuzzer gets
//! past the CRC-32s to the safetensors readers.
//!
//! Asserts: a manifest that parses is of this format, names the folder's
//! id and a valid network, and prints to JSON that parses back equal;
//! files that pass are the bytes given, match the manifest, hold weights
//! of its network and f32 optimizer state with its optimizer's name.
#![no_main]

use crossroads_fuzz::sections;
use crossroads_types::WeightsMeta;
use crossroads_types::checkpoint::{
    FileEntry, MANIFEST_FORMAT, MANIFEST_VERSION, Manifest, OPTIMIZER_FILE, TARGET_FILE,
    WEIGHTS_FILE,
};
use libfuzzer_sys::fuzz_target;

/// The folder the fuzzed manifest is read from.
const ID: &str = "ckpt-000000000001";

fuzz_target!(|data: &[u8]| {
    let Some((&flags, data)) = data.split_first() else {
        return;
    };
    let [manifest, online, target, optimizer] = sections(data, 4)[..] else {
        return;
    };
    let Ok(text) = std::str::from_utf8(manifest) else {
        return;
    };
    let Ok(mut m) = Manifest::parse(ID, text) else {
        return;
    };
    assert_eq!(
        (m.format.as_str(), m.format_version, m.id.as_str()),
        (MANIFEST_FORMAT, MANIFEST_VERSION, ID)
    );
    assert_eq!(m.network.validate(), Ok(()));
    let json = serde_json::to_string(&m).expect("a manifest prints");
    assert_eq!(Manifest::parse(ID, &json).as_ref(), Ok(&m));
    if flags & 1 == 1 {
        for (name, bytes) in [
            (WEIGHTS_FILE, online),
            (TARGET_FILE, target),
            (OPTIMIZER_FILE, optimizer),
        ] {
            m.files.insert(name.to_owned(), FileEntry::of(bytes));
        }
    }
    if let Ok(files) = m.check_files(online.to_vec(), target.to_vec(), optimizer) {
        assert_eq!(
            (files.online.as_slice(), files.target.as_slice()),
            (online, target)
        );
        for (name, bytes) in [(WEIGHTS_FILE, online), (TARGET_FILE, target)] {
            assert_eq!(m.check_file(name, bytes), Ok(()));
            assert_eq!(
                WeightsMeta::read(bytes).map(|w| w.spec),
                Ok(m.network.clone())
            );
        }
        let (meta, tensors) =
            crossroads_types::tensors::read_f32(optimizer).expect("checked already");
        assert_eq!(meta.get("optimizer"), Some(&m.optimizer));
        let steps = meta.get("steps").and_then(|s| s.parse::<u64>().ok());
        assert_eq!(steps, Some(files.optimizer_steps));
        assert_eq!(tensors.len(), files.optimizer.len());
    }
});

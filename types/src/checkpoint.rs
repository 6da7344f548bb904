//! What a checkpoint is, without tensors: its id, the name of its folder
//! (so the learner's store and a client that downloads a checkpoint agree
//! on which names are safe to put in a path), and its [`Manifest`], read
//! and checked against the checkpoint's files ([`Manifest::parse`],
//! [`Manifest::check_files`]) before `crossroads_learner` turns anything
//! into a tensor.

use std::collections::BTreeMap;

use serde::{Deserialize, Serialize};

use crate::spec::NetworkSpec;
use crate::tensors::{self, F32Tensor};
use crate::weights::WeightsMeta;

/// The online network's file.
pub const WEIGHTS_FILE: &str = "weights.safetensors";
/// The target network's file.
pub const TARGET_FILE: &str = "target.safetensors";
/// The optimizer state's file.
pub const OPTIMIZER_FILE: &str = "optimizer.safetensors";
/// The manifest, written last.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Value of the manifest's `format`.
pub const MANIFEST_FORMAT: &str = "crossroads.checkpoint";
/// Version of the checkpoint layout.
pub const MANIFEST_VERSION: u32 = 1;

/// Size and checksum of one file, as the manifest records it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileEntry {
    /// Bytes.
    pub bytes: u64,
    /// CRC-32 (IEEE) of the content.
    pub crc32: u32,
}

impl FileEntry {
    /// The entry of `bytes`.
    pub fn of(bytes: &[u8]) -> Self {
        Self {
            bytes: bytes.len() as u64,
            crc32: crc32fast::hash(bytes),
        }
    }
}

/// `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`MANIFEST_FORMAT`].
    pub format: String,
    /// [`MANIFEST_VERSION`].
    pub format_version: u32,
    /// The checkpoint's id (its folder name).
    pub id: String,
    /// Updates applied when it was taken.
    pub update_step: u64,
    /// Latest published weights version when it was taken.
    pub weights_version: u64,
    /// When it was written, Unix milliseconds.
    pub created_unix_ms: i64,
    /// Scenario of the run.
    pub scenario: String,
    /// The network.
    pub network: NetworkSpec,
    /// `rmsprop` or `adam`.
    pub optimizer: String,
    /// Latest evaluation reported (metric -> value) and the version it
    /// evaluated.
    pub eval_metrics: BTreeMap<String, f64>,
    /// Weights version the evaluation was of; 0 if none.
    pub eval_weights_version: u64,
    /// The run's configuration as TOML (the API token redacted).
    pub config: String,
    /// The other files with their size and checksum.
    pub files: BTreeMap<String, FileEntry>,
}

/// A checkpoint's files checked against its manifest: the two networks'
/// safetensors bytes (their metadata read and matched, their tensors left
/// to the network that loads them) and the optimizer state, decoded.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckedFiles {
    /// The online network's safetensors bytes.
    pub online: Vec<u8>,
    /// The target network's safetensors bytes.
    pub target: Vec<u8>,
    /// Optimizer state tensors `<slot>.<variable>`, sorted by name.
    pub optimizer: Vec<F32Tensor>,
    /// Optimizer steps taken.
    pub optimizer_steps: u64,
}

impl Manifest {
    /// Parses the manifest of checkpoint `id` (its folder name) and checks
    /// what it says of itself: format, version, id and network. The error
    /// names the problem.
    pub fn parse(id: &str, text: &str) -> Result<Self, String> {
        let m: Manifest =
            serde_json::from_str(text).map_err(|e| format!("{MANIFEST_FILE}: {e}"))?;
        if m.format != MANIFEST_FORMAT || m.format_version != MANIFEST_VERSION {
            return Err(format!(
                "format {:?} version {}; this build reads {MANIFEST_FORMAT:?} version {MANIFEST_VERSION}",
                m.format, m.format_version
            ));
        }
        if m.id != id {
            return Err(format!("its manifest names {:?}", m.id));
        }
        m.network
            .validate()
            .map_err(|e| format!("{MANIFEST_FILE}: {e}"))?;
        Ok(m)
    }

    /// Checks one file's bytes against the size and checksum recorded for
    /// `name`.
    pub fn check_file(&self, name: &str, bytes: &[u8]) -> Result<(), String> {
        let entry = self
            .files
            .get(name)
            .ok_or_else(|| format!("the manifest does not list {name}"))?;
        if FileEntry::of(bytes) != *entry {
            return Err(format!(
                "{name} does not match its manifest (size or checksum)"
            ));
        }
        Ok(())
    }

    /// Checks a checkpoint's three files: each matches its size and
    /// checksum, both networks' metadata say the manifest's network, and
    /// the optimizer state is f32 tensors of the manifest's optimizer with
    /// a step count. Everything a load needs from untrusted bytes, before
    /// any tensor is built.
    pub fn check_files(
        &self,
        online: Vec<u8>,
        target: Vec<u8>,
        optimizer: &[u8],
    ) -> Result<CheckedFiles, String> {
        for (name, bytes) in [
            (WEIGHTS_FILE, online.as_slice()),
            (TARGET_FILE, target.as_slice()),
            (OPTIMIZER_FILE, optimizer),
        ] {
            self.check_file(name, bytes)?;
        }
        for (name, bytes) in [(WEIGHTS_FILE, &online), (TARGET_FILE, &target)] {
            let meta = WeightsMeta::read(bytes).map_err(|e| format!("{name}: {e}"))?;
            if meta.spec != self.network {
                return Err(format!(
                    "{name} holds weights of {:?}, the manifest's network is {:?}",
                    meta.spec, self.network
                ));
            }
        }
        let (meta, tensors) =
            tensors::read_f32(optimizer).map_err(|e| format!("{OPTIMIZER_FILE}: {e}"))?;
        if meta.get("optimizer") != Some(&self.optimizer) {
            return Err(format!(
                "{OPTIMIZER_FILE} holds {:?} state, the manifest says {:?}",
                meta.get("optimizer"),
                self.optimizer
            ));
        }
        let optimizer_steps = meta
            .get("steps")
            .and_then(|s| s.parse::<u64>().ok())
            .ok_or_else(|| format!("{OPTIMIZER_FILE}: no step count"))?;
        Ok(CheckedFiles {
            online,
            target,
            optimizer: tensors,
            optimizer_steps,
        })
    }
}

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

//! [`CheckpointStore`]: checkpoints as folders under one directory, written
//! atomically, listed, loaded, pruned and deleted, with ids that cannot
//! leave the directory.
//!
//! A checkpoint `<dir>/<id>/` (id `ckpt-<update step, 12 digits>`, with a
//! `-<n>` suffix when a step is saved twice) holds:
//!
//! | file | content |
//! | --- | --- |
//! | `weights.safetensors` | the online network ([`crossroads_model::weights`] format) |
//! | `target.safetensors` | the target network, same format |
//! | `optimizer.safetensors` | optimizer state tensors `<slot>.<variable>`; metadata `optimizer`, `steps` |
//! | `manifest.json` | [`Manifest`]: step, version, scenario, evaluation, config, time, network |
//!
//! A checkpoint is either whole or absent; after each write the newest
//! `keep` are kept, plus the best by the evaluation metric. An id must be a
//! plain folder name, and a symlink is never followed. The directory also
//! holds the version lease ([`VERSION_LEASE_FILE`]).

use std::collections::{BTreeMap, HashMap};
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::{SystemTime, UNIX_EPOCH};

use crossroads_model::NetworkSpec;
use crossroads_transport::convert::CheckpointSummary;
use crossroads_types::checkpoint::check_checkpoint_id;
use parking_lot::Mutex;
use tch::Tensor;

use crate::trainer::TrainerState;

pub use crossroads_types::checkpoint::{
    FileEntry, MANIFEST_FILE, MANIFEST_FORMAT, MANIFEST_VERSION, Manifest, OPTIMIZER_FILE,
    TARGET_FILE, WEIGHTS_FILE,
};

const TMP_PREFIX: &str = ".tmp-";
/// The file of the version lease: the highest weights version a learner
/// of this folder may have published, written atomically. The learner
/// leases versions a block at a time before publishing them and starts
/// above the lease, so after a kill -9 versions still only increase.
pub const VERSION_LEASE_FILE: &str = "versions.lease";

/// Why a checkpoint operation failed.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The id is not a plain checkpoint name (it has a path separator,
    /// `..`, starts with a dot, or has other characters).
    #[error("invalid checkpoint id {id:?}: {problem}")]
    InvalidId {
        /// The id.
        id: String,
        /// What is wrong with it.
        problem: String,
    },
    /// No checkpoint has this id.
    #[error("no checkpoint {0:?}")]
    NotFound(String),
    /// A file could not be read or written.
    #[error("{action} {}: {source}", path.display())]
    Io {
        /// What was being done.
        action: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The I/O error.
        source: std::io::Error,
    },
    /// A checkpoint's files are incomplete or not valid.
    #[error("checkpoint {id}: {problem}")]
    Corrupt {
        /// The checkpoint.
        id: String,
        /// What is wrong.
        problem: String,
    },
}

fn io<'a>(action: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> StoreError + 'a {
    move |source| StoreError::Io {
        action,
        path: path.to_path_buf(),
        source,
    }
}

/// A checkpoint as listed: its manifest, total size and whether it is the
/// best by evaluation.
#[derive(Debug, Clone, PartialEq)]
pub struct CheckpointEntry {
    /// The manifest.
    pub manifest: Manifest,
    /// Total bytes of its files.
    pub size_bytes: u64,
    /// The best by the evaluation metric among those stored.
    pub best: bool,
}

impl CheckpointEntry {
    /// The id.
    pub fn id(&self) -> &str {
        &self.manifest.id
    }

    /// The file names, manifest last.
    pub fn files(&self) -> Vec<String> {
        let mut files: Vec<String> = self.manifest.files.keys().cloned().collect();
        files.push(MANIFEST_FILE.to_owned());
        files
    }
}

impl From<&CheckpointEntry> for CheckpointSummary {
    fn from(e: &CheckpointEntry) -> Self {
        Self {
            id: e.manifest.id.clone(),
            update_step: e.manifest.update_step,
            weights_version: e.manifest.weights_version,
            created_unix_ms: e.manifest.created_unix_ms,
            size_bytes: e.size_bytes,
            scenario: e.manifest.scenario.clone(),
            eval_metrics: e.manifest.eval_metrics.clone(),
            best: e.best,
            files: e.files(),
        }
    }
}

/// What a checkpoint restores.
#[derive(Debug)]
pub struct Loaded {
    /// The manifest.
    pub manifest: Manifest,
    /// Training state: networks, optimizer, step.
    pub state: TrainerState,
}

/// What the learner hands over to be written.
#[derive(Debug)]
pub struct NewCheckpoint<'a> {
    /// Training state.
    pub state: &'a TrainerState,
    /// Latest published version.
    pub weights_version: u64,
    /// Scenario of the run.
    pub scenario: &'a str,
    /// The network.
    pub network: &'a NetworkSpec,
    /// Optimizer name.
    pub optimizer: &'a str,
    /// Latest evaluation.
    pub eval_metrics: &'a BTreeMap<String, f64>,
    /// Version it evaluated.
    pub eval_weights_version: u64,
    /// Config as TOML.
    pub config: &'a str,
}

/// The checkpoints of one directory. Thread-safe: writes, prunes and
/// deletes are serialized by a lock; reads take it briefly. Writes go to a
/// hidden temporary folder (files fsynced), which is renamed into place
/// and the directory fsynced; leftovers of an interrupted write are
/// removed on open.
#[derive(Debug)]
pub struct CheckpointStore {
    dir: PathBuf,
    keep: usize,
    best_metric: String,
    lock: Mutex<()>,
}

/// Checks that `id` is a plain checkpoint name
/// (`crossroads_types::checkpoint::check_checkpoint_id`: 1 to 128 of ASCII
/// letters, digits, `-`, `_`, `.`, not starting with a dot, so not `.`,
/// `..` or a temporary folder).
pub fn validate_id(id: &str) -> Result<(), StoreError> {
    check_checkpoint_id(id).map_err(|problem| StoreError::InvalidId {
        id: id.to_owned(),
        problem: problem.to_owned(),
    })
}

fn now_ms() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map(|d| d.as_millis() as i64)
        .unwrap_or(0)
}

fn write_synced(path: &Path, bytes: &[u8]) -> Result<FileEntry, StoreError> {
    let mut f = File::create(path).map_err(io("creating", path))?;
    f.write_all(bytes).map_err(io("writing", path))?;
    f.sync_all().map_err(io("syncing", path))?;
    Ok(FileEntry::of(bytes))
}

fn sync_dir(path: &Path) -> Result<(), StoreError> {
    File::open(path)
        .and_then(|d| d.sync_all())
        .map_err(io("syncing folder", path))
}

impl CheckpointStore {
    /// The store of `dir` (created if missing); removes leftovers of
    /// interrupted writes.
    pub fn open(
        dir: impl Into<PathBuf>,
        keep: usize,
        best_metric: &str,
    ) -> Result<Self, StoreError> {
        let dir = dir.into();
        fs::create_dir_all(&dir).map_err(io("creating", &dir))?;
        for entry in fs::read_dir(&dir).map_err(io("reading", &dir))? {
            let entry = entry.map_err(io("reading", &dir))?;
            if entry.file_name().to_string_lossy().starts_with(TMP_PREFIX) {
                let path = entry.path();
                tracing::warn!(path = %path.display(), "removing an interrupted checkpoint write");
                fs::remove_dir_all(&path).map_err(io("removing", &path))?;
            }
        }
        Ok(Self {
            dir,
            keep: keep.max(1),
            best_metric: best_metric.to_owned(),
            lock: Mutex::new(()),
        })
    }

    /// The directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }

    /// The version lease: no learner of this folder published a weights
    /// version above it (0 when none was leased). A learner killed at any
    /// moment restarts above it, so versions only ever increase.
    pub fn version_lease(&self) -> Result<u64, StoreError> {
        let path = self.dir.join(VERSION_LEASE_FILE);
        let text = match fs::read_to_string(&path) {
            Ok(text) => text,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(0),
            Err(e) => return Err(io("reading", &path)(e)),
        };
        text.trim().parse().map_err(|_| StoreError::Corrupt {
            id: VERSION_LEASE_FILE.to_owned(),
            problem: format!(
                "{} holds {:?}, not a version number; remove it only if no learner of this \
                 folder published weights (versions would repeat)",
                path.display(),
                text.trim()
            ),
        })
    }

    /// Records, durably, that versions up to `upto` may be published: a
    /// temporary file, fsynced, renamed over the lease, the folder fsynced.
    /// A crash leaves the old lease or the new one, never a partial file.
    pub fn lease_versions(&self, upto: u64) -> Result<(), StoreError> {
        let path = self.dir.join(VERSION_LEASE_FILE);
        let tmp = self.dir.join(format!(".{VERSION_LEASE_FILE}.tmp"));
        write_synced(&tmp, format!("{upto}\n").as_bytes())?;
        fs::rename(&tmp, &path).map_err(io("renaming into place", &path))?;
        sync_dir(&self.dir)
    }

    /// The folder of checkpoint `id`: INVALID for an id that is not a plain
    /// name or resolves outside the directory (a symlink), NOT_FOUND for
    /// one without a manifest.
    pub fn resolve(&self, id: &str) -> Result<PathBuf, StoreError> {
        validate_id(id)?;
        let path = self.dir.join(id);
        let meta = match fs::symlink_metadata(&path) {
            Ok(m) => m,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(StoreError::NotFound(id.to_owned()));
            }
            Err(e) => return Err(io("reading", &path)(e)),
        };
        if meta.file_type().is_symlink() || !meta.is_dir() {
            return Err(StoreError::InvalidId {
                id: id.to_owned(),
                problem: "is not a checkpoint folder inside the checkpoint directory".to_owned(),
            });
        }
        if !path.join(MANIFEST_FILE).is_file() {
            return Err(StoreError::NotFound(id.to_owned()));
        }
        Ok(path)
    }

    fn read_manifest(&self, id: &str) -> Result<Manifest, StoreError> {
        let path = self.resolve(id)?.join(MANIFEST_FILE);
        let text = fs::read_to_string(&path).map_err(io("reading", &path))?;
        Manifest::parse(id, &text).map_err(|problem| StoreError::Corrupt {
            id: id.to_owned(),
            problem,
        })
    }

    fn entries_unlocked(&self) -> Result<Vec<CheckpointEntry>, StoreError> {
        let mut out = Vec::new();
        for entry in fs::read_dir(&self.dir).map_err(io("reading", &self.dir))? {
            let entry = entry.map_err(io("reading", &self.dir))?;
            let name = entry.file_name().to_string_lossy().into_owned();
            if validate_id(&name).is_err() {
                continue;
            }
            match self.read_manifest(&name) {
                Ok(manifest) => {
                    let size_bytes = manifest.files.values().map(|f| f.bytes).sum::<u64>()
                        + fs::metadata(entry.path().join(MANIFEST_FILE)).map_or(0, |m| m.len());
                    out.push(CheckpointEntry {
                        manifest,
                        size_bytes,
                        best: false,
                    });
                }
                Err(StoreError::NotFound(_)) | Err(StoreError::InvalidId { .. }) => {}
                Err(e) => tracing::warn!(error = %e, "skipping an unreadable checkpoint"),
            }
        }
        out.sort_by(|a, b| {
            (
                b.manifest.update_step,
                b.manifest.created_unix_ms,
                &b.manifest.id,
            )
                .cmp(&(
                    a.manifest.update_step,
                    a.manifest.created_unix_ms,
                    &a.manifest.id,
                ))
        });
        if let Some(best) = self.best_index(&out) {
            out[best].best = true;
        }
        Ok(out)
    }

    fn best_index(&self, entries: &[CheckpointEntry]) -> Option<usize> {
        let mut best: Option<(usize, f64)> = None;
        for (i, e) in entries.iter().enumerate() {
            if let Some(&v) = e.manifest.eval_metrics.get(&self.best_metric)
                && v.is_finite()
                && best.is_none_or(|(_, b)| v > b)
            {
                best = Some((i, v));
            }
        }
        best.map(|(i, _)| i)
    }

    /// Every readable checkpoint, newest first (by update step).
    pub fn list(&self) -> Result<Vec<CheckpointEntry>, StoreError> {
        let _guard = self.lock.lock();
        self.entries_unlocked()
    }

    /// One checkpoint's entry.
    pub fn entry(&self, id: &str) -> Result<CheckpointEntry, StoreError> {
        self.resolve(id)?;
        self.list()?
            .into_iter()
            .find(|e| e.id() == id)
            .ok_or_else(|| StoreError::NotFound(id.to_owned()))
    }

    /// Writes a checkpoint atomically, then prunes; returns its entry.
    pub fn write(&self, c: &NewCheckpoint<'_>) -> Result<CheckpointEntry, StoreError> {
        let _guard = self.lock.lock();
        let base = format!("ckpt-{:012}", c.state.step);
        let mut id = base.clone();
        let mut n = 1;
        while fs::symlink_metadata(self.dir.join(&id)).is_ok() {
            n += 1;
            id = format!("{base}-{n}");
        }
        let tmp = self
            .dir
            .join(format!("{TMP_PREFIX}{id}-{}", std::process::id()));
        fs::create_dir_all(&tmp).map_err(io("creating", &tmp))?;
        let written = self.write_files(&tmp, &id, c);
        let manifest = match written {
            Ok(m) => m,
            Err(e) => {
                let _ = fs::remove_dir_all(&tmp);
                return Err(e);
            }
        };
        let path = self.dir.join(&id);
        fs::rename(&tmp, &path).map_err(io("renaming into place", &path))?;
        sync_dir(&self.dir)?;
        self.prune_unlocked()?;
        let size_bytes = manifest.files.values().map(|f| f.bytes).sum::<u64>()
            + fs::metadata(path.join(MANIFEST_FILE)).map_or(0, |m| m.len());
        let best = self
            .entries_unlocked()?
            .iter()
            .any(|e| e.id() == id && e.best);
        Ok(CheckpointEntry {
            manifest,
            size_bytes,
            best,
        })
    }

    fn write_files(
        &self,
        tmp: &Path,
        id: &str,
        c: &NewCheckpoint<'_>,
    ) -> Result<Manifest, StoreError> {
        let corrupt = |problem: String| StoreError::Corrupt {
            id: id.to_owned(),
            problem,
        };
        let optimizer = crossroads_model::weights::encode(
            &c.state.optimizer,
            &HashMap::from([
                ("optimizer".to_owned(), c.optimizer.to_owned()),
                ("steps".to_owned(), c.state.optimizer_steps.to_string()),
            ]),
        )
        .map_err(|e| corrupt(format!("encoding the optimizer state: {e}")))?;
        let mut files = BTreeMap::new();
        for (name, bytes) in [
            (WEIGHTS_FILE, c.state.online.as_slice()),
            (TARGET_FILE, c.state.target.as_slice()),
            (OPTIMIZER_FILE, optimizer.as_slice()),
        ] {
            files.insert(name.to_owned(), write_synced(&tmp.join(name), bytes)?);
        }
        let manifest = Manifest {
            format: MANIFEST_FORMAT.to_owned(),
            format_version: MANIFEST_VERSION,
            id: id.to_owned(),
            update_step: c.state.step,
            weights_version: c.weights_version,
            created_unix_ms: now_ms(),
            scenario: c.scenario.to_owned(),
            network: c.network.clone(),
            optimizer: c.optimizer.to_owned(),
            eval_metrics: c.eval_metrics.clone(),
            eval_weights_version: c.eval_weights_version,
            config: c.config.to_owned(),
            files,
        };
        let json = serde_json::to_vec_pretty(&manifest)
            .map_err(|e| corrupt(format!("encoding the manifest: {e}")))?;
        write_synced(&tmp.join(MANIFEST_FILE), &json)?;
        sync_dir(tmp)?;
        Ok(manifest)
    }

    fn prune_unlocked(&self) -> Result<(), StoreError> {
        let entries = self.entries_unlocked()?;
        for (i, e) in entries.iter().enumerate() {
            if i >= self.keep && !e.best {
                let path = self.dir.join(e.id());
                tracing::debug!(id = e.id(), "pruning checkpoint");
                fs::remove_dir_all(&path).map_err(io("removing", &path))?;
            }
        }
        Ok(())
    }

    /// Reads and checks a checkpoint: every file present with the size and
    /// checksum its manifest records, weights of the manifest's network.
    pub fn load(&self, id: &str) -> Result<Loaded, StoreError> {
        let manifest = {
            let _guard = self.lock.lock();
            self.read_manifest(id)?
        };
        let dir = self.resolve(id)?;
        let corrupt = |problem: String| StoreError::Corrupt {
            id: id.to_owned(),
            problem,
        };
        let read = |name: &str| -> Result<Vec<u8>, StoreError> {
            if !manifest.files.contains_key(name) {
                return Err(corrupt(format!("the manifest does not list {name}")));
            }
            let path = dir.join(name);
            fs::read(&path).map_err(io("reading", &path))
        };
        let (online, target, optimizer) = (
            read(WEIGHTS_FILE)?,
            read(TARGET_FILE)?,
            read(OPTIMIZER_FILE)?,
        );
        // Every check of the bytes is tch-free (and fuzzed); what is left
        // is making tensors of checked values.
        let files = manifest
            .check_files(online, target, &optimizer)
            .map_err(corrupt)?;
        let optimizer = files
            .optimizer
            .into_iter()
            .map(|t| {
                let name = t.name.clone();
                crossroads_model::weights::to_tensor(t)
                    .map(|tensor| (name, tensor))
                    .map_err(|e| corrupt(format!("{OPTIMIZER_FILE}: {e}")))
            })
            .collect::<Result<Vec<(String, Tensor)>, _>>()?;
        Ok(Loaded {
            state: TrainerState {
                online: files.online,
                target: files.target,
                optimizer,
                optimizer_steps: files.optimizer_steps,
                step: manifest.update_step,
            },
            manifest,
        })
    }

    /// Removes a checkpoint.
    pub fn delete(&self, id: &str) -> Result<(), StoreError> {
        let _guard = self.lock.lock();
        let path = self.resolve(id)?;
        fs::remove_dir_all(&path).map_err(io("removing", &path))?;
        sync_dir(&self.dir)
    }

    /// The path of file `name` of checkpoint `id`, for streaming; only the
    /// files its manifest lists (and the manifest) are served.
    pub fn file_path(&self, id: &str, name: &str) -> Result<PathBuf, StoreError> {
        let entry = self.entry(id)?;
        if !entry.files().iter().any(|f| f == name) {
            return Err(StoreError::NotFound(format!("{id}/{name}")));
        }
        Ok(self.resolve(id)?.join(name))
    }
}

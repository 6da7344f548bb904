//! A batch encoded into a table's compact format before the table's lock
//! is taken, and its image in the write-ahead log.

use crossroads_types::batch::{BatchError, RejectReason, TransitionBatch, ValidBatch};
use crossroads_types::{Columns, ObservationLayout};

use crate::compact;
use crate::storage::content_hash;
use crate::table_image::{TableImage, check_image};

/// A validated batch, encoded into the table's compact format before the
/// table's lock is taken.
#[derive(Debug, Clone)]
pub struct PreparedBatch {
    pub(crate) layout: ObservationLayout,
    pub(crate) num_actions: u32,
    /// The index columns refer to `entries`.
    pub(crate) columns: Columns,
    /// Per pool entry: content hash and range in `bytes`.
    pub(crate) entries: Vec<(u64, usize, usize)>,
    pub(crate) bytes: Vec<u8>,
}

impl PreparedBatch {
    /// Encodes a batch (validated where it entered the process, so not
    /// checked again).
    pub fn new(batch: ValidBatch) -> Self {
        let batch = batch.into_inner();
        let len = batch.layout.check().unwrap_or(0);
        let channels = compact::channels_of_layout(&batch.layout);
        let pool = &batch.observations;
        let mut bytes = Vec::new();
        let mut entries = Vec::with_capacity(pool.len());
        let (mut pairs, mut scratch) = (Vec::new(), Vec::new());
        for i in 0..pool.len() {
            let start = bytes.len();
            compact::from_wire(
                pool.encoding(),
                pool.get(i).unwrap_or_default(),
                len,
                channels,
                &mut pairs,
                &mut scratch,
                &mut bytes,
            );
            entries.push((content_hash(&bytes[start..]), start, bytes.len()));
        }
        Self {
            layout: batch.layout,
            num_actions: batch.num_actions,
            columns: batch.columns,
            entries,
            bytes,
        }
    }

    /// The batch as a small image whose items take keys `first_key..`
    /// (what the write-ahead log stores; counters zero).
    pub fn to_image(&self, first_key: u64) -> TableImage {
        TableImage {
            spec: Some((self.layout.clone(), self.num_actions)),
            next_key: first_key + self.len() as u64,
            items: self.columns.clone(),
            observation_offsets: self.entries.iter().map(|(_, s, _)| *s as u64).collect(),
            observation_data: self.bytes.clone(),
            ..TableImage::default()
        }
    }

    /// The batch an image made by [`to_image`](Self::to_image) holds, and
    /// its first key; an image that does not hold together, or has no
    /// layout, is refused.
    pub fn from_image(image: TableImage) -> Result<(u64, Self), BatchError> {
        let obs_len = check_image(&image)?;
        let Some((layout, num_actions)) = image.spec.clone() else {
            return Err(BatchError::new(
                RejectReason::BadRequest,
                "layout",
                "a batch image must state its observation layout",
            ));
        };
        let n_obs = image.observation_offsets.len();
        let mut entries = Vec::with_capacity(n_obs);
        let mut scratch = Vec::new();
        for i in 0..n_obs {
            let start = image.observation_offsets[i] as usize;
            let bad = |problem: String| {
                BatchError::new(
                    RejectReason::ObservationEncoding,
                    format!("observations[{i}]"),
                    problem,
                )
            };
            let bytes = image
                .observation(i)
                .ok_or_else(|| bad("out of the data".to_owned()))?;
            // Samples decode it later without a check of their own.
            scratch.clear();
            compact::to_sparse_wire(bytes, obs_len, &mut scratch)
                .map_err(|e| bad(e.to_string()))?;
            entries.push((content_hash(bytes), start, start + bytes.len()));
        }
        let first_key = image.next_key - image.len() as u64;
        Ok((
            first_key,
            Self {
                layout,
                num_actions,
                columns: image.items,
                entries,
                bytes: image.observation_data,
            },
        ))
    }

    /// Transitions in the batch.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// Whether it has none.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }
}

impl TryFrom<TransitionBatch> for PreparedBatch {
    type Error = BatchError;

    /// Validates and encodes a batch made in this process (benchmarks,
    /// tests, an in-process actor).
    fn try_from(batch: TransitionBatch) -> Result<Self, BatchError> {
        ValidBatch::new(batch).map(Self::new)
    }
}

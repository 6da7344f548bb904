//! Bird's-eye grid observations: their geometry, channels, normalization and
//! writing into caller-provided buffers.
//!
//! An observation is a flat `f32` vector of [`ObsSpec::len`] values: a
//! channel-major grid `[channels][rows][cols]` ([`ObsSpec::index`]; the
//! grids and channels of [`ObsKind`]) followed by [`EGO_FEATURES`] dense ego
//! features. Cells without a car are 0 in every car channel, so grids are
//! sparse. A car is written into the one cell that holds its centre; if two
//! cars share a cell, the one written last (lanes in scenario order,
//! downstream cars first) wins. Cars outside the grid, and cars in cells the
//! sensor cannot see, are absent.
//!
//! The sizes are written here only: batches and networks carry them as a
//! `crossroads_types::ObservationLayout` ([`ObsSpec::layout`],
//! [`observation_layout`], which gives a view's layout by name,
//! [`OBSERVATION_KINDS`], without building an environment).

use crossroads_types::ObservationLayout;
use serde::{Deserialize, Serialize};

use crate::env::{Env, TTC_CAP_S};
use crate::error::SimError;
use crate::geometry::{Vec2, wrap_angle};

/// Rows of the TTG grid (north to south).
pub const TTG_ROWS: usize = 18;
/// Columns of the TTG grid (west to east).
pub const TTG_COLS: usize = 26;
/// West edge of the TTG grid, m.
pub const TTG_X_MIN: f64 = -104.0;
/// North edge of the TTG grid, m.
pub const TTG_Y_MAX: f64 = 18.0;
/// TTG cell size along x, m.
pub const TTG_CELL_X: f64 = 8.0;
/// TTG cell size along y, m.
pub const TTG_CELL_Y: f64 = 2.0;
/// Rows of the Sequential grid (nearest first).
pub const SEQ_ROWS: usize = 5;
/// Columns of the Sequential grid (left to right).
pub const SEQ_COLS: usize = 11;
/// Sequential cell size ahead, m (5 rows cover 0 to 20 m).
pub const SEQ_CELL_FWD: f64 = 4.0;
/// Half the lateral span of the Sequential grid, m.
pub const SEQ_HALF_LAT: f64 = 90.0;
/// Number of ego features after the grid: speed / speed limit; progress
/// from the stop line to the goal in [0, 1]; 1 once *go* was chosen; steps
/// taken / step limit.
pub const EGO_FEATURES: usize = 4;

/// Which grid an environment writes. Each grid's car channels are followed
/// by the occluded channel, when there is one ([`ObsSpec::occlusion`]), and
/// by the car's two offsets from its cell's centre.
///
/// The occupancy channel and the offsets are our additions to the paper's
/// channels. Occupancy, so that a stopped car is never all zeros. The
/// offsets (the paper gives them to its occlusion networks only) because a
/// TTG cell is 8 m long, 0.4 s at the speed limit: without them gaps within
/// that much of each other look the same (what they changed in training:
/// reports/paper/NOTES.md).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ObsKind {
    /// 18 x 26 grid fixed in the world: x from -104 to 104 m in 26 columns
    /// of 8 m (column 0 west), y from 18 to -18 m in 18 rows of 2 m (row 0
    /// north). Channels, without occlusion:
    ///
    /// | channel | value |
    /// | --- | --- |
    /// | 0 occupied | 1 |
    /// | 1 heading | heading / pi, in (-1, 1] (east 0, north 0.5, west 1) |
    /// | 2 speed | speed / scenario speed limit (20 m/s), about 0 to 1.3 |
    /// | 3 x offset | of the car's centre from its cell's centre, in cells, in [-0.5, 0.5) (east) |
    /// | 4 y offset | the same along y (north) |
    Ttg,
    /// 5 x 11 grid in the ego's frame from its sensor point (the middle of
    /// its front bumper): 5 rows of 4 m from 0 to 20 m ahead (row 0
    /// nearest), 11 columns of 180/11 m from 90 m left to 90 m right
    /// (column 0 leftmost). Channels: 0 occupied, 1 heading relative to the
    /// ego's / pi, 2 speed / speed limit, 3 time to collision
    /// ([`Env::car_ttc`]) / 10 s, capped at 1 (1 also for cars that will not
    /// meet the ego's path), then the car's x offset (ahead) and y offset
    /// (left) from its cell's centre in cells, in [-0.5, 0.5).
    Sequential,
}

/// Shape of an observation: a channel-major `channels x rows x cols` grid
/// followed by [`EGO_FEATURES`] dense ego features.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct ObsSpec {
    /// The grid.
    pub kind: ObsKind,
    /// Channels.
    pub channels: usize,
    /// Rows.
    pub rows: usize,
    /// Columns.
    pub cols: usize,
    /// Trailing dense ego features.
    pub ego_features: usize,
    /// Whether there is an occluded channel, when the scenario has
    /// occluders: 1 when the straight line from the sensor to the cell's
    /// centre crosses an occluder. It comes right after the car channels,
    /// before the two offsets (always the last two), as the paper lists the
    /// occlusion channels (occluded, x offset, y offset).
    pub occlusion: bool,
}

impl ObsSpec {
    /// Length of the grid part.
    pub fn grid_len(&self) -> usize {
        self.channels * self.rows * self.cols
    }

    /// Length of the whole flat observation.
    pub fn len(&self) -> usize {
        self.grid_len() + self.ego_features
    }

    /// Never empty; here for clippy's `len` convention.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// Flat index of grid value `(channel, row, col)`.
    pub fn index(&self, channel: usize, row: usize, col: usize) -> usize {
        (channel * self.rows + row) * self.cols + col
    }

    /// The view's name in [`OBSERVATION_KINDS`]: the grid's, with
    /// `-occlusion` when it has the occluded channel.
    pub fn name(&self) -> String {
        if self.occlusion {
            format!("{}-occlusion", self.kind.name())
        } else {
            self.kind.name().to_owned()
        }
    }

    /// The layout batches and networks carry for this shape.
    pub fn layout(&self) -> ObservationLayout {
        ObservationLayout::new(
            self.name(),
            self.channels as i64,
            self.rows as i64,
            self.cols as i64,
            self.ego_features as i64,
        )
    }
}

/// The observation views by name ([`ObsSpec::name`]): each grid with and
/// without the occluded channel.
pub const OBSERVATION_KINDS: [&str; 4] =
    ["ttg", "ttg-occlusion", "sequential", "sequential-occlusion"];

/// The shape of the view named `kind` (one of [`OBSERVATION_KINDS`]),
/// without building an environment.
pub fn observation_spec(kind: &str) -> Result<ObsSpec, SimError> {
    let (grid, occlusion) = match kind {
        "ttg" => (ObsKind::Ttg, false),
        "ttg-occlusion" => (ObsKind::Ttg, true),
        "sequential" => (ObsKind::Sequential, false),
        "sequential-occlusion" => (ObsKind::Sequential, true),
        other => {
            return Err(SimError::UnknownObservation {
                name: other.to_owned(),
                known: OBSERVATION_KINDS.join(", "),
            });
        }
    };
    Ok(grid.spec(occlusion))
}

/// The layout of the view named `kind` ([`observation_spec`]`.layout()`).
pub fn observation_layout(kind: &str) -> Result<ObservationLayout, SimError> {
    observation_spec(kind).map(|spec| spec.layout())
}

impl ObsKind {
    /// Car channels (before the occluded flag and the offsets).
    fn car_channels(self) -> usize {
        match self {
            Self::Ttg => 3,
            Self::Sequential => 4,
        }
    }

    /// The shape, with or without the occluded channel: the car channels,
    /// the occluded flag if `occlusion`, and the two offsets.
    pub fn spec(self, occlusion: bool) -> ObsSpec {
        let channels = self.car_channels() + usize::from(occlusion) + 2;
        let (rows, cols) = match self {
            Self::Ttg => (TTG_ROWS, TTG_COLS),
            Self::Sequential => (SEQ_ROWS, SEQ_COLS),
        };
        ObsSpec {
            kind: self,
            channels,
            rows,
            cols,
            ego_features: EGO_FEATURES,
            occlusion,
        }
    }

    /// Lower-case name.
    pub fn name(self) -> &'static str {
        match self {
            Self::Ttg => "ttg",
            Self::Sequential => "sequential",
        }
    }
}

/// A grid's frame: cell of a world point, and world centre of a cell.
#[derive(Debug, Clone, Copy)]
struct Frame {
    origin: Vec2,
    /// Unit vector along which `u` grows (column axis for TTG, forward for
    /// Sequential).
    u: Vec2,
    v: Vec2,
    kind: ObsKind,
}

impl Frame {
    fn of(env: &Env, kind: ObsKind) -> Self {
        match kind {
            ObsKind::Ttg => Self {
                origin: Vec2::default(),
                u: Vec2::new(1.0, 0.0),
                v: Vec2::new(0.0, 1.0),
                kind,
            },
            ObsKind::Sequential => {
                let f = env.ego_rect.axis;
                Self {
                    origin: env.sensor,
                    u: f,
                    v: f.perp(),
                    kind,
                }
            }
        }
    }

    /// `(row, col, offset along rows' axis, offset along columns' axis)`,
    /// offsets in cells from the cell centre, in `[-0.5, 0.5)`.
    fn cell(&self, p: Vec2) -> Option<(usize, usize, f64, f64)> {
        let d = p - self.origin;
        let (a, b) = (d.dot(self.u), d.dot(self.v));
        match self.kind {
            ObsKind::Ttg => {
                let c = (a - TTG_X_MIN) / TTG_CELL_X;
                let r = (TTG_Y_MAX - b) / TTG_CELL_Y;
                cell_of(r, c, TTG_ROWS, TTG_COLS)
            }
            ObsKind::Sequential => {
                let r = a / SEQ_CELL_FWD;
                let c = (SEQ_HALF_LAT - b) / (2.0 * SEQ_HALF_LAT / SEQ_COLS as f64);
                cell_of(r, c, SEQ_ROWS, SEQ_COLS)
            }
        }
    }

    fn center(&self, row: usize, col: usize) -> Vec2 {
        let (r, c) = (row as f64 + 0.5, col as f64 + 0.5);
        let (a, b) = match self.kind {
            ObsKind::Ttg => (TTG_X_MIN + c * TTG_CELL_X, TTG_Y_MAX - r * TTG_CELL_Y),
            ObsKind::Sequential => (
                r * SEQ_CELL_FWD,
                SEQ_HALF_LAT - c * (2.0 * SEQ_HALF_LAT / SEQ_COLS as f64),
            ),
        };
        self.origin + self.u * a + self.v * b
    }
}

/// The world geometry of an environment's observation grid, for drawing
/// it: which cell holds a point, and each cell's centre and corners. The
/// Sequential grid moves with the ego, so take a fresh one per state.
#[derive(Debug, Clone, Copy)]
pub struct GridGeometry {
    frame: Frame,
    spec: ObsSpec,
}

impl GridGeometry {
    /// The grid of kind `kind` for `env`'s current state.
    pub fn of(env: &Env, kind: ObsKind) -> Self {
        Self {
            frame: Frame::of(env, kind),
            spec: kind.spec(false),
        }
    }

    /// Rows and columns.
    pub fn shape(&self) -> (usize, usize) {
        (self.spec.rows, self.spec.cols)
    }

    /// `(row, col)` of the cell holding `p`, if `p` is on the grid.
    pub fn cell(&self, p: Vec2) -> Option<(usize, usize)> {
        self.frame.cell(p).map(|(r, c, _, _)| (r, c))
    }

    /// World centre of a cell.
    pub fn center(&self, row: usize, col: usize) -> Vec2 {
        self.frame.center(row, col)
    }

    /// World corners of a cell, in order around it.
    pub fn corners(&self, row: usize, col: usize) -> [Vec2; 4] {
        let c = self.frame.center(row, col);
        // Half a cell along the rows' axis and along the columns' axis.
        let (rows_axis, cols_axis) = match self.frame.kind {
            ObsKind::Ttg => (
                self.frame.v * (-0.5 * TTG_CELL_Y),
                self.frame.u * (0.5 * TTG_CELL_X),
            ),
            ObsKind::Sequential => (
                self.frame.u * (0.5 * SEQ_CELL_FWD),
                self.frame.v * (-SEQ_HALF_LAT / SEQ_COLS as f64),
            ),
        };
        [
            c - rows_axis - cols_axis,
            c - rows_axis + cols_axis,
            c + rows_axis + cols_axis,
            c + rows_axis - cols_axis,
        ]
    }
}

fn cell_of(r: f64, c: f64, rows: usize, cols: usize) -> Option<(usize, usize, f64, f64)> {
    if !(r >= 0.0 && c >= 0.0 && r < rows as f64 && c < cols as f64) {
        return None;
    }
    let (ri, ci) = (r.floor(), c.floor());
    Some((ri as usize, ci as usize, r - ri - 0.5, c - ci - 0.5))
}

/// Recomputes which cells of the environment's grid the sensor sees.
pub(crate) fn compute_visibility(env: &mut Env) {
    let kind = env.config().observation;
    let frame = Frame::of(env, kind);
    let spec = kind.spec(true);
    let sensor = env.sensor;
    let mut vis = std::mem::take(&mut env.cell_visible);
    let occluders = env.occluders();
    vis.resize(spec.rows * spec.cols, true);
    for row in 0..spec.rows {
        for col in 0..spec.cols {
            let p = frame.center(row, col);
            vis[row * spec.cols + col] = occluders.iter().all(|o| !o.intersects_segment(sensor, p));
        }
    }
    env.cell_visible = vis;
}

/// Where an observation's values go: a dense buffer, or a list of the
/// values written by index.
trait Sink {
    fn set(&mut self, index: usize, value: f32);
}

impl Sink for [f32] {
    fn set(&mut self, index: usize, value: f32) {
        self[index] = value;
    }
}

impl Sink for Vec<(u32, f32)> {
    fn set(&mut self, index: usize, value: f32) {
        // An observation is far below 2^32 values (the TTG grid's 2344).
        self.push((index as u32, value));
    }
}

/// Writes `env`'s observation of kind `kind` into `out`.
pub(crate) fn write(env: &Env, kind: ObsKind, out: &mut [f32]) -> Result<(), SimError> {
    let spec = kind.spec(env.scenario().occlusion_channels());
    if out.len() != spec.len() {
        return Err(SimError::BufferLength {
            expected: spec.len(),
            got: out.len(),
        });
    }
    out.fill(0.0);
    write_values(env, kind, out);
    Ok(())
}

/// Writes the non-zero values of `env`'s observation of kind `kind` into
/// `out` as `(index, value)` pairs in increasing index order: exactly the
/// values [`write`] leaves non-zero (of either sign of zero), without
/// touching the zeros, which are most of a grid.
pub(crate) fn write_sparse(env: &Env, kind: ObsKind, out: &mut Vec<(u32, f32)>) {
    out.clear();
    write_values(env, kind, out);
    // A cell written twice (two cars in it) holds the later car's values,
    // as in the dense buffer: a stable sort keeps the writes' order.
    out.sort_by_key(|&(i, _)| i);
    out.dedup_by(|later, earlier| {
        let same = later.0 == earlier.0;
        if same {
            *earlier = *later;
        }
        same
    });
    out.retain(|&(_, v)| v != 0.0);
}

/// Sets every value of the observation that may be non-zero; the caller
/// starts from zeros.
fn write_values<S: Sink + ?Sized>(env: &Env, kind: ObsKind, out: &mut S) {
    let sc = env.scenario();
    let spec = kind.spec(sc.occlusion_channels());
    let frame = Frame::of(env, kind);
    let cells = spec.rows * spec.cols;
    let base = kind.car_channels();
    let offsets = base + usize::from(spec.occlusion);
    if spec.occlusion {
        for (cell, &v) in env.cell_visible.iter().enumerate().take(cells) {
            if !v {
                out.set(base * cells + cell, 1.0);
            }
        }
    }
    let limit = sc.spec().speed_limit;
    let ego_heading = env.ego_rect.axis.y.atan2(env.ego_rect.axis.x);
    for car in env.traffic().cars() {
        let Some((row, col, dr, dc)) = frame.cell(car.pos) else {
            continue;
        };
        let cell = row * spec.cols + col;
        if spec.occlusion && !env.cell_visible[cell] {
            continue;
        }
        let heading = match kind {
            ObsKind::Ttg => wrap_angle(car.heading),
            ObsKind::Sequential => wrap_angle(car.heading - ego_heading),
        };
        out.set(cell, 1.0);
        out.set(cells + cell, (heading / std::f64::consts::PI) as f32);
        out.set(2 * cells + cell, (car.v / limit) as f32);
        if kind == ObsKind::Sequential {
            out.set(
                3 * cells + cell,
                (env.car_ttc(car).min(TTC_CAP_S) / TTC_CAP_S) as f32,
            );
        }
        // x offset along columns, y offset along rows, as in the docs.
        let (dx, dy) = match kind {
            ObsKind::Ttg => (dc, -dr),
            ObsKind::Sequential => (dr, -dc),
        };
        out.set(offsets * cells + cell, dx as f32);
        out.set((offsets + 1) * cells + cell, dy as f32);
    }
    let e = sc.spec();
    let ego = env.ego();
    let progress = (ego.s - e.ego.stop_line_s) / (e.ego.goal_s - e.ego.stop_line_s);
    let tail = spec.grid_len();
    out.set(tail, (ego.v / limit) as f32);
    out.set(tail + 1, progress.clamp(0.0, 1.0) as f32);
    out.set(tail + 2, if ego.committed { 1.0 } else { 0.0 });
    out.set(
        tail + 3,
        (f64::from(env.steps()) / f64::from(e.step_limit)) as f32,
    );
}

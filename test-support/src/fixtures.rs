//! Small data the tests of several crates build on.

use std::path::Path;

use crossroads_types::{ObservationEncoding, ObservationLayout, Transition, TransitionBatch};

/// Ten transitions over observations of `layout` (at least 30 values; the
/// simulator's TTG view, say, as `crossroads_sim::observation_layout`
/// gives it), five actions: rewards 0 to 9, actions `i % 5`, each
/// observation one cell on from the last.
pub fn toy_batch(layout: ObservationLayout) -> TransitionBatch {
    let len = layout.check().expect("a valid layout");
    assert!(len >= 30, "{layout} is too small for ten steps");
    let mut b = TransitionBatch::new(layout, 5, ObservationEncoding::SparseF32);
    let mut grid = vec![0.0; len];
    let mut current = b.push_observation(&grid);
    for i in 0..10 {
        grid[i * 3 + 2] = 1.0;
        let next = b.push_observation(&grid);
        b.push(Transition {
            observation: current,
            action: (i % 5) as u32,
            reward: i as f32,
            discount: 0.99,
            priority: 1.0,
            next_observation: next,
        });
        current = next;
    }
    b
}

/// What a kill -9 leaves on disk: a copy of folder `from` into `to`, the
/// files as they are now, taken while the process writing them runs.
pub fn crash_copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).expect("mkdir");
    for entry in std::fs::read_dir(from).expect("list") {
        let entry = entry.expect("entry");
        let target = to.join(entry.file_name());
        if entry.file_type().expect("type").is_dir() {
            crash_copy(&entry.path(), &target);
        } else {
            std::fs::copy(entry.path(), target).expect("copy");
        }
    }
}

//! Small data the tests of several crates build on.

use std::path::Path;

use crossroads_types::{ObservationEncoding, ObservationSpec, Transition, TransitionBatch};

/// Ten transitions over time-to-go observations, five actions: rewards 0
/// to 9, actions `i % 5`, each observation one cell on from the last.
pub fn toy_batch() -> TransitionBatch {
    let mut b = TransitionBatch::new(ObservationSpec::ttg(), 5, ObservationEncoding::SparseF32);
    let mut grid = vec![0.0; ObservationSpec::ttg().num_values().expect("a shape")];
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

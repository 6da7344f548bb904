//! The paper's published numbers, printed next to ours: Isele et al.,
//! "Navigating Occluded Intersections with Autonomous Vehicles using Deep
//! Reinforcement Learning", ICRA 2018 (Tables I-III).
//! Percentages are in percent, times in seconds.

/// The five scenarios of Tables I and III, in the paper's order.
pub const SCENARIOS: [&str; 5] = ["right", "left", "left2", "forward", "challenge"];

/// The scenarios of Figure 3 (the paper leaves Challenge out "for scale").
pub const FIG3_SCENARIOS: [&str; 4] = ["right", "left", "left2", "forward"];

/// The occluder lengths of Table II, in metres.
pub const OCCLUSION_LENGTHS: [u32; 3] = [30, 60, 90];

/// One method's line in Table I: success %, collision %, time s, brake s.
#[derive(Debug, Clone, Copy)]
pub struct PaperRow1 {
    pub success: f64,
    pub collision: f64,
    pub time: f64,
    pub brake: f64,
}

const fn r1(success: f64, collision: f64, time: f64, brake: f64) -> PaperRow1 {
    PaperRow1 {
        success,
        collision,
        time,
        brake,
    }
}

/// Table I per scenario (in [`SCENARIOS`] order): TTC, DQN-Sequential,
/// DQN-TTG.
pub const TABLE1: [[PaperRow1; 3]; 5] = [
    [
        r1(99.61, 0.0, 6.46, 0.31),
        r1(99.5, 0.47, 5.47, 0.88),
        r1(99.96, 0.04, 4.63, 0.45),
    ],
    [
        r1(99.7, 0.0, 6.97, 0.52),
        r1(99.99, 0.0, 5.26, 0.38),
        r1(99.99, 0.01, 5.24, 0.46),
    ],
    [
        r1(99.42, 0.0, 7.59, 0.21),
        r1(99.79, 0.11, 7.13, 0.22),
        r1(99.99, 0.01, 5.40, 0.20),
    ],
    [
        r1(99.91, 0.0, 6.19, 0.57),
        r1(99.76, 0.14, 4.40, 0.61),
        r1(99.78, 0.01, 4.63, 0.48),
    ],
    [
        r1(39.2, 0.0, 12.55, 1.65),
        r1(82.97, 1.37, 9.94, 1.94),
        r1(98.46, 0.84, 7.94, 1.98),
    ],
];

/// One method's line in Table II: success %, collision %, time s.
#[derive(Debug, Clone, Copy)]
pub struct PaperRow2 {
    pub success: f64,
    pub collision: f64,
    pub time: f64,
}

const fn r2(success: f64, collision: f64, time: f64) -> PaperRow2 {
    PaperRow2 {
        success,
        collision,
        time,
    }
}

/// Table II per occluder length (in [`OCCLUSION_LENGTHS`] order): TTC with
/// creep, DQN-TTG, DQN-Creep, DQN-Sequential.
pub const TABLE2: [[PaperRow2; 4]; 3] = [
    [
        r2(84.1, 0.0, 28.6),
        r2(70.7, 29.2, 12.0),
        r2(92.8, 7.1, 11.7),
        r2(92.6, 7.3, 9.6),
    ],
    [
        r2(83.1, 0.0, 28.9),
        r2(57.2, 36.65, 21.3),
        r2(92.9, 7.1, 16.0),
        r2(88.9, 11.05, 9.91),
    ],
    [
        r2(87.6, 0.0, 28.7),
        r2(26.3, 27.9, 30.8),
        r2(96.3, 3.7, 16.0),
        r2(86.2, 13.8, 10.25),
    ],
];

/// Table III: DQN-TTG success %, row = tested on, column = trained on
/// (both in [`SCENARIOS`] order).
pub const TABLE3: [[f64; 5]; 5] = [
    [99.0, 98.5, 81.1, 98.1, 74.1],
    [87.7, 96.3, 76.8, 95.1, 66.2],
    [70.1, 76.3, 91.7, 74.5, 74.6],
    [87.2, 97.2, 79.0, 97.6, 69.9],
    [58.7, 60.7, 72.3, 62.4, 78.5],
];

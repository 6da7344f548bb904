//! Derivation of per-episode seeds, so results depend on the base seed and
//! the trial index only, never on how trials are spread over threads.

/// One round of splitmix64, a bijective 64-bit mixer.
pub fn splitmix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// Seed of the environment of trial `index` under base seed `base`.
pub fn episode_seed(base: u64, index: u64) -> u64 {
    splitmix64(base ^ splitmix64(index))
}

/// Seed of the policy's random stream in trial `index`.
pub fn policy_seed(base: u64, index: u64) -> u64 {
    splitmix64(episode_seed(base, index) ^ 0x5EED_0FF0_11C7)
}

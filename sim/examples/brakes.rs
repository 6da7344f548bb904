//! Where does baseline braking happen? Histogram of braking car positions.
use crossroads_sim::{Scenario, Traffic};
use rand::SeedableRng;
fn main() {
    let mut spec = Scenario::builtin(&std::env::args().nth(1).unwrap_or("challenge".into())).unwrap().spec().clone();
    spec.traffic.brake_threshold = std::env::args().nth(2).and_then(|t| t.parse().ok()).unwrap_or(2.0);
    let sc = Scenario::compile(spec).unwrap();
    let mut t = Traffic::new(&sc);
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(1);
    let mut hist = [0u32; 31];
    let mut total = 0u64;
    let steps = 20000;
    for _ in 0..steps {
        t.step(&sc, &[], &mut rng);
        for c in t.cars() {
            total += 1;
            if c.braking {
                hist[((c.s / 10.0) as usize).min(30)] += 1;
            }
        }
    }
    println!("car-steps {total}, braking per 10 m bin: {hist:?}");
    println!("brake s per 20 s episode: {:.2}", t.brake_time_s() / (steps as f64 * 0.2) * 20.0);
}

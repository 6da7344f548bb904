use crossroads_sim::*;
use rand::SeedableRng;
fn main() {
    let mut spec = Scenario::builtin("challenge").unwrap().spec().clone();
    if let Some(t) = std::env::args().nth(1).and_then(|t| t.parse().ok()) { spec.traffic.headway = t; }
    if let Some(t) = std::env::args().nth(2).and_then(|t| t.parse().ok()) { spec.traffic.speed_factor_dev = t; }
    let sc = Scenario::compile(spec).unwrap();
    let mut t = Traffic::new(&sc);
    let mut rng = rand_xoshiro::Xoshiro256PlusPlus::seed_from_u64(11);
    let mut seen = std::collections::HashSet::new();
    for step in 0..25000 {
        t.step(&sc, &[], &mut rng);
        seen.extend(t.cars().map(|c| c.id));
        if step % 5000 == 0 {
            let l = t.lane(0);
            let speeds: Vec<String> = l.iter().rev().take(6).map(|c| format!("{:.1}@{:.0}", c.v, c.s)).collect();
            println!("step {step}: emitted {} cars {} lane0 n={} upstream {:?}", seen.len(), t.len(), l.len(), speeds);
        }
    }
}

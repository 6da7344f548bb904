use std::sync::Arc;
use crossroads_sim::*;
fn main() {
    let sc = Arc::new(Scenario::builtin("left").unwrap());
    println!("{:?}", sc.lanes()[0].zone);
    let mut env = Env::new(sc.clone(), EnvConfig::for_actions(ActionSet::Sequential));
    env.clear_traffic();
    // Car 16.7 m before lane_in at 15.8 m/s.
    let z = sc.lanes()[0].zone.unwrap();
    env.place_car(0, z.lane_in - 16.7, 15.8).unwrap();
    for _ in 0..12 {
        let r = env.step(0).unwrap();
        let c = env.traffic().cars().next().unwrap();
        println!("ego s {:.2} v {:.2} | foe {:?} | car s {:.2} v {:.2} y {} b {} {:?}", env.ego().s, env.ego().v, env.foes()[0], c.s, c.v, c.yielding, c.braking, r.outcome);
    }
}

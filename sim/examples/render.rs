//! Writes SVG frames of one episode: `render <scenario> <seed> <out-dir>`,
//! driven by TTC with creep (ttc-creep:3) on the Creep-and-Go action set,
//! one frame per decision (the final *go* is one transition).

use std::sync::Arc;

use crossroads_sim::{
    ActionSet, Env, EnvConfig, Policy, PolicyRng, RenderView, Scenario, TtcPolicy, render_svg,
};
use rand::SeedableRng;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("occluded-60", String::as_str);
    let seed: u64 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(1);
    let dir = std::path::PathBuf::from(args.get(3).map_or("frames", String::as_str));
    std::fs::create_dir_all(&dir)?;
    let sc = Arc::new(Scenario::load(name)?);
    let mut env = Env::new(sc, EnvConfig::for_actions(ActionSet::Creep));
    env.reset(seed);
    let policy = TtcPolicy::new(3.0, true);
    let mut rng = [PolicyRng::seed_from_u64(seed)];
    let view = RenderView::default();
    let mut frame = 0;
    loop {
        std::fs::write(dir.join(format!("{frame:04}.svg")), render_svg(&env, &view))?;
        if env.is_done() {
            break;
        }
        let mut a = [0];
        policy.act(std::slice::from_ref(&env), &mut rng, &mut a)?;
        env.step(a[0])?;
        frame += 1;
    }
    println!(
        "{} frames in {}, outcome {:?}",
        frame + 1,
        dir.display(),
        env.outcome()
    );
    Ok(())
}

//! `crossroads eval`, `tune-ttc` and `bench sim` as a user runs them.

/// Whether `crossroads args` succeeded, its standard output and error.
fn crossroads(args: &[&str]) -> (bool, String, String) {
    let out = crate::crossroads().output(args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn eval_json(threads: &str) -> serde_json::Value {
    let set = format!("runtime.compute_threads={threads}");
    let (ok, stdout, stderr) = crossroads(&[
        "--set",
        &set,
        "eval",
        "--policy",
        "ttc:3",
        "--scenario",
        "left",
        "--trials",
        "300",
        "--seed",
        "11",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    serde_json::from_str(&stdout).expect("one JSON object")
}

#[test]
fn eval_json_has_the_documented_fields_and_ignores_thread_count() {
    let one = eval_json("1");
    for field in [
        "scenario",
        "policy",
        "trials",
        "success_rate",
        "collision_rate",
        "timeout_rate",
        "mean_time_s",
        "mean_brake_s",
        "mean_brake_light_s",
        "mean_wait_s",
        "mean_go_offset_m",
        "mean_go_speed",
    ] {
        assert!(one.get(field).is_some(), "{field} missing: {one}");
    }
    assert_eq!(one["scenario"], "left");
    assert_eq!(one["policy"], "ttc:3");
    assert_eq!(one["trials"], 300);
    let rates: f64 = ["success_rate", "collision_rate", "timeout_rate"]
        .iter()
        .map(|f| one[f].as_f64().expect("rate"))
        .sum();
    assert!(
        (rates - 1.0).abs() < 1e-9,
        "rates are fractions summing to 1: {one}"
    );

    let mut two = eval_json("2");
    let mut one = one;
    for v in [&mut one, &mut two] {
        v.as_object_mut().expect("object").remove("wall_seconds");
    }
    assert_eq!(one, two, "same seed, same result on 1 and 2 threads");
}

#[test]
fn eval_rejects_bad_input_with_a_clear_error() {
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "ttc:-2"]);
    assert!(!ok);
    assert!(stderr.contains("ttc:-2"), "{stderr}");
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "random", "--scenario", "roundabout"]);
    assert!(!ok);
    assert!(stderr.contains("roundabout"), "{stderr}");
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "random", "--actions", "fly"]);
    assert!(!ok);
    assert!(stderr.contains("fly"), "{stderr}");
}

#[test]
fn eval_risk_bins_every_go_and_names_the_riskiest_trials() {
    let args = [
        "eval",
        "--policy",
        "random",
        "--scenario",
        "left",
        "--trials",
        "300",
        "--seed",
        "4",
        "--risk",
        "6",
    ];
    let (ok, stdout, stderr) = crossroads(&[&args[..], &["--json"]].concat());
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    let risk = &v["risk"];
    assert_eq!(risk["futures"], 6, "{v}");
    let bins = risk["bins"].as_array().expect("bins");
    let sum = |field: &str| -> u64 { bins.iter().map(|b| b[field].as_u64().expect("count")).sum() };
    assert_eq!(
        sum("decisions"),
        risk["decisions"].as_u64().expect("decisions")
    );
    let collisions = (v["collision_rate"].as_f64().expect("rate") * 300.0).round() as u64;
    assert!(collisions > 0, "a random policy collides: {v}");
    assert_eq!(
        sum("collisions") + risk["other_collisions"].as_u64().expect("other"),
        collisions,
        "every collision is counted once: {v}"
    );
    let riskiest = risk["riskiest"].as_array().expect("riskiest");
    assert!(!riskiest.is_empty() && riskiest.len() <= 20, "{v}");
    assert_eq!(
        riskiest[0]["collided"], true,
        "collided trials come first: {v}"
    );

    // The text names the first riskiest trial the way render takes it.
    let (ok, text, stderr) = crossroads(&args);
    assert!(ok, "{stderr}");
    let first = format!("--seed 4 --trial {} ", riskiest[0]["trial"]);
    assert!(text.contains("P(collision | state, go)"), "{text}");
    assert!(text.contains(&first), "{first} in\n{text}");

    let (ok, _, stderr) = crossroads(&[
        "eval",
        "--policy",
        "random",
        "--actions",
        "sequential",
        "--risk",
        "4",
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("sequential action set has none"),
        "{stderr}"
    );
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "random", "--risk", "0"]);
    assert!(!ok);
    assert!(stderr.contains("--risk"), "{stderr}");
}

#[test]
fn eval_missed_counts_the_chances_a_policy_passes_up() {
    // Never going times out every trial of Left; each passed up a gap.
    let args = [
        "eval",
        "--policy",
        "never",
        "--scenario",
        "left",
        "--trials",
        "40",
        "--seed",
        "2",
        "--risk",
        "4",
        "--missed",
    ];
    let (ok, stdout, stderr) = crossroads(&[&args[..], &["--json"]].concat());
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    let m = &v["risk"]["missed"];
    assert_eq!(m["timeouts"], 40, "{v}");
    let with_chance = m["timeouts_with_chance"].as_u64().expect("count");
    assert!(with_chance >= 35, "{v}");
    let first = &m["passed_up"][0];
    let (ok, text, stderr) = crossroads(&args);
    assert!(ok, "{stderr}");
    assert!(
        text.contains(&format!("timeouts 40 of which {with_chance} passed up")),
        "{text}"
    );
    let shown = format!(
        "--seed 2 --trial {:<6} --step {}",
        first["trial"].as_u64().expect("trial"),
        first["step"]
    );
    assert!(text.contains(&shown), "{shown} in\n{text}");
    // Without --risk there are no futures to probe in.
    let (ok, _, stderr) = crossroads(&["eval", "--policy", "never", "--missed"]);
    assert!(!ok);
    assert!(stderr.contains("--risk"), "{stderr}");
}

#[test]
fn eval_failures_names_trials_that_render_draws_failing() {
    // 200 trials of seed 3 listing two failures of each kind.
    let eval_failures = |extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--policy",
            "random",
            "--scenario",
            "left",
            "--trials",
            "200",
            "--seed",
            "3",
            "--failures",
            "2",
        ];
        args.extend_from_slice(extra);
        crossroads(&args)
    };
    let (ok, stdout, stderr) = eval_failures(&["--json"]);
    assert!(ok, "{stderr}");
    let eval: serde_json::Value = serde_json::from_str(&stdout).expect("json");
    let listed = |kind: &str| eval["failures"][kind].as_array().expect(kind).clone();
    let (collisions, timeouts) = (listed("collisions"), listed("timeouts"));
    let count = |rate: &str| (eval[rate].as_f64().expect(rate) * 200.0).round() as usize;
    assert_eq!(collisions.len(), count("collision_rate").min(2), "{eval}");
    assert_eq!(timeouts.len(), count("timeout_rate").min(2), "{eval}");
    assert!(!collisions.is_empty(), "a random policy collides: {eval}");

    // The first listed collision is the episode render draws as one.
    let trial = collisions[0][0].as_u64().expect("trial").to_string();
    let at = collisions[0][1].as_f64().expect("time");
    let dir = tempfile::tempdir().expect("temp dir");
    let png = dir.path().join("collision.png");
    let (ok, drawn, stderr) = crossroads(&[
        "render",
        "--policy",
        "random",
        "--scenario",
        "left",
        "--seed",
        "3",
        "--trial",
        &trial,
        "--out",
        png.to_str().expect("utf-8 path"),
    ]);
    assert!(ok, "{stderr}");
    assert!(
        drawn.contains(&format!("collision after {at:.1} s")),
        "{drawn} vs trial {trial} at {at}"
    );

    let (ok, text, stderr) = eval_failures(&[]);
    assert!(ok, "{stderr}");
    assert!(
        text.contains(&format!(
            "--seed 3 --trial {trial:<6} collided at {at:.1} s"
        )),
        "{text}"
    );
    let (ok, _, stderr) = crossroads(&[
        "eval",
        "--policy",
        "random",
        "--risk",
        "2",
        "--failures",
        "1",
    ]);
    assert!(!ok && stderr.contains("--failures"), "{stderr}");
}

#[test]
fn eval_shield_stops_a_reckless_policy_colliding_and_counts_its_vetoes() {
    // ttc:0 goes at once whatever comes; behind the shield it must wait
    // for a gap the shield accepts.
    let eval = |extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--policy",
            "ttc:0",
            "--scenario",
            "left",
            "--trials",
            "300",
            "--seed",
            "3",
            "--json",
        ];
        args.extend_from_slice(extra);
        let (ok, stdout, stderr) = crossroads(&args);
        assert!(ok, "{stderr}");
        serde_json::from_str::<serde_json::Value>(&stdout).expect("json")
    };
    let bare = eval(&[]);
    let shielded = eval(&["--shield"]);
    assert!(bare["collision_rate"].as_f64().unwrap() > 0.05, "{bare}");
    assert_eq!(shielded["collision_rate"].as_f64(), Some(0.0), "{shielded}");
    assert_eq!(shielded["policy"], "ttc:0+shield");
    let counts = &shielded["shield"]["counts"];
    let vetoes = counts["vetoes"].as_u64().unwrap();
    assert!(vetoes > 0, "{counts}");
    let by_kind: u64 = ["crossing", "ahead", "behind"]
        .iter()
        .map(|k| counts[k].as_u64().unwrap())
        .sum();
    assert_eq!(by_kind, vetoes, "{counts}");
    assert_eq!(
        shielded["shield"]["assumptions"]["gap_m"].as_f64(),
        Some(0.5)
    );
    // Overrides reach the assumptions; bad ones are named.
    let wider = eval(&["--shield", "gap_m=2"]);
    assert_eq!(wider["shield"]["assumptions"]["gap_m"].as_f64(), Some(2.0));
    for (bad, named) in [("wings=2", "wings"), ("gap_m=x", "gap_m")] {
        let (ok, _, stderr) = crossroads(&[
            "eval",
            "--policy",
            "ttc:0",
            "--scenario",
            "left",
            "--trials",
            "1",
            "--shield",
            bad,
        ]);
        assert!(
            !ok && stderr.contains("--shield") && stderr.contains(named),
            "{stderr}"
        );
    }
    let (ok, _, stderr) = crossroads(&[
        "eval",
        "--policy",
        "ttc:1",
        "--actions",
        "sequential",
        "--trials",
        "1",
        "--shield",
    ]);
    assert!(!ok && stderr.contains("ttg or creep"), "{stderr}");

    // render draws the phantoms and names a veto in its summary.
    let dir = tempfile::tempdir().expect("temp dir");
    let png = dir.path().join("shield.png");
    let (ok, drawn, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc:0",
        "--scenario",
        "left",
        "--seed",
        "3",
        "--trial",
        "0",
        "--shield",
        "--out",
        png.to_str().expect("utf-8 path"),
    ]);
    assert!(ok, "{stderr}");
    assert!(drawn.contains("the shield vetoed"), "{drawn}");
}

#[test]
fn tune_ttc_writes_csv_and_png() {
    let dir = tempfile::tempdir().expect("temp dir");
    let out = dir.path().to_str().expect("utf-8");
    let (ok, stdout, stderr) = crossroads(&[
        "tune-ttc",
        "--scenario",
        "right",
        "--trials",
        "100",
        "--thresholds",
        "0.5,2,6",
        "--out",
        out,
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("threshold"), "{stdout}");
    let csv = std::fs::read_to_string(dir.path().join("tune-ttc-right.csv")).expect("csv");
    let rows: Vec<Vec<&str>> = csv.lines().map(|l| l.split(',').collect()).collect();
    assert_eq!(rows[0][0], "threshold_s");
    assert_eq!(rows[0].last(), Some(&"mean_brake_light_s"), "{csv}");
    assert_eq!(rows.len(), 4, "header and three thresholds: {csv}");
    let thresholds: Vec<f64> = rows[1..]
        .iter()
        .map(|r| r[0].parse().expect("number"))
        .collect();
    assert_eq!(thresholds, vec![0.5, 2.0, 6.0]);
    let png = std::fs::read(dir.path().join("tune-ttc-right.png")).expect("png");
    assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "a real PNG");
}

#[test]
fn bench_sim_prints_measured_figures() {
    let (ok, stdout, stderr) = crossroads(&["bench", "sim", "--seconds", "0.1", "--json"]);
    assert!(ok, "{stderr}");
    let figures: serde_json::Value = serde_json::from_str(&stdout).expect("JSON");
    let figures = figures.as_array().expect("one entry per scenario");
    assert!(figures.iter().any(|f| f["scenario"] == "left"));
    for f in figures {
        assert!(
            f["decisions_per_s"].as_f64().is_some_and(|d| d > 0.0),
            "{f}"
        );
        assert!(f["steps_per_s"].as_f64().is_some_and(|d| d > 0.0), "{f}");
    }
}

/// Width and height from a PNG's IHDR chunk.
fn png_size(bytes: &[u8]) -> (u32, u32) {
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "not a PNG");
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    (be(16), be(20))
}

#[test]
fn render_gif_animates_the_same_episode_eval_plays() {
    let dir = tempfile::tempdir().expect("temp dir");
    let gif = dir.path().join("nested/left.gif");
    let gif_arg = gif.to_str().expect("utf-8 path");
    let (ok, stdout, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc:3",
        "--scenario",
        "left",
        "--seed",
        "5",
        "--grid",
        "--speed",
        "4",
        "--out",
        gif_arg,
    ]);
    assert!(ok, "{stderr}");
    // Trial 0 of seed 5 is what eval plays as its first trial.
    let (ok, eval, stderr) = crossroads(&[
        "eval",
        "--policy",
        "ttc:3",
        "--scenario",
        "left",
        "--seed",
        "5",
        "--trials",
        "1",
        "--json",
    ]);
    assert!(ok, "{stderr}");
    let eval: serde_json::Value = serde_json::from_str(&eval).expect("json");
    assert!(stdout.contains("success after"), "{stdout}");

    let mut decoder = gif::DecodeOptions::new()
        .read_info(std::fs::File::open(&gif).expect("gif written"))
        .expect("a GIF");
    // The wide view (220 m x 55 m at 5 px/m) that the grid needs.
    assert_eq!((decoder.width(), decoder.height()), (1100, 275));
    let mut frames = 0;
    let mut delays = Vec::new();
    while let Some(frame) = decoder.read_next_frame().expect("frame") {
        frames += 1;
        delays.push(frame.delay);
    }
    // One frame before the first step and one per 0.2 s step.
    let printed: usize = stdout
        .split('(')
        .nth(2)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|n| n.parse().ok())
        .unwrap_or_else(|| panic!("frame count in {stdout}"));
    assert_eq!(frames, printed);
    let time_s: f64 = stdout
        .split("after ")
        .nth(1)
        .and_then(|s| s.split_whitespace().next())
        .and_then(|t| t.parse().ok())
        .unwrap_or_else(|| panic!("time in {stdout}"));
    assert_eq!(frames, (time_s / 0.2).round() as usize + 1);
    // 0.2 s per step at 4x speed: 50 ms, in GIF's 10 ms units.
    assert!(delays.iter().all(|&d| d == 5), "{delays:?}");
    assert_eq!(eval["success_rate"], 1.0, "{eval}");
    let eval_time = eval["mean_time_s"].as_f64().expect("time of the success");
    assert!(
        (eval_time - time_s).abs() < 0.051,
        "{eval_time} vs {time_s}"
    );
}

#[test]
fn render_png_and_svg_draw_one_moment() {
    let dir = tempfile::tempdir().expect("temp dir");
    let png = dir.path().join("right.png");
    let (ok, stdout, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc:3",
        "--scenario",
        "right",
        "--seed",
        "1",
        "--trial",
        "2",
        "--step",
        "3",
        "--out",
        png.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("(1 frame)"), "{stdout}");
    let bytes = std::fs::read(&png).expect("png written");
    // The default view: 120 m x 50 m at 8 px/m.
    assert_eq!(png_size(&bytes), (960, 400));

    let svg = dir.path().join("occluded.svg");
    let (ok, _, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc-creep:3",
        "--actions",
        "creep",
        "--scenario",
        "occluded-60",
        "--grid",
        "--out",
        svg.to_str().expect("utf-8"),
    ]);
    assert!(ok, "{stderr}");
    let text = std::fs::read_to_string(&svg).expect("svg written");
    assert!(text.starts_with("<svg"), "{}", &text[..80.min(text.len())]);
    assert!(text.contains("occluded"), "caption missing");
    // 18 x 26 grid cells plus roads, cars, obstacles and the ego.
    // Every grid cell is outlined (filled cells are polygons as well).
    assert!(
        text.matches("<polyline").count() >= 18 * 26,
        "no grid overlay"
    );
}

#[test]
fn render_rejects_bad_requests_clearly() {
    let dir = tempfile::tempdir().expect("temp dir");
    let bmp = dir.path().join("x.bmp");
    let (ok, _, stderr) = crossroads(&[
        "render",
        "--policy",
        "random",
        "--out",
        bmp.to_str().expect("utf-8"),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("unknown picture format \"bmp\""),
        "{stderr}"
    );
    let png = dir.path().join("x.png");
    let (ok, _, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc:3",
        "--step",
        "5000",
        "--out",
        png.to_str().expect("utf-8"),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("--step 5000: the episode ended at step"),
        "{stderr}"
    );
    assert!(!png.exists(), "nothing written on error");
    let (ok, _, stderr) = crossroads(&[
        "render",
        "--policy",
        "ttc-creep:3",
        "--actions",
        "ttg",
        "--out",
        png.to_str().expect("utf-8"),
    ]);
    assert!(!ok);
    assert!(
        stderr.contains("--policy ttc-creep:3 with --actions ttg"),
        "{stderr}"
    );
}

#[test]
fn eval_takes_a_networks_own_action_set_unless_told_another() {
    let net = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/reports/paper/runs/creep-occluded/best"
    );
    let args = [
        "eval",
        "--policy",
        net,
        "--scenario",
        "occluded-60",
        "--trials",
        "20",
        "--seed",
        "3",
    ];
    let (ok, stdout, stderr) = crossroads(&[&args[..], &["--json"]].concat());
    assert!(ok, "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).expect("one JSON object");
    assert_eq!(v["actions"], "creep", "{v}");
    assert_eq!(v["trials"], 20, "{v}");
    let (ok, _, stderr) = crossroads(&[&args[..], &["--actions", "ttg"]].concat());
    assert!(!ok);
    assert!(
        stderr.contains("with --actions ttg") && stderr.contains("trained for creep actions"),
        "{stderr}"
    );
}

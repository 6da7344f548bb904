//! Rendering of an episode's current state as an SVG picture, for people
//! and for `crossroads render`. No dependencies: SVG is text.

use std::fmt::Write;

use crate::env::Env;
use crate::geometry::{OrientedRect, Vec2};

/// What part of the world to draw, and how large.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RenderView {
    /// West edge, m.
    pub x_min: f64,
    /// East edge, m.
    pub x_max: f64,
    /// South edge, m.
    pub y_min: f64,
    /// North edge, m.
    pub y_max: f64,
    /// Pixels per metre.
    pub scale: f64,
}

impl Default for RenderView {
    /// 120 m x 50 m around the intersection at 8 px/m.
    fn default() -> Self {
        Self {
            x_min: -60.0,
            x_max: 60.0,
            y_min: -25.0,
            y_max: 25.0,
            scale: 8.0,
        }
    }
}

/// The environment's current state as an SVG document: lanes (grey), the
/// ego's path (dashed) and stop line, occluders (dark grey), traffic (green
/// when the ego sees it, yellow when hidden, outlined red while braking),
/// the ego (blue), and the step and outcome.
pub fn render_svg(env: &Env, view: &RenderView) -> String {
    let w = (view.x_max - view.x_min) * view.scale;
    let h = (view.y_max - view.y_min) * view.scale;
    let px = |p: Vec2| {
        (
            (p.x - view.x_min) * view.scale,
            (view.y_max - p.y) * view.scale,
        )
    };
    let mut out = String::with_capacity(16 * 1024);
    // Writing to a String cannot fail.
    let _ = writeln!(
        out,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{w:.0}" height="{h:.0}" viewBox="0 0 {w:.0} {h:.0}">"#
    );
    let _ = writeln!(
        out,
        r##"<rect width="100%" height="100%" fill="#e8efe0"/>"##
    );
    let sc = env.scenario();
    let lane_px = 3.5 * view.scale;
    for lane in sc.lanes() {
        let pts = polyline(&lane.path, 0.0, lane.path.length(), &px);
        let _ = writeln!(
            out,
            r##"<polyline points="{pts}" fill="none" stroke="#9a9a9a" stroke-width="{lane_px:.1}"/>"##
        );
    }
    let ego_spec = &sc.spec().ego;
    let half = 0.5 * ego_spec.params.length;
    let ego_path = polyline(sc.ego_path(), 0.0, sc.ego_path().length(), &px);
    let _ = writeln!(
        out,
        r##"<polyline points="{ego_path}" fill="none" stroke="#9a9a9a" stroke-width="{lane_px:.1}"/>"##
    );
    let route = polyline(
        sc.ego_path(),
        ego_spec.stop_line_s - half,
        ego_spec.goal_s - half,
        &px,
    );
    let _ = writeln!(
        out,
        r##"<polyline points="{route}" fill="none" stroke="#3060c0" stroke-width="1.5" stroke-dasharray="6 4"/>"##
    );
    let stop = sc.ego_path().pose_at(ego_spec.stop_line_s - half);
    let across = Vec2::from_angle(stop.heading).perp() * 1.75;
    let front = stop.pos + Vec2::from_angle(stop.heading) * half;
    let (a, b) = (px(front + across), px(front - across));
    let _ = writeln!(
        out,
        r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="white" stroke-width="3"/>"##,
        a.0, a.1, b.0, b.1
    );
    for o in env.occluders() {
        rect(&mut out, o, "#505050", "none", &px);
    }
    let tp = &sc.spec().traffic;
    for car in env.traffic().cars() {
        let fill = if env.is_visible(car.pos) {
            "#30a040"
        } else {
            "#e0c020"
        };
        let stroke = if car.braking { "#d02020" } else { "none" };
        rect(&mut out, &car.rect(tp.length, tp.width), fill, stroke, &px);
    }
    rect(&mut out, &env.ego_footprint(), "#2050d0", "none", &px);
    let status = match env.outcome() {
        Some(o) => format!("{o:?}"),
        None => String::from("running"),
    };
    let _ = writeln!(
        out,
        r#"<text x="8" y="20" font-family="monospace" font-size="14">{} step {} t={:.1}s ego v={:.1} m/s {}</text>"#,
        sc.name(),
        env.steps(),
        env.metrics().time_s,
        env.ego().v,
        status
    );
    out.push_str("</svg>\n");
    out
}

fn polyline(
    path: &crate::path::Path,
    from: f64,
    to: f64,
    px: &impl Fn(Vec2) -> (f64, f64),
) -> String {
    let n = ((to - from) / 1.0).ceil().max(1.0) as usize;
    let mut s = String::new();
    for i in 0..=n {
        let (x, y) = px(path.pose_at(from + (to - from) * i as f64 / n as f64).pos);
        let _ = write!(s, "{x:.1},{y:.1} ");
    }
    s
}

fn rect(
    out: &mut String,
    r: &OrientedRect,
    fill: &str,
    stroke: &str,
    px: &impl Fn(Vec2) -> (f64, f64),
) {
    let mut pts = String::new();
    for c in r.corners() {
        let (x, y) = px(c);
        let _ = write!(pts, "{x:.1},{y:.1} ");
    }
    let _ = writeln!(
        out,
        r#"<polygon points="{pts}" fill="{fill}" stroke="{stroke}" stroke-width="2"/>"#
    );
}

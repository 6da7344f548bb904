//! What a picture of an episode's state shows, as plain data: a [`Scene`]
//! of coloured polygons and lines in pixel coordinates plus a caption.
//! Drawing it (PNG, animated GIF, SVG) is the caller's business;
//! `crossroads_draw` draws scenes with plotters. Keeping the sim
//! free of drawing libraries keeps it small and lets tests check a scene's
//! content directly.

use crate::env::Env;
use crate::geometry::{OrientedRect, Vec2};
use crate::observation::{GridGeometry, ObsKind};

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

impl RenderView {
    /// A view wide enough for the whole TTG grid (x from -104 to 104 m)
    /// and for the occluders of the paper's family, at 5 px/m.
    pub fn wide() -> Self {
        Self {
            x_min: -110.0,
            x_max: 110.0,
            y_min: -30.0,
            y_max: 25.0,
            scale: 5.0,
        }
    }

    /// Picture size in pixels.
    pub fn size(&self) -> (u32, u32) {
        let w = ((self.x_max - self.x_min) * self.scale).round().max(1.0);
        let h = ((self.y_max - self.y_min) * self.scale).round().max(1.0);
        (w as u32, h as u32)
    }

    /// Pixel position of a world point (y grows downwards in pixels).
    pub fn px(&self, p: Vec2) -> (f64, f64) {
        (
            (p.x - self.x_min) * self.scale,
            (self.y_max - p.y) * self.scale,
        )
    }
}

/// An RGB colour with opacity.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Color {
    /// Red.
    pub r: u8,
    /// Green.
    pub g: u8,
    /// Blue.
    pub b: u8,
    /// Opacity, 0 (transparent) to 1.
    pub alpha: f64,
}

impl Color {
    const fn rgb(r: u8, g: u8, b: u8) -> Self {
        Self {
            r,
            g,
            b,
            alpha: 1.0,
        }
    }

    const fn with_alpha(self, alpha: f64) -> Self {
        Self { alpha, ..self }
    }
}

/// The palette, so that legends and tests can name the colours.
pub mod palette {
    use super::Color;

    /// Background (grass).
    pub const BACKGROUND: Color = Color::rgb(0xe8, 0xef, 0xe0);
    /// Road surface.
    pub const ROAD: Color = Color::rgb(0x9a, 0x9a, 0x9a);
    /// Obstacles that block the view.
    pub const OBSTACLE: Color = Color::rgb(0x50, 0x50, 0x50);
    /// Cars the ego's sensor sees.
    pub const VISIBLE_CAR: Color = Color::rgb(0x30, 0xa0, 0x40);
    /// Cars hidden from the ego's sensor.
    pub const OCCLUDED_CAR: Color = Color::rgb(0xe0, 0xc0, 0x20);
    /// Outline of a car that is braking.
    pub const BRAKING: Color = Color::rgb(0xd0, 0x20, 0x20);
    /// The ego.
    pub const EGO: Color = Color::rgb(0x20, 0x50, 0xd0);
    /// The ego's route from the stop line to the goal, and the stop line.
    pub const ROUTE: Color = Color::rgb(0x30, 0x60, 0xc0);
    /// Stop line.
    pub const STOP_LINE: Color = Color::rgb(0xff, 0xff, 0xff);
    /// Grid lines of the observation overlay.
    pub const GRID: Color = Color::rgb(0x20, 0x20, 0x60).with_alpha(0.35);
    /// Overlay cells the observation marks occupied.
    pub const GRID_OCCUPIED: Color = Color::rgb(0x30, 0x60, 0xe0).with_alpha(0.35);
    /// Overlay cells the sensor cannot see.
    pub const GRID_OCCLUDED: Color = Color::rgb(0x20, 0x20, 0x20).with_alpha(0.25);
    /// Outline of a phantom car (the shield's assumption).
    pub const PHANTOM: Color = Color::rgb(0x80, 0x20, 0xa0);
    /// Outline of the car for which the shield vetoed a *go*.
    pub const THREAT: Color = Color::rgb(0xe0, 0x20, 0xc0);
    /// Caption text.
    pub const TEXT: Color = Color::rgb(0x10, 0x10, 0x10);
}

/// What a [`Shape`] is, so that tests and legends can count by meaning.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Layer {
    /// Lanes and the ego's road.
    Road,
    /// Stop line and route.
    Marking,
    /// Observation grid overlay.
    Grid,
    /// Occluders.
    Obstacle,
    /// A traffic car the sensor sees.
    VisibleCar,
    /// A traffic car hidden from the sensor.
    OccludedCar,
    /// The ego.
    Ego,
    /// A car the safety shield assumes where the ego cannot see
    /// ([`crate::sense`]).
    Phantom,
    /// The car for which the shield vetoed a *go* ([`crate::Threat`]).
    Threat,
}

/// One thing to draw, in pixel coordinates.
#[derive(Debug, Clone, PartialEq)]
pub enum Shape {
    /// A closed polygon, filled and optionally outlined.
    Polygon {
        /// What it shows.
        layer: Layer,
        /// Corners in pixels.
        points: Vec<(f64, f64)>,
        /// Fill colour.
        fill: Color,
        /// Outline colour and width in pixels.
        stroke: Option<(Color, f64)>,
    },
    /// An open polyline.
    Line {
        /// What it shows.
        layer: Layer,
        /// Points in pixels.
        points: Vec<(f64, f64)>,
        /// Colour.
        color: Color,
        /// Width in pixels.
        width: f64,
        /// Dashed rather than solid.
        dashed: bool,
    },
}

impl Shape {
    /// What the shape shows.
    pub fn layer(&self) -> Layer {
        match self {
            Self::Polygon { layer, .. } | Self::Line { layer, .. } => *layer,
        }
    }
}

/// Options of [`Scene::of`].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SceneOptions {
    /// Overlay this observation grid: cell lines, cells the observation
    /// marks occupied, and (in occlusion scenarios) cells the sensor cannot
    /// see.
    pub grid: Option<ObsKind>,
}

/// A picture of one state: shapes in drawing order (background first) and
/// a one-line caption.
#[derive(Debug, Clone, PartialEq)]
pub struct Scene {
    /// Size in pixels.
    pub size: (u32, u32),
    /// Background colour.
    pub background: Color,
    /// Shapes, back to front.
    pub shapes: Vec<Shape>,
    /// Scenario, step, time, ego speed and outcome.
    pub caption: String,
}

impl Scene {
    /// The scene of `env`'s current state: lanes, the ego's route and stop
    /// line, occluders (gray), traffic (green when the ego's sensor sees
    /// it, yellow when hidden, outlined red while braking), the ego (blue),
    /// and optionally the observation grid.
    pub fn of(env: &Env, view: &RenderView, options: &SceneOptions) -> Self {
        let mut shapes = Vec::with_capacity(64);
        let px = |p: Vec2| view.px(p);
        let sc = env.scenario();
        let lane_px = 3.5 * view.scale;
        for lane in sc.lanes() {
            shapes.push(Shape::Line {
                layer: Layer::Road,
                points: polyline(&lane.path, 0.0, lane.path.length(), &px),
                color: palette::ROAD,
                width: lane_px,
                dashed: false,
            });
        }
        let ego_spec = &sc.spec().ego;
        let half = 0.5 * ego_spec.params.length;
        shapes.push(Shape::Line {
            layer: Layer::Road,
            points: polyline(sc.ego_path(), 0.0, sc.ego_path().length(), &px),
            color: palette::ROAD,
            width: lane_px,
            dashed: false,
        });
        shapes.push(Shape::Line {
            layer: Layer::Marking,
            points: polyline(
                sc.ego_path(),
                ego_spec.stop_line_s - half,
                ego_spec.goal_s - half,
                &px,
            ),
            color: palette::ROUTE,
            width: 1.5,
            dashed: true,
        });
        let stop = sc.ego_path().pose_at(ego_spec.stop_line_s - half);
        let along = Vec2::from_angle(stop.heading);
        let front = stop.pos + along * half;
        let across = along.perp() * 1.75;
        shapes.push(Shape::Line {
            layer: Layer::Marking,
            points: vec![px(front + across), px(front - across)],
            color: palette::STOP_LINE,
            width: 3.0,
            dashed: false,
        });
        if let Some(kind) = options.grid {
            grid_overlay(env, kind, &px, &mut shapes);
        }
        for o in env.occluders() {
            shapes.push(rect(Layer::Obstacle, o, palette::OBSTACLE, None, &px));
        }
        let tp = &sc.spec().traffic;
        for car in env.traffic().cars() {
            let (layer, fill) = if env.is_visible(car.pos) {
                (Layer::VisibleCar, palette::VISIBLE_CAR)
            } else {
                (Layer::OccludedCar, palette::OCCLUDED_CAR)
            };
            let stroke = car.braking.then_some((palette::BRAKING, 2.0));
            shapes.push(rect(
                layer,
                &car.rect(tp.length, tp.width),
                fill,
                stroke,
                &px,
            ));
        }
        shapes.push(rect(
            Layer::Ego,
            &env.ego_footprint(),
            palette::EGO,
            None,
            &px,
        ));
        let status = match env.outcome() {
            Some(o) => format!("{o:?}").to_lowercase(),
            None => String::from("running"),
        };
        let caption = format!(
            "{}  step {}  t = {:.1} s  ego {:.1} m/s  {}",
            sc.name(),
            env.steps(),
            env.metrics().time_s,
            env.ego().v,
            status
        );
        Self {
            size: view.size(),
            background: palette::BACKGROUND,
            shapes,
            caption,
        }
    }

    /// Adds what the safety shield considered at this state: its phantom
    /// cars as dashed outlines, and when it vetoed a *go*, the car it
    /// feared outlined and named in the caption.
    pub fn mark_shield(
        &mut self,
        env: &Env,
        view: &RenderView,
        cars: &[crate::shield::SensedCar],
        threat: Option<&crate::shield::Threat>,
    ) {
        let sc = env.scenario();
        let tp = &sc.spec().traffic;
        let px = |p: Vec2| view.px(p);
        let outline = |car: &crate::shield::SensedCar| {
            let pose = sc.lanes()[car.lane].path.pose_at(car.s - 0.5 * tp.length);
            let r = OrientedRect::new(pose.pos, pose.heading, tp.length, tp.width);
            let mut points: Vec<_> = r.corners().into_iter().map(px).collect();
            points.push(points[0]);
            points
        };
        for car in cars.iter().filter(|c| c.phantom) {
            self.shapes.push(Shape::Line {
                layer: Layer::Phantom,
                points: outline(car),
                color: palette::PHANTOM,
                width: 2.0,
                dashed: true,
            });
        }
        if let Some(t) = threat {
            self.shapes.push(Shape::Line {
                layer: Layer::Threat,
                points: outline(&t.car),
                color: palette::THREAT,
                width: 3.0,
                dashed: false,
            });
            self.caption += &format!(
                "  shield: go vetoed ({} {} on {}, {:.1} s)",
                if t.car.phantom { "phantom" } else { "car" },
                t.kind.name(),
                sc.lanes()[t.car.lane].name,
                t.after_s
            );
        }
    }

    /// Number of shapes on `layer`.
    pub fn count(&self, layer: Layer) -> usize {
        self.shapes.iter().filter(|s| s.layer() == layer).count()
    }
}

/// Grid lines of every cell, blue cells where a visible car's centre lies
/// (what the observation's occupancy channel holds), and dark cells the
/// sensor cannot see (when the scenario has occluders).
fn grid_overlay(
    env: &Env,
    kind: ObsKind,
    px: &impl Fn(Vec2) -> (f64, f64),
    shapes: &mut Vec<Shape>,
) {
    let grid = GridGeometry::of(env, kind);
    let (rows, cols) = grid.shape();
    let occlusion = !env.occluders().is_empty();
    let mut occupied = vec![false; rows * cols];
    for car in env.traffic().cars() {
        if let Some((r, c)) = grid.cell(car.pos)
            && (!occlusion || env.is_visible(grid.center(r, c)))
        {
            occupied[r * cols + c] = true;
        }
    }
    for r in 0..rows {
        for c in 0..cols {
            let fill = if occupied[r * cols + c] {
                palette::GRID_OCCUPIED
            } else if occlusion && !env.is_visible(grid.center(r, c)) {
                palette::GRID_OCCLUDED
            } else {
                palette::GRID.with_alpha(0.0)
            };
            shapes.push(Shape::Polygon {
                layer: Layer::Grid,
                points: grid.corners(r, c).into_iter().map(px).collect(),
                fill,
                stroke: Some((palette::GRID, 1.0)),
            });
        }
    }
}

fn polyline(
    path: &crate::path::Path,
    from: f64,
    to: f64,
    px: &impl Fn(Vec2) -> (f64, f64),
) -> Vec<(f64, f64)> {
    let n = ((to - from) / 1.0).ceil().max(1.0) as usize;
    (0..=n)
        .map(|i| px(path.pose_at(from + (to - from) * i as f64 / n as f64).pos))
        .collect()
}

fn rect(
    layer: Layer,
    r: &OrientedRect,
    fill: Color,
    stroke: Option<(Color, f64)>,
    px: &impl Fn(Vec2) -> (f64, f64),
) -> Shape {
    Shape::Polygon {
        layer,
        points: r.corners().into_iter().map(px).collect(),
        fill,
        stroke,
    }
}

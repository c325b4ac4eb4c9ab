//! What the planner reports besides the motion: unreachable targets (each with the reason),
//! per-region reach and coverage, the plan's measured quality, and the samples that came too
//! near the part or a solid ([`Collision`]: its body, obstacle and the kind of segment it lies
//! in, [`SegmentKind`], which the plan's segments carry).
use std::fmt;

use serde::{Deserialize, Serialize};

/// A planned contact point the arm cannot reach or follow; it is left out of the motion.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct UnreachablePoint {
    /// Region id.
    pub region: usize,
    /// Depth layer.
    pub layer: usize,
    /// Stroke index within the region's strokes.
    pub stroke: usize,
    /// Point index within the stroke.
    pub point: usize,
    /// Surface point, reference frame, mm.
    pub surface_mm: [f64; 3],
    /// Requested tool tip, robot frame, m.
    pub tip_m: [f64; 3],
    /// Why.
    pub reason: String,
}

impl fmt::Display for UnreachablePoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let [x, y, z] = self.surface_mm;
        // a contact the removal planner lifted over belongs to no stroke (usize::MAX)
        let stroke = match self.stroke {
            usize::MAX => String::new(),
            s => format!(" stroke {s}"),
        };
        write!(
            f,
            "region {} layer {}{stroke} point {} at ({x:.2}, {y:.2}, {z:.2}) mm: {}",
            self.region, self.layer, self.point, self.reason
        )
    }
}

/// Reach and coverage of one region.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RegionReport {
    /// Region id.
    pub id: usize,
    /// Whether regions.json marks it repairable (only those are planned).
    pub repairable: bool,
    /// Peak distance, mm.
    pub peak_mm: f64,
    /// regions.json says the peak is a lower bound (read by a single point pair): the layers
    /// reach down to it, and the defect may stand higher (inspect again after grinding).
    /// Absent in plans from before 2026-12-01: false.
    #[serde(default)]
    pub peak_lower_bound: bool,
    /// regions.json says the region touches an unmeasured area (a hole or the scan's border):
    /// its peak and area are lower bounds. Absent in plans from before 2026-12-02: false.
    #[serde(default)]
    pub touches_unmeasured: bool,
    /// Area, mm^2.
    pub area_mm2: f64,
    /// Depth layers planned.
    pub layers: usize,
    /// Planned contact points (all layers).
    pub path_points: usize,
    /// Of those, unreachable or not followable (left out).
    pub unreachable_path_points: usize,
    /// Core points of the region (deviations.csv rows).
    pub points: usize,
    /// Core points where the tool can be placed (tip on the normal, axis within the cone).
    pub reachable_points: usize,
    /// Share of the region's area the arm cannot reach (1 - reachable / points).
    pub unreachable_share: f64,
    /// Share of the reachable core points within the tool footprint of a planned stroke.
    pub coverage_of_reachable: f64,
    /// Share of all core points within the tool footprint of a planned stroke.
    pub coverage_of_all: f64,
    /// The setup (fixturing, 1 first) the region is planned in; absent in a cell with one
    /// setup.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub setup: Option<usize>,
    /// The library tool (plan.json `tools[].tool`) the region is ground with; absent in a
    /// cell with one tool.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tool: Option<String>,
}

/// The reachability report of plan.json.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Reachability {
    /// Per region, in regions.json order.
    pub regions: Vec<RegionReport>,
    /// Every planned contact point left out, with the reason.
    pub unreachable: Vec<UnreachablePoint>,
    /// Places where a stroke was split because consecutive IK solutions jumped.
    pub jumps: usize,
    /// Removal mode: contacts the removal's limits (`removal::cap`) lifted over at the
    /// preload's depth that are ground commanded shallower instead (`soften`), counted on
    /// each region's first dwell solve. Absent: none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub softened: usize,
    /// Removal mode: contacts the removal's limits lift over even commanded shallower, on the
    /// same solves. Absent: none.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub lifted: usize,
}

/// Whether a count is zero (serde's `skip_serializing_if`).
fn is_zero(n: &usize) -> bool {
    *n == 0
}

impl Reachability {
    /// Ids of the regions the plan grinds (at least one layer planned), in report order.
    pub fn planned_ids(&self) -> Vec<usize> {
        (self.regions.iter())
            .filter(|r| r.layers > 0)
            .map(|r| r.id)
            .collect()
    }
}

/// Quality of the plan, measured on the sampled trajectory through the robot model.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Time of the last sample, s.
    pub predicted_duration_s: f64,
    /// Contact points in the motion.
    pub path_points: usize,
    /// Joint samples.
    pub samples: usize,
    /// Worst tool-tip error from servo resolution (half a raw count per servo) over all
    /// samples, mm.
    pub resolution_error_max_mm: f64,
    /// Mean of the same, mm.
    pub resolution_error_mean_mm: f64,
    /// Largest distance from a grinding sample's modelled tool tip (FK) to the planned path, mm.
    pub sample_to_path_max_mm: f64,
    /// Largest distance from a planned path point to the modelled tool-tip path (FK of the
    /// samples), mm.
    pub path_to_samples_max_mm: f64,
    /// The feed asked for, mm/s.
    pub feed_mm_s: f64,
    /// Slowest modelled tool-tip speed over cruise samples of grinding strokes, mm/s.
    pub cruise_feed_min_mm_s: f64,
    /// Fastest modelled tool-tip speed over cruise samples, mm/s.
    pub cruise_feed_max_mm_s: f64,
    /// Strokes whose cruise speed the joint limits held below the feed.
    pub slowed_strokes: usize,
    /// Share of grinding time spent at cruise speed.
    pub cruise_share: f64,
}

/// What a stretch of samples does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SegmentKind {
    /// Rest-to-rest move between home and approach / retract points.
    Transit,
    /// Down the normal onto the first contact point.
    Approach,
    /// Along a pass at constant feed.
    Grind,
    /// Up the normal off the last contact point.
    Retract,
    /// At rest between strokes: down one depth step, or a change of tool tilt.
    Reorient,
    /// Removal mode: along the normal between touching the surface and the preload depth
    /// (in before the first contact of a run, out after its last), under the grinding rule.
    Press,
}

/// A moving body.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Body {
    /// The burr's ball.
    Ball,
    /// The burr's shank.
    Shank,
    /// The link after actuated joint `i` (0-based).
    Link(usize),
}

impl fmt::Display for Body {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Body::Ball => write!(f, "tool ball"),
            Body::Shank => write!(f, "tool shank"),
            Body::Link(i) => write!(f, "link after joint {}", i + 1),
        }
    }
}

/// What a body came too near.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Obstacle {
    /// The part at a reference point (index into deviations.csv's rows, position mm).
    Part {
        /// Row index.
        point: usize,
        /// Position, reference frame, mm.
        at_mm: [f64; 3],
    },
    /// A second face of the part inside the ball, its normal `angle_deg` from the first.
    SecondFace {
        /// Row index.
        point: usize,
        /// Position, reference frame, mm.
        at_mm: [f64; 3],
        /// Angle between the two faces' normals, degrees.
        angle_deg: f64,
    },
    /// A fixed solid.
    Solid(String),
}

/// A body nearer an obstacle than allowed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Hit {
    /// The moving body.
    pub body: Body,
    /// What it came near.
    pub obstacle: Obstacle,
    /// Its clearance, mm (negative: inside).
    pub clearance_mm: f64,
}

impl fmt::Display for Hit {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.obstacle {
            Obstacle::Part { point, at_mm: [x, y, z] } => write!(
                f,
                "{} and the part at reference point {point} ({x:.2}, {y:.2}, {z:.2}) mm: clearance {:.3} mm",
                self.body, self.clearance_mm
            ),
            Obstacle::SecondFace { point, at_mm: [x, y, z], angle_deg } => write!(
                f,
                "{} touches a second face at reference point {point} ({x:.2}, {y:.2}, {z:.2}) mm, normals {angle_deg:.0} deg apart: tool does not fit",
                self.body
            ),
            Obstacle::Solid(name) => write!(
                f,
                "{} and solid {name:?}: clearance {:.3} mm",
                self.body, self.clearance_mm
            ),
        }
    }
}

/// One sample too near the part or a solid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Collision {
    /// Sample index.
    pub sample: usize,
    /// Index of the segment it belongs to (the later one at a joint of two).
    pub segment: Option<usize>,
    /// That segment's kind.
    pub kind: Option<SegmentKind>,
    /// That segment's region.
    pub region: Option<usize>,
    /// The colliding pair.
    pub hit: Hit,
}

impl fmt::Display for Collision {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "sample {}", self.sample)?;
        if let (Some(s), Some(k)) = (self.segment, self.kind) {
            write!(f, " (segment {s}, {k:?}")?;
            if let Some(r) = self.region {
                write!(f, ", region {r}")?;
            }
            write!(f, ")")?;
        }
        write!(f, ": {}", self.hit)
    }
}

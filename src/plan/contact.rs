//! What a sample of a plan does and what it came too near: the leaf types that the collision
//! model, the program, the whole-trajectory check and the planner's errors share (so none of
//! those files imports another in a circle).
use std::fmt;

use serde::{Deserialize, Serialize};

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

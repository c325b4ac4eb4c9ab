//! The virtual part: surface points with outward normals that move inward as the true law
//! removes material under the simulated tool.
use nalgebra::{Point3, Vector3};

use super::law::{preston_rate, Contact, KField};
use super::GrindConfig;
use crate::spatial::Neighbours;

/// Extra distance beyond the ball radius at which the nearest surface point is still looked
/// at, mm: the ball is out of contact farther than that, and the query stays cheap.
const CONTACT_SEARCH_MARGIN_MM: f64 = 0.5;

/// Surface points whose heights under the ball give the penetration (their median): one
/// stray point (an outlier that lies near the surface, a normal across an edge) among them
/// cannot press the ball; 9 is a 3 x 3 patch of scan points, 0.15 mm across at synth's
/// density, far under the smallest contact patch.
pub const PENETRATION_NEIGHBOURS: usize = 9;

/// A part being ground, reference frame, mm.
pub struct VirtualPart {
    points: Vec<Point3<f64>>,
    normals: Vec<Vector3<f64>>,
    removal: Vec<f64>,
    k: Vec<f64>,
    index: Neighbours,
}

/// The state of the tool at one step, reference frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ToolState {
    /// Ball centre, mm.
    pub centre: Point3<f64>,
    /// Spindle axis, unit (shank to tip).
    pub axis: Vector3<f64>,
    /// Velocity of the ball centre, mm/s.
    pub velocity: Vector3<f64>,
}

impl VirtualPart {
    /// A part of `points` with outward unit `normals` (same length), true k from `cfg`.
    pub fn new(points: Vec<Point3<f64>>, normals: Vec<Vector3<f64>>, cfg: &GrindConfig) -> Self {
        assert_eq!(points.len(), normals.len(), "one normal per point");
        let field = KField::new(cfg);
        let k = points.iter().map(|p| field.at(p)).collect();
        let index = Neighbours::new(&points);
        VirtualPart {
            removal: vec![0.0; points.len()],
            points,
            normals,
            k,
            index,
        }
    }

    /// Removal so far per point, mm (along the inward normal).
    pub fn removal(&self) -> &[f64] {
        &self.removal
    }

    /// The true k per point, mm^2/N.
    pub fn true_k(&self) -> &[f64] {
        &self.k
    }

    /// The outward normals.
    pub fn normals(&self) -> &[Vector3<f64>] {
        &self.normals
    }

    /// Surface point `i` now (moved inward by its removal), mm.
    pub fn current(&self, i: usize) -> Point3<f64> {
        self.points[i] - self.normals[i] * self.removal[i]
    }

    /// The surface now, every point.
    pub fn current_points(&self) -> Vec<Point3<f64>> {
        (0..self.points.len()).map(|i| self.current(i)).collect()
    }

    /// Penetration of the ball into the surface now, mm: the ball radius minus the centre's
    /// height above the surface, the median over the nearest [`PENETRATION_NEIGHBOURS`]
    /// points of the height above each one's tangent plane (negative: no contact); None when
    /// no point is near. Returns the index of the median point too (its normal is the
    /// contact's).
    pub fn penetration(&self, centre: &Point3<f64>, ball_mm: f64) -> Option<(usize, f64)> {
        let near = self.index.nearest(centre)?;
        let reach = ball_mm + CONTACT_SEARCH_MARGIN_MM;
        if near.dist2 > reach * reach {
            return None;
        }
        let mut heights: Vec<(f64, usize)> = self
            .index
            .knn(centre, PENETRATION_NEIGHBOURS)
            .into_iter()
            .map(|nb| {
                let i = nb.index;
                (self.normals[i].dot(&(centre - self.current(i))), i)
            })
            .collect();
        heights.sort_by(|a, b| a.0.total_cmp(&b.0));
        let (height, i) = heights[heights.len() / 2];
        Some((i, ball_mm - height))
    }

    /// Grinds for `dt` seconds with the tool at `tool`: the spring force from the penetration,
    /// the Hertz patch centred under the ball, and at every point inside it the true Preston
    /// rate at its pressure and its speed relative to the turning ball. Returns the contact.
    pub fn grind_step(&mut self, tool: &ToolState, dt: f64, cfg: &GrindConfig) -> Option<Contact> {
        let (i, depth) = self.penetration(&tool.centre, cfg.ball_radius_mm)?;
        let contact = Contact::hertz(
            depth,
            cfg.spring_rate_n_mm,
            cfg.ball_radius_mm,
            cfg.modulus_mpa,
        )?;
        let n = self.normals[i];
        let below = self.current(i);
        // patch centre: the ball centre's foot on the tangent plane of the nearest point
        let centre = tool.centre - n * n.dot(&(tool.centre - below));
        let omega = tool.axis * cfg.spindle_rpm * std::f64::consts::TAU / 60.0;
        let reach = contact.radius_mm + CONTACT_SEARCH_MARGIN_MM;
        for nb in self.index.within_unsorted(&centre, reach) {
            let j = nb.index;
            let d = self.current(j) - centre;
            let r = (d - n * n.dot(&d)).norm();
            let p = contact.pressure(r);
            if p <= 0.0 {
                continue;
            }
            // surface speed of the ball where it touches point j, plus the feed: the spring
            // takes the penetration, so the ball keeps its radius (its pole is R below the
            // centre along the normal, the patch point offset across it)
            let across = d - n * n.dot(&d);
            let arm = across
                - n * (cfg.ball_radius_mm * cfg.ball_radius_mm - across.norm_squared())
                    .max(0.0)
                    .sqrt();
            let v = (omega.cross(&arm) + tool.velocity).norm();
            self.removal[j] += preston_rate(self.k[j], p, v, cfg) * dt;
        }
        Some(contact)
    }
}

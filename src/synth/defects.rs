//! Surface defects of known shape: bumps, pits and ridges with a Gaussian cross-section.
//! Heights are signed along the outward normal: + is material in excess.
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

/// Full width at half maximum of a Gaussian, in standard deviations.
const FWHM_PER_SIGMA: f64 = 2.354_820_045_030_949;

/// Defect shapes.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum DefectKind {
    /// Round raised spot.
    Bump,
    /// Round depression (negative height).
    Pit,
    /// Raised line segment.
    Ridge,
}

/// One defect in the reference frame (mm).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Defect {
    /// Index in the truth list.
    pub id: usize,
    /// Shape.
    pub kind: DefectKind,
    /// Centre on the nominal surface.
    pub centre: [f64; 3],
    /// Outward unit normal of the surface at the centre.
    pub normal: [f64; 3],
    /// Signed peak height along the normal (mm); negative for pits.
    pub height: f64,
    /// Full width at half maximum across the defect (mm).
    pub width: f64,
    /// Ridge direction (unit, tangent to the surface); zero for bumps and pits.
    pub direction: [f64; 3],
    /// Ridge length between the end centres (mm); zero for bumps and pits.
    pub length: f64,
}

impl Defect {
    /// Distance from `p` to the defect's core (its centre or its ridge segment).
    fn core_distance(&self, p: &Point3<f64>) -> f64 {
        let c = Point3::from(self.centre);
        let d = p - c;
        if self.kind != DefectKind::Ridge {
            return d.norm();
        }
        let dir = Vector3::from(self.direction);
        let t = d.dot(&dir).clamp(-self.length / 2.0, self.length / 2.0);
        (d - dir * t).norm()
    }

    /// Standard deviation of the Gaussian cross-section.
    pub fn sigma(&self) -> f64 {
        self.width / FWHM_PER_SIGMA
    }

    /// Radius beyond which the displacement is below 1e-6 of the peak.
    pub fn support(&self) -> f64 {
        5.3 * self.sigma() + self.length / 2.0
    }

    /// Signed displacement along the outward normal at surface point `p` whose outward normal
    /// is `n`: the Gaussian profile of the core distance; zero on surfaces facing away
    /// (normal more than 60 degrees off the defect's).
    pub fn displacement(&self, p: &Point3<f64>, n: &Vector3<f64>) -> f64 {
        if n.dot(&Vector3::from(self.normal)) < 0.5 {
            return 0.0;
        }
        let r = self.core_distance(p);
        let s = self.sigma();
        self.height * (-(r * r) / (2.0 * s * s)).exp()
    }
}

/// Sum of all defects' displacements at a surface point (the true deviation there).
pub fn deviation_at(defects: &[Defect], p: &Point3<f64>, n: &Vector3<f64>) -> f64 {
    defects.iter().map(|d| d.displacement(p, n)).sum()
}

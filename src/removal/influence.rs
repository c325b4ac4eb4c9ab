//! The tool influence function (Preston: removal depth rate = k x pressure x relative speed
//! over the contact patch) and the matrix A of removal per second of dwell at every core point
//! from every contact point. Method: docs/ALGORITHMS.md, "Removal planning".
use nalgebra::{Point3, Vector3};

use super::tool::ToolModel;
use crate::spatial::Neighbours;

/// Sub-samples along a contact point's piece of stroke when A is built: the tool moves over
/// the piece during its dwell, so its column is the influence averaged over the piece. 8 keeps
/// the discretisation error under 0.5 % of the peak at a spacing of a third of the patch
/// radius (the closed-form test in tests/removal.rs).
const SUBSAMPLES: usize = 8;
/// Smallest cosine between a core point's normal and a contact's for the contact to grind it:
/// cos 60 degrees. A patch of under 1 mm cannot reach a second face at a sharper angle.
const SAME_FACE_COS: f64 = 0.5;
/// The pressure model over the patch.
#[derive(Debug, Clone, PartialEq)]
enum Pressure {
    /// Hertz: p0 sqrt(1 - r^2 / a^2), MPa, patch radius a mm.
    Hertz { p0: f64, a: f64 },
    /// Measured radial profile, scaled to the force: (r mm, p MPa) rows.
    Table(Vec<[f64; 2]>),
}

/// The removal rate of the tool at a point of its contact patch.
#[derive(Debug, Clone, PartialEq)]
pub struct Influence {
    pressure: Pressure,
    /// Ball radius, mm.
    ball_mm: f64,
    /// Spindle speed, rad/s.
    omega: f64,
    /// Preston coefficient, mm^2/N.
    k: f64,
    /// Radius of the placement stencil's ring, mm: `sqrt(3)` times the tool's
    /// `placement_sd_mm` (0: the patch lands where the model puts it).
    ring_mm: f64,
}

/// Weight of the placement stencil's centre (1/3); the rest is spread evenly over four points
/// on a ring of radius `sqrt(3) sd` along the patch's two axes, which gives the stencil the
/// placement's variance, `sd^2`, along each axis and no mean shift: the removal's footprint
/// widens by exactly that variance and keeps its volume (the unit test below).
const STENCIL_CENTRE: f64 = 1.0 / 3.0;

impl Influence {
    /// The influence of `tool` with a ball of radius `ball_mm`.
    pub fn new(tool: &ToolModel, ball_mm: f64) -> Self {
        let force = tool.force_n();
        let pressure = match &tool.influence_table {
            None => {
                // Hertz, sphere on a rigid flat: a = (3 F R / (4 E*))^(1/3), p0 = 3 F / (2 pi a^2)
                let a = (3.0 * force * ball_mm / (4.0 * tool.modulus_mpa)).cbrt();
                let p0 = 3.0 * force / (std::f64::consts::TAU * a * a);
                Pressure::Hertz { p0, a }
            }
            Some(rows) => {
                // integral of p(r) 2 pi r dr over each linear piece, exactly
                let integral: f64 = rows
                    .windows(2)
                    .map(|w| {
                        let ([r0, p0], [r1, p1]) = (w[0], w[1]);
                        let h = r1 - r0;
                        let slope = (p1 - p0) / h;
                        let c = p0 - slope * r0;
                        std::f64::consts::TAU
                            * (c * (r1 * r1 - r0 * r0) / 2.0
                                + slope * (r1.powi(3) - r0.powi(3)) / 3.0)
                    })
                    .sum();
                let scale = force / integral;
                Pressure::Table(rows.iter().map(|&[r, p]| [r, p * scale]).collect())
            }
        };
        Influence {
            pressure,
            ball_mm,
            omega: tool.omega(),
            k: tool.preston_k_mm2_n,
            ring_mm: (2.0 / (1.0 - STENCIL_CENTRE)).sqrt() * tool.placement_sd_mm,
        }
    }

    /// The influence under `ratio` times the preload's force ([`Contact::force_ratio`]):
    /// Hertz's patch radius and peak pressure both grow as `ratio^(1/3)` (the force, the peak
    /// times the radius squared, as `ratio`); a measured table is scaled by `ratio` at its
    /// measured shape (measured at one force, its radii are kept: the pressure still
    /// integrates to the force, the patch does not grow).
    pub fn at_force(&self, ratio: f64) -> Influence {
        let pressure = match &self.pressure {
            Pressure::Hertz { p0, a } => {
                let grow = ratio.cbrt();
                Pressure::Hertz {
                    p0: p0 * grow,
                    a: a * grow,
                }
            }
            Pressure::Table(rows) => {
                Pressure::Table(rows.iter().map(|&[r, p]| [r, p * ratio]).collect())
            }
        };
        Influence {
            pressure,
            ball_mm: self.ball_mm,
            omega: self.omega,
            k: self.k,
            ring_mm: self.ring_mm,
        }
    }

    /// Radius of the ball, mm.
    pub fn ball_mm(&self) -> f64 {
        self.ball_mm
    }

    /// Radius of the contact patch, mm: outside it the pressure is zero.
    pub fn patch_radius(&self) -> f64 {
        match &self.pressure {
            Pressure::Hertz { a, .. } => *a,
            Pressure::Table(rows) => rows.last().map_or(0.0, |r| r[0]),
        }
    }

    /// Radius of the contact patch under `ratio` times the preload's force, mm.
    pub fn patch_radius_at(&self, ratio: f64) -> f64 {
        match &self.pressure {
            Pressure::Hertz { a, .. } => a * ratio.cbrt(),
            Pressure::Table(_) => self.patch_radius(),
        }
    }

    /// How far from a contact's centre its removal reaches under `ratio` times the preload's
    /// force, mm: the patch radius and the placement stencil's ring.
    pub fn reach_at(&self, ratio: f64) -> f64 {
        self.patch_radius_at(ratio) + self.ring_mm
    }

    /// Contact pressure at `r` mm from the patch centre, MPa (N/mm^2).
    pub fn pressure(&self, r: f64) -> f64 {
        match &self.pressure {
            Pressure::Hertz { p0, a } => p0 * (1.0 - (r / a).powi(2)).max(0.0).sqrt(),
            Pressure::Table(rows) => {
                let i = rows.partition_point(|row| row[0] <= r);
                if i == 0 || i == rows.len() {
                    return if i == 0 { rows[0][1] } else { 0.0 };
                }
                let ([r0, p0], [r1, p1]) = (rows[i - 1], rows[i]);
                p0 + (p1 - p0) * (r - r0) / (r1 - r0)
            }
        }
    }

    /// Relative speed of the abrasive at patch offset (x, y) mm, mm/s: x runs along the
    /// tilt direction. The ball spins at omega about an axis through its centre, tilted by
    /// `tilt` from the normal; the speed is omega times the distance from that axis.
    pub fn speed(&self, x: f64, y: f64, tilt: Tilt) -> f64 {
        // the ball's surface point over (x, y), relative to its centre (flat patch)
        let w = Vector3::new(x, y, -self.ball_mm);
        let axis = Vector3::new(tilt.sin, 0.0, -tilt.cos);
        let along = w.dot(&axis);
        self.omega * (w.norm_squared() - along * along).max(0.0).sqrt()
    }

    /// [`Influence::rate`] where the patch lands with the tool's placement scatter
    /// (`placement_sd_mm`): the mean over the placement stencil ([`STENCIL_CENTRE`]).
    pub fn placed_rate(&self, x: f64, y: f64, tilt: Tilt) -> f64 {
        if self.ring_mm == 0.0 {
            return self.rate(x, y, tilt);
        }
        let (r, side) = (self.ring_mm, 0.25 * (1.0 - STENCIL_CENTRE));
        STENCIL_CENTRE * self.rate(x, y, tilt)
            + side
                * [(r, 0.0), (-r, 0.0), (0.0, r), (0.0, -r)]
                    .iter()
                    .map(|(dx, dy)| self.rate(x - dx, y - dy, tilt))
                    .sum::<f64>()
    }

    /// Removal depth rate at patch offset (x, y) mm under a spindle tilted by `tilt`, mm/s.
    pub fn rate(&self, x: f64, y: f64, tilt: Tilt) -> f64 {
        let p = self.pressure((x * x + y * y).sqrt());
        if p <= 0.0 {
            return 0.0;
        }
        self.k * p * self.speed(x, y, tilt)
    }
}

/// The spindle's tilt from the inward normal at a contact: in patch coordinates (x toward
/// the tilt, z along the outward normal) the spin axis is (sin, 0, -cos).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Tilt {
    /// Sine of the angle between the spindle axis and the inward normal.
    pub sin: f64,
    /// Its cosine.
    pub cos: f64,
}

impl Tilt {
    /// The tilt of `angle` radians.
    pub fn of_angle(angle: f64) -> Tilt {
        let (sin, cos) = angle.sin_cos();
        Tilt { sin, cos }
    }

    /// The angle, radians.
    pub fn angle(&self) -> f64 {
        self.sin.atan2(self.cos)
    }
}

/// One raster contact point as the removal model sees it (reference frame, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Contact point on the nominal surface.
    pub point: Point3<f64>,
    /// Outward unit normal there.
    pub normal: Vector3<f64>,
    /// Unit direction of motion along the stroke (tangent).
    pub along: Vector3<f64>,
    /// Unit spindle axis (shank to tip) the arm holds at the contact: its tilt from the
    /// inward normal sets the abrasive's speed over the patch.
    pub spin: Vector3<f64>,
    /// Length of the stroke piece the dwell covers, centred on `point`, mm (0: a spot).
    pub length: f64,
    /// The force the ball presses with here as a share of the tool's preload force (1: the
    /// preload on the nominal surface): the real penetration over the preload
    /// ([`super::press`]), which sets the patch and the pressure.
    pub force_ratio: f64,
    /// The patch centre's offset from `point` along the surface, mm: zero on the nominal
    /// surface; where the part is sloped the ball touches it up-slope of its nominal contact,
    /// at the foot of its centre on the measured surface ([`super::press`]).
    pub offset: Vector3<f64>,
    /// How far the arm commands the ball centre below touching the nominal surface here, mm:
    /// the tool's preload, or less where the force it would press with is more than a servo
    /// holds (`motion::press_depth`); [`super::press`] presses the contact from it.
    pub depth_mm: f64,
}

impl Contact {
    /// Centre of the contact patch, mm: `point + offset`.
    pub fn centre(&self) -> Point3<f64> {
        self.point + self.offset
    }

    /// The spindle's tilt from the inward normal and the patch's x axis (the unit tangent
    /// toward which the spindle leans; any tangent, the stroke's, when it does not lean).
    pub fn tilt(&self) -> (Tilt, Vector3<f64>) {
        let n = self.normal;
        let lean = self.spin - n * n.dot(&self.spin);
        let tilt = Tilt {
            sin: lean.norm(),
            cos: -n.dot(&self.spin),
        };
        (tilt, lean.try_normalize(1e-12).unwrap_or(self.along))
    }
}

/// A is stored by columns: for each contact, the (core index, removal per second, mm/s)
/// pairs it reaches.
pub type InfluenceColumns = Vec<Vec<(usize, f64)>>;

/// Core points (positions and outward normals, mm) indexed for the columns of A.
pub struct Reach<'a> {
    cores: &'a [(Point3<f64>, Vector3<f64>)],
    index: Neighbours,
}

impl<'a> Reach<'a> {
    /// Indexes `cores`.
    pub fn new(cores: &'a [(Point3<f64>, Vector3<f64>)]) -> Self {
        let positions: Vec<Point3<f64>> = cores.iter().map(|c| c.0).collect();
        Reach {
            cores,
            index: Neighbours::new(&positions),
        }
    }

    /// The index of the core points' positions.
    pub fn neighbours(&self) -> &Neighbours {
        &self.index
    }

    /// A by columns: one [`Reach::column`] per contact of `contacts`.
    pub fn matrix(&self, influence: &Influence, contacts: &[Contact]) -> InfluenceColumns {
        contacts.iter().map(|c| self.column(influence, c)).collect()
    }

    /// One column of A: the removal depth per second of dwell at contact `c` at every core
    /// point in reach, the influence averaged over the contact's piece of stroke.
    pub fn column(&self, influence: &Influence, c: &Contact) -> Vec<(usize, f64)> {
        let reach = influence.reach_at(c.force_ratio) + 0.5 * c.length;
        let near = self.index.within(&c.centre(), reach);
        self.column_over(influence, c, near.iter().map(|nb| nb.index))
    }

    /// The core points within `radius` mm of `centre`, in no particular order: a superset to
    /// hand [`Reach::column_among`] for contacts that stay within `radius - reach` of it.
    pub fn candidates(&self, centre: &Point3<f64>, radius: f64) -> Vec<usize> {
        let near = self.index.within_unsorted(centre, radius);
        near.into_iter().map(|nb| nb.index).collect()
    }

    /// [`Reach::column`] over `candidates` (a superset of the core points in reach of `c`,
    /// any order; entries in that order): the points in reach are chosen by the same squared
    /// distance the index uses, so the column holds the same values.
    pub fn column_among(
        &self,
        influence: &Influence,
        c: &Contact,
        candidates: &[usize],
    ) -> Vec<(usize, f64)> {
        let reach = influence.reach_at(c.force_ratio) + 0.5 * c.length;
        let o = c.centre();
        let centre = [o.x, o.y, o.z];
        let inside = candidates.iter().copied().filter(|&i| {
            let p = self.cores[i].0;
            crate::spatial::dist2(&[p.x, p.y, p.z], &centre) <= reach * reach
        });
        self.column_over(influence, c, inside)
    }

    /// The column's entries at the core points `inside` (all in reach of `c`).
    fn column_over(
        &self,
        influence: &Influence,
        c: &Contact,
        inside: impl Iterator<Item = usize>,
    ) -> Vec<(usize, f64)> {
        let n = c.normal;
        let (tilt, tx) = c.tilt();
        let ty = n.cross(&tx);
        let pressed = influence.at_force(c.force_ratio);
        let mut column = Vec::new();
        for index in inside {
            let (p, pn) = self.cores[index];
            if pn.dot(&n) < SAME_FACE_COS {
                continue;
            }
            let mean = (0..SUBSAMPLES)
                .map(|s| {
                    let f = (s as f64 + 0.5) / SUBSAMPLES as f64 - 0.5;
                    let d = p - (c.centre() + c.along * (f * c.length));
                    pressed.placed_rate(d.dot(&tx), d.dot(&ty), tilt)
                })
                .sum::<f64>()
                / SUBSAMPLES as f64;
            if mean > 0.0 {
                column.push((index, mean));
            }
        }
        column
    }
}

/// The matrix A: column i holds the removal depth per second of dwell at contact i at every
/// core point in reach (`cores`: positions and outward normals, mm).
pub fn matrix(
    influence: &Influence,
    contacts: &[Contact],
    cores: &[(Point3<f64>, Vector3<f64>)],
) -> InfluenceColumns {
    Reach::new(cores).matrix(influence, contacts)
}

/// A t: the removal depth at every one of `n` core points, mm.
pub fn apply(columns: &InfluenceColumns, t: &[f64], n: usize) -> Vec<f64> {
    let mut out = vec![0.0; n];
    for (col, ti) in columns.iter().zip(t) {
        for &(j, v) in col {
            out[j] += v * ti;
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hertz_pressure_integrates_to_the_force_and_the_table_too() {
        let tool = ToolModel::default();
        for model in [
            tool.clone(),
            ToolModel {
                influence_table: Some(vec![[0.0, 1.0], [0.4, 0.8], [0.9, 0.0]]),
                ..tool.clone()
            },
        ] {
            // at the preload, and pressed 30 % harder (Hertz: patch and peak x 1.3^(1/3))
            for ratio in [1.0, 1.3] {
                let inf = Influence::new(&model, 3.0).at_force(ratio);
                let a = inf.patch_radius();
                assert_eq!(a, Influence::new(&model, 3.0).patch_radius_at(ratio));
                let n = 20_000;
                let force: f64 = (0..n)
                    .map(|i| {
                        let r = (i as f64 + 0.5) * a / n as f64;
                        inf.pressure(r) * std::f64::consts::TAU * r * a / n as f64
                    })
                    .sum();
                assert!((force - 2.0 * ratio).abs() < 1e-3, "{force} at {ratio}");
            }
        }
        let (one, more) = (
            Influence::new(&tool, 3.0),
            Influence::new(&tool, 3.0).at_force(1.3),
        );
        let grow = 1.3f64.cbrt();
        assert!((more.patch_radius() - one.patch_radius() * grow).abs() < 1e-12);
        assert!((more.pressure(0.0) - one.pressure(0.0) * grow).abs() < 1e-12);
    }

    /// A spot contact's removal on a flat grid, the tool landing with a placement scatter of
    /// 0.15 mm: the same volume and centroid as without it, and a footprint wider by exactly
    /// that variance along both axes of the surface (the stencil's moments).
    #[test]
    fn a_placement_scatter_widens_the_footprint_by_its_variance_and_keeps_its_volume() {
        let (pitch, half) = (0.02, 75i32);
        let cores: Vec<(Point3<f64>, Vector3<f64>)> = (-half..=half)
            .flat_map(|i| (-half..=half).map(move |j| (i, j)))
            .map(|(i, j)| {
                let p = Point3::new(pitch * f64::from(i), pitch * f64::from(j), 0.0);
                (p, Vector3::z())
            })
            .collect();
        let spin = Vector3::new(20f64.to_radians().sin(), 0.0, -20f64.to_radians().cos());
        let spot = Contact {
            point: Point3::origin(),
            normal: Vector3::z(),
            along: Vector3::y(),
            spin,
            length: 0.0,
            force_ratio: 1.0,
            offset: Vector3::zeros(),
            depth_mm: 2.0,
        };
        let reach = Reach::new(&cores);
        // volume, centroid (x, y), variance (x, y) of a column
        let moments = |sd: f64| {
            let tool = ToolModel {
                placement_sd_mm: sd,
                ..ToolModel::default()
            };
            let column = reach.column(&Influence::new(&tool, 3.0), &spot);
            let sum: f64 = column.iter().map(|e| e.1).sum();
            let mean = |f: &dyn Fn(&Point3<f64>) -> f64| {
                column.iter().map(|&(i, v)| f(&cores[i].0) * v).sum::<f64>() / sum
            };
            let (mx, my) = (mean(&|p| p.x), mean(&|p| p.y));
            let (vx, vy) = (mean(&|p| (p.x - mx).powi(2)), mean(&|p| (p.y - my).powi(2)));
            (sum, mx, my, vx, vy)
        };
        let sd = 0.15;
        let (sharp, placed) = (moments(0.0), moments(sd));
        assert!(
            (placed.0 / sharp.0 - 1.0).abs() < 1e-3,
            "{sharp:?} {placed:?}"
        );
        assert!((placed.1 - sharp.1).abs() < 1e-4 && (placed.2 - sharp.2).abs() < 1e-4);
        for (v0, v1) in [(sharp.3, placed.3), (sharp.4, placed.4)] {
            assert!((v1 - v0 - sd * sd).abs() < 0.02 * sd * sd, "{v0} {v1}");
        }
    }

    #[test]
    fn speed_at_the_pole_is_omega_r_sin_tilt() {
        let tool = ToolModel::default();
        let inf = Influence::new(&tool, 3.0);
        let tilt = Tilt::of_angle(20f64.to_radians());
        let want = tool.omega() * 3.0 * tilt.sin;
        assert!((inf.speed(0.0, 0.0, tilt) - want).abs() < 1e-9 * want);
        assert!((tilt.angle() - 20f64.to_radians()).abs() < 1e-15);
        // untilted, the pole does not move
        assert!(inf.speed(0.0, 0.0, Tilt::of_angle(0.0)).abs() < 1e-9);
    }
}

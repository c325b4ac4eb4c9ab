//! Where the tool really ground (issue 50): after a grind, each repairable region's measured
//! removal map (the deviation before minus the deviation after, at the same core points) is
//! registered against the plan's predicted removal by their first moments: the shift s along
//! the surface is where the measured removal's centroid lies from the predicted removal's, the
//! measured centroid taken over a window that follows it (the plan's footprint moved by s and
//! widened by [`ShiftConfig::window_mm`]); the depth scale a is then the least-squares scale of
//! m(x) = a p(x - s). A least-squares search over shifts was used before: the predicted map
//! ripples with the ~1 mm stroke spacing and the removal's shape is not the plan's (the
//! simulator presses one flank of a bump harder), so its residual had basins a stroke apart
//! and a 0.28 mm centroid difference read as 1.50 mm on the demo. The removal planned at y
//! landed at y + s; k is fitted on the prediction moved by s ([`shifted_prediction`]), so that
//! a removal beside the plan is not read as a slower tool; the shift is carried into the next
//! plan (the tool aimed back by it, `motion::aim`), and a grind whose regions disagree on the
//! shift, whose shift is beyond what the plan can aim back by, or that removed where no shift
//! of the plan explains it, stops the loop ([`carry`]).
//! Method: docs/ALGORITHMS.md, "Where the tool really ground".
//!
//! Front function: [`register`] with a [`ShiftConfig`]; result: one [`RegionShift`] per region.
use nalgebra::{Point3, Vector3};
use rayon::prelude::*;
use serde::Serialize;

use crate::motion::aim::{Aim, AimRegion};
use crate::removal::matching::{repairable_ids, GrindPair};
use crate::repair::Inspection;
use crate::spatial::{tangent_basis, Neighbours, SparseGrid};

/// Most steps of the moving window's centroid iteration (30: each step moves the window to the
/// centroid it found; a removal 2 mm off a footprint 3 mm across is followed in 5-10 steps, and
/// the iteration stops earlier once a step moves it less than [`CONVERGED_MM`]).
const MOMENT_ITERATIONS: usize = 30;

/// A step of the centroid iteration under which it has converged, mm (0.005: a twentieth of
/// the 0.1 mm the registration is asked to resolve).
const CONVERGED_MM: f64 = 0.005;

/// Settings of the registration and of the stop rule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ShiftConfig {
    /// Largest shift the registration measures along the surface, mm (2.5: on the documented
    /// arm the demo's first grind landed 0.13-0.28 mm off (its true removal's centroids), the
    /// ten acceptance cases' up to 1.2 mm; a shift beyond it stops the loop, as one larger
    /// than the shift carried, `carry_mm`).
    pub search_mm: f64,
    /// How far beyond the plan's footprint (moved by the shift) the measured removal's
    /// centroid is taken, mm (0.3: half the shipped tool's 0.6 mm patch radius, so removal
    /// spread by the patch beyond the footprint's edge counts, while the inspection's noise at
    /// the points farther out, 0.013-0.021 mm each, does not pull the centroid: measured on a
    /// synthetic raster, 0.6 mm gave a 0.06 mm median error where 0.3 mm gave 0.04-0.06).
    pub window_mm: f64,
    /// Share of the predicted removal around a region (within `search_mm + window_mm` of its
    /// points) that lies on points other regions hold, over which the centroid is not trusted
    /// and the shift is the least-squares fit of the predicted map instead (0.2: the removal
    /// on another region's points is not the region's to weigh, and the centroid of a removal
    /// a fifth of which is cut off moves toward what is left by up to a fifth of the
    /// footprint's width, 0.5 mm on a 2.5 mm footprint; the fit of the whole map is not cut by
    /// the regions' borders, but has basins a stroke apart where the removal's shape is not
    /// the plan's, so it is used only there).
    pub hidden_share: f64,
    /// Step of the least-squares grid, mm (0.1: under a tenth of the patch).
    pub step_mm: f64,
    /// Largest shift (carried and measured together) the next plan aims back by, mm (2.4):
    /// the tool is commanded back along the contact's tangent plane, which on a surface of
    /// curvature radius R puts it s^2 / 2R off the surface along the normal; on the femoral
    /// condyles (R >= 15 mm) a 2.4 mm shift is 0.19 mm, under a tenth of the 2 mm preload
    /// (the force within 10 %).
    pub carry_mm: f64,
    /// Most a region's shift may differ from the cell-wide shift (the regions' mean), mm
    /// (1.2, the shipped tool's contact patch diameter: a region whose removal landed a whole
    /// patch away from where the cell-wide error puts it does not overlap it at all, a
    /// different error rather than the same arm's error changing over the part. Measured on
    /// the documented arm with the least-squares registration: the demo's regions 0.24-0.46 mm
    /// from their mean, acceptance cases 1 and 21 up to 0.73 and 0.70 mm; 0.6 mm, the patch
    /// radius, stopped both cases after grind 1).
    pub agree_mm: f64,
    /// Least predicted removal over a region for its shift to be measured, mm (0.04: twice
    /// the 0.02 mm scatter of the difference of two inspections; the shift is fitted over the
    /// region's 200 or more points). A region that removed less keeps the shift carried to it.
    pub measurable_mm: f64,
    /// Least measured removal that counts as removal, mm (0.06: three times the 0.02 mm
    /// scatter of the difference of two inspections, each 0.013-0.021 mm on ground surface).
    pub removed_mm: f64,
    /// Least prediction at the registered shift under which a removal is "where nothing was
    /// planned", mm (0.005: the removal fit's least predicted removal); also the edge of the
    /// plan's footprint the centroid's window follows.
    pub planned_mm: f64,
    /// Most unplanned removed points tolerated per region (10: a few stray points of the
    /// inspection's noise tail; a misplaced patch covers 30+ core points).
    pub unplanned_points: usize,
}

impl Default for ShiftConfig {
    fn default() -> Self {
        ShiftConfig {
            search_mm: 2.5,
            window_mm: 0.3,
            hidden_share: 0.2,
            step_mm: 0.1,
            carry_mm: 2.4,
            agree_mm: 1.2,
            measurable_mm: 0.04,
            removed_mm: 0.06,
            planned_mm: 0.005,
            unplanned_points: 10,
        }
    }
}

/// One region's registration.
#[derive(Debug, Clone, PartialEq)]
pub struct RegionShift {
    /// Region id (of the inspection before the grind).
    pub region: i64,
    /// Shift of the removal from the plan, reference frame, mm (in the region's tangent plane).
    pub shift_mm: Vector3<f64>,
    /// Depth scale at that shift: measured = scale x predicted.
    pub scale: f64,
    /// Depth scale without a shift.
    pub scale_unshifted: f64,
    /// RMS of measured minus scaled prediction, without and with the shift, mm.
    pub rms_mm: [f64; 2],
    /// Points used.
    pub points: usize,
    /// Points that lost material where the shifted plan removes nothing.
    pub unplanned: usize,
    /// Centre of the region's points, reference frame, mm.
    pub centre: Point3<f64>,
    /// The region's mean outward normal.
    pub normal: Vector3<f64>,
    /// Farthest of the region's points from its centre plus the search, mm: the contacts
    /// within it take the region's shift.
    pub reach_mm: f64,
    /// Largest predicted removal over the points used, mm.
    pub peak_predicted_mm: f64,
    /// Share of the predicted removal around the region on other regions' points: over
    /// [`ShiftConfig::hidden_share`] the shift is the least-squares fit, else first moments.
    pub hidden_share: f64,
}

/// Whether core point `p` may carry region `id`'s removal: its own, or no region's.
fn open_to(p: &crate::repair::SurfacePoint, id: i64) -> bool {
    p.region == id || p.region < 0
}

/// The matched points near region `id` that no other repairable region holds: (index in
/// `before`, measured removal).
fn neighbourhood(
    before: &Inspection,
    measured: &[Option<f64>],
    id: i64,
    reach: f64,
) -> Vec<(usize, f64)> {
    let own = before.points.iter().filter(|p| p.region == id);
    let grid = SparseGrid::new(reach, own.map(|p| p.position));
    // each point's test is its own: in parallel, the order and the answer kept
    (before.points.par_iter())
        .enumerate()
        .filter(|(_, p)| open_to(p, id))
        .filter_map(|(i, p)| {
            Some((i, measured[i]?)).filter(|_| grid.any_within(&p.position, reach))
        })
        .collect()
}

/// The prediction at `x` by inverse-distance weighting of its 4 nearest core points.
fn predicted_at(index: &Neighbours, predicted: &[f64], x: &Point3<f64>) -> f64 {
    let near = index.knn(x, 4);
    let (mut w, mut s) = (0.0, 0.0);
    for nb in near {
        let wi = 1.0 / (nb.dist2 + 1e-6);
        w += wi;
        s += wi * predicted[nb.index];
    }
    if w > 0.0 {
        s / w
    } else {
        0.0
    }
}

/// Least-squares scale of m on p through the origin, and the residual sum of squares.
fn scaled(pairs: impl Iterator<Item = (f64, f64)>) -> (f64, f64) {
    let (mut pp, mut pm, mut mm) = (0.0, 0.0, 0.0);
    for (p, m) in pairs {
        pp += p * p;
        pm += p * m;
        mm += m * m;
    }
    if pp <= 0.0 {
        return (0.0, mm);
    }
    let a = (pm / pp).max(0.0);
    (a, mm - 2.0 * a * pm + a * a * pp)
}

/// The fit of the prediction moved by a shift: depth scale, residual sum of squares, and the
/// moved prediction at each point of the neighbourhood.
type Fitted = (f64, f64, Vec<f64>);

/// What the first moments compare: the core points (`positions`, their index `index`), the
/// measured removal per point (None: unmatched), and the region (`id`) with its mean normal.
struct Moments<'a> {
    before: &'a Inspection,
    positions: &'a [Point3<f64>],
    index: &'a Neighbours,
    measured: &'a [Option<f64>],
    id: i64,
    normal: Vector3<f64>,
}

impl Moments<'_> {
    /// The removal's shift from the plan by first moments: the measured removal's centroid
    /// over the plan's footprint (`footprint`, the points the plan removes from) moved by the
    /// shift and widened by `cfg.window_mm`, from the centroid `planned` of the prediction,
    /// iterated until the window stops moving; in the region's tangent plane. None when the
    /// window holds no net removal.
    fn shift(
        &self,
        footprint: &[Point3<f64>],
        planned: &Point3<f64>,
        cfg: &ShiftConfig,
    ) -> Option<Vector3<f64>> {
        let mut s = Vector3::zeros();
        let mut inside = vec![false; self.positions.len()];
        for _ in 0..MOMENT_ITERATIONS {
            inside.iter_mut().for_each(|b| *b = false);
            let (mut sum, mut moment) = (0.0, Vector3::zeros());
            for f in footprint {
                for nb in self.index.within_unsorted(&(f + s), cfg.window_mm) {
                    let i = nb.index;
                    if inside[i] || !open_to(&self.before.points[i], self.id) {
                        continue;
                    }
                    inside[i] = true;
                    if let Some(m) = self.measured[i] {
                        sum += m;
                        moment += self.positions[i].coords * m;
                    }
                }
            }
            if sum <= 0.0 {
                return None;
            }
            let d = moment / sum - planned.coords;
            let next = d - self.normal * self.normal.dot(&d);
            let step = (next - s).norm();
            s = next;
            if step < CONVERGED_MM || s.norm() > cfg.search_mm + cfg.window_mm {
                break;
            }
        }
        Some(s)
    }

    /// Share of the predicted removal within `reach` of the region's own points that lies on
    /// points other regions hold (`predicted` per core point).
    fn hidden(&self, predicted: &[f64], reach: f64) -> f64 {
        let own = (self.before.points.iter()).filter(|p| p.region == self.id);
        let grid = SparseGrid::new(reach, own.map(|p| p.position));
        let (mut open, mut held) = (0.0, 0.0);
        for (p, q) in self.before.points.iter().zip(predicted) {
            if *q > 0.0 && grid.any_within(&p.position, reach) {
                match open_to(p, self.id) {
                    true => open += q,
                    false => held += q,
                }
            }
        }
        held / (open + held).max(f64::MIN_POSITIVE)
    }

    /// The shift by least squares: the s on a grid of `cfg.step_mm` within `cfg.search_mm`
    /// in the tangent plane whose scaled prediction p(x - s) leaves the least residual over
    /// `near` (`at` gives the scale and the residual sum of squares at s).
    fn least_squares(
        &self,
        at: &dyn Fn(&Vector3<f64>) -> Fitted,
        cfg: &ShiftConfig,
    ) -> Vector3<f64> {
        let (ta, tb) = tangent_basis(&self.normal);
        let n = (cfg.search_mm / cfg.step_mm).round() as i64;
        let mut best = (Vector3::zeros(), at(&Vector3::zeros()).1);
        for u in -n..=n {
            for v in -n..=n {
                let s = (ta * u as f64 + tb * v as f64) * cfg.step_mm;
                if s.norm() > cfg.search_mm + 1e-9 {
                    continue;
                }
                let ss = at(&s).1;
                if ss < best.1 {
                    best = (s, ss);
                }
            }
        }
        best.0
    }
}

/// Registers each repairable region of `pair.before` that the plan removes from (`predicted`,
/// per core point of `pair.before`) against its measured removal in `pair.after`: the shift
/// by first moments ([`Moments::shift`]; by least squares, [`Moments::least_squares`], where
/// other regions hide over [`ShiftConfig::hidden_share`] of the window), the depth scale by
/// least squares at that shift.
pub fn register(pair: &GrindPair, predicted: &[f64], cfg: &ShiftConfig) -> Vec<RegionShift> {
    let before = pair.before;
    let measured: Vec<Option<f64>> = (0..before.points.len())
        .map(|i| pair.removal(i).filter(|m| m.is_finite()))
        .collect();
    let positions: Vec<Point3<f64>> = before.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&positions);
    let mut out = Vec::new();
    for id in repairable_ids(before) {
        let near = neighbourhood(before, &measured, id, cfg.search_mm + cfg.window_mm);
        let footprint: Vec<Point3<f64>> = (near.iter())
            .filter(|(i, _)| predicted[*i] >= cfg.planned_mm)
            .map(|(i, _)| positions[*i])
            .collect();
        if footprint.is_empty() {
            continue;
        }
        let normal = near
            .iter()
            .map(|(i, _)| before.points[*i].normal)
            .sum::<Vector3<f64>>()
            .normalize();
        let weight: f64 = near.iter().map(|(i, _)| predicted[*i].max(0.0)).sum();
        let planned = Point3::from(
            (near.iter())
                .map(|(i, _)| positions[*i].coords * predicted[*i].max(0.0))
                .sum::<Vector3<f64>>()
                / weight,
        );
        let moments = Moments {
            before,
            positions: &positions,
            index: &index,
            measured: &measured,
            id,
            normal,
        };
        let at = |s: &Vector3<f64>| {
            let p: Vec<f64> = (near.par_iter())
                .map(|(i, _)| predicted_at(&index, predicted, &(positions[*i] - s)))
                .collect();
            let (a, ss) = scaled(p.iter().zip(&near).map(|(p, (_, m))| (*p, *m)));
            (a, ss, p)
        };
        // first moments where the window sees the removal whole; where other regions hold
        // part of it, the template's least squares (the moments would be cut there)
        let hidden = moments.hidden(predicted, cfg.search_mm + cfg.window_mm);
        let shift = match hidden > cfg.hidden_share {
            true => Some(moments.least_squares(&at, cfg)),
            false => moments.shift(&footprint, &planned, cfg),
        };
        let zero = at(&Vector3::zeros());
        let s = shift.unwrap_or_else(Vector3::zeros);
        let best = at(&s);
        // no net removal under the footprint: nothing registered, the scale 0 (not measured)
        let scale = if shift.is_some() { best.0 } else { 0.0 };
        let unplanned = (best.2.iter().zip(&near))
            .filter(|(p, (_, m))| **p < cfg.planned_mm && *m > cfg.removed_mm)
            .count();
        let rms = |ss: f64| (ss / near.len().max(1) as f64).sqrt();
        let own: Vec<Point3<f64>> = (before.points.iter())
            .filter(|p| p.region == id)
            .map(|p| p.position)
            .collect();
        let centre = Point3::from(
            own.iter().map(|p| p.coords).sum::<Vector3<f64>>() / own.len().max(1) as f64,
        );
        let extent = own.iter().map(|p| (p - centre).norm()).fold(0.0, f64::max);
        out.push(RegionShift {
            region: id,
            shift_mm: s,
            scale,
            scale_unshifted: zero.0,
            rms_mm: [rms(zero.1), rms(best.1)],
            points: near.len(),
            unplanned,
            centre,
            normal,
            reach_mm: extent + cfg.search_mm,
            peak_predicted_mm: near.iter().map(|(i, _)| predicted[*i]).fold(0.0, f64::max),
            hidden_share: hidden,
        });
    }
    out
}

/// `predicted` (per core point of `before`) moved by each region's shift over its own
/// neighbourhood: what the plan would have predicted had it known where the tool grinds.
pub fn shifted_prediction(
    before: &Inspection,
    predicted: &[f64],
    shifts: &[RegionShift],
    cfg: &ShiftConfig,
) -> Vec<f64> {
    let positions: Vec<Point3<f64>> = before.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&positions);
    let everywhere = vec![Some(0.0); positions.len()];
    let mut out = predicted.to_vec();
    // regions in order (a point near two takes the later one's), each region's points in
    // parallel
    for r in shifts {
        let near = neighbourhood(before, &everywhere, r.region, cfg.search_mm + cfg.window_mm);
        let moved: Vec<(usize, f64)> = (near.par_iter())
            .map(|(i, _)| {
                (
                    *i,
                    predicted_at(&index, predicted, &(positions[*i] - r.shift_mm)),
                )
            })
            .collect();
        for (i, p) in moved {
            out[i] = p;
        }
    }
    out
}

/// A region's shift as the loop carries it (cycle.json's `shifts`).
#[derive(Debug, Clone, PartialEq, Serialize, serde::Deserialize)]
pub struct CarriedShift {
    /// Region id (of the inspection before the grind).
    pub region: i64,
    /// The shift this grind measured (from where the plan aimed), reference frame, mm; None
    /// when the region removed too little to measure it (`ShiftConfig::measurable_mm`).
    pub measured_mm: Option<[f64; 3]>,
    /// The depth scale at that shift.
    pub scale: f64,
    /// The correction the next plan applies there: the shift carried before plus the one
    /// measured, reference frame, mm.
    pub carried_mm: [f64; 3],
}

/// What the next plan aims by, and each region's part of it.
#[derive(Debug, Clone, PartialEq)]
pub struct Carried {
    /// The next plan's aim.
    pub aim: Aim,
    /// Per region registered.
    pub regions: Vec<CarriedShift>,
}

/// The stop rule on the registration, and the correction carried into the next plan: each
/// measured region's shift added to the shift the plan aimed back by there (`aim`), the
/// cell-wide shift their mean weighted by points; a region too little ground to measure keeps
/// what it was carried. A one-line reason naming the region and its measured shift instead
/// when a region removed where nothing was planned, its shift sits at the edge of the search
/// (it may be larger than the search saw), the shift to carry exceeds `carry_mm`, or it
/// differs from the cell-wide shift by more than `agree_mm` (the regions disagree: not one
/// arm error): never a grind on a model that put the tool elsewhere.
pub fn carry(shifts: &[RegionShift], aim: &Aim, cfg: &ShiftConfig) -> Result<Carried, String> {
    let v = |s: &Vector3<f64>| format!("{:.2} mm [{:.2}, {:.2}, {:.2}]", s.norm(), s.x, s.y, s.z);
    let stop = |r: &RegionShift, why: String| {
        format!(
            "region {}: the removal landed {} from where the plan aimed ({why}): the arm is not \
             where the model puts it; not grinding again on that model",
            r.region,
            v(&r.shift_mm)
        )
    };
    if let Some(r) = shifts.iter().find(|r| r.unplanned > cfg.unplanned_points) {
        let why = format!(
            "{} points removed where nothing was planned, limit {}",
            r.unplanned, cfg.unplanned_points
        );
        return Err(stop(r, why));
    }
    let measured = |r: &&RegionShift| r.peak_predicted_mm >= cfg.measurable_mm && r.scale > 0.0;
    if let Some(r) = shifts
        .iter()
        .filter(measured)
        .find(|r| r.shift_mm.norm() > cfg.search_mm)
    {
        let why = format!("beyond the {} mm the registration measures", cfg.search_mm);
        return Err(stop(r, why));
    }
    let total = |r: &RegionShift| aim.shift_at(&r.centre, &r.normal) + r.shift_mm;
    if let Some(r) = shifts
        .iter()
        .filter(measured)
        .find(|r| total(r).norm() > cfg.carry_mm)
    {
        let why = format!(
            "{} with the shift carried, over the {} mm the plan can aim back by",
            v(&total(r)),
            cfg.carry_mm
        );
        return Err(stop(r, why));
    }
    let weight: usize = shifts.iter().filter(measured).map(|r| r.points).sum();
    let common = match weight {
        0 => Vector3::from(aim.common_mm),
        w => {
            let sum: Vector3<f64> = (shifts.iter().filter(measured))
                .map(|r| total(r) * r.points as f64)
                .sum();
            sum / w as f64
        }
    };
    if let Some(r) =
        (shifts.iter().filter(measured)).find(|r| (total(r) - common).norm() > cfg.agree_mm)
    {
        let why = format!(
            "{} from the cell-wide shift {}, over the {} mm regions may disagree",
            v(&(total(r) - common)),
            v(&common),
            cfg.agree_mm
        );
        return Err(stop(r, why));
    }
    let arr = |s: Vector3<f64>| [s.x, s.y, s.z];
    let regions: Vec<CarriedShift> = shifts
        .iter()
        .map(|r| {
            let m = measured(&r);
            CarriedShift {
                region: r.region,
                measured_mm: m.then(|| arr(r.shift_mm)),
                scale: r.scale,
                carried_mm: arr(if m {
                    total(r)
                } else {
                    aim.shift_at(&r.centre, &r.normal)
                }),
            }
        })
        .collect();
    let next = match weight {
        // nothing measured: the plan still does not know where the tool grinds
        0 if aim.regions.is_empty() => aim.clone(),
        _ => Aim {
            first_pass_share: None,
            reach_mm: aim.reach_mm,
            common_mm: arr(common),
            regions: (shifts.iter().zip(&regions))
                .map(|(r, c)| AimRegion {
                    centre_mm: arr(r.centre.coords),
                    reach_mm: r.reach_mm,
                    shift_mm: c.carried_mm,
                })
                .collect(),
        },
    };
    Ok(Carried { aim: next, regions })
}

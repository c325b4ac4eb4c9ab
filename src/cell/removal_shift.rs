//! Where the tool really ground (issue 50): after a grind, each repairable region's measured
//! removal map (the deviation before minus the deviation after, at the same core points) is
//! registered against the plan's predicted removal: the shift s along the surface and the
//! depth scale a that best explain m(x) = a p(x - s) in least squares, over a grid of shifts
//! in the region's tangent plane. The removal planned at y landed at y + s; k is fitted on the
//! prediction moved by s ([`shifted_prediction`]), so that a removal beside the plan is not read
//! as a slower tool; the shift is carried into the next plan (the tool aimed back by it,
//! `motion::aim`), and a grind whose regions disagree on the shift, whose shift is beyond what
//! the plan can aim back by, or that removed where no shift of the plan explains it, stops the
//! loop ([`carry`]).
//! Method: docs/ALGORITHMS.md, "Where the tool really ground".
//!
//! Front function: [`register`] with a [`ShiftConfig`]; result: one [`RegionShift`] per region.
use nalgebra::{Point3, Vector3};
use serde::Serialize;

use crate::motion::aim::{Aim, AimRegion};
use crate::removal::matching::{partners, repairable_ids};
use crate::repair::Inspection;
use crate::spatial::{tangent_basis, Neighbours, SparseGrid};

/// Settings of the registration and of the stop rule.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ShiftConfig {
    /// Largest shift searched along the surface, mm (2.5: on the documented arm the demo's
    /// first grind landed 1.36-1.89 mm off, the ten acceptance cases' 0.8-1.2 mm; a shift at
    /// the edge of the search may be larger than it saw, so the search reaches past the
    /// largest shift carried, `carry_mm`).
    pub search_mm: f64,
    /// Step of the search grid, mm (0.1: under a tenth of the patch).
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
    /// the documented arm: the demo's regions 0.24-0.46 mm from their mean, acceptance cases
    /// 1 and 21 up to 0.73 and 0.70 mm; 0.6 mm, the patch radius, stopped both cases after
    /// grind 1).
    pub agree_mm: f64,
    /// Least predicted removal over a region for its shift to be measured, mm (0.04: twice
    /// the 0.02 mm scatter of the difference of two inspections; the shift is fitted over the
    /// region's 200 or more points). A region that removed less keeps the shift carried to it.
    pub measurable_mm: f64,
    /// Least measured removal that counts as removal, mm (0.06: three times the 0.02 mm
    /// scatter of the difference of two inspections, each 0.013-0.021 mm on ground surface).
    pub removed_mm: f64,
    /// Least prediction at the registered shift under which a removal is "where nothing was
    /// planned", mm (0.005: the removal fit's least predicted removal).
    pub planned_mm: f64,
    /// Most unplanned removed points tolerated per region (10: a few stray points of the
    /// inspection's noise tail; a misplaced patch covers 30+ core points).
    pub unplanned_points: usize,
    /// Share above a region's least residual sum of squares within which two shifts fit it
    /// equally well; the registration takes among them the shift nearest the regions' median
    /// best shift (0.05). The measured removal is
    /// the difference of two noisy inspections, and the removal landing on the arm's real
    /// errors is not the predicted shape moved: a region's residual over the shifts can have
    /// two basins a patch apart. Measured on the demo (documented arm, issue 50): region 1's
    /// best fit landed 1.41 mm off and shifts 1.62 mm from it fitted within 5 % of it, where
    /// the noise-free true removal (`after_truth.ply`) registers at 0.41 mm and a noise-free
    /// rescan at 0.36 mm; every other region's near-best shifts lay within 0.14 mm of its best.
    pub near_best: f64,
}

impl Default for ShiftConfig {
    fn default() -> Self {
        ShiftConfig {
            search_mm: 2.5,
            step_mm: 0.1,
            carry_mm: 2.4,
            agree_mm: 1.2,
            measurable_mm: 0.04,
            removed_mm: 0.06,
            planned_mm: 0.005,
            unplanned_points: 10,
            near_best: 0.05,
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
    before
        .points
        .iter()
        .enumerate()
        .filter(|(_, p)| p.region == id || p.region < 0)
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

/// Registers each repairable region of `before` that the plan removes from (`predicted`, per
/// core point of `before`) against its measured removal in `after`. Where several shifts fit
/// a region within [`ShiftConfig::near_best`] of its best, it takes the one nearest the
/// regions' median best shift (the noise of two inspections cannot choose between them).
pub fn register(
    before: &Inspection,
    after: &Inspection,
    predicted: &[f64],
    cfg: &ShiftConfig,
) -> Vec<RegionShift> {
    let partner = partners(before, after);
    let measured: Vec<Option<f64>> = partner
        .iter()
        .zip(&before.points)
        .map(|(j, p)| j.map(|j| p.distance - after.points[j].distance))
        .map(|m| m.filter(|m| m.is_finite()))
        .collect();
    let positions: Vec<Point3<f64>> = before.points.iter().map(|p| p.position).collect();
    let index = Neighbours::new(&positions);
    let n = (cfg.search_mm / cfg.step_mm).round() as i64;
    // first the best fit of every region, then each region's fit among those the noise
    // cannot tell from its best that lies nearest the regions' median shift
    let mut firsts = Vec::new();
    for id in repairable_ids(before) {
        let near = neighbourhood(before, &measured, id, cfg.search_mm + cfg.step_mm);
        let planned = near.iter().any(|(i, _)| predicted[*i] >= cfg.planned_mm);
        if !planned {
            continue;
        }
        let normal = near
            .iter()
            .map(|(i, _)| before.points[*i].normal)
            .sum::<Vector3<f64>>()
            .normalize();
        let (ta, tb) = tangent_basis(&normal);
        let at = |s: &Vector3<f64>| {
            let p: Vec<f64> = near
                .iter()
                .map(|(i, _)| predicted_at(&index, predicted, &(positions[*i] - s)))
                .collect();
            let (a, ss) = scaled(p.iter().zip(&near).map(|(p, (_, m))| (*p, *m)));
            (a, ss, p)
        };
        let zero = at(&Vector3::zeros());
        let mut grid = vec![(Vector3::zeros(), zero.0, zero.1)];
        for u in -n..=n {
            for v in -n..=n {
                let s = (ta * u as f64 + tb * v as f64) * cfg.step_mm;
                if s.norm() > cfg.search_mm + 1e-9 {
                    continue;
                }
                let (a, ss, _) = at(&s);
                grid.push((s, a, ss));
            }
        }
        let least = grid.iter().map(|g| g.2).fold(f64::INFINITY, f64::min);
        let near_best: Vec<_> = grid
            .into_iter()
            .filter(|g| g.2 <= least * (1.0 + cfg.near_best))
            .collect();
        firsts.push((id, near, normal, zero, near_best));
    }
    let bests: Vec<Vector3<f64>> = (firsts.iter())
        .filter_map(|f| f.4.iter().min_by(|a, b| a.2.total_cmp(&b.2)).map(|g| g.0))
        .collect();
    let median = |k: usize| {
        let mut c: Vec<f64> = bests.iter().map(|b| b[k]).collect();
        c.sort_by(f64::total_cmp);
        c.get(c.len() / 2).copied().unwrap_or(0.0)
    };
    let consensus = Vector3::new(median(0), median(1), median(2));
    let mut out = Vec::new();
    for (id, near, normal, zero, near_best) in firsts {
        let at = |s: &Vector3<f64>| {
            near.iter()
                .map(|(i, _)| predicted_at(&index, predicted, &(positions[*i] - s)))
                .collect::<Vec<f64>>()
        };
        let best = (near_best.into_iter())
            .min_by(|a, b| {
                (a.0 - consensus)
                    .norm()
                    .total_cmp(&(b.0 - consensus).norm())
            })
            .unwrap_or((Vector3::zeros(), zero.0, zero.1));
        let p = at(&best.0);
        let unplanned = p
            .iter()
            .zip(&near)
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
            shift_mm: best.0,
            scale: best.1,
            scale_unshifted: zero.0,
            rms_mm: [rms(zero.1), rms(best.2)],
            points: near.len(),
            unplanned,
            centre,
            normal,
            reach_mm: extent + cfg.search_mm,
            peak_predicted_mm: near.iter().map(|(i, _)| predicted[*i]).fold(0.0, f64::max),
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
    for r in shifts {
        for (i, _) in neighbourhood(before, &everywhere, r.region, cfg.search_mm + cfg.step_mm) {
            out[i] = predicted_at(&index, predicted, &(positions[i] - r.shift_mm));
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
    let edge = cfg.search_mm - 0.5 * cfg.step_mm;
    if let Some(r) = shifts
        .iter()
        .filter(measured)
        .find(|r| r.shift_mm.norm() > edge)
    {
        let why = format!("at the edge of the {} mm search", cfg.search_mm);
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

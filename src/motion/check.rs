//! Measures a program through the robot model: tool-tip path error, feed at cruise, servo
//! resolution error, and each region's reach and coverage.
use nalgebra::{Point3, Vector3};

use super::config::PlanConfig;
use super::program::{PlannedPass, Program, SegmentKind};
use super::raster::PathPoint;
use super::report::{Metrics, RegionReport};
use crate::repair::{Inspection, RegionInfo, SurfacePoint};
use crate::robot::units::mm;
use crate::robot::{resolution_error, IkTarget, Robot, Workcell};
use crate::spatial::Neighbours;

/// Distance from `p` to the polyline `line`.
pub fn polyline_distance(p: &Vector3<f64>, line: &[Vector3<f64>]) -> f64 {
    if line.len() == 1 {
        return (p - line[0]).norm();
    }
    line.windows(2)
        .map(|w| {
            let d = w[1] - w[0];
            let len2 = d.norm_squared();
            let t = if len2 > 0.0 {
                ((p - w[0]).dot(&d) / len2).clamp(0.0, 1.0)
            } else {
                0.0
            };
            (p - (w[0] + d * t)).norm()
        })
        .fold(f64::INFINITY, f64::min)
}

/// Path error, feed and resolution error of `prog`.
pub fn measure(prog: &Program, robot: &Robot, cfg: &PlanConfig) -> Metrics {
    let traj = &prog.trajectory;
    let tips: Vec<Vector3<f64>> = (0..traj.len())
        .map(|i| robot.fk(traj.sample(i)).position)
        .collect();
    let res: Vec<f64> = (0..traj.len())
        .map(|i| resolution_error(robot, traj.sample(i)))
        .collect();
    let mut m = Metrics {
        predicted_duration_s: traj.duration(),
        samples: traj.len(),
        path_points: prog.passes.iter().map(|p| p.points.len()).sum(),
        resolution_error_max_mm: mm(res.iter().copied().fold(0.0, f64::max)),
        resolution_error_mean_mm: mm(res.iter().sum::<f64>() / res.len().max(1) as f64),
        feed_mm_s: cfg.feed_mm_s,
        cruise_feed_min_mm_s: f64::INFINITY,
        slowed_strokes: prog.slowed,
        ..Metrics::default()
    };
    let (mut grind_samples, mut cruise_samples) = (0usize, 0usize);
    for seg in &prog.segments {
        let Some(pass) = seg.pass.filter(|_| seg.kind == SegmentKind::Grind) else {
            continue;
        };
        let planned: Vec<Vector3<f64>> = prog.passes[pass]
            .points
            .iter()
            .map(|p| Vector3::from(p.tip_m))
            .collect();
        let sampled = &tips[seg.first_sample..=seg.last_sample];
        for t in sampled {
            m.sample_to_path_max_mm = m
                .sample_to_path_max_mm
                .max(mm(polyline_distance(t, &planned)));
        }
        for p in &planned {
            m.path_to_samples_max_mm = m
                .path_to_samples_max_mm
                .max(mm(polyline_distance(p, sampled)));
        }
        for k in seg.first_sample + 1..=seg.last_sample {
            grind_samples += 1;
            if prog.cruise[k] && prog.cruise[k - 1] {
                cruise_samples += 1;
                let v = mm((tips[k] - tips[k - 1]).norm() / traj.period);
                m.cruise_feed_min_mm_s = m.cruise_feed_min_mm_s.min(v);
                m.cruise_feed_max_mm_s = m.cruise_feed_max_mm_s.max(v);
            }
        }
    }
    if cruise_samples == 0 {
        m.cruise_feed_min_mm_s = 0.0;
    }
    m.cruise_share = cruise_samples as f64 / grind_samples.max(1) as f64;
    m
}

/// Whether the tool can sit on `sp`'s normal at the last layer's height (tip `reach` mm out
/// from the surface plus the allowance, axis against the normal) with the part placed by `wc`.
pub fn tool_reaches(
    sp: &SurfacePoint,
    robot: &Robot,
    wc: &Workcell,
    cfg: &PlanConfig,
    reach: f64,
) -> bool {
    let pt = PathPoint {
        surface: sp.position,
        normal: sp.normal,
        offset: cfg.allowance_mm,
    };
    let tip = pt.surface + pt.normal * (pt.offset + reach);
    let target = IkTarget {
        position: wc.point_from_reference_mm(&tip).coords,
        axis: -wc.direction_from_reference(&pt.normal),
        roll: None,
    };
    robot.ik(&target, &cfg.home, &cfg.ik).is_ok()
}

/// Where a region's planned strokes grind: where the passes' patches land
/// (`PlannedPoint::landing`, reference frame) densified along each pass to 1/20 of the footprint.
pub struct Cover {
    index: Neighbours,
    footprint: f64,
}

impl Cover {
    /// The strokes of region `region` among `passes`, with footprint radius `footprint` mm.
    pub fn new(passes: &[PlannedPass], region: usize, footprint: f64) -> Cover {
        let mut dense = Vec::new();
        for pass in passes.iter().filter(|p| p.region == region) {
            let pts: Vec<Point3<f64>> = pass.points.iter().map(|p| p.landing().into()).collect();
            dense.extend(pts.first().copied());
            for w in pts.windows(2) {
                let n = ((w[1] - w[0]).norm() / (footprint * 0.05)).ceil().max(1.0) as usize;
                dense.extend((1..=n).map(|k| w[0] + (w[1] - w[0]) * (k as f64 / n as f64)));
            }
        }
        Cover {
            index: Neighbours::new(&dense),
            footprint,
        }
    }

    /// Whether `p` (reference frame, mm) lies within the footprint of a stroke.
    pub fn covers(&self, p: &Point3<f64>) -> bool {
        self.index
            .nearest(p)
            .is_some_and(|n| n.dist2.sqrt() <= self.footprint)
    }
}

/// Reach and coverage of `region`: a core point is reachable when the tool can sit on its
/// normal at the last layer's height; covered when it lies within `footprint` mm of a planned
/// pass of the region (the polylines through where the passes' patches land,
/// `PlannedPoint::landing`).
#[allow(clippy::too_many_arguments)]
pub fn region_report(
    region: &RegionInfo,
    inspection: &Inspection,
    passes: &[PlannedPass],
    layers: usize,
    path_points: usize,
    unreachable_path_points: usize,
    robot: &Robot,
    wc: &Workcell,
    cfg: &PlanConfig,
    reach: f64,
    footprint: f64,
) -> RegionReport {
    let members = inspection.region_points(region.id);
    let cover = Cover::new(passes, region.id, footprint);
    let (mut reachable, mut covered_reachable, mut covered) = (0usize, 0usize, 0usize);
    for &i in &members {
        let sp = &inspection.points[i];
        let ok = tool_reaches(sp, robot, wc, cfg, reach);
        let near = cover.covers(&sp.position);
        reachable += usize::from(ok);
        covered += usize::from(near);
        covered_reachable += usize::from(ok && near);
    }
    let n = members.len().max(1) as f64;
    RegionReport {
        id: region.id,
        repairable: region.repairable,
        peak_mm: region.peak,
        peak_lower_bound: region.peak_lower_bound,
        touches_unmeasured: region.touches_unmeasured,
        area_mm2: region.area,
        layers,
        path_points,
        unreachable_path_points,
        points: members.len(),
        reachable_points: reachable,
        unreachable_share: 1.0 - reachable as f64 / n,
        coverage_of_reachable: if reachable == 0 {
            0.0
        } else {
            covered_reachable as f64 / reachable as f64
        },
        coverage_of_all: covered as f64 / n,
        setup: None,
        tool: None,
    }
}

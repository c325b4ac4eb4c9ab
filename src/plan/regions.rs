//! The regions of a plan in visiting order: rastered, walked and, in removal mode, given
//! their dwell.
use nalgebra::Point3;

use super::config::PlanConfig;
use super::error::PlanError;
use super::free_motion::Cell;
use super::inspection::{Inspection, RegionInfo, SurfacePoint};
use super::raster::RasterGeometry;
use super::report::Reachability;
use super::{collide, order, predict, preston, program, raster, removal, surface};

/// The regions planned, their runs and per region (layers, contact points); in removal mode
/// also the allowance each region's robust solve settled on.
pub(crate) struct Planned {
    pub(crate) runs: Vec<program::Run>,
    pub(crate) counts: std::collections::HashMap<usize, (usize, usize)>,
    pub(crate) allowances: Vec<(usize, f64)>,
    /// Removal mode: each region's walked runs before the dwell (to solve again).
    pub(crate) walked: std::collections::HashMap<usize, Vec<program::Run>>,
    /// Removal mode: each region's verdict as checked before assembling.
    pub(crate) rehearsed: predict::Rehearsed,
    /// Removal mode: each region's highest deviation in reach of its contacts, mm.
    pub(crate) highest: std::collections::HashMap<usize, f64>,
}

/// Rasters, solves and (in removal mode) sets the dwell of every repairable region in
/// visiting order, from the home tool tip over the region centroids.
pub(crate) fn plan_regions(
    inspection: &Inspection,
    ctx: &preston::Setup,
    tool: Option<&removal::ToolModel>,
    scene: &collide::Scene,
    reachability: &mut Reachability,
) -> Result<Planned, PlanError> {
    let (robot, workcell, config) = (ctx.robot, ctx.workcell, ctx.config);
    let radius_mm = robot.tool.radius * 1e3;
    let reach = radius_mm + config.contact_offset_mm;
    let geometry = match tool {
        None => config.geometry(radius_mm),
        Some(t) => removal_geometry(t, radius_mm, config),
    };
    let surface = surface::Surface::new(&inspection.points);
    let planned: Vec<&RegionInfo> = inspection
        .regions
        .iter()
        .filter(|r| r.repairable && !raster::layer_offsets(r.peak, &geometry).is_empty())
        .collect();
    let centroids: Vec<Point3<f64>> = planned
        .iter()
        .map(|r| workcell.point_from_reference_mm(&r.centroid.into()) * 1e3)
        .collect();
    let start = Point3::from(robot.fk(&config.home).position * 1e3);
    let visit = order::order(&start, &centroids);
    let mut out = Planned {
        runs: Vec::new(),
        counts: std::collections::HashMap::new(),
        allowances: Vec::new(),
        walked: std::collections::HashMap::new(),
        rehearsed: predict::Rehearsed::new(),
        highest: std::collections::HashMap::new(),
    };
    let cell = Cell::new(robot, workcell, config, scene);
    let mut prev = config.home.clone();
    for &k in &visit {
        let region = planned[k];
        let members: Vec<SurfacePoint> = inspection
            .region_points(region.id)
            .into_iter()
            .map(|i| inspection.points[i])
            .collect();
        let offsets = match tool {
            None => raster::layer_offsets(region.peak, &geometry),
            Some(t) => vec![-t.preload_mm],
        };
        let strokes = raster::raster_at(region, &members, &surface, &geometry, &offsets);
        let runs = program::walk(
            &strokes,
            robot,
            workcell,
            config,
            reach,
            scene,
            &mut prev,
            &mut reachability.unreachable,
            &mut reachability.jumps,
            tool.map(|t| t.tilt_deg.to_radians()),
        );
        if tool.is_some() {
            out.walked.insert(region.id, runs.clone());
        }
        let runs = match tool {
            None => runs,
            // nothing reachable: every point is already recorded with the reason
            Some(_) if runs.is_empty() => runs,
            Some(_) => {
                match preston::set_dwell(runs, region, inspection, ctx, config.allowance_mm)? {
                    Ok(dwelled) => settle(
                        dwelled,
                        region,
                        inspection,
                        ctx,
                        &cell,
                        &mut out,
                        reachability,
                    )?,
                    Err(reason) => {
                        preston::leave_out(
                            &strokes,
                            &reason,
                            workcell,
                            &mut reachability.unreachable,
                        );
                        Vec::new()
                    }
                }
            }
        };
        out.runs.extend(runs);
        let total: usize = strokes.iter().map(|s| s.points.len()).sum();
        out.counts.insert(region.id, (offsets.len(), total));
    }
    Ok(out)
}

/// Raster geometry of removal mode: lines and contacts spaced as shares of the tool's contact
/// patch radius (`removal.stepover_share`, `removal.spacing_share`), the patch as footprint;
/// one layer (the depth step spans any peak).
pub(crate) fn removal_geometry(
    tool: &removal::ToolModel,
    radius_mm: f64,
    config: &PlanConfig,
) -> RasterGeometry {
    let patch = removal::Influence::new(tool, radius_mm).patch_radius();
    RasterGeometry {
        stepover: config.removal.stepover_share * patch,
        footprint: patch,
        spacing: config.removal.spacing_share * patch,
        depth_step: f64::MAX,
        allowance: config.allowance_mm,
    }
}

/// A region's dwelled runs checked as the trajectory will grind them (`predict::rehearse`);
/// while the Monte Carlo on that dwell over-grinds, the region is solved again alone with its
/// allowance raised (`resolve`). Returns the runs to assemble (none when it is left out) and
/// records the allowance used.
fn settle(
    mut dwelled: preston::Dwelled,
    region: &RegionInfo,
    inspection: &Inspection,
    ctx: &preston::Setup,
    cell: &Cell,
    out: &mut Planned,
    reachability: &mut Reachability,
) -> Result<Vec<program::Run>, PlanError> {
    let id = region.id;
    let rehearsed = &mut out.rehearsed;
    while let Some(reason) = predict::rehearse_region(
        &dwelled.runs,
        (id, dwelled.allowance),
        cell,
        inspection,
        ctx,
        rehearsed,
    )? {
        let walked = out.walked.get(&id).map_or(&[][..], Vec::as_slice);
        let unreachable = &mut reachability.unreachable;
        let level = (dwelled.allowance, dwelled.highest);
        match resolve(walked, region, &reason, level, inspection, ctx, unreachable)? {
            Some(again) => dwelled = again,
            None => return Ok(Vec::new()),
        }
    }
    out.allowances.push((id, dwelled.allowance));
    out.highest.insert(id, dwelled.highest);
    Ok(dwelled.runs)
}

/// Solves a region that over-grinds for `reason` again from its `walked` runs with the
/// allowance raised from `allowance` by `removal::ALLOWANCE_STEP_SHARE` of the tolerance. Once
/// the allowance is above the `highest` deviation in reach (every dwell already at its
/// shortest), or when the solve fails, the region's pieces are left out with both reasons
/// and None comes back.
fn resolve(
    walked: &[program::Run],
    region: &RegionInfo,
    reason: &str,
    (allowance, highest): (f64, f64),
    inspection: &Inspection,
    ctx: &preston::Setup,
    unreachable: &mut Vec<super::report::UnreachablePoint>,
) -> Result<Option<preston::Dwelled>, PlanError> {
    let tolerance = inspection.tolerance.unwrap_or(ctx.config.tolerance_mm);
    let raised = allowance + removal::ALLOWANCE_STEP_SHARE * tolerance;
    let why = match allowance > highest {
        true => format!(
            "it over-grinds even with an allowance of {allowance:.3} mm, above the highest \
             deviation {highest:.3} mm (every dwell at its shortest)"
        ),
        false => match preston::set_dwell(walked.to_vec(), region, inspection, ctx, raised)? {
            Ok(again) => return Ok(Some(again)),
            Err(why) => why,
        },
    };
    for piece in walked.iter().flatten() {
        super::assemble::leave_out(piece, &format!("{reason}; {why}"), unreachable);
    }
    Ok(None)
}

/// Assembles the planned runs into the program and, in removal mode, predicts the part; a
/// region whose trajectory still over-grinds at the Monte Carlo's quantile once assembled
/// (the rehearsal before assembling did not know a chain the assembly left out) is solved
/// again (`resolve`) and the program assembled again; a region the robust solve refuses is
/// left out (its contacts recorded with the reason); the rest stands.
pub(crate) fn assemble_and_predict(
    mut planned: Planned,
    inspection: &Inspection,
    ctx: &preston::Setup,
    removal_mode: bool,
    scene: &collide::Scene,
    unreachable: &mut Vec<super::report::UnreachablePoint>,
) -> Result<(program::Program, Option<preston::RemovalReport>), PlanError> {
    loop {
        let mut left = Vec::new();
        let prog = super::assemble::assemble(
            planned.runs.clone(),
            ctx.robot,
            ctx.workcell,
            ctx.config,
            scene,
            &mut left,
        )?;
        if !removal_mode {
            unreachable.extend(left);
            return Ok((prog, None));
        }
        let (report, failed) = predict::predict(
            &prog,
            inspection,
            &planned.allowances,
            ctx,
            &planned.rehearsed,
        )?;
        if failed.is_empty() {
            unreachable.extend(left);
            return Ok((prog, Some(report)));
        }
        for (id, reason) in failed {
            let at = planned.runs.iter().position(|run| run[0].region == id);
            planned
                .runs
                .retain(|run| run.iter().all(|p| p.region != id));
            let slot = planned.allowances.iter().position(|a| a.0 == id);
            let old = slot.map_or(0.0, |k| planned.allowances[k].1);
            let highest = planned.highest.get(&id).copied().unwrap_or(0.0);
            planned.rehearsed.remove(&id);
            let region = inspection.regions.iter().find(|r| r.id == id);
            let walked = planned.walked.get(&id).cloned().unwrap_or_default();
            let again = match region {
                Some(r) => resolve(
                    &walked,
                    r,
                    &reason,
                    (old, highest),
                    inspection,
                    ctx,
                    unreachable,
                )?,
                None => None,
            };
            match (again, slot) {
                (Some(again), Some(k)) => {
                    planned.allowances[k].1 = again.allowance;
                    let at = at.unwrap_or(planned.runs.len()).min(planned.runs.len());
                    planned.runs.splice(at..at, again.runs);
                }
                (_, slot) => {
                    if let Some(k) = slot {
                        planned.allowances.remove(k);
                    }
                }
            }
        }
    }
}

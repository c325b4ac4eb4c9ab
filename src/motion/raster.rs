//! Grinding passes over one region: a zig-zag raster on the surface, repeated in depth layers.
//! Method: docs/ALGORITHMS.md, section "Grinding planner".
use nalgebra::{Matrix2, Point3, Vector2, Vector3};
use serde::{Deserialize, Serialize};

use super::surface::Surface;
use crate::repair::{RegionInfo, SurfacePoint};

/// What a stroke does.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum StrokeKind {
    /// A raster line across the region.
    Pass,
    /// The stepover from one raster line's end to the next line's start, in contact.
    Link,
}

/// One planned contact point (reference frame, mm).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathPoint {
    /// Point on the nominal surface, mm.
    pub surface: Point3<f64>,
    /// Outward unit normal there.
    pub normal: Vector3<f64>,
    /// Height of this layer's contact above the nominal surface, mm.
    pub offset: f64,
}

/// A straight-ish run of contact points ground at constant feed, at rest at both ends.
#[derive(Debug, Clone, PartialEq)]
pub struct Stroke {
    /// Region id.
    pub region: usize,
    /// Depth layer, 0 first (highest).
    pub layer: usize,
    /// Pass or link.
    pub kind: StrokeKind,
    /// Contact points in order.
    pub points: Vec<PathPoint>,
}

/// Raster geometry, millimetres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RasterGeometry {
    /// Distance between raster lines, mm.
    pub stepover: f64,
    /// Radius of the tool footprint on the surface, mm.
    pub footprint: f64,
    /// Spacing of contact points along a stroke, mm.
    pub spacing: f64,
    /// Depth removed per layer, mm.
    pub depth_step: f64,
    /// Material left above nominal after the last layer, mm.
    pub allowance: f64,
}

/// The depth layers of a region: contact heights above nominal, highest first (empty when
/// nothing lies above the allowance).
pub fn layer_offsets(peak: f64, g: &RasterGeometry) -> Vec<f64> {
    let excess = peak - g.allowance;
    if excess <= 0.0 {
        return Vec::new();
    }
    let n = (excess / g.depth_step - 1e-9).ceil().max(1.0) as usize;
    (1..=n)
        .map(|k| (peak - k as f64 * g.depth_step).max(g.allowance))
        .collect()
}

/// Strokes over `region` (its core points `members`) for every depth layer, in grinding order:
/// passes alternate direction, links join them, and each layer starts where the last ended.
pub fn raster(
    region: &RegionInfo,
    members: &[SurfacePoint],
    surface: &Surface,
    g: &RasterGeometry,
) -> Vec<Stroke> {
    raster_at(region, members, surface, g, &layer_offsets(region.peak, g))
}

/// Strokes over `region` as [`raster`] does, one layer per contact height of `offsets` (mm
/// above the nominal surface; the removal planner's single layer sits below it by the
/// preload).
pub fn raster_at(
    region: &RegionInfo,
    members: &[SurfacePoint],
    surface: &Surface,
    g: &RasterGeometry,
    offsets: &[f64],
) -> Vec<Stroke> {
    raster_turned(region, members, surface, g, offsets, 0.0)
}

/// Strokes over `region` as [`raster_at`] lays them, with the lines turned by `turn` rad
/// (about the region's normal) from the members' principal direction: the finishing
/// planner's cross-hatch (`motion::finish`).
pub fn raster_turned(
    region: &RegionInfo,
    members: &[SurfacePoint],
    surface: &Surface,
    g: &RasterGeometry,
    offsets: &[f64],
    turn: f64,
) -> Vec<Stroke> {
    let lines = raster_lines(region, members, g, turn);
    let mut out = Vec::new();
    let project = |uv: &[Point3<f64>], offset: f64| project(uv, surface, offset);
    let mut order: Vec<usize> = (0..lines.len()).collect();
    let mut forward = true;
    for (layer, &offset) in offsets.iter().enumerate() {
        let mut previous_end: Option<Point3<f64>> = None;
        for &i in &order {
            let mut line = lines[i].clone();
            if !forward {
                line.reverse();
            }
            forward = !forward;
            if let Some(end) = previous_end {
                let link = resample(&end, &line[0], g.spacing);
                out.push(Stroke {
                    region: region.id,
                    layer,
                    kind: StrokeKind::Link,
                    points: project(&link, offset),
                });
            }
            previous_end = line.last().copied();
            out.push(Stroke {
                region: region.id,
                layer,
                kind: StrokeKind::Pass,
                points: project(&line, offset),
            });
        }
        order.reverse();
    }
    out
}

/// The points `uv` (off the surface) projected onto `surface`, each a contact at `offset` mm
/// above it.
pub(crate) fn project(uv: &[Point3<f64>], surface: &Surface, offset: f64) -> Vec<PathPoint> {
    uv.iter()
        .map(|q| {
            let (surface_pt, normal) = surface.project(q);
            PathPoint {
                surface: surface_pt,
                normal,
                offset,
            }
        })
        .collect()
}

/// Points from `a` to `b` (both included) no farther apart than `spacing`.
pub(crate) fn resample(a: &Point3<f64>, b: &Point3<f64>, spacing: f64) -> Vec<Point3<f64>> {
    let n = ((b - a).norm() / spacing).ceil().max(1.0) as usize;
    (0..=n)
        .map(|k| a + (b - a) * (k as f64 / n as f64))
        .collect()
}

/// The raster lines in the region's tangent plane (points off the surface, to be projected):
/// lines along the principal direction of the members turned by `turn` rad, `stepover` apart,
/// centred on their spread; each line spans the members nearest to it.
fn raster_lines(
    region: &RegionInfo,
    members: &[SurfacePoint],
    g: &RasterGeometry,
    turn: f64,
) -> Vec<Vec<Point3<f64>>> {
    let c = Point3::from(region.centroid);
    let n = Vector3::from(region.normal).normalize();
    let (a, b) = crate::spatial::tangent_basis(&n);
    let uv: Vec<Vector2<f64>> = members
        .iter()
        .map(|p| Vector2::new((p.position - c).dot(&a), (p.position - c).dot(&b)))
        .collect();
    let mean = uv.iter().sum::<Vector2<f64>>() / uv.len().max(1) as f64;
    let cov = uv.iter().fold(Matrix2::zeros(), |m, p| {
        m + (p - mean) * (p - mean).transpose()
    });
    let eig = cov.symmetric_eigen();
    let k = if eig.eigenvalues[0] >= eig.eigenvalues[1] {
        0
    } else {
        1
    };
    let d: Vector2<f64> = eig.eigenvectors.column(k).into_owned();
    let (sin, cos) = turn.sin_cos();
    let d = Vector2::new(d.x * cos - d.y * sin, d.x * sin + d.y * cos);
    let e1 = (a * d.x + b * d.y).normalize();
    let e2 = n.cross(&e1);
    let coords: Vec<(f64, f64)> = members
        .iter()
        .map(|p| ((p.position - c).dot(&e1), (p.position - c).dot(&e2)))
        .collect();
    let (vmin, vmax) = coords
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), p| {
            (lo.min(p.1), hi.max(p.1))
        });
    if !vmin.is_finite() {
        return Vec::new();
    }
    let span = vmax - vmin;
    let count = if span <= 2.0 * g.footprint {
        1
    } else {
        ((span - 2.0 * g.footprint) / g.stepover).ceil() as usize + 1
    };
    let vc = 0.5 * (vmin + vmax);
    let v0 = vc - 0.5 * (count - 1) as f64 * g.stepover;
    let mut range = vec![(f64::INFINITY, f64::NEG_INFINITY); count];
    for (u, v) in &coords {
        let i = ((v - v0) / g.stepover)
            .round()
            .clamp(0.0, (count - 1) as f64) as usize;
        range[i] = (range[i].0.min(*u), range[i].1.max(*u));
    }
    range
        .iter()
        .enumerate()
        .filter(|(_, r)| r.0.is_finite())
        .map(|(i, &(u0, u1))| {
            let v = v0 + i as f64 * g.stepover;
            resample(&(c + e1 * u0 + e2 * v), &(c + e1 * u1 + e2 * v), g.spacing)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn layers_step_down_to_the_allowance() {
        let g = RasterGeometry {
            stepover: 2.4,
            footprint: 1.5,
            spacing: 0.5,
            depth_step: 0.1,
            allowance: 0.0,
        };
        let l = layer_offsets(0.25, &g);
        assert_eq!(l.len(), 3);
        assert!((l[0] - 0.15).abs() < 1e-12 && (l[1] - 0.05).abs() < 1e-12 && l[2] == 0.0);
        assert!(layer_offsets(-0.1, &g).is_empty());
        assert_eq!(layer_offsets(0.1, &g).len(), 1);
    }
}

//! Where synth puts things: defects on the articular surface clear of sharp edges and of each
//! other, and outliers off the surface.
use std::collections::HashMap;

use anyhow::{bail, Result};
use nalgebra::{Point3, Vector3};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::config::{SiteFilter, SiteProbe, SynthConfig};
use super::defects::{Defect, DefectKind};
use super::random::gauss;
use super::truth::OutlierTruth;
use crate::cloud::{sample_mesh, Mesh, PointCloud};
use crate::spatial::{tangent_basis, Neighbours, SparseGrid};

/// Points every `step` mm along the mesh's sharp edges (dihedral angle over 25 degrees) and
/// its open boundary edges.
fn sharp_edge_points(mesh: &Mesh, step: f64) -> Vec<Point3<f64>> {
    let mut edges: HashMap<(u32, u32), Vec<usize>> = HashMap::new();
    for (i, f) in mesh.faces.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (f[k], f[(k + 1) % 3]);
            edges.entry((a.min(b), a.max(b))).or_default().push(i);
        }
    }
    let cos_limit = 25f64.to_radians().cos();
    let mut out = Vec::new();
    for ((a, b), faces) in edges {
        let sharp = faces.len() != 2
            || mesh
                .face_normal_area(faces[0])
                .0
                .dot(&mesh.face_normal_area(faces[1]).0)
                < cos_limit;
        if sharp {
            let (pa, pb) = (mesh.vertices[a as usize], mesh.vertices[b as usize]);
            let n = ((pb - pa).norm() / step).ceil().max(1.0) as usize;
            out.extend((0..=n).map(|i| pa + (pb - pa) * (i as f64 / n as f64)));
        }
    }
    out
}

/// Probes around a site's footprint: a defect's rim at the part's edge turns its normal away
/// from the centre's, and an arm that reaches the centre square to the surface may not reach
/// the rim (issue 29's seeds 21 and 41: rim contacts 45-48 degrees off the arm plane). Eight
/// directions keep the gaps between probes under 0.8 x the radius.
const RIM_PROBES: usize = 8;

/// The site's probes for a [`SiteFilter`]: the centre with its normal, then the sampled surface
/// point nearest each of [`RIM_PROBES`] points `radius` mm from the centre in its tangent plane,
/// with that sample's own normal.
fn site_probes(
    p: &Point3<f64>,
    n: &Vector3<f64>,
    radius: f64,
    surface: &Neighbours,
    normals: &[Vector3<f64>],
) -> Vec<SiteProbe> {
    let (t1, t2) = tangent_basis(n);
    let rim = (0..RIM_PROBES).filter_map(|k| {
        let angle = std::f64::consts::TAU * k as f64 / RIM_PROBES as f64;
        let q = p + (t1 * angle.cos() + t2 * angle.sin()) * radius;
        surface
            .nearest(&q)
            .map(|hit| (surface.point(hit.index), normals[hit.index]))
    });
    std::iter::once((*p, *n)).chain(rim).collect()
}

/// Plants `cfg.defects` defects on the surface (on `articular` when given), each clear of
/// sharp edges by its support plus 1 mm and clear of the others.
pub fn place_defects(
    mesh: &Mesh,
    articular: Option<&Mesh>,
    cfg: &SynthConfig,
    accept: &SiteFilter,
    rng: &mut ChaCha8Rng,
) -> Result<Vec<Defect>> {
    if cfg.defects == 0 {
        return Ok(Vec::new());
    }
    let [hmin, hmax] = cfg.height_range;
    let [wmin, wmax] = cfg.width_range;
    anyhow::ensure!(
        0.0 < hmin && hmin <= hmax && 0.0 < wmin && wmin <= wmax,
        "height and width ranges must be positive and ordered"
    );
    let mut sharp = sharp_edge_points(mesh, 0.5);
    let on_articular = match articular {
        Some(a) => {
            sharp.extend(sharp_edge_points(a, 0.5));
            Some(SparseGrid::new(
                1.0,
                sample_mesh(a, 200_000, rng.gen())?.cloud.points,
            ))
        }
        None => None,
    };
    let sharp = SparseGrid::new(2.0, sharp);
    let candidates = sample_mesh(mesh, 20_000, rng.gen())?.cloud;
    let normals = candidates.normals.as_ref().expect("sampled normals");
    let surface = Neighbours::new(&candidates.points);
    let mut defects: Vec<Defect> = Vec::new();
    for (p, n) in candidates.points.iter().zip(normals) {
        if defects.len() == cfg.defects {
            break;
        }
        if let Some(grid) = &on_articular {
            if !grid.any_within(p, 0.3) {
                continue;
            }
        }
        let draw = rng.gen::<f64>();
        let kind = if draw < cfg.pit_share {
            DefectKind::Pit
        } else if draw < cfg.pit_share + cfg.ridge_share {
            DefectKind::Ridge
        } else {
            DefectKind::Bump
        };
        let height = rng.gen_range(hmin..=hmax) * if kind == DefectKind::Pit { -1.0 } else { 1.0 };
        let width = rng.gen_range(wmin..=wmax);
        let (direction, length) = if kind == DefectKind::Ridge {
            let v = Vector3::new(gauss(rng), gauss(rng), gauss(rng));
            let t = (v - n * n.dot(&v)).normalize();
            (t, (rng.gen_range(2.0..5.0) * width).max(1.0))
        } else {
            (Vector3::zeros(), 0.0)
        };
        let d = Defect {
            id: defects.len(),
            kind,
            centre: p.coords.into(),
            normal: (*n).into(),
            height,
            width,
            direction: direction.into(),
            length,
        };
        let reach = 2.0 * width + 1.0;
        let probes: Vec<Point3<f64>> = (-4..=4)
            .map(|k| p + direction * (length / 2.0) * (k as f64 / 4.0))
            .collect();
        if probes.iter().any(|q| sharp.any_within(q, reach)) {
            continue;
        }
        if let Some(grid) = &on_articular {
            if !probes.iter().all(|q| grid.any_within(q, 0.5)) {
                continue;
            }
        }
        let clear = |o: &Defect| {
            (Point3::from(o.centre) - p).norm()
                > 2.0 * (width + o.width) + (length + o.length) / 2.0 + 1.0
        };
        if defects.iter().all(clear)
            && accept(&site_probes(p, n, width + length / 2.0, &surface, normals))
        {
            defects.push(d);
        }
    }
    if defects.len() < cfg.defects {
        bail!("could place only {} of {} defects clear of edges and of each other; ask for fewer or smaller defects", defects.len(), cfg.defects);
    }
    Ok(defects)
}

/// Appends outliers to `points` (half scattered 2-15 mm off the surface and at least 2 mm from
/// every surface point, half in clusters of
/// 15-40 points 1-5 mm off it) and returns their indices.
pub fn add_outliers(
    points: &mut Vec<Point3<f64>>,
    surface: &PointCloud,
    share: f64,
    rng: &mut ChaCha8Rng,
) -> OutlierTruth {
    let n_surface = points.len();
    let total = (n_surface as f64 * share / (1.0 - share)).round() as usize;
    let normals = surface.normals.as_ref().expect("sampled normals");
    let mut truth = OutlierTruth {
        fraction: share,
        ..Default::default()
    };
    let pick = |rng: &mut ChaCha8Rng| {
        let k = rng.gen_range(0..n_surface);
        (points[k], normals[k])
    };
    let mut extra = Vec::with_capacity(total);
    let scattered = total / 2;
    // A scattered outlier must lie at least 2 mm from every surface point (a point closer
    // than that is indistinguishable from surface noise and would not be an outlier).
    let surface_index = Neighbours::new(&points[..]);
    let mut tries = 0usize;
    while truth.scattered.len() < scattered && tries < 100 * scattered.max(1) {
        tries += 1;
        let (p, n) = pick(rng);
        let jitter = Vector3::new(gauss(rng), gauss(rng), gauss(rng)) * 0.6;
        let dir = (n + jitter).normalize();
        let q = p + dir * rng.gen_range(2.0..15.0);
        if surface_index.nearest(&q).is_some_and(|nb| nb.dist2 < 4.0) {
            continue;
        }
        truth.scattered.push(n_surface + extra.len());
        extra.push(q);
    }
    let mut cluster_rng = ChaCha8Rng::seed_from_u64(rng.gen());
    while extra.len() < total {
        let (p, n) = pick(rng);
        let centre = p + n * cluster_rng.gen_range(1.0..5.0);
        let size = cluster_rng.gen_range(15..=40).min(total - extra.len());
        for _ in 0..size {
            let offset = Vector3::new(
                gauss(&mut cluster_rng),
                gauss(&mut cluster_rng),
                gauss(&mut cluster_rng),
            ) * 0.25;
            truth.clustered.push(n_surface + extra.len());
            extra.push(centre + offset);
        }
        truth.clusters += 1;
    }
    points.extend(extra);
    truth
}

//! The software rasteriser behind every figure: orthographic splats of the core points with a
//! depth buffer, remembering which point won each pixel (so a figure can tell which regions it
//! shows and where), then shaded deviation colours.
use nalgebra::{Point3, Vector3};
use plotters::style::RGBColor;

use super::colour::{diverging, shade};
use super::input::ReportInput;

/// No point in this pixel.
pub const NONE: u32 = u32::MAX;

/// An orthographic camera: the view direction (towards the viewer), the screen axes, the
/// point at the image centre (in screen coordinates, mm) and the scale.
#[derive(Debug, Clone)]
pub struct Camera {
    /// Screen right, unit.
    pub right: Vector3<f64>,
    /// Screen up, unit.
    pub up: Vector3<f64>,
    /// Towards the viewer, unit (`right × up`).
    pub towards: Vector3<f64>,
    /// (right, up) coordinates of the image centre, mm.
    pub centre: [f64; 2],
    /// Pixels per mm.
    pub px_per_mm: f64,
    /// Image width and height, px.
    pub size: (usize, usize),
    /// Side of a point's square splat, px.
    pub splat: i64,
    /// Each pixel shows the point nearest to it on screen rather than the front-most one (a
    /// close-up of one facing patch of surface: a mosaic without gaps at any zoom).
    pub nearest: bool,
}

impl Camera {
    /// A camera looking against `towards` with `up_hint` (made orthogonal) up; the rest of the
    /// fields start at one pixel per mm around the origin.
    pub fn looking(towards: Vector3<f64>, up_hint: Vector3<f64>, size: (usize, usize)) -> Camera {
        let towards = towards.normalize();
        let up = (up_hint - towards * up_hint.dot(&towards)).normalize();
        Camera {
            right: up.cross(&towards),
            up,
            towards,
            centre: [0.0, 0.0],
            px_per_mm: 1.0,
            size,
            splat: 2,
            nearest: false,
        }
    }

    /// (right, up) screen coordinates of `p`, mm.
    pub fn screen(&self, p: &Point3<f64>) -> [f64; 2] {
        [p.coords.dot(&self.right), p.coords.dot(&self.up)]
    }

    /// Pixel (x, y) of `p` (may be off the image).
    pub fn pixel(&self, p: &Point3<f64>) -> (f64, f64) {
        let [u, v] = self.screen(p);
        (
            self.size.0 as f64 / 2.0 + (u - self.centre[0]) * self.px_per_mm,
            self.size.1 as f64 / 2.0 - (v - self.centre[1]) * self.px_per_mm,
        )
    }
}

/// A rendered image: per pixel the index of the front-most point (or [`NONE`]).
#[derive(Debug, Clone)]
pub struct Raster {
    /// Width and height, px.
    pub size: (usize, usize),
    /// Winning point per pixel, row-major.
    pub idx: Vec<u32>,
}

/// Rasterises the points `keep` accepts that face the camera (normal towards the viewer).
pub fn raster(input: &ReportInput, cam: &Camera, keep: impl Fn(usize) -> bool) -> Raster {
    let (w, h) = cam.size;
    let mut depth = vec![f64::MIN; w * h];
    let mut idx = vec![NONE; w * h];
    let half = cam.splat / 2;
    for (i, p) in input.points.iter().enumerate() {
        if input.normals[i].dot(&cam.towards) < 0.0 || !keep(i) {
            continue;
        }
        let (fx, fy) = cam.pixel(p);
        let (x, y) = (fx as i64, fy as i64);
        if x + half < 0 || y + half < 0 || x - half >= w as i64 || y - half >= h as i64 {
            continue;
        }
        let d = p.coords.dot(&cam.towards);
        for py in (y - half).max(0)..=(y + half).min(h as i64 - 1) {
            for px in (x - half).max(0)..=(x + half).min(w as i64 - 1) {
                let k = py as usize * w + px as usize;
                let d = if cam.nearest {
                    let (dx, dy) = (px as f64 + 0.5 - fx, py as f64 + 0.5 - fy);
                    -(dx * dx + dy * dy)
                } else {
                    d
                };
                if d > depth[k] {
                    depth[k] = d;
                    idx[k] = i as u32;
                }
            }
        }
    }
    fill_holes(&mut idx, &mut depth, (w, h));
    Raster { size: (w, h), idx }
}

/// Closes the pinholes a random sample leaves between splats: an empty pixel with at least 5
/// of its 8 neighbours covered takes the point of the nearest (front-most) of them. Three
/// passes; the outline stays (a pixel outside a straight edge has 3 covered neighbours).
fn fill_holes(idx: &mut [u32], depth: &mut [f64], (w, h): (usize, usize)) {
    for _ in 0..3 {
        let (before, depth_before) = (idx.to_vec(), depth.to_vec());
        for y in 1..h.saturating_sub(1) {
            for x in 1..w - 1 {
                let i = y * w + x;
                if before[i] != NONE {
                    continue;
                }
                let covered = [
                    i - w - 1,
                    i - w,
                    i - w + 1,
                    i - 1,
                    i + 1,
                    i + w - 1,
                    i + w,
                    i + w + 1,
                ]
                .into_iter()
                .filter(|&j| before[j] != NONE)
                .map(|j| (depth_before[j], before[j]));
                let (n, front) = covered.fold((0, None), |(n, best), (d, p)| {
                    let nearer = best.is_none_or(|(bd, _)| d > bd);
                    (n + 1, if nearer { Some((d, p)) } else { best })
                });
                if let (true, Some((d, p))) = (n >= 5, front) {
                    idx[i] = p;
                    depth[i] = d;
                }
            }
        }
    }
}

/// The shaded deviation colour of every pixel (None where empty), lit from over the viewer's
/// shoulder.
pub fn colours(input: &ReportInput, cam: &Camera, r: &Raster, range: f64) -> Vec<Option<RGBColor>> {
    let light = (cam.towards + cam.up * 0.3 + cam.right * 0.2).normalize();
    r.idx
        .iter()
        .map(|&i| {
            (i != NONE).then(|| {
                let i = i as usize;
                shade(
                    diverging(input.distances[i], range),
                    input.normals[i].dot(&light),
                )
            })
        })
        .collect()
}

/// A square splat side that closes the gaps between points `spacing_mm` apart in a random
/// sample: twice the spacing, px.
pub fn splat_for(spacing_mm: f64, px_per_mm: f64, max: i64) -> i64 {
    ((spacing_mm * px_per_mm * 2.0).ceil() as i64).clamp(2, max)
}

/// Per region id: how many pixels show it and their mean pixel position.
pub fn region_pixels(r: &Raster, labels: &[i64], regions: usize) -> Vec<(usize, [f64; 2])> {
    let mut acc = vec![(0usize, [0.0f64; 2]); regions];
    if labels.is_empty() {
        return acc;
    }
    for (k, &i) in r.idx.iter().enumerate() {
        if i == NONE {
            continue;
        }
        let l = labels[i as usize];
        if l >= 0 && (l as usize) < regions {
            let a = &mut acc[l as usize];
            a.0 += 1;
            a.1[0] += (k % r.size.0) as f64;
            a.1[1] += (k / r.size.0) as f64;
        }
    }
    for a in &mut acc {
        if a.0 > 0 {
            a.1[0] /= a.0 as f64;
            a.1[1] /= a.0 as f64;
        }
    }
    acc
}

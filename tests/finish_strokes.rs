//! Finishing strokes (issue 50, item 4) on a unit scale: a flat plate ground by the planner's
//! own strokes (`motion::finish::strokes`: one parallel raster, or the finish's cross-hatch)
//! under the removal model (`removal::Influence`, each contact's column as the planner builds
//! A), at a constant feed, with a random tool-tip error planted per stroke: 0.15 mm RMS
//! (0.0866 mm per axis; along the surface it moves the stroke, along the normal it changes the
//! force by error / preload), the documented arm's residual after compensation, different
//! from stroke to stroke (backlash flank, read-back noise). The per-point removal spread is
//! the standard deviation of a point's removal over the error draws, over the mean removal,
//! averaged over the plate's interior; the map spread is one draw's standard deviation over
//! the interior, over its mean (the raster's own ripple included).
//! Numbers: docs/ALGORITHMS.md, "Finishing strokes".
use nalgebra::{Point3, Vector3};
use polishbot::motion::finish::{self, FinishConfig};
use polishbot::motion::raster::{RasterGeometry, Stroke, StrokeKind};
use polishbot::motion::surface::Surface;
use polishbot::removal::{influence, Contact, Influence, RemovalConfig, ToolModel};
use polishbot::repair::{RegionInfo, SurfacePoint};
use rand::rngs::StdRng;
use rand::{Rng, SeedableRng};

/// The shipped tool's ball radius, mm (calibration/tool.toml `radius = 0.003`).
const BALL_MM: f64 = 3.0;
/// The arm's random tip error after compensation, mm RMS over the three axes.
const TIP_ERROR_MM: f64 = 0.15;
/// Error draws per layout.
const DRAWS: usize = 24;
/// The plate's half sizes, mm (longer along x, so the raster's principal direction is x).
const HALF: (f64, f64) = (6.0, 5.0);
/// Core point pitch, mm.
const PITCH: f64 = 0.1;
/// The interior judged: this far inside the plate's edge, mm (the lines end a patch inside
/// the members, and the spread near an edge is the edge's).
const INSIDE: f64 = 2.5;

/// The flat plate's core points (z = 0, normal +z), all in region 0.
fn plate() -> Vec<SurfacePoint> {
    let (nx, ny) = ((HALF.0 / PITCH) as i64, (HALF.1 / PITCH) as i64);
    let mut out = Vec::new();
    for i in -nx..=nx {
        for j in -ny..=ny {
            out.push(SurfacePoint {
                position: Point3::new(i as f64 * PITCH, j as f64 * PITCH, 0.0),
                normal: Vector3::z(),
                distance: 0.1,
                uncertainty: 0.005,
                region: 0,
            });
        }
    }
    out
}

fn region(points: usize) -> RegionInfo {
    serde_json::from_value(serde_json::json!({
        "id": 0, "centroid": [0.0, 0.0, 0.0], "normal": [0.0, 0.0, 1.0],
        "area": 4.0 * HALF.0 * HALF.1, "peak": 0.1, "mean": 0.1, "volume": 1.0,
        "points": points, "repairable": true
    }))
    .unwrap()
}

/// The removal planner's raster geometry for `tool` (`by_region::removal_geometry`: lines and
/// contacts spaced as shares of the patch radius).
fn geometry(tool: &ToolModel) -> RasterGeometry {
    let patch = Influence::new(tool, BALL_MM).patch_radius();
    let cfg = RemovalConfig::default();
    RasterGeometry {
        stepover: cfg.stepover_share * patch,
        footprint: patch,
        spacing: cfg.spacing_share * patch,
        depth_step: f64::MAX,
        allowance: 0.0,
    }
}

/// A standard normal draw (Box-Muller).
fn gauss(rng: &mut StdRng) -> f64 {
    let u: f64 = rng.gen_range(f64::EPSILON..1.0);
    let v: f64 = rng.gen_range(0.0..1.0);
    (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// The contacts of the passes of `strokes` (two-point pieces; the links, at the raster's
/// ends and from one raster's end to the next's start, are left out: the planner's dwell
/// solve, not a constant feed, sets their removal) with one tip error per stroke drawn from
/// `rng` (`None`: no error); the spindle held 20 degrees from the normal, leaning along +x.
fn contacts(strokes: &[Stroke], preload: f64, rng: Option<&mut StdRng>) -> Vec<Contact> {
    let sigma = TIP_ERROR_MM / 3f64.sqrt();
    let mut rng = rng;
    let tilt = 20f64.to_radians();
    let spin = Vector3::new(tilt.sin(), 0.0, -tilt.cos());
    let mut out = Vec::new();
    for s in strokes.iter().filter(|s| s.kind == StrokeKind::Pass) {
        let e = match rng.as_deref_mut() {
            Some(r) => Vector3::new(gauss(r), gauss(r), gauss(r)) * sigma,
            None => Vector3::zeros(),
        };
        for w in s.points.windows(2) {
            let (a, b) = (w[0].surface, w[1].surface);
            let d = b - a;
            out.push(Contact {
                point: a + d * 0.5 + Vector3::new(e.x, e.y, 0.0),
                normal: Vector3::z(),
                along: d.normalize(),
                spin,
                length: d.norm(),
                // the tip e.z above its command presses e.z less deep
                force_ratio: (1.0 - e.z / preload).max(0.0),
                offset: Vector3::zeros(),
                depth_mm: preload,
            });
        }
    }
    out
}

/// What one layout removes, and how it spreads.
struct Spread {
    /// Mean over the interior of each point's standard deviation over the draws, over the
    /// mean removal.
    per_point: f64,
    /// Mean over the draws of the interior's standard deviation over its mean.
    map: f64,
    /// The same map spread with no error (the layout's own ripple).
    ripple: f64,
    /// Strokes in contact per interior point (within a patch radius of one of its contacts).
    strokes_per_point: f64,
}

/// The spread of a plate ground by `cfg`'s strokes for its grind (its tool, its turns), at a
/// constant feed.
fn spread(cfg: &FinishConfig, seed: u64) -> Spread {
    let cores = plate();
    let region = region(cores.len());
    let surface = Surface::new(&cores);
    let tool = cfg.tool(ToolModel::default());
    let g = geometry(&tool);
    let influence = Influence::new(&tool, BALL_MM);
    let strokes = finish::strokes(
        (&region, &cores),
        &surface,
        &g,
        &[-tool.preload_mm],
        &cfg.turns(),
    );
    let geometry: Vec<_> = cores.iter().map(|c| (c.position, c.normal)).collect();
    let inside: Vec<usize> = (0..cores.len())
        .filter(|&i| {
            let p = cores[i].position;
            p.x.abs() <= HALF.0 - INSIDE && p.y.abs() <= HALF.1 - INSIDE
        })
        .collect();
    let removal = |c: &[Contact]| {
        let a = influence::matrix(&influence, c, &geometry);
        let t: Vec<f64> = c.iter().map(|c| c.length).collect();
        let r = influence::apply(&a, &t, cores.len());
        inside.iter().map(|&i| r[i]).collect::<Vec<f64>>()
    };
    let stats = |v: &[f64]| {
        let m = v.iter().sum::<f64>() / v.len() as f64;
        let sd = (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / v.len() as f64).sqrt();
        (m, sd)
    };
    let nominal = contacts(&strokes, tool.preload_mm, None);
    let (m0, sd0) = stats(&removal(&nominal));
    let mut rng = StdRng::seed_from_u64(seed);
    let draws: Vec<Vec<f64>> = (0..DRAWS)
        .map(|_| removal(&contacts(&strokes, tool.preload_mm, Some(&mut rng))))
        .collect();
    let map = draws.iter().map(|d| stats(d).1 / stats(d).0).sum::<f64>() / DRAWS as f64;
    let per_point = (0..inside.len())
        .map(|k| stats(&draws.iter().map(|d| d[k]).collect::<Vec<_>>()).1)
        .sum::<f64>()
        / inside.len() as f64
        / m0;
    let patch = influence.patch_radius();
    let strokes_per_point = inside
        .iter()
        .map(|&i| {
            let p = cores[i].position;
            let near = |s: &&Stroke| s.points.iter().any(|q| (q.surface - p).norm() < patch);
            strokes.iter().filter(near).count() as f64
        })
        .sum::<f64>()
        / inside.len() as f64;
    Spread {
        per_point,
        map,
        ripple: sd0 / m0,
        strokes_per_point,
    }
}

/// The settings of the loop's grind `n` with the finish on from grind 2 (it is off by default:
/// `motion::finish::FINISH_FROM_GRIND`).
fn grind(n: usize) -> FinishConfig {
    FinishConfig {
        grind: n,
        from_grind: 2,
        ..FinishConfig::default()
    }
}

fn show(name: &str, s: &Spread) {
    println!(
        "{name}: per-point spread {:.4}, map spread {:.4}, ripple {:.4}, {:.1} strokes per point",
        s.per_point, s.map, s.ripple, s.strokes_per_point
    );
}

/// The cross-hatch at the same tool averages the per-stroke error: its per-point removal
/// spread is at least 1.25 x smaller than one parallel raster's (independent errors over
/// twice the strokes: sqrt(2) = 1.41); the finish as planned (the cross-hatch at 0.8 of the
/// preload, whose normal error weighs 1/0.8 more) is still at least 1.2 x smaller than the
/// first grind's raster, and a third direction would take it further.
#[test]
fn a_cross_hatch_averages_the_arms_random_tip_error() {
    let raster = spread(&grind(1), 7);
    let at = |preload_share: f64, directions: usize| FinishConfig {
        preload_share,
        directions,
        ..grind(2)
    };
    let hatch_same_tool = spread(&at(1.0, 2), 7);
    let finish = spread(&grind(2), 7);
    let later = spread(&grind(3), 7);
    let softer = spread(&at(0.6, 2), 7);
    let three = spread(&at(FinishConfig::default().preload_share, 3), 7);
    show("raster (grind 1, preload 2 mm)", &raster);
    show("cross-hatch 0/90 deg, preload 2 mm", &hatch_same_tool);
    show(
        "finish (grind 2: cross-hatch 0/90 deg, preload 1.6 mm)",
        &finish,
    );
    show("finish (grind 3: 137.5/47.5 deg, preload 1.6 mm)", &later);
    show("cross-hatch 0/90 deg, preload 1.2 mm", &softer);
    show("three directions 0/60/120 deg, preload 1.6 mm", &three);
    let same = raster.per_point / hatch_same_tool.per_point;
    let planned = raster.per_point / finish.per_point;
    println!(
        "per-point spread, raster over cross-hatch: {same:.2} (same tool), {planned:.2} \
         (finish as planned), {:.2} (preload 1.2 mm), {:.2} (three directions)",
        raster.per_point / softer.per_point,
        raster.per_point / three.per_point
    );
    assert!(
        hatch_same_tool.strokes_per_point > 1.8 * raster.strokes_per_point,
        "the cross-hatch should touch each point with about twice the strokes"
    );
    assert!(
        same >= 1.25,
        "cross-hatch reduced the spread only {same:.2} x"
    );
    assert!(
        planned >= 1.2,
        "the finish reduced the spread only {planned:.2} x"
    );
    assert!(later.per_point <= finish.per_point * 1.15);
    assert!(three.per_point < finish.per_point);
    // the error is what spreads it: with none, each layout's own ripple is far smaller
    for s in [&raster, &hatch_same_tool, &finish, &later] {
        assert!(
            s.ripple < 0.5 * s.map,
            "ripple {:.4} map {:.4}",
            s.ripple,
            s.map
        );
    }
}

//! The synthetic scenes the collision tests plan on: labelled surface points and their
//! region records, and the slotted face, the wedge and the cylinder built from them.
use nalgebra::{Matrix4, Point3, Vector3};
use polishbot::motion::{Inspection, RegionInfo, SurfacePoint};
use polishbot::robot::Workcell;

/// Region records for the labelled `points` (peak = largest distance).
pub(super) fn inspection(points: Vec<SurfacePoint>) -> Inspection {
    let ids: std::collections::BTreeSet<i64> = points
        .iter()
        .map(|p| p.region)
        .filter(|r| *r >= 0)
        .collect();
    let regions = ids
        .into_iter()
        .map(|id| {
            let m: Vec<&SurfacePoint> = points.iter().filter(|p| p.region == id).collect();
            let n = m.len() as f64;
            let c = m
                .iter()
                .fold(Vector3::zeros(), |s, p| s + p.position.coords)
                / n;
            let nn = m
                .iter()
                .fold(Vector3::zeros(), |s, p| s + p.normal)
                .normalize();
            RegionInfo {
                id: id as usize,
                centroid: [c.x, c.y, c.z],
                normal: [nn.x, nn.y, nn.z],
                area: n * 0.25,
                peak: m.iter().map(|p| p.distance).fold(0.0, f64::max),
                peak_lower_bound: false,
                mean: m.iter().map(|p| p.distance).sum::<f64>() / n,
                volume: 1.0,
                points: m.len(),
                repairable: true,
                measured_share: 1.0,
                touches_unmeasured: false,
            }
        })
        .collect();
    Inspection {
        dir: "collision-test".into(),
        tolerance: Some(0.05),
        regions,
        points,
        fine: Vec::new(),
    }
}

/// A surface point at `p` with the unit normal along `n`, its `distance` and `region`.
pub(super) fn point(p: Point3<f64>, n: Vector3<f64>, distance: f64, region: i64) -> SurfacePoint {
    SurfacePoint {
        position: p,
        normal: n.normalize(),
        distance,
        uncertainty: 0.0,
        region,
    }
}

/// A grid of `step` over `[-a, a] x [-b, b]` spanned by `u`, `v` about `o`.
pub(super) fn grid(
    o: Point3<f64>,
    u: Vector3<f64>,
    v: Vector3<f64>,
    a: f64,
    b: f64,
    step: f64,
) -> Vec<Point3<f64>> {
    let (na, nb) = ((a / step).round() as i64, (b / step).round() as i64);
    (-na..=na)
        .flat_map(|i| (-nb..=nb).map(move |k| o + u * (i as f64 * step) + v * (k as f64 * step)))
        .collect()
}

/// The front face the default workcell turns to the arm (reference y = -35, normal -y) with
/// a slot 4 mm wide and 3 mm deep across it (narrower than the 6 mm ball): region 0 on the
/// slot's floor, region 1 a bump on the open face beside it.
pub(super) fn slotted_face() -> Inspection {
    let (x0, half, depth) = (5.0, 2.0, 3.0);
    let mut pts = Vec::new();
    let face = grid(
        Point3::new(0.0, -35.0, -25.0),
        Vector3::x(),
        Vector3::z(),
        20.0,
        20.0,
        0.5,
    );
    for p in face.into_iter().filter(|p| (p.x - x0).abs() >= half) {
        let bump = ((p - Point3::new(-8.0, -35.0, -25.0)).norm() <= 4.0).then_some(0.25);
        pts.push(point(
            p,
            -Vector3::y(),
            bump.unwrap_or(0.0),
            bump.map_or(-1, |_| 1),
        ));
    }
    let floor = grid(
        Point3::new(x0, -35.0 + depth, -25.0),
        Vector3::x(),
        Vector3::z(),
        1.5,
        20.0,
        0.5,
    );
    for p in floor {
        let inside = (p.z + 25.0).abs() <= 8.0;
        pts.push(point(
            p,
            -Vector3::y(),
            if inside { 0.3 } else { 0.0 },
            if inside { 0 } else { -1 },
        ));
    }
    for (x, n) in [(x0 - half, Vector3::x()), (x0 + half, -Vector3::x())] {
        let wall = grid(
            Point3::new(x, -35.0 + depth / 2.0, -25.0),
            Vector3::y(),
            Vector3::z(),
            1.0,
            20.0,
            0.5,
        );
        pts.extend(wall.into_iter().map(|p| point(p, n, 0.0, -1)));
    }
    inspection(pts)
}

/// A wedge whose nose points at the arm (reference = robot axes in mm, nose along x at the
/// origin, the faces' normals 30 degrees above and below the horizontal) with a bump on its
/// upper and its lower face.
pub(super) fn wedge() -> (Inspection, Workcell) {
    let mut pts = Vec::new();
    let s = 30f64.to_radians();
    for sign in [1.0, -1.0] {
        let along = Vector3::new(0.0, s.sin(), sign * s.cos());
        let normal = Vector3::new(0.0, -s.cos(), sign * s.sin());
        let centre = Point3::origin() + along * 15.0;
        for p in grid(centre, Vector3::x(), along, 15.0, 15.0, 0.5) {
            let bump = (p - (Point3::origin() + along * 14.0)).norm() <= 4.0;
            let region = if bump { i64::from(sign < 0.0) } else { -1 };
            pts.push(point(p, normal, if bump { 0.15 } else { 0.0 }, region));
        }
    }
    let wc = Workcell {
        robot_from_reference: Matrix4::new_translation(&Vector3::new(0.0, 0.24, 0.2)),
    };
    (inspection(pts), wc)
}

/// The front of a horizontal cylinder (reference frame = robot axes, mm; axis along x) with
/// a defect long along the axis: its raster lines run along the axis at different heights with
/// different normals, so the tool turns at the contacts where one stroke meets the next.
pub(super) fn cylinder() -> (Inspection, Workcell) {
    let radius = 20.0;
    let mut pts = Vec::new();
    let step = 0.5 / radius;
    for i in -50..=50 {
        let a = f64::from(i) * step;
        let normal = Vector3::new(0.0, -a.cos(), a.sin());
        for k in -30..=30 {
            let p = Point3::origin() + normal * radius + Vector3::x() * (f64::from(k) * 0.5);
            let bump = (a * radius).abs() <= 5.0 && p.x.abs() <= 12.0;
            pts.push(point(
                p,
                normal,
                if bump { 0.12 } else { 0.0 },
                if bump { 0 } else { -1 },
            ));
        }
    }
    let wc = Workcell {
        robot_from_reference: Matrix4::new_translation(&Vector3::new(0.0, 0.28, 0.2)),
    };
    (inspection(pts), wc)
}

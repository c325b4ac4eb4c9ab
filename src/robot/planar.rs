//! The closed-form geometry of a DOFBOT-structured chain (base yaw about a vertical axis, three
//! parallel horizontal pitch axes, wrist roll about the tool axis), read from the chain at its
//! zero pose. The model computes it once; the IK solves with it (`ik.rs`).
use nalgebra::{Isometry3, Vector2, Vector3};

/// Geometry of a DOFBOT-structured chain, read from k's chain at the zero pose: everything in
/// the arm plane as (r, z), r horizontal from the base axis along the plane direction.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Planar {
    pub(super) base: Vector2<f64>,
    pub(super) phi0: f64,
    pub(super) s1: f64,
    pub(super) sigma: [f64; 3],
    pub(super) p2: Vector2<f64>,
    pub(super) l23: f64,
    pub(super) beta23: f64,
    pub(super) l34: f64,
    pub(super) beta34: f64,
    pub(super) tip4: Vector2<f64>,
    pub(super) alpha0: f64,
}

/// Tolerance of the structure test (axes parallel or perpendicular, points in the arm plane),
/// m or unitless: a numerical zero, since a DOFBOT URDF states its geometry exactly.
const STRUCTURE_TOL: f64 = 1e-12;

impl Planar {
    /// The closed-form parameters from a five-joint chain at its zero pose (the actuated
    /// joints' world frames and axes, the tool tip and the tool axis), or `None` when the chain
    /// is not DOFBOT-shaped.
    pub(crate) fn from_zero_pose(
        frames: &[Isometry3<f64>],
        axes: &[Vector3<f64>],
        tool_position: Vector3<f64>,
        tool_axis: Vector3<f64>,
    ) -> Option<Planar> {
        let z = Vector3::z();
        let a1 = axes[0].normalize();
        if a1.xy().norm() > STRUCTURE_TOL {
            return None;
        }
        let n0 = axes[1].normalize();
        if n0.z.abs() > STRUCTURE_TOL
            || axes[2..4]
                .iter()
                .any(|a| a.normalize().cross(&n0).norm() > STRUCTURE_TOL)
        {
            return None;
        }
        let b = frames[0].translation.vector;
        let u0 = z.cross(&n0);
        let pos = |i: usize| frames[i].translation.vector;
        let lateral = |p: Vector3<f64>| ((p - b).dot(&n0)).abs();
        let points = [pos(1), pos(2), pos(3), pos(4), tool_position];
        if points.iter().any(|p| lateral(*p) > STRUCTURE_TOL)
            || tool_axis.dot(&n0).abs() > STRUCTURE_TOL
        {
            return None;
        }
        let a5 = axes[4].normalize();
        if a5.cross(&tool_axis).norm() > STRUCTURE_TOL
            || (tool_position - pos(4)).cross(&a5).norm() > STRUCTURE_TOL
        {
            return None;
        }
        let plane = |p: Vector3<f64>| Vector2::new((p - b).dot(&u0), p.z);
        let (p2, p3, p4, t) = (
            plane(pos(1)),
            plane(pos(2)),
            plane(pos(3)),
            plane(tool_position),
        );
        let angle = |v: Vector2<f64>| v.y.atan2(v.x);
        Some(Planar {
            base: b.xy(),
            phi0: u0.y.atan2(u0.x),
            s1: a1.z.signum(),
            sigma: [1, 2, 3].map(|i| axes[i].dot(&n0).signum()),
            p2,
            l23: (p3 - p2).norm(),
            beta23: angle(p3 - p2),
            l34: (p4 - p3).norm(),
            beta34: angle(p4 - p3),
            tip4: t - p4,
            alpha0: tool_axis.z.atan2(tool_axis.dot(&u0)),
        })
    }
}

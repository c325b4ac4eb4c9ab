//! The removal of a pass contact by contact in the order the tool grinds them: each contact is
//! pressed on the part as the contacts before it left it (its force from the deviation that is
//! left, its normal from that surface's slope, `press::press`), where the linear model `A t`
//! presses every contact on the part as measured (with the mid-pass force). A bump's top goes
//! down during the pass, so the later contacts press it with less force and meet a flatter
//! surface whose normal has turned back towards nominal, which at the spindle's tilt changes the
//! abrasive's speed by cot(tilt) per radian. Method: docs/ALGORITHMS.md, "Removal planning".
use super::influence::{Contact, Influence, Reach};
use super::press::press;
use super::tool::ToolModel;
use crate::repair::SurfacePoint;

/// The removal at every one of `cores` (mm) of `contacts` (as the raster placed them: the
/// nominal point and normal, not yet pressed) ground in order for `dwell` s each; `reach`
/// indexes the same core points (the caller's, which its A was built on).
pub fn in_order(
    contacts: &[Contact],
    dwell: &[f64],
    tool: &ToolModel,
    influence: &Influence,
    (cores, reach): (&[SurfacePoint], &Reach),
) -> Vec<f64> {
    let mut part = cores.to_vec();
    let mut removed = vec![0.0; cores.len()];
    for (placed, &t) in contacts.iter().zip(dwell) {
        if t <= 0.0 {
            continue;
        }
        let mut c = [*placed];
        // no allowance: the force is the penetration into the part as it is now
        press(
            &mut c,
            tool,
            influence,
            (&part, reach.neighbours()),
            f64::INFINITY,
        );
        for (j, v) in reach.column(influence, &c[0]) {
            removed[j] += v * t;
            part[j].distance -= v * t;
        }
    }
    removed
}

#[cfg(test)]
mod tests {
    use super::super::influence::apply;
    use super::*;
    use nalgebra::{Point3, Vector3};

    /// A flat part 0.1 mm above nominal ground at one spot for two seconds in order: the first
    /// second presses with 2.1 mm of penetration and leaves a dip, and the second presses on
    /// it. The force drops by the dip (0.01 mm of 2.1, so Hertz's centre pressure, as the
    /// force^(1/3), by 0.2 %); the dip is deeper on the side the tilted spindle turns faster,
    /// and its slope turns the normal and the abrasive's speed at the centre (cot 20 deg = 2.7
    /// per radian): the second second removes 1-3 % less than the first. The linear model
    /// presses both on the part as measured and removes exactly twice.
    #[test]
    fn a_spot_ground_twice_in_order_presses_less_the_second_time() {
        let cores: Vec<SurfacePoint> = (0..41 * 41)
            .map(|i| SurfacePoint {
                position: Point3::new(
                    0.05 * (i % 41) as f64 - 1.0,
                    0.05 * (i / 41) as f64 - 1.0,
                    0.0,
                ),
                normal: Vector3::z(),
                distance: 0.1,
                uncertainty: 0.0,
                region: 0,
            })
            .collect();
        let tool = ToolModel::default();
        let influence = Influence::new(&tool, 3.0);
        let spot = Contact {
            point: Point3::origin(),
            normal: Vector3::z(),
            along: Vector3::x(),
            spin: -Vector3::new(20f64.to_radians().sin(), 0.0, 20f64.to_radians().cos()),
            length: 0.0,
            force_ratio: 1.0,
            offset: Vector3::zeros(),
            depth_mm: tool.preload_mm,
        };
        let centre = 20 * 41 + 20;
        let geometry: Vec<_> = cores.iter().map(|c| (c.position, c.normal)).collect();
        let reach = Reach::new(&geometry);
        let once = in_order(
            std::slice::from_ref(&spot),
            &[1.0],
            &tool,
            &influence,
            (&cores, &reach),
        )[centre];
        let twice = in_order(
            &[spot, spot],
            &[1.0, 1.0],
            &tool,
            &influence,
            (&cores, &reach),
        )[centre];
        assert!(once > 0.001, "{once}");
        let second = (twice - once) / once;
        assert!(second > 0.97 && second < 0.99, "{once} {twice}");
        let mut pressed = [spot, spot];
        press(
            &mut pressed,
            &tool,
            &influence,
            (&cores, reach.neighbours()),
            f64::INFINITY,
        );
        let a = reach.matrix(&influence, &pressed);
        let linear = apply(&a, &[1.0, 1.0], cores.len())[centre];
        assert!(
            (linear - 2.0 * once).abs() < 1e-12 * once,
            "{linear} {once}"
        );
    }
}

//! Further fixturings of the part in the designed cell (issue 51): the same table axis, place
//! and shank, the part turned on its fixture so that another of its directions lies along the
//! table axis. Faces whose normals lie along the first mounting's axis never turn into the
//! arm plane, whatever the table angle (on a femoral component the intercondylar notch walls
//! and the condyles' side faces); mounted another way they roll through it. A sample counts
//! as reached by the setups together when one of them reaches it; the operator re-fixtures
//! the part between setups. Setups are added greedily, each the mounting that reaches most of
//! what the earlier ones leave.
use nalgebra::Vector3;
use rayon::prelude::*;
use serde::Serialize;

use super::config::DesignConfig;
use super::eval::{score, Candidate, Context};

/// One fixturing of the part and what it reaches.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Fixturing {
    /// The part's direction along the table axis (reference frame, unit).
    pub mount: [f64; 3],
    /// Share of the samples this setup reaches alone.
    pub coverage: f64,
    /// Share of the samples this setup and the ones before it reach together.
    pub union_coverage: f64,
}

/// Mountings tried for a further setup: directions at each of `tilts_deg` from `first`,
/// every `azimuth_step_deg` about it.
fn mountings(first: &[f64; 3], tilts_deg: &[f64], azimuth_step_deg: f64) -> Vec<[f64; 3]> {
    let m = Vector3::from(*first).normalize();
    let side = if m.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    let p1 = m.cross(&side).normalize();
    let p2 = m.cross(&p1);
    let steps = (360.0 / azimuth_step_deg).round().max(1.0) as usize;
    let mut out = Vec::new();
    for &tilt in tilts_deg {
        let t = tilt.to_radians();
        for k in 0..steps {
            let a = (k as f64 * azimuth_step_deg).to_radians();
            let v = m * t.cos() + (p1 * a.cos() + p2 * a.sin()) * t.sin();
            out.push([v.x, v.y, v.z]);
        }
    }
    out
}

/// The setups of `first` (whose samples reached are `reached`, on the first `n` samples with
/// table angles every `step_deg`): the first itself, then up to `cfg.setups - 1` further
/// mountings (`cfg.setup_tilts_deg`, `cfg.setup_azimuth_step_deg`), each the one reaching
/// most of what the setups before it leave (none added once one adds nothing).
pub fn setups(
    ctx: &Context,
    first: &Candidate,
    reached: &[bool],
    cfg: &DesignConfig,
    step_deg: f64,
) -> Vec<Fixturing> {
    let count = cfg.setups;
    let n = reached.len().max(1) as f64;
    let share = |r: &[bool]| r.iter().filter(|&&x| x).count() as f64 / n;
    let mut union = reached.to_vec();
    let mut out = vec![Fixturing {
        mount: first.mount,
        coverage: share(reached),
        union_coverage: share(reached),
    }];
    let tried = mountings(
        &first.mount,
        &cfg.setup_tilts_deg,
        cfg.setup_azimuth_step_deg,
    );
    while out.len() < count {
        let scored: Vec<([f64; 3], Vec<bool>)> = tried
            .par_iter()
            .filter_map(|&mount| {
                let c = Candidate {
                    mount,
                    ..first.clone()
                };
                let s = score(ctx, &c, reached.len(), step_deg, true)?;
                Some((
                    mount,
                    s.verdicts.iter().map(|v| v.angle_deg.is_some()).collect(),
                ))
            })
            .collect();
        let gain = |r: &[bool]| r.iter().zip(&union).filter(|(&a, &u)| a && !u).count();
        let Some((mount, r)) = scored.into_iter().max_by_key(|(_, r)| gain(r)) else {
            break;
        };
        if gain(&r) == 0 {
            break;
        }
        for (u, &a) in union.iter_mut().zip(&r) {
            *u |= a;
        }
        out.push(Fixturing {
            mount,
            coverage: share(&r),
            union_coverage: share(&union),
        });
    }
    out
}

//! The check of samples one after another ([`Sweep`]): what it carries from sample to sample
//! and why a search it skips could have found nothing.
use nalgebra::{Point3, Vector3};

use super::{Allow, Capsule, Hit, Scene, ROUNDING_MM};
use crate::robot::Robot;

/// Least spare distance beyond a body's search reach worth carrying to later samples, mm (2:
/// a carried bound then lasts at least 1 mm of motion, ten grinding samples at the 5 mm/s
/// feed, and the march that finds it steps at least 1 mm; below it the body is searched).
const MIN_SPARE_MM: f64 = 2.0;

/// Samples a body is searched as before after its march found it nearer the part than
/// `MIN_SPARE_MM` beyond its reach, before a new march is tried (8: a body that stays near,
/// such as the shank while grinding, costs one wasted nearest query in nine samples).
const NEAR_WAIT: u32 = 8;

/// A stretch of a body's axis, from `from` mm along it to its end, clear of the part.
#[derive(Debug, Clone, Copy)]
pub(super) struct Stretch {
    from: f64,
    /// Its ends when the level was found, reference frame, mm.
    start: Point3<f64>,
    end: Point3<f64>,
    /// No reference point is nearer any point of the stretch, mm.
    level: f64,
}

/// A bound on one body's distance from the part carried from sample to sample.
#[derive(Debug, Clone, Default)]
pub(super) struct Carry {
    /// The stretch of the axis known clear, with its position then.
    anchor: Option<Stretch>,
    /// Samples left before a new march (after one found the body near the part).
    wait: u32,
    /// Searches the bound answered.
    skipped: usize,
}

/// Samples checked one after another (a move, a stroke, a whole program): each body's
/// distance from the part found at one sample bounds it at the next ones by how far the body
/// has moved since, and while that bound stays beyond the body's search reach its search is
/// skipped (the argument: `Scene::search_limit`). Answers are those of [`Scene::check`], bit
/// for bit, whatever the order of the samples.
pub struct Sweep<'s, 'a> {
    scene: &'s Scene<'a>,
    carry: Vec<Carry>,
}

impl Sweep<'_, '_> {
    /// As [`Scene::check`].
    pub fn check(&mut self, robot: &Robot, q: &[f64], allow: Allow) -> Option<Hit> {
        self.scene
            .check_carried(robot, q, allow, Some(&mut self.carry))
    }

    /// Body searches answered by a carried bound so far.
    pub fn skipped(&self) -> usize {
        self.carry.iter().map(|c| c.skipped).sum()
    }
}

impl<'a> Scene<'a> {
    /// A check of samples one after another that carries each body's distance from the part
    /// between them (see [`Sweep`]); it answers every sample exactly as [`Scene::check`] does.
    pub fn sweep(&self) -> Sweep<'_, 'a> {
        Sweep {
            scene: self,
            carry: Vec::new(),
        }
    }

    /// How far along `c`'s axis `part_clearance` must march: None when no reference point
    /// lies within `reach` of the axis (the search would visit no point and answer None),
    /// else a length beyond which none does (infinite when nothing is known). Shown without
    /// searching when `carry`'s bound allows; `carry` is renewed when it does not.
    ///
    /// Why a skip cannot pass a colliding sample: `carry` holds an earlier stretch `s0`-`e0`
    /// of the body's axis (from `from` mm along it to its end) and a level `L` such that every
    /// point of that stretch is at least `L` from every reference point (Euclidean). The same
    /// stretch now runs `s`-`e`, and its point `s + u (e - s)` lies within `|(1 - u)(s - s0) +
    /// u (e - e0)| <= max(|s - s0|, |e - e0|) = moved` of `s0 + u (e0 - s0)`; the distance
    /// to a point set is 1-Lipschitz, so every point of the stretch is at least `L - moved`
    /// from every reference point. When that exceeds `reach` (by `ROUNDING_MM` for rounding),
    /// every nearest query of the search's march there finds its point beyond `reach`, so the
    /// march only steps over the stretch: stopping it at `from` (or not starting it when
    /// `from` is 0) leaves the answer as it was. Nothing is assumed about the motion between
    /// the two samples (only positions are compared), and the solids are checked at every
    /// sample anyway. The ball is never skipped: a centre deep inside the part is far from
    /// every point and only the search's normal test sees it.
    pub(super) fn search_limit(&self, carry: &mut Carry, c: &Capsule, reach: f64) -> Option<f64> {
        if self.outside_box(c, reach) {
            return None;
        }
        let len = (c.b - c.a).norm();
        let at = |from: f64| c.a + (c.b - c.a) * (from / len).min(1.0);
        if let Some(known) = carry.anchor {
            let moved = (at(known.from) - known.start)
                .norm()
                .max((c.b - known.end).norm());
            if known.level - moved > reach + ROUNDING_MM {
                carry.skipped += 1;
                return (known.from > 0.0).then_some(known.from);
            }
        }
        carry.anchor = None;
        if carry.wait > 0 {
            carry.wait -= 1;
            return Some(f64::INFINITY);
        }
        match self.clear_stretch(c, reach) {
            Some((from, level)) => {
                let (start, end) = (at(from), c.b);
                carry.anchor = Some(Stretch {
                    from,
                    start,
                    end,
                    level,
                });
                (from > 0.0).then_some(from)
            }
            None => {
                carry.wait = NEAR_WAIT;
                Some(f64::INFINITY)
            }
        }
    }

    /// The stretch of `c`'s axis from its end back towards its start (from `from` mm along
    /// it) that keeps at least `reach + MIN_SPARE_MM` from every reference point, and a level
    /// no point of it comes nearer than; None when the end itself is nearer. Marches back
    /// from the end: the nearest point at `gap` from a centre leaves every point within
    /// `(gap - reach) / 2` of the centre at least `(gap + reach) / 2` from the part, and the
    /// march steps on by that half, so those balls cover the stretch.
    fn clear_stretch(&self, c: &Capsule, reach: f64) -> Option<(f64, f64)> {
        let d = c.b - c.a;
        let len = d.norm();
        let dir = if len > 0.0 { d / len } else { Vector3::zeros() };
        let mut level = f64::INFINITY;
        let mut t = len;
        loop {
            let gap = self.index.nearest(&(c.a + dir * t))?.dist2.sqrt();
            let half = (gap - reach) / 2.0;
            if half.is_nan() || half < MIN_SPARE_MM / 2.0 {
                return (t < len).then_some((t, level));
            }
            level = level.min(gap - half);
            t -= half;
            if t <= 0.0 {
                return Some((0.0, level));
            }
        }
    }
}

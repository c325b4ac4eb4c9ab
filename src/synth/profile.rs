//! A tangent-continuous planar curve of lines and clockwise arcs, evaluated by arc length.
//! Used for the sagittal (y-z) J-profile of the parametric femoral component.
use nalgebra::Vector2;

/// One piece of a profile.
#[derive(Debug, Clone, Copy)]
pub enum Piece {
    /// Straight run of this length (mm).
    Line(f64),
    /// Clockwise arc of this radius (mm) through this angle (degrees).
    Arc(f64, f64),
}

/// A curve from a start point and heading through pieces.
#[derive(Debug, Clone)]
pub struct Profile {
    start: Vector2<f64>,
    heading: Vector2<f64>,
    pieces: Vec<Piece>,
}

/// A point on the profile with its unit tangent and its left normal (tangent turned
/// counter-clockwise, the outward side of a clockwise-turning J).
#[derive(Debug, Clone, Copy)]
pub struct Station {
    /// Position (y, z).
    pub point: Vector2<f64>,
    /// Unit direction of travel.
    pub tangent: Vector2<f64>,
    /// Unit normal, tangent rotated +90 degrees.
    pub normal: Vector2<f64>,
}

fn left(v: Vector2<f64>) -> Vector2<f64> {
    Vector2::new(-v.y, v.x)
}

impl Profile {
    /// A profile starting at `start` heading along `heading` (normalised).
    pub fn new(start: Vector2<f64>, heading: Vector2<f64>, pieces: Vec<Piece>) -> Self {
        Profile {
            start,
            heading: heading.normalize(),
            pieces,
        }
    }

    /// Total arc length.
    pub fn length(&self) -> f64 {
        self.pieces
            .iter()
            .map(|p| match *p {
                Piece::Line(l) => l,
                Piece::Arc(r, a) => r * a.to_radians(),
            })
            .sum()
    }

    /// The station at arc length `s` (clamped to the curve).
    pub fn at(&self, s: f64) -> Station {
        let mut point = self.start;
        let mut tangent = self.heading;
        let mut left_s = s.clamp(0.0, self.length());
        for piece in &self.pieces {
            let (len, done) = match *piece {
                Piece::Line(l) => (l, left_s <= l),
                Piece::Arc(r, a) => (r * a.to_radians(), left_s <= r * a.to_radians()),
            };
            let step = if done { left_s } else { len };
            match *piece {
                Piece::Line(_) => point += tangent * step,
                Piece::Arc(r, _) => {
                    // Clockwise: the centre lies on the right of the travel direction.
                    let centre = point - left(tangent) * r;
                    let phi = -step / r;
                    let (c, sn) = (phi.cos(), phi.sin());
                    let radial = point - centre;
                    let rotate =
                        |v: Vector2<f64>| Vector2::new(c * v.x - sn * v.y, sn * v.x + c * v.y);
                    point = centre + rotate(radial);
                    tangent = rotate(tangent);
                }
            }
            if done {
                break;
            }
            left_s -= len;
        }
        Station {
            point,
            tangent,
            normal: left(tangent),
        }
    }

    /// Arc lengths of the piece boundaries (0, ends of each piece).
    pub fn breaks(&self) -> Vec<f64> {
        let mut out = vec![0.0];
        let mut s = 0.0;
        for p in &self.pieces {
            s += match *p {
                Piece::Line(l) => l,
                Piece::Arc(r, a) => r * a.to_radians(),
            };
            out.push(s);
        }
        out
    }
}

/// A polyline through `vertices`, evaluated by arc length.
#[derive(Debug, Clone)]
pub struct Polyline {
    /// Corner points.
    pub vertices: Vec<Vector2<f64>>,
}

impl Polyline {
    /// Total length.
    pub fn length(&self) -> f64 {
        self.vertices.windows(2).map(|w| (w[1] - w[0]).norm()).sum()
    }

    /// `m` points along the polyline that include every corner exactly, spread over the
    /// segments in proportion to their lengths (m must exceed the corner count).
    pub fn resample_with_corners(&self, m: usize) -> Vec<Vector2<f64>> {
        let segs = self.vertices.len() - 1;
        let total = self.length();
        let free = m - 1 - segs; // points strictly inside segments
        let mut counts: Vec<usize> = self
            .vertices
            .windows(2)
            .map(|w| ((w[1] - w[0]).norm() / total * free as f64).floor() as usize)
            .collect();
        let mut short = free - counts.iter().sum::<usize>();
        for c in counts.iter_mut() {
            if short == 0 {
                break;
            }
            *c += 1;
            short -= 1;
        }
        let mut out = Vec::with_capacity(m);
        for (k, w) in self.vertices.windows(2).enumerate() {
            let n = counts[k] + 1;
            for i in 0..n {
                out.push(w[0] + (w[1] - w[0]) * (i as f64 / n as f64));
            }
        }
        out.push(*self.vertices.last().expect("non-empty"));
        out
    }
}

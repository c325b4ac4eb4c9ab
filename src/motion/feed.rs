//! Grinding strokes at constant feed: joint angles as natural cubic splines of the tool-tip
//! arc length through the IK solutions, and a time-optimal jerk-limited law s(t) along the
//! path (Ruckig on one axis) whose cruise speed is the feed, slowed only where the joint
//! limits demand. Method: docs/ALGORITHMS.md, section "Grinding planner".
use super::trajectory::{Limits, Move, TrajectoryConfig, TrajectoryError};
use crate::robot::JointSpec;

/// Joint angles as natural cubic splines of arc length (one per joint, shared knots).
#[derive(Debug, Clone)]
pub struct JointSpline {
    s: Vec<f64>,
    q: Vec<Vec<f64>>,
    m: Vec<Vec<f64>>,
}

impl JointSpline {
    /// Spline through `q[i]` at arc lengths `s[i]` (strictly increasing, at least one knot).
    pub fn new(s: Vec<f64>, q: Vec<Vec<f64>>) -> Self {
        let n = s.len();
        let dof = q.first().map_or(0, Vec::len);
        let mut m = vec![vec![0.0; dof]; n];
        if n >= 3 {
            for j in 0..dof {
                let y: Vec<f64> = q.iter().map(|v| v[j]).collect();
                let sol = natural_second_derivatives(&s, &y);
                for (row, v) in m.iter_mut().zip(sol) {
                    row[j] = v;
                }
            }
        }
        JointSpline { s, q, m }
    }

    /// Path length, the last knot.
    pub fn length(&self) -> f64 {
        *self.s.last().unwrap_or(&0.0)
    }

    fn interval(&self, s: f64) -> usize {
        match self.s.partition_point(|k| *k <= s) {
            0 => 0,
            i => (i - 1).min(self.s.len().saturating_sub(2)),
        }
    }

    /// Joint angles at arc length `s` (clamped to the knots).
    pub fn eval(&self, s: f64, out: &mut [f64]) {
        if self.s.len() == 1 {
            out.copy_from_slice(&self.q[0]);
            return;
        }
        let s = s.clamp(0.0, self.length());
        let i = self.interval(s);
        let h = self.s[i + 1] - self.s[i];
        let (a, b) = (self.s[i + 1] - s, s - self.s[i]);
        for (j, o) in out.iter_mut().enumerate() {
            let (m0, m1) = (self.m[i][j], self.m[i + 1][j]);
            let (y0, y1) = (self.q[i][j], self.q[i + 1][j]);
            *o = m0 * a * a * a / (6.0 * h)
                + m1 * b * b * b / (6.0 * h)
                + (y0 / h - m0 * h / 6.0) * a
                + (y1 / h - m1 * h / 6.0) * b;
        }
    }

    /// Largest |dq/ds|, |d2q/ds2|, |d3q/ds3| per joint over the whole spline (exact: the
    /// first derivative is quadratic per interval, the second linear, the third constant).
    pub fn derivative_bounds(&self) -> [Vec<f64>; 3] {
        let dof = self.q.first().map_or(0, Vec::len);
        let (mut b1, mut b2, mut b3) = (vec![0.0; dof], vec![0.0; dof], vec![0.0; dof]);
        for i in 0..self.s.len().saturating_sub(1) {
            let h = self.s[i + 1] - self.s[i];
            for (j, ((o1, o2), o3)) in b1
                .iter_mut()
                .zip(b2.iter_mut())
                .zip(b3.iter_mut())
                .enumerate()
            {
                let (m0, m1) = (self.m[i][j], self.m[i + 1][j]);
                let slope = (self.q[i + 1][j] - self.q[i][j]) / h;
                // q'(x) at x = s - s_i:
                // slope - m0 (h - x)^2 / (2h) + m1 x^2 / (2h) - (m1 - m0) h / 6
                let d1 = |x: f64| {
                    slope - m0 * (h - x) * (h - x) / (2.0 * h) + m1 * x * x / (2.0 * h)
                        - (m1 - m0) * h / 6.0
                };
                let mut best = d1(0.0).abs().max(d1(h).abs());
                if (m0 - m1).abs() > 0.0 {
                    let x = m0 * h / (m0 - m1);
                    if x > 0.0 && x < h {
                        best = best.max(d1(x).abs());
                    }
                }
                *o1 = f64::max(*o1, best);
                *o2 = f64::max(*o2, m0.abs().max(m1.abs()));
                *o3 = f64::max(*o3, ((m1 - m0) / h).abs());
            }
        }
        [b1, b2, b3]
    }
}

/// Second derivatives of the natural cubic spline through (s, y) (Thomas algorithm).
fn natural_second_derivatives(s: &[f64], y: &[f64]) -> Vec<f64> {
    let n = s.len();
    let mut m = vec![0.0; n];
    let inner = n - 2;
    let mut diag = vec![0.0; inner];
    let mut upper = vec![0.0; inner];
    let mut rhs = vec![0.0; inner];
    for k in 0..inner {
        let i = k + 1;
        let (h0, h1) = (s[i] - s[i - 1], s[i + 1] - s[i]);
        diag[k] = 2.0 * (h0 + h1);
        upper[k] = h1;
        rhs[k] = 6.0 * ((y[i + 1] - y[i]) / h1 - (y[i] - y[i - 1]) / h0);
        if k > 0 {
            let w = h0 / diag[k - 1];
            diag[k] -= w * upper[k - 1];
            rhs[k] -= w * rhs[k - 1];
        }
    }
    for k in (0..inner).rev() {
        let next = if k + 1 < inner { m[k + 2] } else { 0.0 };
        m[k + 1] = (rhs[k] - upper[k] * next) / diag[k];
    }
    m
}

/// Path speed, acceleration and jerk limits (m/s, m/s^2, m/s^3) along a stroke.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PathLimits {
    /// Cruise speed, m/s: the feed, or less where the joints demand.
    pub velocity: f64,
    /// Path acceleration, m/s^2.
    pub acceleration: f64,
    /// Path jerk, m/s^3.
    pub jerk: f64,
}

/// The largest path limits up to `wanted` that keep every joint within `margin` times its
/// velocity, acceleration and jerk limits along `spline`: with q' = dq/ds etc.,
/// |q' v| <= V, |q''| v^2 + |q'| a <= A, |q'''| v^3 + 3 |q''| v a + |q'| j <= J; the speed gets at
/// most half of A and a quarter of J, the path acceleration what is left.
pub fn path_limits(
    spline: &JointSpline,
    joints: &[JointSpec],
    wanted: PathLimits,
    margin: f64,
) -> PathLimits {
    let [d1, d2, d3] = spline.derivative_bounds();
    let mut v = wanted.velocity;
    for (i, jt) in joints.iter().enumerate() {
        let (vl, al, jl) = (
            margin * jt.velocity,
            margin * jt.acceleration,
            margin * jt.jerk,
        );
        if d1[i] > 0.0 {
            v = v.min(vl / d1[i]);
        }
        if d2[i] > 0.0 {
            v = v.min((0.5 * al / d2[i]).sqrt());
        }
        if d3[i] > 0.0 {
            v = v.min((0.25 * jl / d3[i]).cbrt());
        }
    }
    let mut a = wanted.acceleration;
    for (i, jt) in joints.iter().enumerate() {
        let (al, jl) = (margin * jt.acceleration, margin * jt.jerk);
        if d1[i] > 0.0 {
            a = a.min((al - d2[i] * v * v) / d1[i]);
        }
        if d2[i] > 0.0 && v > 0.0 {
            a = a.min(0.25 * jl / (3.0 * d2[i] * v));
        }
    }
    let mut j = wanted.jerk;
    for (i, jt) in joints.iter().enumerate() {
        let jl = margin * jt.jerk;
        if d1[i] > 0.0 {
            j = j.min((jl - d3[i] * v * v * v - 3.0 * d2[i] * v * a) / d1[i]);
        }
    }
    PathLimits {
        velocity: v,
        acceleration: a,
        jerk: j,
    }
}

/// One stroke sampled every period: joint samples after t = 0 (the start, at rest, is the
/// caller's last sample) and, per sample, whether it is at cruise speed.
pub fn sample_stroke(
    spline: &JointSpline,
    limits: &PathLimits,
    config: &TrajectoryConfig,
) -> Result<(Vec<Vec<f64>>, Vec<bool>), TrajectoryError> {
    let path = Limits {
        velocity: vec![limits.velocity],
        acceleration: vec![limits.acceleration],
        jerk: vec![limits.jerk],
    };
    let mv = Move::new(&[0.0], &[spline.length()], &path, config)?;
    let steps = (mv.duration() / config.period - 1e-9).ceil().max(0.0) as usize;
    let dof = spline.q.first().map_or(0, Vec::len);
    let (mut s, mut v) = ([0.0], [0.0]);
    let mut samples = Vec::with_capacity(steps);
    let mut speeds = Vec::with_capacity(steps);
    for k in 1..=steps {
        mv.state_at(k as f64 * config.period, &mut s, &mut v);
        let mut q = vec![0.0; dof];
        spline.eval(s[0], &mut q);
        samples.push(q);
        speeds.push(v[0]);
    }
    // cruise: at the stroke's top speed when that is the planned speed (a whole-period
    // duration may leave it a little under); strokes too short to reach it have none
    let top = speeds.iter().copied().fold(0.0, f64::max);
    let reached = top >= 0.95 * limits.velocity;
    let cruise = speeds
        .iter()
        .map(|v| reached && (v - top).abs() <= 1e-6 * top)
        .collect();
    Ok((samples, cruise))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn natural_spline_reproduces_a_cubic_free_line_and_interpolates() {
        let s: Vec<f64> = (0..7)
            .map(|i| f64::from(i) * 0.5 + 0.1 * f64::from(i % 2))
            .collect();
        let q: Vec<Vec<f64>> = s.iter().map(|x| vec![2.0 * x + 1.0, x.sin()]).collect();
        let sp = JointSpline::new(s.clone(), q.clone());
        let mut out = [0.0; 2];
        for (x, y) in s.iter().zip(&q) {
            sp.eval(*x, &mut out);
            assert!((out[0] - y[0]).abs() < 1e-12 && (out[1] - y[1]).abs() < 1e-12);
        }
        sp.eval(1.234, &mut out);
        assert!(
            (out[0] - (2.0 * 1.234 + 1.0)).abs() < 1e-12,
            "a line stays a line"
        );
        assert!((out[1] - 1.234f64.sin()).abs() < 1e-2);
        let [d1, d2, d3] = sp.derivative_bounds();
        assert!((d1[0] - 2.0).abs() < 1e-12 && d2[0] < 1e-12 && d3[0] < 1e-12);
        // the bounds are the maxima of the spline's own derivatives (checked numerically)
        let h = 1e-5;
        let (mut n1, mut n2) = (0.0f64, 0.0f64);
        let (mut a, mut b, mut c) = ([0.0; 2], [0.0; 2], [0.0; 2]);
        let mut x = h;
        while x < sp.length() - h {
            sp.eval(x - h, &mut a);
            sp.eval(x, &mut b);
            sp.eval(x + h, &mut c);
            n1 = n1.max(((c[1] - a[1]) / (2.0 * h)).abs());
            n2 = n2.max(((c[1] - 2.0 * b[1] + a[1]) / (h * h)).abs());
            x += 1e-3;
        }
        assert!(
            d1[1] >= n1 - 1e-6 && d1[1] <= n1 * 1.001,
            "{} vs {n1}",
            d1[1]
        );
        assert!(
            d2[1] >= n2 * 0.99 && d2[1] <= n2 * 1.01,
            "{} vs {n2}",
            d2[1]
        );
        assert!(d3[1] > 0.0);
    }
}

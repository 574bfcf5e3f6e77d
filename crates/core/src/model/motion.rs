use super::{StateMatrix, StateVector};

/// How a tag moves between two reads.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum MotionModel {
    /// Constant velocity driven by white acceleration noise of power
    /// spectral density `q` (m²/s³) on each moving axis (GLAC eq. 3).
    ConstantVelocity { q: f64 },
    /// No velocity state: position is a random walk with diffusion `q`
    /// (m²/s) per axis (the "no velocity model" variant, GLAC sec. 5.2.2).
    RandomWalk { q: f64 },
}

/// A transition over one time step: x' = F x, P' = F P Fᵀ + Q.
///
/// Stored blockwise rather than as two 6×6 matrices because both models
/// are block-diagonal per axis; [`Transition::propagate`] uses that to
/// predict in ~40 flops instead of two dense 6×6 products.
#[derive(Debug, Clone, Copy)]
pub struct Transition {
    /// Time step, seconds.
    pub dt: f64,
    /// Whether position integrates velocity (constant velocity).
    pub with_velocity: bool,
    /// Per-axis process noise blocks [Q_pp, Q_pv, Q_vv] (SI units).
    pub q_blocks: [f64; 3],
    /// Axes that move (2 for a tag in a plane, 3 in space).
    pub axes: usize,
}

impl MotionModel {
    /// Transition for a step of `dt` seconds over `axes` moving axes.
    ///
    /// Constant velocity (discrete white-noise acceleration, Bar-Shalom
    /// 6.2.2): per axis F = [[1, dt], [0, 1]],
    /// Q = q [[dt³/3, dt²/2], [dt²/2, dt]].
    pub fn transition(&self, dt: f64, axes: usize) -> Transition {
        match *self {
            MotionModel::ConstantVelocity { q } => Transition {
                dt,
                with_velocity: true,
                q_blocks: [q * dt * dt * dt / 3.0, q * dt * dt / 2.0, q * dt],
                axes,
            },
            MotionModel::RandomWalk { q } => Transition { dt, with_velocity: false, q_blocks: [q * dt, 0.0, 0.0], axes },
        }
    }

    pub fn has_velocity(&self) -> bool {
        matches!(self, MotionModel::ConstantVelocity { .. })
    }
}

impl Transition {
    /// Dense F (for tests and generic filters).
    pub fn f(&self) -> StateMatrix {
        let mut f = StateMatrix::identity();
        if self.with_velocity {
            for i in 0..self.axes {
                f[(i, i + 3)] = self.dt;
            }
        }
        f
    }

    /// Dense Q.
    pub fn q(&self) -> StateMatrix {
        let mut q = StateMatrix::zeros();
        let [pp, pv, vv] = self.q_blocks;
        for i in 0..self.axes {
            q[(i, i)] = pp;
            q[(i, i + 3)] = pv;
            q[(i + 3, i)] = pv;
            q[(i + 3, i + 3)] = vv;
        }
        q
    }

    /// In place: x ← F x, P ← F P Fᵀ + Q (eqs. 5–6), exploiting F = [[I, dt I], [0, I]].
    ///
    /// With P = [[A, B], [Bᵀ, C]] (3×3 blocks):
    /// A' = A + dt (B + Bᵀ) + dt² C,  B' = B + dt C,  C' = C.
    #[inline]
    pub fn propagate(&self, x: &mut StateVector, p: &mut StateMatrix) {
        let dt = self.dt;
        if self.with_velocity {
            for i in 0..3 {
                x[i] += dt * x[i + 3];
            }
            // Column update P F^T then row update F (P F^T).
            for r in 0..6 {
                for i in 0..3 {
                    p[(r, i)] += dt * p[(r, i + 3)];
                }
            }
            for c in 0..6 {
                for i in 0..3 {
                    p[(i, c)] += dt * p[(i + 3, c)];
                }
            }
            // The two passes add the same terms in a different order above
            // and below the diagonal; re-symmetrise so rounding cannot
            // accumulate into an asymmetric P over thousands of steps.
            for r in 0..6 {
                for c in r + 1..6 {
                    let v = 0.5 * (p[(r, c)] + p[(c, r)]);
                    p[(r, c)] = v;
                    p[(c, r)] = v;
                }
            }
        }
        let [pp, pv, vv] = self.q_blocks;
        for i in 0..self.axes {
            p[(i, i)] += pp;
            p[(i, i + 3)] += pv;
            p[(i + 3, i)] += pv;
            p[(i + 3, i + 3)] += vv;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn blockwise_propagation_matches_dense() {
        let m = MotionModel::ConstantVelocity { q: 0.3 };
        let t = m.transition(0.037, 3);
        let mut x = StateVector::from_iterator((0..6).map(|i| i as f64 * 0.1 + 0.05));
        let a = StateMatrix::from_fn(|r, c| ((r * 7 + c * 3) % 5) as f64 * 0.01);
        let mut p = a * a.transpose() + StateMatrix::identity() * 1e-3;
        let (x0, p0) = (x, p);
        t.propagate(&mut x, &mut p);
        let f = t.f();
        assert!((x - f * x0).norm() < 1e-12);
        assert!((p - (f * p0 * f.transpose() + t.q())).norm() < 1e-12);
    }
}

//! Interacting multiple model (IMM) steps for two motion models (Blom &
//! Bar-Shalom 1988; Bar-Shalom, Li, Kirubarajan 2001, sec. 11.6.6), as
//! pure functions on the model-conditioned (x_j, P_j) and probabilities μ.
//!
//! Why in GLAC: a robot-carried tag alternates between near-constant
//! velocity (a small process noise gives accurate velocity) and sharp
//! manoeuvres (a large one keeps lock); one fixed Q cannot serve both.

use crate::model::{StateMatrix, StateVector};

/// Mixing (IMM step 1): with the Markov switch probability `switch` per
/// step, predicted model probabilities c_j = Σ_i Π_ij μ_i and mixing
/// weights μ_{i|j} = Π_ij μ_i / c_j; each model restarts from
/// x0_j = Σ_i μ_{i|j} x_i, P0_j = Σ_i μ_{i|j} (P_i + (x_i − x0_j)(x_i − x0_j)ᵀ).
/// Returns c.
pub fn mix(x: &mut [StateVector; 2], p: &mut [StateMatrix; 2], mu: &[f64; 2], switch: f64) -> [f64; 2] {
    let stay = 1.0 - switch;
    let c = [stay * mu[0] + switch * mu[1], switch * mu[0] + stay * mu[1]];
    let (x_in, p_in) = (*x, *p);
    for j in 0..2 {
        if c[j] <= 0.0 {
            continue;
        }
        let w = [if j == 0 { stay } else { switch } * mu[0] / c[j], if j == 1 { stay } else { switch } * mu[1] / c[j]];
        let x0 = x_in[0] * w[0] + x_in[1] * w[1];
        let mut p0 = StateMatrix::zeros();
        for i in 0..2 {
            let d = x_in[i] - x0;
            p0 += (p_in[i] + d * d.transpose()) * w[i];
        }
        x[j] = x0;
        p[j] = p0;
    }
    c
}

/// Combination (IMM output): x = Σ μ_j x_j, P = Σ μ_j (P_j + (x_j − x)(x_j − x)ᵀ).
pub fn combine(x: &[StateVector; 2], p: &[StateMatrix; 2], mu: &[f64; 2]) -> (StateVector, StateMatrix) {
    let xc = x[0] * mu[0] + x[1] * mu[1];
    let mut pc = StateMatrix::zeros();
    for j in 0..2 {
        let d = x[j] - xc;
        pc += (p[j] + d * d.transpose()) * mu[j];
    }
    (xc, pc)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mixing_preserves_the_combined_moments() {
        let mut x = [StateVector::from_element(0.1), StateVector::from_element(0.3)];
        let mut p = [StateMatrix::identity() * 1e-3, StateMatrix::identity() * 4e-3];
        let mu = [0.7, 0.3];
        let (x_before, p_before) = combine(&x, &p, &mu);
        let c = mix(&mut x, &mut p, &mu, 0.05);
        assert!((c[0] + c[1] - 1.0).abs() < 1e-12);
        // Mixing redistributes but must keep the overall mean and covariance.
        let (x_after, p_after) = combine(&x, &p, &c);
        assert!((x_after - x_before).norm() < 1e-12);
        assert!((p_after - p_before).norm() < 1e-12);
        // With no switching, each model keeps its own state.
        let mut x2 = [StateVector::from_element(0.1), StateVector::from_element(0.3)];
        let mut p2 = [StateMatrix::identity(), StateMatrix::identity()];
        mix(&mut x2, &mut p2, &mu, 0.0);
        assert!((x2[1] - StateVector::from_element(0.3)).norm() < 1e-12);
    }
}

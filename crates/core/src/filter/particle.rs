//! Particle-filter building blocks as pure functions on flat arrays
//! (weights in log space, one entry per particle; no object per particle).

/// Normalises log-weights in place so that `Σ exp(w) = 1`, returning the
/// log of the normaliser (the log-evidence of the step). All −∞ (every
/// particle impossible) returns −∞ and leaves uniform weights, so the
/// caller can detect the collapse and recover.
pub fn normalise_log_weights(log_weights: &mut [f64]) -> f64 {
    let max = log_weights.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    if !max.is_finite() {
        let uniform = -(log_weights.len() as f64).ln();
        log_weights.iter_mut().for_each(|w| *w = uniform);
        return f64::NEG_INFINITY;
    }
    // Log-sum-exp with the maximum factored out: no overflow/underflow.
    let sum: f64 = log_weights.iter().map(|w| (w - max).exp()).sum();
    let log_norm = max + sum.ln();
    log_weights.iter_mut().for_each(|w| *w -= log_norm);
    log_norm
}

/// Effective sample size `N̂_eff = 1 / Σ wᵢ²` of normalised log-weights
/// (thesis §5.3.2, "Resampling").
pub fn effective_sample_size(log_weights: &[f64]) -> f64 {
    let s: f64 = log_weights.iter().map(|w| (2.0 * w).exp()).sum();
    if s > 0.0 {
        1.0 / s
    } else {
        0.0
    }
}

/// Systematic resampling: ancestor index of each of the `n` new particles,
/// given normalised log-weights and one uniform draw `u ∈ [0, 1)`. Low
/// variance (one random number) and O(n).
pub fn systematic_resample(log_weights: &[f64], u: f64, ancestors: &mut Vec<usize>) {
    let n = log_weights.len();
    ancestors.clear();
    if n == 0 {
        return;
    }
    let step = 1.0 / n as f64;
    let mut position = u * step;
    let mut cumulative = log_weights[0].exp();
    let mut i = 0;
    for _ in 0..n {
        while position > cumulative && i + 1 < n {
            i += 1;
            cumulative += log_weights[i].exp();
        }
        ancestors.push(i);
        position += step;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn weights_sum_to_one_after_normalising() {
        let mut w = vec![-1000.0, -1001.0, -999.5, f64::NEG_INFINITY];
        normalise_log_weights(&mut w);
        let s: f64 = w.iter().map(|v| v.exp()).sum();
        assert!((s - 1.0).abs() < 1e-12);
        let mut dead = vec![f64::NEG_INFINITY; 4];
        assert_eq!(normalise_log_weights(&mut dead), f64::NEG_INFINITY);
        assert!((dead.iter().map(|v| v.exp()).sum::<f64>() - 1.0).abs() < 1e-12);
    }

    #[test]
    fn ess_bounds() {
        let mut w = vec![0.0; 10];
        normalise_log_weights(&mut w);
        assert!((effective_sample_size(&w) - 10.0).abs() < 1e-9);
        let mut one = vec![0.0, f64::NEG_INFINITY, f64::NEG_INFINITY];
        normalise_log_weights(&mut one);
        assert!((effective_sample_size(&one) - 1.0).abs() < 1e-12);
    }

    #[test]
    fn systematic_resampling_follows_weights() {
        let mut w: Vec<f64> = [0.5f64, 0.25, 0.125, 0.125].iter().map(|v| v.ln()).collect();
        normalise_log_weights(&mut w);
        let mut a = Vec::new();
        systematic_resample(&w, 0.5, &mut a);
        let mut counts = [0usize; 4];
        for &i in &a {
            counts[i] += 1;
        }
        assert_eq!(a.len(), 4);
        assert_eq!(counts.iter().sum::<usize>(), 4);
        // Every particle's expected count is n·w ± 1 for systematic resampling.
        for k in 0..4 {
            assert!((counts[k] as f64 - 4.0 * w[k].exp()).abs() < 1.0 + 1e-9, "{counts:?}");
        }
    }
}

use num_complex::{Complex32, Complex64};

use crate::estimate::SymbolSums;
use crate::ofdm::{as_floats, widen, ChannelMatrix, ChannelTransform};

/// The paper's subcarrier-combined magnitude `H_combined(n) = Σ_f |H(f, n)|`
/// (thesis ch. 4.3 (a)), one value per symbol into `out` (NaN for invalid
/// symbols).
///
/// Caveat (why [`combined_projection`] is the default): with the tx → rx
/// leakage `S(f)` much stronger than the tag channel `T(f)`,
/// `|S + T| − |S| ≈ |T| cos(arg T − arg S)`, and that relative phase turns
/// by `2π B Δd / c` across the band (Δd: tag path minus leakage path). For
/// Δd ≈ 3 m at 100 MHz it makes one full turn and the sum nearly cancels.
pub fn combined_magnitude(h: &ChannelMatrix, out: &mut Vec<f64>) {
    out.clear();
    // √(re² + im²) rather than `norm` (hypot): several times faster, and the
    // values are far from overflow.
    out.extend((0..h.symbols).map(|n| {
        if h.valid[n] {
            h.row(n).iter().map(|v| (v.norm_sqr() as f64).sqrt()).sum()
        } else {
            f64::NAN
        }
    }));
}

/// Coherent subcarrier combining: the per-symbol channel projected on the
/// direction in which it changes, one real value per symbol into `out`
/// (NaN for invalid symbols).
///
/// Model: `H(f, n) = S(f) + s(n) T(f) + noise` with the tag state
/// `s(n) ∈ {0, 1}`. Removing the window mean `H̄(f)` leaves
/// `(s(n) − s̄) T(f) + noise`: rank one. Its direction `v ∝ T` is the
/// dominant eigenvector of `Σ_n d_n d_nᴴ` (`d_n = H(·, n) − H̄`), found by a
/// few power iterations on sums over blocks of `block` symbols (shorter than
/// a chip, so the blocks average noise, not the modulation). Then
/// `u(n) = vᴴ d_n = (s(n) − s̄) vᴴT + noise` is a complex constant times a
/// real waveform; rotating by `½ arg Σ u(n)²` makes it real. Unlike
/// [`combined_magnitude`] nothing can cancel, and the subcarriers add
/// coherently (a gain of `N − 1` in SNR over one subcarrier). The sign of
/// the result is arbitrary; the correlation takes care of it. Cost
/// `O(symbols × subcarriers)` per iteration.
pub fn combined_projection(h: &ChannelMatrix, block: usize, out: &mut Vec<f64>) {
    out.clear();
    let f_count = h.subcarriers;
    let valid = h.valid_count();
    if valid == 0 || f_count == 0 {
        out.resize(h.symbols, f64::NAN);
        return;
    }
    let zero = Complex64::new(0.0, 0.0);
    let mut mean = vec![zero; f_count];
    for n in (0..h.symbols).filter(|&n| h.valid[n]) {
        mean.iter_mut().zip(h.row(n)).for_each(|(m, &v)| *m += widen(v));
    }
    mean.iter_mut().for_each(|m| *m /= valid as f64);
    // Block sums of the centred rows.
    let block = block.max(1);
    let mut blocks = Vec::with_capacity(h.symbols.div_ceil(block) * f_count);
    for start in (0..h.symbols).step_by(block) {
        let mut sum = vec![zero; f_count];
        for n in (start..(start + block).min(h.symbols)).filter(|&n| h.valid[n]) {
            for ((s, &v), m) in sum.iter_mut().zip(h.row(n)).zip(&mean) {
                *s += widen(v) - m;
            }
        }
        blocks.extend(sum);
    }
    let Some(v) = dominant_direction(&blocks, f_count) else {
        // A window without any change (e.g. noiseless and no reply): flat feature.
        out.extend(h.valid.iter().map(|&ok| if ok { 0.0 } else { f64::NAN }));
        return;
    };
    let projections: Vec<Complex64> = (0..h.symbols)
        .map(|n| {
            if h.valid[n] {
                h.row(n).iter().zip(&mean).zip(&v).map(|((&x, m), w)| w.conj() * (widen(x) - m)).sum()
            } else {
                zero
            }
        })
        .collect();
    real_part_after_rotation(&projections, &h.valid, out);
}

/// [`combined_projection`] without demodulating every symbol: the block
/// sums come from the antenna's time-domain [`SymbolSums`] through the
/// (linear) [`ChannelTransform`], and `u(n) = vᴴ(H_n − H̄)` is the dot
/// product of the raw symbol with the time-domain filter of `v`
/// ([`ChannelTransform::projection_filter`]) minus `vᴴH̄`: per symbol `N`
/// single-precision multiply-adds instead of an FFT and `N − 1` more.
/// Blocks are `block` symbols rounded to a multiple of
/// [`SymbolSums::STRIDE`], so each is a difference of two prefixes.
pub fn combined_projection_from_sums(
    sums: &SymbolSums,
    transform: &mut ChannelTransform,
    block: usize,
    out: &mut Vec<f64>,
) {
    out.clear();
    let symbols = sums.symbols;
    let f_count = transform.subcarriers();
    let n = sums.n;
    let valid = sums.count_in(0, symbols);
    if valid == 0 || f_count == 0 {
        out.resize(symbols, f64::NAN);
        return;
    }
    let zero = Complex64::new(0.0, 0.0);
    // Window mean of x = y − r in the time domain.
    let mut mean_x = vec![zero; n];
    sums.add_interval(0, symbols, &mut mean_x, None);
    mean_x.iter_mut().for_each(|m| *m /= valid as f64);

    let stride = SymbolSums::STRIDE;
    let block = ((block + stride / 2) / stride).max(1) * stride;
    let count = symbols.div_ceil(block);
    let mut blocks = vec![zero; count * f_count];
    let mut time = vec![zero; n];
    for (b, sum) in blocks.chunks_exact_mut(f_count).enumerate() {
        time.iter_mut().for_each(|t| *t = zero);
        let (from, to) = (b * block, ((b + 1) * block).min(symbols));
        let m = sums.add_interval(from, to, &mut time, None) as f64;
        time.iter_mut().zip(&mean_x).for_each(|(t, x)| *t -= x * m);
        transform.apply(&time, sum);
    }
    let Some(v) = dominant_direction(&blocks, f_count) else {
        out.extend(sums.valid.iter().map(|&ok| if ok { 0.0 } else { f64::NAN }));
        return;
    };
    // offset = vᴴ H̄ with H̄ = T(r + x̄).
    let absolute: Vec<Complex64> = sums.reference.iter().zip(&mean_x).map(|(r, x)| r + x).collect();
    let mut mean_h = vec![zero; f_count];
    transform.apply(&absolute, &mut mean_h);
    let offset: Complex64 = v.iter().zip(&mean_h).map(|(v, h)| v.conj() * h).sum();
    let filter = RealFilter::new(&transform.projection_filter(&v));
    let projections: Vec<Complex64> = as_floats(&sums.samples)
        .chunks_exact(2 * n)
        .zip(&sums.valid)
        .map(|(y, &ok)| if ok { widen(filter.dot(y)) - offset } else { zero })
        .collect();
    real_part_after_rotation(&projections, &sums.valid, out);
}

/// A complex filter `w` as two real ones over interleaved samples
/// `[re y₀, im y₀, re y₁, …]`: `Re Σ w y = Σ a·y` with `a = [re w₀, −im w₀,
/// …]` and `Im Σ w y = Σ b·y` with `b = [im w₀, re w₀, …]`.
///
/// Why: two real dot products vectorise in full width; the complex one
/// (array of structs) did not, and ran 1500 times per antenna and reply.
struct RealFilter {
    a: Vec<f32>,
    b: Vec<f32>,
}

impl RealFilter {
    fn new(w: &[Complex32]) -> Self {
        Self { a: w.iter().flat_map(|w| [w.re, -w.im]).collect(), b: w.iter().flat_map(|w| [w.im, w.re]).collect() }
    }

    /// `Σ_t w(t) y(t)` for interleaved `y`, in eight independent lanes per
    /// part (one running sum would chain every add and not vectorise).
    #[inline]
    fn dot(&self, y: &[f32]) -> Complex32 {
        const L: usize = 8;
        let (mut re, mut im) = ([0.0f32; L], [0.0f32; L]);
        let (ac, bc, yc) = (self.a.chunks_exact(L), self.b.chunks_exact(L), y.chunks_exact(L));
        let (a_rest, b_rest, y_rest) = (ac.remainder(), bc.remainder(), yc.remainder());
        for ((a, b), y) in ac.zip(bc).zip(yc) {
            for l in 0..L {
                re[l] += a[l] * y[l];
                im[l] += b[l] * y[l];
            }
        }
        let mut total = Complex32::new(re.iter().sum(), im.iter().sum());
        for ((a, b), y) in a_rest.iter().zip(b_rest).zip(y_rest) {
            total += Complex32::new(a * y, b * y);
        }
        total
    }
}

/// `Σ conj(x) y` in four independent lanes.
#[inline]
fn dot_conj(x: &[Complex64], y: &[Complex64]) -> Complex64 {
    let mut lanes = [Complex64::new(0.0, 0.0); 4];
    let (xc, yc) = (x.chunks_exact(4), y.chunks_exact(4));
    let (x_rest, y_rest) = (xc.remainder(), yc.remainder());
    for (x4, y4) in xc.zip(yc) {
        for l in 0..4 {
            lanes[l] += x4[l].conj() * y4[l];
        }
    }
    let mut total = (lanes[0] + lanes[1]) + (lanes[2] + lanes[3]);
    for (a, b) in x_rest.iter().zip(y_rest) {
        total += a.conj() * b;
    }
    total
}

/// The dominant direction of the rows of `blocks` (`count × f_count`,
/// unit norm), by a few power iterations `v ← Σ_m b_m (b_mᴴ v)` started
/// from the block that deviates most (never orthogonal to T when a reply is
/// present); None when nothing changes.
fn dominant_direction(blocks: &[Complex64], f_count: usize) -> Option<Vec<Complex64>> {
    let zero = Complex64::new(0.0, 0.0);
    let norm = |x: &[Complex64]| x.iter().map(|v| v.norm_sqr()).sum::<f64>().sqrt();
    let mut v: Vec<Complex64> =
        blocks.chunks_exact(f_count).max_by(|a, b| norm(a).total_cmp(&norm(b))).map(|b| b.to_vec())?;
    let mut next = vec![zero; f_count];
    let mut previous: Option<Vec<Complex64>> = None;
    for _ in 0..6 {
        let length = norm(&v);
        if !(length > 0.0 && length.is_finite()) {
            break;
        }
        v.iter_mut().for_each(|x| *x /= length);
        // Converged (the direction no longer turns): a reply's modulation
        // dominates the noise by far, so this usually stops after 2–3 steps.
        if previous.as_ref().is_some_and(|p| dot_conj(p, &v).norm() > 1.0 - 1e-8) {
            return Some(v);
        }
        previous = Some(v.clone());
        next.iter_mut().for_each(|x| *x = zero);
        for b in blocks.chunks_exact(f_count) {
            let coefficient = dot_conj(b, &v);
            next.iter_mut().zip(b).for_each(|(o, x)| *o += x * coefficient);
        }
        std::mem::swap(&mut v, &mut next);
    }
    let length = norm(&v);
    if !(length > 0.0 && length.is_finite()) {
        return None;
    }
    v.iter_mut().for_each(|x| *x /= length);
    Some(v)
}

/// `u(n)` is a complex constant times a real waveform: rotate by
/// `½ arg Σ u(n)²` and keep the real part (NaN for invalid symbols).
fn real_part_after_rotation(projections: &[Complex64], valid: &[bool], out: &mut Vec<f64>) {
    let square: Complex64 = projections.iter().map(|u| u * u).sum();
    let rotation = Complex64::from_polar(1.0, -0.5 * square.arg());
    out.extend(projections.iter().zip(valid).map(|(u, &ok)| if ok { (u * rotation).re } else { f64::NAN }));
}

/// Centred moving average of `width` symbols (NaN values skipped; NaN
/// where a window has no finite value), into `out`.
///
/// Why: the normalised correlation divides by the feature's variance over
/// the preamble, noise included. Averaging over a fraction of a chip (the
/// tag state is constant over a chip) lowers the noise variance by about
/// `width` while keeping the waveform, so the score reaches the threshold
/// at a lower SNR. A wider window would also make noise-only scores larger
/// (fewer independent samples), hence `chip / 8` in the reply processor.
pub fn moving_average(values: &[f64], width: usize, out: &mut Vec<f64>) {
    out.clear();
    let n = values.len();
    let width = width.max(1);
    if width == 1 {
        out.extend_from_slice(values);
        return;
    }
    let mut sum = vec![0.0; n + 1];
    let mut count = vec![0usize; n + 1];
    for (i, &v) in values.iter().enumerate() {
        let finite = v.is_finite();
        sum[i + 1] = sum[i] + if finite { v } else { 0.0 };
        count[i + 1] = count[i] + usize::from(finite);
    }
    let (before, after) = ((width - 1) / 2, width / 2);
    out.extend((0..n).map(|i| {
        let (a, b) = (i.saturating_sub(before), (i + after + 1).min(n));
        let c = count[b] - count[a];
        if c == 0 {
            f64::NAN
        } else {
            (sum[b] - sum[a]) / c as f64
        }
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    fn modulated(states: &[u8], s: &[Complex64], t: &[Complex64]) -> ChannelMatrix {
        let mut h = ChannelMatrix::new(states.len(), s.len());
        for (n, &state) in states.iter().enumerate() {
            for f in 0..s.len() {
                let v = s[f] + t[f] * state as f64;
                h.row_mut(n)[f] = num_complex::Complex32::new(v.re as f32, v.im as f32);
            }
        }
        h
    }

    #[test]
    fn projection_follows_the_state_up_to_sign_and_scale() {
        let s: Vec<Complex64> = (0..19).map(|f| Complex64::from_polar(100.0, 0.3 * f as f64)).collect();
        // The tag channel's phase relative to S makes a full turn: the paper's
        // magnitude sum nearly cancels, the projection does not.
        let t: Vec<Complex64> =
            (0..19).map(|f| Complex64::from_polar(1.0, 0.3 * f as f64 + 0.33 * f as f64 + 0.2)).collect();
        let states: Vec<u8> = (0..400).map(|n| ((n / 37) % 2) as u8).collect();
        let mut h = modulated(&states, &s, &t);
        h.valid[5] = false;
        let mut u = Vec::new();
        combined_projection(&h, 8, &mut u);
        assert!(u[5].is_nan());
        let pick = |level: u8| -> Vec<f64> {
            states
                .iter()
                .zip(&u)
                .enumerate()
                .filter(|(n, (s, _))| *n != 5 && **s == level)
                .map(|(_, (_, v))| *v)
                .collect()
        };
        let (high, low) = (pick(1), pick(0));
        let gap = (high[0] - low[0]).abs();
        // Full separation: |T| √19 between the states, nothing else varies
        // (up to the single-precision rounding of |S| = 100: ulp 8e-6).
        assert!((gap - 19f64.sqrt()).abs() < 1e-4, "{gap}");
        assert!(high.iter().all(|v| (v - high[0]).abs() < 1e-4) && low.iter().all(|v| (v - low[0]).abs() < 1e-4));

        let mut m = Vec::new();
        combined_magnitude(&h, &mut m);
        let paper_gap = (m[0] - m[37]).abs();
        assert!(paper_gap < 0.3 * gap, "paper {paper_gap} vs projection {gap}");
    }

    #[test]
    fn moving_average_is_centred_and_skips_nan() {
        let mut out = Vec::new();
        moving_average(&[1.0, 2.0, f64::NAN, 4.0, 5.0], 3, &mut out);
        assert_eq!(out, vec![1.5, 1.5, 3.0, 4.5, 4.5]);
        moving_average(&[f64::NAN, f64::NAN, 1.0], 1, &mut out);
        assert!(out[0].is_nan() && out[2] == 1.0);
        moving_average(&[f64::NAN, f64::NAN, 1.0, 2.0], 2, &mut out);
        assert!(out[0].is_nan() && out[1] == 1.0 && out[3] == 2.0);
    }

    #[test]
    fn constant_window_gives_a_flat_feature() {
        let s = vec![Complex64::new(1.0, 0.0); 4];
        let h = modulated(&[0; 10], &s, &s);
        let mut u = Vec::new();
        combined_projection(&h, 2, &mut u);
        assert_eq!(u, vec![0.0; 10]);
    }
}

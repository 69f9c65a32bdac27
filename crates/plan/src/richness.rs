//! How many distinct tiles a longer render will touch: extrapolating the number of "species"
//! (tiles) from the abundances seen in a short sample.
//!
//! A profile at a few percent of the final render's samples sees most tiles the camera looks at
//! (each is read by hundreds of pixels) but only part of those that deeper bounces read (each
//! read rarely). The count of distinct tiles a render with `N = n + m` draws will touch is
//! estimated with the Chao1 / Good–Turing based extrapolation of Chao et al. (2014, "Rarefaction
//! and extrapolation with Hill numbers"), from the observed count `S_obs`, the number of tiles
//! seen exactly once (`f1`) and twice (`f2`):
//!
//! ```text
//! f̂0        = (n−1)/n · f1² / (2 f2)          (f2 > 0)
//!           = (n−1)/n · f1 (f1 − 1) / 2        (f2 = 0)
//! Ŝ(n + m)  = S_obs + f̂0 · [1 − (1 − f1 / (n f̂0 + f1))^m]
//! ```
//!
//! `f̂0` is Chao1's estimate of the tiles never seen; the bracket is the Good–Turing estimate of
//! the fraction of them that `m` more draws find. Why this estimator rather than a fitted
//! saturation curve: it needs nothing but the touch counts a profile keeps anyway, it is exact
//! in expectation for tiles whose probability is well represented by the singletons, and as
//! `m → ∞` it tends to Chao1, a lower bound on the tiles that exist — right for renders many
//! times longer than their profile. Its assumption is that draws are independent and identically
//! distributed: camera samples are (their pixels are a uniform mixture), while the draws of one
//! path are not, which makes singletons slightly rarer than under independence.

/// Extrapolated distinct tiles after `n + extra` draws, from the touch counts of the observed
/// tiles (`n` = their sum). Counts of zero are ignored. Returns `S_obs` when nothing is known
/// about unseen tiles (no singletons, or fewer than two draws).
pub fn extrapolate<I: IntoIterator<Item = u64>>(counts: I, extra: f64) -> f64 {
    let (mut s_obs, mut n, mut f1, mut f2) = (0u64, 0u64, 0u64, 0u64);
    for c in counts {
        if c == 0 {
            continue;
        }
        s_obs += 1;
        n += c;
        match c {
            1 => f1 += 1,
            2 => f2 += 1,
            _ => {}
        }
    }
    extrapolate_from(s_obs as f64, n as f64, f1 as f64, f2 as f64, extra)
}

/// [`extrapolate`] from the summary `(S_obs, n, f1, f2)`.
pub fn extrapolate_from(s_obs: f64, n: f64, f1: f64, f2: f64, extra: f64) -> f64 {
    if n < 2.0 || f1 <= 0.0 || extra <= 0.0 {
        return s_obs;
    }
    let f0 = unseen(n, f1, f2);
    if f0 <= 0.0 {
        return s_obs;
    }
    let x = f1 / (n * f0 + f1);
    // (1 − x)^m without underflow or cancellation for large m and small x.
    let found = 1.0 - (extra * (-x).ln_1p()).exp();
    s_obs + f0 * found
}

/// Chao1's bias-corrected estimate of the tiles never seen, `f̂0`.
pub fn unseen(n: f64, f1: f64, f2: f64) -> f64 {
    let k = (n - 1.0) / n;
    if f2 > 0.0 {
        k * f1 * f1 / (2.0 * f2)
    } else {
        k * f1 * (f1 - 1.0) / 2.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A small deterministic generator (xorshift*).
    struct Rng(u64);
    impl Rng {
        fn f64(&mut self) -> f64 {
            self.0 ^= self.0 >> 12;
            self.0 ^= self.0 << 25;
            self.0 ^= self.0 >> 27;
            (self.0.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// Expected distinct species after `draws` independent draws from `p`.
    fn expected_species(p: &[f64], draws: f64) -> f64 {
        p.iter().map(|&q| 1.0 - (draws * (-q).ln_1p()).exp()).sum()
    }

    /// Draws from `p` by its cumulative distribution.
    fn sample_counts(p: &[f64], n: usize, rng: &mut Rng) -> Vec<u64> {
        let mut cdf = Vec::with_capacity(p.len());
        let mut acc = 0.0;
        for &q in p {
            acc += q;
            cdf.push(acc);
        }
        let mut counts = vec![0u64; p.len()];
        for _ in 0..n {
            let u = rng.f64() * acc;
            let i = cdf.partition_point(|&c| c < u).min(p.len() - 1);
            counts[i] += 1;
        }
        counts
    }

    /// Against the exact expectation on a population shaped like tile reads (a dense core read
    /// often, a long tail read rarely, 16 % of the reads): the extrapolation to 4× the sample is
    /// within 10 % of the truth, to 16× within 20 % (Chao1 is a lower bound: the tail's unseen
    /// tiles are underestimated; measured 3.7 %, 6.9 % and 15.8 %), and always within a third of
    /// the error of assuming no new tiles appear (measured 54 %, 42 %, 75 %).
    #[test]
    fn extrapolation_tracks_the_expected_species_count() {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        // 400 tiles a camera reads often + 5000 tiles deeper bounces read rarely (geometric tail).
        let mut p: Vec<f64> = vec![1.0; 400];
        p.extend((0..5000).map(|i| 0.05 * (-(i as f64) / 1500.0).exp()));
        let total: f64 = p.iter().sum();
        p.iter_mut().for_each(|q| *q /= total);
        for &(n, factor, bound) in &[(4000usize, 4.0, 0.10), (20000, 4.0, 0.10), (4000, 16.0, 0.20)] {
            let mut errs = Vec::new();
            let mut obs_errs = Vec::new();
            for _ in 0..20 {
                let counts = sample_counts(&p, n, &mut rng);
                let truth = expected_species(&p, n as f64 * factor);
                let est = extrapolate(counts.iter().copied(), n as f64 * (factor - 1.0));
                let s_obs = counts.iter().filter(|&&c| c > 0).count() as f64;
                errs.push((est - truth).abs() / truth);
                obs_errs.push((s_obs - truth).abs() / truth);
            }
            let mean = errs.iter().sum::<f64>() / errs.len() as f64;
            let mean_obs = obs_errs.iter().sum::<f64>() / obs_errs.len() as f64;
            eprintln!("n {n} ×{factor}: mean relative error {mean:.3} (S_obs: {mean_obs:.3})");
            assert!(mean < bound, "n {n} ×{factor}: mean relative error {mean:.3}");
            assert!(mean < mean_obs / 3.0, "n {n} ×{factor}: {mean:.3} is not well below S_obs's {mean_obs:.3}");
        }
    }

    /// With every tile seen many times nothing new is predicted; with no extra draws, nothing
    /// either; the estimate grows with the number of extra draws and stays below Chao1.
    #[test]
    fn limits_and_monotonicity() {
        assert_eq!(extrapolate([5, 7, 9, 3], 1e6), 4.0);
        assert_eq!(extrapolate([1, 1, 2, 3], 0.0), 4.0);
        let counts = [1u64, 1, 1, 2, 2, 5, 9];
        let n: u64 = counts.iter().sum();
        let chao1 = 7.0 + unseen(n as f64, 3.0, 2.0);
        let mut last = 7.0;
        for m in [1.0, 10.0, 100.0, 1e4, 1e9] {
            let s = extrapolate(counts, m);
            assert!(s >= last && s <= chao1 + 1e-9, "m {m}: {s} (last {last}, Chao1 {chao1})");
            last = s;
        }
        assert!((last - chao1).abs() < 1e-6);
    }
}

//! Property tests of the BSDFs, each checked against something independent of the code under
//! test: χ² goodness of fit of `sample` against `pdf`, `sample`'s weight against `eval/pdf`,
//! energy (white furnace) against quadrature of `eval`, reciprocity, and the smooth lobes'
//! energy split against the Fresnel equations.

use super::*;
use crate::sampling::Rng;
use std::f64::consts::PI as PI64;

// ---------------------------------------------------------------------------------------------
// Helpers

fn dir(theta: f32, phi: f32) -> Vec3 {
    Vec3::new(theta.sin() * phi.cos(), theta.sin() * phi.sin(), theta.cos())
}

fn dir_zphi(z: f64, phi: f64) -> Vec3 {
    let r = (1.0 - z * z).max(0.0).sqrt();
    Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, z as f32)
}

fn diffuse(r: f32) -> Bsdf {
    Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: Spectrum::splat(r) }))
}

fn rough_conductor(kind: MicrofacetKind, au: f32, av: f32, material: &str) -> Bsdf {
    let (eta, k) = conductor_preset(material).unwrap();
    Bsdf::new(BsdfModel::RoughConductor(RoughConductor {
        distribution: Microfacet::new(kind, au, av),
        eta,
        k,
        specular_reflectance: Spectrum::ONE,
    }))
}

fn rough_dielectric(kind: MicrofacetKind, au: f32, av: f32, eta: f32) -> Bsdf {
    Bsdf::new(BsdfModel::RoughDielectric(RoughDielectric {
        distribution: Microfacet::new(kind, au, av),
        eta,
        specular_reflectance: Spectrum::ONE,
        specular_transmittance: Spectrum::ONE,
    }))
}

const KINDS: [MicrofacetKind; 2] = [MicrofacetKind::Beckmann, MicrofacetKind::Ggx];

/// ∫∫ f over [z0,z1]×[p0,p1] by 3-point Gauss–Legendre in each variable.
fn gauss3(f: &impl Fn(f64, f64) -> f64, z0: f64, z1: f64, p0: f64, p1: f64) -> f64 {
    const X: [f64; 3] = [-0.774_596_669_241_483_4, 0.0, 0.774_596_669_241_483_4];
    const W: [f64; 3] = [5.0 / 9.0, 8.0 / 9.0, 5.0 / 9.0];
    let (zc, zh) = (0.5 * (z0 + z1), 0.5 * (z1 - z0));
    let (pc, ph) = (0.5 * (p0 + p1), 0.5 * (p1 - p0));
    let mut s = 0.0;
    for i in 0..3 {
        for j in 0..3 {
            s += W[i] * W[j] * f(zc + zh * X[i], pc + ph * X[j]);
        }
    }
    s * zh * ph
}

/// Adaptive 2-D quadrature: refines a cell into quadrants until they agree with the whole.
fn integrate(f: &impl Fn(f64, f64) -> f64, z0: f64, z1: f64, p0: f64, p1: f64, abs_tol: f64, depth: u32) -> f64 {
    let whole = gauss3(f, z0, z1, p0, p1);
    let (zm, pm) = (0.5 * (z0 + z1), 0.5 * (p0 + p1));
    let quads = [(z0, zm, p0, pm), (zm, z1, p0, pm), (z0, zm, pm, p1), (zm, z1, pm, p1)];
    let parts: f64 = quads.iter().map(|&(a, b, c, d)| gauss3(f, a, b, c, d)).sum();
    if depth == 0 || (parts - whole).abs() <= 1e-5 * parts.abs() + abs_tol {
        return parts;
    }
    quads.iter().map(|&(a, b, c, d)| integrate(f, a, b, c, d, abs_tol * 0.5, depth - 1)).sum()
}

/// ∫ g(ω) dω over the sphere (or the part with z in [z_lo, z_hi]) by adaptive quadrature on a
/// coarse grid in (z, φ); dω = dz dφ.
fn sphere_integral(g: &impl Fn(Vec3) -> f64, z_lo: f64, z_hi: f64) -> f64 {
    let f = |z: f64, p: f64| g(dir_zphi(z, p));
    let (nz, np) = (16, 32);
    let mut s = 0.0;
    for i in 0..nz {
        let z0 = z_lo + (z_hi - z_lo) * i as f64 / nz as f64;
        let z1 = z_lo + (z_hi - z_lo) * (i + 1) as f64 / nz as f64;
        for j in 0..np {
            let p0 = -PI64 + 2.0 * PI64 * j as f64 / np as f64;
            let p1 = -PI64 + 2.0 * PI64 * (j + 1) as f64 / np as f64;
            s += integrate(&f, z0, z1, p0, p1, 1e-8, 9);
        }
    }
    s
}

// ---------------------------------------------------------------------------------------------
// Regularised incomplete gamma function, for χ² p-values.

/// ln Γ(x) for x > 0: Stirling's series after shifting x above 10 by the recurrence.
fn ln_gamma(mut x: f64) -> f64 {
    let mut shift = 0.0;
    while x < 10.0 {
        shift -= x.ln();
        x += 1.0;
    }
    let x2 = x * x;
    let series =
        1.0 / (12.0 * x) - 1.0 / (360.0 * x * x2) + 1.0 / (1260.0 * x * x2 * x2) - 1.0 / (1680.0 * x * x2 * x2 * x2);
    shift + (x - 0.5) * x.ln() - x + 0.5 * (2.0 * PI64).ln() + series
}

/// Upper regularised incomplete gamma Q(a, x) = Γ(a, x)/Γ(a): the power series of P for
/// x < a + 1, the continued fraction of Q (modified Lentz) otherwise.
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let log_prefactor = a * x.ln() - x - ln_gamma(a);
    if x < a + 1.0 {
        // P(a, x) = e^{-x} x^a / Γ(a+1) Σ x^n / ((a+1)…(a+n))
        let mut term = 1.0 / a;
        let mut sum = term;
        let mut n = 1.0;
        while term.abs() > 1e-16 * sum.abs() && n < 10_000.0 {
            term *= x / (a + n);
            sum += term;
            n += 1.0;
        }
        1.0 - sum * log_prefactor.exp()
    } else {
        // Q(a, x) = e^{-x} x^a / Γ(a) · 1/(x+1−a− 1(1−a)/(x+3−a− 2(2−a)/(x+5−a− …)))
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let delta = d * c;
            h *= delta;
            if (delta - 1.0).abs() < 1e-15 {
                break;
            }
        }
        log_prefactor.exp() * h
    }
}

#[test]
fn bsdf_incomplete_gamma_known_values() {
    // Γ(n) = (n−1)!
    assert!((ln_gamma(5.0) - 24f64.ln()).abs() < 1e-12);
    assert!((ln_gamma(0.5) - PI64.sqrt().ln()).abs() < 1e-12);
    for &x in &[0.01, 0.3, 1.0, 2.5, 7.0, 30.0] {
        // Q(1, x) = e^{−x}: the χ² survival function with 2 degrees of freedom.
        assert!((gamma_q(1.0, x) - (-x).exp()).abs() < 1e-12, "Q(1,{x})");
        // Q(1/2, x) = erfc(√x).
        let want = special::erfc(x.sqrt());
        assert!((gamma_q(0.5, x) - want).abs() < 2e-7 * want + 1e-15, "Q(1/2,{x})");
        // Q(2, x) = (1 + x) e^{−x}.
        assert!((gamma_q(2.0, x) - (1.0 + x) * (-x).exp()).abs() < 1e-12, "Q(2,{x})");
    }
    // χ² with 100 degrees of freedom: median ≈ 99.334.
    assert!((gamma_q(50.0, 99.334 / 2.0) - 0.5).abs() < 1e-3);
}

// ---------------------------------------------------------------------------------------------
// χ² goodness of fit of sample() against pdf()

/// Number of χ² configurations run across all tests: the Bonferroni correction divides the
/// significance level 1 % by it.
const CHI2_TESTS: usize = 4 + 33 + 24;
const CHI2_SAMPLES: usize = 400_000;
const CHI2_PILOT: usize = 40_000;
const CHI2_BINS: usize = 16;
/// Integration cells per χ² bin and axis.
const CHI2_REFINE: usize = 4;

/// Bin edges at the quantiles of `values` (from an independent pilot run, so that the bins are
/// close to equiprobable), plus the fixed edges `fixed`.
fn quantile_edges(values: &mut [f64], n: usize, fixed: &[f64]) -> Vec<f64> {
    values.sort_by(|a, b| a.partial_cmp(b).unwrap());
    let mut edges: Vec<f64> = fixed.to_vec();
    if values.len() >= 10 * n {
        for k in 1..n {
            edges.push(values[k * values.len() / n]);
        }
    }
    edges.sort_by(|a, b| a.partial_cmp(b).unwrap());
    edges.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    edges
}

/// Inserts edges so that neighbouring cells differ in width by at most a factor 2 (a graded
/// mesh): the large outer cells then grow geometrically away from the fine cells of a lobe,
/// and quadrature nodes follow its tails instead of stepping over them.
fn graded(edges: &[f64]) -> Vec<f64> {
    let mut e = edges.to_vec();
    loop {
        let mut out = vec![e[0]];
        let mut changed = false;
        for k in 0..e.len() - 1 {
            let (a, b) = (e[k], e[k + 1]);
            let w = b - a;
            let wl = if k > 0 { e[k] - e[k - 1] } else { f64::INFINITY };
            let wr = if k + 2 < e.len() { e[k + 2] - e[k + 1] } else { f64::INFINITY };
            let wn = wl.min(wr);
            if w > 2.0 * wn && wn > 0.0 {
                // Split next to the smaller neighbour.
                out.push(if wl <= wr { a + 2.0 * wl } else { b - 2.0 * wr });
                changed = true;
            }
            out.push(b);
        }
        out.sort_by(|x, y| x.partial_cmp(y).unwrap());
        e = out;
        if !changed {
            return e;
        }
    }
}

struct Chi2Outcome {
    p: f64,
    chi2: f64,
    dof: usize,
    none_observed: usize,
    none_expected: f64,
}

/// χ² test of `bsdf.sample(wi, ·)` against `bsdf.pdf(wi, ·)` on a (cos θ, φ) grid whose edges
/// are pilot-run quantiles (plus the horizon, where the density jumps). The expected count of a
/// cell is N ∫ pdf over it by adaptive quadrature; failed samples (`None`) form one more cell
/// whose expectation is N (1 − ∫ pdf). Cells expecting fewer than 5 are pooled.
fn chi2_test(bsdf: &Bsdf, wi: Vec3, seed: u64) -> Chi2Outcome {
    let zphi = |w: Vec3| {
        let w = w.normalize();
        ((w.z as f64).clamp(-1.0, 1.0), (w.y as f64).atan2(w.x as f64))
    };
    // Pilot run for the bin edges.
    let mut rng = Rng::new(seed, 11);
    let (mut zs, mut ps) = (Vec::new(), Vec::new());
    for _ in 0..CHI2_PILOT {
        if let Some(s) = bsdf.sample(wi, rng.next_f32(), rng.next_2d()) {
            let (z, p) = zphi(s.wo);
            zs.push(z);
            ps.push(p);
        }
    }
    let z_edges = quantile_edges(&mut zs, CHI2_BINS, &[-1.0, 0.0, 1.0]);
    let p_edges = quantile_edges(&mut ps, CHI2_BINS, &[-PI64, PI64]);
    let (nz, np) = (z_edges.len() - 1, p_edges.len() - 1);

    // Expected probabilities: adaptive quadrature on a finer quantile grid nested in the bins,
    // so that no integration cell is much larger than the lobe's local scale (a compact lobe
    // hiding between the nodes of a large cell would otherwise be missed).
    let fz = graded(&quantile_edges(&mut zs, CHI2_BINS * CHI2_REFINE, &z_edges));
    let fp = graded(&quantile_edges(&mut ps, CHI2_BINS * CHI2_REFINE, &p_edges));
    let pdf = |z: f64, p: f64| bsdf.pdf(wi, dir_zphi(z, p)) as f64;
    let mut expected = vec![0.0; nz * np];
    for a in 0..fz.len() - 1 {
        let i = z_edges.partition_point(|&e| e <= 0.5 * (fz[a] + fz[a + 1])).clamp(1, nz) - 1;
        for b in 0..fp.len() - 1 {
            let j = p_edges.partition_point(|&e| e <= 0.5 * (fp[b] + fp[b + 1])).clamp(1, np) - 1;
            expected[i * np + j] += integrate(&pdf, fz[a], fz[a + 1], fp[b], fp[b + 1], 1e-10, 6);
        }
    }
    let total: f64 = expected.iter().sum();
    assert!(total <= 1.0 + 1e-3, "pdf integrates to {total} > 1");

    // Observations.
    let mut observed = vec![0usize; nz * np];
    let mut none_observed = 0;
    let mut rng = Rng::new(seed, 12);
    for _ in 0..CHI2_SAMPLES {
        match bsdf.sample(wi, rng.next_f32(), rng.next_2d()) {
            Some(s) => {
                let (z, p) = zphi(s.wo);
                let i = z_edges.partition_point(|&e| e <= z).clamp(1, nz) - 1;
                let j = p_edges.partition_point(|&e| e <= p).clamp(1, np) - 1;
                observed[i * np + j] += 1;
            }
            None => none_observed += 1,
        }
    }
    let n = CHI2_SAMPLES as f64;
    let none_expected = n * (1.0 - total).max(0.0);
    let mut cells: Vec<(f64, f64)> = expected.iter().zip(&observed).map(|(&e, &o)| (e * n, o as f64)).collect();
    cells.push((none_expected, none_observed as f64));
    // Observations where the density is exactly zero are a plain failure.
    if let Some(&(_, o)) = cells.iter().find(|&&(e, o)| e == 0.0 && o > 0.0) {
        println!("{o} samples where the density integrates to zero");
        return Chi2Outcome { p: 0.0, chi2: f64::INFINITY, dof: 0, none_observed, none_expected };
    }
    // Pool cells expecting < 5 into one (merging it with the next smallest until it reaches 5).
    cells.sort_by(|a, b| a.0.partial_cmp(&b.0).unwrap());
    let mut pooled = (0.0, 0.0);
    let mut chi2 = 0.0;
    let mut k = 0usize;
    for &(e, o) in &cells {
        if pooled.0 < 5.0 && (e < 5.0 || pooled.0 > 0.0) {
            pooled.0 += e;
            pooled.1 += o;
            if pooled.0 >= 5.0 {
                chi2 += (pooled.1 - pooled.0).powi(2) / pooled.0;
                k += 1;
            }
            continue;
        }
        chi2 += (o - e).powi(2) / e;
        k += 1;
    }
    if pooled.0 > 0.0 && pooled.0 < 5.0 {
        // Whatever is left is too small to be a cell of its own; it still must not be wildly off.
        chi2 += (pooled.1 - pooled.0).powi(2) / pooled.0.max(1.0);
        k += 1;
    }
    let dof = k.saturating_sub(1).max(1);
    Chi2Outcome { p: gamma_q(dof as f64 / 2.0, chi2 / 2.0), chi2, dof, none_observed, none_expected }
}

fn run_chi2(cases: &[(String, Bsdf, Vec3)]) {
    let threshold = 0.01 / CHI2_TESTS as f64;
    let mut failures = Vec::new();
    for (i, (name, bsdf, wi)) in cases.iter().enumerate() {
        let r = chi2_test(bsdf, *wi, 1000 + i as u64);
        println!(
            "χ² {name}: p = {:.4}, χ² = {:.1}, dof = {}, none {} (expected {:.1})",
            r.p, r.chi2, r.dof, r.none_observed, r.none_expected
        );
        if r.p.is_nan() || r.p <= threshold {
            failures.push(format!("{name}: p = {:.3e} (χ² {:.1}, dof {})", r.p, r.chi2, r.dof));
        }
    }
    assert!(failures.is_empty(), "χ² failures (threshold {threshold:.1e}):\n{}", failures.join("\n"));
}

#[test]
fn bsdf_chi2_diffuse() {
    let mut cases = Vec::new();
    for theta in [0.0f32, 0.8, 1.5] {
        cases.push((format!("diffuse θ={theta}"), diffuse(0.7), dir(theta, 0.4)));
    }
    cases.push(("twosided diffuse, back".into(), diffuse(0.7).two_sided(), dir(2.2, 1.0)));
    assert_eq!(cases.len(), 4);
    run_chi2(&cases);
}

#[test]
fn bsdf_chi2_rough_conductor() {
    let mut cases = Vec::new();
    for kind in KINDS {
        for (au, av) in [(0.05, 0.05), (0.2, 0.2), (0.5, 0.5), (0.05, 0.3)] {
            for theta in [0.0f32, 0.7, 1.2, 1.53] {
                let b = rough_conductor(kind, au, av, "Cu");
                cases.push((format!("roughconductor {kind:?} α=({au},{av}) θ={theta}"), b, dir(theta, 0.3)));
            }
        }
    }
    let b = rough_conductor(MicrofacetKind::Beckmann, 0.3, 0.3, "Au").two_sided();
    cases.push(("twosided roughconductor, back".into(), b, dir(2.5, -0.5)));
    assert_eq!(cases.len(), 33);
    run_chi2(&cases);
}

#[test]
fn bsdf_chi2_rough_dielectric() {
    let mut cases = Vec::new();
    for kind in KINDS {
        for (au, av) in [(0.1, 0.1), (0.5, 0.5), (0.08, 0.3)] {
            // Outside; outside near grazing; inside below and beyond the critical angle (41.7°).
            for theta in [0.5f32, 1.45, std::f32::consts::PI - 0.4, std::f32::consts::PI - 1.0] {
                let b = rough_dielectric(kind, au, av, 1.5);
                cases.push((format!("roughdielectric {kind:?} α=({au},{av}) θ={theta}"), b, dir(theta, 0.9)));
            }
        }
    }
    assert_eq!(cases.len(), 24);
    run_chi2(&cases);
}

// ---------------------------------------------------------------------------------------------
// sample() against eval()/pdf()

fn smooth_bsdfs() -> Vec<(String, Bsdf)> {
    let mut v = vec![("diffuse".to_string(), diffuse(0.6)), ("twosided diffuse".to_string(), diffuse(0.6).two_sided())];
    for kind in KINDS {
        for (au, av) in [(0.05, 0.05), (0.3, 0.3), (0.8, 0.8), (0.04, 0.4)] {
            v.push((format!("roughconductor {kind:?} ({au},{av})"), rough_conductor(kind, au, av, "Au")));
            v.push((format!("roughdielectric {kind:?} ({au},{av})"), rough_dielectric(kind, au, av, 1.5)));
        }
        v.push((format!("twosided roughconductor {kind:?}"), rough_conductor(kind, 0.2, 0.2, "Al").two_sided()));
        v.push((format!("roughdielectric {kind:?} η<1"), rough_dielectric(kind, 0.3, 0.3, 1.0 / 1.33)));
    }
    v
}

#[test]
fn bsdf_sample_weight_matches_eval_over_pdf() {
    let mut rng = Rng::new(77, 3);
    for (name, bsdf) in smooth_bsdfs() {
        let (mut n, mut loose) = (0usize, 0usize);
        for _ in 0..20_000 {
            // Directions over the whole sphere, including near-grazing ones.
            let wi = crate::sampling::square_to_uniform_sphere(rng.next_2d());
            let Some(s) = bsdf.sample(wi, rng.next_f32(), rng.next_2d()) else { continue };
            n += 1;
            assert!((s.wo.length() - 1.0).abs() < 1e-4, "{name}: |wo| = {}", s.wo.length());
            assert_eq!(s.transmitted, s.wo.z * wi.z < 0.0, "{name}: transmitted flag");
            assert!(s.pdf > 0.0 && s.pdf.is_finite() && s.weight.is_finite() && s.weight.min_element() >= 0.0);
            let (f, pdf) = bsdf.eval_pdf(wi, s.wo);
            assert_eq!(f, bsdf.eval(wi, s.wo));
            assert_eq!(pdf, bsdf.pdf(wi, s.wo));
            let rel = |a: f32, b: f32| (a - b).abs() / a.abs().max(b.abs()).max(1e-30);
            let e_pdf = rel(s.pdf, pdf);
            let expect = f / pdf;
            let e_w = (0..3).map(|c| rel(s.weight[c], expect[c])).fold(0.0f32, f32::max);
            // f32 recomputation of the half vector: demand 1e-3 almost always, 2 % always.
            if e_pdf > 1e-3 || e_w > 1e-3 {
                loose += 1;
            }
            assert!(
                e_pdf < 2e-2 && e_w < 2e-2,
                "{name}: wi {wi} wo {}: pdf {} vs {pdf}, weight {} vs {expect}",
                s.wo,
                s.pdf,
                s.weight
            );
            let want_eta = if s.transmitted {
                let eta = match bsdf.model {
                    BsdfModel::RoughDielectric(d) => d.eta,
                    _ => unreachable!(),
                };
                if wi.z > 0.0 {
                    eta
                } else {
                    1.0 / eta
                }
            } else {
                1.0
            };
            assert!((s.eta - want_eta).abs() < 1e-6, "{name}: eta {}", s.eta);
            assert_eq!(
                s.kind,
                if name.contains("diffuse") && !name.contains("rough") { LobeKind::Diffuse } else { LobeKind::Glossy }
            );
        }
        assert!(n > 2000, "{name}: only {n} samples");
        assert!(loose * 1000 <= n, "{name}: {loose} of {n} samples off by more than 1e-3");
    }
}

// ---------------------------------------------------------------------------------------------
// Energy (white furnace)

/// Mean and standard error of sample weights (channel 0), or of `map(sample)`.
fn mean_weight(bsdf: &Bsdf, wi: Vec3, n: usize, seed: u64, map: impl Fn(&BsdfSample) -> f64) -> (f64, f64) {
    let mut rng = Rng::new(seed, 5);
    let (mut s, mut s2) = (0.0, 0.0);
    for _ in 0..n {
        if let Some(b) = bsdf.sample(wi, rng.next_f32(), rng.next_2d()) {
            let w = map(&b);
            s += w;
            s2 += w * w;
        }
    }
    let mean = s / n as f64;
    (mean, ((s2 / n as f64 - mean * mean).max(0.0) / n as f64).sqrt())
}

#[test]
fn bsdf_furnace_diffuse() {
    let b = diffuse(1.0);
    for theta in [0.0f32, 0.7, 1.4] {
        let wi = dir(theta, 0.2);
        let albedo = sphere_integral(&|wo| b.eval(wi, wo).x as f64, -1.0, 1.0);
        assert!((albedo - 1.0).abs() < 1e-3, "∫ eval = {albedo}");
        let (m, _) = mean_weight(&b, wi, 10_000, 1, |s| s.weight.x as f64);
        assert!((m - 1.0).abs() < 1e-6);
        let pdf_total = sphere_integral(&|wo| b.pdf(wi, wo) as f64, -1.0, 1.0);
        assert!((pdf_total - 1.0).abs() < 1e-3, "∫ pdf = {pdf_total}");
    }
    // One-sided: black from the back.
    assert!(b.sample(dir(2.0, 0.0), 0.5, Vec2::splat(0.5)).is_none());
    assert_eq!(b.eval(dir(2.0, 0.0), dir(0.3, 0.0)), Spectrum::ZERO);
}

#[test]
fn bsdf_furnace_rough_conductor() {
    // material "none": F = 1, so the albedo is the Smith masking loss alone.
    let (m, se) =
        mean_weight(&rough_conductor(MicrofacetKind::Beckmann, 0.05, 0.05, "none"), Vec3::Z, 100_000, 2, |s| {
            s.weight.x as f64
        });
    assert!(m > 0.97 && m <= 1.0 + 1e-6, "Beckmann α=0.05 normal incidence albedo {m} ± {se}");
    for kind in KINDS {
        for alpha in [0.05f32, 0.2, 0.5] {
            let b = rough_conductor(kind, alpha, alpha, "none");
            for theta in [0.0f32, 0.8, 1.3] {
                let wi = dir(theta, 0.5);
                let (m, se) = mean_weight(&b, wi, 100_000, 3, |s| s.weight.x as f64);
                assert!(m <= 1.0 + 3.0 * se + 1e-6, "{kind:?} α={alpha} θ={theta}: albedo {m}");
                if alpha >= 0.2 {
                    // Independent estimate: quadrature of eval over the hemisphere.
                    let q = sphere_integral(&|wo| b.eval(wi, wo).x as f64, 0.0, 1.0);
                    assert!(
                        (q - m).abs() < 4.0 * se + 2e-3,
                        "{kind:?} α={alpha} θ={theta}: ∫eval {q} vs E[weight] {m} ± {se}"
                    );
                    let p = sphere_integral(&|wo| b.pdf(wi, wo) as f64, 0.0, 1.0);
                    assert!(p <= 1.0 + 1e-3, "∫pdf = {p}");
                }
                // Normal incidence loses little for moderate roughness (GGX α = 0.5 reflects 20 %
                // of its facets' light below the horizon, so it is not checked).
                if theta == 0.0 && alpha <= 0.2 {
                    assert!(m > 0.9, "{kind:?} α={alpha}: albedo {m} at normal incidence");
                }
            }
        }
    }
}

#[test]
fn bsdf_furnace_rough_dielectric() {
    let eta = 1.5f32;
    for kind in KINDS {
        for alpha in [0.1f32, 0.4] {
            let b = rough_dielectric(kind, alpha, alpha, eta);
            for theta in [0.3f32, 1.2, std::f32::consts::PI - 0.3, std::f32::consts::PI - 1.0] {
                let wi = dir(theta, -0.4);
                // Undo the radiance scaling η_ti² of refraction to get the energy fraction.
                let eta_ti2 = if wi.z > 0.0 { 1.0 / (eta * eta) } else { eta * eta } as f64;
                let energy = |s: &BsdfSample| s.weight.x as f64 / if s.transmitted { eta_ti2 } else { 1.0 };
                let (m, se) = mean_weight(&b, wi, 100_000, 4, energy);
                assert!(m <= 1.0 + 3.0 * se + 1e-6, "{kind:?} α={alpha} θ={theta}: energy {m}");
                let floor = if alpha <= 0.1 { 0.95 } else { 0.6 };
                assert!(m > floor, "{kind:?} α={alpha} θ={theta}: energy {m} too low");
                if alpha >= 0.4 {
                    let q = sphere_integral(
                        &|wo| {
                            let v = b.eval(wi, wo).x as f64;
                            if wo.z * wi.z < 0.0 {
                                v / eta_ti2
                            } else {
                                v
                            }
                        },
                        -1.0,
                        1.0,
                    );
                    assert!((q - m).abs() < 4.0 * se + 3e-3, "{kind:?} α={alpha} θ={theta}: ∫eval {q} vs E {m} ± {se}");
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Reciprocity

#[test]
fn bsdf_reciprocity() {
    let mut rng = Rng::new(5, 9);
    let hemi = |rng: &mut Rng| {
        let mut v = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        v.z = v.z.abs();
        v
    };
    let mut cases = vec![diffuse(0.8), rough_conductor(MicrofacetKind::Beckmann, 0.3, 0.3, "Au")];
    for kind in KINDS {
        cases.push(rough_conductor(kind, 0.6, 0.15, "Cu"));
        cases.push(rough_dielectric(kind, 0.4, 0.4, 1.5));
    }
    for b in &cases {
        let mut checked = 0;
        for _ in 0..5000 {
            let (mut wi, mut wo) = (hemi(&mut rng), hemi(&mut rng));
            if matches!(b.model, BsdfModel::RoughDielectric(_)) && rng.next_f32() < 0.5 {
                // Reflection from inside.
                wi.z = -wi.z;
                wo.z = -wo.z;
            }
            let a = b.eval(wi, wo) / wo.z.abs();
            let c = b.eval(wo, wi) / wi.z.abs();
            let scale = a.max_element().max(c.max_element());
            if scale > 0.0 {
                checked += 1;
            }
            assert!((a - c).abs().max_element() <= 1e-3 * scale + 1e-5, "{b:?}: f(wi,wo) {a} vs f(wo,wi) {c}");
        }
        assert!(checked > 1000);
    }
    // Refraction: with radiance scaling, f(wo→wi) = η² f(wi→wo) for wi outside, wo inside
    // (f/η_o² is symmetric, η_o the IOR on wo's side).
    for kind in KINDS {
        let eta = 1.5f32;
        let b = rough_dielectric(kind, 0.4, 0.4, eta);
        let mut checked = 0;
        for _ in 0..20_000 {
            let wi = hemi(&mut rng);
            let mut wo = hemi(&mut rng);
            wo.z = -wo.z;
            let a = b.eval(wi, wo).x / wo.z.abs();
            let c = b.eval(wo, wi).x / wi.z.abs();
            if a > 0.0 {
                checked += 1;
            }
            assert!(
                (c - eta * eta * a).abs() <= 1e-3 * c.max(eta * eta * a) + 1e-4,
                "f(wo,wi) {c} vs η² f(wi,wo) {}; wi {wi} wo {wo}",
                eta * eta * a
            );
        }
        assert!(checked > 1000, "{checked}");
    }
}

// ---------------------------------------------------------------------------------------------
// Smooth (delta) BSDFs

#[test]
fn bsdf_smooth_dielectric_energy_split() {
    let spec_t = Spectrum::new(1.0, 0.5, 0.25);
    let spec_r = Spectrum::new(0.9, 0.8, 0.7);
    for eta in [1.5f32, 1.0 / 1.33] {
        let b = Bsdf::new(BsdfModel::Dielectric(Dielectric {
            eta,
            specular_reflectance: spec_r,
            specular_transmittance: spec_t,
        }));
        assert!(!b.has_smooth());
        for theta in [0.0f32, 0.4, 1.0, 1.5, 1.7, 2.3, 2.8, std::f32::consts::PI] {
            let wi = dir(theta, 0.6);
            let eta_ti = if wi.z > 0.0 { 1.0 / eta } else { eta };
            let f = fresnel_dielectric(wi.z, eta).r;
            let n = 10_000;
            let (mut refl, mut trans) = (Spectrum::ZERO, Spectrum::ZERO);
            for i in 0..n {
                let s = b.sample(wi, (i as f32 + 0.5) / n as f32, Vec2::splat(0.5)).unwrap();
                assert_eq!(s.kind, LobeKind::Specular);
                assert_eq!(s.alpha, 0.0);
                assert!((s.wo.length() - 1.0).abs() < 1e-5);
                assert_eq!(b.eval(wi, s.wo), Spectrum::ZERO);
                assert_eq!(b.pdf(wi, s.wo), 0.0);
                if s.transmitted {
                    assert!((s.pdf - (1.0 - f)).abs() < 1e-6);
                    assert!((s.eta - 1.0 / eta_ti).abs() < 1e-6);
                    // Snell: sin θ_t = η_ti sin θ_i, in the plane of incidence, other side.
                    let sin_i = (1.0 - wi.z * wi.z).sqrt();
                    let sin_t = (1.0 - s.wo.z * s.wo.z).max(0.0).sqrt();
                    assert!((sin_t - eta_ti * sin_i).abs() < 1e-5);
                    assert!(s.wo.z * wi.z < 0.0 && s.wo.truncate().dot(wi.truncate()) <= 1e-6);
                    trans += s.weight / (eta_ti * eta_ti);
                } else {
                    assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
                    assert!((s.pdf - f).abs() < 1e-6 && s.eta == 1.0);
                    refl += s.weight;
                }
            }
            refl /= n as f32;
            trans /= n as f32;
            let tol = 2e-4;
            assert!((refl - spec_r * f).abs().max_element() < tol, "η {eta} θ {theta}: R {refl} vs {}", spec_r * f);
            assert!((trans - spec_t * (1.0 - f)).abs().max_element() < tol, "T {trans} vs {}", spec_t * (1.0 - f));
            // Beyond the critical angle everything reflects.
            let sin_i = (1.0 - wi.z * wi.z).sqrt();
            if eta_ti * sin_i > 1.0 {
                assert_eq!(f, 1.0);
                assert_eq!(trans, Spectrum::ZERO);
            }
        }
        // With unit multipliers the split conserves energy exactly: R + T/η_ti² = 1.
        let b = Bsdf::new(BsdfModel::Dielectric(Dielectric {
            eta,
            specular_reflectance: Spectrum::ONE,
            specular_transmittance: Spectrum::ONE,
        }));
        let wi = dir(0.9, 0.0);
        let eta_ti = 1.0 / eta;
        let n = 4000;
        let e: f32 = (0..n)
            .map(|i| {
                let s = b.sample(wi, (i as f32 + 0.5) / n as f32, Vec2::ZERO).unwrap();
                s.weight.x / if s.transmitted { eta_ti * eta_ti } else { 1.0 }
            })
            .sum::<f32>()
            / n as f32;
        assert!((e - 1.0).abs() < 1e-4, "energy {e}");
    }
}

#[test]
fn bsdf_smooth_conductor() {
    for name in ["Au", "Ag", "Cu", "Al", "none"] {
        let (eta, k) = conductor_preset(name).unwrap();
        let spec = Spectrum::new(1.0, 0.9, 0.8);
        let b = Bsdf::new(BsdfModel::Conductor(Conductor { eta, k, specular_reflectance: spec }));
        assert!(!b.has_smooth());
        for theta in [0.0f32, 0.5, 1.2, 1.55] {
            let wi = dir(theta, 1.1);
            let s = b.sample(wi, 0.3, Vec2::new(0.2, 0.7)).unwrap();
            assert_eq!(s.wo, Vec3::new(-wi.x, -wi.y, wi.z));
            assert_eq!((s.pdf, s.kind, s.transmitted, s.eta, s.alpha), (1.0, LobeKind::Specular, false, 1.0, 0.0));
            let want = spec * fresnel_conductor(wi.z, eta, k);
            assert!((s.weight - want).abs().max_element() < 1e-6);
            if name == "none" {
                assert!((s.weight - spec).abs().max_element() < 1e-6);
            }
            assert_eq!(b.eval(wi, s.wo), Spectrum::ZERO);
            assert_eq!(b.pdf(wi, s.wo), 0.0);
        }
        assert!(b.sample(dir(2.0, 0.0), 0.3, Vec2::ZERO).is_none(), "one-sided");
        assert!(b.two_sided().sample(dir(2.0, 0.0), 0.3, Vec2::ZERO).unwrap().wo.z < 0.0);
    }
}

// ---------------------------------------------------------------------------------------------
// twosided, descriptions, robustness

#[test]
fn bsdf_twosided_mirrors_the_front() {
    let inner = rough_conductor(MicrofacetKind::Ggx, 0.3, 0.1, "Cu");
    let b = inner.two_sided();
    let mut rng = Rng::new(3, 3);
    for _ in 0..1000 {
        let wi = dir(0.2 + 1.2 * rng.next_f32(), 6.0 * rng.next_f32());
        let wo = dir(0.1 + 1.4 * rng.next_f32(), 6.0 * rng.next_f32());
        let flip = |v: Vec3| Vec3::new(v.x, v.y, -v.z);
        assert_eq!(b.eval(flip(wi), flip(wo)), inner.eval(wi, wo));
        assert_eq!(b.pdf(flip(wi), flip(wo)), inner.pdf(wi, wo));
        assert_eq!(b.eval(wi, wo), inner.eval(wi, wo));
        assert_eq!(inner.eval(flip(wi), flip(wo)), Spectrum::ZERO, "one-sided inner");
        assert_eq!(b.eval(flip(wi), wo), Spectrum::ZERO, "no transmission");
        let (u1, u2) = (rng.next_f32(), rng.next_2d());
        let (a, c) = (b.sample(flip(wi), u1, u2), inner.sample(wi, u1, u2));
        assert_eq!(a.map(|s| flip(s.wo)), c.map(|s| s.wo));
        assert_eq!(a.map(|s| s.weight), c.map(|s| s.weight));
    }
}

#[test]
fn bsdf_desc_evaluates_textures() {
    use glam::Affine2;
    let checker = Texture::Checkerboard {
        color0: Spectrum::new(0.9, 0.1, 0.1),
        color1: Spectrum::new(0.1, 0.1, 0.9),
        to_uv: Affine2::IDENTITY,
    };
    let desc = BsdfDesc::TwoSided(Box::new(BsdfDesc::Diffuse { reflectance: checker }));
    let a = desc.at(&ShadeContext::uv(Vec2::new(0.25, 0.25)));
    let c = desc.at(&ShadeContext::uv(Vec2::new(0.75, 0.25)));
    assert!(a.two_sided && desc.has_smooth());
    match (a.model, c.model) {
        (BsdfModel::Diffuse(x), BsdfModel::Diffuse(y)) => {
            assert_eq!(x.reflectance, Spectrum::new(0.9, 0.1, 0.1));
            assert_eq!(y.reflectance, Spectrum::new(0.1, 0.1, 0.9));
        }
        _ => panic!("wrong model"),
    }
    match BsdfDesc::default().at(&ShadeContext::uv(Vec2::ZERO)).model {
        BsdfModel::Diffuse(d) => assert_eq!(d.reflectance, Spectrum::splat(0.5)),
        _ => panic!(),
    }
    let (eta, k) = conductor_preset("Au").unwrap();
    let rc = BsdfDesc::RoughConductor {
        eta,
        k,
        specular_reflectance: Texture::Constant(Spectrum::ONE),
        distribution: MicrofacetKind::Ggx,
        alpha_u: Texture::Constant(Spectrum::splat(0.0)),
        alpha_v: Texture::Constant(Spectrum::splat(0.3)),
    };
    match rc.at(&ShadeContext::uv(Vec2::ZERO)).model {
        BsdfModel::RoughConductor(r) => {
            assert_eq!(r.distribution.alpha_u, microfacet::MIN_ALPHA, "α clamped like Mitsuba");
            assert_eq!(r.distribution.kind, MicrofacetKind::Ggx);
        }
        _ => panic!(),
    }
    let d = BsdfDesc::Dielectric {
        eta: DEFAULT_INT_IOR / DEFAULT_EXT_IOR,
        specular_reflectance: Texture::Constant(Spectrum::ONE),
        specular_transmittance: Texture::Constant(Spectrum::ONE),
    };
    assert!(!d.has_smooth() && !d.at(&ShadeContext::uv(Vec2::ZERO)).has_smooth());
    assert!(conductor_preset("Xx").is_none());
    assert_eq!(dielectric_ior_preset("bk7"), Some(1.5046));
    assert_eq!(beckmann_equivalent_alpha(MicrofacetKind::Beckmann, 0.3), 0.3);
    // Median slope magnitudes agree: the Beckmann CDF of |slope| at GGX's median (= α) is ½.
    let ab = beckmann_equivalent_alpha(MicrofacetKind::Ggx, 0.3) as f64;
    let beckmann_cdf_at_ggx_median = 1.0 - (-(0.3f64 * 0.3) / (ab * ab)).exp();
    assert!((beckmann_cdf_at_ggx_median - 0.5).abs() < 1e-5, "{beckmann_cdf_at_ggx_median}");
}

#[test]
fn bsdf_never_returns_nan() {
    let mut all: Vec<Bsdf> = smooth_bsdfs().into_iter().map(|(_, b)| b).collect();
    for kind in KINDS {
        for alpha in [1e-4f32, 1e-3, 1.0, 3.0] {
            all.push(rough_conductor(kind, alpha, alpha, "Ag"));
            all.push(rough_dielectric(kind, alpha, alpha, 1.5));
            all.push(rough_dielectric(kind, alpha, alpha, 1.0));
        }
    }
    for eta in [1.5f32, 1.0] {
        all.push(Bsdf::new(BsdfModel::Dielectric(Dielectric {
            eta,
            specular_reflectance: Spectrum::ONE,
            specular_transmittance: Spectrum::ONE,
        })));
    }
    let (eta, k) = conductor_preset("Au").unwrap();
    all.push(Bsdf::new(BsdfModel::Conductor(Conductor { eta, k, specular_reflectance: Spectrum::ONE })));
    let special = [
        Vec3::Z,
        -Vec3::Z,
        Vec3::X,
        -Vec3::Y,
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        Vec3::new(0.0, 1.0, -1e-7).normalize(),
        Vec3::new(0.6, 0.8, 0.0),
        Vec3::new(1e-7, 0.0, 1.0).normalize(),
    ];
    let us = [0.0f32, 1e-7, 0.5, 0.999_999_9];
    let mut rng = Rng::new(8, 8);
    for b in &all {
        let mut dirs: Vec<Vec3> = special.to_vec();
        for _ in 0..200 {
            dirs.push(crate::sampling::square_to_uniform_sphere(rng.next_2d()));
        }
        for &wi in &dirs {
            for &wo in &dirs {
                let (f, p) = b.eval_pdf(wi, wo);
                assert!(
                    f.is_finite() && f.min_element() >= 0.0 && p.is_finite() && p >= 0.0,
                    "{b:?} {wi} {wo}: {f} {p}"
                );
            }
            for &u0 in &us {
                for &u1 in &us {
                    for &ul in &[0.0f32, 0.5, 0.999_999_9] {
                        if let Some(s) = b.sample(wi, ul, Vec2::new(u0, u1)) {
                            assert!(
                                s.wo.is_finite() && (s.wo.length() - 1.0).abs() < 1e-3,
                                "{b:?} wi {wi} u ({u0},{u1}): wo {}",
                                s.wo
                            );
                            assert!(
                                s.weight.is_finite() && s.weight.min_element() >= 0.0,
                                "{b:?}: weight {}",
                                s.weight
                            );
                            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{b:?} wi {wi}: pdf {}", s.pdf);
                            assert!(s.eta.is_finite() && s.alpha.is_finite());
                        }
                    }
                }
            }
        }
    }
}

// ---------------------------------------------------------------------------------------------
// Autodesk Standard Surface (MaterialX standard_surface)

use super::standard_surface::{StandardSurface, StandardSurfaceParams};

/// A standard surface with MaterialX defaults changed by `f`.
fn std_surface(f: impl FnOnce(&mut StandardSurfaceParams)) -> Bsdf {
    let mut p = StandardSurfaceParams::DEFAULT;
    f(&mut p);
    Bsdf::new(BsdfModel::StandardSurface(StandardSurface::new(&p)))
}

/// `specular_roughness` giving GGX roughness `alpha` (α = roughness²).
fn rough_for(alpha: f32) -> f32 {
    alpha.sqrt()
}

/// Named parameter sets exercising every lobe and combination.
fn std_surface_sets() -> Vec<(String, Bsdf)> {
    let mut v = Vec::new();
    v.push((
        "pure diffuse".to_string(),
        std_surface(|p| {
            p.specular = 0.0;
            p.base_color = Spectrum::new(0.7, 0.5, 0.3);
        }),
    ));
    for alpha in [0.05f32, 0.5] {
        v.push((
            format!("metal α={alpha}"),
            std_surface(|p| {
                p.metalness = 1.0;
                p.base = 1.0;
                p.base_color = Spectrum::new(0.95, 0.64, 0.54);
                p.specular_color = Spectrum::new(1.0, 0.9, 0.8);
                p.specular_roughness = rough_for(alpha);
            }),
        ));
        v.push((
            format!("plastic α={alpha}"),
            std_surface(|p| {
                p.base = 1.0;
                p.base_color = Spectrum::new(0.8, 0.1, 0.1);
                p.specular_roughness = rough_for(alpha);
            }),
        ));
        v.push((
            format!("glass α={alpha}"),
            std_surface(|p| {
                p.transmission = 1.0;
                p.specular_roughness = rough_for(alpha);
            }),
        ));
    }
    v.push((
        "50/50 mix".to_string(),
        std_surface(|p| {
            p.metalness = 0.5;
            p.transmission = 0.5;
            p.base = 1.0;
            p.base_color = Spectrum::new(0.2, 0.6, 0.9);
            p.specular_color = Spectrum::new(0.9, 1.0, 0.8);
            p.transmission_color = Spectrum::new(1.0, 0.7, 0.7);
            p.specular_roughness = rough_for(0.25);
            p.specular_ior = 1.33;
        }),
    ));
    v.push((
        "half-specular glass".to_string(),
        std_surface(|p| {
            p.transmission = 1.0;
            p.specular = 0.5;
            p.specular_roughness = rough_for(0.2);
            p.specular_ior = 1.7;
        }),
    ));
    v
}

/// χ² configurations of the standard surface, counted in the Bonferroni family with the others.
const STD_CHI2_TESTS: usize = 2 + 4 + 6 + 6 + 3 + 2;

/// As `run_chi2`, with the significance level divided by `family` tests.
fn run_chi2_family(cases: &[(String, Bsdf, Vec3)], family: usize, seed: u64) {
    let threshold = 0.01 / family as f64;
    let mut failures = Vec::new();
    for (i, (name, bsdf, wi)) in cases.iter().enumerate() {
        let r = chi2_test(bsdf, *wi, seed + i as u64);
        println!(
            "χ² {name}: p = {:.4}, χ² = {:.1}, dof = {}, none {} (expected {:.1})",
            r.p, r.chi2, r.dof, r.none_observed, r.none_expected
        );
        if r.p.is_nan() || r.p <= threshold {
            failures.push(format!("{name}: p = {:.3e} (χ² {:.1}, dof {})", r.p, r.chi2, r.dof));
        }
    }
    assert!(failures.is_empty(), "χ² failures (threshold {threshold:.1e}):\n{}", failures.join("\n"));
}

#[test]
fn bsdf_chi2_standard_surface() {
    use std::f32::consts::PI;
    let sets = std_surface_sets();
    let get = |name: &str| sets.iter().find(|(n, _)| n == name).unwrap().1;
    let mut cases = Vec::new();
    let mut add = |name: &str, thetas: &[f32]| {
        for &theta in thetas {
            cases.push((format!("standard_surface {name} θ={theta}"), get(name), dir(theta, 0.7)));
        }
    };
    add("pure diffuse", &[0.3, 1.3]);
    add("metal α=0.05", &[0.2, 1.2]);
    add("metal α=0.5", &[0.2, 1.2]);
    add("plastic α=0.05", &[0.0, 0.8, 1.45]);
    add("plastic α=0.5", &[0.0, 0.8, 1.45]);
    // Outside; inside below and beyond the critical angle (41.8°).
    add("glass α=0.05", &[0.5, PI - 0.4, PI - 1.0]);
    add("glass α=0.5", &[0.5, PI - 0.4, PI - 1.0]);
    add("50/50 mix", &[0.4, 1.3, PI - 0.6]);
    add("half-specular glass", &[0.9, PI - 0.9]);
    assert_eq!(cases.len(), STD_CHI2_TESTS);
    run_chi2_family(&cases, CHI2_TESTS + STD_CHI2_TESTS, 5000);
}

#[test]
fn bsdf_standard_surface_sample_matches_eval_and_pdf() {
    let mut rng = Rng::new(78, 3);
    for (name, bsdf) in std_surface_sets() {
        let BsdfModel::StandardSurface(ss) = bsdf.model else { unreachable!() };
        let eta = ss.params().specular_ior;
        let want_alpha = beckmann_equivalent_alpha(MicrofacetKind::Ggx, ss.distribution().alpha_u);
        let (mut n, mut loose, mut kinds) = (0usize, 0usize, [0usize; 2]);
        for _ in 0..20_000 {
            let wi = crate::sampling::square_to_uniform_sphere(rng.next_2d());
            let Some(s) = bsdf.sample(wi, rng.next_f32(), rng.next_2d()) else { continue };
            n += 1;
            assert!((s.wo.length() - 1.0).abs() < 1e-4, "{name}: |wo| = {}", s.wo.length());
            assert_eq!(s.transmitted, s.wo.z * wi.z < 0.0, "{name}: transmitted flag");
            assert!(s.pdf > 0.0 && s.pdf.is_finite() && s.weight.is_finite() && s.weight.min_element() >= 0.0);
            let (f, pdf) = bsdf.eval_pdf(wi, s.wo);
            assert_eq!(f, bsdf.eval(wi, s.wo));
            assert_eq!(pdf, bsdf.pdf(wi, s.wo));
            let rel = |a: f32, b: f32| (a - b).abs() / a.abs().max(b.abs()).max(1e-30);
            let e_pdf = rel(s.pdf, pdf);
            let expect = f / pdf;
            let e_w = (0..3).map(|c| rel(s.weight[c], expect[c])).fold(0.0f32, f32::max);
            if e_pdf > 1e-3 || e_w > 1e-3 {
                loose += 1;
            }
            assert!(
                e_pdf < 2e-2 && e_w < 2e-2,
                "{name}: wi {wi} wo {}: pdf {} vs {pdf}, weight {} vs {expect}",
                s.wo,
                s.pdf,
                s.weight
            );
            let want_eta = match (s.transmitted, wi.z > 0.0) {
                (false, _) => 1.0,
                (true, true) => eta,
                (true, false) => 1.0 / eta,
            };
            assert!((s.eta - want_eta).abs() < 1e-6, "{name}: eta {}", s.eta);
            match s.kind {
                LobeKind::Diffuse => {
                    kinds[0] += 1;
                    assert_eq!(s.alpha, 1.0);
                    assert!(wi.z > 0.0 && s.wo.z > 0.0);
                }
                LobeKind::Glossy => {
                    kinds[1] += 1;
                    assert_eq!(s.alpha, want_alpha);
                }
                LobeKind::Specular => panic!("{name}: no delta lobes"),
            }
        }
        println!("{name}: {n} samples, {} diffuse, {} glossy, {loose} loose", kinds[0], kinds[1]);
        assert!(n > 2000, "{name}: only {n} samples");
        assert!(loose * 1000 <= n, "{name}: {loose} of {n} samples off by more than 1e-3");
        if name.contains("plastic") || name.contains("mix") {
            assert!(kinds[0] > 0 && kinds[1] > 0, "{name}: both strategies must be used");
        }
    }
}

#[test]
fn bsdf_standard_surface_pure_diffuse_is_lambert() {
    let rho = Spectrum::new(0.7, 0.5, 0.3);
    let b = std_surface(|p| {
        p.specular = 0.0;
        p.base = 1.0;
        p.base_color = rho;
        p.specular_roughness = 0.4;
    });
    let lambert = Bsdf::new(BsdfModel::Diffuse(Diffuse { reflectance: rho }));
    let mut rng = Rng::new(12, 1);
    for _ in 0..5000 {
        let wi = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        let wo = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        let (f, p) = b.eval_pdf(wi, wo);
        let (fl, pl) = lambert.eval_pdf(wi, wo);
        assert!((f - fl).abs().max_element() <= 1e-6 * fl.max_element(), "{f} vs Lambert {fl}");
        assert!((p - pl).abs() <= 1e-6 * pl, "pdf {p} vs {pl}");
        let (ul, u) = (rng.next_f32(), rng.next_2d());
        match (b.sample(wi, ul, u), lambert.sample(wi, ul, u)) {
            (Some(s), Some(t)) => {
                assert_eq!(s.wo, t.wo);
                assert!((s.weight - rho).abs().max_element() < 1e-5, "weight {}", s.weight);
                assert_eq!((s.kind, s.alpha, s.transmitted), (LobeKind::Diffuse, 1.0, false));
            }
            (None, None) => {}
            (a, c) => panic!("sample mismatch {a:?} vs {c:?}"),
        }
    }
}

/// Energy of a sample: its weight (channel 0) with the radiance scaling of refraction undone.
fn std_energy(eta: f32, wi: Vec3) -> impl Fn(&BsdfSample) -> f64 {
    let eta_ti2 = if wi.z > 0.0 { 1.0 / (eta * eta) } else { eta * eta } as f64;
    move |s: &BsdfSample| s.weight.x as f64 / if s.transmitted { eta_ti2 } else { 1.0 }
}

#[test]
fn bsdf_furnace_standard_surface() {
    use std::f32::consts::PI;
    let eta = 1.5f32;
    for metalness in [0.0f32, 1.0] {
        for transmission in [0.0f32, 1.0] {
            for alpha in [0.04f32, 0.25, 0.64] {
                let b = std_surface(|p| {
                    p.base = 1.0;
                    p.metalness = metalness;
                    p.transmission = transmission;
                    p.specular_roughness = rough_for(alpha);
                    p.specular_ior = eta;
                });
                let mut thetas = vec![0.0f32, 0.7, 1.3];
                if transmission > 0.0 {
                    thetas.extend([PI - 0.3, PI - 1.0]);
                }
                for theta in thetas {
                    let wi = dir(theta, -0.4);
                    let name = format!("m={metalness} t={transmission} α={alpha} θ={theta}");
                    let (m, se) = mean_weight(&b, wi, 100_000, 7, std_energy(eta, wi));
                    println!("furnace {name}: {m:.5} ± {se:.5}");
                    assert!(m <= 1.0 + 3.0 * se + 1e-3, "{name}: energy {m} ± {se} > 1");
                    // The opaque dielectric: specular + albedo-scaled diffuse = 1 up to the table's
                    // error (and the diffuse lobe is white).
                    if metalness == 0.0 && transmission == 0.0 {
                        assert!((m - 1.0).abs() < 3.0 * se + 4e-3, "{name}: energy {m} ± {se}, want 1");
                    }
                    // Independent estimate: quadrature of eval.
                    if alpha >= 0.25 && theta < 1.0 {
                        let eta_ti2 = if wi.z > 0.0 { 1.0 / (eta * eta) } else { eta * eta } as f64;
                        let q = sphere_integral(
                            &|wo| {
                                let v = b.eval(wi, wo).x as f64;
                                if wo.z * wi.z < 0.0 {
                                    v / eta_ti2
                                } else {
                                    v
                                }
                            },
                            -1.0,
                            1.0,
                        );
                        assert!((q - m).abs() < 4.0 * se + 3e-3, "{name}: ∫eval {q} vs E[weight] {m} ± {se}");
                    }
                }
            }
        }
    }
}

#[test]
fn bsdf_standard_surface_metal_matches_conductor() {
    // base·base_color = 1 and a white edge: Gulbrandsen's IOR reflects 0.99 at normal incidence
    // (the reflectivity is clamped there) and more toward grazing, so the albedo is within ~1 %
    // of the perfect GGX mirror's (masking loss only), and never above it.
    for alpha in [0.04f32, 0.25, 0.64] {
        let b = std_surface(|p| {
            p.base = 1.0;
            p.metalness = 1.0;
            p.specular_roughness = rough_for(alpha);
        });
        let c = rough_conductor(MicrofacetKind::Ggx, alpha, alpha, "none");
        for theta in [0.0f32, 0.8, 1.3] {
            let wi = dir(theta, 0.5);
            let (m, se) = mean_weight(&b, wi, 50_000, 3, |s| s.weight.x as f64);
            let (mc, _) = mean_weight(&c, wi, 50_000, 3, |s| s.weight.x as f64);
            println!("metal α={alpha} θ={theta}: {m:.5} ± {se:.5} vs conductor {mc:.5}");
            // Same random numbers and the same visible-normal sampling: the estimates differ by
            // the Fresnel factor alone.
            assert!(m <= mc + 1e-6 && m > mc - 0.012, "α={alpha} θ={theta}: {m} vs conductor {mc}");
        }
    }
}

#[test]
fn bsdf_standard_surface_glass_is_rough_dielectric() {
    // transmission 1, specular 1, white tints: exactly GGX roughdielectric.
    for (alpha, eta) in [(0.05f32, 1.5f32), (0.3, 1.33), (0.7, 2.0)] {
        let b = std_surface(|p| {
            p.transmission = 1.0;
            p.specular_roughness = rough_for(alpha);
            p.specular_ior = eta;
        });
        let BsdfModel::StandardSurface(ss) = b.model else { unreachable!() };
        let a = ss.distribution().alpha_u;
        let d = rough_dielectric(MicrofacetKind::Ggx, a, a, eta);
        let mut rng = Rng::new(4, 4);
        let mut nonzero = 0;
        for _ in 0..20_000 {
            let wi = crate::sampling::square_to_uniform_sphere(rng.next_2d());
            let wo = crate::sampling::square_to_uniform_sphere(rng.next_2d());
            let (f, p) = b.eval_pdf(wi, wo);
            let (fd, pd) = d.eval_pdf(wi, wo);
            if pd > 0.0 {
                nonzero += 1;
            }
            assert!((f - fd).abs().max_element() <= 1e-4 * fd.max_element() + 1e-12, "{f} vs {fd}");
            assert!((p - pd).abs() <= 1e-4 * pd + 1e-12, "pdf {p} vs {pd}");
        }
        assert!(nonzero > 5000);
    }
}

#[test]
fn bsdf_reciprocity_standard_surface() {
    // With the symmetric albedo scaling (1 − sE(θ_i))(1 − sE(θ_o))/(1 − sE_avg), the whole
    // reflection part is reciprocal — metal, dielectric specular and diffuse together, outside;
    // inside (transmission > 0) the dielectric reflection. Refraction obeys
    // f(wo, wi) = η² f(wi, wo) for wi outside. (A plain (1 − F(θ_i)) diffuse attenuation would
    // not be reciprocal; this model does not use one.)
    let mut rng = Rng::new(6, 9);
    let hemi = |rng: &mut Rng| {
        let mut v = crate::sampling::square_to_uniform_sphere(rng.next_2d());
        v.z = v.z.abs();
        v
    };
    for (name, b) in std_surface_sets() {
        let BsdfModel::StandardSurface(ss) = b.model else { unreachable!() };
        let has_t = ss.params().transmission > 0.0;
        let eta = ss.params().specular_ior;
        let mut checked = 0;
        for _ in 0..5000 {
            let (mut wi, mut wo) = (hemi(&mut rng), hemi(&mut rng));
            if has_t && rng.next_f32() < 0.5 {
                wi.z = -wi.z;
                wo.z = -wo.z;
            }
            let a = b.eval(wi, wo) / wo.z.abs();
            let c = b.eval(wo, wi) / wi.z.abs();
            let scale = a.max_element().max(c.max_element());
            if scale > 0.0 {
                checked += 1;
            }
            assert!((a - c).abs().max_element() <= 1e-3 * scale + 1e-5, "{name}: f(wi,wo) {a} vs f(wo,wi) {c}");
        }
        assert!(checked > 1000, "{name}: {checked}");
        if has_t {
            let mut checked = 0;
            for _ in 0..5000 {
                let wi = hemi(&mut rng);
                let mut wo = hemi(&mut rng);
                wo.z = -wo.z;
                let a = b.eval(wi, wo) / wo.z.abs();
                let c = b.eval(wo, wi) / wi.z.abs();
                if a.max_element() > 0.0 {
                    checked += 1;
                }
                let want = a * (eta * eta);
                assert!(
                    (c - want).abs().max_element() <= 1e-3 * c.max_element().max(want.max_element()) + 1e-4,
                    "{name}: f(wo,wi) {c} vs η² f(wi,wo) {want}"
                );
            }
            assert!(checked > 500, "{name}: {checked}");
        }
    }
}

#[test]
fn bsdf_standard_surface_one_sided_and_back() {
    // Opaque: black from below, like roughconductor.
    let b = std_surface(|p| p.metalness = 0.3);
    let below = dir(2.0, 0.3);
    assert!(b.sample(below, 0.5, Vec2::splat(0.5)).is_none());
    assert_eq!(b.eval_pdf(below, dir(0.5, 0.0)), (Spectrum::ZERO, 0.0));
    assert_eq!(b.eval_pdf(below, dir(2.5, 0.0)), (Spectrum::ZERO, 0.0));
    // No transmission when opaque.
    assert_eq!(b.eval(dir(0.5, 0.0), dir(2.5, 1.0)), Spectrum::ZERO);
    // Two-sided via the adapter.
    assert!(b.two_sided().sample(below, 0.5, Vec2::splat(0.5)).is_some());
    // With transmission, from inside: only reflection and refraction — no diffuse, no metal.
    let t = std_surface(|p| {
        p.transmission = 0.5;
        p.metalness = 0.5;
        p.specular_roughness = 0.5;
    });
    let mut rng = Rng::new(2, 2);
    for _ in 0..2000 {
        if let Some(s) = t.sample(dir(2.6, 0.2), rng.next_f32(), rng.next_2d()) {
            assert_eq!(s.kind, LobeKind::Glossy);
        }
    }
    assert!(b.has_smooth() && t.has_smooth());
}

#[test]
fn bsdf_standard_surface_desc() {
    let c = |v: f32| Texture::Constant(Spectrum::splat(v));
    let desc = BsdfDesc::StandardSurface {
        base: c(0.5),
        base_color: Texture::Constant(Spectrum::new(0.2, 0.4, 0.6)),
        metalness: c(0.25),
        specular: c(0.75),
        specular_color: c(0.9),
        specular_roughness: c(0.3),
        specular_ior: c(1.6),
        transmission: c(0.1),
        transmission_color: c(0.8),
    };
    assert!(desc.has_smooth());
    let b = desc.at(&ShadeContext::uv(Vec2::ZERO));
    assert!(b.has_smooth() && !b.two_sided);
    let BsdfModel::StandardSurface(ss) = b.model else { panic!("wrong model") };
    let p = ss.params();
    assert_eq!((p.base, p.metalness, p.specular, p.specular_roughness), (0.5, 0.25, 0.75, 0.3));
    assert_eq!((p.specular_ior, p.transmission), (1.6, 0.1));
    assert_eq!(p.base_color, Spectrum::new(0.2, 0.4, 0.6));
    assert_eq!((p.specular_color, p.transmission_color), (Spectrum::splat(0.9), Spectrum::splat(0.8)));
    assert!((ss.distribution().alpha_u - 0.09).abs() < 1e-7 && ss.distribution().kind == MicrofacetKind::Ggx);
    // α clamped like the other BSDFs; inputs clamped to their ranges.
    let z = std_surface(|p| {
        p.specular_roughness = 0.0;
        p.metalness = 7.0;
        p.specular_ior = f32::NAN;
        p.base_color = Spectrum::new(-1.0, f32::NAN, 2.0);
    });
    let BsdfModel::StandardSurface(z) = z.model else { unreachable!() };
    assert_eq!(z.distribution().alpha_u, microfacet::MIN_ALPHA);
    assert_eq!((z.params().metalness, z.params().specular_ior), (1.0, 1.5));
    assert_eq!(z.params().base_color, Spectrum::new(0.0, 0.0, 1.0));
}

#[test]
fn bsdf_standard_surface_never_returns_nan() {
    let mut all: Vec<Bsdf> = std_surface_sets().into_iter().map(|(_, b)| b).collect();
    for r in [0.0f32, 0.01, 1.0] {
        for eta in [0.25f32, 0.9, 1.0, 1.0001, 4.0] {
            for (m, s, t) in
                [(0.0f32, 1.0f32, 0.0f32), (0.0, 0.0, 1.0), (1.0, 1.0, 0.0), (0.5, 0.5, 0.5), (0.0, 1.0, 1.0)]
            {
                all.push(std_surface(|p| {
                    p.specular_roughness = r;
                    p.specular_ior = eta;
                    p.metalness = m;
                    p.specular = s;
                    p.transmission = t;
                    p.base = 1.0;
                }));
            }
        }
    }
    // Black everything.
    all.push(std_surface(|p| {
        p.base = 0.0;
        p.specular = 0.0;
        p.transmission = 0.0;
    }));
    all.push(std_surface(|p| {
        p.base = 0.0;
        p.metalness = 1.0;
        p.specular = 0.0;
    }));
    let special = [
        Vec3::Z,
        -Vec3::Z,
        Vec3::X,
        -Vec3::Y,
        Vec3::new(1.0, 0.0, 1e-7).normalize(),
        Vec3::new(0.0, 1.0, -1e-7).normalize(),
        Vec3::new(0.6, 0.8, 0.0),
        Vec3::new(1e-7, 0.0, 1.0).normalize(),
    ];
    let us = [0.0f32, 1e-7, 0.5, 0.999_999_9];
    let mut rng = Rng::new(8, 9);
    for b in &all {
        let mut dirs: Vec<Vec3> = special.to_vec();
        for _ in 0..60 {
            dirs.push(crate::sampling::square_to_uniform_sphere(rng.next_2d()));
        }
        for &wi in &dirs {
            for &wo in &dirs {
                let (f, p) = b.eval_pdf(wi, wo);
                assert!(
                    f.is_finite() && f.min_element() >= 0.0 && p.is_finite() && p >= 0.0,
                    "{b:?} {wi} {wo}: {f} {p}"
                );
            }
            for &u0 in &us {
                for &u1 in &us {
                    for &ul in &[0.0f32, 0.3, 0.999_999_9] {
                        if let Some(s) = b.sample(wi, ul, Vec2::new(u0, u1)) {
                            assert!(
                                s.wo.is_finite() && (s.wo.length() - 1.0).abs() < 1e-3,
                                "{b:?} wi {wi}: wo {}",
                                s.wo
                            );
                            assert!(
                                s.weight.is_finite() && s.weight.min_element() >= 0.0,
                                "{b:?}: weight {}",
                                s.weight
                            );
                            assert!(s.pdf.is_finite() && s.pdf > 0.0, "{b:?} wi {wi}: pdf {}", s.pdf);
                            assert!(s.eta.is_finite() && s.alpha.is_finite());
                        }
                    }
                }
            }
        }
    }
}

/// `reads_uv` is false only where the BSDF (and its opacity) is the same at every uv: the path
/// loop then skips a hit's parametrisation.
#[test]
fn reads_uv_only_where_the_bsdf_varies() {
    use glam::Affine2;
    let checker = || Texture::Checkerboard {
        color0: Spectrum::new(0.9, 0.2, 0.1),
        color1: Spectrum::new(0.1, 0.3, 0.8),
        to_uv: Affine2::from_scale(Vec2::splat(3.0)),
    };
    let constant = |v: f32| Texture::Constant(Spectrum::splat(v));
    let rough = |alpha_v: Texture| BsdfDesc::RoughConductor {
        eta: Spectrum::splat(0.2),
        k: Spectrum::splat(3.0),
        specular_reflectance: constant(1.0),
        distribution: MicrofacetKind::Ggx,
        alpha_u: constant(0.2),
        alpha_v,
    };
    let cases = [
        (BsdfDesc::Diffuse { reflectance: constant(0.5) }, false),
        (BsdfDesc::Diffuse { reflectance: checker() }, true),
        (BsdfDesc::TwoSided(Box::new(BsdfDesc::Diffuse { reflectance: checker() })), true),
        (BsdfDesc::TwoSided(Box::new(rough(constant(0.4)))), false),
        (rough(checker()), true),
        (
            BsdfDesc::Mask {
                opacity: checker(),
                scalar: true,
                bsdf: Box::new(BsdfDesc::Diffuse { reflectance: constant(0.5) }),
            },
            true,
        ),
        (
            BsdfDesc::Mask {
                opacity: constant(0.7),
                scalar: true,
                bsdf: Box::new(BsdfDesc::Diffuse { reflectance: constant(0.5) }),
            },
            false,
        ),
    ];
    let uvs = [Vec2::new(0.05, 0.05), Vec2::new(0.2, 0.05), Vec2::new(0.05, 0.2), Vec2::new(0.7, 0.9)];
    for (k, (desc, reads)) in cases.iter().enumerate() {
        assert_eq!(desc.reads_uv(), *reads, "case {k}");
        let at = |uv| (desc.at(&ShadeContext::uv(uv)), desc.opacity(&ShadeContext::uv(uv)));
        let same = uvs.iter().all(|&uv| at(uv) == at(uvs[0]));
        // Every varying case here does vary over these points; none that reads no uv may.
        assert_eq!(same, !reads, "case {k}");
    }
}

//! Tests of the filtered Perlin lattices: fits of the constants, against brute force.

use super::filter::*;
use super::lattice::*;
use super::perlin::*;
use crate::nodes::hash::{self, cell3_float, cell3_vec3};
use glam::{DVec2, DVec3, Vec2, Vec3};

mod perlin2 {
    use super::*;

    /// Room for spreads up to 3.8 lattice units: the references beyond [`PERLIN_SIGMA_EXACT`].
    const WIDE: usize = 32;

    /// The exact convolution at any spread (per channel: value, ∂/∂x, ∂/∂y).
    fn exact_wide(p: DVec2, s: DVec2, sel: HashSel) -> (f64, f64, f64) {
        let mut o = [(0.0, 0.0, 0.0); 4];
        perlin_exact_n::<WIDE, false>(
            p,
            s.max(DVec2::splat(1e-4)),
            PERLIN_TAIL,
            &[sel],
            &mut o,
            &mut crate::eval::Work::default(),
        );
        o[0]
    }

    /// Centres spread over many lattice cells (incommensurate steps).
    fn centres() -> Vec<DVec2> {
        let mut v = Vec::new();
        for i in 0..40 {
            for j in 0..40 {
                v.push(DVec2::new(0.37 + i as f64 * 0.6173, 0.11 + j as f64 * 0.5791));
            }
        }
        v
    }

    fn field(s: DVec2, sel: HashSel) -> Vec<f64> {
        centres().iter().map(|&p| exact_wide(p, s, sel).0).collect()
    }

    fn mean_square(v: impl Iterator<Item = f64>) -> f64 {
        let (mut acc, mut n) = (0.0, 0.0);
        for x in v {
            acc += x * x;
            n += 1.0;
        }
        acc / n
    }

    const LATTICES: [HashSel; 2] = [HashSel::Full, HashSel::Slice(0.37)];

    /// The global variance of Perlin noise (`PERLIN_VARIANCE`).
    #[test]
    fn perlin_variance() {
        let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..400 {
            for j in 0..400 {
                let v = perlin_float(Vec2::new(0.013 + i as f32 * 0.0517, 0.029 + j as f32 * 0.0491)) as f64;
                s += v;
                s2 += v * v;
                n += 1.0;
            }
        }
        let var = s2 / n - (s / n).powi(2);
        println!("perlin variance {var:.4}");
        assert!((var - PERLIN_VARIANCE).abs() < 0.005, "variance {var}");
    }

    /// The corner sum is the Gaussian average of the unfiltered noise, up to and beyond
    /// [`PERLIN_SIGMA_EXACT`] (against brute-force quadrature over ±6σ, which sees every
    /// corner), and its derivatives are those of the value.
    #[test]
    fn exact_matches_brute_force() {
        let cases = [
            (DVec2::new(0.3, -1.7), DVec2::new(0.25, 0.25), HashSel::Full),
            (DVec2::new(2.61, 0.45), DVec2::new(0.6, 0.35), HashSel::Full),
            (DVec2::new(-3.2, 5.05), DVec2::new(1.0, 1.0), HashSel::Full),
            (DVec2::new(7.9, -0.2), DVec2::new(1.0, 0.1), HashSel::Byte(1)),
            (DVec2::new(1.37, 2.61), DVec2::new(0.8, 0.5), HashSel::Slice(0.37)),
            (DVec2::new(-4.1, 3.3), DVec2::new(1.6, 1.2), HashSel::Full),
        ];
        for (p, s, sel) in cases {
            let n = 400;
            let mut acc = 0.0;
            let mut wsum = 0.0;
            for i in 0..n {
                let zx = -6.0 + 12.0 * (i as f64 + 0.5) / n as f64;
                let wx = (-0.5 * zx * zx).exp();
                for j in 0..n {
                    let zy = -6.0 + 12.0 * (j as f64 + 0.5) / n as f64;
                    let w = wx * (-0.5 * zy * zy).exp();
                    let q = p + DVec2::new(zx * s.x, zy * s.y);
                    acc += w * perlin_point(q.as_vec2(), sel) as f64;
                    wsum += w;
                }
            }
            let brute = acc / wsum;
            let (v, dx, dy) = exact_wide(p, s, sel);
            let mut o = [(0.0, 0.0, 0.0); 4];
            if s.max_element() <= PERLIN_SIGMA_EXACT {
                perlin_exact(p, s, &[sel], &mut o, &mut crate::eval::Work::default());
                // The filters' tabulated kernel terms against the exact ones.
                assert!((o[0].0 - v).abs() < 5e-6, "table {} vs exact {v}", o[0].0);
            }
            let h = 1e-4;
            let fdx = (exact_wide(p + DVec2::X * h, s, sel).0 - exact_wide(p - DVec2::X * h, s, sel).0) / (2.0 * h);
            let fdy = (exact_wide(p + DVec2::Y * h, s, sel).0 - exact_wide(p - DVec2::Y * h, s, sel).0) / (2.0 * h);
            println!(
                "{p} σ {s} {sel:?}: exact {v:.6} brute {brute:.6}; d/dx {dx:.5} ({fdx:.5}) d/dy {dy:.5} ({fdy:.5})"
            );
            assert!((v - brute).abs() < 2e-5, "exact {v} vs brute force {brute}");
            assert!((dx - fdx).abs() < 1e-6 && (dy - fdy).abs() < 1e-6);
        }
    }

    /// Against the full tail, what summing over ±`tail`·σₑ leaves out of the values at σₑ of 4000
    /// damped octaves (isotropic and anisotropic): the worst difference, the values' RMS and the
    /// corners the shorter sums visit on average.
    fn damped_tail_error(tail: f64) -> (f64, f64, f64) {
        let (mut worst, mut sq, mut corners) = (0.0f64, 0.0, 0u64);
        for k in 0..4000 {
            let p = DVec2::new((k as f64 * 0.61803) % 50.0, (k as f64 * 0.7548) % 50.0);
            let s = DVec2::new(
                PERLIN_SIGMA_EXACT,
                if k % 2 == 0 { PERLIN_SIGMA_EXACT } else { 0.2 + (k as f64 * 0.1) % 0.55 },
            );
            let (mut a, mut b) = ([(0.0, 0.0, 0.0); 4], [(0.0, 0.0, 0.0); 4]);
            let w = &mut crate::eval::Work::default();
            perlin_exact_n::<MAX_AXIS, true>(p, s, PERLIN_TAIL, &[HashSel::Full], &mut a, w);
            let w = &mut crate::eval::Work::default();
            perlin_exact_n::<MAX_AXIS, true>(p, s, tail, &[HashSel::Full], &mut b, w);
            corners += w.lattice;
            worst = worst.max((a[0].0 - b[0].0).abs());
            sq += a[0].0 * a[0].0;
        }
        (worst, (sq / 4000.0).sqrt(), corners as f64 / 4000.0)
    }

    /// Damped octaves sum their corners over ±`PERLIN_DAMPED_TAIL`·σₑ: against the full tail the
    /// value moves by under 1.5e-3 (1.08e-3 measured), 2 % of its RMS at σₑ.
    #[test]
    fn damped_tail_is_small_beside_the_value() {
        let (worst, rms, _) = damped_tail_error(PERLIN_DAMPED_TAIL);
        println!("damped tail: worst {worst:.2e}, value RMS {rms:.3e}");
        assert!(worst < 1.5e-3 && worst < 0.02 * rms, "worst {worst:.2e} against RMS {rms:.3e}");
    }

    /// The shorter tails of strongly damped octaves ([`PERLIN_DAMPED_TAILS`]): what each leaves
    /// out of the value at σₑ, times the largest damping that uses it, stays under the bound on
    /// [`PERLIN_DAMPED_TAIL`]'s error for an undamped octave (1.5e-3), so no damped octave moves
    /// by more than the longest damped tail moves one. The tails also shorten the sum.
    #[test]
    fn damped_tails_scale_with_the_damping() {
        let mut upper = 1.0;
        let mut corners_before = f64::INFINITY;
        for (below, tail) in [(1.0, PERLIN_DAMPED_TAIL)].into_iter().chain(PERLIN_DAMPED_TAILS) {
            assert!(below <= upper && tail < PERLIN_TAIL);
            let (worst, _, corners) = damped_tail_error(tail);
            println!(
                "damping below {below}: tail {tail}, worst {worst:.2e} (× {below}: {:.2e}), {corners:.1} corners",
                worst * below
            );
            assert!(worst * below < 1.5e-3, "tail {tail} below damping {below}: {worst:.2e}");
            assert!(corners < corners_before);
            // The octave's tail at that damping and just below it.
            assert_eq!(<Dim<2> as PerlinOctave<2>>::tail(below * (1.0 - 1e-12)), tail);
            corners_before = corners;
            upper = below;
        }
        assert_eq!(<Dim<2> as PerlinOctave<2>>::tail(1.0), PERLIN_TAIL);
        assert_eq!(<Dim<2> as PerlinOctave<2>>::tail(0.5), PERLIN_DAMPED_TAIL);
    }

    /// The corners beyond ±`PERLIN_TAIL`·σ carry under 5e-5 of filtered noise (against a sum
    /// over ±6σ).
    #[test]
    fn tail_is_negligible() {
        let mut worst: f64 = 0.0;
        for &sg in &[0.1, 0.25, 0.5, 0.75, PERLIN_SIGMA_EXACT] {
            for (k, &p) in centres().iter().enumerate().step_by(7) {
                let s = DVec2::new(sg, sg * (0.3 + 0.7 * (k % 5) as f64 / 4.0));
                let mut o = [(0.0, 0.0, 0.0); 4];
                perlin_exact(p, s, &[HashSel::Full], &mut o, &mut crate::eval::Work::default());
                // Reference: every corner within ±6σ, by widening the spread's tail.
                let (mut refv, mut xs, mut ys) =
                    (0.0, [(0, AxisTerms::default()); WIDE], [(0, AxisTerms::default()); WIDE]);
                let wide = |m: f64, s: f64, buf: &mut [(i32, AxisTerms); WIDE]| {
                    axis_terms_exact(m, s, (m - 1.0 - 6.0 * s).floor() as i32, (m + 1.0 + 6.0 * s).ceil() as i32, buf)
                };
                let nx = wide(p.x, s.x, &mut xs);
                let ny = wide(p.y, s.y, &mut ys);
                for &(cy, ty) in &ys[..ny] {
                    for &(cx, tx) in &xs[..nx] {
                        let g = gradient_vector(hash::hash2(cx, cy));
                        refv += g.x * tx.dw * ty.w + g.y * tx.w * ty.dw;
                    }
                }
                worst = worst.max((o[0].0 - refv * GRADIENT_SCALE_2D as f64).abs());
            }
        }
        println!("largest tail left out: {worst:.2e}");
        assert!(worst < 5e-5, "{worst}");
    }

    /// The damping rates: least-squares fits of `exact(σₑ) · Π exp(−κ (σ² − σₑ²))` to the exact
    /// convolution at σ, for isotropic and anisotropic spreads from 1.1 σₑ to 3 σₑ (σₑ =
    /// [`PERLIN_SIGMA_EXACT`]). The constants sit at the fitted minimum, and the damped value
    /// is closer to the exact one than either the undamped value or dropping the octave.
    #[test]
    fn damping_fit() {
        let l = PERLIN_SIGMA_EXACT;
        let mut failures = Vec::new();
        for sel in LATTICES {
            let m0 = mean_square(field(DVec2::ZERO, sel).into_iter());
            let steps = [1.1, 1.25, 1.5, 1.75, 2.0, 2.5, 3.0];
            // Families: (σ, σ), (σ, σₑ), (σ, 0.3 σₑ); each against its clamped evaluation.
            let mut pairs = Vec::new();
            for (lo_y, fam) in [(1.0, 0), (1.0, 1), (0.3, 2)] {
                let base = field(DVec2::new(l, lo_y * l), sel);
                for &t in &steps {
                    let sg = t * l;
                    let s = match fam {
                        0 => DVec2::splat(sg),
                        _ => DVec2::new(sg, lo_y * l),
                    };
                    let axes_beyond = if fam == 0 { 2.0 } else { 1.0 };
                    pairs.push((axes_beyond * (sg * sg - l * l), field(s, sel), base.clone()));
                }
            }
            let err = |kappa: f64| -> f64 {
                pairs
                    .iter()
                    .map(|(e, f, b)| mean_square(f.iter().zip(b).map(|(x, y)| x - (-kappa * e).exp() * y)))
                    .sum::<f64>()
                    / m0
            };
            let (mut best, mut best_err) = (0.0, f64::MAX);
            for i in 1..=120 {
                let k = i as f64 * 0.01;
                let e = err(k);
                if e < best_err {
                    (best, best_err) = (k, e);
                }
            }
            let kappa = sel.kappa();
            let (e_const, e_none, e_drop) = (err(kappa), err(0.0), err(1e6));
            println!(
                "{sel:?}: fitted kappa {best:.2} (rms error {:.4} of the unfiltered rms); constant {kappa}: {:.4}; undamped {:.4}; dropped {:.4}",
                best_err.sqrt(),
                e_const.sqrt(),
                e_none.sqrt(),
                e_drop.sqrt()
            );
            if e_const > best_err * 1.02 || e_const > 0.5 * e_none.min(e_drop) {
                failures.push(format!("{sel:?}: kappa {kappa} is off the fit {best}"));
            }
        }
        assert!(failures.is_empty(), "{failures:?}");
    }

    /// The share of the lattice's variance that the filtered mean keeps (measured from the exact
    /// convolution over a grid of per-axis spreads) against [`HashSel::mean_share`], and the
    /// least-squares fit of [`share_model`]'s parameters (coordinate descent from the constants).
    #[test]
    fn mean_share_fit() {
        let grid = [0.0, 0.1, 0.25, 0.5, 0.75, 1.0, 1.5, 2.0];
        for sel in LATTICES {
            let m0 = mean_square(field(DVec2::ZERO, sel).into_iter());
            let mut pts = Vec::new();
            for (i, &x) in grid.iter().enumerate() {
                for &y in &grid[..=i] {
                    pts.push((DVec2::new(x, y), mean_square(field(DVec2::new(x, y), sel).into_iter()) / m0));
                }
            }
            let err = |q: [f64; 4]| {
                (pts.iter().map(|&(s, r)| (share_model(q, s) - r).powi(2)).sum::<f64>() / pts.len() as f64).sqrt()
            };
            let konst = match sel {
                HashSel::Slice(_) => PERLIN3_SLICE_SHARE,
                _ => PERLIN_SHARE,
            };
            let mut q = konst;
            let mut step = 0.2;
            for _ in 0..400 {
                let mut moved = false;
                for k in 0..4 {
                    for f in [1.0 + step, 1.0 / (1.0 + step)] {
                        let mut t = q;
                        t[k] *= f;
                        if err(t) < err(q) {
                            q = t;
                            moved = true;
                        }
                    }
                }
                if !moved {
                    step *= 0.5;
                }
            }
            let worst = pts.iter().map(|&(s, r)| (sel.mean_share(s) - r).abs()).fold(0.0, f64::max);
            println!(
                "{sel:?}: fitted {q:.3?} (rms {:.4}); constants {konst:?}: rms {:.4}, worst {worst:.4}",
                err(q),
                err(konst)
            );
            for &(s, r) in &pts {
                println!("  σ ({:.2}, {:.2}): share {r:.4}, model {:.4}", s.x, s.y, sel.mean_share(s));
            }
            assert!(err(konst) <= err(q) * 1.05 + 1e-4, "{sel:?}: off the fit");
            assert!(worst < 0.03, "{sel:?}: worst {worst}");
        }
    }
}

mod slice {
    use super::*;

    /// The 3D slice lattice reproduces unfiltered 3D Perlin noise through the corner kernels,
    /// and prints its variance over the plane at a few slices.
    #[test]
    fn perlin3_slice() {
        for &z in &[0.0f32, 0.3, 0.5, 0.9012] {
            let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
            for i in 0..300 {
                for j in 0..300 {
                    let p = Vec2::new(0.013 + i as f32 * 0.0517, 0.029 + j as f32 * 0.0491);
                    let v = perlin3_float([p.x, p.y, z]) as f64;
                    s += v;
                    s2 += v * v;
                    n += 1.0;
                }
            }
            println!("z {z}: variance {:.4}", s2 / n - (s / n).powi(2));
            // Filtered at a tiny footprint = the point value.
            let p = DVec2::new(1.37, -2.61);
            let mut o = [(0.0, 0.0, 0.0); 4];
            let mut work = crate::eval::Work::default();
            perlin_exact(p, DVec2::splat(1e-4), &[HashSel::Slice(z)], &mut o, &mut work);
            let v = perlin3_float([p.x as f32, p.y as f32, z]) as f64;
            assert!((o[0].0 - v).abs() < 1e-4, "z {z}: {} vs {v}", o[0].0);
        }
    }
}

mod perlin3 {
    use super::*;
    use crate::eval::Work;

    /// The closed-form gradient lattice reproduces MaterialX's GLSL-style point evaluation, for
    /// the float lattice and every byte lattice.
    #[test]
    fn exact_at_tiny_spread_is_the_point_value() {
        let mut work = Work::default();
        for i in 0..200 {
            let p = DVec3::new(-3.7 + i as f64 * 0.131, 2.2 - i as f64 * 0.077, 0.45 + i as f64 * 0.093);
            for sel in [Sel::Full, Sel::Byte(0), Sel::Byte(1), Sel::Byte(2)] {
                let mut r = [(0.0, DVec3::ZERO); 4];
                perlin3_exact(p, DVec3::splat(1e-4), &[sel], &mut r, &mut work);
                let v = perlin3_point(p.as_vec3(), sel) as f64;
                assert!((r[0].0 - v).abs() < 2e-4, "{p:?} {sel:?}: {} vs {v}", r[0].0);
                // The gradient against central differences of the point function.
                let h = 1e-3;
                for k in 0..3 {
                    let mut e = DVec3::ZERO;
                    e[k] = h;
                    let fd = (perlin3_point((p + e).as_vec3(), sel) - perlin3_point((p - e).as_vec3(), sel)) as f64
                        / (2.0 * h);
                    assert!(
                        (r[0].1[k] - fd).abs() < 2e-2 * (1.0 + fd.abs()),
                        "{p:?} {sel:?} axis {k}: {} vs {fd}",
                        r[0].1[k]
                    );
                }
            }
        }
    }

    /// Prints the global variance of 3D Perlin noise and the decay of the exactly filtered
    /// noise's RMS with an isotropic σ: `PERLIN3_VARIANCE` and the damping's κ come from here.
    #[test]
    fn perlin3_constants() {
        let (mut s, mut s2, mut n) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..60 {
            for j in 0..60 {
                for l in 0..60 {
                    let p = Vec3::new(0.013 + i as f32 * 0.317, 0.029 + j as f32 * 0.291, 0.041 + l as f32 * 0.273);
                    let v = perlin3(p) as f64;
                    s += v;
                    s2 += v * v;
                    n += 1.0;
                }
            }
        }
        let var = s2 / n - (s / n).powi(2);
        println!("perlin3 variance {var:.4}");
        assert!((var - PERLIN3_VARIANCE).abs() < 0.01, "variance {var}");
        let mut work = Work::default();
        let mut rms = Vec::new();
        for &sig in &[0.25, 0.35, 0.45] {
            let (mut acc, mut cnt) = (0.0, 0.0);
            for i in 0..20 {
                for j in 0..20 {
                    let p = DVec3::new(0.37 + i as f64 * 0.173, 0.11 + j as f64 * 0.191, 0.7 + (i + j) as f64 * 0.137);
                    let mut o = [(0.0, DVec3::ZERO); 4];
                    perlin3_exact(p, DVec3::splat(sig), &[Sel::Full], &mut o, &mut work);
                    acc += o[0].0 * o[0].0;
                    cnt += 1.0;
                }
            }
            rms.push((sig, (acc / cnt).sqrt()));
        }
        for &(sig, r) in &rms {
            let kappa = -(r / rms[0].1).ln() / (3.0 * (sig * sig - 0.0625));
            println!("sigma {sig}: rms {r:.5}, per-axis kappa {kappa:.2}");
        }
    }

    /// Vector cell noise hashes four integers (`hash4`, with its `bjmix` round): its channels
    /// differ from each other and from the float lattice's `hash3`, and lie in [0, 1].
    #[test]
    fn cell_vec3_channels_differ() {
        let a = cell3_vec3(3, -2, 7, 0);
        let b = cell3_vec3(3, -2, 7, 1);
        let c = cell3_float(3, -2, 7);
        assert!(a != b && a != c && (0.0..=1.0).contains(&a) && (0.0..=1.0).contains(&b));
    }
}

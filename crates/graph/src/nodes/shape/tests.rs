use super::*;
use coverage::{coverage_with, small_coverage, union_coverage_with, SETTLED};

/// The pieces reproduce the point functions (at a point footprint the coverage is the
/// indicator) away from edges.
#[test]
fn pieces_match_points() {
    let s = DVec2::splat(1e-7);
    let mut bad = 0;
    let mut n = 0;
    for a in 0..60 {
        for b in 0..60 {
            let q = Vec2::new(-1.3 + a as f32 * 0.0613, -1.1 + b as f32 * 0.0571);
            let m = q.as_dvec2();
            let c = Vec2::new(0.2, -0.1);
            let pc = coverage(&[Piece::one(Prim::Disk { c: c.as_dvec2(), r: 0.7 })], m, s).0;
            bad += ((pc - circle_point(q, c, 0.7) as f64).abs() > 0.5) as i32;
            let ph = coverage(&[Piece::one(Prim::Hex { c: c.as_dvec2(), r: 0.6 })], m, s).0;
            bad += ((ph - hexagon_point(q, c, 0.6) as f64).abs() > 0.5) as i32;
            let (p1, p2) = (Vec2::new(-0.5, 0.3), Vec2::new(0.6, -0.4));
            let cap = Prim::Capsule { a: (p1 + c).as_dvec2(), b: (p2 + c).as_dvec2(), r: 0.2 };
            let pl = coverage(&[Piece::one(cap)], m, s).0;
            bad += ((pl - line_point(q, c, 0.2, p1, p2) as f64).abs() > 0.5) as i32;
            let mut clover = Vec::new();
            Piece::clover(c.as_dvec2(), 0.35, None, &mut clover);
            let pc4 = union_coverage(&clover, m, s).0;
            bad += ((pc4 - clover_point(q, c, 0.7) as f64).abs() > 0.5) as i32;
            for pat in TEST_PATTERNS {
                let h = pat.row_height();
                let (i, j) = ((m.x).floor() as i64, (m.y / h).floor() as i64);
                let mut pieces = Vec::new();
                let mut p = 0.0;
                for jj in j - 1..=j + 1 {
                    for ii in i - 1..=i + 1 {
                        pieces.clear();
                        pat.pieces(ii, jj, &mut pieces);
                        p += if pat.overlaps() { union_coverage(&pieces, m, s).0 } else { coverage(&pieces, m, s).0 };
                    }
                }
                bad += ((p - pat.point(q) as f64).abs() > 0.5) as i32;
                n += 1;
            }
            n += 4;
        }
    }
    assert!(bad <= n / 500, "{bad} of {n} points disagree");
}

/// Random footprints for the shortcut tests: centres in [−4, 4]², spreads from 1e-5 to 0.3
/// (log-uniform), aspect 0.2–1.
fn random_footprints(n: usize) -> Vec<(DVec2, DVec2)> {
    let mut rnd = crate::testing::uniform(0x2545_f491_4f6c_dd1d);
    (0..n)
        .map(|_| {
            let m = DVec2::new(rnd() * 8.0 - 4.0, rnd() * 8.0 - 4.0);
            let sigma = 10f64.powf(-5.0 + 4.5 * rnd());
            let s = DVec2::new(sigma, sigma * (0.2 + 0.8 * rnd()));
            if rnd() < 0.5 {
                (m, s)
            } else {
                (m, DVec2::new(s.y, s.x))
            }
        })
        .collect()
}

/// One of each tiled pattern, staggered or not (staggered circles of size 1.3, which overlap).
const TEST_PATTERNS: [Tiled; 8] = [
    Tiled::Cross { th: 0.1, staggered: false },
    Tiled::Cross { th: 0.15, staggered: true },
    Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Circle },
    Tiled::Shapes { size: 1.3, staggered: true, motif: Motif::Circle },
    Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Hexagon },
    Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Hexagon },
    Tiled::Shapes { size: 0.8, staggered: false, motif: Motif::Clover },
    Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Clover },
];

/// The 5 × 5 cells around `m`, each by `f(pieces, union)`.
fn cells_around(pat: Tiled, m: DVec2, mut f: impl FnMut(&[Piece], bool)) {
    let (i, j) = (m.x.floor() as i64, (m.y / pat.row_height()).floor() as i64);
    let mut pieces = Vec::new();
    for jj in j - 2..=j + 2 {
        for ii in i - 2..=i + 2 {
            pieces.clear();
            pat.pieces(ii, jj, &mut pieces);
            f(&pieces, pat.overlaps());
        }
    }
}

/// A piece that a footprint settles (no boundary within its reach) is, at every one of 64
/// points drawn from the footprint, what its shortcut says: in or out. The point test is the
/// pieces' own (their chords), independent of the distance bounds the shortcut reads. And the
/// shortcut settles most pieces of small footprints, so that it is taken where it pays.
#[test]
fn settled_pieces_are_constant_over_the_footprint() {
    let mut rnd = crate::testing::uniform(0x9e37_79b9_7f4a_7c15);
    // Inside by the chord at the point's height, as the quadrature counts it.
    let contains = |pc: &Piece, q: DVec2| {
        let (lo, hi) = pc.chord(0, q.x);
        lo <= q.y && q.y < hi
    };
    let (mut settled, mut pieces_seen) = (0, 0);
    for (m, s) in random_footprints(1500) {
        let draws: Vec<DVec2> = (0..64)
            .map(|_| {
                let (u, v) = (rnd().max(1e-300), rnd());
                let r = (-2.0 * u.ln()).sqrt();
                let (sn, cs) = (std::f64::consts::TAU * v).sin_cos();
                m + DVec2::new(r * cs, r * sn) * s
            })
            .collect();
        let reach = SETTLED * s.length();
        let mut check = |pc: &Piece| {
            pieces_seen += (s.x < 3e-3) as i32;
            let Some(inside) = pc.settled(m, reach) else { return };
            settled += (s.x < 3e-3) as i32;
            for q in &draws {
                assert_eq!(contains(pc, *q), inside, "{pc:?} m {m} s {s}: settled {inside}, not so at {q}");
            }
        };
        let c = DVec2::new(0.2, -0.1);
        for pc in [
            Piece::one(Prim::Disk { c, r: 0.7 }),
            Piece::one(Prim::Hex { c, r: 0.6 }),
            Piece::one(Prim::Capsule { a: DVec2::new(-0.3, 0.2), b: DVec2::new(0.8, -0.5), r: 0.2 }),
        ] {
            check(&pc);
        }
        for pat in TEST_PATTERNS {
            let (i, j) = (m.x.floor() as i64, (m.y / pat.row_height()).floor() as i64);
            let mut pieces = Vec::new();
            pat.pieces(i, j, &mut pieces);
            pieces.iter().for_each(&mut check);
        }
    }
    assert!(settled as f64 > 0.7 * pieces_seen as f64, "settled {settled} of {pieces_seen} pieces of small footprints");
}

/// The coverage of signed pieces (or their union) by brute force: along y, the midpoint rule
/// with 4000 points over ±7σ; along x, the exact Φ-mass of each height's chords (merged for a
/// union).
fn brute_coverage(pieces: &[Piece], m: DVec2, s: DVec2, union: bool) -> f64 {
    let n = 4000;
    let (lo, h) = (m.y - 7.0 * s.y, 14.0 * s.y / n as f64);
    let (mut acc, mut wsum) = (0.0, 0.0);
    for i in 0..n {
        let y = lo + (i as f64 + 0.5) * h;
        let w = (-0.5 * ((y - m.y) / s.y).powi(2)).exp();
        let mut q = 0.0;
        if union {
            let mut ch: Vec<(f64, f64)> = pieces.iter().map(|pc| pc.chord(1, y)).filter(|(a, b)| a < b).collect();
            ch.sort_by(|a, b| a.0.total_cmp(&b.0));
            let mut cur: Option<(f64, f64)> = None;
            for (a, b) in ch {
                match cur {
                    Some((ca, cb)) if a <= cb => cur = Some((ca, cb.max(b))),
                    _ => {
                        if let Some((ca, cb)) = cur {
                            q += interval(ca, cb, m.x, s.x).0;
                        }
                        cur = Some((a, b));
                    }
                }
            }
            if let Some((ca, cb)) = cur {
                q += interval(ca, cb, m.x, s.x).0;
            }
        } else {
            for pc in pieces {
                let (a, b) = pc.chord(1, y);
                q += pc.sign * interval(a, b, m.x, s.x).0;
            }
        }
        acc += w * q;
        wsum += w;
    }
    acc / wsum
}

/// With its shortcuts (settled pieces, closed forms for one strip or rectangle edge), the
/// coverage is as accurate as by quadrature alone, against a brute-force integration: every
/// single shape, the cloverleaf and each tiled pattern over the cells around random footprints
/// (from 1e-3 cells: below, the brute force's 4000 rows are too coarse for some edges).
#[test]
fn shortcuts_are_as_accurate_as_quadrature() {
    let (mut worst_short, mut worst_quad, mut n) = (0.0f64, 0.0f64, 0);
    for (m, s) in random_footprints(250).into_iter().filter(|(_, s)| s.min_element() > 1e-3) {
        let mut both = |pieces: &[Piece], union: bool| {
            let (a, da) = if union { union_coverage(pieces, m, s) } else { coverage(pieces, m, s) };
            let (b, db) =
                if union { union_coverage_with(pieces, m, s, false) } else { coverage_with(pieces, m, s, false) };
            let want = brute_coverage(pieces, m, s, union);
            let (ea, eb) = ((a - want).abs(), (b - want).abs());
            worst_short = worst_short.max(ea);
            worst_quad = worst_quad.max(eb);
            n += 1;
            // Overlapping pieces summed instead of united would be off by up to 1 (staggered
            // circles of size 1.3 were); the quadrature's own error, at the kinks of strips
            // clipped to a cell, reaches 1.5e-2.
            assert!(ea < 0.02, "m {m} s {s}: {a} with shortcuts, {want} by brute force; {pieces:?}");
            assert!(
                ea <= eb + 1e-5,
                "m {m} s {s}: {a} with shortcuts, {b} by quadrature, {want} by brute force; {pieces:?}"
            );
            // The gradient against the quadrature's, relative to its scale (the density of an
            // edge, ~1/σ). Not for unions, whose quadrature takes a short rule on each of several
            // spans: where one piece holds the whole footprint, its gradient is off by up to 2e-3
            // of that scale, and the shortcut's 0 is the exact one
            // (`settled_pieces_are_constant_over_the_footprint`).
            let scale = 1.0 / s.min_element();
            assert!(
                union || (da - db).length() < 1e-4 * scale,
                "m {m} s {s}: gradient {da} with shortcuts, {db} by quadrature; {pieces:?}"
            );
        };
        let c = DVec2::new(0.2, -0.1);
        both(&[Piece::one(Prim::Disk { c, r: 0.7 })], false);
        both(&[Piece::one(Prim::Hex { c, r: 0.6 })], false);
        let mut clover = Vec::new();
        Piece::clover(c, 0.35, None, &mut clover);
        both(&clover, true);
        for pat in TEST_PATTERNS {
            cells_around(pat, m, &mut both);
        }
    }
    println!("{n} cases; largest error {worst_short:.2e} with shortcuts, {worst_quad:.2e} by quadrature alone");
}

/// A shape far smaller than its footprint (a disk, hexagon or capsule, any orientation) takes
/// the density-times-moments form: the coverage within 2e-4 relative of a brute-force
/// integration over the shape (20 000 rows across its extent, the exact mass along each; the
/// 20-point quadrature errs by up to 2e-3 on the hexagon's kinked chords), its gradient within
/// 1e-2 of the quadrature's scale; and it is used often below its size bound.
#[test]
fn small_shapes_match_quadrature() {
    let mut rnd = crate::testing::uniform(0x0bad_5eed_1234_5678);
    let mut used = 0;
    for k in 0..2000 {
        let sx = 10f64.powf(-1.0 + 3.0 * rnd());
        let s = DVec2::new(sx, sx * (0.3 + 0.7 * rnd()));
        let m = DVec2::new(rnd() - 0.5, rnd() - 0.5) * 6.0 * s;
        let size = s.min_element() * 10f64.powf(-3.0 + 1.6 * rnd());
        let c = DVec2::new(rnd() - 0.5, rnd() - 0.5);
        let a = rnd() * std::f64::consts::TAU;
        let prim = match k % 3 {
            0 => Prim::Disk { c, r: size },
            1 => Prim::Hex { c, r: size },
            _ => {
                let e = DVec2::new(a.cos(), a.sin()) * size;
                Prim::Capsule { a: c - e, b: c + e, r: 0.3 * size }
            }
        };
        let Some((p, dp)) = small_coverage(&prim, m, s) else { continue };
        used += 1;
        let (q, dq) = coverage_with(&[Piece::one(prim)], m, s, false);
        let piece = Piece::one(prim);
        let (y0, y1) = piece.extent(1);
        let rows = 20_000;
        let h = (y1 - y0) / rows as f64;
        let want: f64 = (0..rows)
            .map(|i| {
                let y = y0 + (i as f64 + 0.5) * h;
                let (lo, hi) = piece.chord(1, y);
                let w = (-0.5 * ((y - m.y) / s.y).powi(2)).exp() / (s.y * (2.0 * std::f64::consts::PI).sqrt());
                w * h * interval(lo, hi, m.x, s.x).0
            })
            .sum();
        assert!(
            (p - want).abs() <= 2e-4 * want + 1e-15,
            "{prim:?} m {m} s {s}: {p} vs brute force {want} (quadrature {q})"
        );
        let scale = dq.length().max(q / s.min_element());
        // (Beyond 6σ the quadrature leaves the narrow axis out: gradients below 1e-9 are not
        // compared.)
        assert!((dp - dq).length() <= 1e-2 * scale + 1e-9, "{prim:?} m {m} s {s}: gradient {dp} vs {dq}");
    }
    assert!(used > 600, "used {used} times");
}

/// The union quadrature's constants at its shoulders are Φ there.
#[test]
fn shoulder_constants_are_the_normal_cdf() {
    use coverage::{PHI_SHOULDER, SHOULDER};
    assert!((PHI_SHOULDER[0] - crate::gaussian::cdf(-SHOULDER)).abs() < 1e-16);
    assert!((PHI_SHOULDER[1] - crate::gaussian::cdf(SHOULDER)).abs() < 2e-16);
}

use super::*;

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
            for pat in [
                Tiled::Cross { th: 0.1, staggered: false },
                Tiled::Cross { th: 0.1, staggered: true },
                Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Circle },
                Tiled::Shapes { size: 0.7, staggered: true, motif: Motif::Circle },
                Tiled::Shapes { size: 0.7, staggered: false, motif: Motif::Hexagon },
                Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Hexagon },
                Tiled::Shapes { size: 0.8, staggered: false, motif: Motif::Clover },
                Tiled::Shapes { size: 0.9, staggered: true, motif: Motif::Clover },
            ] {
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

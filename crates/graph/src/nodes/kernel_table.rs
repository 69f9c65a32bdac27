//! Tabulated Gaussian averages of Perlin's corner kernel, the inner loop of filtered Perlin noise.
//!
//! Along one axis a lattice coordinate `c` contributes through four expectations of the offset
//! `d = m − c` under a Gaussian of spread `s`: `E[W(d + sZ)]`, `E[(d + sZ) W(d + sZ)]` and their
//! derivatives in `d` ([`AxisTerms`]). Computed exactly they need an `erfc` and an `exp` per
//! integer boundary and degree-7 moment algebra per cell (most of a textured render's time before
//! this table). They depend on `(d, s)` alone and are smooth there — `W` is C², so its Gaussian
//! averages are C² uniformly down to `s = 0` — so a table over `d ∈ [0, 4]`, `s ∈ [0, 0.75]`
//! interpolates them closely:
//!
//! - each node keeps the value and the first three `d`-derivatives of both functions, and beside
//!   those eight numbers their own `d`-slopes times the node spacing: one 64-byte line of f32
//!   that interpolates as two four-wide vectors;
//! - in `d`, cubic Hermite between nodes `1/64` apart, each quantity from its derivative (the
//!   third derivatives' slopes by central differences of the nodes);
//! - in `s`, cubic Hermite between rows `1/128` apart, with the slope the heat equation gives:
//!   a Gaussian average `f(d, s)` of a fixed kernel has `∂f/∂s = s ∂²f/∂d²`, which the
//!   interpolated row already holds;
//! - the functions' parity (`E[W]` and `∂E[dW]` even in `d`, the other two odd) halves the table.
//!
//! The table (1.5 MiB) is computed from the exact integrals and embedded in the binary
//! (`kernel_table.bin`; building it took about 7 ms of every process); the tests rebuild it and
//! bound its error against the integrals. A spread that lies on a row reads that row alone
//! (damped octaves, clamped to the last). Where a coordinate's footprint lies inside one
//! polynomial piece of the kernel (small spreads, away from the piece ends), the terms are
//! computed in closed form instead, more exactly than the table and without its loads
//! ([`within_piece`]).

#[cfg(test)]
use super::noise::axis_terms_exact;
#[cfg(test)]
use super::noise::kernel_expectations;
use super::noise::AxisTerms;

/// Nodes per lattice unit along `d`.
const D_RES: f64 = 64.0;
/// Largest `|d|` tabulated: `1 + 4σ` at σ = 0.75 reaches 4 (the 2D sum reaches `1 + 3.5σ`, the 3D
/// one `1 + 4σ` at σ ≤ 0.25). Beyond, a coordinate is outside every sum.
const D_MAX: f64 = 4.0;
const ND: usize = (D_MAX * D_RES) as usize + 1;
/// Rows per unit of `s`.
const S_RES: f64 = 128.0;
/// Largest tabulated spread (lattice units): [`super::noise::perlin::PERLIN_SIGMA_EXACT`].
pub(crate) const S_MAX: f64 = 0.75;
const NS: usize = (S_MAX * S_RES) as usize + 1;

/// One node: `v = [w, w', w'', w''', dw, dw', dw'', dw''']` at `(d, s)` (primes in `d`), and
/// `g`, the `d`-derivative of each times the node spacing.
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(C, align(64))]
struct Node {
    v: [f32; 8],
    g: [f32; 8],
}

/// The table's nodes as [`build`] computes them, row by row, each node's `v` then `g` as
/// little-endian `f32`: building them took about 7 ms of every process that filters Perlin
/// noise (a twentieth of a small demo render's texture time, on one core while the other
/// waited). The test `embedded_table_is_what_build_gives` recomputes them;
/// `regenerate_kernel_table` rewrites the file. The array's length is the table's: a file of
/// another size does not compile.
static EMBEDDED: Aligned<[u8; ND * NS * std::mem::size_of::<Node>()]> = Aligned(*include_bytes!("kernel_table.bin"));

/// Bytes aligned as a [`Node`] is, so that they can be read as nodes in place.
#[repr(C, align(64))]
struct Aligned<T>(T);

/// The embedded nodes, read in place: decoding them into a table of their own cost 1.3 ms of
/// page faults and copying in the first filtered Perlin evaluation of every process (which a
/// profile then charged to that node's cost), and touched all 1.6 MB where a render reads
/// a few rows.
#[cfg(target_endian = "little")]
fn table() -> &'static [Node] {
    bytemuck::cast_slice(&EMBEDDED.0)
}

/// The embedded nodes, decoded from little-endian `f32` once.
#[cfg(not(target_endian = "little"))]
fn table() -> &'static [Node] {
    static T: std::sync::OnceLock<Box<[Node]>> = std::sync::OnceLock::new();
    T.get_or_init(|| {
        let f: Vec<f32> = EMBEDDED.0.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        f.chunks_exact(16)
            .map(|n| {
                let (mut v, mut g) = ([0.0; 8], [0.0; 8]);
                v.copy_from_slice(&n[..8]);
                g.copy_from_slice(&n[8..]);
                Node { v, g }
            })
            .collect()
    })
}

/// Builds the table from the exact integrals ([`kernel_expectations`]: the kernel's derivatives
/// averaged, from one set of cell moments per node); the first row (`s = 0`) from the kernel's
/// polynomials.
#[cfg(test)]
fn build() -> Box<[Node]> {
    let mut t = vec![[0.0f64; 8]; ND * NS];
    for j in 0..NS {
        let s = j as f64 / S_RES;
        for i in 0..ND {
            let d = i as f64 / D_RES;
            t[j * ND + i] = if j == 0 { kernel_at(d) } else { kernel_expectations(d, s) };
        }
    }
    let hd = 1.0 / D_RES;
    let mut nodes = Vec::with_capacity(ND * NS);
    for j in 0..NS {
        for i in 0..ND {
            let v = &t[j * ND + i];
            let (lo, hi) = (i.saturating_sub(1), (i + 1).min(ND - 1));
            let third = |k: usize| (t[j * ND + hi][k] - t[j * ND + lo][k]) / (hi - lo) as f64;
            let g = [hd * v[1], hd * v[2], hd * v[3], third(3), hd * v[5], hd * v[6], hd * v[7], third(7)];
            nodes.push(Node { v: v.map(|x| x as f32), g: g.map(|x| x as f32) });
        }
    }
    nodes.into_boxed_slice()
}

#[cfg(test)]
/// The kernel itself at `d ≥ 0`: `W(d) = 1 − fade(d)` on `[0, 1)`, 0 beyond, and `d·W(d)`, with
/// their derivatives (one-sided from above at `d = 0`, where the third derivative jumps).
fn kernel_at(d: f64) -> [f64; 8] {
    if d >= 1.0 {
        return [0.0; 8];
    }
    // W = 1 − 10d³ + 15d⁴ − 6d⁵.
    let w = 1.0 - d * d * d * (10.0 - d * (15.0 - 6.0 * d));
    let w1 = -d * d * (30.0 - d * (60.0 - 30.0 * d));
    let w2 = -d * (60.0 - d * (180.0 - 120.0 * d));
    let w3 = -(60.0 - d * (360.0 - 360.0 * d));
    // (dW)' = W + dW', (dW)'' = 2W' + dW'', (dW)''' = 3W'' + dW'''.
    [w, w1, w2, w3, d * w, w + d * w1, 2.0 * w1 + d * w2, 3.0 * w2 + d * w3]
}

/// Cubic Hermite basis at `t ∈ [0, 1]`: weights of `f₀, h f₀', f₁, h f₁'`.
#[inline(always)]
fn hermite_basis(t: f32) -> [f32; 4] {
    let t2 = t * t;
    let t3 = t2 * t;
    [2.0 * t3 - 3.0 * t2 + 1.0, t3 - 2.0 * t2 + t, 3.0 * t2 - 2.0 * t3, t3 - t2]
}

/// The spread's place between two rows of the table: shared by every coordinate of one axis.
#[derive(Clone, Copy)]
struct Rows {
    j: usize,
    /// Hermite basis in s.
    b: [f32; 4],
    /// The row spacing times `s` at the two rows (the heat equation's slope factor).
    k0: f32,
    k1: f32,
}

impl Rows {
    #[inline]
    fn at(s: f64) -> Rows {
        let y = s.clamp(0.0, S_MAX) * S_RES;
        let j = (y as usize).min(NS - 2);
        let hs = 1.0 / S_RES;
        let b = hermite_basis((y - j as f64) as f32);
        Rows { j, b, k0: (hs * j as f64 * hs) as f32, k1: (hs * (j + 1) as f64 * hs) as f32 }
    }

    /// The one row the interpolation in `s` reads where the spread lies on a row (its basis is
    /// `[1, 0, 0, 0]` or `[0, 0, 1, 0]`): damped octaves, whose spreads are clamped to the last
    /// row, and 3D octaves at σₑ. The other row's terms are multiplied by zeros there, so reading
    /// this row alone gives the same numbers.
    #[inline]
    fn single(&self) -> Option<usize> {
        match self.b {
            [1.0, 0.0, 0.0, 0.0] => Some(self.j),
            [0.0, 0.0, 1.0, 0.0] => Some(self.j + 1),
            _ => None,
        }
    }
}

/// The axis terms at offset `d` and spread `s ∈ [0, S_MAX]`, interpolated.
#[cfg(test)]
fn lookup(d: f64, s: f64) -> AxisTerms {
    lookup_in(table(), &Rows::at(s), d)
}

/// Row `r` at `|d| < D_MAX`: eight quantities by Hermite in `d` (written lane by lane so that
/// it compiles to vector arithmetic).
#[inline(always)]
fn row_at(tab: &[Node], r: usize, ad: f64) -> [f32; 8] {
    let x = ad * D_RES;
    let i = (x as usize).min(ND - 2);
    let bd = hermite_basis((x - i as f64) as f32);
    let (a, b) = (&tab[r * ND + i], &tab[r * ND + i + 1]);
    let mut o = [0.0f32; 8];
    for k in 0..8 {
        o[k] = bd[0] * a.v[k] + bd[1] * a.g[k] + bd[2] * b.v[k] + bd[3] * b.g[k];
    }
    o
}

/// The axis terms from the row's `w, w′, dw, (dw)′` and the sign of `d` (parity: `w` and
/// `(dw)′` even in `d`, `w′` and `dw` odd).
#[inline(always)]
fn with_parity(d: f64, w: f64, w1: f64, dw: f64, dw1: f64) -> AxisTerms {
    let sign = if d < 0.0 { -1.0 } else { 1.0 };
    AxisTerms { w, dw: sign * dw, w1: sign * w1, dw1 }
}

/// [`lookup_in`] where the spread lies on row `r` ([`Rows::single`]).
#[inline]
fn lookup_row(tab: &[Node], r: usize, d: f64) -> AxisTerms {
    let ad = d.abs();
    if ad >= D_MAX {
        return AxisTerms::default();
    }
    let o = row_at(tab, r, ad);
    with_parity(d, o[0] as f64, o[1] as f64, o[4] as f64, o[5] as f64)
}

#[inline]
fn lookup_in(tab: &[Node], rows: &Rows, d: f64) -> AxisTerms {
    let ad = d.abs();
    if ad >= D_MAX {
        return AxisTerms::default();
    }
    // Both rows at d.
    let (r0, r1) = (row_at(tab, rows.j, ad), row_at(tab, rows.j + 1, ad));
    // In s, by Hermite with the slope ∂f/∂s = s ∂²f/∂d²: w from its second derivative, w' from
    // its third, likewise for dw.
    let b = &rows.b;
    let sl = |k: usize| (b[0] * r0[k] + b[1] * rows.k0 * r0[k + 2] + b[2] * r1[k] + b[3] * rows.k1 * r1[k + 2]) as f64;
    with_parity(d, sl(0), sl(1), sl(4), sl(5))
}

/// [`super::noise::axis_terms_exact`] from the table: the terms of every lattice coordinate in
/// `lo..=hi` (at most `N`), for `s ≤ S_MAX`.
#[inline]
pub(crate) fn axis_terms<const N: usize>(m: f64, s: f64, lo: i32, hi: i32, out: &mut [(i32, AxisTerms); N]) -> usize {
    let (tab, rows) = (table(), Rows::at(s));
    // One loop per case (each its own copy of `each_coordinate`), so that none tests the case
    // per coordinate.
    if let Some(r) = rows.single() {
        each_coordinate(m, lo, hi, out, |d| lookup_row(tab, r, d))
    } else if s < PIECE_SPREAD_LIMIT {
        each_coordinate(m, lo, hi, out, |d| within_piece(d, s).unwrap_or_else(|| lookup_in(tab, &rows, d)))
    } else {
        each_coordinate(m, lo, hi, out, |d| lookup_in(tab, &rows, d))
    }
}

/// `out[k] = (c, terms(m − c))` for the lattice coordinates `c` in `lo..=hi` (at most `N`;
/// returns how many).
#[inline(always)]
fn each_coordinate<const N: usize>(
    m: f64,
    lo: i32,
    hi: i32,
    out: &mut [(i32, AxisTerms); N],
    terms: impl Fn(f64) -> AxisTerms,
) -> usize {
    let mut n = 0;
    for c in lo..=hi {
        if n >= N {
            break;
        }
        out[n] = (c, terms(m - c as f64));
        n += 1;
    }
    n
}

/// Spread below which [`within_piece`] can hold a coordinate's footprint inside one piece of the
/// kernel (its pieces are a unit long, the footprint `2 PIECE_REACH s`).
const PIECE_SPREAD_LIMIT: f64 = 0.5 / PIECE_REACH;
/// Half-width of a footprint, in σ, that must lie inside one piece of the kernel for
/// [`within_piece`]: what lies beyond is under 1e-9 of φ, and the kernel's pieces differ there
/// only from their third derivative on (the kernel is C²), so the error is far below the table's.
const PIECE_REACH: f64 = 6.0;

/// The axis terms in closed form where the footprint `d ± PIECE_REACH·s` lies inside one
/// polynomial piece of the kernel (`[−1, 0]` or `[0, 1]`; `None` elsewhere): the Gaussian average
/// of a polynomial is the polynomial plus its even derivatives times the normal's moments,
/// `E[P(d + sZ)] = P + s²/2 P″ + s⁴/8 P⁽⁴⁾ + s⁶/48 P⁽⁶⁾`, exactly (W is quintic, dW sextic). At
/// the small spreads of footprints finer than a lattice cell most coordinates qualify, and skip
/// the table's two rows of lookups.
#[inline(always)]
fn within_piece(d: f64, s: f64) -> Option<AxisTerms> {
    let r = PIECE_REACH * s;
    // On [0, 1]: W = 1 − 10x³ + 15x⁴ − 6x⁵; on [−1, 0] its mirror image, 1 + 10x³ + 15x⁴ + 6x⁵.
    let sign = if d - r >= 0.0 && d + r <= 1.0 {
        1.0
    } else if d - r >= -1.0 && d + r <= 0.0 {
        -1.0
    } else {
        return None;
    };
    let (a, b) = (-10.0 * sign, -6.0 * sign);
    let x = d;
    let (x2, s2) = (x * x, s * s);
    let x3 = x2 * x;
    // W and its derivatives.
    let w0 = 1.0 + x3 * (a + x * (15.0 + b * x));
    let w1 = x2 * (3.0 * a + x * (60.0 + 5.0 * b * x));
    let w2 = x * (6.0 * a + x * (180.0 + 20.0 * b * x));
    let w3 = 6.0 * a + x * (360.0 + 60.0 * b * x);
    let w4 = 360.0 + 120.0 * b * x;
    let w5 = 120.0 * b;
    // D = xW and its derivatives.
    let d0 = x * w0;
    let d1 = 1.0 + x3 * (4.0 * a + x * (75.0 + 6.0 * b * x));
    let d2 = x2 * (12.0 * a + x * (300.0 + 30.0 * b * x));
    let d3 = x * (24.0 * a + x * (900.0 + 120.0 * b * x));
    let d4 = 24.0 * a + x * (1800.0 + 360.0 * b * x);
    let d5 = 1800.0 + 720.0 * b * x;
    let d6 = 720.0 * b;
    let (h2, h4, h6) = (0.5 * s2, 0.125 * s2 * s2, s2 * s2 * s2 / 48.0);
    Some(AxisTerms {
        w: w0 + h2 * w2 + h4 * w4,
        dw: d0 + h2 * d2 + h4 * d4 + h6 * d6,
        w1: w1 + h2 * w3 + h4 * w5,
        dw1: d1 + h2 * d3 + h4 * d5,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The closed form inside a piece against the exact integrals, on random offsets and
    /// spreads where it applies (and it applies to most small ones).
    #[test]
    fn within_piece_is_the_exact_average() {
        let mut next = uniforms(0x51ce);
        let (mut used, mut worst) = (0, 0.0f64);
        for _ in 0..20_000 {
            let s = PIECE_SPREAD_LIMIT * next().powi(2);
            let d = -1.2 + 2.4 * next();
            let Some(t) = within_piece(d, s.max(1e-6)) else { continue };
            used += 1;
            let mut e = [(0, AxisTerms::default()); 1];
            axis_terms_exact(d, s.max(1e-6), 0, 0, &mut e);
            let e = e[0].1;
            for (a, b) in [(t.w, e.w), (t.dw, e.dw), (t.w1, e.w1), (t.dw1, e.dw1)] {
                worst = worst.max((a - b).abs());
            }
        }
        println!("within_piece: {used} of 20000 draws, worst difference from the exact integrals {worst:e}");
        // The largest differences are where the footprint's 6σ reach touches a piece's end (the
        // Gaussian beyond it is left out): 2.4e-11 here, against the table's 5e-7.
        assert!(used > 10_000 && worst < 1e-10, "{used} draws, worst {worst:e}");
    }

    /// The embedded nodes are [`build`]'s, bit for bit where the machine's maths library agrees
    /// with the one that wrote them, and within 1e-6 (relative to 1 + |value|) anywhere.
    #[test]
    fn embedded_table_is_what_build_gives() {
        let fresh = build();
        let embedded = table();
        assert_eq!(fresh.len(), embedded.len());
        let (mut same, mut worst) = (0, 0.0f32);
        for (a, b) in fresh.iter().zip(embedded) {
            for (x, y) in a.v.iter().chain(&a.g).zip(b.v.iter().chain(&b.g)) {
                same += usize::from(x.to_bits() == y.to_bits());
                worst = worst.max((x - y).abs() / (1.0 + x.abs()));
            }
        }
        println!("kernel table: {same} of {} values bit-identical, worst difference {worst:e}", fresh.len() * 16);
        assert!(worst <= 1e-6, "kernel_table.bin is stale (worst difference {worst:e}): run regenerate_kernel_table");
    }

    /// Rewrites `kernel_table.bin` after a change to the kernel, its integrals or the nodes:
    /// `cargo test --release -p graph --lib regenerate_kernel_table -- --ignored`.
    #[test]
    #[ignore]
    fn regenerate_kernel_table() {
        let bytes: Vec<u8> =
            build().iter().flat_map(|n| n.v.iter().chain(&n.g)).flat_map(|v| v.to_le_bytes()).collect();
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("src/nodes/kernel_table.bin");
        std::fs::write(&path, bytes).unwrap();
    }

    /// A splitmix64 stream of uniforms in [0, 1).
    fn uniforms(mut state: u64) -> impl FnMut() -> f64 {
        move || {
            state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
            let mut z = state;
            z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
            ((z ^ (z >> 31)) >> 11) as f64 / (1u64 << 53) as f64
        }
    }

    /// The interpolated terms against the exact integrals at random offsets and spreads, in the
    /// range the filters ask for (s from the point limit 0.003 to 0.75, |d| ≤ 1 + 3.5 s): values
    /// within 1e-6 (5.3e-7 measured), derivatives within 3e-4 (1.3e-4 measured, at the smallest
    /// spreads beside a lattice line, where the kernel's third derivative jumps).
    #[test]
    fn table_matches_the_exact_integrals() {
        let mut u = uniforms(7);
        let (mut worst_v, mut worst_g, mut at) = (0.0f64, 0.0f64, (0.0, 0.0));
        for _ in 0..200_000 {
            let s = 0.003 + u() * (S_MAX - 0.003);
            let d = (2.0 * u() - 1.0) * (1.0 + 3.5 * s);
            let mut e = [(0, AxisTerms::default()); 1];
            axis_terms_exact(d, s, 0, 0, &mut e);
            let (e, t) = (e[0].1, lookup(d, s));
            worst_v = worst_v.max((e.w - t.w).abs()).max((e.dw - t.dw).abs());
            let g = (e.w1 - t.w1).abs().max((e.dw1 - t.dw1).abs());
            if g > worst_g {
                (worst_g, at) = (g, (d, s));
            }
        }
        println!("worst value error {worst_v:.2e}, derivative error {worst_g:.2e} at (d, s) = {at:?}");
        assert!(worst_v < 1e-6, "value error {worst_v:.2e}");
        assert!(worst_g < 3e-4, "derivative error {worst_g:.2e}");
    }

    /// The table's source: the averaged kernel and its first derivatives are the exact axis
    /// terms, and each higher derivative is the finite difference of the one below.
    #[test]
    fn kernel_expectations_are_the_axis_terms_and_their_derivatives() {
        let mut u = uniforms(11);
        for _ in 0..2000 {
            let s = 0.003 + u() * (S_MAX - 0.003);
            let d = (2.0 * u() - 1.0) * (1.0 + 3.5 * s);
            let e = kernel_expectations(d, s);
            let mut a = [(0, AxisTerms::default()); 1];
            axis_terms_exact(d, s, 0, 0, &mut a);
            let a = a[0].1;
            for (x, y) in [(e[0], a.w), (e[1], a.w1), (e[4], a.dw), (e[5], a.dw1)] {
                assert!((x - y).abs() < 1e-12, "d {d} s {s}: {x} vs {y}");
            }
            let h = 1e-5 * s.max(0.01);
            let (lo, hi) = (kernel_expectations(d - h, s), kernel_expectations(d + h, s));
            for k in [1usize, 2, 5, 6] {
                let fd = (hi[k] - lo[k]) / (2.0 * h);
                assert!(
                    (fd - e[k + 1]).abs() < 1e-4 * (1.0 + e[k + 1].abs()),
                    "d {d} s {s} k {k}: {fd} vs {}",
                    e[k + 1]
                );
            }
        }
    }

    /// The first row is the kernel: its derivatives agree with finite differences of itself.
    #[test]
    fn point_row_is_the_kernel_and_its_derivatives() {
        for k in 1..63 {
            let d = k as f64 / 64.0;
            let h = 1e-6;
            let (a, b, c) = (kernel_at(d - h), kernel_at(d), kernel_at(d + h));
            for q in [0usize, 1, 2, 4, 5, 6] {
                let fd = (c[q] - a[q]) / (2.0 * h);
                assert!((fd - b[q + 1]).abs() < 1e-6 * (1.0 + b[q + 1].abs()), "d {d} q {q}: {fd} vs {}", b[q + 1]);
            }
        }
    }
}

//! The Perlin corner kernel's Gaussian expectations along one axis.

use crate::gaussian::{self, poly, poly_deriv, poly_mul, Poly};
use std::sync::OnceLock;

pub(crate) struct Kernel {
    /// W on [-1, 0), [0, 1); d·W on the same; and their derivatives.
    w: [Poly; 2],
    dw: [Poly; 2],
    w1: [Poly; 2],
    dw1: [Poly; 2],
    /// The pieces on [-1, 0) rewritten in `y = d + 1 ∈ [0, 1)`, the offset from the cell's lower
    /// lattice coordinate, so that both pieces read the same unit-interval moments.
    w_up: Poly,
    dw_up: Poly,
    w1_up: Poly,
    dw1_up: Poly,
}

pub(crate) fn kernel() -> &'static Kernel {
    static K: OnceLock<Kernel> = OnceLock::new();
    K.get_or_init(|| {
        let wn = poly(&[1.0, 0.0, 0.0, 10.0, 15.0, 6.0]);
        let wp = poly(&[1.0, 0.0, 0.0, -10.0, 15.0, -6.0]);
        let d = poly(&[0.0, 1.0]);
        let (dwn, dwp) = (poly_mul(&d, &wn), poly_mul(&d, &wp));
        let up = |p: &Poly| gaussian::poly_shift_scale(p, -1.0, 1.0);
        Kernel {
            w: [wn, wp],
            dw: [dwn, dwp],
            w1: [poly_deriv(&wn), poly_deriv(&wp)],
            dw1: [poly_deriv(&dwn), poly_deriv(&dwp)],
            w_up: up(&wn),
            dw_up: up(&dwn),
            w1_up: up(&poly_deriv(&wn)),
            dw1_up: up(&poly_deriv(&dwn)),
        }
    })
}

/// 1D expectations for lattice coordinate `c`: E[W], E[dW], dE[W]/dm, dE[dW]/dm.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct AxisTerms {
    pub w: f64,
    pub dw: f64,
    pub w1: f64,
    pub dw1: f64,
}

/// Binomial coefficients C(k, i), k, i ≤ [`gaussian::MAX_DEGREE`].
pub(super) const BINOMIAL: [[f64; 8]; 8] = {
    let mut c = [[0.0; 8]; 8];
    let mut k = 0;
    while k < 8 {
        c[k][0] = 1.0;
        let mut i = 1;
        while i <= k {
            c[k][i] = c[k - 1][i - 1] + if i < k { c[k - 1][i] } else { 0.0 };
            i += 1;
        }
        k += 1;
    }
    c
};

/// `E[Y^k 1{0 ≤ Y < 1}]`, k = 0..=7, for `Y = mu + s Z`, from the interval moments `i` of `Z`
/// over the corresponding standardised interval.
#[inline]
pub(crate) fn unit_moments(mu: f64, s: f64, i: &Poly) -> Poly {
    let mut v = *i;
    let mut sk = 1.0;
    for vk in v.iter_mut() {
        *vk *= sk;
        sk *= s;
    }
    let mut mu_pow = [1.0; 8];
    for k in 1..8 {
        mu_pow[k] = mu_pow[k - 1] * mu;
    }
    let mut r = [0.0; 8];
    for k in 0..8 {
        let mut acc = 0.0;
        for j in 0..=k {
            acc += BINOMIAL[k][j] * mu_pow[k - j] * v[j];
        }
        r[k] = acc;
    }
    r
}

#[inline]
pub(crate) fn dot(p: &Poly, r: &Poly) -> f64 {
    p.iter().zip(r).map(|(a, b)| a * b).sum()
}

/// The terms of every lattice coordinate `c` in `lo..=hi` (at most `N`; returns how many).
/// Coordinate `c`'s kernel has pieces on the unit cells `[c − 1, c)` and `[c, c + 1)`; each cell's
/// moments `E[y^k 1{cell}]` (y the offset from the cell's lower end) are computed once, from tail
/// moments shared at the integer boundaries, and serve both coordinates that meet the cell.
/// The filters read these through [`axis_terms`] (tabulated); this is the table's source and the
/// tests' reference.
pub(crate) fn axis_terms_exact<const N: usize>(
    m: f64,
    s: f64,
    lo: i32,
    hi: i32,
    out: &mut [(i32, AxisTerms); N],
) -> usize {
    let k = kernel();
    let z = |c: i32| (c as f64 - m) / s;
    let tail = |c: i32| gaussian::TailMoments::at(z(c));
    // A cell wholly beyond the footprint's reach (both ends past `TAIL_ZERO` σ on one side) has
    // no moments: `None`, skipped without arithmetic.
    let cell = |j: i32, a: &gaussian::TailMoments, b: &gaussian::TailMoments| {
        let (za, zb) = (z(j), z(j + 1));
        (za < gaussian::TAIL_ZERO && zb > -gaussian::TAIL_ZERO)
            .then(|| unit_moments(m - j as f64, s, &gaussian::TailMoments::between(a, b)))
    };
    let mut t1 = tail(lo);
    let mut below = cell(lo - 1, &tail(lo - 1), &t1);
    let mut n = 0;
    for c in lo..=hi {
        if n >= N {
            break;
        }
        let t2 = tail(c + 1);
        let above = cell(c, &t1, &t2);
        let mut t = AxisTerms::default();
        if let Some(r) = &below {
            t.w += dot(&k.w_up, r);
            t.dw += dot(&k.dw_up, r);
            t.w1 += dot(&k.w1_up, r);
            t.dw1 += dot(&k.dw1_up, r);
        }
        if let Some(r) = &above {
            t.w += dot(&k.w[1], r);
            t.dw += dot(&k.dw[1], r);
            t.w1 += dot(&k.w1[1], r);
            t.dw1 += dot(&k.dw1[1], r);
        }
        out[n] = (c, t);
        n += 1;
        (t1, below) = (t2, above);
    }
    n
}

/// The Gaussian averages `E[q(d + sZ)]` of the kernel's derivatives, for the table of
/// [`crate::nodes::kernel_table`]: `q` = W, W′, W″, W‴, dW, (dW)′, (dW)″, (dW)‴ (`s > 0`). Each is a
/// piecewise polynomial on the two unit cells around 0, so all eight read the same two sets of
/// cell moments (the third derivatives jump at 0 and ±1 but the second are continuous, so these
/// are also the `d`-derivatives of the averages).
#[cfg(test)]
pub(crate) fn kernel_expectations(d: f64, s: f64) -> [f64; 8] {
    let z = |c: f64| (c - d) / s;
    let (t0, t1, t2) =
        (gaussian::TailMoments::at(z(-1.0)), gaussian::TailMoments::at(z(0.0)), gaussian::TailMoments::at(z(1.0)));
    // Cell [-1, 0) in y = x + 1, cell [0, 1) in y = x.
    let below = unit_moments(d + 1.0, s, &gaussian::TailMoments::between(&t0, &t1));
    let above = unit_moments(d, s, &gaussian::TailMoments::between(&t1, &t2));
    let k = kernel();
    let up = |p: &Poly| gaussian::poly_shift_scale(p, -1.0, 1.0);
    let mut out = [0.0; 8];
    for (base, (n, p)) in [(0, (k.w[0], k.w[1])), (4, (k.dw[0], k.dw[1]))] {
        let (mut n, mut p) = (n, p);
        for k in 0..4 {
            out[base + k] = dot(&up(&n), &below) + dot(&p, &above);
            n = poly_deriv(&n);
            p = poly_deriv(&p);
        }
    }
    out
}

/// [`axis_terms_exact`] as the filters use it: from the table of [`crate::nodes::kernel_table`] for
/// spreads it covers (all the filters ask for), exactly beyond.
#[inline]
pub(crate) fn axis_terms<const N: usize>(m: f64, s: f64, lo: i32, hi: i32, out: &mut [(i32, AxisTerms); N]) -> usize {
    if s <= crate::nodes::kernel_table::S_MAX {
        crate::nodes::kernel_table::axis_terms(m, s, lo, hi, out)
    } else {
        axis_terms_exact(m, s, lo, hi, out)
    }
}

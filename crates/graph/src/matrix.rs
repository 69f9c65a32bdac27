//! Uniform matrices: MaterialX's `matrix33` and `matrix44` values.
//!
//! tessera evaluates matrices once, at load: a matrix is a uniform of the graph, never a
//! stream that varies over the surface. Every matrix-valued node (`constant`, `dot`,
//! `transpose`, `invertmatrix`, `determinant`, `creatematrix`, `add`, `subtract`, `multiply`,
//! `divide`, and the conditionals) is folded from constant inputs while the document loads, and
//! the nodes that read a matrix take the folded value as a parameter: `transformmatrix` becomes
//! a linear (affine, for homogeneous inputs) map of its vector input, `extract` of a matrix row
//! and `determinant` become constants. A matrix that would depend on the shading point (a
//! `creatematrix` of a varying vector, say) is reported as unsupported, naming the input.
//!
//! Conventions (MaterialX's): a value string lists the matrix row by row; vectors are rows,
//! transformed as `v' = v · M`, so a `matrix44`'s translation is its last row and a vector3 or
//! vector2 is extended with a homogeneous 1 (`transformmatrix` then drops the extra channel
//! without dividing by it). `extract` with `index` i gives row i. `multiply` of two matrices is
//! the product `in1 · in2`, `divide` is `in1 · in2⁻¹`.

use std::fmt;

/// The matrix-valued categories folded at load (beyond `constant`, `dot`, the arithmetic nodes
/// and the conditionals, which also exist for other types).
pub const FOLDED: &[&str] = &["creatematrix", "determinant", "invertmatrix", "transpose"];

/// A square matrix of size 3 or 4, row-major, in double precision (folding happens once).
#[derive(Clone, Copy, PartialEq)]
pub struct Matrix {
    /// 3 or 4.
    pub n: usize,
    /// Rows; entries beyond `n` are those of the identity.
    pub m: [[f64; 4]; 4],
}

impl fmt::Debug for Matrix {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "matrix{}{}[", self.n, self.n)?;
        for r in 0..self.n {
            let row: Vec<String> = (0..self.n).map(|c| format!("{}", self.m[r][c])).collect();
            write!(f, "{}{}", if r > 0 { "; " } else { "" }, row.join(", "))?;
        }
        f.write_str("]")
    }
}

impl Matrix {
    /// The identity of size `n`.
    pub fn identity(n: usize) -> Matrix {
        let mut m = [[0.0; 4]; 4];
        for (i, row) in m.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        Matrix { n, m }
    }

    /// Every entry `x` (the entries beyond `n` stay those of the identity).
    pub fn splat(n: usize, x: f64) -> Matrix {
        let mut a = Matrix::identity(n);
        for r in 0..n {
            for c in 0..n {
                a.m[r][c] = x;
            }
        }
        a
    }

    /// The size a MaterialX type name gives (`matrix33` → 3, `matrix44` → 4).
    pub fn size_of_type(ty: &str) -> Option<usize> {
        match ty {
            "matrix33" => Some(3),
            "matrix44" => Some(4),
            _ => None,
        }
    }

    /// Parses a MaterialX value string of `n·n` finite numbers, row by row.
    pub fn parse(n: usize, text: &str) -> Option<Matrix> {
        let parts: Vec<&str> = text.split(',').map(str::trim).collect();
        if parts.len() != n * n {
            return None;
        }
        let mut a = Matrix::identity(n);
        for (k, p) in parts.iter().enumerate() {
            let x = p.parse::<f64>().ok().filter(|x| x.is_finite())?;
            a.m[k / n][k % n] = x;
        }
        Some(a)
    }

    /// Row `i` (`None` beyond the size).
    pub fn row(&self, i: usize) -> Option<&[f64]> {
        (i < self.n).then(|| &self.m[i][..self.n])
    }

    /// The transpose.
    pub fn transpose(&self) -> Matrix {
        let mut t = *self;
        for r in 0..self.n {
            for c in 0..self.n {
                t.m[r][c] = self.m[c][r];
            }
        }
        t
    }

    /// The product `self · b` (sizes must match).
    pub fn mul(&self, b: &Matrix) -> Matrix {
        let mut p = Matrix::identity(self.n);
        for r in 0..self.n {
            for c in 0..self.n {
                p.m[r][c] = (0..self.n).map(|k| self.m[r][k] * b.m[k][c]).sum();
            }
        }
        p
    }

    /// Entry-wise `f(self, b)`.
    pub fn zip(&self, b: &Matrix, f: impl Fn(f64, f64) -> f64) -> Matrix {
        let mut p = *self;
        for r in 0..self.n {
            for c in 0..self.n {
                p.m[r][c] = f(self.m[r][c], b.m[r][c]);
            }
        }
        p
    }

    /// The determinant (Gaussian elimination with partial pivoting).
    pub fn determinant(&self) -> f64 {
        self.lu().map_or(0.0, |(_, det)| det)
    }

    /// The inverse, or `None` when the matrix is singular (a pivot below 1e-12 of the largest
    /// entry) or its inverse is not finite.
    pub fn inverse(&self) -> Option<Matrix> {
        let n = self.n;
        let scale = self.m.iter().take(n).flat_map(|r| r[..n].iter()).fold(0.0f64, |a, x| a.max(x.abs()));
        if !(scale > 0.0 && scale.is_finite()) {
            return None;
        }
        // Gauss–Jordan on [A | I].
        let mut a = self.m;
        let mut inv = Matrix::identity(n).m;
        for col in 0..n {
            let piv = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
            if a[piv][col].abs() <= 1e-12 * scale {
                return None;
            }
            a.swap(col, piv);
            inv.swap(col, piv);
            let d = a[col][col];
            for k in 0..n {
                a[col][k] /= d;
                inv[col][k] /= d;
            }
            for r in 0..n {
                if r != col {
                    let f = a[r][col];
                    for k in 0..n {
                        a[r][k] -= f * a[col][k];
                        inv[r][k] -= f * inv[col][k];
                    }
                }
            }
        }
        let out = Matrix { n, m: inv };
        out.m.iter().all(|r| r.iter().all(|x| x.is_finite())).then_some(out)
    }

    /// Upper-triangular factor's diagonal product: `(pivots, determinant)`; `None` if not finite.
    fn lu(&self) -> Option<(usize, f64)> {
        let n = self.n;
        let mut a = self.m;
        let mut det = 1.0;
        for col in 0..n {
            let piv = (col..n).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
            if a[piv][col] == 0.0 {
                return Some((col, 0.0));
            }
            if piv != col {
                a.swap(col, piv);
                det = -det;
            }
            det *= a[col][col];
            for r in col + 1..n {
                let f = a[r][col] / a[col][col];
                for k in col..n {
                    a[r][k] -= f * a[col][k];
                }
            }
        }
        det.is_finite().then_some((n, det))
    }

    /// The affine map `transformmatrix` applies to a vector of `dim` channels (2, 3 or 4):
    /// `out[k] = Σⱼ in[j] · M[j][k] + t[k]`, with `t` the row after the vector's channels when the
    /// vector is extended homogeneously (`dim < n`), else zero. `None` when the sizes do not fit
    /// (a vector2 needs a matrix33, a vector4 a matrix44).
    pub fn affine_for(&self, dim: usize) -> Option<([[f32; 4]; 4], [f32; 4])> {
        let homogeneous = match (dim, self.n) {
            (2, 3) | (3, 4) => true,
            (3, 3) | (4, 4) => false,
            _ => return None,
        };
        let mut lin = [[0.0f32; 4]; 4];
        let mut t = [0.0f32; 4];
        for k in 0..dim {
            for (j, row) in lin.iter_mut().enumerate().take(dim) {
                row[k] = self.m[j][k] as f32;
            }
            if homogeneous {
                t[k] = self.m[dim][k] as f32;
            }
        }
        Some((lin, t))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lcg(s: &mut u64) -> f64 {
        *s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        ((*s >> 11) as f64 / (1u64 << 53) as f64) * 4.0 - 2.0
    }

    fn random(n: usize, s: &mut u64) -> Matrix {
        let mut a = Matrix::identity(n);
        for r in 0..n {
            for c in 0..n {
                a.m[r][c] = lcg(s);
            }
        }
        a
    }

    #[test]
    fn inverse_times_matrix_is_identity() {
        let mut s = 7;
        for n in [3, 4] {
            for _ in 0..50 {
                let a = random(n, &mut s);
                let Some(inv) = a.inverse() else { continue };
                let p = a.mul(&inv);
                for r in 0..n {
                    for c in 0..n {
                        let want = if r == c { 1.0 } else { 0.0 };
                        assert!((p.m[r][c] - want).abs() < 1e-9, "{a:?} · {inv:?} = {p:?}");
                    }
                }
            }
        }
    }

    #[test]
    fn determinant_matches_cofactor_expansion() {
        fn cofactor(a: &[Vec<f64>]) -> f64 {
            if a.len() == 1 {
                return a[0][0];
            }
            (0..a.len())
                .map(|c| {
                    let minor: Vec<Vec<f64>> = a[1..]
                        .iter()
                        .map(|r| r.iter().enumerate().filter(|(k, _)| *k != c).map(|(_, x)| *x).collect())
                        .collect();
                    let sign = if c % 2 == 0 { 1.0 } else { -1.0 };
                    sign * a[0][c] * cofactor(&minor)
                })
                .sum()
        }
        let mut s = 11;
        for n in [3, 4] {
            for _ in 0..50 {
                let a = random(n, &mut s);
                let rows: Vec<Vec<f64>> = (0..n).map(|r| a.m[r][..n].to_vec()).collect();
                let want = cofactor(&rows);
                assert!((a.determinant() - want).abs() < 1e-9 * want.abs().max(1.0), "{a:?}");
            }
        }
    }

    #[test]
    fn singular_matrices_have_no_inverse() {
        let a = Matrix::parse(3, "1,2,3, 2,4,6, 0,0,1").unwrap();
        assert!(a.inverse().is_none());
        assert_eq!(a.determinant(), 0.0);
        assert!(Matrix::splat(4, 0.0).inverse().is_none());
    }

    #[test]
    fn parse_reads_rows_and_rejects_bad_text() {
        let a = Matrix::parse(3, "1, 2, 3, 4, 5, 6, 7, 8, 9").unwrap();
        assert_eq!(a.row(1).unwrap(), &[4.0, 5.0, 6.0]);
        assert_eq!(a.transpose().row(0).unwrap(), &[1.0, 4.0, 7.0]);
        assert!(Matrix::parse(3, "1, 2, 3").is_none());
        assert!(Matrix::parse(4, "1,0,0,0, 0,1,0,0, 0,0,1,0, 0,0,0,nan").is_none());
        assert!(Matrix::parse(3, "1,0,0, 0,x,0, 0,0,1").is_none());
    }

    #[test]
    fn affine_map_is_the_row_vector_product() {
        let mut s = 3;
        let a = random(4, &mut s);
        // vector3 with a matrix44: (x, y, z, 1) · M, first three channels.
        let (lin, t) = a.affine_for(3).unwrap();
        let v = [0.3, -1.2, 2.0];
        for k in 0..3 {
            let want: f64 = (0..3).map(|j| v[j] * a.m[j][k]).sum::<f64>() + a.m[3][k];
            let got: f64 = (0..3).map(|j| v[j] * lin[j][k] as f64).sum::<f64>() + t[k] as f64;
            assert!((want - got).abs() < 1e-5);
        }
        assert!(a.affine_for(2).is_none());
        assert!(Matrix::identity(3).affine_for(4).is_none());
    }
}

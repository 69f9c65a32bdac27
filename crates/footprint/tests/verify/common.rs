//! Independent test-side geometry: analytic surfaces, exact path tracing with half-vector
//! perturbations, an RNG, and a dense linear solver. Nothing here calls the library's maths;
//! the library is only handed `footprint::Vertex` descriptions, as a renderer would.

#![allow(dead_code)]

use footprint::Vertex;
use glam::{DMat2, DVec2, DVec3};

// ---------------------------------------------------------------------------------------------
// Random numbers

/// PCG-XSH-RR 64/32 with Box–Muller normals.
pub struct Rng {
    state: u64,
    spare: Option<f64>,
}

impl Rng {
    pub fn new(seed: u64) -> Self {
        let mut r = Rng { state: seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ 0xDA3E_39CB_94B9_5BDB, spare: None };
        r.next_u32();
        r
    }
    pub fn next_u32(&mut self) -> u32 {
        let old = self.state;
        self.state = old.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let xorshifted = (((old >> 18) ^ old) >> 27) as u32;
        let rot = (old >> 59) as u32;
        xorshifted.rotate_right(rot)
    }
    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        let hi = self.next_u32() as u64;
        let lo = self.next_u32() as u64;
        (((hi << 32) | lo) >> 11) as f64 / (1u64 << 53) as f64
    }
    pub fn range(&mut self, a: f64, b: f64) -> f64 {
        a + (b - a) * self.uniform()
    }
    pub fn normal(&mut self) -> f64 {
        if let Some(s) = self.spare.take() {
            return s;
        }
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
    pub fn normal2(&mut self) -> DVec2 {
        DVec2::new(self.normal(), self.normal())
    }
    pub fn unit_vector(&mut self) -> DVec3 {
        loop {
            let v = DVec3::new(self.normal(), self.normal(), self.normal());
            let l = v.length();
            if l > 1e-3 {
                return v / l;
            }
        }
    }
    /// Random symmetric positive definite 2×2 with eigenvalues in [lo, hi].
    pub fn spd(&mut self, lo: f64, hi: f64) -> DMat2 {
        let a = self.range(0.0, std::f64::consts::PI);
        let (s, c) = a.sin_cos();
        let r = DMat2::from_cols(DVec2::new(c, s), DVec2::new(-s, c));
        let d = DMat2::from_diagonal(DVec2::new(self.range(lo, hi), self.range(lo, hi)));
        r * d * r.transpose()
    }
    pub fn mat2(&mut self, scale: f64) -> DMat2 {
        DMat2::from_cols(self.normal2() * scale, self.normal2() * scale)
    }
}

// ---------------------------------------------------------------------------------------------
// Frames

#[derive(Clone, Copy, Debug)]
pub struct Frame {
    pub t: DVec3,
    pub b: DVec3,
    pub n: DVec3,
}

impl Frame {
    /// A frame around `n` with the tangent rotated by `angle` from a Gram–Schmidt choice.
    pub fn around(n: DVec3, angle: f64) -> Frame {
        let n = n.normalize();
        let a = if n.x.abs() < 0.6 { DVec3::X } else { DVec3::Y };
        let t0 = (a - n * n.dot(a)).normalize();
        let b0 = n.cross(t0);
        let (s, c) = angle.sin_cos();
        let t = t0 * c + b0 * s;
        Frame { t, b: n.cross(t), n }
    }
    pub fn to_local(&self, v: DVec3) -> DVec2 {
        DVec2::new(self.t.dot(v), self.b.dot(v))
    }
}

/// Rotates `v` by the smallest rotation taking unit `from` to unit `to` (Rodrigues).
pub fn min_rotation(from: DVec3, to: DVec3, v: DVec3) -> DVec3 {
    let c = from.dot(to);
    let k = from.cross(to);
    v * c + k.cross(v) + k * (k.dot(v) / (1.0 + c))
}

/// The frame carried from `f0` to the new normal `n` by minimal rotation.
pub fn transport(f0: &Frame, n: DVec3) -> Frame {
    Frame { t: min_rotation(f0.n, n, f0.t), b: min_rotation(f0.n, n, f0.b), n }
}

/// Rotates `v` about unit `axis` by `angle`.
pub fn rotate(v: DVec3, axis: DVec3, angle: f64) -> DVec3 {
    let (s, c) = angle.sin_cos();
    v * c + axis.cross(v) * s + axis * axis.dot(v) * (1.0 - c)
}

/// Some unit vector perpendicular to `d`.
pub fn perpendicular(d: DVec3) -> DVec3 {
    Frame::around(d, 0.0).t
}

fn solve2(m: [[f64; 2]; 2], r: DVec2) -> DVec2 {
    let det = m[0][0] * m[1][1] - m[0][1] * m[1][0];
    DVec2::new((r.x * m[1][1] - m[0][1] * r.y) / det, (m[0][0] * r.y - m[1][0] * r.x) / det)
}

// ---------------------------------------------------------------------------------------------
// Surfaces

#[derive(Clone, Copy, Debug)]
pub enum Surface {
    /// Plane through `p0` with normal `n`, parameterised as `p0 + u a + v c` (uv = (u, v)).
    Plane { p0: DVec3, n: DVec3, a: DVec3, c: DVec3 },
    /// Sphere; the normal is outward unless `inward`. uv = (φ, θ) in world spherical coordinates.
    Sphere { c: DVec3, r: f64, inward: bool },
    /// Flat triangle with vertex normals `m` (interpolated, normalised) and vertex uvs.
    Triangle { q: [DVec3; 3], m: [DVec3; 3], uv: [DVec2; 3] },
}

impl Surface {
    pub fn plane(p0: DVec3, n: DVec3) -> Surface {
        let n = n.normalize();
        let f = Frame::around(n, 0.7);
        Surface::Plane { p0, n, a: f.t * 1.3 + f.b * 0.4, c: f.t * -0.2 + f.b * 0.9 }
    }

    /// Barycentrics (β₁, β₂) of a point in the triangle's plane.
    fn bary(q: &[DVec3; 3], p: DVec3) -> DVec2 {
        let e1 = q[1] - q[0];
        let e2 = q[2] - q[0];
        let d = p - q[0];
        solve2([[e1.dot(e1), e1.dot(e2)], [e2.dot(e1), e2.dot(e2)]], DVec2::new(e1.dot(d), e2.dot(d)))
    }

    fn tri_interp_normal(q: &[DVec3; 3], m: &[DVec3; 3], p: DVec3) -> DVec3 {
        let bb = Self::bary(q, p);
        m[0] * (1.0 - bb.x - bb.y) + m[1] * bb.x + m[2] * bb.y
    }

    /// Shading normal at a point of the surface.
    pub fn normal(&self, p: DVec3) -> DVec3 {
        match *self {
            Surface::Plane { n, .. } => n,
            Surface::Sphere { c, r, inward } => {
                let n = (p - c) / r;
                if inward {
                    -n
                } else {
                    n
                }
            }
            Surface::Triangle { q, m, .. } => Self::tri_interp_normal(&q, &m, p).normalize(),
        }
    }

    pub fn geometric_normal(&self, p: DVec3) -> DVec3 {
        match *self {
            Surface::Triangle { q, .. } => (q[1] - q[0]).cross(q[2] - q[0]).normalize(),
            _ => self.normal(p),
        }
    }

    /// Intersection of the ray `o + s d` (s > 0) nearest to `near`.
    pub fn intersect(&self, o: DVec3, d: DVec3, near: DVec3) -> DVec3 {
        match *self {
            Surface::Plane { p0, n, .. } => o + d * ((p0 - o).dot(n) / d.dot(n)),
            Surface::Triangle { q, .. } => {
                let n = (q[1] - q[0]).cross(q[2] - q[0]);
                o + d * ((q[0] - o).dot(n) / d.dot(n))
            }
            Surface::Sphere { c, r, .. } => {
                let dd = d.dot(d);
                let oc = o - c;
                let bh = oc.dot(d);
                let disc = bh * bh - dd * (oc.dot(oc) - r * r);
                assert!(disc >= 0.0, "ray misses sphere");
                let sq = disc.sqrt();
                let p1 = o + d * ((-bh - sq) / dd);
                let p2 = o + d * ((-bh + sq) / dd);
                if (p1 - near).length() < (p2 - near).length() {
                    p1
                } else {
                    p2
                }
            }
        }
    }

    /// The point whose projection onto the base tangent plane of (`p0`, `f0`) is offset by
    /// `dx`, exactly on the surface, and the frame carried there by minimal rotation.
    pub fn moved(&self, p0: DVec3, f0: &Frame, dx: DVec2) -> (DVec3, Frame) {
        match *self {
            Surface::Plane { .. } => (p0 + f0.t * dx.x + f0.b * dx.y, *f0),
            Surface::Sphere { c, r, .. } => {
                let nout = (p0 - c) / r;
                let q = c + f0.t * dx.x + f0.b * dx.y + nout * (r * r - dx.length_squared()).sqrt();
                (q, transport(f0, self.normal(q)))
            }
            Surface::Triangle { q, .. } => {
                let e1 = q[1] - q[0];
                let e2 = q[2] - q[0];
                let db = solve2([[f0.t.dot(e1), f0.t.dot(e2)], [f0.b.dot(e1), f0.b.dot(e2)]], dx);
                let p = p0 + e1 * db.x + e2 * db.y;
                (p, transport(f0, self.normal(p)))
            }
        }
    }

    /// Texture coordinates of a point on the surface.
    pub fn uv(&self, p: DVec3) -> DVec2 {
        match *self {
            Surface::Plane { p0, a, c, .. } => {
                let d = p - p0;
                solve2([[a.dot(a), a.dot(c)], [c.dot(a), c.dot(c)]], DVec2::new(a.dot(d), c.dot(d)))
            }
            Surface::Sphere { c, r, .. } => {
                let d = (p - c) / r;
                DVec2::new(d.y.atan2(d.x), d.z.clamp(-1.0, 1.0).acos())
            }
            Surface::Triangle { q, uv, .. } => {
                let bb = Self::bary(&q, p);
                uv[0] * (1.0 - bb.x - bb.y) + uv[1] * bb.x + uv[2] * bb.y
            }
        }
    }

    /// What a renderer would hand the library at `p` with shading frame `f`.
    pub fn lib_vertex(&self, p: DVec3, f: &Frame) -> Vertex {
        let (dpdu, dpdv, dndu, dndv) = match *self {
            Surface::Plane { a, c, .. } => (a, c, DVec3::ZERO, DVec3::ZERO),
            Surface::Sphere { c, r, inward } => {
                let d = p - c;
                let rho = (d.x * d.x + d.y * d.y).sqrt();
                let (st, ct) = (rho / r, d.z / r);
                let (sp, cp) = (d.y / rho, d.x / rho);
                let dpdu = DVec3::new(-d.y, d.x, 0.0);
                let dpdv = DVec3::new(r * ct * cp, r * ct * sp, -r * st);
                let s = if inward { -1.0 / r } else { 1.0 / r };
                (dpdu, dpdv, dpdu * s, dpdv * s)
            }
            Surface::Triangle { q, m, uv } => {
                let e1 = q[1] - q[0];
                let e2 = q[2] - q[0];
                let nn = Self::tri_interp_normal(&q, &m, p);
                let len = nn.length();
                let n = nn / len;
                let dn = |dm: DVec3| (dm - n * n.dot(dm)) / len;
                let (dnb1, dnb2) = (dn(m[1] - m[0]), dn(m[2] - m[0]));
                // d(uv)/dβ = [uv1 − uv0, uv2 − uv0]; invert to get d/d(uv).
                let du1 = uv[1] - uv[0];
                let du2 = uv[2] - uv[0];
                let det = du1.x * du2.y - du2.x * du1.y;
                // dβ/d(uv) = inverse of [[du1.x, du2.x], [du1.y, du2.y]]
                let inv = [[du2.y / det, -du2.x / det], [-du1.y / det, du1.x / det]];
                let dpdu = e1 * inv[0][0] + e2 * inv[1][0];
                let dpdv = e1 * inv[0][1] + e2 * inv[1][1];
                let dndu = dnb1 * inv[0][0] + dnb2 * inv[1][0];
                let dndv = dnb1 * inv[0][1] + dnb2 * inv[1][1];
                (dpdu, dpdv, dndu, dndv)
            }
        };
        Vertex { p, n: f.n, t: f.t, b: f.b, dpdu, dpdv, dndu, dndv, uv: self.uv(p) }
    }
}

// ---------------------------------------------------------------------------------------------
// Half-vector slope, reflection and refraction about a half vector

/// How the path continues at a vertex (test-side twin of the library's `Scatter`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    Reflect,
    /// `eta = η_o / η_i`.
    Refract(f64),
    End,
}

impl Event {
    pub fn lib(self) -> footprint::Scatter {
        match self {
            Event::Reflect => footprint::Scatter::Reflection,
            Event::Refract(eta) => footprint::Scatter::Refraction { eta },
            Event::End => panic!("no scatter at the end"),
        }
    }
}

/// Half-vector slope at `cur` in frame `f` (independent implementation).
pub fn slope(prev: DVec3, cur: DVec3, f: &Frame, next: DVec3, ev: Event) -> DVec2 {
    let wi = (prev - cur).normalize();
    let wo = (next - cur).normalize();
    let h = match ev {
        Event::Reflect => wi + wo,
        Event::Refract(eta) => -(wi + wo * eta),
        Event::End => panic!(),
    };
    DVec2::new(h.dot(f.t) / h.dot(f.n), h.dot(f.b) / h.dot(f.n))
}

/// Outgoing direction at a vertex with frame `f` for incoming direction `wi` (pointing away
/// from the surface, towards the previous vertex) and half-vector slope `s`.
pub fn scatter_dir(wi: DVec3, f: &Frame, s: DVec2, ev: Event) -> DVec3 {
    let h = (f.t * s.x + f.b * s.y + f.n).normalize();
    match ev {
        Event::Reflect => h * (2.0 * wi.dot(h)) - wi,
        Event::Refract(eta) => {
            let h = if wi.dot(h) > 0.0 { h } else { -h };
            let c = wi.dot(h);
            let k = 1.0 - (1.0 - c * c) / (eta * eta);
            assert!(k > 0.0, "total internal reflection in a test path");
            -wi / eta + h * (c / eta - k.sqrt())
        }
        Event::End => panic!(),
    }
}

// ---------------------------------------------------------------------------------------------
// Paths built by placing surfaces along a traced base path

/// Where to put the next surface relative to the current ray `x + s ω`.
#[derive(Clone, Copy, Debug)]
pub enum Place {
    /// A plane hit at distance `dist`, its normal `−ω` tilted by `tilt` radians.
    Plane { dist: f64, tilt: f64 },
    /// A sphere of radius `r` hit from outside at distance `dist` with incidence angle `beta`.
    SphereOutside { dist: f64, r: f64, beta: f64, inward: bool },
    /// A sphere of radius `r` containing the ray origin, hit from inside at distance `dist` with
    /// incidence angle `beta` (requires `dist < 2 r cos beta`).
    SphereInside { dist: f64, r: f64, beta: f64, inward: bool },
    /// The far side of the previous vertex's sphere (the ray is inside it).
    SameSphere,
    /// A triangle with vertex normals tilted by up to `bend` radians, hit at `dist`, its
    /// geometric normal `−ω` tilted by `tilt`.
    Triangle { dist: f64, tilt: f64, bend: f64 },
}

#[derive(Clone, Copy, Debug)]
pub struct Node {
    pub place: Place,
    pub event: Event,
    pub alpha: f64,
    pub base_slope: DVec2,
    /// Rotation of the tangent within the tangent plane at the base hit.
    pub frame_angle: f64,
}

pub struct Camera {
    pub origin: DVec3,
    /// Unnormalised direction of the base pixel; the direction for pixel offset `(x, y)` is
    /// `forward + x right + y up`.
    pub forward: DVec3,
    pub right: DVec3,
    pub up: DVec3,
}

impl Camera {
    pub fn looking_at(origin: DVec3, target: DVec3, pixel_angle: f64) -> Camera {
        let f = (target - origin).normalize();
        let right = perpendicular(f);
        let up = f.cross(right);
        Camera { origin, forward: f, right: right * pixel_angle, up: up * pixel_angle }
    }
    pub fn dir(&self, px: DVec2) -> DVec3 {
        self.forward + self.right * px.x + self.up * px.y
    }
}

pub struct Path {
    pub camera: Camera,
    pub nodes: Vec<Node>,
    pub surfaces: Vec<Surface>,
    /// Base vertices and frames (x₁ … x_k).
    pub points: Vec<DVec3>,
    pub frames: Vec<Frame>,
}

impl Path {
    /// Traces the base path, creating the surfaces on the way.
    pub fn build(camera: Camera, nodes: Vec<Node>) -> Path {
        let mut surfaces: Vec<Surface> = Vec::new();
        let mut points = Vec::new();
        let mut frames = Vec::new();
        let mut o = camera.origin;
        let mut d = camera.forward.normalize();
        for (k, node) in nodes.iter().enumerate() {
            let surf = match node.place {
                Place::Plane { dist, tilt } => {
                    let h = o + d * dist;
                    let axis = perpendicular(d);
                    Surface::plane(h, rotate(-d, axis, tilt))
                }
                Place::SphereOutside { dist, r, beta, inward } => {
                    let h = o + d * dist;
                    let n = -d * beta.cos() + perpendicular(d) * beta.sin();
                    Surface::Sphere { c: h - n * r, r, inward }
                }
                Place::SphereInside { dist, r, beta, inward } => {
                    assert!(dist < 2.0 * r * beta.cos());
                    let h = o + d * dist;
                    let n = d * beta.cos() + perpendicular(d) * beta.sin();
                    Surface::Sphere { c: h - n * r, r, inward }
                }
                Place::SameSphere => surfaces[k - 1],
                Place::Triangle { dist, tilt, bend } => {
                    let h = o + d * dist;
                    let axis = perpendicular(d);
                    let ng = rotate(-d, axis, tilt);
                    let f = Frame::around(ng, 0.3);
                    let q = [h + f.t * -1.0 + f.b * -0.7, h + f.t * 1.2 + f.b * -0.4, h + f.t * -0.1 + f.b * 1.1];
                    let m = [
                        rotate(ng, f.t, bend).normalize(),
                        rotate(ng, f.b, -0.8 * bend).normalize(),
                        rotate(ng, (f.t + f.b).normalize(), 0.6 * bend).normalize(),
                    ];
                    let uv = [DVec2::new(0.1, 0.2), DVec2::new(0.9, 0.35), DVec2::new(0.3, 0.8)];
                    Surface::Triangle { q, m, uv }
                }
            };
            let near = match node.place {
                Place::SameSphere => {
                    // far intersection: the one away from the current origin
                    o + d * 1e9
                }
                _ => o,
            };
            let p = match node.place {
                Place::SameSphere => surf.intersect(o, d, near),
                Place::Plane { dist, .. }
                | Place::SphereOutside { dist, .. }
                | Place::SphereInside { dist, .. }
                | Place::Triangle { dist, .. } => surf.intersect(o, d, o + d * dist),
            };
            let f = Frame::around(surf.normal(p), node.frame_angle);
            surfaces.push(surf);
            points.push(p);
            frames.push(f);
            if node.event != Event::End {
                let wo = scatter_dir(-d, &f, node.base_slope, node.event);
                o = p;
                d = wo.normalize();
            }
        }
        Path { camera, nodes, surfaces, points, frames }
    }

    /// Library vertex descriptions of the base path.
    pub fn lib_vertices(&self) -> Vec<Vertex> {
        (0..self.points.len()).map(|k| self.surfaces[k].lib_vertex(self.points[k], &self.frames[k])).collect()
    }

    /// Exactly re-traces the path for a pixel offset and half-vector slope offsets (one per
    /// scattering vertex), returning the perturbed vertices.
    pub fn trace(&self, px: DVec2, dh: &[DVec2]) -> Vec<DVec3> {
        let mut out = Vec::with_capacity(self.points.len());
        let mut o = self.camera.origin;
        let mut d = self.camera.dir(px).normalize();
        for k in 0..self.points.len() {
            let surf = &self.surfaces[k];
            let p = surf.intersect(o, d, self.points[k]);
            out.push(p);
            let node = &self.nodes[k];
            if node.event == Event::End {
                break;
            }
            let f = transport(&self.frames[k], surf.normal(p));
            let s = node.base_slope + dh.get(k).copied().unwrap_or(DVec2::ZERO);
            d = scatter_dir(-d, &f, s, node.event).normalize();
            o = p;
        }
        out
    }
}

// ---------------------------------------------------------------------------------------------
// Matrix helpers

pub fn frob(m: DMat2) -> f64 {
    m.to_cols_array().iter().map(|x| x * x).sum::<f64>().sqrt()
}

pub fn rel_err(a: DMat2, b: DMat2) -> f64 {
    frob(a - b) / frob(b).max(1e-300)
}

/// Dense inverse by Gauss–Jordan with partial pivoting (row-major `n × n`).
pub fn dense_inverse(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let n = a.len();
    let mut m: Vec<Vec<f64>> = a
        .iter()
        .enumerate()
        .map(|(i, row)| {
            let mut r = row.clone();
            r.extend((0..n).map(|j| if i == j { 1.0 } else { 0.0 }));
            r
        })
        .collect();
    for col in 0..n {
        let piv = (col..n).max_by(|&i, &j| m[i][col].abs().partial_cmp(&m[j][col].abs()).unwrap()).unwrap();
        m.swap(col, piv);
        let p = m[col][col];
        assert!(p.abs() > 1e-300, "singular");
        for v in m[col].iter_mut() {
            *v /= p;
        }
        for i in 0..n {
            if i != col {
                let f = m[i][col];
                if f != 0.0 {
                    for j in 0..2 * n {
                        let x = m[col][j];
                        m[i][j] -= f * x;
                    }
                }
            }
        }
    }
    m.into_iter().map(|r| r[n..].to_vec()).collect()
}

pub fn matmul(a: &[Vec<f64>], b: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (n, k, m) = (a.len(), b.len(), b[0].len());
    let mut c = vec![vec![0.0; m]; n];
    for i in 0..n {
        for l in 0..k {
            let x = a[i][l];
            if x != 0.0 {
                for j in 0..m {
                    c[i][j] += x * b[l][j];
                }
            }
        }
    }
    c
}

pub fn transpose(a: &[Vec<f64>]) -> Vec<Vec<f64>> {
    let (n, m) = (a.len(), a[0].len());
    (0..m).map(|j| (0..n).map(|i| a[i][j]).collect()).collect()
}

/// Writes a 2×2 block into a dense matrix at block (bi, bj).
pub fn put_block(d: &mut [Vec<f64>], bi: usize, bj: usize, m: DMat2) {
    for r in 0..2 {
        for c in 0..2 {
            d[2 * bi + r][2 * bj + c] = m.col(c)[r];
        }
    }
}

pub fn get_block(d: &[Vec<f64>], bi: usize, bj: usize) -> DMat2 {
    DMat2::from_cols(
        DVec2::new(d[2 * bi][2 * bj], d[2 * bi + 1][2 * bj]),
        DVec2::new(d[2 * bi][2 * bj + 1], d[2 * bi + 1][2 * bj + 1]),
    )
}

//! Values flowing through a graph: unfiltered [`Value`]s and filtered [`Filtered`] moments.

use glam::{Mat2, Vec2, Vec3};
use std::fmt;

/// The MaterialX data types a node output or input can carry.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
// Four bytes, not one: a `Filtered` is copied whole right after its type is written, and a
// one-byte store followed by a four-byte load of the same word stalls store forwarding (it was a
// fifth of the interpreter's time).
#[repr(u32)]
pub enum ValueType {
    /// `float`
    Float,
    /// `integer` (carried as a float channel)
    Integer,
    /// `boolean` (carried as 0.0 / 1.0)
    Boolean,
    /// `vector2`
    Vector2,
    /// `vector3`
    Vector3,
    /// `vector4`
    Vector4,
    /// `color3`
    Color3,
    /// `color4`
    Color4,
}

impl ValueType {
    /// Number of channels.
    pub fn channels(self) -> usize {
        match self {
            ValueType::Float | ValueType::Integer | ValueType::Boolean => 1,
            ValueType::Vector2 => 2,
            ValueType::Vector3 | ValueType::Color3 => 3,
            ValueType::Vector4 | ValueType::Color4 => 4,
        }
    }

    /// The MaterialX type name.
    pub fn name(self) -> &'static str {
        match self {
            ValueType::Float => "float",
            ValueType::Integer => "integer",
            ValueType::Boolean => "boolean",
            ValueType::Vector2 => "vector2",
            ValueType::Vector3 => "vector3",
            ValueType::Vector4 => "vector4",
            ValueType::Color3 => "color3",
            ValueType::Color4 => "color4",
        }
    }

    /// Parses a MaterialX type name; `None` for types that carry no numeric stream.
    pub fn from_name(s: &str) -> Option<ValueType> {
        Some(match s {
            "float" => ValueType::Float,
            "integer" => ValueType::Integer,
            "boolean" => ValueType::Boolean,
            "vector2" => ValueType::Vector2,
            "vector3" => ValueType::Vector3,
            "vector4" => ValueType::Vector4,
            "color3" => ValueType::Color3,
            "color4" => ValueType::Color4,
            _ => return None,
        })
    }

    /// True for float, integer and boolean.
    pub fn is_scalar(self) -> bool {
        self.channels() == 1
    }
}

impl fmt::Display for ValueType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

/// An unfiltered value: up to four channels and their type.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Value {
    /// The type.
    pub ty: ValueType,
    /// Channel values; channels beyond `ty.channels()` are 0.
    pub v: [f32; 4],
}

impl Value {
    /// A value of type `ty` with every channel `x`.
    pub fn splat(ty: ValueType, x: f32) -> Value {
        let mut v = [0.0; 4];
        v[..ty.channels()].fill(x);
        Value { ty, v }
    }

    /// A float.
    pub fn float(x: f32) -> Value {
        Value::splat(ValueType::Float, x)
    }

    /// A value from its channels (the slice length must match `ty`).
    pub fn new(ty: ValueType, c: &[f32]) -> Value {
        assert_eq!(c.len(), ty.channels());
        let mut v = [0.0; 4];
        v[..c.len()].copy_from_slice(c);
        Value { ty, v }
    }

    /// The used channels.
    pub fn channels(&self) -> &[f32] {
        &self.v[..self.ty.channels()]
    }
}

/// The surface geometry at a shading point, for nodes that read more than uv (`position`,
/// `normal`, `tangent`, `bitangent`, 3D noises through their default `position`).
///
/// Everything is in world space: tessera transforms meshes to world space at load and keeps no
/// object transform, so MaterialX's `object`, `model` and `world` spaces coincide. `dpdu`,
/// `dpdv` (and `dndu`, `dndv`) carry the uv footprint to the surface: a channel of the position
/// has the uv gradient `(∂Pᵢ/∂u, ∂Pᵢ/∂v)`, so the 3D footprint of a uv covariance Σ is `J Σ Jᵀ`
/// with `J = [dpdu dpdv]`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Geometry {
    /// Position.
    pub p: Vec3,
    /// Shading normal (unit).
    pub n: Vec3,
    /// Tangent (unit, along ∂P/∂u made orthogonal to `n`).
    pub t: Vec3,
    /// Bitangent (unit, `n × t`).
    pub b: Vec3,
    /// ∂P/∂u.
    pub dpdu: Vec3,
    /// ∂P/∂v.
    pub dpdv: Vec3,
    /// ∂N/∂u of the shading normal.
    pub dndu: Vec3,
    /// ∂N/∂v of the shading normal.
    pub dndv: Vec3,
}

impl Geometry {
    /// MaterialX's baking geometry, the quad `[−1, 1]²` in the plane z = 0 spanned by uv
    /// `[0, 1]²`: position `(2u − 1, 2v − 1, 0)`, normal +z, tangent +x, bitangent +y,
    /// `dpdu = (2, 0, 0)`, `dpdv = (0, 2, 0)`. The geometry of footprints built without one.
    pub fn flat_quad(uv: Vec2) -> Geometry {
        Geometry {
            p: Vec3::new(2.0 * uv.x - 1.0, 2.0 * uv.y - 1.0, 0.0),
            n: Vec3::Z,
            t: Vec3::X,
            b: Vec3::Y,
            dpdu: Vec3::new(2.0, 0.0, 0.0),
            dpdv: Vec3::new(0.0, 2.0, 0.0),
            dndu: Vec3::ZERO,
            dndv: Vec3::ZERO,
        }
    }
}

/// The footprint of a path vertex in texture space: the Gaussian `N(uv, cov)`, and the surface
/// [`Geometry`] at its centre.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Footprint {
    /// Centre.
    pub uv: Vec2,
    /// 2×2 covariance in uv units (symmetric, positive semi-definite).
    pub cov: Mat2,
    /// Surface geometry at the centre (MaterialX's flat baking quad unless given).
    pub geom: Geometry,
}

impl Footprint {
    /// A footprint with centre `uv` and covariance `cov` on the flat baking quad
    /// ([`Geometry::flat_quad`]).
    pub fn new(uv: Vec2, cov: Mat2) -> Footprint {
        Footprint { uv, cov, geom: Geometry::flat_quad(uv) }
    }

    /// A footprint with centre `uv`, covariance `cov` and the surface geometry at its centre.
    pub fn with_geometry(uv: Vec2, cov: Mat2, geom: Geometry) -> Footprint {
        Footprint { uv, cov, geom }
    }

    /// A point: unfiltered evaluation.
    pub fn point(uv: Vec2) -> Footprint {
        Footprint::new(uv, Mat2::ZERO)
    }

    /// An isotropic footprint with standard deviation `sigma` uv units.
    pub fn isotropic(uv: Vec2, sigma: f32) -> Footprint {
        Footprint::new(uv, Mat2::from_diagonal(Vec2::splat(sigma * sigma)))
    }

    /// `gᵀ Σ h`: the covariance of two linear functions with gradients `g`, `h`.
    #[inline]
    pub fn quad(&self, g: Vec2, h: Vec2) -> f32 {
        g.dot(self.cov * h)
    }
}

/// The filtered statistics of one channel over a footprint.
///
/// For a channel `f` and footprint `N(uv, Σ)`: `mean = E[f]`, `var = Var[f]`, and `grad` the
/// gradient of `mean` with respect to the footprint centre (for a linear function of uv, its
/// Jacobian row). A node whose input is a transformed coordinate forms its own footprint from
/// these: the input coordinate's covariance is `var` per channel, and for affine chains
/// `J Σ Jᵀ` exactly.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Moments {
    /// Filtered value `E[f]`.
    pub mean: f32,
    /// Gradient of `mean` with respect to uv.
    pub grad: Vec2,
    /// Spread `Var[f]` over the footprint.
    pub var: f32,
}

impl Moments {
    /// A constant.
    pub const fn constant(x: f32) -> Moments {
        Moments { mean: x, grad: Vec2::ZERO, var: 0.0 }
    }

    /// Standard deviation.
    #[inline]
    pub fn sigma(&self) -> f32 {
        self.var.max(0.0).sqrt()
    }
}

/// A filtered value: per channel [`Moments`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Filtered {
    /// The type.
    pub ty: ValueType,
    /// Per-channel moments; channels beyond `ty.channels()` are zero.
    pub ch: [Moments; 4],
}

impl Filtered {
    /// A constant (zero spread).
    pub fn constant(v: Value) -> Filtered {
        let mut ch = [Moments::default(); 4];
        for (c, x) in ch.iter_mut().zip(v.v) {
            c.mean = x;
        }
        Filtered { ty: v.ty, ch }
    }

    /// Zero of type `ty`.
    pub fn zero(ty: ValueType) -> Filtered {
        Filtered { ty, ch: [Moments::default(); 4] }
    }

    /// The filtered mean as a [`Value`].
    pub fn mean(&self) -> Value {
        let mut v = [0.0; 4];
        for (x, c) in v.iter_mut().zip(&self.ch).take(self.ty.channels()) {
            *x = c.mean;
        }
        Value { ty: self.ty, v }
    }

    /// Number of channels.
    #[inline]
    pub fn n(&self) -> usize {
        self.ty.channels()
    }

    /// Channel `i`, broadcasting a one-channel value to any index.
    #[inline]
    pub fn at(&self, i: usize) -> Moments {
        if self.n() == 1 {
            self.ch[0]
        } else {
            self.ch[i]
        }
    }

    /// True if no channel varies over the footprint.
    pub fn is_uniform(&self) -> bool {
        self.ch.iter().all(|c| c.var == 0.0 && c.grad == Vec2::ZERO)
    }
}

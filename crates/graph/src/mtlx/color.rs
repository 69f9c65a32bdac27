//! Colour management: colour values and colour images converted to the working space.

use super::importer::{Fail, Importer};
use crate::error::{LoadError, LoadErrorKind};
use crate::graph::Source;
use crate::value::{Value, ValueType};
use glam::{DMat3, DVec3};
use roxmltree::Node as XNode;

/// How a colour space encodes values.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Transfer {
    Linear,
    Srgb,
    Gamma(f64),
}

/// Colour primaries (with their white point).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Primaries {
    Rec709,
    Ap1,
    AdobeRgb,
    DisplayP3,
}

impl Primaries {
    /// The matrix to linear Rec.709 primaries (rows: output channels), as MaterialX's colour
    /// management library defines it.
    fn to_rec709(self) -> DMat3 {
        let rows = match self {
            Primaries::Rec709 => return DMat3::IDENTITY,
            Primaries::Ap1 => [
                [1.705050992658, -0.621792120657, -0.083258872001],
                [-0.130256417507, 1.140804736575, -0.010548319068],
                [-0.024003356805, -0.128968976065, 1.15297233287],
            ],
            Primaries::AdobeRgb => [[1.39835574, -0.398355744, 0.0], [0.0, 1.0, 0.0], [0.0, -0.0429289893, 1.04292899]],
            Primaries::DisplayP3 => [
                [1.22493029, -0.22492968, 0.00000006],
                [-0.04205868, 1.04205894, -0.00000001],
                [-0.01964128, -0.07864794, 1.09828925],
            ],
        };
        DMat3::from_cols_array_2d(&rows).transpose()
    }
}

/// The colour spaces a document may name.
const COLOR_SPACES: &[&str] = &[
    "lin_rec709",
    "srgb_texture",
    "g22_rec709",
    "g18_rec709",
    "rec709_display",
    "acescg",
    "lin_ap1",
    "g22_ap1",
    "g18_ap1",
    "lin_adobergb",
    "adobergb",
    "srgb_displayp3",
    "lin_displayp3",
];

pub(super) fn color_space(name: &str) -> Option<(Transfer, Primaries)> {
    use Primaries::*;
    use Transfer::*;
    Some(match name {
        "lin_rec709" => (Linear, Rec709),
        "srgb_texture" => (Srgb, Rec709),
        "g22_rec709" => (Gamma(2.2), Rec709),
        "g18_rec709" => (Gamma(1.8), Rec709),
        "rec709_display" => (Gamma(2.4), Rec709),
        "acescg" | "lin_ap1" => (Linear, Ap1),
        "g22_ap1" => (Gamma(2.2), Ap1),
        "g18_ap1" => (Gamma(1.8), Ap1),
        "lin_adobergb" => (Linear, AdobeRgb),
        "adobergb" => (Gamma(563.0 / 256.0), AdobeRgb),
        "srgb_displayp3" => (Srgb, DisplayP3),
        "lin_displayp3" => (Linear, DisplayP3),
        _ => return None,
    })
}

/// A conversion from a colour space to the working space.
#[derive(Clone, Copy, Debug)]
pub(super) struct Conversion {
    pub(super) transfer: Transfer,
    /// Source primaries to working primaries, `None` when they are the same.
    matrix: Option<DMat3>,
}

impl Conversion {
    pub(super) fn apply(&self, rgb: DVec3) -> DVec3 {
        let decode = |x: f64| match self.transfer {
            Transfer::Linear => x,
            Transfer::Srgb => {
                if x > 0.04045 {
                    ((x + 0.055).max(0.0) / 1.055).powf(2.4)
                } else {
                    x / 12.92
                }
            }
            Transfer::Gamma(g) => x.max(0.0).powf(g),
        };
        let lin = DVec3::new(decode(rgb.x), decode(rgb.y), decode(rgb.z));
        match self.matrix {
            Some(m) => m * lin,
            None => lin,
        }
    }
}

impl<'a, 'i> Importer<'a, 'i> {
    pub(super) fn unknown_color_space(&self, at: XNode, cs: &str) -> LoadError {
        self.err(
            at,
            LoadErrorKind::Structure(format!("unknown colour space `{cs}`; supported: {}", COLOR_SPACES.join(", "))),
        )
    }

    /// The conversion from the active colour space to the working space: the `colorspace` of the
    /// first of `own` that has one, else of `el` or its nearest ancestor; `None` when there is
    /// nothing to do.
    pub(super) fn conversion(&self, own: &[XNode<'a, 'i>], el: XNode<'a, 'i>) -> Result<Option<Conversion>, Fail> {
        let found = own
            .iter()
            .find_map(|e| e.attribute("colorspace").map(|c| (*e, c)))
            .or_else(|| el.ancestors().find_map(|a| a.attribute("colorspace").map(|c| (a, c))));
        let Some((at, cs)) = found else { return Ok(None) };
        if cs.is_empty() {
            return Ok(None);
        }
        let (transfer, primaries) = color_space(cs).ok_or_else(|| Fail::Hard(self.unknown_color_space(at, cs)))?;
        let matrix = (primaries != self.working)
            .then(|| self.working.to_rec709().inverse() * primaries.to_rec709())
            .filter(|m| !m.abs_diff_eq(DMat3::IDENTITY, 1e-12));
        if transfer == Transfer::Linear && matrix.is_none() {
            return Ok(None);
        }
        Ok(Some(Conversion { transfer, matrix }))
    }

    /// Appends the nodes converting a colour image's filtered value to the working space.
    pub(super) fn convert_colors(
        &mut self,
        q: &str,
        src: Source,
        ty: ValueType,
        c: &Conversion,
        at: XNode<'a, 'i>,
    ) -> Result<Source, Fail> {
        let add = |imp: &mut Self, suffix: &str, cat: &str, t: ValueType, ins: &[(&str, Source)]| {
            imp.builder
                .add_node(&format!("{q}#colorspace_{suffix}"), cat, t, ins, vec![])
                .map(|id| Source::Node { node: id, channel: None })
                .map_err(|e| imp.hard(at, e.into()))
        };
        let mut s = src.clone();
        if let Transfer::Gamma(g) = c.transfer {
            let m = add(self, "max", "max", ty, &[("in1", s), ("in2", Source::Constant(Value::float(0.0)))])?;
            s = add(self, "gamma", "power", ty, &[("in1", m), ("in2", Source::Constant(Value::float(g as f32)))])?;
        }
        let rgb: Vec<Source> = match c.matrix {
            Some(m) => {
                let mut out = Vec::new();
                for (k, suffix) in ["r", "g", "b"].iter().enumerate() {
                    let row = m.row(k);
                    let mut v = Value::splat(ty, 0.0);
                    v.v[..3].copy_from_slice(&[row.x as f32, row.y as f32, row.z as f32]);
                    out.push(add(
                        self,
                        suffix,
                        "dotproduct",
                        ValueType::Float,
                        &[("in1", s.clone()), ("in2", Source::Constant(v))],
                    )?);
                }
                out
            }
            None if ty == ValueType::Color4 => {
                (0..3).map(|k| self.pick(&s, k, at)).collect::<Result<Vec<_>, Fail>>()?
            }
            None => return Ok(s),
        };
        let mut ins: Vec<(&str, Source)> = ["in1", "in2", "in3"].into_iter().zip(rgb).collect();
        if ty == ValueType::Color4 {
            ins.push(("in4", self.pick(&src, 3, at)?));
        }
        let cat = if ty == ValueType::Color4 { "combine4" } else { "combine3" };
        add(self, "out", cat, ty, &ins)
    }
}

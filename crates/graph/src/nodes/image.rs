//! Image lookups (`image`, `tiledimage`): not implemented yet. The [`Texture`] type is the
//! seam a mip-mapped, footprint-filtered lookup will fill.

use super::{Ctx, NodeDef};
use crate::value::{Filtered, ValueType};

pub(crate) const CATEGORIES: &[&str] = &[];

/// A decoded, mip-mapped image (placeholder).
#[derive(Debug)]
pub struct Texture;

pub(crate) fn definition(_category: &str) -> Option<NodeDef> {
    None
}

pub(crate) fn eval(_t: &Texture, ty: ValueType, _ins: &[Filtered], _ctx: &mut Ctx) -> Filtered {
    Filtered::zero(ty)
}

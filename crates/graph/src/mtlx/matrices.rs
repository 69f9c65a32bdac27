//! Matrices: matrix inputs and nodes folded to constants at load (matrices are uniforms in tessera).

use super::importer::{qualify, Fail, Importer};
use crate::error::LoadErrorKind;
use crate::graph::Source;
use crate::matrix::Matrix;
use crate::value::{Value, ValueType};
use roxmltree::Node as XNode;

impl<'a, 'i> Importer<'a, 'i> {
    /// `extract` of a matrix row and `determinant`: nodes that read a (uniform) matrix and give
    /// a constant. `None` for every other node.
    pub(super) fn matrix_reader(
        &mut self,
        scope: usize,
        q: &str,
        el: XNode<'a, 'i>,
        category: &str,
    ) -> Result<Option<Source>, Fail> {
        if !matches!(category, "extract" | "determinant") {
            return Ok(None);
        }
        let inputs = self.inputs_of(el);
        let Some(inp) = inputs.iter().copied().find(|c| c.attribute("name") == Some("in")) else {
            return Ok(None);
        };
        let Some(n) = self.type_name(inp).and_then(Matrix::size_of_type) else {
            return Ok(None);
        };
        let m = self.matrix_input(scope, inp, n, 0)?.unwrap_or_else(|| Matrix::identity(n));
        if category == "determinant" {
            return Ok(Some(Source::Constant(Value::float(m.determinant() as f32))));
        }
        let index = match inputs.iter().copied().find(|c| c.attribute("name") == Some("index")) {
            Some(i) => self.uniform_value(scope, i, q)?.map_or(0, |v| v.v[0].round() as i64),
            None => 0,
        };
        let ty = if n == 3 { ValueType::Vector3 } else { ValueType::Vector4 };
        if self.value_type(el) != Some(ty) {
            let found = self.type_name(el).unwrap_or("?");
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!(
                    "`{q}`: extract from a matrix{n}{n} gives a {ty} (one row), not a {found}"
                )),
            ));
        }
        let Some(row) = usize::try_from(index).ok().and_then(|i| m.row(i)) else {
            return Err(self.hard(
                el,
                LoadErrorKind::Structure(format!(
                    "`{q}`: index {index} is not a row of a matrix{n}{n} (0 to {})",
                    n - 1
                )),
            ));
        };
        let row: Vec<f32> = row.iter().map(|x| *x as f32).collect();
        Ok(Some(Source::Constant(Value::new(ty, &row))))
    }

    /// The value of a non-matrix input that a matrix computation needs at load: `None` when
    /// omitted; unsupported (naming the input) when it varies over the surface.
    fn uniform_value(&mut self, scope: usize, inp: XNode<'a, 'i>, q: &str) -> Result<Option<Value>, Fail> {
        match self.input_source(scope, inp)? {
            None => Ok(None),
            Some(Source::Constant(v)) => Ok(Some(v)),
            Some(_) => {
                let name = inp.attribute("name").unwrap_or("?");
                let category = inp.parent_element().map_or("?", |p| self.category(p));
                Err(self.unsupported(
                    category,
                    q,
                    format!("input `{name}` varies over the surface, but matrices are uniforms in tessera"),
                    inp,
                ))
            }
        }
    }

    /// The matrix an `<input>` of type matrix33/44 carries, folded at load: its value, or the
    /// matrix node (or interface input) it connects to. `None` when the input is neither set nor
    /// connected (its node's default applies).
    pub(super) fn matrix_input(
        &mut self,
        scope: usize,
        inp: XNode<'a, 'i>,
        n: usize,
        depth: usize,
    ) -> Result<Option<Matrix>, Fail> {
        let port = inp.attribute("name").unwrap_or("?");
        if depth > 256 {
            let q = qualify(&self.scopes[scope].prefix, port);
            return Err(self.hard(inp, LoadErrorKind::Cycle(q)));
        }
        if let Some(target) = inp.attribute("nodename") {
            let Some(el) = self.scopes[scope].nodes.get(target).copied() else {
                let from = qualify(&self.scopes[scope].prefix, port);
                let to = qualify(&self.scopes[scope].prefix, target);
                return Err(self.hard(inp, LoadErrorKind::Dangling { from, to }));
            };
            return self.fold_matrix(scope, el, n, depth + 1).map(Some);
        }
        if let Some(iface) = inp.attribute("interfacename") {
            return match self.interface_binding(scope, iface, inp)? {
                None => Ok(None),
                Some((el, sc)) => self.matrix_input(sc, el, n, depth + 1),
            };
        }
        if inp.attribute("nodegraph").is_some() {
            let q = qualify(&self.scopes[scope].prefix, port);
            return Err(self.unsupported("nodegraph", &q, "a matrix-typed node graph output".into(), inp));
        }
        match inp.attribute("value") {
            None => Ok(None),
            Some(text) => match Matrix::parse(n, text) {
                Some(m) => Ok(Some(m)),
                None => Err(self.hard(
                    inp,
                    LoadErrorKind::MalformedValue {
                        ty: format!("matrix{n}{n} (n² numbers, row by row)"),
                        text: text.into(),
                    },
                )),
            },
        }
    }

    /// Folds a matrix-valued node to its value.
    pub(super) fn fold_matrix(
        &mut self,
        scope: usize,
        el: XNode<'a, 'i>,
        n: usize,
        depth: usize,
    ) -> Result<Matrix, Fail> {
        let category = self.category(el);
        let q = qualify(&self.scopes[scope].prefix, el.attribute("name").unwrap_or("?"));
        let inputs = self.inputs_of(el);
        let find = |name: &str| inputs.iter().copied().find(|c| c.attribute("name") == Some(name));
        let ident = Matrix::identity(n);
        // A matrix operand, or a float broadcast to every entry (the `FA` variants).
        let operand = |me: &mut Self, name: &str, default: Matrix| -> Result<Matrix, Fail> {
            let Some(inp) = find(name) else { return Ok(default) };
            if me.type_name(inp).and_then(Matrix::size_of_type).is_some() {
                return Ok(me.matrix_input(scope, inp, n, depth)?.unwrap_or(default));
            }
            Ok(me.uniform_value(scope, inp, &q)?.map_or(default, |v| Matrix::splat(n, v.v[0] as f64)))
        };
        Ok(match category {
            "constant" => operand(self, "value", ident)?,
            "dot" => operand(self, "in", ident)?,
            "transpose" => operand(self, "in", ident)?.transpose(),
            "invertmatrix" => {
                let m = operand(self, "in", ident)?;
                m.inverse().ok_or_else(|| {
                    self.hard(
                        el,
                        LoadErrorKind::Structure(format!(
                            "`{q}`: cannot invert a singular matrix (determinant {:e})",
                            m.determinant()
                        )),
                    )
                })?
            }
            "add" | "subtract" | "multiply" | "divide" => {
                let a = operand(self, "in1", Matrix::splat(n, 0.0))?;
                let b_is_matrix = find("in2").and_then(|i| self.type_name(i)).and_then(Matrix::size_of_type).is_some();
                let b = operand(
                    self,
                    "in2",
                    if category == "add" || category == "subtract" { Matrix::splat(n, 0.0) } else { ident },
                )?;
                match category {
                    "add" => a.zip(&b, |x, y| x + y),
                    "subtract" => a.zip(&b, |x, y| x - y),
                    "multiply" if b_is_matrix => a.mul(&b),
                    "multiply" => a.zip(&b, |x, y| x * y),
                    _ if b_is_matrix => match b.inverse() {
                        Some(inv) => a.mul(&inv),
                        None => {
                            return Err(self
                                .hard(el, LoadErrorKind::Structure(format!("`{q}`: division by a singular matrix"))))
                        }
                    },
                    _ => a.zip(&b, |x, y| x / y),
                }
            }
            "creatematrix" => {
                let mut m = Matrix::identity(n);
                for r in 0..n {
                    let name = ["in1", "in2", "in3", "in4"][r];
                    let Some(inp) = find(name) else { continue };
                    if let Some(v) = self.uniform_value(scope, inp, &q)? {
                        let k = v.ty.channels();
                        for c in 0..k.min(n) {
                            m.m[r][c] = v.v[c] as f64;
                        }
                        // vector3 rows of a matrix44: (x, y, z, 0), the last row (x, y, z, 1).
                        if n == 4 && k == 3 {
                            m.m[r][3] = if r == 3 { 1.0 } else { 0.0 };
                        }
                    }
                }
                m
            }
            "ifgreater" | "ifgreatereq" | "ifequal" => {
                let v1 = find("value1").map(|i| self.uniform_value(scope, i, &q)).transpose()?.flatten();
                let v2 = find("value2").map(|i| self.uniform_value(scope, i, &q)).transpose()?.flatten();
                let (a, b) = (v1.map_or(1.0, |v| v.v[0]), v2.map_or(0.0, |v| v.v[0]));
                let yes = match category {
                    "ifgreater" => a > b,
                    "ifgreatereq" => a >= b,
                    _ => a == b,
                };
                operand(self, if yes { "in1" } else { "in2" }, Matrix::splat(n, 0.0))?
            }
            _ => {
                return Err(self.unsupported(category, &q, format!("matrix{n}{n}-valued `{category}`"), el));
            }
        })
    }
}

//! Triangle meshes from OBJ and PLY files, and Mitsuba's built-in `rectangle` and `cube`.
//!
//! OBJ goes through the `tobj` crate (`single_index` unifies per-corner `v/vt/vn` indices into
//! unique vertices, `triangulate` fans polygons); we only add line numbers to its errors. PLY
//! goes through `ply-rs-bw` (a maintained fork of `ply-rs`; ASCII and both binary encodings),
//! reading straight into our own vertex/face records.
//!
//! Loaders check structure (indices in range, attribute counts); call
//! [`TriangleMesh::validate`] afterwards for non-finite data and degenerate triangles.

use std::io::{BufRead, BufReader};
use std::path::Path;

use glam::{Vec2, Vec3};
use ply_rs_bw::parser::{ParseError, Parser, Reader};
use ply_rs_bw::ply::{Property, PropertyAccess, PropertyAccessResult};

use crate::error::{Error, Loc, Result};

/// An indexed triangle mesh. `normals` and `uvs`, when present, have one entry per position.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TriangleMesh {
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex shading normals (as stored in the file, not normalised).
    pub normals: Option<Vec<Vec3>>,
    /// Per-vertex texture coordinates.
    pub uvs: Option<Vec<Vec2>>,
    /// Triangles, as indices into the vertex arrays.
    pub indices: Vec<[u32; 3]>,
}

impl TriangleMesh {
    /// Checks the mesh read from `path` and removes degenerate (zero-area) triangles and
    /// triangles that repeat an earlier one (the same three vertices in the same winding order).
    ///
    /// Errors: no triangles, attribute counts that differ from the position count, an index out
    /// of range, a NaN/infinite position, normal or uv, or only degenerate triangles. Returns
    /// warnings (at most one for the removed degenerate triangles and one for the repeats).
    pub fn validate(&mut self, path: &Path) -> Result<Vec<String>> {
        let n = self.positions.len();
        if self.indices.is_empty() {
            return Err(Error::in_file(path, "mesh has no triangles"));
        }
        if let Some(normals) = &self.normals {
            if normals.len() != n {
                return Err(Error::in_file(path, format!("mesh has {} normals for {n} vertices", normals.len())));
            }
        }
        if let Some(uvs) = &self.uvs {
            if uvs.len() != n {
                return Err(Error::in_file(
                    path,
                    format!("mesh has {} texture coordinates for {n} vertices", uvs.len()),
                ));
            }
        }
        for (t, tri) in self.indices.iter().enumerate() {
            if let Some(&bad) = tri.iter().find(|&&i| i as usize >= n) {
                return Err(Error::in_file(
                    path,
                    format!("triangle {t} refers to vertex {bad}, but the mesh has only {n} vertices"),
                ));
            }
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::in_file(path, format!("vertex {i} has a non-finite position {}", self.positions[i])));
        }
        if let Some(normals) = &self.normals {
            if let Some(i) = normals.iter().position(|v| !v.is_finite()) {
                return Err(Error::in_file(path, format!("vertex {i} has a non-finite normal {}", normals[i])));
            }
        }
        if let Some(uvs) = &self.uvs {
            if let Some(i) = uvs.iter().position(|v| !v.is_finite()) {
                return Err(Error::in_file(path, format!("vertex {i} has non-finite texture coordinates {}", uvs[i])));
            }
        }

        let total = self.indices.len();
        let mut first: Option<(usize, [u32; 3])> = None;
        let mut removed = 0usize;
        // Repeated faces draw nothing new, but a few dozen copies of one made the BVH a chain
        // deeper than its traversal walks (found by fuzzing; see `Accel::build`).
        let mut seen = std::collections::HashSet::with_capacity(total);
        let mut first_repeat: Option<(usize, [u32; 3])> = None;
        let mut repeats = 0usize;
        let positions = &self.positions;
        let mut t = 0usize;
        self.indices.retain(|tri| {
            let [a, b, c] = tri.map(|i| positions[i as usize]);
            let degenerate = (b - a).cross(c - a).length_squared() == 0.0;
            if degenerate {
                removed += 1;
                first.get_or_insert((t, *tri));
            }
            // The same triangle whichever corner comes first, as long as the winding is kept.
            let r = (0..3).min_by_key(|&k| tri[k]).unwrap_or(0);
            let repeated = !degenerate && !seen.insert([tri[r], tri[(r + 1) % 3], tri[(r + 2) % 3]]);
            if repeated {
                repeats += 1;
                first_repeat.get_or_insert((t, *tri));
            }
            t += 1;
            !degenerate && !repeated
        });
        let mut warnings = Vec::new();
        if let Some((t, tri)) = first {
            if self.indices.is_empty() {
                return Err(Error::in_file(
                    path,
                    format!("all {total} triangles of the mesh are degenerate (zero area)"),
                ));
            }
            warnings.push(format!(
                "{}: removed {removed} of {total} triangles with zero area; the first is triangle {t} (vertices {}, {}, {})",
                path.display(),
                tri[0],
                tri[1],
                tri[2]
            ));
        }
        if let Some((t, tri)) = first_repeat {
            warnings.push(format!(
                "{}: removed {repeats} of {total} triangles that repeat an earlier one; the first is triangle {t} (vertices {}, {}, {})",
                path.display(),
                tri[0],
                tri[1],
                tri[2]
            ));
        }
        Ok(warnings)
    }
}

/// A `BufRead` over bytes that hands out at most one line per `fill_buf`, so that we know which
/// line `tobj` was reading when it failed.
struct LineReader<'a> {
    data: &'a [u8],
    pos: usize,
    /// Byte offset of the line read last.
    line_start: usize,
}

impl LineReader<'_> {
    /// 1-based number of the line read last.
    fn line(&self) -> u32 {
        1 + self.data[..self.line_start].iter().filter(|&&b| b == b'\n').count() as u32
    }
}

impl std::io::Read for LineReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let avail = self.fill_buf()?;
        let n = avail.len().min(buf.len());
        buf[..n].copy_from_slice(&avail[..n]);
        self.consume(n);
        Ok(n)
    }
}

impl BufRead for LineReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        let rest = &self.data[self.pos..];
        let end = rest.iter().position(|&b| b == b'\n').map_or(rest.len(), |i| i + 1);
        Ok(&rest[..end])
    }

    fn consume(&mut self, amt: usize) {
        if amt > 0 && (self.pos == 0 || self.data[self.pos - 1] == b'\n') {
            self.line_start = self.pos;
        }
        self.pos += amt;
    }
}

/// Finds the first face line with an out-of-range index of one of the kinds `slots` (0:
/// position, 1: texture coordinate, 2: normal), for errors `tobj` reports without a line.
fn locate_bad_face_index(text: &str, slots: &[usize]) -> Option<(u32, String)> {
    let mut counts = [0i64; 3];
    for (ln, line) in text.lines().enumerate() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => counts[0] += 1,
            Some("vt") => counts[1] += 1,
            Some("vn") => counts[2] += 1,
            Some("f") => {
                for corner in words {
                    for &slot in slots {
                        let Some(part) = corner.split('/').nth(slot) else { continue };
                        let Ok(x) = part.parse::<i64>() else { continue };
                        let count = counts[slot];
                        let resolved = if x < 0 { count + x } else { x - 1 };
                        if resolved < 0 || resolved >= count {
                            let kind = ["vertex (v)", "texture coordinate (vt)", "normal (vn)"][slot];
                            return Some((
                                ln as u32 + 1,
                                format!("face refers to {kind} {x}, but only {count} are defined before this line"),
                            ));
                        }
                    }
                }
            }
            _ => {}
        }
    }
    None
}

/// Reads a Wavefront OBJ file: positions, `vt`, `vn`; faces with more than three corners are
/// fan-triangulated; each distinct `v/vt/vn` corner becomes one vertex. All groups/objects are
/// merged; materials are ignored. `flip_tex_coords` maps v to 1 − v (Mitsuba's default for OBJ).
pub fn load_obj(path: &Path, flip_tex_coords: bool) -> Result<TriangleMesh> {
    let bytes = std::fs::read(path).map_err(|e| Error::in_file(path, format!("cannot read OBJ file: {e}")))?;
    // Face indices are checked before `tobj` sees them: it turns an out-of-range one (a relative
    // index before the first element, or a huge one) into an offset that overflows, which panics
    // where overflow checks are on (tests, fuzzing) instead of returning its error. Like `tobj`,
    // vt and vn indices are ignored in a file that defines no vt or vn.
    let text = String::from_utf8_lossy(&bytes);
    let defines = |kw: &str| text.lines().any(|l| l.split_whitespace().next() == Some(kw));
    let slots: Vec<usize> = [(0, true), (1, defines("vt")), (2, defines("vn"))]
        .into_iter()
        .filter_map(|(slot, checked)| checked.then_some(slot))
        .collect();
    if let Some((line, msg)) = locate_bad_face_index(&text, &slots) {
        return Err(Error::at(&Loc::new(std::sync::Arc::new(path.to_path_buf()), line, 0), msg));
    }
    let mut reader = LineReader { data: &bytes, pos: 0, line_start: 0 };
    // tobj's other fields depend on its cargo features, hence the (possibly no-op) update.
    #[allow(clippy::needless_update)]
    let options = tobj::LoadOptions {
        single_index: true,
        triangulate: true,
        ignore_points: true,
        ignore_lines: true,
        ..Default::default()
    };
    let result = tobj::load_obj_buf(&mut reader, &options, |_| Err(tobj::LoadError::OpenFileFailed));
    let models = match result {
        Ok((models, _materials)) => models,
        Err(e) => return Err(obj_error(path, &bytes, &reader, e)),
    };

    let mut mesh = TriangleMesh::default();
    let (mut with_uv, mut with_n) = (0usize, 0usize);
    let mut normals = Vec::new();
    let mut uvs = Vec::new();
    for model in &models {
        let m = &model.mesh;
        let base = mesh.positions.len();
        let nv = m.positions.len() / 3;
        let (has_uv, has_n) = (!m.texcoords.is_empty(), !m.normals.is_empty());
        if (has_uv && m.texcoords.len() != 2 * nv) || (has_n && m.normals.len() != 3 * nv) {
            return Err(Error::in_file(
                path,
                format!(
                    "in object/group '{}', some face corners have texture coordinates or normals (v/vt/vn) and others do not; give all corners the same form",
                    model.name
                ),
            ));
        }
        mesh.positions.extend(m.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        if has_uv {
            with_uv += 1;
            uvs.extend(
                m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], if flip_tex_coords { 1.0 - t[1] } else { t[1] })),
            );
        }
        if has_n {
            with_n += 1;
            normals.extend(m.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])));
        }
        let base = u32::try_from(base).map_err(|_| Error::in_file(path, "mesh has more than 2^32 vertices"))?;
        mesh.indices.extend(m.indices.chunks_exact(3).map(|t| [t[0] + base, t[1] + base, t[2] + base]));
    }
    let groups = models.len();
    if (with_uv != 0 && with_uv != groups) || (with_n != 0 && with_n != groups) {
        return Err(Error::in_file(path, "some objects/groups have texture coordinates or normals and others do not"));
    }
    if with_uv > 0 {
        mesh.uvs = Some(uvs);
    }
    if with_n > 0 {
        mesh.normals = Some(normals);
    }
    Ok(mesh)
}

/// Turns a `tobj` error into ours, with the offending line where we can find it.
fn obj_error(path: &Path, bytes: &[u8], reader: &LineReader, e: tobj::LoadError) -> Error {
    use tobj::LoadError as E;
    let slot = match e {
        E::FaceVertexOutOfBounds | E::FaceColorOutOfBounds => Some(0),
        E::FaceTexCoordOutOfBounds => Some(1),
        E::FaceNormalOutOfBounds => Some(2),
        _ => None,
    };
    let file = std::sync::Arc::new(path.to_path_buf());
    if let Some(slot) = slot {
        let text = String::from_utf8_lossy(bytes);
        return match locate_bad_face_index(&text, &[slot]) {
            Some((line, msg)) => Error::at(&Loc::new(file, line, 0), msg),
            None => Error::in_file(path, format!("invalid OBJ file: {e}")),
        };
    }
    if matches!(e, E::InvalidPolygon) {
        return Error::in_file(path, format!("invalid OBJ file: {e}"));
    }
    let line = reader.line();
    let text = bytes[reader.line_start..]
        .split(|&b| b == b'\n')
        .next()
        .map(|l| String::from_utf8_lossy(l).trim().to_string())
        .unwrap_or_default();
    let what = if matches!(e, E::ReadError) { "not valid UTF-8 text".to_string() } else { e.to_string() };
    Error::at(&Loc::new(file, line, 0), format!("invalid OBJ line \"{text}\": {what}"))
}

/// A PLY vertex as we keep it.
#[derive(Default)]
struct PlyVertex {
    p: [f32; 3],
    n: [f32; 3],
    uv: [f32; 2],
}

impl PropertyAccess for PlyVertex {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        let Some(v) = property.to_f32_lossy() else { return PropertyAccessResult::Ignored };
        let slot = match name {
            "x" => &mut self.p[0],
            "y" => &mut self.p[1],
            "z" => &mut self.p[2],
            "nx" => &mut self.n[0],
            "ny" => &mut self.n[1],
            "nz" => &mut self.n[2],
            "u" | "s" | "texture_u" | "texture_s" => &mut self.uv[0],
            "v" | "t" | "texture_v" | "texture_t" => &mut self.uv[1],
            _ => return PropertyAccessResult::Ignored,
        };
        *slot = v;
        PropertyAccessResult::Set
    }
}

/// A PLY face: its vertex indices (negative ones kept so we can report them).
#[derive(Default)]
struct PlyFace {
    indices: Vec<i64>,
}

impl PropertyAccess for PlyFace {
    fn new() -> Self {
        Self::default()
    }

    fn set_property(&mut self, name: &str, property: Property) -> PropertyAccessResult {
        if name != "vertex_indices" && name != "vertex_index" {
            return PropertyAccessResult::Ignored;
        }
        self.indices = match property {
            Property::ListChar(l) => l.into_iter().map(i64::from).collect(),
            Property::ListUChar(l) => l.into_iter().map(i64::from).collect(),
            Property::ListShort(l) => l.into_iter().map(i64::from).collect(),
            Property::ListUShort(l) => l.into_iter().map(i64::from).collect(),
            Property::ListInt(l) => l.into_iter().map(i64::from).collect(),
            Property::ListUInt(l) => l.into_iter().map(i64::from).collect(),
            _ => return PropertyAccessResult::UnsupportedType,
        };
        PropertyAccessResult::Set
    }
}

/// An element we do not use (read and dropped).
struct PlySkip;

impl PropertyAccess for PlySkip {
    fn new() -> Self {
        PlySkip
    }
}

fn ply_error(path: &Path, e: ParseError) -> Error {
    let full = e.to_string();
    // The crate writes "Line N: message\n\tString: <the offending line>\n\tError: ...": keep the
    // message alone (the file's own text is never echoed: it may be anything, even a secret)
    // with our own location, and at most 200 characters of it.
    let first = full.lines().next().unwrap_or("");
    let first = match e.line() {
        Some(l) => first.strip_prefix(&format!("Line {l}: ")).unwrap_or(first),
        None => first,
    };
    let cut = (0..=first.len().min(200)).rev().find(|&i| first.is_char_boundary(i)).unwrap_or(0);
    let msg = format!("invalid PLY file: {}{}", &first[..cut], if cut < first.len() { "…" } else { "" });
    match e.line() {
        Some(line) => Error::at(&Loc::new(std::sync::Arc::new(path.to_path_buf()), line as u32, 0), msg),
        None => Error::in_file(path, msg),
    }
}

/// Reads a PLY file (ASCII, binary little- or big-endian): vertex `x y z`, optional
/// `nx ny nz` and texture coordinates (`u v`, `s t`, `texture_u texture_v` or
/// `texture_s texture_t`), faces as `vertex_indices` (or `vertex_index`) lists of any integer
/// type; polygons are fan-triangulated. Other elements and properties are skipped.
/// `flip_tex_coords` maps v to 1 − v (Mitsuba's default for PLY is not to).
pub fn load_ply(path: &Path, flip_tex_coords: bool) -> Result<TriangleMesh> {
    let file = std::fs::File::open(path).map_err(|e| Error::in_file(path, format!("cannot read PLY file: {e}")))?;
    let mut reader = Reader::new(BufReader::new(file));
    let header = Parser::<PlySkip>::new().read_header(&mut reader).map_err(|e| ply_error(path, e))?;

    let vertex_def =
        header.elements.get("vertex").ok_or_else(|| Error::in_file(path, "PLY file has no 'vertex' element"))?;
    let has = |names: &[&str]| names.iter().all(|n| vertex_def.properties.contains_key(*n));
    if !has(&["x", "y", "z"]) {
        return Err(Error::in_file(path, "PLY 'vertex' element lacks x, y, z properties"));
    }
    let has_normals = has(&["nx", "ny", "nz"]);
    let has_uv =
        [["u", "v"], ["s", "t"], ["texture_u", "texture_v"], ["texture_s", "texture_t"]].iter().any(|pair| has(pair));
    if let Some(face) = header.elements.get("face") {
        if !face.properties.contains_key("vertex_indices") && !face.properties.contains_key("vertex_index") {
            return Err(Error::in_file(path, "PLY 'face' element lacks a 'vertex_indices' list"));
        }
    }

    let mut vertices: Vec<PlyVertex> = Vec::new();
    let mut faces: Vec<PlyFace> = Vec::new();
    for (_, element) in &header.elements {
        match element.name.as_str() {
            "vertex" => {
                vertices = Parser::<PlyVertex>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| ply_error(path, e))?;
            }
            "face" => {
                faces = Parser::<PlyFace>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| ply_error(path, e))?;
            }
            _ => {
                Parser::<PlySkip>::new()
                    .read_payload_for_element(&mut reader, element, &header)
                    .map_err(|e| ply_error(path, e))?;
            }
        }
    }

    let n = vertices.len() as i64;
    let mut indices = Vec::with_capacity(faces.len());
    for (f, face) in faces.iter().enumerate() {
        if face.indices.len() < 3 {
            return Err(Error::in_file(
                path,
                format!("face {f} has {} vertex indices (at least 3 needed)", face.indices.len()),
            ));
        }
        if let Some(&bad) = face.indices.iter().find(|&&i| i < 0 || i >= n) {
            return Err(Error::in_file(
                path,
                format!("face {f} refers to vertex {bad}, but the file has only {n} vertices"),
            ));
        }
        let idx = |k: usize| face.indices[k] as u32;
        for k in 1..face.indices.len() - 1 {
            indices.push([idx(0), idx(k), idx(k + 1)]);
        }
    }

    Ok(TriangleMesh {
        positions: vertices.iter().map(|v| Vec3::from(v.p)).collect(),
        normals: has_normals.then(|| vertices.iter().map(|v| Vec3::from(v.n)).collect()),
        uvs: has_uv.then(|| {
            vertices.iter().map(|v| Vec2::new(v.uv[0], if flip_tex_coords { 1.0 - v.uv[1] } else { v.uv[1] })).collect()
        }),
        indices,
    })
}

/// Mitsuba's `rectangle`: [−1, 1]² in the xy plane, normal +z, uv = ((x+1)/2, (y+1)/2).
pub fn rectangle_mesh() -> TriangleMesh {
    TriangleMesh {
        positions: vec![
            Vec3::new(-1.0, -1.0, 0.0),
            Vec3::new(1.0, -1.0, 0.0),
            Vec3::new(1.0, 1.0, 0.0),
            Vec3::new(-1.0, 1.0, 0.0),
        ],
        normals: None,
        uvs: Some(vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)]),
        indices: vec![[0, 1, 2], [0, 2, 3]],
    }
}

/// Mitsuba's `cube`: [−1, 1]³ with flat faces, outward normals.
pub fn cube_mesh() -> TriangleMesh {
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut indices = Vec::new();
    for axis in 0..3 {
        for sign in [-1.0f32, 1.0] {
            let n = Vec3::from_array(std::array::from_fn(|i| if i == axis { sign } else { 0.0 }));
            // Two tangents so that t1 × t2 = n.
            let t1 = Vec3::from_array(std::array::from_fn(|i| if i == (axis + 1) % 3 { 1.0 } else { 0.0 }));
            let t2 = n.cross(t1);
            let base = positions.len() as u32;
            for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
                positions.push(n + t1 * a + t2 * b);
                uvs.push(Vec2::new((a + 1.0) * 0.5, (b + 1.0) * 0.5));
            }
            indices.push([base, base + 1, base + 2]);
            indices.push([base, base + 2, base + 3]);
        }
    }
    TriangleMesh { positions, normals: None, uvs: Some(uvs), indices }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    /// A file written for one test, in a folder of its own that goes when the test is done.
    struct TempFile(PathBuf);

    impl std::ops::Deref for TempFile {
        type Target = Path;
        fn deref(&self) -> &Path {
            &self.0
        }
    }

    impl Drop for TempFile {
        fn drop(&mut self) {
            if let Some(dir) = self.0.parent() {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
    }

    /// Writes `contents` as `name` (every test names its own file) in a folder of its own.
    fn temp_file(name: &str, contents: &[u8]) -> TempFile {
        let dir = std::env::temp_dir().join(format!("tessera_mesh_tests_{}_{name}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join(name);
        std::fs::write(&p, contents).unwrap();
        TempFile(p)
    }

    /// The triangle corners as positions, to compare meshes independent of vertex order.
    fn corners(m: &TriangleMesh) -> Vec<[Vec3; 3]> {
        m.indices.iter().map(|t| t.map(|i| m.positions[i as usize])).collect()
    }

    #[test]
    fn mesh_obj_quads_negative_indices_and_attributes() {
        let obj = b"# a quad and a pentagon-ish polygon\n\
            v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n\
            vt 0 0\nvt 1 0\nvt 1 0.25\nvt 0 1\n\
            vn 0 0 1\n\
            f 1/1/1 2/2/1 3/3/1 4/4/1\n\
            o second\n\
            v 0 0 1\nv 1 0 1\nv 1 1 1\nv 0.5 1.5 1\nv 0 1 1\n\
            f -5/1/1 -4/2/1 -3/3/1 -2/4/1 -1/1/1\n";
        let p = temp_file("quads.obj", obj);
        let mut m = load_obj(&p, false).unwrap();
        assert_eq!(m.indices.len(), 2 + 3);
        let c = corners(&m);
        let v = |x, y, z| Vec3::new(x, y, z);
        // Fan triangulation around the first corner.
        assert_eq!(c[0], [v(0., 0., 0.), v(1., 0., 0.), v(1., 1., 0.)]);
        assert_eq!(c[1], [v(0., 0., 0.), v(1., 1., 0.), v(0., 1., 0.)]);
        assert_eq!(c[2], [v(0., 0., 1.), v(1., 0., 1.), v(1., 1., 1.)]);
        assert_eq!(c[4], [v(0., 0., 1.), v(0.5, 1.5, 1.), v(0., 1., 1.)]);
        let uvs = m.uvs.clone().unwrap();
        let normals = m.normals.clone().unwrap();
        assert_eq!(uvs.len(), m.positions.len());
        assert_eq!(normals.len(), m.positions.len());
        assert!(normals.iter().all(|n| *n == Vec3::Z));
        // Corner 3 of the quad has vt (1, 0.25).
        assert_eq!(uvs[m.indices[0][2] as usize], Vec2::new(1.0, 0.25));
        assert!(m.validate(&p).unwrap().is_empty());

        // flip_tex_coords: v -> 1 - v.
        let f = load_obj(&p, true).unwrap();
        assert_eq!(f.uvs.unwrap()[f.indices[0][2] as usize], Vec2::new(1.0, 0.75));
    }

    #[test]
    fn mesh_obj_unique_vertices_per_corner() {
        // Same position with two different normals -> two vertices.
        let obj = b"v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nvn 0 0 1\nvn 0 1 0\n\
            f 1//1 2//1 3//1\nf 1//2 4//2 2//2\n";
        let p = temp_file("corners.obj", obj);
        let m = load_obj(&p, true).unwrap();
        assert_eq!(m.positions.len(), 6);
        assert!(m.uvs.is_none());
        assert_eq!(m.normals.unwrap().len(), 6);
    }

    #[test]
    fn mesh_obj_errors_name_file_and_line() {
        let p = temp_file("bad_index.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\n\nf 1 2 3\nf 1 2 7\n");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("bad_index.obj:6") && e.contains("vertex (v) 7"), "{e}");
        let p = temp_file("bad_neg.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("bad_neg.obj:4") && e.contains("-4"), "{e}");
        let p = temp_file("bad_num.obj", b"v 0 0 0\nv 1 zero 0\nv 0 1 0\nf 1 2 3\n");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("bad_num.obj:2") && e.contains("v 1 zero 0"), "{e}");
        let p = temp_file("bad_vt.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("bad_vt.obj:5") && e.contains("texture coordinate"), "{e}");
        let e = load_obj(Path::new("/nonexistent/x.obj"), true).unwrap_err().to_string();
        assert!(e.contains("/nonexistent/x.obj") && e.contains("cannot read"), "{e}");
    }

    /// Found by fuzzing (fuzz/fuzz_targets/obj.rs): a relative texture-coordinate index before the
    /// first one (-3 of 1) overflowed in `tobj`'s offset arithmetic, a panic where overflow
    /// checks are on; so did a huge normal index. Both are now errors naming the line.
    #[test]
    fn mesh_obj_fuzz_out_of_range_relative_indices_are_errors() {
        let p = temp_file("fuzz_vt.obj", b"v 0 0 0\nv 1 0 0\nvt 1 1\nf 2/-3/-2 2 2");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("fuzz_vt.obj:4") && e.contains("texture coordinate (vt) -3"), "{e}");
        let p = temp_file("fuzz_vn.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//1 2//1 3//7000000000000000000\n");
        let e = load_obj(&p, true).unwrap_err().to_string();
        assert!(e.contains("fuzz_vn.obj:5") && e.contains("normal (vn) 7000000000000000000"), "{e}");
        // Without any vt (vn), their indices are ignored, as before.
        let p = temp_file("no_vt.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/9 2/9 3/9\n");
        assert_eq!(load_obj(&p, true).unwrap().indices.len(), 1);
    }

    #[test]
    fn mesh_nan_and_empty_errors() {
        let p = temp_file("nan.obj", b"v 0 0 0\nv nan 0 0\nv 0 1 0\nf 1 2 3\n");
        let mut m = load_obj(&p, true).unwrap();
        let e = m.validate(&p).unwrap_err().to_string();
        assert!(e.contains("nan.obj") && e.contains("non-finite position"), "{e}");
        let p = temp_file("nan_n.obj", b"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 inf 1\nf 1//1 2//1 3//1\n");
        let mut m = load_obj(&p, true).unwrap();
        let e = m.validate(&p).unwrap_err().to_string();
        assert!(e.contains("non-finite normal"), "{e}");
        let p = temp_file("empty.obj", b"# nothing\nv 0 0 0\n");
        let mut m = load_obj(&p, true).unwrap();
        let e = m.validate(&p).unwrap_err().to_string();
        assert!(e.contains("empty.obj") && e.contains("no triangles"), "{e}");
    }

    /// Found by fuzzing (fuzz/fuzz_targets/obj.rs): 42 copies of one quad made the BVH a chain
    /// deeper than its traversal walks (an assertion in obvhs's debug builds; in release builds
    /// rays skipped nodes). A triangle that repeats an earlier one, whichever corner it starts
    /// from, is removed with a warning; the same corners wound the other way are kept.
    #[test]
    fn mesh_validate_removes_repeated_triangles() {
        let p = PathBuf::from("mem.obj");
        let mut m = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            normals: None,
            uvs: None,
            indices: [vec![[0, 1, 2]; 40], vec![[1, 2, 0], [2, 0, 1], [0, 2, 1], [1, 3, 2]]].concat(),
        };
        let w = m.validate(&p).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 1], [1, 3, 2]]);
        assert_eq!(w.len(), 1, "{w:?}");
        assert!(w[0].contains("mem.obj") && w[0].contains("removed 41 of 44") && w[0].contains("triangle 1"), "{w:?}");
    }

    #[test]
    fn mesh_validate_degenerate_and_range() {
        let p = PathBuf::from("mem.obj");
        let mut m = TriangleMesh {
            positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::new(2.0, 0.0, 0.0)],
            normals: None,
            uvs: None,
            indices: vec![[0, 1, 2], [0, 1, 3], [2, 2, 1], [0, 2, 1]],
        };
        let w = m.validate(&p).unwrap();
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 1]]);
        assert_eq!(w.len(), 1);
        assert!(w[0].contains("mem.obj") && w[0].contains("removed 2 of 4") && w[0].contains("triangle 1"), "{w:?}");
        let mut all_bad = TriangleMesh { indices: vec![[0, 1, 3]], ..m.clone() };
        let e = all_bad.validate(&p).unwrap_err().to_string();
        assert!(e.contains("degenerate"), "{e}");
        let mut out = TriangleMesh { indices: vec![[0, 1, 4]], ..m.clone() };
        let e = out.validate(&p).unwrap_err().to_string();
        assert!(e.contains("mem.obj") && e.contains("vertex 4") && e.contains("only 4 vertices"), "{e}");
        let mut short = TriangleMesh { uvs: Some(vec![Vec2::ZERO]), ..m.clone() };
        assert!(short.validate(&p).unwrap_err().to_string().contains("1 texture coordinates for 4 vertices"));
        let mut nan_uv = TriangleMesh { uvs: Some(vec![Vec2::new(0.0, f32::NAN); 4]), ..m };
        assert!(nan_uv.validate(&p).unwrap_err().to_string().contains("non-finite texture"));
    }

    const PLY_HEADER_TAIL: &str = "element vertex 5\n\
        property float x\nproperty float y\nproperty float z\n\
        property float nx\nproperty float ny\nproperty float nz\n\
        property float u\nproperty float v\n\
        element edge 1\nproperty int vertex1\nproperty int vertex2\n\
        element face 2\nproperty list uchar int vertex_indices\n\
        end_header\n";

    fn ply_vertices() -> Vec<[f32; 8]> {
        vec![
            [0., 0., 0., 0., 0., 1., 0., 0.],
            [1., 0., 0., 0., 0., 1., 1., 0.],
            [1., 1., 0., 0., 0., 1., 1., 0.25],
            [0., 1., 0., 0., 0., 1., 0., 1.],
            [0., 0., 1., 0., 0., 1., 0., 0.],
        ]
    }

    fn check_ply_mesh(m: &TriangleMesh, flipped: bool) {
        assert_eq!(m.positions.len(), 5);
        assert_eq!(m.indices, vec![[0, 1, 2], [0, 2, 3], [0, 1, 4]]);
        assert_eq!(m.positions[2], Vec3::new(1.0, 1.0, 0.0));
        assert!(m.normals.as_ref().unwrap().iter().all(|n| *n == Vec3::Z));
        let v = m.uvs.as_ref().unwrap()[2].y;
        assert_eq!(v, if flipped { 0.75 } else { 0.25 });
    }

    #[test]
    fn mesh_ply_ascii() {
        let mut s = format!("ply\nformat ascii 1.0\ncomment test\n{PLY_HEADER_TAIL}");
        for v in ply_vertices() {
            let t: Vec<String> = v.iter().map(|x| x.to_string()).collect();
            s += &(t.join(" ") + "\n");
        }
        s += "0 1\n4 0 1 2 3\n3 0 1 4\n";
        let p = temp_file("ascii.ply", s.as_bytes());
        let mut m = load_ply(&p, false).unwrap();
        check_ply_mesh(&m, false);
        assert!(m.validate(&p).unwrap().is_empty());
        check_ply_mesh(&load_ply(&p, true).unwrap(), true);

        // A face index out of range.
        let bad = s.replace("3 0 1 4\n", "3 0 1 9\n");
        let p = temp_file("bad.ply", bad.as_bytes());
        let e = load_ply(&p, false).unwrap_err().to_string();
        assert!(e.contains("bad.ply") && e.contains("vertex 9") && e.contains("only 5"), "{e}");
        // A malformed number: the crate's line number comes through.
        let bad = s.replacen("1 0 0 0 0 1 1 0\n", "1 zero 0 0 0 1 1 0\n", 1);
        let p = temp_file("badnum.ply", bad.as_bytes());
        let e = load_ply(&p, false).unwrap_err().to_string();
        assert!(e.contains("badnum.ply:") && e.contains("invalid PLY"), "{e}");
        // Not a PLY at all: the message names the file and never echoes its content.
        let p = temp_file("junk.ply", b"SECRET_TOKEN=hunter2\n");
        let e = load_ply(&p, false).unwrap_err().to_string();
        assert!(e.contains("junk.ply") && e.contains("magic number"), "{e}");
        assert!(!e.contains("SECRET") && !e.contains("hunter2"), "{e}");
    }

    fn binary_ply(big_endian: bool) -> Vec<u8> {
        let fmt = if big_endian { "binary_big_endian" } else { "binary_little_endian" };
        let mut out = format!("ply\nformat {fmt} 1.0\n{PLY_HEADER_TAIL}").into_bytes();
        let f = |out: &mut Vec<u8>, x: f32| {
            out.extend_from_slice(&if big_endian { x.to_be_bytes() } else { x.to_le_bytes() })
        };
        let i = |out: &mut Vec<u8>, x: i32| {
            out.extend_from_slice(&if big_endian { x.to_be_bytes() } else { x.to_le_bytes() })
        };
        for v in ply_vertices() {
            for x in v {
                f(&mut out, x);
            }
        }
        i(&mut out, 0);
        i(&mut out, 1);
        out.push(4);
        for k in [0, 1, 2, 3] {
            i(&mut out, k);
        }
        out.push(3);
        for k in [0, 1, 4] {
            i(&mut out, k);
        }
        out
    }

    #[test]
    fn mesh_ply_binary() {
        for big in [false, true] {
            let p = temp_file(if big { "be.ply" } else { "le.ply" }, &binary_ply(big));
            let m = load_ply(&p, false).unwrap();
            check_ply_mesh(&m, false);
        }
        // Truncated payload -> error naming the file.
        let mut b = binary_ply(false);
        b.truncate(b.len() - 6);
        let p = temp_file("short.ply", &b);
        let e = load_ply(&p, false).unwrap_err().to_string();
        assert!(e.contains("short.ply"), "{e}");
    }

    #[test]
    fn mesh_ply_texture_names_and_no_optional_attributes() {
        let s = "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
            property double z\nproperty float texture_s\nproperty float texture_t\n\
            element face 1\nproperty list uchar uint vertex_index\nend_header\n\
            0 0 0 0 0\n1 0 0 1 0\n0 1 0 0 1\n3 0 1 2\n";
        let p = temp_file("st.ply", s.as_bytes());
        let m = load_ply(&p, true).unwrap();
        assert!(m.normals.is_none());
        assert_eq!(m.uvs.unwrap(), vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 0.0)]);
        let s = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
            property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n\
            0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
        let p = temp_file("plain.ply", s.as_bytes());
        let m = load_ply(&p, false).unwrap();
        assert!(m.normals.is_none() && m.uvs.is_none());
        assert_eq!(m.indices, vec![[0, 1, 2]]);
    }

    #[test]
    fn mesh_reference_objs_load() {
        let dir = Path::new("/work/shared/refs/scenes/meshes");
        for (name, tris) in [("torus.obj", 2304usize), ("ribbon.obj", 640)] {
            let p = dir.join(name);
            if !p.exists() {
                eprintln!("skipping {} (not present)", p.display());
                continue;
            }
            let mut m = load_obj(&p, true).unwrap();
            let warnings = m.validate(&p).unwrap();
            assert!(warnings.is_empty(), "{warnings:?}");
            assert_eq!(m.indices.len(), tris, "{name}");
            let nv = m.positions.len();
            assert!(nv > 300 && nv <= 3 * tris, "{name}: {nv} vertices");
            let uvs = m.uvs.as_ref().unwrap();
            let normals = m.normals.as_ref().unwrap();
            assert!(uvs.iter().all(|t| (0.0..=1.0).contains(&t.x) && (0.0..=1.0).contains(&t.y)));
            assert!(normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-3), "{name}: unit normals");
            assert!(m.positions.iter().all(|p| p.is_finite() && p.length() < 2.0));
        }
    }
}

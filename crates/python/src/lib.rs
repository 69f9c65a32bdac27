//! `tessera._tessera`, the native module of the `tessera` Python package (`python/tessera`).
//!
//! It is a thin layer over `tessera::api`: renders take `tessera render`'s flags (the Python
//! wrapper spells them from keyword arguments), so a render from Python is the command's, bit
//! for bit. Images reach NumPy without a copy: the render's pixel buffer becomes the array's
//! memory. Errors are `tessera.TesseraError` with tessera's own message (file and line where it
//! knows them). The interpreter lock is released while rendering and baking.

use numpy::ndarray::{Array3, ShapeBuilder};
use numpy::{PyArray3, PyReadonlyArray3, PyUntypedArrayMethods};
use pyo3::exceptions::PyException;
use pyo3::prelude::*;
use std::path::PathBuf;
use tessera::api::LoadedScene;

pyo3::create_exception!(_tessera, TesseraError, PyException, "An error tessera reports: bad input, a failed render.");

fn error(e: anyhow::Error) -> PyErr {
    TesseraError::new_err(format!("{e:#}"))
}

/// A loaded scene (`tessera.load`).
#[pyclass(frozen, module = "tessera._tessera")]
struct Scene {
    loaded: LoadedScene,
}

/// The render's pixels as a height × width × 3 float32 array over the same memory.
fn image_array<'py>(py: Python<'py>, image: render::film::Image) -> PyResult<Bound<'py, PyArray3<f32>>> {
    const _: () = assert!(std::mem::size_of::<render::math::Spectrum>() == 12);
    const _: () = assert!(std::mem::align_of::<render::math::Spectrum>() == std::mem::align_of::<f32>());
    let (w, h) = (image.width as usize, image.height as usize);
    let mut pixels = std::mem::ManuallyDrop::new(image.pixels);
    let (ptr, len, cap) = (pixels.as_mut_ptr(), pixels.len(), pixels.capacity());
    // SAFETY: a Spectrum (glam's Vec3) is `#[repr(C)]` of three f32 with f32's alignment (checked
    // above), so the buffer of `cap` pixels is a buffer of `3 cap` floats with the same layout.
    let floats = unsafe { Vec::from_raw_parts(ptr.cast::<f32>(), 3 * len, 3 * cap) };
    let array = Array3::from_shape_vec((h, w, 3).strides((3 * w, 3, 1)), floats)
        .map_err(|e| TesseraError::new_err(format!("image of {w} × {h}: {e}")))?;
    Ok(PyArray3::from_owned_array(py, array))
}

#[pymethods]
impl Scene {
    /// Image width in pixels.
    #[getter]
    fn width(&self) -> u32 {
        self.loaded.scene().camera.width
    }

    /// Image height in pixels.
    #[getter]
    fn height(&self) -> u32 {
        self.loaded.scene().camera.height
    }

    /// Samples per pixel the scene asks for.
    #[getter]
    fn spp(&self) -> u32 {
        self.loaded.scene().spp
    }

    /// The seed the scene's sampler asks for.
    #[getter]
    fn seed(&self) -> u64 {
        self.loaded.scene().seed
    }

    /// The scene file (`None` for the embedded demo scene).
    #[getter]
    fn path(&self) -> Option<PathBuf> {
        self.loaded.path().map(PathBuf::from)
    }

    /// The `-D` defines it was loaded with.
    #[getter]
    fn defines(&self) -> Vec<(String, String)> {
        self.loaded.defines().to_vec()
    }

    /// Every file the scene was built from, the scene file first.
    #[getter]
    fn files(&self) -> Vec<PathBuf> {
        self.loaded.files().to_vec()
    }

    /// Profiles and plans as `--strategy auto` would for a render with these flags; returns
    /// the plan file's JSON.
    fn plan(&self, py: Python<'_>, options: Vec<String>) -> PyResult<String> {
        py.detach(|| self.loaded.plan(&options)).map_err(error)
    }

    /// Renders with `tessera render`'s flags; returns the image and the stats as JSON.
    fn render<'py>(&self, py: Python<'py>, options: Vec<String>) -> PyResult<(Bound<'py, PyArray3<f32>>, String)> {
        let (out, stats) = py.detach(|| self.loaded.render(&options)).map_err(error)?;
        let json = serde_json::to_string(&stats).map_err(|e| TesseraError::new_err(e.to_string()))?;
        Ok((image_array(py, out.image)?, json))
    }

    /// One camera path's footprints as JSON (`tessera.footprint/1`).
    fn footprint(
        &self,
        py: Python<'_>,
        x: u32,
        y: u32,
        seed: Option<u64>,
        estimator: &str,
        density: f64,
    ) -> PyResult<String> {
        py.detach(|| self.loaded.footprint(x, y, seed, estimator, density)).map_err(error)
    }

    fn __repr__(&self) -> String {
        let s = self.loaded.scene();
        let name = self.loaded.path().map_or("<embedded default scene>".into(), |p| p.display().to_string());
        format!("tessera.Scene('{name}', {}x{}, {} spp)", s.camera.width, s.camera.height, s.spp)
    }
}

/// Loads a scene file (`None`: the embedded demo scene) with `-D` defines.
#[pyfunction]
#[pyo3(signature = (path, defines))]
fn load(py: Python<'_>, path: Option<PathBuf>, defines: Vec<(String, String)>) -> PyResult<Scene> {
    let loaded = py.detach(|| LoadedScene::load(path.as_deref(), &defines)).map_err(error)?;
    Ok(Scene { loaded })
}

/// Bakes a MaterialX document's element with `tessera bake`'s flags (not `--out`); returns the
/// texels as a rows × columns × channels float32 array and the channel names.
#[pyfunction]
fn bake<'py>(
    py: Python<'py>,
    document: PathBuf,
    options: Vec<String>,
) -> PyResult<(Bound<'py, PyArray3<f32>>, Vec<&'static str>)> {
    let (image, names) = py.detach(|| tessera::api::bake(&document, &options)).map_err(error)?;
    let (w, h, c) = (image.width as usize, image.height as usize, names.len());
    let array = Array3::from_shape_vec((h, w, c), image.data)
        .map_err(|e| TesseraError::new_err(format!("bake of {w} × {h} × {c}: {e}")))?;
    Ok((PyArray3::from_owned_array(py, array), names))
}

/// Merges pass files as `tessera merge` does; returns the image and the summed counts as JSON.
#[pyfunction]
fn merge<'py>(py: Python<'py>, passes: Vec<PathBuf>) -> PyResult<(Bound<'py, PyArray3<f32>>, String)> {
    let merged = py.detach(|| tessera::api::merge(&passes)).map_err(error)?;
    let counts = serde_json::to_string(&merged.counts).map_err(|e| TesseraError::new_err(e.to_string()))?;
    Ok((image_array(py, merged.image)?, counts))
}

/// Writes a height × width × 3 float32 image (linear RGB) as tessera writes renders: `.exr`
/// (float32) or `.png` (sRGB, 8-bit), through a temporary file renamed into place.
#[pyfunction]
fn save_image(py: Python<'_>, image: PyReadonlyArray3<'_, f32>, path: PathBuf) -> PyResult<()> {
    let shape = image.shape().to_vec();
    let [h, w, 3] = shape[..] else {
        return Err(TesseraError::new_err(format!("an image is height × width × 3, got shape {shape:?}")));
    };
    let a = image.as_array();
    let pixels: Vec<render::math::Spectrum> = a
        .outer_iter()
        .flat_map(|row| row.outer_iter().map(|p| render::math::Spectrum::new(p[0], p[1], p[2])).collect::<Vec<_>>())
        .collect();
    let img = render::film::Image { width: w as u32, height: h as u32, pixels };
    py.detach(|| img.save(&path)).map_err(|e| TesseraError::new_err(e.to_string()))
}

#[pymodule]
fn _tessera(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Scene>()?;
    m.add_function(wrap_pyfunction!(load, m)?)?;
    m.add_function(wrap_pyfunction!(bake, m)?)?;
    m.add_function(wrap_pyfunction!(merge, m)?)?;
    m.add_function(wrap_pyfunction!(save_image, m)?)?;
    m.add("TesseraError", m.py().get_type::<TesseraError>())?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}

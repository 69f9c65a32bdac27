//! Helpers shared by the fuzz targets: the readers under test take file paths (as the renderer
//! calls them), so each input is written to a file in a per-process scratch folder first, and
//! scenes get a folder of tiny, valid assets to refer to.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// This process's scratch folder (in /dev/shm when there is one: inputs are written there on
/// every execution), created on first use and holding the assets of [`write_assets`].
pub fn scratch_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let shm = Path::new("/dev/shm");
        let root = if shm.is_dir() { shm.to_path_buf() } else { std::env::temp_dir() };
        let dir = root.join(format!("tessera-fuzz-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("create the fuzz scratch folder");
        write_assets(&dir);
        dir
    })
}

/// Writes `data` to `input.<ext>` in the scratch folder and returns its path.
pub fn input_file(ext: &str, data: &[u8]) -> PathBuf {
    let path = scratch_dir().join(format!("input.{ext}"));
    std::fs::write(&path, data).expect("write the fuzz input file");
    path
}

/// A quad with texture coordinates and normals, for scenes that name an OBJ file.
pub const QUAD_OBJ: &str = "v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\n\
vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\nf 1/1/1 2/2/1 3/3/1 4/4/1\n";

/// The same quad as ASCII PLY.
pub const QUAD_PLY: &str = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
property float z\nproperty float u\nproperty float v\nelement face 1\nproperty list uchar int vertex_indices\n\
end_header\n-1 -1 0 0 0\n1 -1 0 1 0\n1 1 0 1 1\n-1 1 0 0 1\n4 0 1 2 3\n";

/// Files a fuzzed scene or document may name: the mesh and texture names the repository's
/// scenes use, and a few more (the same tiny assets under every name), and a scene to include.
pub fn write_assets(dir: &Path) {
    let put = |name: &str, data: &[u8]| {
        let p = dir.join(name);
        std::fs::create_dir_all(p.parent().unwrap()).unwrap();
        std::fs::write(p, data).unwrap();
    };
    for name in ["meshes/torus.obj", "meshes/ribbon.obj", "mesh.obj"] {
        put(name, QUAD_OBJ.as_bytes());
    }
    put("mesh.ply", QUAD_PLY.as_bytes());
    let png = tiny_image(image::ImageFormat::Png);
    let exr = tiny_image(image::ImageFormat::OpenExr);
    for name in ["textures/uvgrid.png", "textures/finegrid.png", "texture.png", "grid.png", "cloth.png"] {
        put(name, &png);
    }
    put("texture.exr", &exr);
    put(
        "part.xml",
        br#"<scene version="3.0.0"><shape type="sphere"><float name="radius" value="0.5"/></shape></scene>"#,
    );
}

/// A 2×2 RGB image in `format`.
fn tiny_image(format: image::ImageFormat) -> Vec<u8> {
    let img = image::Rgb32FImage::from_fn(2, 2, |x, y| image::Rgb([x as f32, y as f32, 0.5]));
    let dynamic = image::DynamicImage::ImageRgb32F(img);
    let dynamic =
        if format == image::ImageFormat::Png { image::DynamicImage::ImageRgb8(dynamic.to_rgb8()) } else { dynamic };
    let mut out = std::io::Cursor::new(Vec::new());
    dynamic.write_to(&mut out, format).expect("encode a tiny image");
    out.into_inner()
}

/// Loads a scene of a 4×4 film, a constant emitter and `body` (shapes, emitters) from the
/// scratch folder, as `tessera render` would load it from a file there.
pub fn load_scene(body: &str) -> render::error::Result<render::scene::Scene> {
    let text = format!(
        r#"<scene version="3.0.0">
    <sensor type="perspective">
        <transform name="to_world"><lookat origin="0, 0, 4" target="0, 0, 0" up="0, 1, 0"/></transform>
        <film type="hdrfilm"><integer name="width" value="4"/><integer name="height" value="4"/></film>
    </sensor>
    <emitter type="constant"><rgb name="radiance" value="0.5, 0.5, 0.5"/></emitter>
    {body}
</scene>"#
    );
    let dir = scratch_dir();
    render::loader::load_str(&text, &dir.join("scene.xml"), dir, &[])
}

/// Renders `scene` at one sample per pixel when its film is small (at most 32×32), so that what
/// a reader produced is also traced, looked up and filtered; larger films are left alone.
pub fn render_tiny(scene: &render::scene::Scene) {
    let (w, h) = (u64::from(scene.camera.width), u64::from(scene.camera.height));
    if w * h <= 32 * 32 {
        let _ = render::integrator::render(scene, render::integrator::RenderSettings::new(1, 7), &|_| {});
    }
}

/// One worker thread for the renderer (called once, before any render): libFuzzer runs one
/// input at a time, and a panic on a pool thread should stop the same process.
pub fn init() {
    std::env::set_var("RAYON_NUM_THREADS", "1");
    let _ = scratch_dir();
}

/// With `TESSERA_FUZZ_VERBOSE` set, prints what became of an input (to check that seeds load,
/// e.g. `TESSERA_FUZZ_VERBOSE=1 fuzz/target/.../obj -runs=0 fuzz/seeds/obj`).
pub fn note<T, E: std::fmt::Display>(what: &str, r: &Result<T, E>) {
    static VERBOSE: OnceLock<bool> = OnceLock::new();
    if *VERBOSE.get_or_init(|| std::env::var_os("TESSERA_FUZZ_VERBOSE").is_some()) {
        match r {
            Ok(_) => eprintln!("fuzz: {what}: ok"),
            Err(e) => eprintln!("fuzz: {what}: error: {e}"),
        }
    }
}

//! `tessera bake`: evaluate one output of a MaterialX document on a grid of texels and write it
//! as an image (the grid, its orientation and its filtering are `graph::bake`'s).
//!
//! EXR files hold linear float32 channels named as MaterialX's baker names them (`Y` for
//! scalars, `R,G` for vector2, `R,G,B`, `R,G,B,A`); PNG files hold 8-bit values clamped to
//! [0, 1] and sRGB-encoded (alpha linear), grey for scalars, with blue 0 for vector2.

use crate::write_atomic;
use anyhow::{Context, Result};
use glam::Vec2;
use graph::bake::{self, BakeFilter, BakeSettings, BakedImage, Orientation};
use graph::{Document, LoadOptions};
use std::io::Cursor;
use std::path::PathBuf;
use std::time::Instant;

/// Arguments of `tessera bake`.
#[derive(clap::Args, Debug)]
pub struct BakeArgs {
    /// What to bake, and how.
    #[command(flatten)]
    pub(crate) bake: BakeJob,
    /// Output image: .exr (linear float) or .png (8-bit sRGB).
    #[arg(long)]
    out: PathBuf,
    /// No summary line.
    #[arg(long)]
    quiet: bool,
}

/// What `tessera bake` evaluates: a document's element on a grid of texels.
#[derive(clap::Args, Debug)]
pub(crate) struct BakeJob {
    /// The MaterialX document.
    document: PathBuf,
    /// What to bake: a node graph output (`nodegraph/output`, or `output` at the top level) or a
    /// material input (`material/shader/input`, `material/input`).
    #[arg(long)]
    element: String,
    /// Texels per row (and rows, unless --res-y is given).
    #[arg(long)]
    res: u32,
    /// Rows (default: --res).
    #[arg(long)]
    res_y: Option<u32>,
    /// uv at the left and v0 edges: u,v.
    #[arg(long, default_value = "0,0", value_parser = parse_uv, allow_hyphen_values = true)]
    uv_min: Vec2,
    /// uv at the right and v1 edges: u,v.
    #[arg(long, default_value = "1,1", value_parser = parse_uv, allow_hyphen_values = true)]
    uv_max: Vec2,
    /// point: unfiltered at texel centres; texel: filtered over a one-texel footprint (a
    /// Gaussian of half a texel's standard deviation per axis).
    #[arg(long, default_value = "point", value_parser = |s: &str| s.parse::<BakeFilter>())]
    filter: BakeFilter,
    /// materialx: the top row is v = v1 (MaterialX's baker, OpenGL); mitsuba: the top row is
    /// v = v0 (Mitsuba's bitmaps: uv (0,0) at the top-left).
    #[arg(long, default_value = "materialx", value_parser = |s: &str| s.parse::<Orientation>())]
    orientation: Orientation,
    /// Extra folder to search for images and includes (repeatable).
    #[arg(long = "search-path")]
    search_paths: Vec<PathBuf>,
    /// Worker threads (default: all cores); the image does not depend on it.
    #[arg(long)]
    threads: Option<usize>,
    /// The frame MaterialX's `frame` and `time` nodes read (default 1; `time` is frame / fps).
    #[arg(long, value_parser = parse_frame)]
    frame: Option<f32>,
}

fn parse_frame(s: &str) -> Result<f32, String> {
    s.trim().parse::<f32>().ok().filter(|f| f.is_finite()).ok_or_else(|| format!("`{s}` is not a frame number"))
}

/// A finished bake: the image, the element's type, the threads it ran on and its seconds.
pub(crate) struct Baked {
    pub image: BakedImage,
    pub ty: graph::ValueType,
    pub threads: usize,
    pub seconds: f64,
    /// The document's load warnings (nodes that load but cannot do what it asks).
    pub warnings: Vec<String>,
}

impl BakeJob {
    /// Loads the document and bakes the element.
    pub(crate) fn run(&self) -> Result<Baked> {
        crate::check_threads(self.threads)?;
        let settings = BakeSettings {
            width: self.res,
            height: self.res_y.unwrap_or(self.res),
            uv_min: self.uv_min,
            uv_max: self.uv_max,
            filter: self.filter,
            orientation: self.orientation,
        };
        settings.validate()?;
        // Lenient: nodes the element does not need may be unsupported; if it needs one,
        // resolving it reports which (with their lines).
        let opts = LoadOptions { search_paths: self.search_paths.clone(), lenient: true, frame: self.frame };
        let doc = Document::load_with(&self.document, &opts)?;
        let (source, ty) = bake::resolve(&doc, &self.element).with_context(|| self.document.display().to_string())?;
        let threads = self.threads.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()));
        let pool =
            rayon::ThreadPoolBuilder::new().num_threads(threads).build().context("cannot start worker threads")?;
        let t = Instant::now();
        let image = pool.install(|| bake::bake(doc.graph(), &source, ty, &settings))?;
        Ok(Baked { image, ty, threads, seconds: t.elapsed().as_secs_f64(), warnings: doc.warnings() })
    }
}

fn parse_uv(s: &str) -> Result<Vec2, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let nums: Vec<f32> = parts.iter().filter_map(|p| p.parse::<f32>().ok()).filter(|x| x.is_finite()).collect();
    match (parts.len(), nums.as_slice()) {
        (2, [u, v]) => Ok(Vec2::new(*u, *v)),
        _ => Err(format!("expected two finite numbers u,v, got '{s}'")),
    }
}

/// Runs `tessera bake`.
pub fn run(args: BakeArgs) -> Result<()> {
    let format = render::film::check_image_output(&args.out)?;
    let Baked { image: img, ty, threads, seconds: bake_s, warnings } = args.bake.run()?;
    // Never quiet, as with renders.
    for w in &warnings {
        eprintln!("warning: {}: {w}", args.bake.document.display());
    }
    let bytes = match format {
        render::film::ImageFormat::Exr => encode_exr(&img)?,
        render::film::ImageFormat::Png => encode_png(&img)?,
    };
    write_atomic(&args.out, &bytes)?;
    if !args.quiet {
        eprintln!(
            "baked {} ({ty}) at {}x{} in {bake_s:.2} s on {threads} threads; wrote {}",
            args.bake.element,
            img.width,
            img.height,
            args.out.display()
        );
    }
    Ok(())
}

fn encode_exr(img: &BakedImage) -> Result<Vec<u8>> {
    use exr::prelude::*;
    let n = img.channels();
    let channels: Vec<AnyChannel<FlatSamples>> = img
        .channel_names()
        .iter()
        .enumerate()
        .map(|(k, name)| {
            let v: Vec<f32> = img.data.iter().skip(k).step_by(n).copied().collect();
            AnyChannel::new(*name, FlatSamples::F32(v))
        })
        .collect();
    let layer = Layer::new(
        (img.width as usize, img.height as usize),
        LayerAttributes::default(),
        // Increasing line order: the blocks are then written in order even when compressed in
        // parallel, so the file's bytes do not depend on thread timing.
        Encoding { line_order: LineOrder::Increasing, ..Encoding::FAST_LOSSLESS },
        AnyChannels::sort(channels.into()),
    );
    let mut buf = Cursor::new(Vec::new());
    Image::from_layer(layer).write().to_buffered(&mut buf).context("cannot encode EXR")?;
    Ok(buf.into_inner())
}

fn srgb8(x: f32) -> u8 {
    let x = if x.is_finite() { x.clamp(0.0, 1.0) } else { 0.0 };
    let s = if x <= 0.0031308 { 12.92 * x } else { 1.055 * x.powf(1.0 / 2.4) - 0.055 };
    (s * 255.0 + 0.5).clamp(0.0, 255.0) as u8
}

fn encode_png(img: &BakedImage) -> Result<Vec<u8>> {
    use image::{ColorType, ImageEncoder};
    let n = img.channels();
    let (out_n, color) = match n {
        1 => (1, ColorType::L8),
        2 | 3 => (3, ColorType::Rgb8),
        _ => (4, ColorType::Rgba8),
    };
    let mut buf = Vec::with_capacity(img.width as usize * img.height as usize * out_n);
    for px in img.data.chunks_exact(n) {
        for k in 0..out_n {
            let x = px.get(k).copied().unwrap_or(0.0);
            buf.push(if k == 3 { (x.clamp(0.0, 1.0) * 255.0 + 0.5) as u8 } else { srgb8(x) });
        }
    }
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(&buf, img.width, img.height, color.into())
        .context("cannot encode PNG")?;
    Ok(out)
}

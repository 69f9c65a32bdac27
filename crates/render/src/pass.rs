//! Sample passes and image windows that merge exactly.
//!
//! A render may be split by sample index (`tessera render --samples A..B`: every pixel takes
//! samples A to B−1 of a render of `spp` samples) and by image window (`--crop x0,y0,x1,y1`).
//! Each part is written as a *pass file*: an OpenEXR image whose `R`, `G`, `B` channels hold
//! the part's own mean (any viewer shows it) and whose `sum.R.0` … `sum.B.3` channels hold each
//! pixel's exact sum of samples ([`PixelSum`], an `i128` per channel as four `u32` words, least
//! significant first). A header attribute, `tessera.pass`, says what the part is ([`PassInfo`]):
//! which render (scene, seed, resolution, samples per pixel, settings, cached nodes, tessera's
//! version) and which samples and window of it.
//!
//! [`merge`] adds the sums of passes that split the same render and divides once: since the
//! sums are integers, the merged image is the one render's bit for bit, however it was split.
//! Passes of another render, duplicated or overlapping passes, and samples or pixels no pass
//! covers are errors naming the files, never a darker or partial image.

use crate::error::{Error, Result};
use crate::film::{Image, PixelSum, SUM_FRACTION_BITS};
use crate::integrator::{Bucket, RenderOutput};
use crate::stats::Counts;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// The schema name and version every pass file's `tessera.pass` attribute carries.
pub const PASS_SCHEMA: &str = "tessera.pass/1";

/// The EXR header attribute that holds a pass's [`PassInfo`] as JSON.
pub const PASS_ATTRIBUTE: &str = "tessera.pass";

/// What makes two passes parts of one render: every field must agree for them to merge.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct RenderIdentity {
    /// The version of tessera that rendered it (another build may compute other values).
    pub tessera: String,
    /// Hash of the scene's text and `-D` defines.
    pub scene: String,
    /// Hash of each procedural graph's structure, in scene order.
    pub graphs: Vec<String>,
    /// Full image width in pixels.
    pub width: u32,
    /// Full image height in pixels.
    pub height: u32,
    /// Samples per pixel of the whole render.
    pub spp: u32,
    /// Seed of the random streams.
    pub seed: u64,
    /// Footprint estimator.
    pub footprint: String,
    /// Texture filter scale.
    pub filter_scale: String,
    /// Whether textures were replaced by their means.
    pub free_textures: bool,
    /// Whether every camera sample evaluated its own first-hit textures (not its pixel's shared
    /// ones).
    #[serde(default)]
    pub per_sample_textures: bool,
    /// The cached nodes and how they are cached (`none` when nothing is).
    pub cache: String,
    /// [`SUM_FRACTION_BITS`] of the sums.
    pub sum_fraction_bits: i32,
}

/// A pass file's description of itself.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct PassInfo {
    /// [`PASS_SCHEMA`].
    pub schema: String,
    /// The scene's file name, for messages (passes rendered on other machines may name it
    /// differently; it is not compared).
    pub scene_name: String,
    /// The render this pass is part of.
    pub render: RenderIdentity,
    /// The sample indices every pixel of the pass took, `[start, end)`.
    pub samples: [u32; 2],
    /// The window of the full image it covers, `[x0, y0, x1, y1)`.
    pub window: [u32; 4],
    /// What the pass counted while rendering.
    pub counts: Counts,
}

impl PassInfo {
    /// Reads and checks a pass file's description (its header only, no pixel).
    pub fn read(path: &Path) -> Result<PassInfo> {
        use exr::prelude::{AttributeValue, Text};
        let not_a_pass = |why: String| not_a_pass(path, why);
        let meta = exr::meta::MetaData::read_from_file(path, false)
            .map_err(|e| Error::in_file(path, format!("cannot read the EXR header: {e}")))?;
        let header = meta.headers.first().ok_or_else(|| not_a_pass("no image in the file".into()))?;
        let size = header.layer_size;
        if size.area() as u64 > crate::loader::MAX_PIXELS {
            return Err(Error::in_file(path, format!("{} × {} pixels is more than a pass can hold", size.0, size.1)));
        }
        let info_text = header
            .shared_attributes
            .other
            .get(&Text::from(PASS_ATTRIBUTE))
            .or_else(|| header.own_attributes.other.get(&Text::from(PASS_ATTRIBUTE)));
        let info: PassInfo = match info_text {
            Some(AttributeValue::Text(t)) => {
                let text =
                    std::str::from_utf8(t.as_slice()).map_err(|_| not_a_pass("its description is not UTF-8".into()))?;
                serde_json::from_str(text).map_err(|e| not_a_pass(format!("its description does not parse: {e}")))?
            }
            _ => return Err(not_a_pass(format!("no `{PASS_ATTRIBUTE}` attribute"))),
        };
        if info.schema != PASS_SCHEMA {
            return Err(not_a_pass(format!("schema '{}', expected '{PASS_SCHEMA}'", info.schema)));
        }
        let b = info.bucket();
        let [s0, s1] = info.samples;
        let (w, h) = (info.render.width, info.render.height);
        if !(b.x0 < b.x1 && b.y0 < b.y1 && b.x1 <= w && b.y1 <= h && s0 < s1 && s1 <= info.render.spp) {
            return Err(not_a_pass(format!(
                "{} does not fit a {w} × {h} image of {} spp",
                info.describe(),
                info.render.spp
            )));
        }
        if (size.0, size.1) != (b.width() as usize, b.height() as usize) {
            return Err(not_a_pass(format!(
                "its pixels are {} × {}, its window {} × {}",
                size.0,
                size.1,
                b.width(),
                b.height()
            )));
        }
        Ok(info)
    }

    fn bucket(&self) -> Bucket {
        let [x0, y0, x1, y1] = self.window;
        Bucket { x0, y0, x1, y1 }
    }

    fn describe(&self) -> String {
        let [x0, y0, x1, y1] = self.window;
        format!("samples {}..{} of window {x0},{y0},{x1},{y1}", self.samples[0], self.samples[1])
    }
}

/// A pass: its description and each pixel's exact sum, row by row over its window.
#[derive(Clone, Debug, PartialEq)]
pub struct Pass {
    /// What the pass is.
    pub info: PassInfo,
    /// Per pixel of the window.
    pub sums: Vec<PixelSum>,
}

const CHANNELS: [&str; 3] = ["R", "G", "B"];

/// The error for a file that is not a (whole, valid) pass file, and why.
fn not_a_pass(path: &Path, why: String) -> Error {
    Error::in_file(
        path,
        format!("not a tessera pass file ({why}); passes are written by `tessera render --samples A..B` or `--crop`"),
    )
}

fn sum_channel(c: usize, word: usize) -> String {
    format!("sum.{}.{word}", CHANNELS[c])
}

impl Pass {
    /// The pass a render made (`settings.keep_sums` must have been set), as part of `render`.
    pub fn of_render(out: &RenderOutput, render: RenderIdentity, scene_name: &str) -> Result<Pass> {
        let sums = out.sums.clone().ok_or_else(|| Error::plain("the render kept no pixel sums for a pass file"))?;
        let w = out.window;
        Ok(Pass {
            info: PassInfo {
                schema: PASS_SCHEMA.into(),
                scene_name: scene_name.into(),
                render,
                samples: [out.samples.start, out.samples.end],
                window: [w.x0, w.y0, w.x1, w.y1],
                counts: (&out.counts).into(),
            },
            sums,
        })
    }

    /// The pass's own mean image (of its window and samples).
    pub fn mean(&self) -> Image {
        let b = self.info.bucket();
        let n = self.info.samples[1] - self.info.samples[0];
        Image { width: b.width(), height: b.height(), pixels: self.sums.iter().map(|s| s.mean(n)).collect() }
    }

    /// Writes the pass file (through a temporary file renamed into place).
    pub fn save(&self, path: &Path) -> Result<()> {
        use exr::prelude::{
            AnyChannel, AnyChannels, AttributeValue, Encoding, FlatSamples, IntegerBounds, Layer, LayerAttributes,
            LineOrder, SmallVec, Text, Vec2, WritableImage,
        };
        let b = self.info.bucket();
        let mean = self.mean();
        let mut list: SmallVec<[AnyChannel<FlatSamples>; 4]> = SmallVec::new();
        for (c, name) in CHANNELS.iter().enumerate() {
            list.push(AnyChannel::new(*name, FlatSamples::F32(mean.pixels.iter().map(|p| p[c]).collect())));
            for word in 0..4 {
                let words = self.sums.iter().map(|s| (s.0[c] as u128 >> (32 * word)) as u32).collect();
                list.push(AnyChannel::new(sum_channel(c, word).as_str(), FlatSamples::U32(words)));
            }
        }
        let json = serde_json::to_string(&self.info).map_err(|e| Error::in_file(path, e.to_string()))?;
        let attributes =
            LayerAttributes { layer_position: Vec2(b.x0 as i32, b.y0 as i32), ..LayerAttributes::default() };
        let encoding = Encoding { line_order: LineOrder::Increasing, ..Encoding::SMALL_LOSSLESS };
        let layer =
            Layer::new((b.width() as usize, b.height() as usize), attributes, encoding, AnyChannels::sort(list));
        let mut image = exr::image::Image::from_layer(layer);
        let (w, h) = (self.info.render.width as usize, self.info.render.height as usize);
        image.attributes.display_window = IntegerBounds::new((0, 0), (w, h));
        image
            .attributes
            .other
            .insert(Text::from(PASS_ATTRIBUTE), AttributeValue::Text(Text::from_slice_unchecked(json.as_bytes())));
        crate::film::write_through_temp(path, |tmp| {
            image.write().to_file(tmp).map_err(|e| Error::in_file(tmp, format!("cannot write the pass file: {e}")))
        })
    }

    /// Reads a pass file written by [`Pass::save`].
    pub fn load(path: &Path) -> Result<Pass> {
        use exr::prelude::{read, FlatSamples, ReadChannels, ReadLayers};
        let info = PassInfo::read(path)?;
        let not_a_pass = |why: String| not_a_pass(path, why);
        let b = info.bucket();
        let image = read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(path)
            .map_err(|e| Error::in_file(path, format!("cannot read the pass file: {e}")))?;
        let channels = &image.layer_data.channel_data.list;
        let n = b.len();
        let mut sums = vec![PixelSum::default(); n];
        for c in 0..3 {
            for word in 0..4 {
                let name = sum_channel(c, word);
                let ch = channels
                    .iter()
                    .find(|ch| ch.name.eq(name.as_str()))
                    .ok_or_else(|| not_a_pass(format!("no channel {name}")))?;
                let FlatSamples::U32(words) = &ch.sample_data else {
                    return Err(not_a_pass(format!("channel {name} is not 32-bit unsigned")));
                };
                if words.len() != n {
                    return Err(not_a_pass(format!("channel {name} has {} values for {n} pixels", words.len())));
                }
                for (s, v) in sums.iter_mut().zip(words.iter().copied()) {
                    s.0[c] = (s.0[c] as u128 | (u128::from(v) << (32 * word))) as i128;
                }
            }
        }
        Ok(Pass { info, sums })
    }
}

/// The result of [`merge`]: the image and what its passes counted together.
#[derive(Clone, Debug)]
pub struct Merged {
    /// The full image.
    pub image: Image,
    /// The passes' counts, summed.
    pub counts: Counts,
    /// The render the passes were parts of.
    pub render: RenderIdentity,
}

/// Each window with the passes (indices) that cover it, sorted by their samples.
type Windows = Vec<(Bucket, Vec<usize>)>;

/// Merges passes that split one render into the render's image, bit for bit the image the
/// render makes unsplit. Each pass comes with the file it was read from, for messages.
///
/// The passes must all be parts of the same render ([`RenderIdentity`]); any two windows must
/// be equal or disjoint; the passes of each window must take every sample index `0..spp`
/// exactly once; and the windows must cover the whole image.
pub fn merge(passes: &[(PathBuf, Pass)]) -> Result<Merged> {
    let infos: Vec<(PathBuf, &PassInfo)> = passes.iter().map(|(p, pass)| (p.clone(), &pass.info)).collect();
    let (id, windows) = merge_plan(&infos)?;
    sum_windows(id, &windows, |i| Ok(std::borrow::Cow::Borrowed(&passes[i].1)))
}

/// [`merge`] of pass files, reading them one at a time: their headers first (every check is
/// made before any pixel is read), then each pass's sums, added to its window's and dropped,
/// so that memory holds one window's sums and one pass, however many passes there are.
pub fn merge_files(paths: &[PathBuf]) -> Result<Merged> {
    let infos: Vec<PassInfo> = paths.iter().map(|p| PassInfo::read(p)).collect::<Result<_>>()?;
    let named: Vec<(PathBuf, &PassInfo)> = paths.iter().cloned().zip(&infos).collect();
    let (id, windows) = merge_plan(&named)?;
    sum_windows(id, &windows, |i| {
        let pass = Pass::load(&paths[i])?;
        if pass.info != infos[i] {
            return Err(Error::in_file(&paths[i], "changed while it was being merged"));
        }
        Ok(std::borrow::Cow::Owned(pass))
    })
}

/// Adds up each window's passes (`pass(i)` gives pass `i`) and divides once.
fn sum_windows<'a>(
    id: &RenderIdentity,
    windows: &Windows,
    pass: impl Fn(usize) -> Result<std::borrow::Cow<'a, Pass>>,
) -> Result<Merged> {
    let mut image = Image::new(id.width, id.height);
    let mut counts = Counts::default();
    for (w, list) in windows {
        let mut sums = vec![PixelSum::default(); w.len()];
        for &i in list {
            let p = pass(i)?;
            for (s, o) in sums.iter_mut().zip(&p.sums) {
                s.merge(o);
            }
            counts.add(&p.info.counts);
        }
        for ((x, y), s) in w.pixels().zip(&sums) {
            image.pixels[(y * id.width + x) as usize] = s.mean(id.spp);
        }
    }
    Ok(Merged { image, counts, render: id.clone() })
}

/// Checks that `passes` split one render (see [`merge`]); returns the render and its windows.
fn merge_plan<'a>(passes: &'a [(PathBuf, &'a PassInfo)]) -> Result<(&'a RenderIdentity, Windows)> {
    let Some((first_path, first)) = passes.first() else {
        return Err(Error::plain("no passes to merge"));
    };
    let id = &first.render;
    for (i, (path, _)) in passes.iter().enumerate() {
        if passes[..i].iter().any(|(q, _)| q == path) {
            return Err(Error::in_file(path, "is given twice"));
        }
    }
    for (path, p) in &passes[1..] {
        if let Some(field) = identity_difference(id, &p.render) {
            return Err(Error::in_file(
                path,
                format!("a pass of another render than {}: {field}", first_path.display()),
            ));
        }
    }
    // Windows, each with its passes.
    let mut windows: Vec<(Bucket, Vec<usize>)> = Vec::new();
    for (i, (path, p)) in passes.iter().enumerate() {
        let b = p.bucket();
        match windows.iter_mut().find(|(w, _)| overlaps(*w, b)) {
            Some((w, list)) if *w == b => list.push(i),
            Some((w, list)) => {
                return Err(Error::in_file(
                    path,
                    format!(
                        "its window {},{},{},{} overlaps the window {},{},{},{} of {} without being the same",
                        b.x0,
                        b.y0,
                        b.x1,
                        b.y1,
                        w.x0,
                        w.y0,
                        w.x1,
                        w.y1,
                        passes[list[0]].0.display()
                    ),
                ))
            }
            None => windows.push((b, vec![i])),
        }
    }
    // Within a window, the sample ranges must tile 0..spp.
    for (w, list) in &mut windows {
        list.sort_by_key(|&i| (passes[i].1.samples, i));
        let mut next = 0u32;
        let mut previous: Option<usize> = None;
        for &i in list.iter() {
            let (path, p) = &passes[i];
            let [s0, s1] = p.samples;
            if s0 < next {
                let prev = previous.map(|j| passes[j].0.display().to_string()).unwrap_or_default();
                let what = if Some(p.samples) == previous.map(|j| passes[j].1.samples) {
                    format!("duplicates {prev} ({})", p.describe())
                } else {
                    format!("its samples {s0}..{s1} overlap those of {prev}")
                };
                return Err(Error::in_file(path, what));
            }
            if s0 > next {
                return Err(Error::plain(format!(
                    "no pass has samples {next}..{s0} of window {},{},{},{} (the next pass is {})",
                    w.x0,
                    w.y0,
                    w.x1,
                    w.y1,
                    path.display()
                )));
            }
            next = s1;
            previous = Some(i);
        }
        if next != id.spp {
            return Err(Error::plain(format!(
                "no pass has samples {next}..{} of window {},{},{},{} (the render takes {} spp)",
                id.spp, w.x0, w.y0, w.x1, w.y1, id.spp
            )));
        }
    }
    // The windows (disjoint by now) must cover the image.
    let covered: u64 = windows.iter().map(|(w, _)| w.len() as u64).sum();
    if covered != u64::from(id.width) * u64::from(id.height) {
        let (x, y) = Bucket::full(id.width, id.height)
            .pixels()
            .find(|&(x, y)| !windows.iter().any(|(w, _)| w.x0 <= x && x < w.x1 && w.y0 <= y && y < w.y1))
            .unwrap_or_default();
        return Err(Error::plain(format!(
            "the passes cover {covered} of the {} × {} image's pixels: none covers pixel ({x}, {y})",
            id.width, id.height
        )));
    }
    Ok((id, windows))
}

fn overlaps(a: Bucket, b: Bucket) -> bool {
    a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1
}

/// The first field in which two renders differ, said for a reader; `None` when they agree.
fn identity_difference(a: &RenderIdentity, b: &RenderIdentity) -> Option<String> {
    let pair = |what: &str, x: String, y: String| (x != y).then(|| format!("{what} {y}, not {x}"));
    pair("tessera version", a.tessera.clone(), b.tessera.clone())
        .or_else(|| pair("scene (text and defines) hash", a.scene.clone(), b.scene.clone()))
        .or_else(|| pair("graph hashes", a.graphs.join(","), b.graphs.join(",")))
        .or_else(|| pair("resolution", format!("{}x{}", a.width, a.height), format!("{}x{}", b.width, b.height)))
        .or_else(|| pair("samples per pixel", a.spp.to_string(), b.spp.to_string()))
        .or_else(|| pair("seed", a.seed.to_string(), b.seed.to_string()))
        .or_else(|| pair("footprint estimator", a.footprint.clone(), b.footprint.clone()))
        .or_else(|| pair("filter scale", a.filter_scale.clone(), b.filter_scale.clone()))
        .or_else(|| pair("free textures", a.free_textures.to_string(), b.free_textures.to_string()))
        .or_else(|| pair("per-sample textures", a.per_sample_textures.to_string(), b.per_sample_textures.to_string()))
        .or_else(|| pair("cached nodes", a.cache.clone(), b.cache.clone()))
        .or_else(|| pair("sum precision", a.sum_fraction_bits.to_string(), b.sum_fraction_bits.to_string()))
}

/// The identity of a render of `scene` with `settings`: `scene_hash` hashes its text and
/// defines, `cache` names what is cached ([`crate::caching::NodeCache::identity`], or `none`).
pub fn identity(
    scene: &crate::scene::Scene,
    settings: &crate::integrator::RenderSettings,
    scene_hash: &str,
    cache: String,
) -> RenderIdentity {
    RenderIdentity {
        tessera: env!("CARGO_PKG_VERSION").into(),
        scene: scene_hash.into(),
        graphs: scene.graphs.iter().map(|g| crate::profiling::graph_hash(g.graph())).collect(),
        width: scene.camera.width,
        height: scene.camera.height,
        spp: settings.spp,
        seed: settings.seed,
        footprint: format!("{:?}", settings.footprint).to_lowercase(),
        filter_scale: match settings.filter_scale {
            crate::integrator::FilterScale::Auto => "auto".into(),
            crate::integrator::FilterScale::Fixed(s) => format!("{s:?}"),
        },
        free_textures: settings.free_textures,
        per_sample_textures: settings.per_sample_textures,
        cache,
        sum_fraction_bits: SUM_FRACTION_BITS,
    }
}

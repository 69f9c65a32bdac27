//! Split renders: sample passes and image windows written as pass files, read back and merged,
//! reproduce the unsplit render bit for bit; every bad merge is an error naming a file.

use render::caching::{render_cached, NodeCache, Strategy};
use render::film::Image;
use render::integrator::{Bucket, RenderSettings};
use render::pass::{identity, merge, merge_files, Pass};
use render::scene::Scene;
use std::path::{Path, PathBuf};

const SPP: u32 = 7;

fn marble() -> Scene {
    let scenes = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes");
    let defines = [("res".to_string(), "40".to_string())];
    render::loader::load_file(&scenes.join("marble.xml"), &defines).unwrap_or_else(|e| panic!("{e}"))
}

fn dir(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("tessera-passes-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// Renders one part of the render of `SPP` samples with `seed` (the whole render when both are
/// `None`), on `threads` threads, and writes it as a pass file.
struct Parts<'a> {
    scene: &'a Scene,
    cache: Option<&'a NodeCache>,
    seed: u64,
    threads: usize,
}

impl Parts<'_> {
    fn settings(&self, samples: Option<(u32, u32)>, window: Option<Bucket>) -> RenderSettings {
        RenderSettings { sample_range: samples, window, keep_sums: true, ..RenderSettings::new(SPP, self.seed) }
    }

    fn render(&self, settings: RenderSettings) -> render::integrator::RenderOutput {
        let pool = rayon::ThreadPoolBuilder::new().num_threads(self.threads).build().unwrap();
        pool.install(|| render_cached(self.scene, settings, self.cache, &|_| {}))
    }

    fn write(&self, path: &Path, samples: Option<(u32, u32)>, window: Option<Bucket>) -> (PathBuf, Pass) {
        let settings = self.settings(samples, window);
        let out = self.render(settings);
        let cache = self.cache.map_or("none", |c| c.identity()).to_string();
        let pass = Pass::of_render(&out, identity(self.scene, &settings, "scene-hash", cache), "marble.xml").unwrap();
        pass.save(path).unwrap();
        let back = Pass::load(path).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(back, pass, "a pass file reads back as written");
        (path.to_path_buf(), back)
    }

    fn whole(&self) -> Image {
        self.render(RenderSettings::new(SPP, self.seed)).image
    }
}

fn bits(img: &Image) -> Vec<u32> {
    img.pixels.iter().flat_map(|p| p.to_array()).map(f32::to_bits).collect()
}

/// `k` sample ranges of uneven lengths covering 0..SPP.
fn splits(k: u32) -> Vec<(u32, u32)> {
    let mut cuts: Vec<u32> = (0..=k).map(|i| (i * SPP).div_ceil(k)).collect();
    cuts.dedup();
    assert_eq!(cuts.len() as u32, k + 1, "{k} passes of {SPP} samples");
    cuts.windows(2).map(|w| (w[0], w[1])).collect()
}

#[test]
fn sample_passes_and_windows_merge_into_the_single_render_bit_for_bit() {
    let scene = marble();
    let (w, h) = (scene.camera.width, scene.camera.height);
    // The whole render on 1 thread; the parts on 2, so that bucket scheduling differs too.
    let single = Parts { scene: &scene, cache: None, seed: 3, threads: 1 }.whole();
    let parts = Parts { scene: &scene, cache: None, seed: 3, threads: 2 };
    let d = dir("split");
    for k in [1, 2, 3, 7] {
        let passes: Vec<_> = splits(k)
            .into_iter()
            .enumerate()
            .map(|(i, r)| parts.write(&d.join(format!("s{k}-{i}.exr")), Some(r), None))
            .collect();
        let merged = merge(&passes).unwrap_or_else(|e| panic!("{k} passes: {e}"));
        assert!(bits(&merged.image) == bits(&single), "{k} sample passes differ from the single render");
        // Read from the files one pass at a time: the same image.
        let paths: Vec<PathBuf> = passes.iter().map(|(p, _)| p.clone()).collect();
        assert!(bits(&merge_files(&paths).unwrap().image) == bits(&single), "{k} pass files merged");
        assert_eq!(merged.counts.samples, u64::from(w * h * SPP));
    }
    // Four windows of uneven sizes, then windows split into sample passes as well.
    let (cx, cy) = (w / 3, h * 2 / 3);
    let windows = [
        Bucket { x0: 0, y0: 0, x1: cx, y1: cy },
        Bucket { x0: cx, y0: 0, x1: w, y1: cy },
        Bucket { x0: 0, y0: cy, x1: cx, y1: h },
        Bucket { x0: cx, y0: cy, x1: w, y1: h },
    ];
    let passes: Vec<_> =
        windows.iter().enumerate().map(|(i, b)| parts.write(&d.join(format!("w{i}.exr")), None, Some(*b))).collect();
    assert!(bits(&merge(&passes).unwrap().image) == bits(&single), "four windows differ from the single render");
    let mut mixed = Vec::new();
    for (i, b) in windows.iter().enumerate() {
        for (j, r) in splits(1 + i as u32).into_iter().enumerate() {
            mixed.push(parts.write(&d.join(format!("m{i}-{j}.exr")), Some(r), Some(*b)));
        }
    }
    mixed.reverse();
    assert!(bits(&merge(&mixed).unwrap().image) == bits(&single), "windows × sample passes differ");
    std::fs::remove_dir_all(&d).unwrap();
}

/// With cached nodes, passes of the same plan merge exactly too (tiles are filled on demand in
/// whatever order each pass reads them; their values do not depend on it).
#[test]
fn cached_passes_merge_exactly() {
    let scene = marble();
    let nc = NodeCache::new(&scene, &Strategy::Outputs, 64 << 20).unwrap().expect("the marble graph has outputs");
    let single = Parts { scene: &scene, cache: Some(&nc), seed: 5, threads: 1 }.whole();
    let d = dir("cached");
    let passes: Vec<_> = splits(3)
        .into_iter()
        .enumerate()
        .map(|(i, r)| {
            // A fresh cache per pass, as on another machine.
            let nc = NodeCache::new(&scene, &Strategy::Outputs, 64 << 20).unwrap().unwrap();
            Parts { scene: &scene, cache: Some(&nc), seed: 5, threads: 2 }.write(
                &d.join(format!("{i}.exr")),
                Some(r),
                None,
            )
        })
        .collect();
    assert!(bits(&merge(&passes).unwrap().image) == bits(&single));
    std::fs::remove_dir_all(&d).unwrap();
}

fn merge_error(passes: &[(PathBuf, Pass)]) -> String {
    match merge(passes) {
        Ok(_) => panic!("the merge of {:?} should fail", passes.iter().map(|p| &p.0).collect::<Vec<_>>()),
        Err(e) => e.to_string(),
    }
}

fn assert_mentions(msg: &str, words: &[&str]) {
    for w in words {
        assert!(msg.contains(w), "'{msg}' should mention '{w}'");
    }
}

#[test]
fn bad_merges_are_errors_naming_the_pass() {
    let scene = marble();
    let d = dir("bad");
    let parts = Parts { scene: &scene, cache: None, seed: 1, threads: 2 };
    let a = parts.write(&d.join("a.exr"), Some((0, 3)), None);
    let b = parts.write(&d.join("b.exr"), Some((3, SPP)), None);
    let overlapping = parts.write(&d.join("overlap.exr"), Some((2, 5)), None);
    assert!(merge(&[a.clone(), b.clone()]).is_ok());

    assert_mentions(&merge_error(std::slice::from_ref(&a)), &["no pass has samples 3..7"]);
    assert_mentions(&merge_error(std::slice::from_ref(&b)), &["no pass has samples 0..3", "b.exr"]);
    assert_mentions(&merge_error(&[a.clone(), b.clone(), a.clone()]), &["a.exr", "given twice"]);
    let mut copy = a.clone();
    copy.0 = d.join("copy-of-a.exr");
    assert_mentions(&merge_error(&[a.clone(), b.clone(), copy]), &["copy-of-a.exr", "duplicates", "a.exr"]);
    assert_mentions(&merge_error(&[a.clone(), overlapping, b.clone()]), &["overlap.exr", "overlap", "a.exr"]);
    assert_eq!(merge_error(&[]), "no passes to merge");
    // Files are checked (all headers) before any is summed.
    let e = merge_files(&[a.0.clone(), d.join("missing.exr")]).unwrap_err().to_string();
    assert!(e.contains("missing.exr"), "{e}");
    let e = merge_files(&[a.0.clone(), a.0.clone()]).unwrap_err().to_string();
    assert!(e.contains("given twice"), "{e}");

    // Parts of other renders: another seed, another sample count, another resolution, other
    // cached nodes, another scene.
    let other_seed = Parts { seed: 2, ..parts }.write(&d.join("seed2.exr"), Some((3, SPP)), None);
    assert_mentions(&merge_error(&[a.clone(), other_seed]), &["seed2.exr", "another render", "seed 2, not 1"]);
    let mut other = b.clone();
    other.1.info.render.spp = 8;
    assert_mentions(&merge_error(&[a.clone(), other]), &["b.exr", "samples per pixel 8, not 7"]);
    let small = render::loader::load_file(
        &PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../scenes/marble.xml"),
        &[("res".to_string(), "24".to_string())],
    )
    .unwrap();
    let small = Parts { scene: &small, ..parts }.write(&d.join("small.exr"), Some((3, SPP)), None);
    assert_mentions(&merge_error(&[a.clone(), small]), &["small.exr", "resolution"]);
    let nc = NodeCache::new(&scene, &Strategy::All, 64 << 20).unwrap().unwrap();
    let cached = Parts { cache: Some(&nc), ..parts }.write(&d.join("cached.exr"), Some((3, SPP)), None);
    assert_mentions(&merge_error(&[a.clone(), cached]), &["cached.exr", "cached nodes"]);
    let mut other = b.clone();
    other.1.info.render.scene = "another".into();
    assert_mentions(&merge_error(&[a.clone(), other]), &["b.exr", "scene"]);

    // Windows: partly overlapping, and not covering the image.
    let (w, h) = (scene.camera.width, scene.camera.height);
    let left = parts.write(&d.join("left.exr"), None, Some(Bucket { x0: 0, y0: 0, x1: w / 2, y1: h }));
    let middle = parts.write(&d.join("middle.exr"), None, Some(Bucket { x0: w / 4, y0: 0, x1: w, y1: h }));
    assert_mentions(&merge_error(&[left.clone(), middle]), &["middle.exr", "overlaps", "left.exr"]);
    assert_mentions(&merge_error(&[left]), &["cover", &format!("pixel ({}, 0)", w / 2)]);
    std::fs::remove_dir_all(&d).unwrap();
}

#[test]
fn files_that_are_not_passes_are_refused() {
    let d = dir("files");
    let plain = d.join("plain.exr");
    Image::new(4, 4).save(&plain).unwrap();
    assert_mentions(&Pass::load(&plain).unwrap_err().to_string(), &["plain.exr", "not a tessera pass file"]);
    let missing = d.join("missing.exr");
    assert_mentions(&Pass::load(&missing).unwrap_err().to_string(), &["missing.exr"]);
    // A pass cut short: an error, never a panic or a partial image.
    let scene = marble();
    let (path, _) =
        Parts { scene: &scene, cache: None, seed: 1, threads: 2 }.write(&d.join("cut.exr"), Some((0, 1)), None);
    let bytes = std::fs::read(&path).unwrap();
    for len in [bytes.len() / 2, bytes.len() - 7, 40] {
        std::fs::write(&path, &bytes[..len]).unwrap();
        assert_mentions(&Pass::load(&path).unwrap_err().to_string(), &["cut.exr"]);
    }
    std::fs::remove_dir_all(&d).unwrap();
}

/// A scene lists every file it was built from, each once (what a render on another machine
/// needs): includes, meshes, bitmaps, MaterialX documents with their includes, and the images
/// their nodes read.
#[test]
fn scenes_list_every_file_they_read() {
    let d = dir("files-list");
    let refs = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs/scenes");
    std::fs::create_dir_all(d.join("parts")).unwrap();
    std::fs::copy(refs.join("meshes/torus.obj"), d.join("parts/torus.obj")).unwrap();
    std::fs::copy(refs.join("textures/uvgrid.png"), d.join("grid.png")).unwrap();
    std::fs::copy(refs.join("textures/uvgrid.png"), d.join("parts/leaf.png")).unwrap();
    std::fs::write(
        d.join("parts/part.xml"),
        "<scene version=\"3.0.0\">\n<shape type=\"obj\"><string name=\"filename\" value=\"parts/torus.obj\"/>\n\
         <bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
         <string name=\"filename\" value=\"grid.png\"/></texture></bsdf></shape>\n</scene>\n",
    )
    .unwrap();
    std::fs::write(
        d.join("parts/leaf.mtlx"),
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\">\n<nodegraph name=\"NG\">\n\
         <image name=\"img\" type=\"color3\"><input name=\"file\" type=\"filename\" value=\"leaf.png\"/></image>\n\
         <output name=\"out\" type=\"color3\" nodename=\"img\"/>\n</nodegraph>\n</materialx>\n",
    )
    .unwrap();
    std::fs::write(
        d.join("top.mtlx"),
        "<?xml version=\"1.0\"?>\n<materialx version=\"1.39\" xmlns:xi=\"http://www.w3.org/2001/XInclude\">\n\
         <xi:include href=\"parts/leaf.mtlx\"/>\n</materialx>\n",
    )
    .unwrap();
    let main = d.join("main.xml");
    std::fs::write(
        &main,
        "<scene version=\"3.0.0\">\n<sensor type=\"perspective\"><film type=\"hdrfilm\">\
         <integer name=\"width\" value=\"8\"/><integer name=\"height\" value=\"8\"/></film></sensor>\n\
         <include filename=\"parts/part.xml\"/>\n\
         <shape type=\"sphere\"><bsdf type=\"diffuse\"><texture type=\"mtlx\" name=\"reflectance\">\
         <string name=\"filename\" value=\"top.mtlx\"/><string name=\"output\" value=\"NG/out\"/></texture></bsdf></shape>\n\
         <shape type=\"sphere\"><bsdf type=\"diffuse\"><texture type=\"bitmap\" name=\"reflectance\">\
         <string name=\"filename\" value=\"grid.png\"/></texture></bsdf></shape>\n</scene>\n",
    )
    .unwrap();
    let scene = render::loader::load_file(&main, &[]).unwrap_or_else(|e| panic!("{e}"));
    let canon = |p: &Path| p.canonicalize().unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let listed: Vec<PathBuf> = scene.files.iter().map(|p| canon(p)).collect();
    let mut want: Vec<PathBuf> = ["main.xml", "parts/part.xml", "parts/torus.obj", "grid.png", "top.mtlx"]
        .iter()
        .chain(&["parts/leaf.mtlx", "parts/leaf.png"])
        .map(|f| canon(&d.join(f)))
        .collect();
    assert_eq!(listed[0], want[0], "the scene file comes first");
    let mut sorted = listed.clone();
    sorted.sort();
    sorted.dedup();
    assert_eq!(sorted.len(), listed.len(), "each file once: {listed:?}");
    want.sort();
    assert_eq!(sorted, want);
    std::fs::remove_dir_all(&d).unwrap();
}

//! References: each scene's high-spp image, cached under an FNV-1a hash of everything it depends on.

use super::results::ReferenceInfo;
use super::runs::{run_child, Job};
use super::{Config, REF_SEED_OFFSET};
use crate::flip::Srgb8;
use crate::write_atomic;
use anyhow::{Context, Result};
use plan::Fnv;
use render::film::Image;
use serde_json::Value;
use std::path::{Path, PathBuf};

/// Files a scene depends on: every attribute value naming an existing file relative to the
/// document that names it (MaterialX documents, meshes, images, included XML), followed into
/// XML and MaterialX documents a few levels deep. In document order, each once.
fn referenced_files(doc: &Path, depth: u32, seen: &mut Vec<PathBuf>) {
    let Ok(text) = std::fs::read(doc) else { return };
    let text = String::from_utf8_lossy(&text);
    let dir = doc.parent().unwrap_or(Path::new("."));
    for pattern in ["value=\"", "filename=\""] {
        for (i, _) in text.match_indices(pattern) {
            let rest = &text[i + pattern.len()..];
            let Some(end) = rest.find('"') else { continue };
            let candidate = &rest[..end];
            if candidate.is_empty() || candidate.len() > 1024 {
                continue;
            }
            let p = dir.join(candidate);
            if p.is_file() && !seen.contains(&p) {
                seen.push(p.clone());
                let ext = p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
                if depth > 0 && (ext == "xml" || ext == "mtlx") {
                    referenced_files(&p, depth - 1, seen);
                }
            }
        }
    }
}

/// The reference's cache key: the scene and the files it names, the resolution, spp, seed,
/// extra defines, and the renderer (version and executable contents).
fn reference_key(cfg: &Config, scene: &Path, exe_hash: u64) -> Result<String> {
    let mut h = Fnv::new();
    h.part(b"tessera.bench.reference/1");
    h.part(env!("CARGO_PKG_VERSION").as_bytes());
    h.part(&exe_hash.to_le_bytes());
    h.part(&std::fs::read(scene).with_context(|| format!("{}: cannot read the scene", scene.display()))?);
    let mut files = Vec::new();
    referenced_files(scene, 3, &mut files);
    let dir = scene.parent().unwrap_or(Path::new("."));
    for f in &files {
        h.part(f.strip_prefix(dir).unwrap_or(f).to_string_lossy().as_bytes());
        h.part(&std::fs::read(f).unwrap_or_default());
    }
    h.part(&cfg.res.to_le_bytes());
    h.part(&cfg.ref_spp.to_le_bytes());
    h.part(&cfg.seed.wrapping_add(REF_SEED_OFFSET).to_le_bytes());
    for d in &cfg.defines {
        h.part(d.as_bytes());
    }
    Ok(h.hex())
}

pub(super) fn hash_file(path: &Path) -> Result<u64> {
    use std::io::Read;
    let mut f = std::fs::File::open(path).with_context(|| format!("{}: cannot read", path.display()))?;
    let mut h = Fnv::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).with_context(|| format!("{}: cannot read", path.display()))?;
        if n == 0 {
            return Ok(h.value());
        }
        h.bytes(&buf[..n]);
    }
}

pub(super) struct Reference {
    pub(super) image: Image,
    pub(super) srgb: Srgb8,
    pub(super) footprint_png: Option<Vec<u8>>,
    pub(super) info: ReferenceInfo,
}

/// The scene's reference: from the cache when its key is there, otherwise rendered (strategy
/// none, `ref_spp`, with the footprint AOV) and stored in the cache.
pub(super) fn reference(
    cfg: &Config,
    scene: &Path,
    name: &str,
    work: &Path,
    exe_hash: u64,
) -> std::result::Result<Reference, String> {
    let key = reference_key(cfg, scene, exe_hash).map_err(|e| format!("{e:#}"))?;
    let exr = cfg.ref_cache.join(format!("{key}.exr"));
    let fp = cfg.ref_cache.join(format!("{key}.footprint.png"));
    let meta = cfg.ref_cache.join(format!("{key}.json"));
    let info = |reused: bool, render_s: Option<f64>, has_fp: bool| ReferenceInfo {
        spp: cfg.ref_spp,
        seed: cfg.seed.wrapping_add(REF_SEED_OFFSET),
        key: key.clone(),
        reused,
        render_s,
        image: format!("images/{name}.reference.png"),
        footprint_image: has_fp.then(|| format!("images/{name}.footprint.png")),
    };
    if let Ok(image) = Image::load_exr(&exr) {
        let render_s = std::fs::read(&meta)
            .ok()
            .and_then(|b| serde_json::from_slice::<Value>(&b).ok())
            .and_then(|v| v["phases"]["render_s"].as_f64());
        let footprint_png = std::fs::read(&fp).ok();
        let has_fp = footprint_png.is_some();
        let srgb = Srgb8::from_linear(&image);
        return Ok(Reference { image, srgb, footprint_png, info: info(true, render_s, has_fp) });
    }
    cfg.progress(&format!("  reference: {} spp (key {key})", cfg.ref_spp));
    let base = format!("{name}.reference");
    let s = run_child(cfg, scene, Job::Reference, work, &base).map_err(|e| format!("reference render failed: {e}"))?;
    let footprint_png = std::fs::read(work.join(format!("{base}.footprint.png"))).ok();
    // Keep it for the next benchmark; a cache that cannot be written only costs time.
    let store = || -> Result<()> {
        std::fs::create_dir_all(&cfg.ref_cache)
            .with_context(|| format!("{}: cannot create the folder", cfg.ref_cache.display()))?;
        if let Some(png) = &footprint_png {
            write_atomic(&fp, png)?;
        }
        write_atomic(&meta, serde_json::to_string_pretty(&s.stats)?.as_bytes())?;
        write_atomic(&exr, &std::fs::read(work.join(format!("{base}.exr")))?)
    };
    if let Err(e) = store() {
        eprintln!("warning: cannot keep the reference in {}: {e:#}", cfg.ref_cache.display());
    }
    let srgb = Srgb8::from_linear(&s.image);
    let has_fp = footprint_png.is_some();
    Ok(Reference { image: s.image, srgb, footprint_png, info: info(false, Some(s.phases.render_s), has_fp) })
}

//! The MaterialX importer (`graph::Document::parse`, as the scene loader calls it; a document
//! with unsupported nodes is also read leniently, as `tessera bake` reads it), then every
//! material binding and up to eight graph outputs evaluated at a point and over a footprint.
#![no_main]

use glam::Vec2;
use graph::{Document, EvalScratch, Footprint, LoadErrorKind, LoadOptions, OutputId};
use libfuzzer_sys::fuzz_target;

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let path = tessera_fuzz::scratch_dir().join("document.mtlx");
    let strict = Document::parse(text, &path, &LoadOptions::default());
    tessera_fuzz::note("document", &strict);
    let doc = match strict {
        Ok(doc) => doc,
        Err(e) if matches!(e.kind, LoadErrorKind::Unsupported { .. }) => {
            match Document::parse(text, &path, &LoadOptions { lenient: true, ..LoadOptions::default() }) {
                Ok(doc) => doc,
                Err(_) => return,
            }
        }
        Err(_) => return,
    };
    for name in doc.material_names() {
        let _ = doc.material(name);
    }
    let _ = doc.shader_input_paths();
    let g = doc.graph();
    let _ = g.warnings();
    let mut scratch = EvalScratch::new(g);
    let uv = Vec2::new(0.3, 0.7);
    for i in 0..g.outputs().len().min(8) {
        let out = OutputId(i as u32);
        let _ = g.eval_output(out, &Footprint::point(uv), &mut scratch);
        let _ = g.eval_output(out, &Footprint::isotropic(uv, 0.05), &mut scratch);
    }
});

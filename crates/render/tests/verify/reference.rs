//! The renderer against Mitsuba 3's own images of the same scenes (`../shared/refs/`).
//!
//! For each scene: two renders at N spp with different seeds, one at 4N spp. The error against
//! the reference must be what noise explains: the relative MSE against the reference may exceed
//! half the relative MSE between the two equal-spp renders (their noise is twice one render's)
//! only by a small factor, and it must fall by at least 2× when the sample count grows 4×
//! (an unbiased renderer falls 4×; a biased one levels off). No pixel may be NaN or infinite.

use render::film::Image;
use render::integrator::{render, RenderSettings};
use std::path::PathBuf;

fn refs() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/refs")
}

/// Relative squared error summed over 2×2 pixel blocks (box-downsampled), normalised by the
/// reference: averaging blocks damps pure noise 4× while keeping any systematic difference.
fn block_rel_mse(a: &Image, r: &Image) -> f64 {
    let (w, h) = (a.width / 2, a.height / 2);
    let mut sum = 0.0;
    for y in 0..h {
        for x in 0..w {
            let avg = |img: &Image| {
                (img.get(2 * x, 2 * y)
                    + img.get(2 * x + 1, 2 * y)
                    + img.get(2 * x, 2 * y + 1)
                    + img.get(2 * x + 1, 2 * y + 1))
                    * 0.25
            };
            let (pa, pr) = (avg(a), avg(r));
            for c in 0..3 {
                let d = (pa[c] - pr[c]) as f64;
                sum += d * d / ((pr[c] as f64).powi(2) + 1e-2);
            }
        }
    }
    sum / (w as f64 * h as f64 * 3.0)
}

fn check_scene(name: &str, spp: u32) {
    let scene_path = refs().join("scenes").join(format!("{name}.xml"));
    let scene = render::loader::load_file(&scene_path, &[]).unwrap_or_else(|e| panic!("{e}"));
    let reference = Image::load_exr(&refs().join("images").join(format!("{name}.exr"))).unwrap();
    let run = |spp, seed| render(&scene, RenderSettings::new(spp, seed), &|_| {}).image;
    let a = run(spp, 1);
    let b = run(spp, 2);
    let c = run(4 * spp, 3);
    for img in [&a, &b, &c] {
        assert!(img.pixels.iter().all(|p| p.is_finite()), "{name}: NaN or Inf pixel");
        assert_eq!((img.width, img.height), (reference.width, reference.height));
    }
    let err_a = block_rel_mse(&a, &reference);
    let err_b = block_rel_mse(&b, &reference);
    let noise = block_rel_mse(&a, &b) / 2.0;
    let err_c = block_rel_mse(&c, &reference);
    let mean_err = 0.5 * (err_a + err_b);
    eprintln!(
        "{name}: relMSE vs Mitsuba {mean_err:.3e} at {spp} spp (noise alone {noise:.3e}), {err_c:.3e} at {} spp",
        4 * spp
    );
    assert!(mean_err < 1.5 * noise + 2e-4, "{name}: error {mean_err:.3e} is more than noise ({noise:.3e}) explains");
    assert!(err_c < 0.5 * mean_err, "{name}: error does not fall with spp ({mean_err:.3e} -> {err_c:.3e})");
}

#[test]
fn cbox_matches_mitsuba() {
    check_scene("cbox", 16);
}

#[test]
fn roughconductors_match_mitsuba() {
    check_scene("roughconductors", 16);
}

#[test]
fn dielectrics_match_mitsuba() {
    check_scene("dielectrics", 16);
}

#[test]
fn textured_mesh_matches_mitsuba() {
    check_scene("textured_mesh", 16);
}

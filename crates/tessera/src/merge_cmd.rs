//! `tessera merge` and `tessera assemble`: the pass files of one split render into its image.

use anyhow::{bail, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug)]
pub struct MergeArgs {
    /// Pass files (`tessera render --samples A..B` or `--crop x0,y0,x1,y1`) of one render:
    /// every sample of every pixel exactly once.
    #[arg(required = true)]
    passes: Vec<PathBuf>,
    /// The image to write, .exr (linear float) or .png (sRGB 8-bit).
    #[arg(long)]
    out: PathBuf,
    /// No summary.
    #[arg(long)]
    quiet: bool,
}

pub fn run(args: MergeArgs) -> Result<()> {
    render::film::check_image_output(&args.out)?;
    for p in &args.passes {
        if p.canonicalize().ok().is_some_and(|c| args.out.canonicalize().ok() == Some(c)) {
            bail!("{}: the output is one of the passes; write the merged image elsewhere", args.out.display());
        }
    }
    let merged = crate::api::merge(&args.passes)?;
    merged.image.save(&args.out)?;
    let c = merged.counts;
    if !args.quiet {
        eprintln!(
            "merged {} passes of a {}x{} render at {} spp ({} samples) into {}",
            args.passes.len(),
            merged.render.width,
            merged.render.height,
            merged.render.spp,
            c.samples,
            args.out.display()
        );
    }
    // Never quiet: a wrong value is reported even with --quiet.
    if c.nonfinite_samples > 0 {
        eprintln!(
            "warning: {} samples had NaN or infinite radiance and were left out of their pixels (the passes' own \
             messages and stats say where)",
            c.nonfinite_samples
        );
    }
    if c.clamped_samples > 0 {
        eprintln!(
            "warning: {} samples had radiance beyond {:e} and were clamped to it",
            c.clamped_samples,
            render::film::SAMPLE_LIMIT
        );
    }
    Ok(())
}

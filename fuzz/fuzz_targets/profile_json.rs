//! The profile reader (`plan::Profile::from_json`, as `tessera plan` reads a profile), then
//! what `tessera plan` does with a profile it accepts: the model for the profile's own render,
//! the standard plans' predictions and a plan search (exhaustive up to four candidates, with
//! level thresholds), and the plan file written for it read back.
#![no_main]

use libfuzzer_sys::fuzz_target;
use plan::{Model, PlanFile, PlanSpec, Profile, SearchOptions, Target};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let profile = Profile::from_json(text);
    tessera_fuzz::note("profile", &profile);
    let Ok(profile) = profile else { return };
    let _ = profile.to_json();
    // As `tessera plan` picks its target (tessera::select_cmd::target_for).
    let spp = u64::from(profile.render.scene_spp.max(1));
    let samples = u64::from(profile.render.width) * u64::from(profile.render.height) * spp;
    let target = Target { samples, threads: profile.render.threads.max(1) };
    let model = Model::new(&profile, target);
    tessera_fuzz::note("model", &model);
    let Ok(model) = model else { return };
    for spec in [PlanSpec::none(&profile), PlanSpec::outputs(&profile), PlanSpec::all(&profile)] {
        let _ = model.predict(&spec);
    }
    let budget = 64.0 * 1048576.0;
    let opts = SearchOptions { budget_bytes: budget, exhaustive_limit: 4, thresholds: true };
    if let Ok(r) = plan::search(&model, opts) {
        let file = PlanFile::new(&profile, target, budget as u64, &r);
        let back = PlanFile::from_json(&file.to_json()).expect("a written plan file reads back");
        let _ = back.to_spec(&profile).expect("a written plan names the profile's nodes");
    }
});

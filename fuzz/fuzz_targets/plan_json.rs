//! The plan file reader as the renderer calls it (`tessera render --strategy plan:FILE`:
//! `render::caching::NodeCache::new` reads the file with `plan::PlanFile::from_json` and picks
//! the scene's nodes it names), over the small_graph scene; and as `tessera` resolves a plan
//! against a profile (`PlanFile::to_spec`), over that scene's profile, then predicted.
#![no_main]

use libfuzzer_sys::fuzz_target;
use plan::{Model, PlanFile, Profile, Target};
use render::caching::{NodeCache, Strategy};
use render::scene::Scene;

const SCENE: &str = include_str!("../../scenes/small/small_graph.xml");
const DOCUMENT: &str = include_str!("../../scenes/small/small_graph.mtlx");
const PROFILE: &str = include_str!("../assets/small_graph.profile.json");

struct Fixture {
    scene: Scene,
    profile: Profile,
}

// `Scene` holds reference-counted graph handles and is not `Sync`: one per fuzzing thread.
thread_local! {
    static FIXTURE: Fixture = {
        let dir = tessera_fuzz::scratch_dir();
        let defines = [("res".to_string(), "4".to_string()), ("spp".to_string(), "1".to_string())];
        let scene = render::loader::load_str_with_files(
            SCENE,
            &dir.join("small_graph.xml"),
            dir,
            &defines,
            &[("small_graph.mtlx", DOCUMENT)],
        )
        .expect("the small_graph scene loads");
        let profile = Profile::from_json(PROFILE).expect("the small_graph profile reads");
        Fixture { scene, profile }
    };
}

fuzz_target!(init: tessera_fuzz::init(), |data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let path = tessera_fuzz::input_file("plan.json", data);
    FIXTURE.with(|f| {
        tessera_fuzz::note("node cache", &NodeCache::new(&f.scene, &Strategy::Plan(path), 16 << 20));
        let Ok(file) = PlanFile::from_json(text) else { return };
        let _ = file.to_json();
        let spec = file.to_spec(&f.profile);
        tessera_fuzz::note("plan over the profile", &spec);
        let Ok(spec) = spec else { return };
        let target = Target { samples: 128 * 128 * 16, threads: 4 };
        let model = Model::new(&f.profile, target).expect("the small_graph profile's model");
        let _ = model.predict(&spec);
        let _ = plan::planfile::nodes_of(&f.profile, &spec);
    });
});

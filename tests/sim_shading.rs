//! One shading model: the grey the renderer draws for a block face (`shaders/scene.wgsl`, on
//! the GPU) is the grey `render::shading::Lighting::grey` predicts on the CPU, which the
//! layout randomiser relies on to keep every edge visible.

use handeye_sim::render::Renderer;
use handeye_sim::render::scene::block_face_id;
use handeye_sim::{Scenario, Simulator};

#[test]
fn rendered_face_greys_match_the_shading_model() {
    let path = format!("{}/scenarios/clutter3.toml", env!("CARGO_MANIFEST_DIR"));
    let mut scenario = Scenario::load(path).expect("scenario");
    for c in &mut scenario.cameras {
        c.noise_sigma = 0.0;
        c.blur_sigma_px = 0.0;
    }
    let sim = Simulator::new(scenario).expect("simulator");
    let mut renderer = Renderer::for_scene(&sim.scene, &sim.events.cameras).expect("renderer");
    let mut poses = Vec::new();
    sim.object_poses(&mut poses);
    let frame = sim.frame_input(&poses);
    let mut grey = vec![0u8; renderer.frame_bytes()];
    let mut ids = vec![0u32; renderer.frame_bytes()];
    renderer.render(&frame, &mut grey).expect("render");
    renderer.render_ids(&frame, &mut ids).expect("render ids");

    let mut faces_checked = 0;
    for (bi, block) in sim.world.blocks.iter().enumerate() {
        let (_, pose) = sim.block_pose(bi);
        for (fi, face) in block.shape.faces.iter().enumerate() {
            let id = block_face_id(bi, fi);
            let mut pixels: Vec<u8> = ids.iter().zip(&grey).filter(|(i, _)| **i == id).map(|(_, g)| *g).collect();
            // Faces seen by a few hundred pixels: their inside, away from anti-aliased or
            // rasterised edges, is one grey.
            if pixels.len() < 200 {
                continue;
            }
            pixels.sort_unstable();
            let median = f64::from(pixels[pixels.len() / 2]);
            let want = 255.0 * sim.events.lighting.grey(block.shades[fi], pose.matrix3 * face.normal);
            assert!((median - want).abs() <= 1.0, "{} face {}: rendered {median}, the shading model says {want:.2}", block.name, face.name);
            faces_checked += 1;
        }
    }
    assert!(faces_checked >= 6, "only {faces_checked} faces big enough to check");
}

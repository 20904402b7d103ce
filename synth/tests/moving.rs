//! Which objects of a synthetic scene move: the novel-view scores single out their
//! pixels (`degs eval`), so `ObjectSpec::moves` must agree with the world's motion.

/// `ObjectSpec::moves` agrees with the world: an object moves exactly when some of its
/// material points (its centre and the corners of a small cube about it) are somewhere
/// else at a later time, on every preset.
#[test]
fn objects_that_move_are_the_ones_the_world_moves() {
    let mut seen = (0, 0);
    for preset in synth::PRESETS {
        let cfg = synth::SynthConfig::preset(preset).unwrap();
        let world = synth::SynthWorld::new(&cfg).unwrap();
        for (k, o) in cfg.objects.iter().enumerate() {
            let points = [
                glam::DVec3::ZERO,
                glam::DVec3::new(0.1, 0.1, 0.1),
                glam::DVec3::new(-0.1, 0.05, -0.07),
            ];
            let moved = [0.13, 0.37, 0.71].iter().any(|&f| {
                let t = f * cfg.duration;
                points.iter().any(|&q| {
                    (world.material_to_world(k, q, t) - world.material_to_world(k, q, 0.0)).length()
                        > 1e-9
                })
            });
            assert_eq!(o.moves(), moved, "{preset}: object {k} ({})", o.name);
            if moved {
                seen.0 += 1;
            } else {
                seen.1 += 1;
            }
        }
    }
    assert!(
        seen.0 > 0 && seen.1 > 0,
        "moving and still objects: {seen:?}"
    );
}

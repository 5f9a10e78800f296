//! The pose stages' training samples are the same for any number of render
//! threads (a GPU run renders on every core, a 2-core run on one): the
//! trained weights must not depend on the machine.

use std::sync::Arc;
use std::time::Duration;

use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_train::data::{DataConfig, Sample, Source, Stream, frame_samples, workspace};

fn config() -> DataConfig {
    DataConfig { augment: true, ..DataConfig::unaugmented(200, 48) }
}

#[test]
fn three_render_threads_deliver_the_samples_of_one_in_seed_order() {
    let set = Arc::new(builtin_objects());
    let first = 4_000_000_017;
    let n = 24;
    let take = |threads: usize| {
        let mut s = Stream::spawn(set.clone(), config(), Source::Rendered, first, 64, None, threads).unwrap();
        (0..n).map(|_| s.recv_timeout(Duration::from_secs(60)).unwrap()).collect::<Vec<Sample>>()
    };
    let one = take(1);
    let three = take(3);
    // What a single loop over the seeds makes.
    let cfg = config();
    let mut ws = workspace(&set, &cfg).unwrap();
    let mut target = RenderTarget::for_intrinsics(&cfg.sampler.intrinsics);
    let direct: Vec<Sample> = (first..)
        .flat_map(|seed| frame_samples(&set, &cfg, seed, &mut ws, &mut target, None).unwrap())
        .take(n)
        .collect();
    for (i, ((a, b), d)) in one.iter().zip(&three).zip(&direct).enumerate() {
        for (name, x) in [("one thread", a), ("three threads", b)] {
            assert_eq!((x.class, &x.points, &x.choose), (d.class, &d.points, &d.choose), "sample {i}: {name}");
            assert_eq!(x.crop, d.crop, "sample {i}: {name}");
        }
    }
    assert!(direct.windows(2).all(|w| w[0].points != w[1].points), "samples differ from one another");
}

#[test]
fn a_stream_with_small_buffers_keeps_up_with_its_reader() {
    // Small capacities: the readers wait on the render threads often.
    let set = Arc::new(builtin_objects());
    let mut s = Stream::spawn(set, config(), Source::Rendered, 9, 2, None, 2).unwrap();
    for _ in 0..30 {
        s.recv_timeout(Duration::from_secs(60)).unwrap();
    }
    assert!(s.check().is_ok());
}

//! The segmenter's training frames are the same for any number of data
//! threads: the trained weights must not depend on the machine's cores.

use std::sync::Arc;
use std::time::Duration;

use fusepose_estimator::seg::SegConfig;
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::RenderTarget;
use fusepose_scene::sampler::SamplerConfig;
use fusepose_train::seg::data::{SegStream, frame_sample, render_camera};

#[test]
fn three_data_threads_deliver_the_frames_of_one_in_seed_order() {
    let set = Arc::new(builtin_objects());
    let cfg = SegConfig::new(set.len());
    let sampler = SamplerConfig::training();
    let first = 0x5e90_0000_0000 + 17;
    let take = |threads: usize| {
        let mut s = SegStream::spawn(set.clone(), cfg.clone(), sampler.clone(), 0.5, first, 4, threads, None).unwrap();
        (0..5).map(|_| s.recv_timeout(Duration::from_secs(60)).unwrap()).collect::<Vec<_>>()
    };
    let one = take(1);
    let three = take(3);
    // What a single loop over the seeds makes, skipped scenes stepped over.
    let mut target = RenderTarget::for_intrinsics(&render_camera(&sampler));
    let direct: Vec<_> = (first..)
        .filter_map(|seed| frame_sample(&set, &cfg, &sampler, seed, true, 0.5, &mut target).unwrap())
        .take(5)
        .collect();
    for (i, ((a, b), d)) in one.iter().zip(&three).zip(&direct).enumerate() {
        assert_eq!(a.input, d.input, "frame {i}: one thread against the direct loop");
        assert_eq!(a.target, d.target, "frame {i}");
        assert_eq!(b.input, d.input, "frame {i}: three threads against the direct loop");
        assert_eq!(b.target, d.target, "frame {i}");
        assert_eq!(b.offsets, d.offsets, "frame {i}");
    }
    assert!(direct.windows(2).all(|w| w[0].input != w[1].input), "frames differ from one another");
}

//! Golden hashes of frames rendered before randomisation and depth-sensor
//! models existed: with `Randomize::Off` and the basic noise model, scenes and
//! frames must stay bit-for-bit identical, so old test splits reproduce.

use super::*;
use crate::builtin::builtin_objects;

/// FNV-1a 64 over byte slices.
fn fnv(h: &mut u64, bytes: &[u8]) {
    for &b in bytes {
        *h ^= b as u64;
        *h = h.wrapping_mul(0x100_0000_01b3);
    }
}

/// Hash of everything a frame consists of: planes, truth and the scene layout.
fn frame_hash(scene: &Scene, truth: &FrameTruth, t: &RenderTarget) -> u64 {
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    fnv(&mut h, t.rgb());
    for z in t.depth_m() {
        fnv(&mut h, &z.to_le_bytes());
    }
    for z in t.depth_u16() {
        fnv(&mut h, &z.to_le_bytes());
    }
    for l in t.labels() {
        fnv(&mut h, &l.to_le_bytes());
    }
    fnv(&mut h, format!("{truth:?}").as_bytes());
    fnv(&mut h, format!("{:?}{:?}", scene.objects, scene.views).as_bytes());
    h
}

/// (case name, hash) of the golden cases.
fn golden_cases() -> Vec<(&'static str, u64)> {
    let set = builtin_objects();
    let k = Intrinsics::YCB_VIDEO;
    let kq = Intrinsics { fx: 533.4, fy: 533.7, cx: 156.5, cy: 120.4, width: 320, height: 240 };
    let mut out = Vec::new();
    let mut t = RenderTarget::for_intrinsics(&k);
    for seed in [0u64, 3] {
        let s = sample_scene(&set, &SamplerConfig::default(), seed).unwrap();
        let truth = render_view(&s, &set, 0, &k, &NoiseConfig::default(), &mut t).unwrap();
        out.push((if seed == 0 { "builtin seed 0 noise" } else { "builtin seed 3 noise" }, frame_hash(&s, &truth, &t)));
    }
    let cfg = SamplerConfig { views: 2, target_occlusion: Some((0.3, 0.7)), intrinsics: kq, ..Default::default() };
    let mut s = sample_scene(&set, &cfg, 5).unwrap();
    s.add_views(&set, &cfg, 1, 9).unwrap();
    let mut tq = RenderTarget::for_intrinsics(&kq);
    for view in 0..3 {
        let truth = render_view(&s, &set, view, &kq, &NoiseConfig::off(), &mut tq).unwrap();
        out.push((["occl view 0", "occl view 1", "occl added view"][view], frame_hash(&s, &truth, &tq)));
    }
    let truth = render_view_labelled(&s, &set, 1, &kq, &NoiseConfig::default(), LabelKind::Class, &mut tq).unwrap();
    out.push(("occl view 1 class labels noise", frame_hash(&s, &truth, &tq)));
    out
}

#[test]
fn off_and_basic_frames_are_bit_identical_to_the_pre_randomisation_renderer() {
    // Computed with the renderer of commit b382669 (before randomisation).
    let expected: [(&str, u64); 6] = [
        ("builtin seed 0 noise", 0xf73b4cbdc6b97bf2),
        ("builtin seed 3 noise", 0xccd287b2639dc132),
        ("occl view 0", 0x72804bd4e60addab),
        ("occl view 1", 0x8e1eebeeacb0615a),
        ("occl added view", 0x469b22423083b2aa),
        ("occl view 1 class labels noise", 0x3193258194142199),
    ];
    let got = golden_cases();
    assert_eq!(got.len(), expected.len());
    let mut changed = Vec::new();
    for ((name, h), (ename, eh)) in got.iter().zip(expected.iter()) {
        assert_eq!(name, ename);
        if h != eh {
            changed.push(format!("{name}: 0x{h:016x}"));
        }
    }
    assert!(changed.is_empty(), "frames changed: {changed:?}");
}

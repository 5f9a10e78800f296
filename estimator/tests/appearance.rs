//! The appearance check on rendered built-in scenes: it keeps a true pose
//! (perturbed by a few degrees and millimetres, like an estimate), and from a
//! turned (wrong) pose it often turns back to the truth.

use fusepose_estimator::appearance::{AppearanceCheck, AppearanceConfig};
use fusepose_estimator::{ColorFormat, DepthPlane, FrameView};
use fusepose_scene::builtin::builtin_objects;
use fusepose_scene::render::{NoiseConfig, RenderTarget};
use fusepose_scene::sampler::{SamplerConfig, render_view, sample_scene};
use fusepose_scene::{Intrinsics, Pose};
use nalgebra::{Matrix3, Vector3};

const PERTURB_DEG: f32 = 6.0;
const PERTURB_M: f32 = 0.005;

fn parts(p: &Pose) -> (Matrix3<f32>, Vector3<f32>) {
    (p.rotation.to_rotation_matrix().into_inner().cast::<f32>(), p.translation.vector.cast::<f32>())
}

#[test]
fn keeps_true_poses_and_turns_wrong_ones_back() {
    let set = builtin_objects();
    let check = AppearanceCheck::new(&set, AppearanceConfig::default());
    let k = Intrinsics::YCB_VIDEO;
    let mut target = RenderTarget::for_intrinsics(&k);
    let (mut kept, mut truths, mut back, mut turned_cases) = (0, 0, 0, 0);
    for seed in 0..12u64 {
        let scene = sample_scene(&set, &SamplerConfig { views: 1, ..Default::default() }, 1000 + seed).unwrap();
        let truth = render_view(&scene, &set, 0, &k, &NoiseConfig::default(), &mut target).unwrap();
        let frame = FrameView {
            intrinsics: k,
            color_format: ColorFormat::Rgb8,
            color: target.rgb(),
            depth: DepthPlane::F32(target.depth_m()),
            labels: None,
        };
        for (o, obj) in truth.objects.iter().enumerate() {
            let ci = obj.class_id as usize - 1;
            let turns = check.turns(ci);
            if turns.is_empty() || obj.visible_fraction < 0.5 {
                continue;
            }
            let (r, t) = parts(&obj.pose);
            // A pose estimate's typical error: a few degrees and millimetres.
            let jitter = |i: u64| ((seed * 7 + o as u64 * 3 + i) as f32 * 2.399).sin();
            let dr = nalgebra::Rotation3::from_scaled_axis(Vector3::new(jitter(0), jitter(1), jitter(2)) * PERTURB_DEG.to_radians() / 1.7);
            let r = dr.matrix() * r;
            let t = t + Vector3::new(jitter(3), jitter(4), jitter(5)) * PERTURB_M / 1.7;
            let c = check.choose(ci, &frame, &r, &t);
            truths += 1;
            kept += c.turn.is_none() as usize;
            eprintln!("seed {seed} obj {o} {} vis {:.2}: at truth score {:.3} -> {:?} {:.3}", set.objects[ci].name, obj.visible_fraction, c.estimate_score, c.turn, c.chosen_score);
            // From a wrong pose: the truth turned by its first few turns.
            for turn in turns.iter().take(3) {
                let (rw, tw) = (r * turn.rotation, r * turn.shift + t);
                let c = check.choose(ci, &frame, &rw, &tw);
                turned_cases += 1;
                // Back within 25° of the (perturbed) truth: the nearest turn.
                let err = nalgebra::Rotation3::from_matrix_unchecked(c.rotation.transpose() * r).angle().to_degrees();
                back += (err < 25.0) as usize;
                eprintln!("    from turn: score {:.3} -> {:?} {:.3} rot err {:.1}°", c.estimate_score, c.turn, c.chosen_score, err);
            }
        }
    }
    eprintln!("kept {kept}/{truths} true poses, turned back {back}/{turned_cases}");
    assert!(truths >= 20);
    assert!(kept * 10 >= truths * 9, "kept {kept}/{truths}");
    // Measured 75/133 (2026-11-23): subtle prints (a can turned by 15°) stay ambiguous.
    assert!(back * 100 >= turned_cases * 45, "back {back}/{turned_cases}");
}

/// Analysis helper (not a check): for each estimate in a BOP results CSV
/// (`FP_CSV`) on a dataset (`FP_DS`, split folder), prints the estimate's
/// colour score, the best turn's score and both rotation errors to the
/// nearest ground truth of its class.
#[test]
#[ignore]
fn dump_scores() {
    use fusepose_scene::bop::BopDataset;
    let (Some(csv), Some(ds)) = (std::env::var_os("FP_CSV"), std::env::var_os("FP_DS")) else { return };
    let set = builtin_objects();
    let cfg = AppearanceConfig { min_gain: -10.0, max_residual_ratio: 10.0, ..AppearanceConfig::default() };
    let check = AppearanceCheck::new(&set, cfg);
    let ds = BopDataset::open(std::path::PathBuf::from(ds)).unwrap();
    let text = std::fs::read_to_string(csv).unwrap();
    let rows: Vec<Vec<String>> = text.lines().skip(1).map(|l| l.split(',').map(String::from).collect()).collect();
    for i in 0..ds.len() {
        let f = ds.load(i).unwrap();
        let view = FrameView {
            intrinsics: f.intrinsics,
            color_format: ColorFormat::Rgb8,
            color: &f.rgb,
            depth: DepthPlane::U16 { data: &f.depth, scale: f.depth_unit_m as f32 },
            labels: None,
        };
        for r in rows.iter().filter(|r| r[0].parse::<u32>().unwrap() == f.id.scene_id && r[1].parse::<u32>().unwrap() == f.id.im_id) {
            let obj: u16 = r[2].parse().unwrap();
            let ci = obj as usize - 1;
            if check.turns(ci).is_empty() {
                continue;
            }
            let rv: Vec<f32> = r[4].split(' ').map(|x| x.parse().unwrap()).collect();
            let tv: Vec<f32> = r[5].split(' ').map(|x| x.parse::<f32>().unwrap() / 1000.0).collect();
            let rot = Matrix3::from_row_slice(&rv);
            let t = Vector3::new(tv[0], tv[1], tv[2]);
            let Some(gt) = f.gt.iter().filter(|g| g.obj_id == obj).min_by(|a, b| {
                let d = |g: &&fusepose_scene::bop::BopGt| (parts(&g.pose).1 - t).norm();
                d(a).total_cmp(&d(b))
            }) else { continue };
            let (gr, _) = parts(&gt.pose);
            let ang = |m: &Matrix3<f32>| nalgebra::Rotation3::from_matrix_unchecked(m.transpose() * gr).angle().to_degrees();
            let c = check.choose(ci, &view, &rot, &t);
            println!("ROW {} {} {} {:.2} {:.4} {:.4} {:.1} {:.1}", f.id.scene_id, f.id.im_id, obj, gt.visib_fract, c.estimate_score, c.chosen_score, ang(&rot), ang(&c.rotation));
        }
    }
}

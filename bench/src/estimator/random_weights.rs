//! A randomly initialised weight file for the built-in objects, built in
//! memory (no trainer, no burn): the default architecture
//! ([`NetConfig::new`]), He-uniform weights, small biases, the metadata the
//! engine checks. For timing the network before trained weights exist —
//! its poses are meaningless.

use std::collections::HashMap;

use fusepose_estimator::net::meta::{self, TrainRecord, object_entries};
use fusepose_estimator::net::{NetConfig, WeightFile};
use fusepose_scene::ObjectSet;
use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use safetensors::tensor::{Dtype, TensorView};

/// Random weights of the default architecture for `set`.
pub fn random_weights(set: &ObjectSet, seed: u64) -> anyhow::Result<WeightFile> {
    let cfg = NetConfig::new(set.len());
    let mut rng = Pcg64Mcg::seed_from_u64(seed);
    let data: Vec<(String, Vec<usize>, Vec<u8>)> = cfg
        .tensor_shapes()
        .into_iter()
        .map(|(name, shape)| {
            // Linear weights are [in, out], convolutions [out, in, 3, 3].
            let fan_in = match shape.as_slice() {
                [_, i, kh, kw] => i * kh * kw,
                [i, _] => *i,
                _ => 0,
            };
            let bound = if fan_in == 0 { 0.01 } else { (6.0 / fan_in as f32).sqrt() };
            let n: usize = shape.iter().product();
            let bytes = (0..n).flat_map(|_| rng.random_range(-bound..=bound).to_le_bytes()).collect();
            (name, shape, bytes)
        })
        .collect();
    let views = data
        .iter()
        .map(|(name, shape, bytes)| Ok((name.clone(), TensorView::new(Dtype::F32, shape.clone(), bytes)?)))
        .collect::<Result<Vec<_>, safetensors::SafeTensorError>>()?;
    let record = TrainRecord { seed, data: "random init (fusepose-bench, untrained)".into(), ..TrainRecord::default() };
    let metadata = HashMap::from([
        (meta::KEY_FORMAT.to_string(), meta::FORMAT.to_string()),
        (meta::KEY_CONFIG.to_string(), serde_json::to_string(&cfg)?),
        (meta::KEY_OBJECTS.to_string(), serde_json::to_string(&object_entries(set))?),
        (meta::KEY_TRAIN.to_string(), serde_json::to_string(&record)?),
    ]);
    let bytes = safetensors::serialize(views, Some(metadata))?;
    Ok(WeightFile::from_bytes(&bytes)?)
}

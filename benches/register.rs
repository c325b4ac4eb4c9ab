//! Registration speed on the default synth case (400k reference, 300k scan points, random
//! pose, noise, outliers, defects), the case of BENCHMARKS.md's side-by-side with Open3D
//! (benches/peers/register_open3d.py).
use criterion::{criterion_group, criterion_main, Criterion};
use polishbot::register::correspondences::match_features;
use polishbot::register::fpfh::{Fpfh, FPFH_BINS};
use polishbot::register::{register, RegisterConfig};
use polishbot::synth::{synth, SynthConfig};

fn bench(c: &mut Criterion) {
    let case = synth(&SynthConfig::default()).expect("synth");
    let cfg = RegisterConfig::default();
    let mut g = c.benchmark_group("register");
    g.sample_size(10);
    g.bench_function("synth_default_300k_onto_400k", |b| {
        b.iter(|| register(&case.scan, &case.reference, &cfg).expect("registration"))
    });
    // The matching step alone at that case's sizes (7k scan keypoints, 42k reference
    // descriptors): a brute-force scan, so the descriptors' values do not change its cost.
    let descriptors = |n: usize, seed: usize| -> Vec<Fpfh> {
        (0..n)
            .map(|i| {
                std::array::from_fn(|d| {
                    ((i * 31 + d * 7 + seed) % 97) as f64 / (1 + d % FPFH_BINS) as f64
                })
            })
            .collect()
    };
    let (scan, reference) = (descriptors(7_000, 1), descriptors(42_000, 2));
    g.bench_function("match_features_7k_onto_42k", |b| {
        b.iter(|| match_features(&scan, &reference, true, 3_000))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

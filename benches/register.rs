//! Registration speed on the default synth case (400k reference, 300k scan points, random
//! pose, noise, outliers, defects), the case of BENCHMARKS.md's side-by-side with Open3D
//! (benches/peers/register_open3d.py).
use criterion::{criterion_group, criterion_main, Criterion};
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
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

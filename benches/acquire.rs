//! Merge speed on the goal case of issue 10: 36 synthetic turntable views of 100k points each
//! (10 degree steps, true angles off by up to 3 degrees) with the table axis given (a
//! calibrated table). Goal: under 10 s on 2 cores. Prints one merge's step times first.
use criterion::{criterion_group, criterion_main, Criterion};
use polishbot::acquire::{merge_views, MergeConfig};
use polishbot::synth::{synth, SynthConfig, TurntableConfig};

fn bench(c: &mut Criterion) {
    let cfg = SynthConfig {
        turntable: Some(TurntableConfig {
            views: 36,
            ..TurntableConfig::default()
        }),
        ..SynthConfig::default()
    };
    let case = synth(&cfg).expect("synth");
    let (views, _) = case.turntable.expect("turntable views");
    let names: Vec<String> = (0..views.len()).map(|i| format!("view_{i:03}")).collect();
    let angles: Vec<f64> = (0..views.len()).map(|i| i as f64 * 10.0).collect();
    let merge = MergeConfig {
        axis: Some([0.0, 0.0, 1.0]),
        ..MergeConfig::default()
    };
    // One merge first: where its time goes (the report's step times).
    let m = merge_views(&views, &names, &angles, &merge).expect("merge");
    eprintln!("merge_36_views_100k steps (s): {:?}", m.times);
    let mut g = c.benchmark_group("acquire");
    g.sample_size(10);
    g.bench_function("merge_36_views_100k", |b| {
        b.iter(|| merge_views(&views, &names, &angles, &merge).expect("merge"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Comparison speed on the 400k-reference / 300k-scan femoral_dm case, 20k and 100k core
//! points (reference[::stride], as benches/peers/m3c2_py4dgeo.py picks them), 2 threads.
//! Times include building the k-d trees (py4dgeo's numbers include its own).
use criterion::{criterion_group, criterion_main, Criterion};
use polishbot::cloud::Units;
use polishbot::compare::{compare, CompareConfig, Method};
use polishbot::synth::{synth, SynthConfig};

fn bench(c: &mut Criterion) {
    let _ = rayon::ThreadPoolBuilder::new()
        .num_threads(2)
        .build_global();
    let data = concat!(env!("CARGO_MANIFEST_DIR"), "/../shared/data/");
    let cfg = SynthConfig {
        seed: 11,
        mesh: Some(format!("{data}femoral_dm.stl").into()),
        surface: Some(format!("{data}femoral_dm_contact.stl").into()),
        units: Some(Units::M),
        ..SynthConfig::default()
    };
    let mut case = synth(&cfg).expect("synth");
    if let Ok(dir) = std::env::var("POLISHBOT_BENCH_DIR") {
        case.write(std::path::Path::new(&dir)).expect("write case");
    }
    case.scan.transform(&case.truth.pose().unwrap());
    let mut group = c.benchmark_group("compare");
    group.sample_size(10);
    for count in [20_000usize, 100_000] {
        let stride = case.reference.len() / count;
        let idx: Vec<usize> = (0..case.reference.len())
            .step_by(stride)
            .take(count)
            .collect();
        let core = case.reference.select(&idx);
        for method in [Method::Classic, Method::Adaptive] {
            let cfg = CompareConfig {
                method,
                radius: Some(0.6),
                max_distance: 1.0,
                ..CompareConfig::default()
            };
            group.bench_function(format!("{method:?}_{count}").to_lowercase(), |b| {
                b.iter(|| compare(&core, &case.reference, &case.scan, &cfg).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

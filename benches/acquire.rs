//! Merge speed on the goal case of issue 10: 36 synthetic turntable views of 100k points each
//! (10 degree steps, true angles off by up to 3 degrees) with the table axis given (a
//! calibrated table). Goal: under 10 s on 2 cores. Prints one merge's step times first, its
//! worst pose against the synth truth and a fingerprint of the merged cloud (equal
//! fingerprints of two builds: the same cloud bit for bit).
use std::hash::{DefaultHasher, Hash, Hasher};

use criterion::{criterion_group, criterion_main, Criterion};
use polishbot::acquire::{merge_views, MergeConfig, Merged};
use polishbot::cloud::transform::{isometry_from_rows, pose_difference};
use polishbot::synth::{synth, SynthConfig, TurntableConfig, TurntableTruth};

/// Worst rotation (degrees) and translation (mm) of a merged view pose against the truth.
fn worst_pose(m: &Merged, truth: &TurntableTruth) -> [f64; 2] {
    m.views
        .iter()
        .zip(&truth.views)
        .fold([0.0f64; 2], |w, (v, t)| {
            let t = isometry_from_rows(&t.view_to_first).expect("truth pose");
            let (dr, dt) = pose_difference(&t, &v.pose);
            [w[0].max(dr), w[1].max(dt)]
        })
}

/// Hash of the merged cloud's coordinates' bits.
fn fingerprint(m: &Merged) -> u64 {
    let mut h = DefaultHasher::new();
    for p in &m.cloud.points {
        p.coords.iter().for_each(|c| c.to_bits().hash(&mut h));
    }
    h.finish()
}

fn bench(c: &mut Criterion) {
    let cfg = SynthConfig {
        turntable: Some(TurntableConfig {
            views: 36,
            ..TurntableConfig::default()
        }),
        ..SynthConfig::default()
    };
    let case = synth(&cfg).expect("synth");
    let (views, truth) = case.turntable.expect("turntable views");
    let names: Vec<String> = (0..views.len()).map(|i| format!("view_{i:03}")).collect();
    let angles: Vec<f64> = (0..views.len()).map(|i| i as f64 * 10.0).collect();
    let merge = MergeConfig {
        axis: Some([0.0, 0.0, 1.0]),
        ..MergeConfig::default()
    };
    // One merge first: where its time goes (the report's step times) and what it gives.
    let m = merge_views(&views, &names, &angles, &merge).expect("merge");
    eprintln!("merge_36_views_100k steps (s): {:?}", m.times);
    let [dr, dt] = worst_pose(&m, &truth);
    eprintln!(
        "merge_36_views_100k: worst pose {dr:.5} deg {dt:.5} mm against the truth; {} points, \
         fingerprint {:016x}",
        m.cloud.len(),
        fingerprint(&m)
    );
    let mut g = c.benchmark_group("acquire");
    g.sample_size(10);
    g.bench_function("merge_36_views_100k", |b| {
        b.iter(|| merge_views(&views, &names, &angles, &merge).expect("merge"))
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Reading speed: a 2M-point binary PLY (positions and normals, float) from memory and from disk.
use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use polishbot::cloud::{self, Format, PlyPrecision, PointCloud, Units};

fn two_million() -> PointCloud {
    let n = 2_000_000;
    PointCloud {
        points: (0..n)
            .map(|i| Point3::new(i as f64 * 1e-3, (i % 997) as f64, (i % 13) as f64 * 0.5))
            .collect(),
        normals: Some(
            (0..n)
                .map(|i| Vector3::new(0.0, (i as f64).sin(), (i as f64).cos()))
                .collect(),
        ),
        fields: Vec::new(),
    }
}

fn bench(c: &mut Criterion) {
    let cloud = two_million();
    let bytes = cloud::write_ply_bytes(&cloud, None, PlyPrecision::F32);
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("two_million.ply");
    std::fs::write(&path, &bytes).unwrap();
    let mut g = c.benchmark_group("read");
    g.sample_size(10);
    g.bench_function("ply_binary_float_2M_parse", |b| {
        b.iter(|| cloud::parse(&bytes, Format::Ply).unwrap())
    });
    g.bench_function("ply_binary_float_2M_load_file", |b| {
        b.iter(|| cloud::load(&path, None, Some(Units::Mm)).unwrap())
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

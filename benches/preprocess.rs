//! Preprocessing speed: the statistical outlier filter on 300k and 1M points of the femoral
//! part (sampled, noisy, 1 % scattered outliers). The clouds are written as PLY files under
//! `$POLISHBOT_BENCH_DATA` (default: the system temp dir, `polishbot-bench/`) so that
//! `benches/peers/sor.py` can time Open3D on exactly the same input. Run both with two threads:
//!   RAYON_NUM_THREADS=2 cargo bench --bench preprocess
//!   OMP_NUM_THREADS=2 $POLISHBOT_PYTHON benches/peers/sor.py
use std::path::{Path, PathBuf};

use criterion::{criterion_group, criterion_main, Criterion};
use nalgebra::{Point3, Vector3};
use polishbot::cloud::{self, PlyPrecision, PointCloud, Units};
use polishbot::preprocess::{statistical_outlier_filter, SorConfig};
use rand::{Rng, SeedableRng};

fn bench_dir() -> PathBuf {
    let dir = std::env::var_os("POLISHBOT_BENCH_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| std::env::temp_dir().join("polishbot-bench"));
    std::fs::create_dir_all(&dir).expect("bench data dir");
    dir
}

/// The femoral part sampled at `n` points, 0.02 mm noise, 1 % uniform outliers in its box.
fn part_cloud(n: usize) -> PointCloud {
    let stl = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data/femoral_dm.stl");
    let mesh = match cloud::load(&stl, None, Some(Units::M))
        .expect("femoral_dm.stl")
        .geometry
    {
        cloud::Geometry::Mesh { mesh, .. } => mesh,
        _ => panic!("femoral_dm.stl is not a mesh"),
    };
    let outliers = n / 100;
    let mut points = cloud::sample_mesh(&mesh, n - outliers, 1)
        .unwrap()
        .cloud
        .points;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let bbox = cloud::Aabb::of(&points).unwrap();
    for p in points.iter_mut() {
        *p += Vector3::new(rng.gen(), rng.gen(), rng.gen()).map(|v: f64| (v - 0.5) * 0.04);
    }
    for _ in 0..outliers {
        let t = Vector3::new(rng.gen(), rng.gen(), rng.gen());
        points.push(bbox.min + bbox.extent().component_mul(&t));
    }
    PointCloud::from_points(points)
}

fn bench_file(n: usize) -> PathBuf {
    let path = bench_dir().join(format!("sor_{}k.ply", n / 1000));
    if !path.exists() {
        cloud::write_ply(&path, &part_cloud(n), None, PlyPrecision::F64).unwrap();
    }
    path
}

fn sor(c: &mut Criterion) {
    let mut group = c.benchmark_group("sor");
    group.sample_size(10);
    for n in [300_000, 1_000_000] {
        let path = bench_file(n);
        let cloud = cloud::load_cloud(&path, None, Some(Units::Mm)).unwrap();
        let _: &[Point3<f64>] = &cloud.points;
        for (name, count_self) in [("paper", false), ("open3d", true)] {
            let cfg = SorConfig {
                count_self,
                ..SorConfig::default()
            };
            group.bench_function(format!("{name}_{}k", n / 1000), |b| {
                b.iter(|| statistical_outlier_filter(&cloud, &cfg).unwrap())
            });
        }
    }
    group.finish();
}

criterion_group!(benches, sor);
criterion_main!(benches);

//! Foundation: file I/O against real files and known answers, bad input, CLI, synth.
mod common;

use common::{polishbot, shared_data, tempdir};
use nalgebra::{Point3, Vector3};
use polishbot::cloud::{self, Format, Geometry, PlyPrecision, PointCloud, ScalarField, Units};
use polishbot::synth::{synth, SynthConfig, Truth};

fn info_json(args: &[&str]) -> serde_json::Value {
    let out = common::succeed(polishbot().arg("info").args(args));
    serde_json::from_slice(&out.stdout).unwrap()
}

#[test]
fn info_on_the_femoral_mesh_matches_its_provenance() {
    let path = shared_data("femoral_dm.stl");
    let v = info_json(&[path.to_str().unwrap(), "--units", "m"]);
    assert_eq!(v["points"], 12_223);
    assert_eq!(v["points_are"], "unique vertices");
    assert_eq!(v["faces"], 24_442);
    let ext: Vec<f64> = v["extent"]
        .as_array()
        .unwrap()
        .iter()
        .map(|x| x.as_f64().unwrap())
        .collect();
    for (got, want) in ext.iter().zip([66.4, 55.6, 75.1]) {
        assert!((got - want).abs() <= 0.1, "extent {ext:?}");
    }
    assert_eq!(v["units"], "m");
}

#[test]
fn metre_sized_file_without_units_is_refused_with_a_hint() {
    let path = shared_data("femoral_dm.stl");
    let out = polishbot()
        .args(["info", path.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    assert!(
        err.contains("femoral_dm.stl") && err.contains("--units m"),
        "{err}"
    );
}

#[test]
fn bunny_range_scans_read_with_their_extra_elements() {
    for (name, n) in [("bunny/bun000.ply", 40_256), ("bunny/bun045.ply", 40_097)] {
        let c = cloud::load_cloud(&shared_data(name), None, Some(Units::M)).unwrap();
        assert_eq!(c.len(), n, "{name}");
        // The bunny is about 15 cm across.
        let b = cloud::Aabb::of(&c.points).unwrap();
        assert!(b.extent().max() > 100.0 && b.extent().max() < 200.0);
    }
}

fn sample_cloud(n: usize) -> PointCloud {
    let points = (0..n)
        .map(|i| {
            Point3::new(
                i as f64 * 0.1 + 1.0 / 3.0,
                (i as f64).sin() * 7.0,
                -2.5e-3 * i as f64,
            )
        })
        .collect();
    let normals = (0..n)
        .map(|i| Vector3::new((i as f64).cos(), (i as f64).sin(), 0.0))
        .collect();
    let fields = vec![ScalarField {
        name: "distance".into(),
        values: (0..n).map(|i| (i as f32 * 0.25 - 3.0) as f64).collect(),
    }];
    PointCloud {
        points,
        normals: Some(normals),
        fields,
    }
}

#[test]
fn ply_round_trip_is_bitwise() {
    let c = sample_cloud(1000);
    let bytes = cloud::write_ply_bytes(&c, None, PlyPrecision::F64);
    let Geometry::Cloud(back) = cloud::parse(&bytes, Format::Ply).unwrap() else {
        panic!("cloud expected")
    };
    assert_eq!(back, c);
    // Float PLY: values that are f32 survive bit for bit.
    let mut c32 = c.clone();
    c32.points
        .iter_mut()
        .for_each(|p| p.coords = p.coords.map(|v| v as f32 as f64));
    c32.normals
        .as_mut()
        .unwrap()
        .iter_mut()
        .for_each(|n| *n = n.map(|v| v as f32 as f64));
    let bytes = cloud::write_ply_bytes(&c32, None, PlyPrecision::F32);
    let Geometry::Cloud(back) = cloud::parse(&bytes, Format::Ply).unwrap() else {
        panic!("cloud expected")
    };
    for (a, b) in back.points.iter().zip(&c32.points) {
        assert!(a
            .coords
            .iter()
            .zip(b.coords.iter())
            .all(|(x, y)| x.to_bits() == y.to_bits()));
    }
    assert_eq!(back, c32);
    // A mesh keeps its faces.
    let faces = vec![[0u32, 1, 2], [2, 3, 0]];
    let bytes = cloud::write_ply_bytes(&c.select(&[0, 1, 2, 3]), Some(&faces), PlyPrecision::F64);
    let Geometry::Mesh { mesh, .. } = cloud::parse(&bytes, Format::Ply).unwrap() else {
        panic!("mesh expected")
    };
    assert_eq!(mesh.faces, faces);
}

#[test]
fn csv_round_trip_is_exact() {
    let dir = tempdir();
    // Several of write_csv's parallel row blocks (8192 rows each).
    let c = sample_cloud(20_000);
    let path = dir.path().join("c.csv");
    cloud::write_csv(&path, &c).unwrap();
    let back = cloud::load_cloud(&path, None, Some(Units::Mm)).unwrap();
    assert_eq!(back, c);
}

#[test]
fn every_format_reads_the_same_tetrahedron() {
    let expect: [[f64; 3]; 4] = [
        [0.0, 0.0, 0.0],
        [10.0, 0.0, 0.0],
        [0.0, 10.0, 0.0],
        [0.0, 0.0, 10.0],
    ];
    let faces_expect = 4;
    let meshes = tetrahedron_files(expect);
    for (name, bytes, format) in meshes {
        let g = cloud::parse(&bytes, format).unwrap_or_else(|e| panic!("{name}: {e}"));
        let Geometry::Mesh { mesh, .. } = g else {
            panic!("{name}: mesh expected")
        };
        assert_eq!(mesh.faces.len(), faces_expect, "{name}");
        let mut pts: Vec<[f64; 3]> = mesh.vertices.iter().map(|p| [p.x, p.y, p.z]).collect();
        pts.sort_by(|a, b| a.partial_cmp(b).unwrap());
        let mut want = expect.to_vec();
        want.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(pts, want, "{name}");
        // Outward winding: the signed volume is positive (1000/6).
        let vol: f64 = mesh
            .faces
            .iter()
            .map(|f| {
                let [a, b, c] = f.map(|v| mesh.vertices[v as usize].coords);
                a.dot(&b.cross(&c)) / 6.0
            })
            .sum();
        assert!((vol - 1000.0 / 6.0).abs() < 1e-9, "{name}: volume {vol}");
    }
    let pcd_ascii = "# .PCD v0.7\nVERSION 0.7\nFIELDS x y z normal_x normal_y normal_z intensity\nSIZE 4 4 4 4 4 4 4\nTYPE F F F F F F F\nCOUNT 1 1 1 1 1 1 1\nWIDTH 2\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS 2\nDATA ascii\n1 2 3 0 0 1 7\n4 5 6 1 0 0 8\n";
    let mut pcd_bin = b"VERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 2\nTYPE F F F I\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA binary\n".to_vec();
    for (p, l) in [([1f32, 2.0, 3.0], -5i16), ([4.0, 5.0, 6.0], 9)] {
        p.iter()
            .for_each(|c| pcd_bin.extend_from_slice(&c.to_le_bytes()));
        pcd_bin.extend_from_slice(&l.to_le_bytes());
    }
    let xyz = "x,y,z,nx,ny,nz,intensity\n1,2,3,0,0,1,7\n4,5,6,1,0,0,8\n";
    let txt = "# no header\n1 2 3\n4\t5  6\n";
    for (name, bytes, format, field) in [
        (
            "ascii pcd",
            pcd_ascii.as_bytes().to_vec(),
            Format::Pcd,
            Some(("intensity", [7.0, 8.0])),
        ),
        (
            "binary pcd",
            pcd_bin,
            Format::Pcd,
            Some(("label", [-5.0, 9.0])),
        ),
        (
            "csv",
            xyz.as_bytes().to_vec(),
            Format::Xyz,
            Some(("intensity", [7.0, 8.0])),
        ),
        ("txt", txt.as_bytes().to_vec(), Format::Xyz, None),
    ] {
        let Geometry::Cloud(c) =
            cloud::parse(&bytes, format).unwrap_or_else(|e| panic!("{name}: {e}"))
        else {
            panic!()
        };
        assert_eq!(
            c.points,
            vec![Point3::new(1.0, 2.0, 3.0), Point3::new(4.0, 5.0, 6.0)],
            "{name}"
        );
        if let Some((f, v)) = field {
            assert_eq!(c.field(f).unwrap(), &v, "{name}");
        }
    }
}

/// The tetrahedron with the corners `expect` (faces wound outward) as the bytes of each mesh
/// format: ASCII and binary STL, OBJ (with texture indices and negative indices), OFF, ASCII
/// and big-endian binary PLY; each with its name and format.
fn tetrahedron_files(expect: [[f64; 3]; 4]) -> Vec<(&'static str, Vec<u8>, Format)> {
    let stl_ascii = "solid t\n".to_string()
        + &[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]
            .iter()
            .map(|f: &[usize; 3]| {
                let v: String = f
                    .iter()
                    .map(|&i| {
                        format!(
                            "vertex {} {} {}\n",
                            expect[i][0], expect[i][1], expect[i][2]
                        )
                    })
                    .collect();
                format!("facet normal 0 0 0\nouter loop\n{v}endloop\nendfacet\n")
            })
            .collect::<String>()
        + "endsolid t\n";
    let mut stl_bin = vec![0u8; 80];
    stl_bin.extend_from_slice(&4u32.to_le_bytes());
    for f in [[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        stl_bin.extend_from_slice(&[0u8; 12]);
        for i in f {
            for c in expect[i] {
                stl_bin.extend_from_slice(&(c as f32).to_le_bytes());
            }
        }
        stl_bin.extend_from_slice(&[0, 0]);
    }
    let obj =
        "# t\nv 0 0 0\nv 10 0 0\nv 0 10 0\nv 0 0 10\nf 1 3 2\nf 1/1 2/2 4/4\nf -4 -1 -2\nf 2 3 4\n";
    let off = "OFF\n# comment\n4 4 6\n0 0 0\n10 0 0\n0 10 0\n0 0 10\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    let ply_ascii = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 4\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n10 0 0\n0 10 0\n0 0 10\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n";
    let mut ply_be = b"ply\nformat binary_big_endian 1.0\nelement vertex 4\nproperty double x\nproperty double y\nproperty double z\nelement face 4\nproperty list uchar uint vertex_indices\nend_header\n".to_vec();
    for p in expect {
        for c in p {
            ply_be.extend_from_slice(&c.to_be_bytes());
        }
    }
    for f in [[0u32, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]] {
        ply_be.push(3);
        f.iter()
            .for_each(|v| ply_be.extend_from_slice(&v.to_be_bytes()));
    }
    vec![
        ("ascii stl", stl_ascii.into_bytes(), Format::Stl),
        ("binary stl", stl_bin, Format::Stl),
        ("obj", obj.as_bytes().to_vec(), Format::Obj),
        ("off", off.as_bytes().to_vec(), Format::Off),
        ("ascii ply", ply_ascii.as_bytes().to_vec(), Format::Ply),
        ("big-endian ply", ply_be, Format::Ply),
    ]
}

/// Bad files give a one-line error naming the file and the place.
#[test]
fn bad_input_names_file_and_place() {
    let dir = tempdir();
    let good_head = "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n";
    let mut truncated = good_head.as_bytes().to_vec();
    truncated.extend_from_slice(&[0u8; 20]);
    let mut nan = good_head.as_bytes().to_vec();
    for v in [1f32, 2.0, 3.0, 4.0, f32::NAN, 6.0, 7.0, 8.0, 9.0] {
        nan.extend_from_slice(&v.to_le_bytes());
    }
    let body_start = format!("byte {}", good_head.len());
    let cases: Vec<(&str, Vec<u8>, &str)> = vec![
        ("empty.ply", vec![], "byte 0"),
        ("truncated.ply", truncated, &body_start),
        ("short.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nend_header\n1 2 3\n4 5 6\n".to_vec(), "line 10"),
        ("nan.ply", nan, "point 1"),
        ("type.ply", b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n".to_vec(), "line 4"),
        ("faces.off", b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n".to_vec(), "line 6"),
        ("faces.ply", b"ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n0 1 0\n3 0 1 9\n".to_vec(), "face 0"),
        ("inf.xyz", b"1 2 3\n4 inf 6\n".to_vec(), "line 2"),
        ("count.stl", { let mut b = vec![0u8; 80]; b.extend_from_slice(&5u32.to_le_bytes()); b.extend_from_slice(&[0u8; 60]); b }, "byte 80"),
    ];
    for (name, bytes, place) in cases {
        let path = dir.path().join(name);
        std::fs::write(&path, &bytes).unwrap();
        let out = polishbot()
            .args(["info", path.to_str().unwrap(), "--units", "mm"])
            .output()
            .unwrap();
        assert!(!out.status.success(), "{name} accepted");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(err.trim_end().lines().count(), 1, "{name}: {err}");
        assert!(
            err.contains(name) && err.contains(place),
            "{name}: expected {place:?} in {err}"
        );
        assert!(!err.contains("panicked"), "{name}: {err}");
    }
    let out = polishbot()
        .args(["info", dir.path().to_str().unwrap()])
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("directory"), "{err}");
}

#[test]
fn every_subcommand_of_the_contract_is_in_help() {
    let out = polishbot().arg("--help").output().unwrap();
    let help = String::from_utf8_lossy(&out.stdout);
    for cmd in [
        "info",
        "merge",
        "filter",
        "register",
        "inspect",
        "plan",
        "run",
        "arm",
        "calibrate",
        "synth",
        "demo",
    ] {
        assert!(
            help.contains(&format!("  {cmd} ")) || help.contains(&format!("  {cmd}\n")),
            "{cmd} missing from --help:\n{help}"
        );
    }
}

fn small_config(seed: u64) -> SynthConfig {
    SynthConfig {
        seed,
        reference_points: 60_000,
        scan_points: 50_000,
        ..SynthConfig::default()
    }
}

#[test]
fn synth_is_deterministic_and_writes_the_contract_files() {
    let (a, b) = (tempdir(), tempdir());
    for d in [&a, &b] {
        common::succeed(polishbot().args([
            "synth",
            "--out",
            d.path().to_str().unwrap(),
            "--seed",
            "7",
            "--reference-points",
            "20000",
            "--scan-points",
            "20000",
        ]));
    }
    for f in ["reference.ply", "scan.ply", "truth.json"] {
        assert_eq!(
            std::fs::read(a.path().join(f)).unwrap(),
            std::fs::read(b.path().join(f)).unwrap(),
            "{f} differs between runs"
        );
    }
    let truth = Truth::load(&a.path().join("truth.json")).unwrap();
    assert_eq!(truth.defects.len(), 6);
    let scan = cloud::load_cloud(&a.path().join("scan.ply"), None, Some(Units::Mm)).unwrap();
    assert_eq!(scan.len(), truth.scan_points);
}

/// The scan, moved back by the true pose, lies on the reference surface within noise plus the
/// planted defect heights; outliers lie off it.
#[test]
fn synth_truth_explains_the_scan() {
    for mesh in [None, Some(shared_data("femoral_dm.stl"))] {
        let cfg = SynthConfig {
            mesh: mesh.clone(),
            surface: mesh.as_ref().map(|_| shared_data("femoral_dm_contact.stl")),
            units: mesh.as_ref().map(|_| Units::M),
            ..small_config(3)
        };
        let case = synth(&cfg).unwrap();
        let pose = case.truth.pose().unwrap();
        let mut scan = case.scan.clone();
        scan.transform(&pose);
        let sample = cloud::sample_mesh(&case.mesh, 400_000, 99).unwrap().cloud;
        let normals = sample.normals.as_ref().unwrap();
        // Nearest dense sample by brute force over a coarse grid of buckets.
        let nearest = |p: &Point3<f64>| -> (f64, usize) {
            sample
                .points
                .iter()
                .enumerate()
                .map(|(i, q)| ((q - p).norm(), i))
                .fold((f64::MAX, 0), |a, b| if b.0 < a.0 { b } else { a })
        };
        let outliers: std::collections::HashSet<usize> = case
            .truth
            .outliers
            .scattered
            .iter()
            .chain(&case.truth.outliers.clustered)
            .copied()
            .collect();
        let mut residuals = Vec::new();
        for i in (0..scan.len()).step_by(97) {
            let (d, j) = nearest(&scan.points[i]);
            if outliers.contains(&i) {
                assert!(d > 0.5, "outlier {i} lies on the surface ({d} mm)");
                continue;
            }
            let signed = (scan.points[i] - sample.points[j]).dot(&normals[j]);
            residuals.push(signed - case.truth.deviation_at(&sample.points[j], &normals[j]));
        }
        residuals.sort_by(f64::total_cmp);
        let median_abs = {
            let mut a: Vec<f64> = residuals.iter().map(|r| r.abs()).collect();
            a.sort_by(f64::total_cmp);
            a[a.len() / 2]
        };
        assert!(
            median_abs < 0.04,
            "{mesh:?}: median |residual| {median_abs}"
        );
        assert!(
            case.truth.outliers.scattered.len() + case.truth.outliers.clustered.len()
                == scan.len() - cfg.scan_points
        );
    }
}

#[path = "foundation/mutation.rs"]
mod mutation;

/// Turntable views, moved by their true view_to_first, lie on the part moved by
/// first_from_reference (median distance at the noise level), and each view sees only part of it.
#[test]
fn turntable_views_are_consistent_with_their_truth() {
    use polishbot::cloud::transform::isometry_from_rows;
    use polishbot::synth::TurntableConfig;
    let cfg = SynthConfig {
        turntable: Some(TurntableConfig {
            views: 8,
            points_per_view: 20_000,
            ..TurntableConfig::default()
        }),
        defects: 0,
        ..small_config(5)
    };
    let case = synth(&cfg).unwrap();
    let (views, truth) = case.turntable.as_ref().unwrap();
    assert_eq!(views.len(), 8);
    let first_from_ref = isometry_from_rows(&truth.first_from_reference).unwrap();
    let mut surface = cloud::sample_mesh(&case.mesh, 300_000, 4).unwrap().cloud;
    surface.transform(&first_from_ref);
    let index = polishbot::spatial::Neighbours::new(&surface.points);
    let normals = surface.normals.clone().unwrap();
    let mut coarse = cloud::sample_mesh(&case.mesh, 5_000, 6).unwrap().cloud;
    coarse.transform(&first_from_ref);
    let coarse_index = polishbot::spatial::Neighbours::new(&coarse.points);
    let mut seen = vec![false; coarse.len()];
    for (view, t) in views.iter().zip(&truth.views) {
        assert!((t.true_deg - t.nominal_deg).abs() <= 3.0 + 1e-9);
        let pose = isometry_from_rows(&t.view_to_first).unwrap();
        let mut d: Vec<f64> = view
            .points
            .iter()
            .map(|p| {
                let q = pose * p;
                let n = index.knn(&q, 1)[0];
                seen[coarse_index.knn(&q, 1)[0].index] = true;
                // Distance to the surface's tangent plane at the nearest sample.
                (q - surface.points[n.index]).dot(&normals[n.index]).abs()
            })
            .collect();
        d.sort_by(f64::total_cmp);
        assert!(
            d[d.len() / 2] < 0.02,
            "{}: median distance {}",
            t.file,
            d[d.len() / 2]
        );
    }
    let coverage = seen.iter().filter(|s| **s).count() as f64 / seen.len() as f64;
    assert!(
        coverage > 0.7,
        "views together touch {coverage:.2} of the surface samples"
    );
}

//! Hostile input to the readers and the outlier/voxel stage, through the built binary: every
//! case ends within a time limit, exits non-zero with one line naming the file and the place,
//! never panics, and stays within a memory bound (the child's peak resident set, from wait4).
mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use common::{polishbot, tempdir};
use polishbot::cloud::{self, Format, Geometry, ParseError, Place};

/// What a bounded run of the binary gave.
struct Outcome {
    /// Exit code (None: killed at the time limit or by a signal).
    code: Option<i32>,
    stderr: String,
    /// Peak resident set of the child, MB.
    peak_mb: f64,
}

/// Runs `cmd` for at most `limit`, killing it then; returns its exit code, stderr and peak
/// memory (getrusage of exactly this child through wait4).
#[allow(clippy::zombie_processes)] // reaped by wait4, which also gives its rusage
fn run_bounded(cmd: &mut Command, limit: Duration) -> Outcome {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("start polishbot");
    let mut err_pipe = child.stderr.take().expect("piped");
    let reader = std::thread::spawn(move || {
        let mut s = String::new();
        let _ = std::io::Read::read_to_string(&mut err_pipe, &mut s);
        s
    });
    let pid = child.id() as libc::pid_t;
    let start = Instant::now();
    let mut status = 0;
    // SAFETY: rusage is plain data; wait4 writes it and the status for our own child.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    loop {
        let r = unsafe { libc::wait4(pid, &mut status, libc::WNOHANG, &mut usage) };
        if r == pid {
            break;
        }
        assert!(r == 0, "wait4 failed");
        if start.elapsed() > limit {
            let _ = child.kill();
            unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
            break;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
    let code = libc::WIFEXITED(status).then(|| libc::WEXITSTATUS(status));
    Outcome {
        code,
        stderr: reader.join().expect("stderr reader"),
        peak_mb: usage.ru_maxrss as f64 / 1024.0,
    }
}

/// Limit for every case: the bound on any hostile case is 20 s.
const LIMIT: Duration = Duration::from_secs(20);

/// Asserts a refusal: exit 1 (not killed), one line naming `file` and each of `says`, no panic.
fn assert_refused(out: &Outcome, file: &Path, says: &[&str]) {
    let err = out.stderr.trim_end();
    let name = file.file_name().unwrap().to_str().unwrap();
    assert_eq!(out.code, Some(1), "{name}: exit {:?}: {err}", out.code);
    assert_eq!(err.lines().count(), 1, "{name}: {err}");
    assert!(!err.contains("panicked"), "{name}: {err}");
    assert!(err.contains(name), "{name} not named: {err}");
    for s in says {
        assert!(err.contains(s), "{name}: expected {s:?} in {err}");
    }
}

/// Writes `bytes` as `name` and runs `polishbot info FILE --units mm` on it.
fn info_on(dir: &Path, name: &str, bytes: &[u8]) -> (PathBuf, Outcome) {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    let out = run_bounded(
        polishbot().args(["info", path.to_str().unwrap(), "--units", "mm"]),
        LIMIT,
    );
    (path, out)
}

const PLY_HEAD: &str = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nproperty uchar red\nend_header\n";

#[test]
fn devices_and_fifos_are_refused_before_reading() {
    let out = run_bounded(
        polishbot().args(["info", "/dev/zero", "--format", "xyz"]),
        LIMIT,
    );
    assert_refused(&out, Path::new("/dev/zero"), &["not a regular file"]);
    assert!(out.peak_mb < 100.0, "read /dev/zero: {} MB", out.peak_mb);

    let dir = tempdir();
    let fifo = dir.path().join("scan.xyz");
    let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
    // SAFETY: a valid C string path.
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    let start = Instant::now();
    let out = run_bounded(polishbot().args(["info", fifo.to_str().unwrap()]), LIMIT);
    assert_refused(&out, &fifo, &["not a regular file", "FIFO"]);
    assert!(start.elapsed() < Duration::from_secs(5), "FIFO blocked");
}

#[test]
fn ply_rows_columns_and_types_must_match_the_header() {
    let dir = tempdir();
    let d = dir.path();
    let body = "0 0 0 1\n1 0 0 2\n0 1 0 3\n";
    // Header lines 1-8, body lines 9-11.
    for (name, text, says) in [
        ("rows.ply", format!("{PLY_HEAD}{body}5 5 5 4\n"), vec!["line 12", "more rows"]),
        ("columns.ply", format!("{PLY_HEAD}0 0 0 1\n1 0 0 2 7\n0 1 0 3\n"), vec!["line 10", "more values"]),
        ("uchar.ply", format!("{PLY_HEAD}0 0 0 1\n1 0 0 300\n0 1 0 3\n"), vec!["line 10", "red", "uchar"]),
        ("fraction.ply", format!("{PLY_HEAD}0 0 0 1.5\n1 0 0 2\n0 1 0 3\n"), vec!["line 9", "uchar"]),
        ("float.ply", format!("{PLY_HEAD}0 0 1e39 1\n1 0 0 2\n0 1 0 3\n"), vec!["line 9", "float"]),
        (
            "list.ply",
            format!("{}element face 1\nproperty list uchar int vertex_indices\nend_header\n{body}300 0 1 2\n", PLY_HEAD.replace("end_header\n", "")),
            vec!["line 14", "uchar"],
        ),
    ] {
        let (path, out) = info_on(d, name, text.as_bytes());
        assert_refused(&out, &path, &says);
    }
    // Binary: bytes after the declared vertices.
    let mut bin = b"ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n".to_vec();
    let end = bin.len() + 12;
    for v in [1f32, 2.0, 3.0, 4.0, 5.0, 6.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    let (path, out) = info_on(d, "extra.ply", &bin);
    assert_refused(&out, &path, &[&format!("byte {end}"), "12 bytes after"]);
    // The same file without the extra row reads, and a trailing newline is no row.
    bin.truncate(end);
    bin.push(b'\n');
    let (_, out) = info_on(d, "exact.ply", &bin);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
}

#[test]
fn stl_cut_inside_a_facet_is_refused() {
    let dir = tempdir();
    let facet = "facet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 1 0 0\nvertex 0 1 0\nendloop\nendfacet\n";
    let whole = format!("solid s\n{facet}{facet}endsolid s\n");
    let lines: Vec<&str> = whole.lines().collect();
    // Cut after the second facet's second vertex (line 12) and between facets (line 8).
    let inside = lines[..12].join("\n") + "\n";
    let between = lines[..8].join("\n") + "\n";
    for (name, text, says) in [
        (
            "inside.stl",
            inside,
            vec!["line 12", "inside the facet begun at line 9"],
        ),
        ("between.stl", between, vec!["line 8", "without endsolid"]),
        (
            "loopless.stl",
            whole.replacen("endloop\n", "", 1),
            vec!["line 7", "endfacet"],
        ),
    ] {
        let (path, out) = info_on(dir.path(), name, text.as_bytes());
        assert_refused(&out, &path, &says);
    }
    let (_, out) = info_on(dir.path(), "whole.stl", whole.as_bytes());
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    // Binary STL cut inside its last facet: the size contradicts the triangle count.
    let mut bin = vec![0u8; 80];
    bin.extend_from_slice(&2u32.to_le_bytes());
    bin.extend_from_slice(&[0u8; 75]);
    let (path, out) = info_on(dir.path(), "cut.stl", &bin);
    assert_refused(&out, &path, &["byte 80", "2 triangles"]);
}

#[test]
fn pcd_off_and_text_rows_are_bounded_by_their_headers() {
    let dir = tempdir();
    let pcd = "VERSION 0.7\nFIELDS x y z label\nSIZE 4 4 4 1\nTYPE F F F U\nCOUNT 1 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n";
    let off = "OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n";
    for (name, text, says) in [
        (
            "rows.pcd",
            format!("{pcd}1 2 3 4\n5 6 7 8\n9 9 9 9\n"),
            vec!["line 12", "more rows"],
        ),
        (
            "label.pcd",
            format!("{pcd}1 2 3 4\n5 6 7 300\n"),
            vec!["line 11", "label"],
        ),
        (
            "columns.pcd",
            format!("{pcd}1 2 3 4 5\n5 6 7 8\n"),
            vec!["line 10", "expected 4 values"],
        ),
        (
            "count.pcd",
            pcd.replace("COUNT 1 1 1 1", "COUNT 1 1 1 18446744073709551615") + "1 2 3\n",
            vec!["line 9", "too large"],
        ),
        (
            "rows.off",
            format!("{off}3 2 1 0\n"),
            vec!["line 7", "more lines"],
        ),
        (
            "faces.off",
            off.replace("3 0 1 2", "18446744073709551615 0 1 2"),
            vec!["line 6", "face declares"],
        ),
        (
            "columns.xyz",
            "1 2 3\n4 5 6 7\n".to_string(),
            vec!["line 2", "expected 3 values"],
        ),
    ] {
        let (path, out) = info_on(dir.path(), name, text.as_bytes());
        assert_refused(&out, &path, &says);
    }
}

/// A 20 MB file of one line of ten million numbers used to become ten million scalar fields
/// (2.3 GB). Now the row is refused at its 1025th value: the peak is the file itself plus the
/// program.
#[test]
fn a_twenty_megabyte_line_is_refused_in_bounded_memory() {
    let dir = tempdir();
    let line = "1 ".repeat(10_000_000);
    let (path, out) = info_on(dir.path(), "line.xyz", line.as_bytes());
    assert_refused(&out, &path, &["line 1", "more than 1024 values"]);
    eprintln!("20 MB one-line XYZ: peak {:.1} MB", out.peak_mb);
    assert!(
        out.peak_mb < 120.0,
        "peak {} MB for a 20 MB file",
        out.peak_mb
    );
}

#[test]
fn coordinates_beyond_a_kilometre_are_refused_after_units() {
    let dir = tempdir();
    let d = dir.path();
    let mut ply = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty double x\nproperty double y\nproperty double z\nend_header\n".to_vec();
    for v in [0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 1e300, 0.0, 0.0] {
        ply.extend_from_slice(&f64::to_le_bytes(v));
    }
    let (path, out) = info_on(d, "far.ply", &ply);
    assert_refused(&out, &path, &["point 2", "1e300", "1e6 mm"]);
    // 1500 units are fine in mm and 1.5 km in metres.
    let xyz = "0 0 0\n1 1 1\n1500 0 0\n";
    let (path, out) = info_on(d, "metres.xyz", xyz.as_bytes());
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let out = run_bounded(
        polishbot().args(["info", path.to_str().unwrap(), "--units", "m"]),
        LIMIT,
    );
    assert_refused(&out, &path, &["point 2", "--units"]);
    // filter and inspect go through the same check.
    let filtered = d.join("out.ply");
    let far = d.join("far.ply");
    let out = run_bounded(
        polishbot().args([
            "filter",
            far.to_str().unwrap(),
            "-o",
            filtered.to_str().unwrap(),
            "--units",
            "mm",
        ]),
        LIMIT,
    );
    assert_refused(&out, &far, &["point 2"]);
    let reference = d.join("tetra.off");
    std::fs::write(
        &reference,
        "OFF\n4 4 0\n0 0 0\n10 0 0\n0 10 0\n0 0 10\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n",
    )
    .unwrap();
    let out = run_bounded(
        polishbot().args([
            "inspect",
            "--reference",
            reference.to_str().unwrap(),
            "--scan",
            far.to_str().unwrap(),
            "-o",
            d.join("insp").to_str().unwrap(),
            "--units",
            "mm",
        ]),
        LIMIT,
    );
    assert_refused(&out, &far, &["point 2"]);
}

/// A cloud on a grid with one point 900 m away (inside the bound): filter runs (no panic, no
/// runaway grid) and removes it as an outlier; absurd voxels are refused naming the option.
#[test]
fn filter_survives_far_points_and_refuses_absurd_voxels() {
    let dir = tempdir();
    let mut text = String::new();
    for i in 0..2500 {
        text += &format!("{} {} 0\n", (i % 50) as f64 * 0.5, (i / 50) as f64 * 0.5);
    }
    text += "900000 -900000 900000\n";
    let input = dir.path().join("plane.xyz");
    std::fs::write(&input, text).unwrap();
    let output = dir.path().join("out.ply");
    let filter = |extra: &[&str]| {
        let mut cmd = polishbot();
        cmd.args([
            "filter",
            input.to_str().unwrap(),
            "-o",
            output.to_str().unwrap(),
        ])
        .args(["--units", "mm"])
        .args(extra);
        run_bounded(&mut cmd, LIMIT)
    };
    let out = filter(&[]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
    let kept = cloud::load_cloud(&output, None, Some(cloud::Units::Mm)).unwrap();
    assert_eq!(kept.len(), 2500, "the far point is an outlier");
    for (voxel, says) in [
        ("1e-300", "absurdly small"),
        ("1e300", "larger than the whole cloud"),
        ("nan", "positive number"),
    ] {
        let out = filter(&["--voxel", voxel]);
        assert_refused(&out, &input, &["--voxel", says]);
    }
    // A voxel of a plain size still works: 2 × 2 points per 1 mm voxel.
    let out = filter(&["--no-outlier-filter", "--voxel", "1"]);
    assert_eq!(out.code, Some(0), "{}", out.stderr);
}

/// The library readers give the same places as the binary (no file: parse errors only).
#[test]
fn parse_errors_carry_their_place() {
    let place = |bytes: &[u8], format| match cloud::parse(bytes, format) {
        Err(ParseError { place, .. }) => place,
        Ok(g) => panic!("accepted: {} points", g.points().len()),
    };
    let rows = format!("{PLY_HEAD}0 0 0 1\n1 0 0 2\n0 1 0 3\n\n\n4 4 4 4\n");
    assert_eq!(place(rows.as_bytes(), Format::Ply), Place::Line(14));
    assert_eq!(
        place(
            b"OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2\n# ok\n1 2\n",
            Format::Off
        ),
        Place::Line(8)
    );
    // The valid version of each reads.
    let ok = format!("{PLY_HEAD}0 0 0 1\n1 0 0 255\n0 1 0 3\n\n");
    let Ok(Geometry::Cloud(c)) = cloud::parse(ok.as_bytes(), Format::Ply) else {
        panic!("valid file refused")
    };
    assert_eq!(c.field("red").unwrap(), &[1.0, 255.0, 3.0]);
}

/// A PCD header whose `POINTS` is not `WIDTH` × `HEIGHT` and an OBJ face corner with a
/// texture or normal index that is not a number were read as if they were fine; both are
/// refused at their line. The valid forms beside them read.
#[test]
fn pcd_point_counts_and_obj_face_corners_must_agree_with_themselves() {
    let dir = tempdir();
    let pcd = "VERSION 0.7\nFIELDS x y z\nSIZE 4 4 4\nTYPE F F F\nCOUNT 1 1 1\nWIDTH 2\nHEIGHT 1\nPOINTS 2\nDATA ascii\n1 2 3\n4 5 6\n";
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1/1/1 2/2/2 3/3/3\n";
    for (name, text, says) in [
        (
            "width.pcd",
            pcd.replace("WIDTH 2", "WIDTH 3"),
            vec!["line 8", "POINTS 2", "WIDTH"],
        ),
        (
            "height.pcd",
            pcd.replace("HEIGHT 1", "HEIGHT 2"),
            vec!["line 8", "2 × 2 = 4"],
        ),
        (
            "texture.obj",
            obj.replace("f 1/1/1", "f 1/x/1"),
            vec!["line 4", "1/x/1"],
        ),
        (
            "normal.obj",
            obj.replace("3/3/3", "3/3/n"),
            vec!["line 4", "3/3/n"],
        ),
        (
            "corner.obj",
            obj.replace("2/2/2", "2/2/2/2"),
            vec!["line 4", "2/2/2/2"],
        ),
    ] {
        let (path, out) = info_on(dir.path(), name, text.as_bytes());
        assert_refused(&out, &path, &says);
    }
    let faces = |text: &str| match cloud::parse(text.as_bytes(), Format::Obj) {
        Ok(Geometry::Mesh { mesh, .. }) => mesh.faces.len(),
        other => panic!("{text}: {:?}", other.err()),
    };
    assert_eq!(faces(obj), 1);
    assert_eq!(
        faces(
            &obj.replace("/1/1", "//1")
                .replace("/2/2", "//2")
                .replace("/3/3", "//3")
        ),
        1
    );
    assert_eq!(
        faces(
            &obj.replace("/1/1", "/1")
                .replace("/2/2", "/2")
                .replace("/3/3", "/3")
        ),
        1
    );
    let Ok(Geometry::Cloud(c)) = cloud::parse(pcd.as_bytes(), Format::Pcd) else {
        panic!("valid PCD refused")
    };
    assert_eq!(c.len(), 2);
}

/// An ascii STL in capitals (`SOLID`, `FACET NORMAL`, `VERTEX`: what many CAD exporters
/// write) was taken for binary and refused with a triangle count from its header's bytes; its
/// keywords are read in any case now, its errors name its lines, and a binary STL whose
/// 80-byte header begins with "solid" is still binary.
#[test]
fn ascii_stl_keywords_are_read_in_any_case() {
    let facet = "FACET NORMAL 0 0 1\n OUTER LOOP\n  VERTEX 0 0 0\n  Vertex 1 0 0\n  VERTEX 0 1 0\n ENDLOOP\nENDFACET\n";
    let upper = format!("SOLID part\n{facet}{facet}ENDSOLID part\n");
    let Ok(Geometry::Mesh { mesh, .. }) = cloud::parse(upper.as_bytes(), Format::Stl) else {
        panic!("uppercase ascii STL refused")
    };
    assert_eq!((mesh.faces.len(), mesh.vertices.len()), (2, 3));
    let dir = tempdir();
    let cut = upper.replacen("ENDLOOP\n", "", 1);
    let (path, out) = info_on(dir.path(), "upper.stl", cut.as_bytes());
    assert_refused(&out, &path, &["line 7", "endfacet"]);
    let mut bin = b"solid written by a binary exporter".to_vec();
    bin.resize(80, b' ');
    bin.extend_from_slice(&1u32.to_le_bytes());
    for v in [0f32, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0, 0.0] {
        bin.extend_from_slice(&v.to_le_bytes());
    }
    bin.extend_from_slice(&[0, 0]);
    let Ok(Geometry::Mesh { mesh, .. }) = cloud::parse(&bin, Format::Stl) else {
        panic!("binary STL with a solid header refused")
    };
    assert_eq!(mesh.faces.len(), 1);
}
